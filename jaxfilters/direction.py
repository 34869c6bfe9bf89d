"""Direction filter (docs/nav2_semantics.md §13): one-way lanes from a mask, per robot heading.

Not a Nav2 filter: Nav2 users have asked for directional lanes as masks
(navigation2 issues #1522, #3395, #5145), and Nav2 has none. The mask is a
plain Nav2 filter mask (map_server YAML + image, `FilterInfo` type 5,
`constants.DIRECTION_FILTER`, the next code Nav2 does not use) whose cell value
d says which way the cell may be driven:

* d = 0 (free) or d = -1 (unknown): no constraint;
* d >= 1: the lane's direction, `d * multiplier + base` degrees in the mask
  frame, counter-clockwise from +x (CostmapFilterInfo's conversion); with
  base -5 and multiplier 5, d = 1 is east, 19 north, 37 west, 55 south;
* d <= -2 (a raw-mode byte 128..254): not a direction; never written, and the
  robot that meets one gets `error` set.

A heading h is allowed on a cell of direction c when |wrap(h - c)| <=
`DirectionConfig.half_width` (a closed sector; default 90 degrees: anything
but against the lane), all in float32 radians. Per robot the filter

(a) writes LETHAL_OBSTACLE (254, whatever the cell held) into every costmap
    cell whose centre lies on a constrained mask cell that the robot's heading
    (its yaw) is not allowed on: each robot its own heading, so one batch
    blocks the lane for the robots facing against it only; and
(b) flags wrong-way motion: the robot's own mask cell is constrained and its
    direction of motion (its yaw, or with `velocities` the direction of its
    velocity; a speed at or below `min_speed` is not motion) is not allowed.

Cell geometry is the keepout filter's (docs/nav2_semantics.md §4.3): each
costmap cell centre is mapped to its mask cell by the exact floor on the host
doubles (`geometry.centres_to_cells_2d`), or, with a frame transform, rotated
as `keepout.reference.se2_axes_one` does; the heading is turned by the
transform's yaw. The whole costmap is visited (no update window).

Value problems are masked and flagged, never raised (also under `jit`): a
robot with a traced out-of-range `mask_index`, unusable mask or costmap
geometry (`types.mask_geometry_ok`), or a non-finite pose or velocity keeps
its costmap untouched, gets `wrong_way` False and `error` True. A mask whose
info type is not 5 changes nothing either (Nav2's filters log an error and
ignore a mask of another type) and sets `error`, so a keepout or speed mask
passed here by mistake is never silent. Static problems (shapes, dtypes, a
bad config) raise.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants, geometry
from jaxfilters.keepout.common import usable_geometry
from jaxfilters.keepout.reference import se2_axes_one, se2_grid
from jaxfilters.mask_lookup import mask_cell, mask_leaves, transform_point
from jaxfilters.types import (Costmap, FilterMask, check_costmap, check_robot_inputs, host_view, pytree_dataclass,
                              robot_inputs)
from jaxfilters.validate import short_repr

_F32 = jnp.float32
_PI = np.float32(np.pi)
_TWO_PI = np.float32(2.0 * np.pi)
_DEG = np.float32(np.pi / 180.0)


@dataclasses.dataclass(frozen=True)
class DirectionConfig:
  """Direction filter settings (static: one compile per value).

  Attributes:
    half_width_deg: degrees, half the allowed sector around a lane's direction,
      in (0, 180]. 90 (the default) allows every heading that is not against
      the lane; 180 allows every heading (the filter then writes nothing).
    min_speed: m/s, >= 0: with `velocities`, a robot at or below this speed is
      not moving and is never flagged wrong-way.
  """
  half_width_deg: float = 90.0
  min_speed: float = 0.0

  def __post_init__(self):
    for name in ("half_width_deg", "min_speed"):
      v = getattr(self, name)
      if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)):
        raise TypeError(f"DirectionConfig.{name} must be a number; got {short_repr(v)}")
      if not math.isfinite(float(v)):
        raise ValueError(f"DirectionConfig.{name} must be finite; got {short_repr(v)}")
      object.__setattr__(self, name, float(v))
    if not 0.0 < self.half_width_deg <= 180.0:
      raise ValueError(f"DirectionConfig.half_width_deg must lie in (0, 180] degrees; got {self.half_width_deg!r}")
    if np.float32(math.radians(self.half_width_deg)) < np.finfo(np.float32).tiny:
      raise ValueError(f"DirectionConfig.half_width_deg {self.half_width_deg!r} is 0 in float32 radians")
    if self.min_speed < 0.0 or np.isinf(np.float32(self.min_speed)):
      raise ValueError(f"DirectionConfig.min_speed must be >= 0 m/s and finite in float32; got {self.min_speed!r}")

  @property
  def half_width(self) -> np.float32:
    """The half-width in float32 radians, the value the sector test compares with."""
    return np.float32(math.radians(self.half_width_deg))


@pytree_dataclass
class DirectionResult:
  """One direction-filter call per robot.

  Attributes:
    wrong_way: bool [B], the robot's own mask cell is constrained and its
      direction of motion is not allowed on it.
    constrained: bool [B], the robot's own mask cell holds a direction (d >= 1).
    blocked_cells: int32 [B], costmap cells this call made lethal.
    error: bool [B], a value problem (see the module docstring): nothing was
      written for the robot, or (a mask value <= -2 met) those cells were not.
  """
  wrong_way: jax.Array
  constrained: jax.Array
  blocked_cells: jax.Array
  error: jax.Array


def lane_direction(d: jax.Array, info) -> tuple[jax.Array, jax.Array, jax.Array]:
  """A direction mask value's lane (docs/nav2_semantics.md §13.1).

  Args:
    d: int32 [...] raw mask values. info: FilterInfo with scalar leaves.

  Returns:
    (centre float32 [...] radians in [-pi, pi] (meaningless where not
    constrained), constrained bool [...]: d >= 1 on a type-5 mask with a
    finite direction, bad bool [...]: d <= -2, or a direction that is not
    finite in float32, on a type-5 mask).
  """
  typed = info.type == constants.DIRECTION_FILTER
  deg = geometry.rounded_product(d.astype(_F32), info.multiplier) + info.base
  finite = jnp.isfinite(deg)
  deg = jnp.where(finite, deg, 0.0)
  deg = jnp.remainder(deg + 180.0, 360.0) - 180.0
  centre = geometry.rounded_product(deg, jnp.asarray(_DEG))
  constrained = typed & (d >= 1) & finite
  bad = typed & ((d <= -2) | ((d >= 1) & ~finite))
  return centre, constrained, bad


def angle_off(heading: jax.Array, centre: jax.Array) -> jax.Array:
  """|heading - centre| wrapped into [0, pi] (float32 radians; centre in [-pi, pi]).

  The heading is first reduced by the nearest multiple of 2 pi (a heading in
  [-pi, pi] is kept as it is), then the difference is brought into [-pi, pi]
  by one turn.
  """
  h = heading - _TWO_PI * jnp.round(heading / _TWO_PI)
  delta = h - centre
  delta = jnp.where(delta > _PI, delta - _TWO_PI, jnp.where(delta < -_PI, delta + _TWO_PI, delta))
  return jnp.abs(delta)


def wrong_way_cells(d: jax.Array, info, heading: jax.Array, half_width) -> tuple[jax.Array, jax.Array, jax.Array]:
  """Nav2-style per-cell rule of the direction filter (docs/nav2_semantics.md §13.2).

  Args:
    d: int32 [...] raw mask values. info: FilterInfo with scalar leaves.
    heading: float32 [] or [...] heading in the mask frame (rad).
    half_width: float32 [] allowed half-width (rad).

  Returns:
    (wrong bool [...]: constrained and |wrap(heading - centre)| > half_width,
    constrained bool [...], bad bool [...]), as `lane_direction`.
  """
  centre, constrained, bad = lane_direction(d, info)
  return constrained & (angle_off(heading, centre) > half_width), constrained, bad


def direction_filter_one(cost, origin, res, data, mask_origin, mask_res, info, pose, velocity, enabled,
                         transform, *, config: DirectionConfig):
  """The direction filter for one robot (see the module docstring).

  Args:
    cost: uint8 [H, W] the robot's costmap; origin, res: its geometry as float32
      parts (`geometry.origin_terms`, `geometry.resolution_terms`).
    data: int8 [Hm, Wm] the mask; mask_origin: float32 [2] parts; mask_res: float32 [];
      info: FilterInfo with scalar leaves.
    pose: float32 [3] (x, y, yaw) in the costmap frame.
    velocity: float32 [2] (vx, vy) in the costmap frame, or None (motion along the yaw).
    enabled: bool [].
    transform: float32 [3] T_mask_from_global, or None (same frame).
    config: static DirectionConfig.

  Returns:
    (new cost uint8 [H, W], DirectionResult with scalar leaves).
  """
  h, w = cost.shape
  hm, wm = data.shape
  half = jnp.asarray(config.half_width, _F32)
  turn = jnp.float32(0.0) if transform is None else transform[2]
  heading = pose[2] + turn
  if transform is None:
    (mx, vx), (my, vy) = geometry.centres_to_cells_2d((h, w), origin, res, mask_origin, mask_res, (hm, wm))
    vals = data[my[:, None], mx[None, :]].astype(jnp.int32)
    on_mask = vy[:, None] & vx[None, :]
  else:
    px, py = se2_grid(se2_axes_one(origin, res, transform, h, w))
    mx, my, on_mask = geometry.world_to_cell(px, py, mask_origin, mask_res, wm, hm)
    vals = data[my, mx].astype(jnp.int32)
  wrong, _, bad = wrong_way_cells(vals, info, heading, half)

  xy = pose[:2] if transform is None else transform_point(transform, pose[:2])
  d_here, inside = mask_cell(data, mask_origin, mask_res, xy)
  if velocity is None:
    motion, moving, v_ok = heading, jnp.asarray(True), jnp.asarray(True)
  else:
    motion = jnp.arctan2(velocity[1], velocity[0]) + turn
    moving = jnp.hypot(velocity[0], velocity[1]) > config.min_speed
    v_ok = jnp.all(jnp.isfinite(velocity))
  wrong_here, constrained_here, bad_here = wrong_way_cells(d_here, info, motion, half)
  ok = enabled & jnp.all(jnp.isfinite(pose)) & v_ok
  write = ok & on_mask & wrong
  new_cost = jnp.where(write, jnp.uint8(constants.LETHAL_OBSTACLE), cost)
  blocked = jnp.sum(write & (cost != constants.LETHAL_OBSTACLE), dtype=jnp.int32)
  wrong_type = info.type != constants.DIRECTION_FILTER      # Nav2 logs an error and ignores such a mask
  error = (enabled & ~ok) | (ok & (wrong_type | jnp.any(on_mask & bad) | (inside & bad_here)))
  constrained_here = ok & inside & constrained_here
  return new_cost, DirectionResult(constrained_here & wrong_here & moving, constrained_here, blocked, error)


def direction_filter(costmap: Costmap, mask: FilterMask, poses, *, velocities=None, mask_index=None,
                     enabled=None, transform=None,
                     config: DirectionConfig = DirectionConfig()) -> tuple[Costmap, DirectionResult]:
  """One-way lanes over a fleet (docs/nav2_semantics.md §13). Jitted at the edge (config static).

  Args:
    costmap: Costmap [B] of the robots (each robot's own map).
    mask: FilterMask of type 5 (another type changes nothing and sets `error`); M = 1
      shared or a stack with `mask_index`.
    poses: float [B, 3] (x, y, yaw) in the costmap frame; the yaw is the
      heading the costmap is made for.
    velocities: optional float [B, 2] (vx, vy) m/s in the costmap frame: the
      wrong-way flag then follows the direction of motion (None: the yaw).
    mask_index: optional int [B], as `jaxfilters.speed_filter`.
    enabled: optional bool [B] or scalar; a disabled robot is untouched.
    transform: optional [B, 3] or [3] T_mask_from_global for a mask in another frame.
    config: static DirectionConfig.

  Returns:
    (Costmap with the wrong-way cells lethal, DirectionResult [B]).

  Raises:
    TypeError: costmap, mask or config of the wrong type.
    ValueError: shapes or dtypes that do not fit B (naming both), or (eager) a
      mask_index outside [0, M).
  """
  if not isinstance(config, DirectionConfig):
    raise TypeError(f"config must be a DirectionConfig; got {type(config).__name__}")
  check_costmap(costmap, "direction_filter")
  b = costmap.num_robots
  # The checks here, in Python; the conversions in the program (no eager device operation).
  poses, mask_index, enabled, transform = check_robot_inputs(mask, poses, b, mask_index, enabled, transform)
  if velocities is not None:
    v = host_view(velocities)
    if tuple(v.shape) != (b, 2) or not jnp.issubdtype(v.dtype, jnp.floating):
      raise ValueError(f"velocities must be float [B, 2] = ({b}, 2) (vx, vy m/s); got {v.dtype}{tuple(v.shape)}")
  return _direction_jit(costmap, mask, poses, velocities, mask_index, enabled, transform, config=config)


@functools.partial(jax.jit, static_argnames=("config",))
def _direction_jit(costmap, mask, poses, velocities, mask_index, enabled, transform, *, config):
  b = costmap.num_robots
  idx, idx_ok, poses, enabled, transform = robot_inputs(mask, poses, b, mask_index, enabled, transform)
  with jax.named_scope("direction_filter"):
    safe_cm, safe_mask, ok = usable_geometry(costmap, mask, idx, idx_ok)
    vel = None if velocities is None else jnp.asarray(velocities, _F32)

    def one(cost, o, o_lo, r, r_lo, i, good, pose, v, en, tf):
      data, m_origin, m_res, info = mask_leaves(safe_mask, i)
      new, out = direction_filter_one(cost, geometry.origin_terms(o, o_lo), geometry.resolution_terms(r, r_lo),
                                      data, m_origin, m_res, info, pose, v, en & good, tf, config=config)
      return new, dataclasses.replace(out, error=out.error | ~good)

    geo = (safe_cm.origin, safe_cm.origin_lo, safe_cm.resolution, safe_cm.resolution_lo)
    axes = (0, *(None if g is None else 0 for g in geo), 0, 0, 0, None if vel is None else 0, 0,
            None if transform is None else 0)
    cost, out = jax.vmap(one, in_axes=axes)(costmap.cost, *geo, idx, ok, poses, vel, enabled, transform)
    return dataclasses.replace(costmap, cost=cost), out
