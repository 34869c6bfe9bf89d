"""SpeedFilter (docs/nav2_semantics.md §5): the speed limit under each robot, as carried state.

Nav2 publishes a `SpeedLimit` only when the limit changes, keeps the previous
limit on unknown or off-mask cells, and uses 0.0 for "no limit". Here that is
explicit state in, new state plus a per-robot `changed` flag out:

    state = SpeedState.create(num_robots)
    state, out = speed_filter(mask, poses, state)
    # out.speed_limit [B]: the limit in force; out.changed [B]: Nav2 would publish.

Range checks (percent outside [0, 100], absolute < 0 -> 0.0) are decided
exactly on `d * multiplier + base` (error-free arithmetic), as Nav2 does in
float64; the limit value itself is the float32 rounding of that double, so
|limit - Nav2's double| <= 2**-24 * |Nav2's double| (6e-6 at 100 %: the bound
documented in README.md's float policy).

Public functions are jitted at the edge (inline inside a caller's `jit`). A
robot whose traced `mask_index` is outside [0, M), or whose mask has traced
geometry that is unusable (`types.mask_geometry_ok`), gets `valid` False,
`error` True and its state untouched (eager calls raise for a bad index).
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from jaxfilters import geometry
from jaxfilters.mask_lookup import mask_cell, mask_leaves, transform_point
from jaxfilters.types import (FilterInfo, FilterMask, check_robot_inputs, mask_geometry_ok, per_robot_bool,
                              pytree_dataclass, robot_inputs)

_F32 = jnp.float32


@pytree_dataclass
class SpeedState:
  """Per-robot SpeedFilter state.

  Attributes:
    speed_limit_prev: float32 [B], the last published limit (Nav2 starts at 0.0
      and never resets it).
    path_start: int32 [B], cached closest-segment index for path lookahead.
    held_lookahead: float32 [B], lookahead distance held while decelerating.
    path_dropped: bool [B], a reset dropped the held path
      (`LookaheadConfig.clear_path_on_reset`): the path passed in is ignored
      until `new_path` says a new one arrived. Always False otherwise.
  """
  speed_limit_prev: jax.Array
  path_start: jax.Array
  held_lookahead: jax.Array
  path_dropped: jax.Array

  @classmethod
  def create(cls, num_robots: int) -> "SpeedState":
    """Nav2's state before the first cycle: last published limit 0.0 (no limit), no path cached."""
    return cls(jnp.zeros((num_robots,), _F32), jnp.zeros((num_robots,), jnp.int32),
               jnp.zeros((num_robots,), _F32), jnp.zeros((num_robots,), jnp.bool_))


@pytree_dataclass
class SpeedResult:
  """What one SpeedFilter cycle says, per robot.

  Attributes:
    speed_limit: float32 [B], the limit in force after this cycle (0.0 = no limit).
    percentage: bool [B], True for percent of max speed, False for m/s.
    changed: bool [B], Nav2 would publish a SpeedLimit this cycle.
    valid: bool [B], a limit was computed this cycle (False off-mask, on an
      unknown cell, for a mask whose type is not 1 or 2, when disabled, or
      on an error).
    error: bool [B], the robot's traced mask_index was outside [0, M), its
      mask's traced geometry is unusable (`types.mask_geometry_ok`: a
      resolution that is not a normal float32 > 0, a non-finite origin) or,
      with lookahead, its traced path length was outside [0, N]: nothing was
      computed and its state was kept. None only in a hand-built result.
  """
  speed_limit: jax.Array
  percentage: jax.Array
  changed: jax.Array
  valid: jax.Array
  error: jax.Array | None = None


