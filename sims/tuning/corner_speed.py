"""Tuning a speed zone with `jax.grad` through a fleet rollout, checked against the hard filters.

The question a fleet operator asks: how fast may robots take a corner whose
outside edge is a keepout zone (a machine, a doorway)? Faster corners mean more
goals per hour; too fast and the robots swing wide into the keepout.

Scenario (`CornerScenario`): B robots follow an L-shaped route east, then
north (the corner rounded with a 0.8 m arc), with pure pursuit. A square speed
zone covers the corner; its limit (m/s) is the parameter. A keepout rectangle
starts just past the corner's outside. Robots are unicycles with the fleet's
limits (`sims.fleet.config.RobotConfig`: top speed, yaw rate, acceleration); their
linear speed is capped by the speed limit at their position.

With the defaults (6 robots, 9 s), tuning from 0.3 m/s ends near 0.81 m/s;
the hard re-run at d = 40 (0.80 m/s) keeps 0.09 m between every footprint and
every keepout cell while mean progress grows from 7.9 m to 11.6 m; at the
robots' top speed (1.5 m/s) they overlap the keepout by 0.18 m.

Why a kinematic rollout and not `mujoco.mjx` steps: the fleet env's local
planner picks the best of enumerated (v, w) candidates (an argmin), so its
gradient with respect to a zone is zero almost everywhere, and the planar MJX
robot (slide x, slide y, hinge yaw with velocity actuators, 0.01 s lag) tracks
its commanded twist, which is what the unicycle integrates. The unicycle with
a goal-seeking controller (pure pursuit, smoothly saturated yaw rate and
acceleration) keeps the dynamics that make the trade-off real and is
differentiable end to end with `lax.scan`; its gradient matches central
differences to < 1 % (tests/tuning/test_corner_speed.py).

Objective (maximised): mean progress along the route after T seconds minus
`penalty` x the time-integrated soft keepout cost (`jaxfilters.soft`, zones
grown by the robot radius plus a safety margin, /254). Soft zones: the speed
limit is `soft_speed_limit` (width `speed_width`), so the gradient of the
progress reaches the zone's limit.

Check against the hard path (`hard_check`): the tuned limit is written into
a speed mask exactly as Nav2 would carry it (type 2, base 0, multiplier 0.02,
so mask value d = floor(50 v), rounded down to stay at or under the tuned
limit), both zones are rasterised with
`jaxfilters.shapes.rasterize_mask`, the same fleet is re-run with
`jaxfilters.speed.speed_filter` (its published-limit state carried per robot,
0.0 = no limit), and every footprint is tested against every keepout cell of
the rasterised mask: the margin holds when no footprint overlaps a keepout
cell.

`tune` returns the optimisation history (objective, limit, gradient per
iteration) for a notebook; `python -m sims.commands.soft_tuning [figure.png]`
prints a run (and draws it with `plot_tuning`).
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from jaxfilters import shapes as zones
from jaxfilters import soft
from jaxfilters.grid import OccupancyGrid
from jaxfilters.speed import SpeedState, speed_filter
from jaxfilters.types import FilterInfo, FilterMask
from sims.fleet.config import RobotConfig

_F32 = jnp.float32
SPEED_BASE = 0.0          # speed mask: type 2 (m/s), limit = 0.02 d
SPEED_MULTIPLIER = 0.02


def _tuple2(owner, name, value):
  arr = np.asarray(value, np.float64)
  if arr.ndim != 2 or arr.shape[1] != 2 or not np.all(np.isfinite(arr)):
    raise ValueError(f"{owner}.{name} must be finite (x, y) rows [N, 2]; got shape {arr.shape}")
  return tuple(tuple(float(v) for v in row) for row in arr)


@dataclasses.dataclass(frozen=True)
class CornerScenario:
  """The corner, the fleet and the objective (static: one compile per scenario).

  Attributes:
    route: (x, y) waypoints of the route, metres; interior corners are rounded
      with `corner_radius` arcs (the followed path).
    corner_radius: m, fillet radius at each interior waypoint.
    speed_zone: polygon of the speed zone around the corner.
    keepout: polygon of the keepout zone outside the corner.
    starts: (x, y, yaw) start pose of each robot (B rows).
    robot: RobotConfig (radius, max_speed, max_yaw_rate, max_accel).
    dt: s, control and integration step.
    steps: number of steps (T = steps * dt seconds).
    lookahead: m, pure-pursuit carrot distance along the route.
    yaw_gain: 1/s, yaw-rate command per radian of heading error (then clipped).
    safety_margin: m, kept between the footprint and the keepout.
    keepout_width, speed_width: m, soft-zone widths.
    penalty: weight of the integrated soft keepout cost (per second of full cost).
    mask_origin, mask_resolution, mask_shape: grid of the hard masks (Nav2 style 5 cm).
  """
  route: tuple = ((-3.0, 0.0), (4.0, 0.0), (4.0, 8.0))
  corner_radius: float = 0.8
  speed_zone: tuple = ((2.5, -1.5), (5.5, -1.5), (5.5, 1.5), (2.5, 1.5))
  keepout: tuple = ((4.35, -1.2), (6.0, -1.2), (6.0, 1.5), (4.35, 1.5))
  starts: tuple = ((-2.5, 0.3, 0.0), (-2.0, -0.3, 0.0), (-1.5, 0.15, 0.2), (-1.0, -0.15, -0.2),
                   (-3.0, 0.0, 0.1), (-0.5, 0.25, 0.0))
  robot: RobotConfig = RobotConfig(max_speed=1.5, max_yaw_rate=1.5, max_accel=1.0)
  dt: float = 0.05
  steps: int = 180
  lookahead: float = 0.6
  yaw_gain: float = 3.0
  safety_margin: float = 0.05
  keepout_width: float = 0.01
  speed_width: float = 0.1
  penalty: float = 20.0
  mask_origin: tuple = (-4.0, -2.0)
  mask_resolution: float = 0.05
  mask_shape: tuple = (100, 220)

  def __post_init__(self):
    o = "CornerScenario"
    for name in ("route", "speed_zone", "keepout"):
      object.__setattr__(self, name, _tuple2(o, name, getattr(self, name)))
    if len(self.route) < 2:
      raise ValueError(f"{o}.route needs at least 2 waypoints; got {len(self.route)}")
    starts = np.asarray(self.starts, np.float64)
    if starts.ndim != 2 or starts.shape[1] != 3 or len(starts) < 1 or not np.all(np.isfinite(starts)):
      raise ValueError(f"{o}.starts must be finite (x, y, yaw) rows [B, 3]; got shape {starts.shape}")
    object.__setattr__(self, "starts", tuple(tuple(float(v) for v in r) for r in starts))
    if not isinstance(self.robot, RobotConfig):
      raise ValueError(f"{o}.robot must be a RobotConfig; got {type(self.robot).__name__}")
    for name in ("dt", "lookahead", "yaw_gain", "keepout_width", "speed_width", "mask_resolution",
                 "corner_radius"):
      v = float(getattr(self, name))
      if not np.isfinite(v) or v <= 0:
        raise ValueError(f"{o}.{name} must be finite and > 0; got {getattr(self, name)!r}")
    for name in ("safety_margin", "penalty"):
      v = float(getattr(self, name))
      if not np.isfinite(v) or v < 0:
        raise ValueError(f"{o}.{name} must be finite and >= 0; got {getattr(self, name)!r}")
    if isinstance(self.steps, bool) or int(self.steps) != self.steps or self.steps < 1:
      raise ValueError(f"{o}.steps must be an integer >= 1; got {self.steps!r}")
    if len(self.mask_shape) != 2 or any(int(s) != s or s < 1 for s in self.mask_shape):
      raise ValueError(f"{o}.mask_shape must be (H, W) positive integers; got {self.mask_shape!r}")
    route_pieces(self.route, self.corner_radius)          # raises if a fillet does not fit

  @property
  def num_robots(self) -> int:
    return len(self.starts)

  @property
  def duration(self) -> float:
    return self.steps * self.dt

  @property
  def path(self) -> tuple:
    """The followed path: the route with rounded corners, as line and arc pieces."""
    return route_pieces(self.route, self.corner_radius)

  @property
  def route_length(self) -> float:
    return float(sum(_piece_length(p) for p in self.path))


def _piece_length(piece) -> float:
  kind, g = piece
  return float(np.hypot(g[2] - g[0], g[3] - g[1])) if kind == "line" else float(g[2] * abs(g[4]))


def route_pieces(route, corner_radius: float) -> tuple:
  """The route as ("line", (ax, ay, bx, by)) and ("arc", (cx, cy, r, start_angle, turn)) pieces.

  Each interior corner is replaced by a tangent circular arc of `corner_radius`.
  The closest-point progress along lines and exact arcs is continuous for
  points within the radius of the path, so the rollout is continuous in the
  zone parameters (a sharp corner, or a polyline of chords, jumps across the
  bisector on its inner side, which finite differences see as a step).

  Raises:
    ValueError: a fillet that does not fit its two segments, a repeated
      waypoint or a reversal.
  """
  pts = [np.asarray(p, np.float64) for p in route]
  pieces, cur = [], pts[0]
  for a, b, c in zip(pts[:-2], pts[1:-1], pts[2:]):
    d1, d2 = b - a, c - b
    l1, l2 = np.linalg.norm(d1), np.linalg.norm(d2)
    if l1 == 0 or l2 == 0:
      raise ValueError("route waypoints must not repeat")
    d1, d2 = d1 / l1, d2 / l2
    turn = float(np.arctan2(d1[0] * d2[1] - d1[1] * d2[0], d1 @ d2))
    if abs(turn) < 1e-9:
      continue
    if abs(abs(turn) - np.pi) < 1e-6:
      raise ValueError("the route must not reverse on itself")
    t = corner_radius * np.tan(abs(turn) / 2)
    if t > 0.5 * min(l1, l2):
      raise ValueError(f"corner_radius {corner_radius} m needs {t:.3g} m of each segment at {tuple(b)}; "
                       f"the segments are {l1:.3g} and {l2:.3g} m (at most half of each may be used)")
    start, end = b - d1 * t, b + d2 * t
    centre = start + np.array([-d1[1], d1[0]]) * np.sign(turn) * corner_radius
    pieces.append(("line", (*cur, *start)))
    pieces.append(("arc", (*centre, corner_radius, float(np.arctan2(*(start - centre)[::-1])), turn)))
    cur = end
  pieces.append(("line", (*cur, *pts[-1])))
  return tuple((k, tuple(float(v) for v in g)) for k, g in pieces)


def zone_shapes(scenario: CornerScenario, limit: float | None = None) -> tuple[zones.Shapes, zones.Shapes]:
  """(keepout Shapes with value 100, speed Shapes whose value carries `limit`, or 100 if None)."""
  keep = zones.Shapes.create([zones.Polygon(scenario.keepout, constants.OCC_GRID_OCCUPIED)])
  value = constants.OCC_GRID_OCCUPIED if limit is None else speed_mask_value(limit)
  speed = zones.Shapes.create([zones.Polygon(scenario.speed_zone, value)])
  return keep, speed


def speed_mask_value(limit: float) -> int:
  """Mask value d carrying a limit in m/s through base 0, multiplier 0.02: d = floor(v / 0.02).

  Rounded down, so the published limit d * 0.02 never exceeds the tuned one.

  Raises:
    ValueError: a limit whose mask value falls outside 1..100 (0.02 to 2.0 m/s).
  """
  d = int(np.floor(float(limit) / SPEED_MULTIPLIER + 1e-9))
  if not 1 <= d <= 100:
    raise ValueError(f"a speed-zone limit must map to a mask value 1..100 (0.02 to 2.0 m/s with "
                     f"multiplier {SPEED_MULTIPLIER}); got {limit!r} m/s -> {d}")
  return d


# ----------------------------------------------------------------------------- fleet rollout


def _project(piece, xy):
  """(squared distance, arc length from the piece's start) of xy's closest point on a piece."""
  kind, g = piece
  if kind == "line":
    a = jnp.asarray(g[:2], _F32)
    ab = jnp.asarray(g[2:], _F32) - a
    length = float(np.hypot(g[2] - g[0], g[3] - g[1]))
    t = jnp.clip(jnp.sum((xy - a) * ab) / (length * length), 0.0, 1.0)
    return jnp.sum((xy - a - t * ab) ** 2), t * length
  cx, cy, r, a0, turn = g
  rel = xy - jnp.asarray([cx, cy], _F32)
  ang = jnp.arctan2(rel[1], rel[0]) - a0
  ang = jnp.arctan2(jnp.sin(ang), jnp.cos(ang)) * np.sign(turn)       # progress angle, wrapped
  ang = jnp.clip(ang, 0.0, abs(turn))
  q = jnp.asarray([cx, cy], _F32) + r * jnp.stack([jnp.cos(a0 + np.sign(turn) * ang),
                                                   jnp.sin(a0 + np.sign(turn) * ang)])
  return jnp.sum((xy - q) ** 2), r * ang


def route_progress(path, xy):
  """Arc length along the path (pieces from `route_pieces`) of the closest point to xy [2]."""
  d2, s, offset = [], [], 0.0
  for piece in path:
    dd, ss = _project(piece, xy)
    d2.append(dd)
    s.append(ss + offset)
    offset += _piece_length(piece)
  k = jnp.argmin(jnp.stack(d2))
  return jnp.stack(s)[k]


def route_point(path, s):
  """Point at arc length s along the path (clamped to its ends)."""
  out, offset = None, 0.0
  for piece in path:
    kind, g = piece
    length = _piece_length(piece)
    u = jnp.clip(s - offset, 0.0, length)
    if kind == "line":
      a, b = jnp.asarray(g[:2], _F32), jnp.asarray(g[2:], _F32)
      pt = a + (b - a) * (u / length)
    else:
      cx, cy, r, a0, turn = g
      ang = a0 + np.sign(turn) * u / r
      pt = jnp.asarray([cx, cy], _F32) + r * jnp.stack([jnp.cos(ang), jnp.sin(ang)])
    out = pt if out is None else jnp.where(s >= offset, pt, out)
    offset += length
  return out


def _step(scenario: CornerScenario, state, cap):
  """One control step of one robot: pure pursuit, speed cap, acceleration and yaw-rate limits.

  Saturations are smooth (w_max tanh(k e / w_max), dv tanh(dv_cmd / dv)): a
  realistic controller shape that keeps the rollout differentiable everywhere.
  """
  x, y, yaw, v = state[0], state[1], state[2], state[3]
  r = scenario.robot
  xy = jnp.stack([x, y])
  path = scenario.path
  carrot = route_point(path, route_progress(path, xy) + scenario.lookahead)
  err = jnp.arctan2(carrot[1] - y, carrot[0] - x) - yaw
  err = jnp.arctan2(jnp.sin(err), jnp.cos(err))
  w = r.max_yaw_rate * jnp.tanh(scenario.yaw_gain * err / r.max_yaw_rate)
  target = jnp.minimum(cap, r.max_speed)
  dv = r.max_accel * scenario.dt
  v = v + dv * jnp.tanh((target - v) / dv)
  yaw = yaw + w * scenario.dt
  x = x + v * jnp.cos(yaw) * scenario.dt
  y = y + v * jnp.sin(yaw) * scenario.dt
  return jnp.stack([x, y, yaw, v])


def _initial_state(scenario):
  s = jnp.asarray(scenario.starts, _F32)
  return jnp.concatenate([s, jnp.zeros((s.shape[0], 1), _F32)], axis=1)        # [B, 4] x, y, yaw, v


def soft_rollout(scenario: CornerScenario, limit):
  """Fleet rollout under the soft speed zone whose limit is `limit` (m/s).

  Returns:
    float32 [T, B, 4] states (x, y, yaw, v) after each step.
  """
  _, speed_shapes = zone_shapes(scenario)
  info = FilterInfo.create(constants.SPEED_FILTER_ABSOLUTE, SPEED_BASE, SPEED_MULTIPLIER)
  limits = jnp.reshape(jnp.asarray(limit, _F32), (1,))
  no_limit = scenario.robot.max_speed

  def body(states, _):
    caps = soft.soft_speed_limit(speed_shapes, info, states[:, :2], width=scenario.speed_width,
                                 no_limit=no_limit, limits=limits)
    states = jax.vmap(functools.partial(_step, scenario))(states, caps)
    return states, states

  _, traj = jax.lax.scan(body, _initial_state(scenario), None, length=scenario.steps)
  return traj


def soft_objective(scenario: CornerScenario, limit):
  """(objective, (mean progress m, integrated soft keepout cost s)) for a zone limit (m/s)."""
  keep_shapes, _ = zone_shapes(scenario)
  traj = soft_rollout(scenario, limit)
  margin = scenario.robot.radius + scenario.safety_margin
  pos = traj[..., :2].reshape(-1, 2)
  cost = soft.soft_keepout_cost(keep_shapes, pos, width=scenario.keepout_width, margin=margin)
  exposure = jnp.sum(cost) / 254.0 * scenario.dt / scenario.num_robots
  progress = jnp.mean(jax.vmap(lambda xy: route_progress(scenario.path, xy))(traj[-1, :, :2]))
  return progress - scenario.penalty * exposure, (progress, exposure)


@functools.partial(jax.jit, static_argnames="scenario")
def objective_and_grad(scenario: CornerScenario, limit):
  """((objective, (progress, exposure)), d objective / d limit), jitted."""
  return jax.value_and_grad(soft_objective, argnums=1, has_aux=True)(scenario, limit)


_objective = jax.jit(soft_objective, static_argnames="scenario")


def finite_difference(scenario: CornerScenario, limit: float, eps: float = 1e-2) -> float:
  """Central finite-difference estimate of d objective / d limit."""
  up = float(_objective(scenario, jnp.float32(limit + eps))[0])
  dn = float(_objective(scenario, jnp.float32(limit - eps))[0])
  return (up - dn) / (2 * eps)


@dataclasses.dataclass(frozen=True)
class History:
  """Per-iteration record of `tune` (host numpy arrays, iteration 0 = the start).

  Attributes:
    limit: float [K], the zone limit (m/s) evaluated at each iteration.
    objective: float [K].
    gradient: float [K], d objective / d limit.
    progress: float [K], mean metres along the route after T seconds.
    exposure: float [K], integrated soft keepout cost (s at full cost).
  """
  limit: np.ndarray
  objective: np.ndarray
  gradient: np.ndarray
  progress: np.ndarray
  exposure: np.ndarray

  @property
  def best_limit(self) -> float:
    return float(self.limit[int(np.argmax(self.objective))])


def tune(scenario: CornerScenario, *, init: float = 0.3, iterations: int = 40, step: float = 0.1,
         lo: float = 0.05, hi: float | None = None, min_step: float = 1e-3) -> History:
  """Gradient ascent on the zone's limit (normalised steps, projected onto [lo, hi]).

  The step is `step` m/s in the direction of the gradient, halved whenever the
  gradient changes sign (the objective is one-dimensional and its scale
  changes by orders of magnitude where the keepout starts to bite); it stops
  after `iterations` evaluations or once the step is below `min_step`.

  Args:
    scenario: the corner and fleet.
    init: starting limit (m/s).
    iterations: gradient evaluations.
    step: initial step (m/s).
    lo, hi: bounds on the limit (hi defaults to the robot's top speed).
    min_step: m/s, stop once the step is smaller.

  Returns:
    History of every evaluated limit.

  Raises:
    ValueError: non-finite or inverted bounds, init outside them, iterations < 1.
  """
  hi = scenario.robot.max_speed if hi is None else float(hi)
  if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo < hi):
    raise ValueError(f"tune: need 0 < lo < hi (m/s); got lo={lo!r}, hi={hi!r}")
  if not lo <= init <= hi:
    raise ValueError(f"tune: init must lie in [lo, hi] = [{lo}, {hi}]; got {init!r}")
  if isinstance(iterations, bool) or int(iterations) != iterations or iterations < 1:
    raise ValueError(f"tune: iterations must be an integer >= 1; got {iterations!r}")
  rec = {k: [] for k in ("limit", "objective", "gradient", "progress", "exposure")}
  x, last_sign = float(init), 0.0
  for _ in range(int(iterations)):
    if step < min_step:
      break
    (obj, (prog, expo)), g = objective_and_grad(scenario, jnp.float32(x))
    for k, v in zip(rec, (x, obj, g, prog, expo)):
      rec[k].append(float(v))
    sign = float(np.sign(g))
    if sign == 0.0:
      break
    if last_sign and sign != last_sign:
      step *= 0.5
    last_sign = sign
    x = float(np.clip(x + step * sign, lo, hi))
  return History(**{k: np.asarray(v, np.float64) for k, v in rec.items()})


# ----------------------------------------------------------------------------- hard check


@dataclasses.dataclass(frozen=True)
class HardCheck:
  """The tuned zone re-run through the hard Nav2 path.

  Attributes:
    limit: m/s asked for; mask_value: the speed mask value d carrying it;
    hard_limit: d * 0.02, the limit the SpeedFilter publishes (m/s).
    progress: mean metres along the route after T seconds (hard run).
    keepout_cells: int, keepout cells of the rasterised mask.
    cells_entered: int, (step, robot) pairs whose footprint overlaps a keepout cell.
    clearance: m, smallest distance between any footprint and any keepout cell
      over the run (negative: overlap).
    margin_held: clearance >= 0 (no keepout cell entered).
    trajectory: float [T, B, 4] states of the hard run.
  """
  limit: float
  mask_value: int
  hard_limit: float
  progress: float
  keepout_cells: int
  cells_entered: int
  clearance: float
  margin_held: bool
  trajectory: np.ndarray


def _masks(scenario: CornerScenario, limit: float):
  h, w = scenario.mask_shape
  grid = OccupancyGrid.create(np.zeros((h, w), np.int8), scenario.mask_resolution, scenario.mask_origin)
  keep_shapes, speed_shapes = zone_shapes(scenario, limit)
  keep, kv = zones.rasterize_mask(keep_shapes, FilterMask.create(grid, FilterInfo.create(constants.KEEPOUT_FILTER)),
                                  default_value=0)
  info = FilterInfo.create(constants.SPEED_FILTER_ABSOLUTE, SPEED_BASE, SPEED_MULTIPLIER)
  speed, sv = zones.rasterize_mask(speed_shapes, FilterMask.create(grid, info), default_value=0)
  if not (bool(kv[0]) and bool(sv[0])):
    raise ValueError("the scenario's zones fall outside the rasteriser's exact domain")
  return keep, speed


@functools.partial(jax.jit, static_argnames="scenario")
def _hard_rollout(scenario: CornerScenario, speed: FilterMask):
  b = scenario.num_robots

  def body(carry, _):
    states, sp = carry
    poses = states[:, :3]
    sp, out = speed_filter(speed, poses, sp)
    # Nav2: 0.0 means "no limit"; the last published limit stays in force.
    caps = jnp.where(out.speed_limit > 0, out.speed_limit, scenario.robot.max_speed)
    states = jax.vmap(functools.partial(_step, scenario))(states, caps)
    return (states, sp), states

  (_, _), traj = jax.lax.scan(body, (_initial_state(scenario), SpeedState.create(b)), None,
                              length=scenario.steps)
  return traj


def footprint_clearance(traj_xy: np.ndarray, cells_xy: np.ndarray, resolution: float, radius: float) -> np.ndarray:
  """Distance from each circular footprint to the nearest keepout cell square (m; < 0 overlap).

  Args:
    traj_xy: float [..., 2] robot centres.
    cells_xy: float [K, 2] centres of keepout cells.
    resolution: cell side (m).
    radius: footprint radius (m).

  Returns:
    float [...] clearance.
  """
  p = np.asarray(traj_xy, np.float64)[..., None, :]
  q = np.abs(p - np.asarray(cells_xy, np.float64)) - resolution / 2
  outside = np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(np.max(q, axis=-1), 0.0)
  return np.min(outside, axis=-1) - radius


def hard_check(scenario: CornerScenario, limit: float) -> HardCheck:
  """Re-runs the fleet with the zone rasterised into Nav2 masks and the hard speed filter.

  Raises:
    ValueError: a limit that no speed mask value carries (see speed_mask_value).
  """
  d = speed_mask_value(limit)
  keep, speed = _masks(scenario, limit)
  traj = np.asarray(_hard_rollout(scenario, speed))
  data = np.asarray(keep.data[0])
  rows, cols = np.nonzero(data == constants.OCC_GRID_OCCUPIED)
  res = scenario.mask_resolution
  ox, oy = np.float32(scenario.mask_origin[0]), np.float32(scenario.mask_origin[1])
  cells = np.stack([ox + (cols + 0.5) * np.float32(res), oy + (rows + 0.5) * np.float32(res)], axis=1)
  clear = footprint_clearance(traj[..., :2], cells, float(np.float32(res)), scenario.robot.radius)
  progress = float(np.mean([float(route_progress(scenario.path, jnp.asarray(xy))) for xy in traj[-1, :, :2]]))
  return HardCheck(limit=float(limit), mask_value=d, hard_limit=d * SPEED_MULTIPLIER, progress=progress,
                   keepout_cells=int(len(cells)), cells_entered=int(np.sum(clear < 0)),
                   clearance=float(np.min(clear)), margin_held=bool(np.min(clear) >= 0), trajectory=traj)


def plot_tuning(scenario: CornerScenario, history: History, checks: dict, path) -> None:
  """Saves a figure: zones and hard-run trajectories per limit (left), the history (right).

  Args:
    scenario: the corner.
    history: from `tune`.
    checks: {label: HardCheck} to draw.
    path: image file to write (png).
  """
  import matplotlib
  matplotlib.use("Agg")
  import matplotlib.pyplot as plt

  fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 5.2), gridspec_kw=dict(width_ratios=[1.15, 1]))
  some = next(iter(checks.values()))
  keep, speed = _masks(scenario, some.limit)
  h, w = scenario.mask_shape
  res, (ox, oy) = scenario.mask_resolution, scenario.mask_origin
  extent = (ox, ox + w * res, oy, oy + h * res)
  ax.imshow(np.asarray(speed.data[0]) > 0, origin="lower", extent=extent, cmap="Blues", alpha=0.25, vmin=0, vmax=1)
  ax.imshow(np.where(np.asarray(keep.data[0]) == 100, 1.0, np.nan), origin="lower", extent=extent,
            cmap="Reds", vmin=0, vmax=1.2)
  pts = np.asarray([route_point(scenario.path, jnp.float32(u)) for u in np.linspace(0, scenario.route_length, 200)])
  ax.plot(pts[:, 0], pts[:, 1], "k--", lw=1, label="route")
  colours = ["tab:green", "tab:blue", "tab:red", "tab:purple"]
  rows, cols = np.nonzero(np.asarray(keep.data[0]) == constants.OCC_GRID_OCCUPIED)
  cells = np.stack([ox + (cols + 0.5) * res, oy + (rows + 0.5) * res], axis=1)
  for (label, chk), col in zip(checks.items(), colours):
    tr = chk.trajectory
    for b in range(tr.shape[1]):
      ax.plot(tr[:, b, 0], tr[:, b, 1], color=col, lw=1,
              label=(f"{label}: {chk.hard_limit:.2f} m/s, clearance {chk.clearance:+.3f} m" if b == 0 else None))
    # The footprint where it came closest to a keepout cell.
    clear = footprint_clearance(tr[..., :2], cells, res, scenario.robot.radius)
    t, b = np.unravel_index(np.argmin(clear), clear.shape)
    ax.add_patch(plt.Circle(tuple(tr[t, b, :2]), scenario.robot.radius, fill=False, color=col, lw=1.5))
  ax.set_xlim(2.0, 6.0)
  ax.set_ylim(-1.5, 3.0)
  ax.set_aspect("equal")
  ax.set_xlabel("x (m)")
  ax.set_ylabel("y (m)")
  ax.set_title("hard re-run: speed zone (blue), keepout cells (red),\nfootprints at closest approach", fontsize=10)
  ax.legend(loc="upper left", fontsize=8)
  it = np.arange(len(history.limit))
  bx.plot(it, history.objective, "k.-", label="objective (soft)")
  bx.plot(it, history.progress, "g.-", label="progress (m)")
  bx.set_xlabel("iteration")
  bx.set_ylabel("metres")
  cx = bx.twinx()
  cx.plot(it, history.limit, "b.-", label="zone limit (m/s)")
  cx.set_ylabel("zone limit (m/s)", color="b")
  bx.legend(loc="lower right", fontsize=8)
  bx.set_title(f"gradient ascent: best {history.best_limit:.3f} m/s")
  fig.tight_layout()
  fig.savefig(path, dpi=110)
  plt.close(fig)
