"""The fast same-frame keepout path: the exact path's integers at a fraction of its work.

`same_frame_prologue` decides, from per-robot scalars, each robot's clipped update
window and whether its mask cells are one slice of the mask. A robot whose cells are a
slice reads them with one `dynamic_slice` of the mask padded with unknown cells; the
others read them through their two exact index vectors (other_resolution.py).

The cells run one robot after another with `lax.map` on the CPU backend (`loop`
"map": each robot's slice-or-gather choice a real branch, each slice contiguous) and
vectorised over the fleet elsewhere ("vmap": one choice for the whole batch, the slice
on four cells per uint32 word when W % 4 == 0, or with `KeepoutConfig.kernel` the
Pallas kernel of pallas.py).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxfilters.keepout import pallas
from jaxfilters.keepout.common import (cost_plus_one_table, m1_rule_u8, processed, tree_where, window_flags,
                                       with_error, write_u8)
from jaxfilters.keepout.config import KeepoutConfig
from jaxfilters.keepout.other_resolution import gather_write_one, other_resolution_batch
from jaxfilters.keepout.packed import pack, shifted_words, unpack, write_rule
from jaxfilters.keepout.prologue import index_vectors, same_frame_prologue


def _slice_write_one(cost, padded, i, sx, sy, col_ok, row_ok, state, *, config: KeepoutConfig):
  """The write rule on one [H, W] slice of the masks padded with unknown (-1) cells (uint8 [H, W])."""
  h, w = cost.shape
  d = jax.lax.dynamic_slice(padded, (i, sy, sx), (1, h, w))[0]
  return write_u8(cost, d, col_ok[None, :] & row_ok[:, None], state, config)


def aligned_one(cost, table, i, sx, sy, col_ok, row_ok, state, *, config: KeepoutConfig):
  """The slice kernel on a (cost + 1) table (the vectorised choice when W % 4 != 0).

  With the mask cell of master cell (j, k) at (k0y + j, k0x + k), the mask cells are a
  plain [H, W] window: a `dynamic_slice` of `table`, the mask's (cost + 1) bytes padded
  by H rows and W columns of 0 (= unknown, never written), so windows partly or wholly
  off the mask read 0 there. The write rule is `common.m1_rule_u8`.

  Args:
    cost: uint8 [H, W]. table: uint8 [M, Hm + 2H, Wm + 2W] padded (cost + 1) masks
      (`common.cost_plus_one_table`); i: int32 [] the mask; (sx, sy): the window's
      start in the table; col_ok [W], row_ok [H]: the update window as flags.
    state, config: as `reference.keepout_one`.

  Returns:
    new cost uint8 [H, W].
  """
  h, w = cost.shape
  m1 = jax.lax.dynamic_slice(table, (i, sy, sx), (1, h, w))[0]
  m1 = jnp.where(col_ok[None, :] & row_ok[:, None], m1, jnp.uint8(0))
  return m1_rule_u8(cost, m1, state, config)


def aligned_packed_one(cost, words, i, sx, sy, col_ok, row_ok, state, *, config: KeepoutConfig):
  """`aligned_one` on uint32 words (W % 4 == 0): the same slice, the word write rule of packed.py.

  words: `packed.shifted_words` of `aligned_one`'s table.
  """
  h, w = cost.shape
  m1 = jax.lax.dynamic_slice(words, (sx % 4, i, sy, sx // 4), (1, 1, h, w // 4))[0, 0]
  col_bytes = jnp.where(col_ok, jnp.uint8(0xFF), jnp.uint8(0))
  m1 = jnp.where(row_ok[:, None], m1 & pack(col_bytes)[None, :], jnp.uint32(0))
  return unpack(write_rule(pack(cost), m1, state, config))


def same_frame_batch(costmap, mask, idx, idx_ok, state, window, enabled, *, config: KeepoutConfig, loop: str):
  """The fast same-frame keepout over a fleet: same integers as the exact path.

  The prologue works on per-robot scalars (`same_frame_prologue`). Only when some robot
  is not sliced are the [B, W] / [B, H] index vectors built (`index_vectors`), inside
  that branch. `loop` "map" runs the cells robot by robot (the CPU kernels), "vmap"
  vectorises them (the other backends' kernels); see the module docstring.

  Returns:
    (new cost uint8 [B, H, W], new state).
  """
  b, h, w = costmap.cost.shape
  m, hm, wm = mask.data.shape
  mshape = (hm, wm)
  flat = mask.data.reshape(-1)

  box, run, sx, sy, sliced = same_frame_prologue(costmap, mask, idx, idx_ok, window, enabled)
  new_state = with_error(jax.vmap(processed)(state, run), ~idx_ok)
  if not config.aligned_fast_path:
    sliced = jnp.zeros((b,), bool)
  flags = lambda bx: window_flags(w, h, *bx, True)

  def gather(c, i, mx, vx, my, vy, bx, st):
    return gather_write_one(c, flat, i, mshape, mx, vx, my, vy, *flags(bx), st, config=config)

  def gather_all(cost):
    """The vectorised kernel for robots not sliced (`other_resolution_batch`)."""
    (mx, vx), (my, vy) = index_vectors(costmap, mask, idx)
    col_ok, row_ok = jax.vmap(flags)(box)
    return other_resolution_batch((cost, idx, mx, vx, my, vy, col_ok, row_ok, state), mask, config=config)

  table_bytes = m * (hm + 2 * h) * (wm + 2 * w)
  if pallas.use_pallas(config.kernel, config.pallas, table_bytes=table_bytes):
    return _pallas_batch(costmap.cost, mask.data, sliced, idx, sx, sy, box, state, gather_all,
                         config=config), new_state
  if loop == "map":
    def all_sliced():
      padded = jnp.pad(mask.data, ((0, 0), (h, h), (w, w)), constant_values=-1)
      return jax.lax.map(lambda a: _slice_write_one(a[0], padded, a[1], a[2], a[3], *flags(a[4]), a[5],
                                                    config=config),
                         (costmap.cost, idx, sx, sy, box, state))

    def mixed():
      padded = jnp.pad(mask.data, ((0, 0), (h, h), (w, w)), constant_values=-1)
      (mx, vx), (my, vy) = index_vectors(costmap, mask, idx)

      def body(a):
        c, i, mx, vx, my, vy, bx, st, x, y, sl = a
        return jax.lax.cond(sl, lambda: _slice_write_one(c, padded, i, x, y, *flags(bx), st, config=config),
                            lambda: gather(c, i, mx, vx, my, vy, bx, st))
      return jax.lax.map(body, (costmap.cost, idx, mx, vx, my, vy, box, state, sx, sy, sliced))

    # A branch inside the loop costs a copy of every robot's result, so a fleet that is
    # sliced, or gathered, throughout runs a loop without one.
    def map_gather():
      (mx, vx), (my, vy) = index_vectors(costmap, mask, idx)
      return jax.lax.map(lambda a: gather(*a), (costmap.cost, idx, mx, vx, my, vy, box, state))
    return jax.lax.cond(jnp.all(sliced), all_sliced,
                        lambda: jax.lax.cond(jnp.any(sliced), mixed, map_gather)), new_state
  if loop != "vmap":
    raise ValueError(f"loop must be 'auto', 'map' or 'vmap'; got {loop!r}")

  def by_slice():
    table = cost_plus_one_table(mask.data, h, w)
    if w % 4 == 0:
      words = shifted_words(table)
      one = lambda c, i, x, y, bx, st: aligned_packed_one(c, words, i, x, y, *flags(bx), st, config=config)
    else:
      one = lambda c, i, x, y, bx, st: aligned_one(c, table, i, x, y, *flags(bx), st, config=config)
    return jax.vmap(one)(costmap.cost, idx, sx, sy, box, state)

  return jax.lax.cond(jnp.all(sliced), by_slice, lambda: gather_all(costmap.cost)), new_state


def _pallas_batch(cost, data, sliced, idx, sx, sy, box, state, gather_all, *, config: KeepoutConfig):
  """The same-frame cells with the Pallas kernel on the sliced robots (`KeepoutConfig.kernel`).

  The kernel takes per-robot scalars (`pallas.slice_params_from_bounds`: the window
  bounds, no [B, W] flags); it writes the sliced robots and passes the others through;
  those are then gathered from its result (their cells are still the old ones), only
  when there are any (`gather_all(cost)` gathers every robot). Without `in_place` a
  fleet not sliced throughout is gathered at once; `in_place`'s kernel must not sit in
  a `lax.cond` branch (XLA would copy the costmap into the branch to update it there).
  """
  h, w = cost.shape[1:]
  x0, y0, x1, y1 = box

  def kernel_then_gather():
    params = pallas.slice_params_from_bounds(idx, sx, sy, x0, x1, y0, y1, sliced, state.is_pose_lethal,
                                             shape=(h, w))
    out = pallas.aligned_write(cost, cost_plus_one_table(data, h, w), params,
                               escape=config.override_lethal_cost,
                               lethal_cost=config.lethal_override_cost, tuning=config.pallas,
                               unknown_overwrite=config.unknown_overwrite)

    def rest(out):
      return tree_where(sliced, out, gather_all(out))
    return jax.lax.cond(jnp.all(sliced), lambda o: o, rest, out)

  if config.pallas.in_place:
    return kernel_then_gather()
  # A fleet not sliced throughout is gathered whole (exact for every robot), as on the XLA
  # vectorised path: the kernel followed by a gather of the rest is slower than the
  # gather alone when few robots are sliced.
  return jax.lax.cond(jnp.all(sliced), kernel_then_gather, lambda: gather_all(cost))