@dataclasses.dataclass(frozen=True)
class LookaheadConfig:
  """SpeedFilter path lookahead parameters (docs/nav2_semantics.md §5.6), with Nav2's corrections.

  The defaults of `max_path_rewind` and `clear_path_on_reset` are Nav2 main's
  behaviour (a forward-only cached index, the path kept over a reset); the
  other values are Nav2 PR #6522's fixes (docs/nav2_semantics.md §5.7).

  Attributes:
    max_decel: m/s^2, must be negative to scale the distance with speed; a
      value >= 0 makes the lookahead distance `max_lookahead` (Nav2 WARNs).
    min_lookahead: m, clamped to >= 0.
    max_lookahead: m, raised to min_lookahead if smaller.
    max_path_rewind: m of path, finite and >= 0. 0 (Nav2 main): the cached
      start index only moves forward. > 0: each cycle the closest-segment
      search also covers the segments that start at most this far back along
      the path from the cached start, so the index follows a robot that
      reverses; a segment behind wins only if it is strictly closer.
    clear_path_on_reset: a reset (`reset=` of `speed_filter_lookahead`) also
      drops the held path, so the filter uses the plain rule at the robot pose
      until a new path arrives. False (Nav2 main): the path is kept.
  """
  max_decel: float = -0.5
  min_lookahead: float = 0.3
  max_lookahead: float = 5.0
  max_path_rewind: float = 0.0
  clear_path_on_reset: bool = False

  def __post_init__(self):
    for name in ("max_decel", "min_lookahead", "max_lookahead", "max_path_rewind"):
      if not np.isfinite(float(getattr(self, name))):
        raise ValueError(f"LookaheadConfig.{name} must be finite; got {getattr(self, name)!r}")
    rewind = float(self.max_path_rewind)
    with np.errstate(over="ignore", under="ignore"):
      rewind32 = np.float32(rewind)
    if rewind < 0 or (rewind > 0 and not (np.finfo(np.float32).tiny <= rewind32 < np.inf)):
      raise ValueError(f"LookaheadConfig.max_path_rewind must be 0 (forward only, as Nav2 main) or a normal "
                       f"float32 > 0 (metres of path the start index may move back per cycle); got {rewind!r}")
    if not isinstance(self.clear_path_on_reset, (bool, np.bool_)):
      raise TypeError(f"LookaheadConfig.clear_path_on_reset must be a bool; got "
                      f"{type(self.clear_path_on_reset).__name__}")
    object.__setattr__(self, "clear_path_on_reset", bool(self.clear_path_on_reset))
    object.__setattr__(self, "min_lookahead", max(0.0, float(self.min_lookahead)))
    object.__setattr__(self, "max_lookahead", max(float(self.max_lookahead), self.min_lookahead))


def speed_limit_value(d: jax.Array, info: FilterInfo) -> tuple[jax.Array, jax.Array]:
  """Nav2's SpeedFilter rule for one mask value (docs/nav2_semantics.md §5.3).

  Args:
    d: int32 [] the raw mask value. info: FilterInfo with scalar leaves.

  Returns:
    (limit float32 [], Nav2's value for the cell: 0.0 for mask value 0 and for a
    computed limit out of range (< 0, or > 100 in percent), else
    `d * multiplier + base` rounded to float32; known bool [], False on an
    unknown cell (-1) or when the info type is neither 1 (percent) nor 2 (m/s):
    Nav2 then has no limit to apply).
  """
  percent = info.type == constants.SPEED_FILTER_PERCENT
  typed = percent | (info.type == constants.SPEED_FILTER_ABSOLUTE)
  raw = d.astype(_F32) * info.multiplier + info.base
  below_zero = geometry.exact_sign_affine(d, info.multiplier, info.base, 0.0) < 0
  above_100 = geometry.exact_sign_affine(d, info.multiplier, info.base, 100.0) > 0
  out_of_range = below_zero | (percent & above_100)
  limit = jnp.where((d == constants.SPEED_MASK_NO_LIMIT) | out_of_range, 0.0, raw)
  return limit.astype(_F32), typed & (d != constants.SPEED_MASK_UNKNOWN)


