"""Internal: what the keepout path modules share.

The per-cell write rule in uint8 arithmetic, the mask tables it reads, the per-robot
state updates, the fleet's batched inputs, and `rerun`, which redoes the robots a
fast path could not decide with the exact arithmetic.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from jaxfilters import geometry
from jaxfilters.keepout.config import KeepoutConfig, KeepoutState, mask_cost_plus_one_table
from jaxfilters.types import Costmap, FilterMask, check_costmap, robot_inputs

_COST1 = mask_cost_plus_one_table()


def with_error(state, error):
  """`state` with its `error` leaf set to `error` (bool)."""
  return dataclasses.replace(state, error=jnp.asarray(error, bool))


def window_flags(w, h, x0, y0, x1, y1, run):
  """col_ok bool [W], row_ok bool [H] of a half-open window; rows all False when not run."""
  cols = jnp.arange(w, dtype=jnp.int32)
  rows = jnp.arange(h, dtype=jnp.int32)
  return (cols >= x0) & (cols < x1), (rows >= y0) & (rows < y1) & run


def mask_cost_u8(d):
  """int8 mask values -> (known bool, cost uint8) in integer arithmetic (no table).

  Known are 0..100 (a byte <= 100 once read as uint8); their cost round(2.54 d) is
  2 d + ((553 d + 511) >> 10), checked for every d in 0..100 by
  tests/test_keepout_paths.py against `occ_to_cost`. Unknown bytes give garbage costs
  that `known` masks.
  """
  u = jax.lax.bitcast_convert_type(d, jnp.uint8)
  known = u <= jnp.uint8(100)
  d16 = u.astype(jnp.uint16)
  cost = (d16 * jnp.uint16(2) + ((d16 * jnp.uint16(553) + jnp.uint16(511)) >> jnp.uint16(10))).astype(jnp.uint8)
  return known, cost


def write_u8(cost, d, visit, state, config):
  """Nav2's per-cell rule (docs/nav2_semantics.md §4.4) on int8 mask values d where `visit`, in uint8 arithmetic.

  With c1 = cost + 1 and m1 = mask cost + 1 (0 where unknown or not visited), both
  wrapping 255 to 0, `mask != 255 and (mask > old or old == 255)` is `m1 > c1` and
  the written value max(c1, m1) - 1 (`m1_rule_u8`).
  """
  known, mc = mask_cost_u8(d)
  m1 = jnp.where(visit & known, mc + jnp.uint8(1), jnp.uint8(0))
  return m1_rule_u8(cost, m1, state, config)


def processed(state, run):
  """State after process(): last_pose_lethal follows is_pose_lethal unless it returned early."""
  return dataclasses.replace(
      state, last_pose_lethal=jnp.where(run, state.is_pose_lethal, state.last_pose_lethal))


def robot_geometry(costmap: Costmap, mask: FilterMask):
  """Per-robot geometry leaves for vmap: (origin parts, resolution parts) of the costmaps."""
  return (costmap.origin, costmap.origin_lo, costmap.resolution, costmap.resolution_lo)


def mask_origin_terms(mask: FilterMask, i):
  """Mask i's origin as float32 parts (`geometry.origin_terms`)."""
  return geometry.origin_terms(mask.origin[i], None if mask.origin_lo is None else mask.origin_lo[i])


def tree_where(pick, a, b):
  """Per-robot choice between two batched pytrees (pick bool [B])."""
  return jax.tree.map(lambda x, y: jnp.where(pick.reshape(pick.shape + (1,) * (x.ndim - 1)), x, y), a, b)


def rerun_if_any(need, fast, exact_fn, args, capacity):
  """`rerun` inside one batch-level `lax.cond`: when no robot needs the exact arithmetic
  (`need` bool [B] all False) nothing runs, not even a loop test (on a GPU each turn of a
  loop whose trip count is data dependent waits for the host)."""
  return jax.lax.cond(jnp.any(need), lambda f: rerun(need, f, exact_fn, args, capacity), lambda f: f, fast)


