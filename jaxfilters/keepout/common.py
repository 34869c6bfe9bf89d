"""Internal: what the keepout path modules share.

The per-cell write rule in uint8 arithmetic, the mask tables it reads, the per-robot
state updates, the fleet's batched inputs, and `rerun`, which redoes the robots a
fast path could not decide with the exact arithmetic.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from jaxfilters import constants
from jaxfilters.keepout.config import KeepoutConfig, KeepoutState, mask_cost_plus_one_table
from jaxfilters.types import (Costmap, FilterMask, check_costmap, check_robot_inputs, check_state_batch,
                              costmap_geometry_ok, host_view, mask_geometry_ok, robot_inputs)

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
  tests/jaxfilters/test_keepout_paths.py against `occ_to_cost`. Unknown bytes give garbage costs
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
  the written value max(c1, m1) - 1 (`m1_rule_u8`). With
  `KeepoutConfig.unknown_overwrite="inscribed"` an unknown old cell (c1 = 0)
  compares as c1 = 253, so only m1 >= 254 (mask cost >= 253) overwrites it.
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


def usable_geometry(costmap: Costmap, mask: FilterMask, idx, idx_ok):
  """The robots whose mask and costmap geometry can be used, and that geometry made safe to compute with.

  A traced resolution or origin can be anything (NaN, inf, a negative, zero or
  subnormal resolution; `types.mask_geometry_ok`, `types.costmap_geometry_ok`). A
  robot on such a mask or costmap is treated as one with an out-of-range mask
  index: nothing is written, its state is kept and `error` is set. Its geometry
  is replaced by resolution 1 and origin 0 so that no kernel (window sizes, loop
  counts, Pallas grids) computes from the garbage values; the replaced values are
  never written anywhere, since the robot does not run.

  Args:
    costmap, mask: as keepout_filter. idx int32 [B], idx_ok bool [B] (index in range).

  Returns:
    (costmap, mask, idx_ok & both geometries usable).
  """
  mask_ok = mask_geometry_ok(mask)
  cm_ok = costmap_geometry_ok(costmap)
  ok = idx_ok & mask_ok[idx] & cm_ok

  def safe(x, good, fill):
    if x is None:
      return None
    return jnp.where(good.reshape(good.shape + (1,) * (x.ndim - 1)), x, jnp.asarray(fill, x.dtype))

  mask = dataclasses.replace(mask, resolution=safe(mask.resolution, mask_ok, 1.0),
                             origin=safe(mask.origin, mask_ok, 0.0), origin_lo=safe(mask.origin_lo, mask_ok, 0.0))
  costmap = dataclasses.replace(costmap, resolution=safe(costmap.resolution, cm_ok, 1.0),
                                resolution_lo=safe(costmap.resolution_lo, cm_ok, 0.0),
                                origin=safe(costmap.origin, cm_ok, 0.0),
                                origin_lo=safe(costmap.origin_lo, cm_ok, 0.0))
  return costmap, mask, ok


def tree_where(pick, a, b):
  """Per-robot choice between two batched pytrees (pick bool [B])."""
  return jax.tree.map(lambda x, y: jnp.where(pick.reshape(pick.shape + (1,) * (x.ndim - 1)), x, y), a, b)


def rerun_if_any(need, fast, exact_fn, args, capacity):
  """`rerun` inside one batch-level `lax.cond`: when no robot needs the exact arithmetic
  (`need` bool [B] all False) nothing runs, not even a loop test (on a GPU each turn of a
  loop whose trip count is data dependent waits for the host)."""
  return jax.lax.cond(jnp.any(need), lambda f: rerun(need, f, exact_fn, args, capacity), lambda f: f, fast)


def rerun_as(mode, need, fast, exact_fn, args, capacity):
  """`rerun` as `mode` says, so a path is paid for only when it is taken.

  mode: False or True, decided on the host before tracing (an eager call's `plan.Plan`):
  nothing runs, or the `rerun` loop; "loop": the loop alone, its trip count data (zero
  turns when no robot needs it; no conditional); "cond": `rerun_if_any`.
  """
  if mode is False:
    return fast
  if mode == "cond":
    return rerun_if_any(need, fast, exact_fn, args, capacity)
  if mode is not True and mode != "loop":
    raise ValueError(f"rerun mode must be True, False, 'loop' or 'cond'; got {mode!r}")
  return rerun(need, fast, exact_fn, args, capacity)


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
    # The barrier ties the inputs to the turn: with B = 1 the slice below is the whole batch, so
    # without it the exact path is loop-invariant and XLA hoists it out of the loop, to run at
    # every call even when the loop turns zero times (a jitted call of one robot paid the exact
    # path's ~90 turns of its own inner loops: 400 vs 185 us on a 2-core CPU).
    inputs, k = jax.lax.optimization_barrier((args, k))
    if capacity == 1:   # in-place slices: a scatter would copy the whole batch each turn
      r = order[k]
      res = exact_fn(jax.tree.map(lambda a: jax.lax.dynamic_slice_in_dim(a, r, 1), inputs))
      return jax.tree.map(lambda o, x: jax.lax.dynamic_update_slice_in_dim(o, x, r, 0), out, res)
    sel = jax.lax.dynamic_slice(order, (k * capacity,), (capacity,))
    res = exact_fn(jax.tree.map(lambda a: a[sel], inputs))
    return jax.tree.map(lambda o, r: o.at[sel].set(r), out, res)

  return jax.lax.fori_loop(0, (count + capacity - 1) // capacity, body, fast)


def rerun_capacity(b):
  """How many robots one turn of `rerun` redoes in a fleet of b."""
  return min(b, max(8, b // 32))


def divisor_at_most(b, limit):
  """The largest divisor of b that is <= max(limit, 1): lax.map chunks without a remainder
  (a remainder chunk runs outside the loop, where XLA fuses it into the next pass)."""
  return max(d for d in range(1, min(b, max(limit, 1)) + 1) if b % d == 0)


def batched_inputs(costmap, mask, poses, mask_index, enabled, window, transform, where, state=None):
  """The public functions' inputs checked and batched: (idx, idx_ok, poses, enabled, window int32 [B, 4], transform).

  `where` names the caller in error messages. The window defaults to the whole map and is
  clipped to it like LayeredCostmap does. `state` (a KeepoutState; None skips the
  check) must hold the costmaps' B robots in every leaf.

  Raises:
    TypeError: state is not a KeepoutState (and the checks of `types.robot_inputs`).
    ValueError: a state leaf whose batch is not the costmaps' (naming both sizes), a
      window of the wrong shape or dtype, and the checks of `types.robot_inputs`.
  """
  check_costmap(costmap, where)
  b = costmap.num_robots
  h, w = costmap.cost.shape[1:]
  if state is not None:
    if not isinstance(state, KeepoutState):
      raise TypeError(f"{where}: state must be a KeepoutState (KeepoutState.create); got {type(state).__name__}")
    check_state_batch(state, b, f"costmaps have {b} (cost {list(costmap.cost.shape)})")
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


def check_batched_inputs(costmap, mask, poses, mask_index, enabled, window, transform, where, state):
  """`batched_inputs`' checks at an eager call's edge, with no device work (`types.check_robot_inputs`).

  Returns:
    (mask_index, enabled, window, transform): arrays (NumPy for Python values) or None,
    for a jitted body that runs `batched_inputs` on them.
  """
  check_costmap(costmap, where)
  b = costmap.num_robots
  h, w = costmap.cost.shape[1:]
  if not isinstance(state, KeepoutState):
    raise TypeError(f"{where}: state must be a KeepoutState (KeepoutState.create); got {type(state).__name__}")
  check_state_batch(state, b, f"costmaps have {b} (cost {list(costmap.cost.shape)})")
  _, mask_index, enabled, transform = check_robot_inputs(mask, poses, b, mask_index, enabled, transform)
  if window is not None:
    window = host_view(window)
    if tuple(window.shape) not in ((4,), (b, 4)) or not jnp.issubdtype(window.dtype, jnp.integer):
      raise ValueError(f"window must be integer (min_i, min_j, max_i, max_j) of shape (4,) or ({b}, 4); "
                       f"got {window.dtype}{tuple(window.shape)}")
  return mask_index, enabled, window, transform


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


def old_plus_one_u8(cost, unknown_overwrite: str):
  """c1 of the write rule `m1 > c1` for old costs (uint8, any shape): cost + 1, wrapping 255 to 0,
  except that with unknown_overwrite "inscribed" (`KeepoutConfig`) an unknown cell gives
  INSCRIBED_INFLATED_OBSTACLE (253), as an old 252 would: m1 > 253 iff the mask cost is >= 253."""
  c1 = cost + jnp.uint8(1)
  if unknown_overwrite == "inscribed":
    c1 = jnp.where(c1 == jnp.uint8(0), jnp.uint8(constants.INSCRIBED_INFLATED_OBSTACLE), c1)
  return c1


def m1_rule_u8(cost, m1, state, config: KeepoutConfig):
  """Nav2's write rule on (mask cost + 1) bytes m1 (0: unknown or not visited), uint8 [H, W]."""
  c1 = old_plus_one_u8(cost, config.unknown_overwrite)
  if config.override_lethal_cost:
    value = jnp.where(state.is_pose_lethal, jnp.uint8(config.lethal_override_cost), m1 - jnp.uint8(1))
    return jnp.where(m1 > c1, value, cost)
  if config.unknown_overwrite == "inscribed":
    return jnp.where(m1 > c1, m1 - jnp.uint8(1), cost)
  return jnp.maximum(c1, m1) - jnp.uint8(1)