def speed_limit_at_one(data, mask_origin, mask_res, info: FilterInfo, xy):
  """SpeedFilter::getSpeedLimitAtPose for one point (docs/nav2_semantics.md §5.3).

  Args:
    data: int8 [Hm, Wm] the mask.
    mask_origin: float32 [2], or a list of [2] parts whose exact sum is the host
      origin (`mask_lookup.mask_leaves` gives them); mask_res: float32 [].
    info: FilterInfo with scalar leaves.
    xy: float32 [2] point in the mask frame.

  Returns:
    (limit float32 [], valid bool []). Invalid off the mask, on d == -1, or when
    the info type is neither 1 (percent) nor 2 (absolute): Nav2 then has no mask.
  """
  d, inside = mask_cell(data, mask_origin, mask_res, xy)
  limit, known = speed_limit_value(d, info)
  return limit, inside & known


def _publish_step(prev, limit, valid, enabled):
  """Publish-on-change with keep-previous on invalid cycles (docs/nav2_semantics.md §5.4)."""
  ok = valid & enabled
  changed = ok & (limit != prev)
  new_prev = jnp.where(ok, limit, prev)
  return new_prev, changed, ok


def speed_filter_one(state, data, mask_origin, mask_res, info, pose, enabled, transform):
  """SpeedFilter::process at the robot pose for one robot.

  Args:
    state: SpeedState of one robot (scalar leaves).
    data, mask_origin, mask_res, info: this robot's mask.
    pose: float32 [3] robot pose in the costmap frame.
    enabled: bool [].
    transform: float32 [3] T_mask_from_global or None (same frame).

  Returns:
    (new state, SpeedResult with scalar leaves).
  """
  xy = pose[:2]
  if transform is not None:
    xy = transform_point(transform, xy)
  limit, valid = speed_limit_at_one(data, mask_origin, mask_res, info, xy)
  prev, changed, ok = _publish_step(state.speed_limit_prev, limit, valid, enabled)
  out = SpeedResult(prev, info.type == constants.SPEED_FILTER_PERCENT, changed, ok, jnp.asarray(False))
  return dataclasses.replace(state, speed_limit_prev=prev), out


def _segment_distance(p, a, b):
  ab = b - a
  denom = jnp.sum(ab * ab)
  t = jnp.where(denom > 0, jnp.clip(jnp.sum((p - a) * ab) / jnp.where(denom > 0, denom, 1.0), 0.0, 1.0), 0.0)
  return jnp.linalg.norm(p - (a + t * ab))


