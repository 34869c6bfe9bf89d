"""The fast same-frame keepout path: the exact path's integers at a fraction of its work.

`same_frame_prologue` decides, from per-robot scalars, each robot's clipped update
window and whether its mask cells are one slice of the mask. A robot whose cells are a
slice reads them with one `dynamic_slice` of the mask padded with unknown cells; the
others read them through their two exact index vectors (other_resolution.py).

The cells run one robot after another with `lax.map` on the CPU backend (`loop`
"map": every robot through its index vectors, a sliced robot's made by arithmetic from
its slice start, so one kernel with no branch and no padded copy of the mask) and
vectorised over the fleet elsewhere ("vmap": one choice for the whole batch, the slice
on four cells per uint32 word when W % 4 == 0, or with `KeepoutConfig.kernel` the
Pallas kernel of pallas.py). An eager call makes its batch-level choices on the host
(plan.py) and traces only the path it takes.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxfilters.keepout import pallas
from jaxfilters.keepout.common import (cost_plus_one_table, m1_rule_u8, processed, tree_where, window_flags,
                                       with_error)
from jaxfilters.keepout.config import KeepoutConfig
from jaxfilters.keepout.other_resolution import gather_write_one, other_resolution_batch
from jaxfilters.keepout.packed import pack, shifted_words, unpack, write_rule
from jaxfilters.keepout.prologue import index_vectors, same_frame_prologue


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


def same_frame_batch(costmap, mask, idx, idx_ok, state, window, enabled, *, config: KeepoutConfig, loop: str,
                     plan=None):
  """The fast same-frame keepout over a fleet: same integers as the exact path.

  The prologue works on per-robot scalars (`same_frame_prologue`). `loop` "map" runs the
  cells robot by robot (the CPU kernel, `_map_cells`: every robot through its index
  vectors, a sliced robot's made by arithmetic, so one kernel and no branch), "vmap"
  vectorises them (the other backends' kernels); see the module docstring.

  `plan` None (inside a caller's `jit`): the robots whose brackets are open are redone
  exactly in the program, the "map" loop with loops of data-dependent trip count (no
  conditional), the "vmap" loop inside batch-level `lax.cond`s. With a `plan.Plan`
  (static: an eager call, decided on the host) nothing is redone here: the batch also
  returns needs bool [B], the robots whose brackets are open (their cost and state
  here are not theirs; process.py redoes them with the exact path), and the vectorised
  loop takes the slice kernel only if `plan.all_sliced`.

  Returns:
    (new cost uint8 [B, H, W], new state), and needs bool [B] with a plan.
  """
  b, h, w = costmap.cost.shape
  m, hm, wm = mask.data.shape
  traced = "loop" if loop == "map" else "cond"
  if plan is None:
    box, run, sx, sy, sliced = same_frame_prologue(costmap, mask, idx, idx_ok, window, enabled,
                                                   reruns=(traced, traced))
    needs = None
  else:
    box, run, sx, sy, sliced, box_known, decided = same_frame_prologue(costmap, mask, idx, idx_ok, window,
                                                                       enabled, flags=True)
    needs = ~box_known | ~decided
  new_state = with_error(jax.vmap(processed)(state, run), ~idx_ok)
  if not config.aligned_fast_path:
    sliced = jnp.zeros((b,), bool)
  flags = lambda bx: window_flags(w, h, *bx, True)

  def vectors(gathered):
    """The index vectors, and the robots (of `gathered`) whose exact ones are not known."""
    if plan is None:
      return index_vectors(costmap, mask, idx, need=gathered, rerun=traced), None
    cells, known = index_vectors(costmap, mask, idx, flags=True)
    return cells, ~known if gathered is None else ~known & gathered

  def gather_all(cost):
    """The vectorised kernel for robots not sliced (`other_resolution_batch`)."""
    ((mx, vx), (my, vy)), open_ = vectors(None)
    col_ok, row_ok = jax.vmap(flags)(box)
    return other_resolution_batch((cost, idx, mx, vx, my, vy, col_ok, row_ok, state), mask,
                                  config=config), open_

  def result(cost, open_=None):
    if plan is None:
      return cost, new_state
    return cost, new_state, needs if open_ is None else needs | open_

  table_bytes = m * (hm + 2 * h) * (wm + 2 * w)
  if pallas.use_pallas(config.kernel, config.pallas, table_bytes=table_bytes):
    if plan is None:
      return result(_pallas_batch(costmap.cost, mask.data, sliced, idx, sx, sy, box, state,
                                  lambda c: gather_all(c)[0], config=config))
    if plan.all_sliced:
      return result(_pallas_batch(costmap.cost, mask.data, sliced, idx, sx, sy, box, state, None,
                                  config=config, all_sliced=True))
    return result(*gather_all(costmap.cost))
  if loop == "map":
    vecs, open_ = vectors(~sliced)
    return result(_map_cells(costmap, mask, idx, box, sx, sy, sliced, state, vecs, config=config), open_)
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

  if plan is not None:
    return result(by_slice()) if plan.all_sliced else result(*gather_all(costmap.cost))
  return result(jax.lax.cond(jnp.all(sliced), by_slice, lambda: gather_all(costmap.cost)[0]))


def _map_cells(costmap, mask, idx, box, sx, sy, sliced, state, vectors, *, config: KeepoutConfig):
  """The CPU kernel: robot by robot, each robot's cells gathered through its two index vectors.

  A sliced robot's vectors are k0 + i (the slice test proved them equal to the exact
  ones: `prologue.slice_test_one`), so they come from its slice start by arithmetic; the
  others' are `vectors` ((mx, vx), (my, vy): `index_vectors`). One kernel for both, no
  branch, and the mask is read in place (no padded copy of it per call).
  """
  b, h, w = costmap.cost.shape
  _, hm, wm = mask.data.shape
  flat = mask.data.reshape(-1)
  (mx, vx), (my, vy) = vectors
  cols = jnp.arange(w, dtype=jnp.int32)
  rows = jnp.arange(h, dtype=jnp.int32)

  def one(c, i, bx, st, x, y, sl, mx, vx, my, vy):
    qx, qy = x - w + cols, y - h + rows           # the slice's mask columns and rows (`_slice_start`)
    mx = jnp.where(sl, jnp.clip(qx, 0, wm - 1), mx)
    vx = jnp.where(sl, (qx >= 0) & (qx < wm), vx)
    my = jnp.where(sl, jnp.clip(qy, 0, hm - 1), my)
    vy = jnp.where(sl, (qy >= 0) & (qy < hm), vy)
    col_ok, row_ok = window_flags(w, h, *bx, True)
    return gather_write_one(c, flat, i, (hm, wm), mx, vx, my, vy, col_ok, row_ok, st, config=config)

  args = (costmap.cost, idx, box, state, sx, sy, sliced, mx, vx, my, vy)
  if b == 1:          # one robot: no loop around it
    return one(*jax.tree.map(lambda a: a[0], args))[None]
  return jax.lax.map(lambda a: one(*a), args)


def _pallas_batch(cost, data, sliced, idx, sx, sy, box, state, gather_all, *, config: KeepoutConfig,
                  all_sliced=None):
  """The same-frame cells with the Pallas kernel on the sliced robots (`KeepoutConfig.kernel`).

  The kernel takes per-robot scalars (`pallas.slice_params_from_bounds`: the window
  bounds, no [B, W] flags); it writes the sliced robots and passes the others through;
  those are then gathered from its result (their cells are still the old ones), only
  when there are any (`gather_all(cost)` gathers every robot). Without `in_place` a
  fleet not sliced throughout is gathered at once; `in_place`'s kernel must not sit in
  a `lax.cond` branch (XLA would copy the costmap into the branch to update it there).
  `all_sliced=True` (static: an eager call's plan saw every robot sliced) runs the
  kernel alone.
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
    if all_sliced:
      return out
    return jax.lax.cond(jnp.all(sliced), lambda o: o, rest, out)

  if config.pallas.in_place or all_sliced:
    return kernel_then_gather()
  # A fleet not sliced throughout is gathered whole (exact for every robot), as on the XLA
  # vectorised path: the kernel followed by a gather of the rest is slower than the
  # gather alone when few robots are sliced.
  return jax.lax.cond(jnp.all(sliced), kernel_then_gather, lambda: gather_all(cost))
