"""`keepout_update_bounds`: Nav2's KeepoutFilter::updateBounds over a fleet (docs/nav2_semantics.md §4.2).

It grows the update window when a new mask arrives (with Nav2's quirk of using the
master grid's origin and resolution with the mask's cell counts) and runs the
robot-in-zone test of the escape mode (`override_lethal_cost`), growing an accumulated
box while the robot is inside a zone and one cycle after.

Beyond Nav2 (an option; Nav2's centre-cell test stays the default):
`KeepoutConfig(robot_in_zone="footprint")` decides escape mode over the robot's
footprint, with hysteresis (Nav2 issue #6505, PR #6526; the rule is in
jaxfilters/footprint.py). Only updateBounds changes: process() writes as Nav2.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from jaxfilters import footprint as footprint_lib
from jaxfilters import geometry
from jaxfilters.keepout.common import batched_inputs, fill_error, usable_geometry, with_error
from jaxfilters.keepout.config import EMPTY_BOX, KeepoutConfig, KeepoutState, occ_to_cost
from jaxfilters.mask_lookup import mask_cell
from jaxfilters.types import Costmap, FilterMask, per_robot_bool

_F32 = jnp.float32


def pose_in_lethal_zone_one(data, mask_origin, mask_res, xy, mask_origin_lo=None):
  """Nav2's robot-in-keepout test (docs/nav2_semantics.md §4.2): the point's mask cell costs 253 or 254.

  The cell is the one every mask reader uses (`mask_lookup.mask_cell`, the exact
  float64 origin parts).

  Unknown mask cells (cost 255, data -1) are not lethal: a robot standing on
  one does not switch escape mode on.

  Args:
    data: int8 [Hm, Wm]; mask_origin float32 [2]; mask_res float32 [].
    xy: float32 [2] point in the mask frame.
    mask_origin_lo: optional float32 [2, 2] parts of a float64 mask origin.

  Returns:
    bool []: False off the mask.
  """
  d, inside = mask_cell(data, geometry.origin_terms(mask_origin, mask_origin_lo), mask_res, xy)
  cost = occ_to_cost(d)
  return inside & (cost >= constants.INSCRIBED_INFLATED_OBSTACLE) & (cost <= constants.LETHAL_OBSTACLE)


def keepout_update_bounds_one(state, data, mask_origin, mask_res, pose, bounds,
                              master_origin, master_res, new_mask, enabled, transform,
                              *, override_lethal_cost: bool, mask_origin_lo=None, index_ok=True,
                              config: KeepoutConfig | None = None):
  """KeepoutFilter::updateBounds for one robot (docs/nav2_semantics.md §4.2).

  Args:
    state: KeepoutState of one robot (scalar leaves, acc_box [4]).
    data: int8 [Hm, Wm] this robot's mask.
    mask_origin, mask_res: float32 [2], [].
    pose: float32 [3], robot (x, y, yaw) in the costmap's global frame.
    bounds: float32 [4] world (min_x, min_y, max_x, max_y) so far this cycle.
    master_origin, master_res: the costmap's geometry ([2], []).
    new_mask: bool [], a new mask arrived since the last cycle.
    enabled: bool [].
    transform: float32 [3] T_mask_from_global or None (same frame).
    override_lethal_cost: static, escape mode.
    mask_origin_lo: optional float32 [2, 2] parts of a float64 mask origin.
    index_ok: bool [], this robot's mask_index is in range (else nothing runs
      and `error` is set).
    config: static KeepoutConfig whose `robot_in_zone` "footprint" (with
      override_lethal_cost) replaces the centre test by the footprint test of
      jaxfilters/footprint.py: the centre test OR a covered lethal cell, the
      footprint grown by `escape_clearance` while `state.is_pose_lethal` was
      True. `error` is then also set where the mask is finer than
      `min_mask_resolution` (the window read is still tested). None: Nav2's test.

  Returns:
    (new state, new bounds).
  """
  hm, wm = data.shape
  # New mask: grow to the master-grid centres of (0, 0) and (Wm, Hm) (Nav2 quirk) and return.
  lo = master_origin + 0.5 * master_res
  hi = master_origin + (jnp.asarray([wm, hm], _F32) + 0.5) * master_res
  grown = jnp.concatenate([jnp.minimum(bounds[:2], lo), jnp.maximum(bounds[2:], hi)])

  xy = pose[:2]
  if transform is not None:
    xy = jnp.stack(geometry.transform_points(transform, xy[0], xy[1]))
  lethal = jnp.asarray(False)
  window_bad = jnp.asarray(False)
  if override_lethal_cost:
    lethal = pose_in_lethal_zone_one(data, mask_origin, mask_res, xy, mask_origin_lo)
    if config is not None and config.robot_in_zone == "footprint":
      yaw = pose[2] if transform is None else pose[2] + transform[2]
      margin = jnp.where(state.is_pose_lethal, jnp.float32(config.escape_clearance), jnp.float32(0.0))
      lethal = lethal | footprint_lib.footprint_in_zone_one(
          data, mask_origin, mask_res, jnp.stack([xy[0], xy[1], yaw]), polygon=config.footprint,
          radius=config.robot_radius, window=config.footprint_window, margin=margin,
          mask_origin_lo=mask_origin_lo)
      window_bad = ~footprint_lib.window_fits(mask_res, config.min_mask_resolution)
  keep_box = override_lethal_cost & (lethal | state.last_pose_lethal)
  union = jnp.concatenate([jnp.minimum(state.acc_box[:2], bounds[:2]),
                           jnp.maximum(state.acc_box[2:], bounds[2:])])
  acc = jnp.where(keep_box, union, jnp.asarray(EMPTY_BOX, _F32))
  normal_state = dataclasses.replace(state, is_pose_lethal=lethal, acc_box=acc)
  normal_bounds = jnp.where(keep_box, union, bounds)

  pick = lambda a, b: jax.tree.map(lambda x, y: jnp.where(new_mask, x, y), a, b)
  out_state = pick(state, normal_state)
  out_bounds = jnp.where(new_mask, grown, normal_bounds)
  run = enabled & index_ok
  out_state = jax.tree.map(lambda x, y: jnp.where(run, x, y), out_state, state)
  out_state = with_error(out_state, ~index_ok | (run & ~new_mask & window_bad))
  return out_state, jnp.where(run, out_bounds, bounds)


def keepout_update_bounds(costmap: Costmap, mask: FilterMask, poses, state: KeepoutState,
                          bounds, *, new_mask=None, mask_index=None, enabled=None,
                          transform=None, config: KeepoutConfig = KeepoutConfig()):
  """Nav2 KeepoutFilter::updateBounds over a fleet (docs/nav2_semantics.md §4.2).

  Jitted at the edge like `keepout_filter`.

  Args:
    costmap: the costmap whose geometry (origin, resolution) the bounds use.
    mask, poses, state, mask_index, enabled, transform, config: as keepout_filter.
    bounds: float [B, 4] world (min_x, min_y, max_x, max_y) grown by the layers
      this cycle (Nav2 starts from (+inf, +inf, -inf, -inf)).
    new_mask: optional bool [B] or scalar, a new mask arrived since last cycle.

  Returns:
    (new KeepoutState, new bounds float32 [B, 4]). `KeepoutState.error` [B] is
    True, as in keepout_filter, for a robot with a traced mask_index outside
    [0, M) or an unusable traced mask or costmap geometry; that robot's state
    and bounds are returned unchanged. With `config.robot_in_zone == "footprint"`,
    `is_pose_lethal` comes from the footprint test (jaxfilters/footprint.py) and
    `error` is also set for a robot whose mask is finer than
    `config.min_mask_resolution` (traced masks; a concrete one raises).

  Raises:
    TypeError / ValueError: as keepout_filter (a state, poses or per-robot array
      whose batch is not the costmaps' B included); bounds not [B, 4]; a concrete
      mask finer than `config.min_mask_resolution` in "footprint" mode.
  """
  if not isinstance(config, KeepoutConfig):
    raise TypeError(f"config must be a KeepoutConfig; got {type(config).__name__}")
  b = costmap.num_robots
  idx, idx_ok, poses, enabled, _, transform = batched_inputs(
      costmap, mask, poses, mask_index, enabled, None, transform, "keepout_update_bounds", state)
  bounds = jnp.asarray(bounds, _F32)
  if bounds.shape != (b, 4):
    raise ValueError(f"bounds must be float [B, 4] = ({b}, 4); got {tuple(bounds.shape)}")
  new_mask = per_robot_bool("new_mask", new_mask, b, default=False)
  state = fill_error(state, b)
  _check_footprint_window(mask, config)
  footprint = config if config.robot_in_zone == "footprint" else None
  return _update_bounds_jit(costmap, mask, idx, idx_ok, poses, state, bounds, new_mask, enabled, transform,
                            override_lethal_cost=config.override_lethal_cost, footprint=footprint)


def _check_footprint_window(mask: FilterMask, config: KeepoutConfig) -> None:
  """Eagerly: a concrete mask finer than `min_mask_resolution` raises (under jit: `error`)."""
  if config.robot_in_zone != "footprint" or isinstance(mask.resolution, jax.core.Tracer):
    return
  res = np.asarray(mask.resolution, np.float32)
  if np.any(res < np.float32(config.min_mask_resolution)):
    raise ValueError(f"keepout_update_bounds: mask resolution {float(res.min()):g} m is finer than "
                     f"KeepoutConfig.min_mask_resolution = {config.min_mask_resolution:g} m, which sizes the "
                     "footprint test's window; build the config with min_mask_resolution <= the finest mask")


@functools.partial(jax.jit, static_argnames=("override_lethal_cost", "footprint"))
def _update_bounds_jit(costmap, mask, idx, idx_ok, poses, state, bounds, new_mask, enabled, transform, *,
                       override_lethal_cost, footprint=None):
  with jax.named_scope("keepout_update_bounds"):
    costmap, mask, idx_ok = usable_geometry(costmap, mask, idx, idx_ok)

    def one(st, i, ok, pose, bnd, origin, res, nm, en, tf):
      return keepout_update_bounds_one(
          st, mask.data[i], mask.origin[i], mask.resolution[i], pose, bnd, origin, res, nm, en, tf,
          override_lethal_cost=override_lethal_cost,
          mask_origin_lo=None if mask.origin_lo is None else mask.origin_lo[i], index_ok=ok, config=footprint)

    tf_axis = None if transform is None else 0
    return jax.vmap(one, in_axes=(0, 0, 0, 0, 0, 0, 0, 0, 0, tf_axis))(
        state, idx, idx_ok, poses, bounds, costmap.origin, costmap.resolution, new_mask, enabled, transform)