def speed_lookahead_one(state, data, mask_origin, mask_res, info, pose, path, path_len, new_path,
                        velocity, enabled, transform=None, reset=None, *, config: LookaheadConfig):
  """SpeedFilter::process with path lookahead for one robot (docs/nav2_semantics.md §5.6-§5.7).

  Args:
    state: SpeedState of one robot.
    data, mask_origin, mask_res, info: this robot's mask (same frame as the path).
    pose: float32 [3] robot pose.
    path: float32 [N, 2] path poses (x, y); only the first `path_len` are used.
    path_len: int32 [], number of valid path poses (0 = no path: plain filter).
    new_path: bool [], a new path arrived (resets the cached start index).
    velocity: float32 [], smoothed |linear x| speed (m/s).
    enabled: bool [].
    transform: float32 [3] T_mask_from_global or None: the pose and the path
      are in the costmap frame and are moved into the mask frame for lookups
      (distances are frame-independent under SE2).
    reset: bool [] or None (no reset): the filter was reset before this cycle
      (Nav2 `CostmapFilter::reset`): the cached start index and the held
      lookahead distance return to 0, and with `config.clear_path_on_reset`
      the held path is dropped until `new_path`.
    config: static LookaheadConfig.

  Returns:
    (new state, SpeedResult with scalar leaves).
  """
  if transform is not None:
    pose = jnp.concatenate([transform_point(transform, pose[:2]), pose[2:]])
    path = jnp.stack(geometry.transform_points(transform, path[:, 0], path[:, 1]), axis=-1)
  n = path.shape[0]
  v = jnp.abs(velocity)
  cached, held_before, dropped = state.path_start, state.held_lookahead, state.path_dropped
  if reset is not None:                 # initializeFilter: start index and held distance back to 0
    cached = jnp.where(reset, 0, cached)
    held_before = jnp.where(reset, 0.0, held_before)
    if config.clear_path_on_reset:
      dropped = dropped | reset
  dropped = dropped & ~new_path         # a path that arrives after the reset is held again
  path_len = jnp.where(dropped, 0, path_len)
  if config.max_decel < 0:
    dist = jnp.clip(v * v / (2.0 * abs(config.max_decel)), config.min_lookahead, config.max_lookahead)
    dist = jnp.maximum(dist, held_before)
  else:
    dist = jnp.asarray(config.max_lookahead, _F32)
  start = jnp.where(new_path | (cached >= path_len), 0, cached)
  # Closest segment [i, i+1] from the cached start (first minimum wins).
  seg = jnp.arange(n, dtype=jnp.int32)
  seg_dist = jax.vmap(lambda a, b: _segment_distance(pose[:2], a, b))(path, jnp.roll(path, -1, axis=0))
  seg_ok = (seg >= start) & (seg < path_len - 1)
  ahead = jnp.where(seg_ok, seg_dist, jnp.inf)
  if config.max_path_rewind == 0:
    start = jnp.where(jnp.any(seg_ok), jnp.argmin(ahead).astype(jnp.int32), start)
  else:
    # Segments behind the cached start whose first pose lies at most max_path_rewind back along
    # the path; one of them wins only if strictly closer than every segment from the start on.
    seg_len = jnp.where(seg < path_len - 1, jnp.linalg.norm(jnp.roll(path, -1, axis=0) - path, axis=1), 0.0)
    to_pose = jnp.cumsum(seg_len) - seg_len       # path length from pose 0 to pose i
    back_ok = (seg < start) & (seg < path_len - 1) & (to_pose[start] - to_pose <= config.max_path_rewind)
    behind = jnp.where(back_ok, seg_dist, jnp.inf)
    i_ahead, i_behind = jnp.argmin(ahead).astype(jnp.int32), jnp.argmin(behind).astype(jnp.int32)
    best = jnp.where(behind[i_behind] < ahead[i_ahead], i_behind, i_ahead)
    start = jnp.where(jnp.any(seg_ok) | jnp.any(back_ok), best, start)
  start = jnp.where(path_len <= 1, 0, start)

  robot_limit, robot_valid = speed_limit_at_one(data, mask_origin, mask_res, info, pose[:2])
  step = jnp.linalg.norm(jnp.roll(path, -1, axis=0) - path, axis=1)
  step = jnp.where((seg >= start) & (seg < path_len - 1), step, 0.0)
  travelled = jnp.cumsum(step) - step            # distance from start to pose i
  sampled = (seg >= start) & (seg < path_len) & (travelled <= dist)
  limits, valids = jax.vmap(lambda xy: speed_limit_at_one(data, mask_origin, mask_res, info, xy))(path)
  use = sampled & valids & (limits != 0)
  strictest = jnp.min(jnp.where(use, limits, jnp.inf))
  strictest = jnp.minimum(strictest, jnp.where(robot_limit != 0, robot_limit, jnp.inf))
  limit = jnp.where(jnp.isinf(strictest), 0.0, strictest)
  held = jnp.where(robot_valid & (robot_limit != limit), dist, 0.0)

  has_path = path_len > 0
  limit = jnp.where(has_path, limit, robot_limit)
  prev, changed, ok = _publish_step(state.speed_limit_prev, limit, robot_valid, enabled)
  new_state = SpeedState(prev, jnp.where(has_path, start, cached),
                         jnp.where(enabled & has_path, held, held_before), dropped)
  out = SpeedResult(prev, info.type == constants.SPEED_FILTER_PERCENT, changed, ok, jnp.asarray(False))
  return new_state, out