def rerun(need, fast, exact_fn, args, capacity):
  """`fast` (a batched pytree) with the robots where `need` replaced by `exact_fn`'s results.

  exact_fn maps batched args to batched results (one compiled copy). The robots that
  need it are gathered `capacity` at a time, in a loop of as many turns as that takes
  (none when no robot needs it); the last turn's spare slots redo robot 0 (or another
  already redone), whose exact result is right either way.
  """
  b = need.shape[0]
  count = jnp.sum(need.astype(jnp.int32))
  order = jnp.nonzero(need, size=b + capacity, fill_value=0)[0]

  def body(k, out):
    if capacity == 1:   # in-place slices: a scatter would copy the whole batch each turn
      r = order[k]
      res = exact_fn(jax.tree.map(lambda a: jax.lax.dynamic_slice_in_dim(a, r, 1), args))
      return jax.tree.map(lambda o, x: jax.lax.dynamic_update_slice_in_dim(o, x, r, 0), out, res)
    sel = jax.lax.dynamic_slice(order, (k * capacity,), (capacity,))
    res = exact_fn(jax.tree.map(lambda a: a[sel], args))
    return jax.tree.map(lambda o, r: o.at[sel].set(r), out, res)

  return jax.lax.fori_loop(0, (count + capacity - 1) // capacity, body, fast)


def rerun_capacity(b):
  """How many robots one turn of `rerun` redoes in a fleet of b."""
  return min(b, max(8, b // 32))


def divisor_at_most(b, limit):
  """The largest divisor of b that is <= max(limit, 1): lax.map chunks without a remainder
  (a remainder chunk runs outside the loop, where XLA fuses it into the next pass)."""
  return max(d for d in range(1, min(b, max(limit, 1)) + 1) if b % d == 0)


def batched_inputs(costmap, mask, poses, mask_index, enabled, window, transform, where):
  """The public functions' inputs checked and batched: (idx, idx_ok, poses, enabled, window int32 [B, 4], transform).

  `where` names the caller in error messages. The window defaults to the whole map and is
  clipped to it like LayeredCostmap does.
  """
  check_costmap(costmap, where)
  b = costmap.num_robots
  h, w = costmap.cost.shape[1:]
  idx, idx_ok, poses, enabled, transform = robot_inputs(mask, poses, b, mask_index, enabled, transform)
  if window is None:
    window = jnp.tile(jnp.asarray([0, 0, w, h], jnp.int32), (b, 1))
  else:
    window = jnp.asarray(window)
    if window.shape not in ((4,), (b, 4)) or not jnp.issubdtype(window.dtype, jnp.integer):
      raise ValueError(f"window must be integer (min_i, min_j, max_i, max_j) of shape (4,) or ({b}, 4); "
                       f"got {window.dtype}{tuple(window.shape)}")
    # Clip to the map like LayeredCostmap does.
    window = jnp.broadcast_to(window.astype(jnp.int32), (b, 4))
    window = jnp.stack([jnp.maximum(window[:, 0], 0), jnp.maximum(window[:, 1], 0),
                        jnp.minimum(window[:, 2], w), jnp.minimum(window[:, 3], h)], axis=1)
  return idx, idx_ok, poses, enabled, window, transform


def fill_error(state: KeepoutState, b: int) -> KeepoutState:
  """A hand-built state without `error` gets an all-False one (same pytree every cycle)."""
  if state.error is None:
    state = dataclasses.replace(state, error=jnp.zeros((b,), bool))
  return state


def cost_plus_one_table(data, h, w):
  """uint8 [M, Hm + 2H, Wm + 2W]: the masks' (cost + 1) bytes (`_COST1`) padded with 0 (unknown)."""
  table = jnp.asarray(_COST1)[jax.lax.bitcast_convert_type(data, jnp.uint8).astype(jnp.int32)]
  return jnp.pad(table, ((0, 0), (h, h), (w, w)))


def m1_table(data):
  """uint8 [M, Hm, Wm]: each mask cell's cost + 1, 0 where unknown (`mask_cost_plus_one_table`)."""
  return jnp.asarray(_COST1)[jax.lax.bitcast_convert_type(data, jnp.uint8).astype(jnp.int32)]


def m1_rule_u8(cost, m1, state, config: KeepoutConfig):
  """Nav2's write rule on (mask cost + 1) bytes m1 (0: unknown or not visited), uint8 [H, W]."""
  c1 = cost + jnp.uint8(1)
  if config.override_lethal_cost:
    value = jnp.where(state.is_pose_lethal, jnp.uint8(config.lethal_override_cost), m1 - jnp.uint8(1))
    return jnp.where(m1 > c1, value, cost)
  return jnp.maximum(c1, m1) - jnp.uint8(1)
