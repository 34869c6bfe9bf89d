"""The fleet planner in its straightforward form, kept as a reference for the optimised one.

sims/fleet/planner.py and sims/fleet/navigation.py share work between candidates, pack
the costmap rules into one table and gather through flat indices;
tests/fleet/test_planner_reference.py checks that they choose the same commands with the
same scores as this straightforward version (and the navigation field lookups
below), and benchmarks/fleet_breakdown.py times it as the `reference_planner`
variant. It shares no code with sims/fleet/planner.py.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from sims.fleet.config import FleetConfig

_F32 = jnp.float32
_SPEED_PENALTY = 1e3
_COLLISION = 1e9
_REVERSE = 1e4
_MONITORED = 4
UNREACHABLE = 1e6


def candidates(config: FleetConfig, extra_speeds: tuple[float, ...] = ()) -> np.ndarray:
  """float32 [C, 2] target twists (v, w).

  Args:
    config: planner and robot limits.
    extra_speeds: more linear speeds to try (m/s), e.g. just under each speed
      zone's limit so robots use a zone's full allowance.

  Returns:
    C = (num_speeds + extra speeds in (0, max_speed) + 1 reverse speed) * num_yaw_rates
    targets. The reverse speed (-reverse_speed) is only used in recovery mode.
  """
  p, r = config.planner, config.robot
  v = np.linspace(0.0, r.max_speed, p.num_speeds)
  extra = [float(e) for e in extra_speeds if 0.0 < e < r.max_speed]
  v = np.unique(np.concatenate([v, np.asarray(extra + [-p.reverse_speed], np.float64)]))
  w = np.linspace(-r.max_yaw_rate, r.max_yaw_rate, p.num_yaw_rates) if p.num_yaw_rates > 1 else np.zeros(1)
  vv, ww = np.meshgrid(v, w, indexing="ij")
  return np.stack([vv.ravel(), ww.ravel()], axis=1).astype(np.float32)


def _cos_sin_small(a: jax.Array) -> tuple[jax.Array, jax.Array]:
  """cos and sin of |a| <= 0.3 rad by Taylor series (error < 3e-8; no transcendental calls)."""
  a2 = a * a
  return (1.0 - a2 * (0.5 - a2 * (1.0 / 24.0 - a2 / 720.0)),
          a * (1.0 - a2 * (1.0 / 6.0 - a2 * (1.0 / 120.0 - a2 / 5040.0))))


def rollout(pose: jax.Array, cmd: jax.Array, targets: jax.Array, config: FleetConfig):
  """Unicycle rollouts with acceleration limits.

  Each step ramps (v, w) toward the target within the acceleration limits, then
  moves along the midpoint heading. The heading is carried as a unit vector
  rotated by small-angle series (|w| dt is small), so the C x T rollout needs
  no sin/cos calls, which dominate its cost on CPU.

  Args:
    pose: float32 [3] (x, y, yaw).
    cmd: float32 [2] the last command (v, w).
    targets: float32 [C, 2] target twists.
    config: static FleetConfig.

  Returns:
    (xy float32 [C, T+1, 2] with xy[:, 0] = pose, heading unit vectors
    float32 [C, 2] at the end, v float32 [C, T+1]).
  """
  p, r = config.planner, config.robot
  dt = p.rollout_dt
  if r.max_yaw_rate * dt > 0.6:
    raise ValueError(f"max_yaw_rate * rollout_dt must be <= 0.6 rad for the rollout's series; "
                     f"got {r.max_yaw_rate * dt}")
  c = targets.shape[0]
  x = jnp.full((c,), pose[0])
  y = jnp.full((c,), pose[1])
  hc = jnp.full((c,), jnp.cos(pose[2]))
  hs = jnp.full((c,), jnp.sin(pose[2]))
  v = jnp.full((c,), cmd[0])
  w = jnp.full((c,), cmd[1])
  xs, ys, vs = [x], [y], [v]
  for _ in range(p.num_rollout_steps):
    v = v + jnp.clip(targets[:, 0] - v, -r.max_accel * dt, r.max_accel * dt)
    w = w + jnp.clip(targets[:, 1] - w, -r.max_yaw_accel * dt, r.max_yaw_accel * dt)
    ch, sh = _cos_sin_small(0.5 * w * dt)
    mc, ms = hc * ch - hs * sh, hs * ch + hc * sh          # midpoint heading
    x = x + v * dt * mc
    y = y + v * dt * ms
    hc, hs = mc * ch - ms * sh, ms * ch + mc * sh          # end-of-step heading
    xs.append(x), ys.append(y), vs.append(v)
  xy = jnp.stack([jnp.stack(xs, 1), jnp.stack(ys, 1)], axis=-1)
  return xy, jnp.stack([hc, hs], axis=1), jnp.stack(vs, 1)


def local_cost_at(cost: jax.Array, origin: jax.Array, res: jax.Array, xy: jax.Array) -> jax.Array:
  """Local costmap value at points; NO_INFORMATION outside the window.

  Args:
    cost: uint8 [N, N] local costmap (or `hard_cells` of it).
    origin: float32 [2] window origin (m); res: float32 [] metres per cell.
    xy: float32 [..., 2] points (m).

  Returns:
    int32 [...] cost per point.
  """
  n_rows, n_cols = cost.shape
  o = jnp.reshape(origin, (1,) * (xy.ndim - 1) + (2,))
  ij = jnp.floor((xy - o) / res).astype(jnp.int32)
  inside = (ij[..., 0] >= 0) & (ij[..., 0] < n_cols) & (ij[..., 1] >= 0) & (ij[..., 1] < n_rows)
  v = cost[jnp.clip(ij[..., 1], 0, n_rows - 1), jnp.clip(ij[..., 0], 0, n_cols - 1)].astype(jnp.int32)
  return jnp.where(inside, v, constants.NO_INFORMATION)


def speed_cap_at(speed_cap: jax.Array, mask_origin: jax.Array, mask_res: jax.Array,
                 xy: jax.Array) -> jax.Array:
  """Speed-mask limit in m/s at points xy [..., 2] (+inf off the mask or where there is none).

  `speed_cap` holds `speed_limit_at_one`'s limit of every mask cell (see
  WorldParams), so this is one float floor and a gather per point. A point
  within float rounding of a cell edge may read the neighbouring cell; the
  interval rule (both ends of every rollout interval) makes that harmless.

  Args:
    speed_cap: float32 [Hs, Ws] m/s per speed-mask cell (+inf none).
    mask_origin: float32 [2] (m); mask_res: float32 [] metres per cell.
    xy: float32 [..., 2] points (m).

  Returns:
    float32 [...] m/s cap per point.
  """
  h, w = speed_cap.shape
  o = jnp.reshape(mask_origin, (1,) * (xy.ndim - 1) + (2,))
  ij = jnp.floor((xy - o) / mask_res).astype(jnp.int32)
  inside = (ij[..., 0] >= 0) & (ij[..., 0] < w) & (ij[..., 1] >= 0) & (ij[..., 1] < h)
  v = speed_cap[jnp.clip(ij[..., 1], 0, h - 1), jnp.clip(ij[..., 0], 0, w - 1)]
  return jnp.where(inside, v, jnp.inf)


def hard_cells(cost: jax.Array) -> jax.Array:
  """Cells a rollout must not enter: lethal or unknown (>= 254) ones and their 8 neighbours.

  Args:
    cost: uint8 [N, N] local costmap.

  Returns:
    uint8 [N, N], 1 where the cell or one of its 8 neighbours is >= 254.
  """
  a = cost >= constants.LETHAL_OBSTACLE
  p = jnp.pad(a, 1)
  n0, n1 = a.shape
  out = a
  for i in range(3):
    for j in range(3):
      out = out | p[i:i + n0, j:j + n1]
  return out.astype(jnp.uint8)


def limit_to_speed(limit: jax.Array, percent: jax.Array, valid: jax.Array, max_speed: float) -> jax.Array:
  """Nav2 speed limit (percent or m/s; 0.0 = none) -> m/s cap (+inf = none).

  Args:
    limit: float32 [...] the speed filter's published limit.
    percent: bool [...] whether the limit is a percentage of max_speed.
    valid: bool [...] whether a limit is known (False: no cap).
    max_speed: m/s, the robot's maximum speed.

  Returns:
    float32 [...] cap in m/s; +inf where there is no limit.
  """
  ms = jnp.where(percent, max_speed * limit / 100.0, limit)
  return jnp.where(valid & (limit > 0), ms, jnp.inf).astype(_F32)


def plan_one(pose, cmd, goal, limit_now, recovering, cost, hard, origin, res, others, others_valid,
             nav, speed_mask, speed_cap: jax.Array, *,
             config: FleetConfig, extra_speeds: tuple[float, ...] = ()):
  """Chooses this control tick's command for one robot.

  Args:
    pose: float32 [3] robot (x, y, yaw).
    cmd: float32 [2] last command (v, w).
    goal: int32 [] station index.
    limit_now: float32 [] speed cap in force (m/s, +inf none) from the speed filter.
    recovering: bool [], recovery mode (see PlannerConfig.recovery_after).
    cost: uint8 [N, N] the robot's local costmap; origin float32 [2]; res float32 [].
    hard: uint8 [N, N] `hard_cells(cost)`, computed at the costmap rate.
    others: float32 [K, 2] positions of the world's robots; others_valid bool [K]
      (False for this robot itself).
    nav: shared NavField.
    speed_mask: shared FilterMask (M = 1) of the speed filter (its geometry).
    speed_cap: float32 [Hs, Ws] the mask's limit per cell in m/s (WorldParams.speed_cap).
    config: static FleetConfig.
    extra_speeds: static extra candidate speeds (see `candidates`).

  Returns:
    (command float32 [2] (v, w) for this tick, within the acceleration limits
    unless it is an emergency stop; info dict of scalars: 'stopped' bool,
    'speed_violation' float32 (m/s x s) of the chosen candidate).
  """
  ev = evaluate(pose, cmd, goal, limit_now, recovering, cost, hard, origin, res, others, others_valid, nav,
                speed_mask, speed_cap, config=config, extra_speeds=extra_speeds)
  r = config.robot
  best = jnp.argmin(ev["score"])
  stopped = ev["collide"][best]
  dt = config.control_dt
  target = ev["targets"][best]
  new_v = cmd[0] + jnp.clip(target[0] - cmd[0], -r.max_accel * dt, r.max_accel * dt)
  new_w = cmd[1] + jnp.clip(target[1] - cmd[1], -r.max_yaw_accel * dt, r.max_yaw_accel * dt)
  command = jnp.where(stopped, jnp.zeros((2,), _F32), jnp.stack([new_v, new_w]).astype(_F32))
  return command, {"stopped": stopped, "speed_violation": jnp.where(stopped, 0.0, ev["violation"][best])}


def evaluate(pose, cmd, goal, limit_now, recovering, cost, hard, origin, res, others, others_valid,
             nav, speed_mask, speed_cap: jax.Array, *,
             config: FleetConfig, extra_speeds: tuple[float, ...] = ()) -> dict:
  """Every candidate's rollout, checks and score terms (arguments as `plan_one`).

  Returns:
    dict of per-candidate arrays: targets [C, 2], xy [C, T+1, 2], collide [C],
    violation [C] (excess speed integrated over the rollout, m/s x s), progress,
    heading, clearance, score [C].
  """
  p, r = config.planner, config.robot
  targets = jnp.asarray(candidates(config, extra_speeds))
  # The barrier materialises the rollouts once: without it XLA:CPU may fuse (recompute) the
  # whole T-step chain into each of its consumers below.
  xy, head, v = jax.lax.optimization_barrier(rollout(pose, cmd, targets, config))  # [C,T+1,2],[C,2],[C,T+1]

  # Collision against the local costmap, at points and interval midpoints (at most half a
  # cell apart up to 0.5 m/s at 0.05 m cells). Lethal and unknown cells are also blocked one
  # cell around (keepout cells are lethal but not inflated), so a path cannot clip a
  # keepout corner between two samples.
  mids = 0.5 * (xy[:, 1:] + xy[:, :-1])
  pts = jnp.concatenate([mids, xy[:, 1:]], axis=1)               # [C, 2T, 2]
  c_pts = local_cost_at(cost, origin, res, pts)
  hard_pts = local_cost_at(hard, origin, res, pts)               # 255 outside the window
  c_here = local_cost_at(cost, origin, res, pose[:2])
  hard_here = local_cost_at(hard, origin, res, pose[:2]) > 0
  escape = c_here >= constants.INSCRIBED_INFLATED_OBSTACLE
  blocked = ((c_pts >= constants.LETHAL_OBSTACLE) | ((hard_pts > 0) & ~hard_here)
             | ((c_pts == constants.INSCRIBED_INFLATED_OBSTACLE) & ~escape))
  collide = jnp.any(blocked, axis=1)
  clearance = jnp.max(jnp.where(c_pts <= constants.MAX_NON_OBSTACLE, c_pts, 0), axis=1) / 252.0

  # Collision monitor against the nearest other robots' current positions (squared distances,
  # every other rollout point: at most 0.1 m apart at 0.5 m/s).
  safe2 = (2.0 * r.radius + p.monitor_margin) ** 2
  rel_now = others - pose[None, :2]
  d2_now = jnp.where(others_valid, jnp.sum(rel_now * rel_now, axis=-1), jnp.inf)   # [K]
  m = min(_MONITORED, others.shape[0])
  neg, near = jax.lax.top_k(-d2_now, m)
  rel_near = rel_now[near]                                       # [m, 2]
  t = xy.shape[1] - 1
  rel = xy[:, 2 - t % 2::2, None, :] - others[near][None, None]  # [C, ~T/2, m, 2], ends at T
  d2_path = jnp.sum(rel * rel, axis=-1)                          # [C, T/2, m]
  d2_min = jnp.min(d2_path, axis=1)                              # [C, m]
  approach = jnp.isfinite(neg)[None, :] & (d2_min < safe2) & (d2_min < -neg[None, :] - 1e-4)
  collide = collide | jnp.any(approach, axis=1)

  # Speed-zone lookahead along each rollout: every interval's speed against the strictest
  # (dilated) mask limit at its ends and midpoint; the first interval also under the limit in force.
  cap = speed_cap_at(speed_cap, speed_mask.origin[0], speed_mask.resolution[0], xy)   # [C, T+1]
  cap = cap.at[:, 0].min(limit_now)
  cap_mid = speed_cap_at(speed_cap, speed_mask.origin[0], speed_mask.resolution[0], mids)  # [C, T]
  interval_cap = jnp.minimum(jnp.minimum(cap[:, 1:], cap[:, :-1]), cap_mid)
  interval_v = jnp.maximum(jnp.abs(v[:, 1:]), jnp.abs(v[:, :-1]))
  # Integrated, not the worst interval: when the first interval is already too fast (a zone
  # met at a shallow angle), candidates that brake still score better than those that do not.
  violation = jnp.sum(jnp.maximum(interval_v - interval_cap, 0.0), axis=1) * p.rollout_dt

  # Score.
  reach = r.max_speed * p.horizon
  start_val = nav_value(nav, goal, pose[:2])
  end_val = jax.vmap(lambda q: nav_value(nav, goal, q))(xy[:, -1])
  progress = (end_val - start_val) / reach
  desired = jax.vmap(lambda q: descent_direction(nav, goal, q))(xy[:, -1])
  heading = 0.5 * (1.0 - jnp.sum(head * desired, axis=1))
  speed_term = 1.0 - targets[:, 0] / r.max_speed
  # Right-hand traffic: with another robot ahead (within 2 m, +-45 deg), prefer turning right,
  # so two robots meeting head-on both veer right instead of blocking each other.
  c_yaw, s_yaw = jnp.cos(pose[2]), jnp.sin(pose[2])
  ahead_x = c_yaw * rel_near[:, 0] + s_yaw * rel_near[:, 1]
  ahead_y = -s_yaw * rel_near[:, 0] + c_yaw * rel_near[:, 1]
  oncoming = jnp.any(jnp.isfinite(neg) & (ahead_x > 0) & (jnp.abs(ahead_y) < ahead_x)
                     & (ahead_x * ahead_x + ahead_y * ahead_y < 4.0))
  keep_right = jnp.where(
      oncoming, p.keep_right_weight * jnp.maximum(targets[:, 1], 0.0) / r.max_yaw_rate, 0.0)
  reverse = targets[:, 0] < 0
  normal = (p.progress_weight * progress + p.heading_weight * heading + keep_right
            + jnp.where(reverse, _REVERSE, 0.0))
  # Recovery: back away from the nearest robot (reversing allowed), turning right.
  d_end = jnp.sqrt(jnp.min(jnp.where(jnp.isfinite(neg)[None, :], d2_path[:, -1], jnp.inf), axis=1))
  separation = -jnp.minimum(d_end, 2.0) / 2.0
  recovery = 0.3 * p.progress_weight * progress + separation + 0.2 * targets[:, 1] / r.max_yaw_rate
  score = (jnp.where(recovering, recovery, normal)
           + p.clearance_weight * clearance + p.speed_weight * speed_term
           + _SPEED_PENALTY * violation + jnp.where(collide, _COLLISION, 0.0))
  return {"targets": targets, "xy": xy, "collide": collide, "violation": violation,
          "progress": progress, "heading": heading, "clearance": clearance, "score": score}


def nav_value(field: NavField, goal: jax.Array, xy: jax.Array) -> jax.Array:
  """Bilinear distance-to-goal at one point, over the corners that are finite.

  Args:
    field: the shared NavField.
    goal: int32 [], station index.
    xy: float32 [2], world point.

  Returns:
    float32 [] metres; UNREACHABLE where no corner is finite.
  """
  _, hn, wn = field.dist.shape
  g = (xy - field.origin) / field.resolution - 0.5      # continuous cell-centre coordinates
  c0 = jnp.floor(g)
  f = g - c0
  c0 = c0.astype(jnp.int32)
  vals, wts = [], []
  for dy in (0, 1):
    for dx in (0, 1):
      cx, cy = c0[0] + dx, c0[1] + dy
      inside = (cx >= 0) & (cx < wn) & (cy >= 0) & (cy < hn)
      v = field.dist[goal, jnp.clip(cy, 0, hn - 1), jnp.clip(cx, 0, wn - 1)]
      ok = inside & jnp.isfinite(v)
      wgt = (f[0] if dx else 1.0 - f[0]) * (f[1] if dy else 1.0 - f[1])
      vals.append(jnp.where(ok, v, 0.0))
      wts.append(jnp.where(ok, wgt + 1e-6, 0.0))
  vals, wts = jnp.stack(vals), jnp.stack(wts)
  total = jnp.sum(wts)
  return jnp.where(total > 0, jnp.sum(vals * wts) / jnp.where(total > 0, total, 1.0), UNREACHABLE)


def descent_direction(field: NavField, goal: jax.Array, xy: jax.Array) -> jax.Array:
  """Unit vector of steepest descent of the field at xy.

  Differences are one cell wide and one-sided where the other side is
  unreachable (next to a wall), so walls do not dominate the direction.

  Args:
    field: the shared NavField.
    goal: int32 [] station index.
    xy: float32 [2] point (m).

  Returns:
    float32 [2]; zero where the field is flat or unreachable.
  """
  h = field.resolution
  v0 = nav_value(field, goal, xy)

  def slope(e):
    vp, vm = nav_value(field, goal, xy + e), nav_value(field, goal, xy - e)
    okp, okm = vp < UNREACHABLE, vm < UNREACHABLE
    n = okp.astype(_F32) + okm.astype(_F32)
    total = jnp.where(okp, vp - v0, 0.0) + jnp.where(okm, v0 - vm, 0.0)
    return jnp.where(n > 0, total / jnp.maximum(n, 1.0), 0.0)

  g = -jnp.stack([slope(jnp.asarray([1.0, 0.0], _F32) * h), slope(jnp.asarray([0.0, 1.0], _F32) * h)])
  g = jnp.where(v0 < UNREACHABLE, g, 0.0)
  n = jnp.sqrt(jnp.sum(g * g))
  return jnp.where(n > 1e-9, g / jnp.where(n > 1e-9, n, 1.0), 0.0)