def speed_inputs(mask, poses, state, mask_index, enabled, transform):
  """Validates the speed filters' inputs: (B, then `types.robot_inputs`' tuple)."""
  if not isinstance(state, SpeedState):
    raise TypeError(f"state must be a SpeedState (SpeedState.create); got {type(state).__name__}")
  b = state.speed_limit_prev.shape[0]
  return (b, *robot_inputs(mask, poses, b, mask_index, enabled, transform, state=state))


def guard_index(new_state, out, state, ok):
  """Keeps a robot's state and marks its result invalid + error where `ok` is False (bool []).

  `ok` is False for a bad mask index or unusable mask geometry (value problems under jit).
  """
  kept = jax.tree.map(lambda a, b: jnp.where(ok, a, b), new_state, state)
  out = dataclasses.replace(out, valid=out.valid & ok, error=~ok)
  if hasattr(out, "changed"):
    out = dataclasses.replace(out, changed=out.changed & ok)
  if hasattr(out, "speed_limit"):          # the limit in force is the kept one
    out = dataclasses.replace(out, speed_limit=jnp.where(ok, out.speed_limit, state.speed_limit_prev))
  return kept, out


def speed_filter(mask: FilterMask, poses, state: SpeedState, *, mask_index=None, enabled=None,
                 transform=None) -> tuple[SpeedState, SpeedResult]:
  """Nav2 SpeedFilter over a fleet, at each robot's pose (docs/nav2_semantics.md §5.3-§5.4).

  Jitted at the edge: an eager call compiles once per shape and runs with
  memory independent of B beyond the outputs; inside a caller's `jit` it inlines.

  Args:
    mask: FilterMask of type 1 (percent) or 2 (m/s); M = 1 shared or a stack.
    poses: float [B, 3] robot (x, y, yaw).
    state: SpeedState [B].
    mask_index: optional int [B], which mask each robot uses (concrete values
      outside [0, M) raise; traced ones give valid False and error True).
    enabled: optional bool [B] or scalar; a disabled robot publishes nothing.
    transform: optional [B, 3] or [3] T_mask_from_global for a mask in another frame.

  Returns:
    (new SpeedState, SpeedResult [B]).
  """
  if not isinstance(state, SpeedState):
    raise TypeError(f"state must be a SpeedState (SpeedState.create); got {type(state).__name__}")
  # The checks here, in Python; the conversions in the program (no eager device operation).
  inputs = check_robot_inputs(mask, poses, state.speed_limit_prev.shape[0], mask_index, enabled, transform,
                              state=state)
  return _speed_filter_jit(mask, state, *inputs)


@jax.jit
def _speed_filter_jit(mask, state, poses, mask_index, enabled, transform):
  _, idx, idx_ok, poses, enabled, transform = speed_inputs(mask, poses, state, mask_index, enabled, transform)
  with jax.named_scope("speed_filter"):
    idx_ok = idx_ok & mask_geometry_ok(mask)[idx]

    def one(st, i, ok, pose, en, tf):
      new, out = speed_filter_one(st, *mask_leaves(mask, i), pose, en, tf)
      return guard_index(new, out, st, ok)

    return jax.vmap(one, in_axes=(0, 0, 0, 0, 0, None if transform is None else 0))(
        state, idx, idx_ok, poses, enabled, transform)


def speed_filter_lookahead(mask: FilterMask, poses, state: SpeedState, paths, path_lengths,
                           velocities, *, new_path=None, reset=None, mask_index=None, enabled=None,
                           transform=None,
                           config: LookaheadConfig = LookaheadConfig()) -> tuple[SpeedState, SpeedResult]:
  """Nav2 SpeedFilter with `enable_path_lookahead` over a fleet (docs/nav2_semantics.md §5.6-§5.7).

  The strictest (smallest non-zero) limit along each robot's path within the
  lookahead distance is published; robots with path_lengths 0 use the plain
  filter. Pass the path the filter holds (the last one received) every cycle,
  with `new_path` True on the cycle it arrives. Jitted at the edge (config
  static). `config.max_path_rewind` and `config.clear_path_on_reset` select
  Nav2 PR #6522's fixes; their defaults are Nav2 main's behaviour.

  Args:
    mask, poses, state, mask_index, enabled: as speed_filter.
    paths: float [B, N, 2] path positions, in the same frame as the poses.
    path_lengths: int [B], valid poses per path, each in [0, N].
    velocities: float [B], smoothed odometry linear speed (m/s).
    new_path: optional bool [B] or scalar, a new path arrived this cycle.
    reset: optional bool [B] or scalar, the filter was reset since the last
      cycle (Nav2 `CostmapFilter::reset`, e.g. a costmap clear): the cached
      start index and the held lookahead distance return to 0; with
      `config.clear_path_on_reset` the held path is also dropped, and the
      robot uses the plain filter until a cycle with `new_path` True (a path
      arriving in the reset's cycle is held). None: no reset.
    transform: optional [B, 3] or [3] T_mask_from_global: poses and paths are
      in the costmap frame, the mask in another (as speed_filter).
    config: static LookaheadConfig.

  Returns:
    (new SpeedState, SpeedResult [B]).

  Raises:
    ValueError: wrong shapes or dtypes, or (concrete) path_lengths outside [0, N].
  """
  if not isinstance(config, LookaheadConfig):
    raise TypeError(f"config must be a LookaheadConfig; got {type(config).__name__}")
  b, idx, idx_ok, poses, enabled, transform = speed_inputs(mask, poses, state, mask_index, enabled, transform)
  paths = jnp.asarray(paths)
  if paths.ndim != 3 or paths.shape[0] != b or paths.shape[2] != 2 or not jnp.issubdtype(paths.dtype, jnp.floating):
    raise ValueError(f"paths must be float [B, N, 2] with B = {b}; got {paths.dtype}{tuple(paths.shape)}")
  paths = paths.astype(_F32)
  lengths = jnp.asarray(path_lengths)
  if lengths.shape != (b,) or not jnp.issubdtype(lengths.dtype, jnp.integer):
    raise ValueError(f"path_lengths must be int [B] = ({b},); got {lengths.dtype}{tuple(lengths.shape)}")
  if not isinstance(lengths, jax.core.Tracer):
    host = np.asarray(lengths)
    bad = np.nonzero((host < 0) | (host > paths.shape[1]))[0]
    if bad.size:
      raise ValueError(f"path_lengths must lie in [0, N = {paths.shape[1]}]; robots {bad[:8].tolist()} "
                       f"have {host[bad[:8]].tolist()}")
  vel = jnp.asarray(velocities, _F32)
  if vel.shape != (b,):
    raise ValueError(f"velocities must be float [B] = ({b},); got {tuple(vel.shape)}")
  new_path = per_robot_bool("new_path", new_path, b, default=False)
  reset = None if reset is None else per_robot_bool("reset", reset, b, default=False)
  return _lookahead_jit(mask, poses, state, paths, lengths.astype(jnp.int32), vel, new_path, reset, idx, idx_ok,
                        enabled, transform, config=config)


@functools.partial(jax.jit, static_argnames=("config",))
def _lookahead_jit(mask, poses, state, paths, lengths, vel, new_path, reset, idx, idx_ok, enabled, transform,
                   *, config):
  with jax.named_scope("speed_filter_lookahead"):
    # Traced lengths outside [0, N] are a value problem: such a robot is flagged, not clipped.
    len_ok = (lengths >= 0) & (lengths <= paths.shape[1])
    idx_ok = idx_ok & mask_geometry_ok(mask)[idx]

    def one(st, i, ok, pose, path, n, npth, v, en, tf, rs):
      new, out = speed_lookahead_one(st, *mask_leaves(mask, i), pose, path, jnp.where(ok, n, 0), npth, v,
                                     en, tf, rs, config=config)
      return guard_index(new, out, st, ok)

    return jax.vmap(one, in_axes=(0, 0, 0, 0, 0, 0, 0, 0, 0, None if transform is None else 0,
                                  None if reset is None else 0))(
        state, idx, idx_ok & len_ok, poses, paths, lengths, new_path, vel, enabled, transform, reset)
