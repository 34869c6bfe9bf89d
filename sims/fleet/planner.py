"""Local planner for one robot: enumerate (v, w) targets, roll out, reject, score.

Each candidate is a target twist (v, w), v in [0, max_speed] (plus one slow reverse
speed), w in [-max_yaw_rate, max_yaw_rate]; its rollout ramps from the robot's pose and
last command toward it within the acceleration limits (a unicycle, `rollout_dt` steps
over `horizon`). A candidate is rejected when a rollout point or interval midpoint lands
on a lethal (254, keepout cells included) or unknown (255) cell of the local costmap, or
on an inscribed (253) cell unless the robot stands on one (so it can back out of another
robot's inflation; `PlannerConfig.inscribed_is_collision` drops that exception, as Nav2's
controllers do for a circular robot); or when it brings the robot closer than 2 * radius
+ monitor_margin to another robot (a collision monitor in the spirit of Nav2's
FootprintApproach; moving away is always allowed).

Speed compliance at zone entry: every rollout interval [p_t, p_t+1] must have
max(|v_t|, |v_t+1|) <= the speed-mask limit at its ends and midpoint
(`jaxfilters.speed.speed_limit_at_one` per mask cell, dilated by one cell; Nav2's path
lookahead, docs/nav2_semantics.md §5.6, on the candidate's own path), and the first
interval the limit in force; the excess is penalised above every other term, so the robot
brakes *before* a slower zone. Survivors are scored by progress along the navigation
function, heading toward its descent direction, clearance (the highest cost along the
rollout), optionally the mean cost along it (`cost_weight`) and speed, plus a keep-right
rule when another robot is ahead. Reversing is used only in recovery mode or when every
forward candidate is blocked; if every candidate collides, the robot stops (it never
drives into a keepout cell).

Cost of a tick (the fleet's largest part; benchmarks/fleet_breakdown.py times it): the
candidates form a speeds x yaw rates grid, so ramps and rotations run once per axis value
(`ramp_tables`); the costmap rules are one uint16 code per cell (`lookup_table`, built at
the costmap's 5 Hz), one gather per rollout point for every rule and the costs. On the CPU
the points are materialised once (`rollout_grid`) and each rule runs over them, the
navigation value and descent stencil one gather per candidate
(`navigation.value_and_direction`); on a GPU every rule is folded into one pass over the
rollout steps (`one_pass_terms`) with elementwise navigation lookups
(`navigation.value_and_direction_xy`), writing no per-point array (`rollout_mode`).

Written for one robot; sims/fleet/env.py vmaps it over the robots of a world.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from jaxfilters.types import FilterMask
from sims.fleet import navigation, topk
from sims.fleet.config import FleetConfig

_F32 = jnp.float32
_SPEED_PENALTY = 1e3   # score per metre of speed-limit violation (dominates every other term)
_COLLISION = 1e9
_REVERSE = 1e4         # reversing outside recovery: only when every forward candidate is blocked
_MONITORED = 4         # nearest other robots the collision monitor checks


def target_axes(config: FleetConfig, extra_speeds: tuple[float, ...] = ()) -> tuple[np.ndarray, np.ndarray]:
  """The two axes of the candidate grid: target speeds and target yaw rates.

  Args:
    config: planner and robot limits.
    extra_speeds: more linear speeds to try (m/s), see `candidates`.

  Returns:
    (speeds float32 [Nv] in m/s, ascending: num_speeds in [0, max_speed], the
    extra speeds in (0, max_speed) and -reverse_speed; yaw rates float32 [Nw]
    in rad/s). `candidates` is their product, speed-major.
  """
  p, r = config.planner, config.robot
  v = np.linspace(0.0, r.max_speed, p.num_speeds)
  extra = [float(e) for e in extra_speeds if 0.0 < e < r.max_speed]
  v = np.unique(np.concatenate([v, np.asarray(extra + [-p.reverse_speed], np.float64)]))
  w = np.linspace(-r.max_yaw_rate, r.max_yaw_rate, p.num_yaw_rates) if p.num_yaw_rates > 1 else np.zeros(1)
  return v.astype(np.float32), w.astype(np.float32)


def candidates(config: FleetConfig, extra_speeds: tuple[float, ...] = ()) -> np.ndarray:
  """float32 [C, 2] target twists (v, w).

  Args:
    config: planner and robot limits.
    extra_speeds: more linear speeds to try (m/s), e.g. just under each speed
      zone's limit so robots use a zone's full allowance.

  Returns:
    C = Nv * Nw targets (`target_axes`, speed-major: candidate i * Nw + j is
    speed i, yaw rate j), Nv = num_speeds + extra speeds in (0, max_speed) + 1
    reverse speed. The reverse speed (-reverse_speed) is only used in recovery mode.
  """
  v, w = target_axes(config, extra_speeds)
  vv, ww = np.meshgrid(v, w, indexing="ij")
  return np.stack([vv.ravel(), ww.ravel()], axis=1).astype(np.float32)


def _cos_sin_small(a: jax.Array) -> tuple[jax.Array, jax.Array]:
  """cos and sin of |a| <= 0.3 rad by Taylor series (error < 3e-8; no transcendental calls)."""
  a2 = a * a
  return (1.0 - a2 * (0.5 - a2 * (1.0 / 24.0 - a2 / 720.0)),
          a * (1.0 - a2 * (1.0 / 6.0 - a2 * (1.0 / 120.0 - a2 / 5040.0))))


def _check_series(config: FleetConfig) -> None:
  r, dt = config.robot, config.planner.rollout_dt
  if r.max_yaw_rate * dt > 0.6:
    raise ValueError(f"max_yaw_rate * rollout_dt must be <= 0.6 rad for the rollout's series; "
                     f"got {r.max_yaw_rate * dt}")


def rollout_mode() -> str:
  """How `evaluate_lut` runs the candidates on this backend.

  "cumsum" or "chain": `rollout_grid` in that mode, then each rule over the
  [Nv, Nw, T] points; "fused": `one_pass_terms`, every rule folded into the
  rollout step by step. "cumsum" on CPU, "fused" elsewhere
  (benchmarks/fleet_breakdown.py times all three).
  """
  return "cumsum" if jax.default_backend() == "cpu" else "fused"


def ramp_tables(pose: jax.Array, cmd: jax.Array, speeds: jax.Array, yaw_rates: jax.Array,
                config: FleetConfig) -> dict:
  """What the candidates of a grid share: speed ramps per target speed, headings per target yaw rate.

  A candidate's speed profile depends only on its target speed and its heading
  only on its target yaw rate, so the ramps run once per speed (Nv) and the
  heading rotations once per yaw rate (Nw). Each step ramps (v, w) toward the
  target within the acceleration limits and moves along the midpoint heading,
  carried as a unit vector rotated by small-angle series (|w| dt is small), so
  no sin/cos call runs per step (they dominate the cost on CPU).

  Args:
    pose: float32 [3] (x, y, yaw); cmd: float32 [2] the last command (v, w).
    speeds: float32 [Nv] target speeds (m/s); yaw_rates: float32 [Nw] (rad/s).
    config: static FleetConfig.

  Returns:
    dict: 'v' float32 [Nv, T+1] speed profile (v[:, 0] = cmd[0]); 'mc', 'ms'
    lists of T float32 [Nw], the midpoint heading of each step; 'hc', 'hs'
    float32 [Nw] the heading at the end.
  """
  _check_series(config)
  p, r = config.planner, config.robot
  dt = p.rollout_dt
  nv, nw = speeds.shape[0], yaw_rates.shape[0]
  v = jnp.full((nv,), cmd[0])
  w = jnp.full((nw,), cmd[1])
  hc = jnp.full((nw,), jnp.cos(pose[2]))
  hs = jnp.full((nw,), jnp.sin(pose[2]))
  vs, mcs, mss = [v], [], []
  for _ in range(p.num_rollout_steps):
    v = v + jnp.clip(speeds - v, -r.max_accel * dt, r.max_accel * dt)
    w = w + jnp.clip(yaw_rates - w, -r.max_yaw_accel * dt, r.max_yaw_accel * dt)
    ch, sh = _cos_sin_small(0.5 * w * dt)
    mc, ms = hc * ch - hs * sh, hs * ch + hc * sh          # midpoint heading [Nw]
    hc, hs = mc * ch - ms * sh, ms * ch + mc * sh          # end-of-step heading
    vs.append(v), mcs.append(mc), mss.append(ms)
  return {"v": jnp.stack(vs, -1), "mc": mcs, "ms": mss, "hc": hc, "hs": hs}


def rollout_grid(pose: jax.Array, cmd: jax.Array, speeds: jax.Array, yaw_rates: jax.Array,
                 config: FleetConfig, *, mode: str | None = None) -> dict:
  """Unicycle rollouts of the candidate grid speeds x yaw_rates, with acceleration limits.

  The ramps and headings are `ramp_tables`'; each candidate's points then add
  up its steps (v_t dt) (cos, sin)(midpoint heading_t), and its interval
  midpoints are the points less half a step (positions within 1e-5 m of a
  step-by-step unicycle in float32; tests/fleet/test_planner_reference.py).

  `mode` picks how the sums run: "cumsum" (one cumulative sum over T, the
  points materialised behind an optimization barrier: XLA:CPU otherwise fuses
  the chain into every consumer) or "chain" (T dependent adds and no barrier);
  None picks "cumsum" on CPU and "chain" elsewhere (`one_pass_terms` adds the
  same steps in the chain's order).

  Args:
    pose: float32 [3] (x, y, yaw).
    cmd: float32 [2] the last command (v, w).
    speeds: float32 [Nv] target speeds (m/s); yaw_rates: float32 [Nw] (rad/s).
    config: static FleetConfig.
    mode: static "cumsum", "chain" or None (see above).

  Returns:
    dict of float32 arrays: 'x', 'y' [Nv, Nw, T] rollout points 1..T (m),
    'mx', 'my' [Nv, Nw, T] interval midpoints (m), 'v' [Nv, T+1] speed profile
    (v[:, 0] = cmd[0]), 'hc', 'hs' [Nw] heading unit vector at the end.
  """
  if mode is None:
    mode = "cumsum" if jax.default_backend() == "cpu" else "chain"
  if mode not in ("cumsum", "chain"):
    raise ValueError(f"rollout_grid mode must be 'cumsum', 'chain' or None; got {mode!r}")
  tab = ramp_tables(pose, cmd, speeds, yaw_rates, config)
  v = tab["v"]                                             # [Nv, T+1]
  vdt = v[:, 1:] * config.planner.rollout_dt               # [Nv, T]
  step_x = vdt[:, None, :] * jnp.stack(tab["mc"], -1)[None, :, :]   # [Nv, Nw, T]
  step_y = vdt[:, None, :] * jnp.stack(tab["ms"], -1)[None, :, :]
  if mode == "cumsum":
    x = pose[0] + jnp.cumsum(step_x, axis=-1)
    y = pose[1] + jnp.cumsum(step_y, axis=-1)
    out = {"x": x, "y": y, "mx": x - 0.5 * step_x, "my": y - 0.5 * step_y}
    # Materialise the points once: without the barrier XLA:CPU may fuse (recompute) the
    # sums into each of their consumers.
    out = jax.lax.optimization_barrier(out)
  else:
    xs, ys = [], []
    x, y = pose[0], pose[1]
    for t in range(config.planner.num_rollout_steps):
      x, y = x + step_x[..., t], y + step_y[..., t]
      xs.append(x), ys.append(y)
    x, y = jnp.stack(xs, -1), jnp.stack(ys, -1)
    out = {"x": x, "y": y, "mx": x - 0.5 * step_x, "my": y - 0.5 * step_y}
  return {**out, "v": v, "hc": tab["hc"], "hs": tab["hs"]}


def one_pass_terms(lut, origin, res, pose, cmd, speeds, yaw_rates, speed_cap, speed_mask: FilterMask,
                   limit_now, others, others_valid, config: FleetConfig, *, full: bool = False) -> dict:
  """Every candidate's costmap, monitor and speed terms in one pass over the rollout steps.

  The same rules as `rollout_grid` followed by `_costmap_rules`, `_monitor` and
  `_speed_lookahead`, but each step's point, midpoint, lookups and checks are
  folded into running per-candidate values (an OR and a MAX of table codes,
  the smallest distance to each monitored robot, the summed speed excess), so
  no [Nv, Nw, T] array exists: on a GPU the whole tick is elementwise work
  over [robots, Nv, Nw] that XLA can fuse into one kernel, instead of writing
  and re-reading every point per robot. Positions are the "chain" sums of
  `rollout_grid` (the same operations in the same order, up to the compiler's
  multiply-add contraction); the speed excess is summed step by step (a
  reduction may add in another order). Decisions equal the other modes'
  (tests/fleet/test_planner_reference.py).

  Args:
    lut, origin, res, pose, cmd, limit_now, others, others_valid: as `plan_lut_one`.
    speeds, yaw_rates: float32 [Nv], [Nw] the candidate grid's axes (`target_axes`).
    speed_cap, speed_mask: as `plan_lut_one`.
    config: static FleetConfig.
    full: static; also return the points 'x', 'y' float32 [Nv, Nw, T].

  Returns:
    dict: 'collide_costmap' bool [Nv, Nw], 'clearance' float32 [C], 'violation'
    float32 [C] (m/s x s), 'approach' bool [C], 'd2_end' float32 [C, m], 'neg'
    float32 [m], 'rel_near' float32 [m, 2], 'x_end', 'y_end' float32 [Nv, Nw],
    'hc', 'hs' float32 [Nw].
  """
  p = config.planner
  t_steps = p.num_rollout_steps
  tab = ramp_tables(pose, cmd, speeds, yaw_rates, config)
  v = tab["v"]
  vdt = v[:, 1:] * p.rollout_dt                                           # [Nv, T]
  interval_v = jnp.maximum(jnp.abs(v[:, 1:]), jnp.abs(v[:, :-1]))        # [Nv, T]
  near = _nearest_others(pose, others, others_valid, config)
  m = near["neg"].shape[0]
  m_origin, m_res = speed_mask.origin[0], speed_mask.resolution[0]
  rules = _blocking_flags(lut_at(lut, origin, res, pose[0], pose[1]), p.inscribed_is_collision)
  cap_prev = jnp.minimum(speed_cap_xy(speed_cap, m_origin, m_res, pose[0], pose[1]), limit_now)
  x, y = pose[0], pose[1]
  seen = top = jnp.uint16(0)
  total = jnp.int32(0)
  excess = jnp.float32(0.0)
  d2_min = [jnp.float32(jnp.inf)] * m
  xs, ys = [], []
  for t in range(t_steps):
    step_x = vdt[:, None, t] * tab["mc"][t][None, :]                      # [Nv, Nw]
    step_y = vdt[:, None, t] * tab["ms"][t][None, :]
    x, y = x + step_x, y + step_y
    mx, my = x - 0.5 * step_x, y - 0.5 * step_y
    code_mid, code_end = lut_at(lut, origin, res, mx, my), lut_at(lut, origin, res, x, y)
    seen = seen | code_mid | code_end
    top = jnp.maximum(top, jnp.maximum(code_mid, code_end))
    total = total + (code_end >> LUT_CLEARANCE_SHIFT).astype(jnp.int32) if p.cost_weight > 0 else total
    cap_end = speed_cap_xy(speed_cap, m_origin, m_res, x, y)
    cap = jnp.minimum(jnp.minimum(cap_end, cap_prev), speed_cap_xy(speed_cap, m_origin, m_res, mx, my))
    excess = excess + jnp.maximum(interval_v[:, None, t] - cap, 0.0)
    cap_prev = cap_end
    if t % 2 == (t_steps - 1) % 2:                                        # every other point, ending at T
      dx = [x - near["x"][j] for j in range(m)]
      dy = [y - near["y"][j] for j in range(m)]
      d2 = [a * a + b * b for a, b in zip(dx, dy)]
      d2_min = [jnp.minimum(a, b) for a, b in zip(d2_min, d2)]
    if full:
      xs.append(x), ys.append(y)
  c = x.shape[0] * x.shape[1]
  out = {"collide_costmap": (seen & rules) != 0,
         "clearance": (top >> LUT_CLEARANCE_SHIFT).astype(jnp.int32).reshape(-1) / 252.0,
         "violation": excess.reshape(c) * p.rollout_dt,
         "approach": _approach(jnp.stack([a.reshape(c) for a in d2_min], 1), near["neg"], config),
         "d2_end": jnp.stack([a.reshape(c) for a in d2], 1),
         "neg": near["neg"], "rel_near": near["rel"], "x_end": x, "y_end": y, "hc": tab["hc"], "hs": tab["hs"],
         **({"mean_cost": total.reshape(-1) / (252.0 * t_steps)} if p.cost_weight > 0 else {})}
  if full:
    out["x"], out["y"] = jnp.stack(xs, -1), jnp.stack(ys, -1)
  return out


def speed_cap_xy(speed_cap: jax.Array, mask_origin: jax.Array, mask_res: jax.Array, x: jax.Array,
                 y: jax.Array) -> jax.Array:
  """Speed-mask limit in m/s at points (+inf off the mask or where there is none).

  `speed_cap` holds `speed_limit_at_one`'s limit of every mask cell (see
  WorldParams), so this is one float floor and a gather per point. A point
  within float rounding of a cell edge may read the neighbouring cell; the
  interval rule (both ends of every rollout interval) makes that harmless.

  Args:
    speed_cap: float32 [Hs, Ws] m/s per speed-mask cell (+inf none).
    mask_origin: float32 [2] (m); mask_res: float32 [] metres per cell.
    x, y: float32 [...] point coordinates (m), the same shape.

  Returns:
    float32 [...] m/s cap per point; +inf off the mask (and for NaN or infinite points).
  """
  h, w = speed_cap.shape
  flat, inside = _flat_cell(x, y, mask_origin, 1.0 / mask_res, h, w)
  return jnp.where(inside, speed_cap.reshape(-1)[flat], jnp.inf)


def _flat_cell(x: jax.Array, y: jax.Array, origin: jax.Array, inv_res: jax.Array, h: int, w: int):
  """Row-major cell index of points on an h x w grid, and whether they are on it.

  Multiplies by 1 / resolution (a division costs several multiplies on a GPU):
  a point within float rounding of a cell edge may read the neighbouring cell,
  as with a division. The range check is on the floats, so NaN and infinite
  points are off the grid (XLA converts NaN to integer 0, a valid cell).

  Returns:
    (int32 [...] flat index, 0 off the grid; bool [...] on the grid).
  """
  u = jnp.floor((x - origin[0]) * inv_res)
  v = jnp.floor((y - origin[1]) * inv_res)
  inside = (u >= 0) & (u < w) & (v >= 0) & (v < h)
  return jnp.where(inside, v.astype(jnp.int32) * w + u.astype(jnp.int32), 0), inside


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


# Bits of a lookup-table code (`lookup_table`): what the planner needs of one local-costmap cell.
LUT_LETHAL = 1        # cost >= LETHAL_OBSTACLE (lethal or unknown)
LUT_HARD = 2          # `hard_cells`: the cell or one of its 8 neighbours is lethal or unknown
LUT_INSCRIBED = 4     # cost == INSCRIBED_INFLATED_OBSTACLE
LUT_CLEARANCE_SHIFT = 3   # code >> 3: the cost where it is <= MAX_NON_OBSTACLE, else 0
LUT_OUTSIDE = LUT_LETHAL | LUT_HARD   # a point outside the window: unknown (255), so lethal and hard


def lookup_table(cost: jax.Array, hard: jax.Array | None = None) -> jax.Array:
  """The planner's per-cell table of a local costmap: one uint16 code per cell.

  code = LUT_LETHAL | LUT_HARD | LUT_INSCRIBED flags | (clearance cost << 3), so
  one gather per rollout point gives every collision rule and the clearance term,
  and a candidate needs one OR and one MAX over its points. Built once per
  costmap update (5 Hz), not per controller tick.

  Args:
    cost: uint8 [N, N] local costmap.
    hard: optional uint8 [N, N] `hard_cells(cost)` (computed here when None).

  Returns:
    uint16 [N, N] codes.
  """
  if hard is None:
    hard = hard_cells(cost)
  u16 = jnp.uint16
  clear = jnp.where(cost <= constants.MAX_NON_OBSTACLE, cost.astype(u16), u16(0))
  return ((clear << LUT_CLEARANCE_SHIFT)
          | jnp.where(cost >= constants.LETHAL_OBSTACLE, u16(LUT_LETHAL), u16(0))
          | jnp.where(hard > 0, u16(LUT_HARD), u16(0))
          | jnp.where(cost == constants.INSCRIBED_INFLATED_OBSTACLE, u16(LUT_INSCRIBED), u16(0)))


def lut_at(lut: jax.Array, origin: jax.Array, res: jax.Array, x: jax.Array, y: jax.Array) -> jax.Array:
  """Lookup-table codes at points; LUT_OUTSIDE outside the window (unknown, 255).

  Args:
    lut: uint16 [N, N] `lookup_table` of a local costmap.
    origin: float32 [2] window origin (m); res: float32 [] metres per cell.
    x, y: float32 [...] point coordinates (m), the same shape.

  Returns:
    uint16 [...] codes.
  """
  n_rows, n_cols = lut.shape
  flat, inside = _flat_cell(x, y, origin, 1.0 / res, n_rows, n_cols)
  return jnp.where(inside, lut.reshape(-1)[flat], jnp.uint16(LUT_OUTSIDE))


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
             nav: navigation.NavField, speed_mask: FilterMask, speed_cap: jax.Array, *,
             config: FleetConfig, extra_speeds: tuple[float, ...] = ()):
  """Chooses this control tick's command for one robot.

  Builds the costmap's `lookup_table` and runs `plan_lut_one`; a caller that
  plans several ticks on one costmap (sims/fleet/env.py) builds the table once and
  calls `plan_lut_one` directly.

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
  return plan_lut_one(pose, cmd, goal, limit_now, recovering, lookup_table(cost, hard), origin, res, others,
                      others_valid, nav, speed_mask, speed_cap, config=config, extra_speeds=extra_speeds)


def plan_lut_one(pose, cmd, goal, limit_now, recovering, lut, origin, res, others, others_valid,
                 nav: navigation.NavField, speed_mask: FilterMask, speed_cap: jax.Array, *,
                 config: FleetConfig, extra_speeds: tuple[float, ...] = ()):
  """`plan_one` on the costmap's `lookup_table`, built once per costmap update (sims/fleet/env.py).

  Args:
    pose: float32 [3] robot (x m, y m, yaw rad); a non-finite pose stops the robot.
    cmd: float32 [2] last command (v m/s, w rad/s).
    goal: int32 [] station index.
    limit_now: float32 [] speed cap in force (m/s, +inf none).
    recovering: bool [] recovery mode.
    lut: uint16 [N, N] `lookup_table` of the robot's local costmap; origin float32 [2] (m);
      res float32 [] (m per cell).
    others: float32 [K, 2] positions of the world's robots (m); others_valid bool [K].
    nav, speed_mask, speed_cap, config, extra_speeds: as `plan_one`.

  Returns:
    (command float32 [2], info dict: 'stopped' bool [], 'speed_violation' float32 [] m/s x s),
    as `plan_one`.
  """
  ev = evaluate_lut(pose, cmd, goal, limit_now, recovering, lut, origin, res, others, others_valid, nav,
                    speed_mask, speed_cap, config=config, extra_speeds=extra_speeds, full=False)
  r = config.robot
  best = first_argmin(ev["score"])
  stopped = ev["collide"][best]
  dt = config.control_dt
  target = ev["targets"][best]
  new_v = cmd[0] + jnp.clip(target[0] - cmd[0], -r.max_accel * dt, r.max_accel * dt)
  new_w = cmd[1] + jnp.clip(target[1] - cmd[1], -r.max_yaw_accel * dt, r.max_yaw_accel * dt)
  command = jnp.where(stopped, jnp.zeros((2,), _F32), jnp.stack([new_v, new_w]).astype(_F32))
  return command, {"stopped": stopped, "speed_violation": jnp.where(stopped, 0.0, ev["violation"][best])}


def first_argmin(score: jax.Array) -> jax.Array:
  """jnp.argmin of a 1-D array (the first minimum, or the first NaN) as a min and a masked index min.

  XLA:CPU lowers argmin to a variadic (value, index) reduce that is several
  times slower than two plain reductions.
  """
  c = score.shape[0]
  low = jnp.min(score)
  idx = jnp.arange(c, dtype=jnp.int32)
  return jnp.min(jnp.where((score == low) | jnp.isnan(score), idx, c))


def evaluate(pose, cmd, goal, limit_now, recovering, cost, hard, origin, res, others, others_valid,
             nav: navigation.NavField, speed_mask: FilterMask, speed_cap: jax.Array, *,
             config: FleetConfig, extra_speeds: tuple[float, ...] = ()) -> dict:
  """Every candidate's rollout, checks and score terms (arguments as `plan_one`).

  Returns:
    dict of per-candidate arrays: targets [C, 2], xy [C, T+1, 2], collide [C],
    violation [C] (excess speed integrated over the rollout, m/s x s), progress,
    heading, clearance, score [C].
  """
  return evaluate_lut(pose, cmd, goal, limit_now, recovering, lookup_table(cost, hard), origin, res, others,
                      others_valid, nav, speed_mask, speed_cap, config=config, extra_speeds=extra_speeds)


def evaluate_lut(pose, cmd, goal, limit_now, recovering, lut, origin, res, others, others_valid,
                 nav: navigation.NavField, speed_mask: FilterMask, speed_cap: jax.Array, *,
                 config: FleetConfig, extra_speeds: tuple[float, ...] = (), full: bool = True) -> dict:
  """`evaluate` on the costmap's `lookup_table`.

  Args:
    pose, cmd, goal, limit_now, recovering, lut, origin, res, others, others_valid, nav,
      speed_mask, speed_cap, config, extra_speeds: as `plan_lut_one`.
    full: static; False leaves out 'xy', which only plots and tests read.

  Returns:
    dict of per-candidate arrays (C = Nv * Nw, speed-major): targets float32 [C, 2],
    xy float32 [C, T+1, 2] (m, only with full), collide bool [C], violation float32 [C]
    (m/s x s), progress, heading, clearance, score float32 [C]; with
    `PlannerConfig.cost_weight` > 0 also mean_cost float32 [C].
  """
  p, r = config.planner, config.robot
  speeds_np, yaw_rates_np = target_axes(config, extra_speeds)
  nv, nw = speeds_np.shape[0], yaw_rates_np.shape[0]
  c = nv * nw
  targets = jnp.asarray(candidates(config, extra_speeds))
  speeds, yaw_rates = jnp.asarray(speeds_np), jnp.asarray(yaw_rates_np)
  mode = rollout_mode()
  if mode == "fused":
    t = one_pass_terms(lut, origin, res, pose, cmd, speeds, yaw_rates, speed_cap, speed_mask, limit_now,
                       others, others_valid, config, full=full)
    collide, clearance, violation = t["collide_costmap"], t["clearance"], t["violation"]
    mean_cost = t.get("mean_cost")
    approach, d2_end, neg, rel_near = t["approach"], t["d2_end"], t["neg"], t["rel_near"]
    x_end, y_end, hc, hs = t["x_end"], t["y_end"], t["hc"], t["hs"]
    x, y = t.get("x"), t.get("y")
  else:
    with jax.named_scope("rollout"):
      ro = rollout_grid(pose, cmd, speeds, yaw_rates, config, mode=mode)
    x, y, mx, my, v = ro["x"], ro["y"], ro["mx"], ro["my"], ro["v"]      # [Nv, Nw, T] x4, [Nv, T+1]
    with jax.named_scope("costmap_rules"):
      collide, clearance = _costmap_rules(lut, origin, res, pose, x, y, mx, my,
                                          inscribed_is_collision=p.inscribed_is_collision)
      mean_cost = (jnp.sum((lut_at(lut, origin, res, x, y) >> LUT_CLEARANCE_SHIFT).astype(jnp.int32), axis=-1)
                   .reshape(-1) / (252.0 * x.shape[-1]) if p.cost_weight > 0 else None)   # as one_pass_terms
    with jax.named_scope("monitor"):
      near = _nearest_others(pose, others, others_valid, config)
      approach, d2_end = _monitor(pose, near, x, y, config)
      neg, rel_near = near["neg"], near["rel"]
    with jax.named_scope("speed_lookahead"):
      violation = _speed_lookahead(speed_cap, speed_mask, pose, limit_now, x, y, mx, my, v, config)
    x_end, y_end, hc, hs = x[..., -1], y[..., -1], ro["hc"], ro["hs"]

  def flat(a):  # [Nv, Nw, ...] -> [C, ...], candidate i * Nw + j
    return a.reshape((c,) + a.shape[2:])

  collide = flat(collide) | approach
  with jax.named_scope("navigation"):
    start_val = navigation.nav_value(nav, goal, pose[:2])
    head_c, head_s = jnp.broadcast_to(hc, (nv, nw)).reshape(c), jnp.broadcast_to(hs, (nv, nw)).reshape(c)
    if mode == "fused":   # elementwise: no [C, 2] or stencil arrays between the GPU's kernels
      end_val, dx, dy = navigation.value_and_direction_xy(nav, goal, flat(x_end), flat(y_end))
      along = head_c * dx + head_s * dy
    else:
      end = jnp.stack([flat(x_end), flat(y_end)], axis=1)                     # [C, 2]
      end_val, desired = jax.vmap(lambda q: navigation.value_and_direction(nav, goal, q))(end)
      along = jnp.sum(jnp.stack([head_c, head_s], axis=1) * desired, axis=1)

  with jax.named_scope("score"):
    reach = r.max_speed * p.horizon
    progress = (end_val - start_val) / reach
    heading = 0.5 * (1.0 - along)
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
    d_end = jnp.sqrt(jnp.min(jnp.where(jnp.isfinite(neg)[None, :], d2_end, jnp.inf), axis=1))
    separation = -jnp.minimum(d_end, 2.0) / 2.0
    recovery = 0.3 * p.progress_weight * progress + separation + 0.2 * targets[:, 1] / r.max_yaw_rate
    mean_term = (p.cost_weight * mean_cost,) if p.cost_weight > 0 else ()   # no op at all when 0
    score = sum(mean_term, jnp.where(recovering, recovery, normal)
                + p.clearance_weight * clearance + p.speed_weight * speed_term
                + _SPEED_PENALTY * violation + jnp.where(collide, _COLLISION, 0.0))
  out = {"targets": targets, "collide": collide, "violation": violation,
         "progress": progress, "heading": heading, "clearance": clearance, "score": score,
         **({"mean_cost": mean_cost} if p.cost_weight > 0 else {})}
  if full:
    xs = jnp.concatenate([jnp.full((c, 1), pose[0]), flat(x)], axis=1)
    ys = jnp.concatenate([jnp.full((c, 1), pose[1]), flat(y)], axis=1)
    out["xy"] = jnp.stack([xs, ys], axis=-1)
  return out


def _costmap_rules(lut, origin, res, pose, x, y, mx, my, *, inscribed_is_collision: bool = False):
  """Collision against the local costmap and the clearance term, per candidate [Nv, Nw].

  Checked at rollout points and interval midpoints (at most half a cell apart up
  to 0.5 m/s at 0.05 m cells). Lethal and unknown cells are also blocked one cell
  around (keepout cells are lethal but not inflated), so a path cannot clip a
  keepout corner between two samples. One table code per point carries every rule.
  With `inscribed_is_collision` (static; Nav2's controllers for a circular robot) an
  inscribed cell blocks even a robot that stands on one.
  """
  code_mid = lut_at(lut, origin, res, mx, my)                     # [Nv, Nw, T]
  code_end = lut_at(lut, origin, res, x, y)
  rules = _blocking_flags(lut_at(lut, origin, res, pose[0], pose[1]), inscribed_is_collision)
  seen = (jax.lax.reduce(code_mid, jnp.uint16(0), jax.lax.bitwise_or, (2,))
          | jax.lax.reduce(code_end, jnp.uint16(0), jax.lax.bitwise_or, (2,)))
  top = jnp.maximum(jnp.max(code_mid, axis=-1), jnp.max(code_end, axis=-1))
  return (seen & rules) != 0, (top >> LUT_CLEARANCE_SHIFT).astype(jnp.int32).reshape(-1) / 252.0


def _nearest_others(pose, others, others_valid, config: FleetConfig) -> dict:
  """The collision monitor's robots: the nearest `_MONITORED` others and their distances now.

  Returns:
    dict: 'neg' float32 [m] minus the squared distances now (-inf where fewer
    than m others), 'rel' float32 [m, 2] their positions relative to the robot,
    'x', 'y' float32 [m] their positions.
  """
  rel_now = others - pose[None, :2]
  d2_now = jnp.where(others_valid, jnp.sum(rel_now * rel_now, axis=-1), jnp.inf)   # [K]
  m = min(_MONITORED, others.shape[0])
  neg, near = topk.top_k(-d2_now, m)      # lax.top_k would gather a sharded batch
  return {"neg": neg, "rel": rel_now[near], "x": others[near, 0], "y": others[near, 1]}


def _blocking_flags(here, inscribed_is_collision: bool):
  """uint16 []: table flags that block a candidate for a robot on code `here`: lethal/unknown always; a hard
  cell unless it stands on one; an inscribed cell unless on an inscribed or lethal one (or `inscribed_is_collision`)."""
  return (jnp.uint16(LUT_LETHAL)
          | jnp.where((here & LUT_HARD) == 0, jnp.uint16(LUT_HARD), jnp.uint16(0))
          | jnp.where(((here & (LUT_INSCRIBED | LUT_LETHAL)) == 0) | inscribed_is_collision,
                      jnp.uint16(LUT_INSCRIBED), jnp.uint16(0)))


def _monitor(pose, near: dict, x, y, config: FleetConfig):
  """Collision monitor against the nearest other robots' current positions (`_nearest_others`).

  Squared distances at every other rollout point (at most 0.1 m apart at 0.5 m/s),
  ending at the last one.

  Returns:
    (approach bool [C]: the candidate comes too close to one of them; d2_end float32
    [C, m] squared distance of the last point to each).
  """
  c, t = x.shape[0] * x.shape[1], x.shape[-1]
  m = near["neg"].shape[0]
  sel = slice(1 - t % 2, t, 2)                                   # points 2 - T % 2, ..., T (ends at T)
  ox, oy = near["x"], near["y"]                                   # [m]
  # [m, Nv, Nw, ~T/2]: the points innermost, so the squares and the min run along contiguous memory.
  dx = x[None, ..., sel] - ox[:, None, None, None]
  dy = y[None, ..., sel] - oy[:, None, None, None]
  d2_path = dx * dx + dy * dy
  d2_min = jnp.min(d2_path, axis=-1).reshape(m, c).T             # [C, m]
  d2_last = d2_path[..., -1].reshape(m, c).T
  return _approach(d2_min, near["neg"], config), d2_last


def _approach(d2_min, neg, config: FleetConfig):
  """bool [C]: a candidate's path comes closer than 2 radius + margin to a monitored robot it is not
  already closer to (moving away is always allowed). d2_min float32 [C, m], neg float32 [m]."""
  p, r = config.planner, config.robot
  safe2 = (2.0 * r.radius + p.monitor_margin) ** 2
  approach = jnp.isfinite(neg)[None, :] & (d2_min < safe2) & (d2_min < -neg[None, :] - 1e-4)
  return jnp.any(approach, axis=1)


def _speed_lookahead(speed_cap, speed_mask, pose, limit_now, x, y, mx, my, v, config: FleetConfig):
  """Excess speed integrated over each rollout (m/s x s), per candidate [C].

  Every interval's speed against the strictest (dilated) mask limit at its ends and
  midpoint; the first interval also under the limit in force. Integrated, not the
  worst interval: when the first interval is already too fast (a zone met at a
  shallow angle), candidates that brake still score better than those that do not.
  """
  nv, nw = x.shape[0], x.shape[1]
  m_origin, m_res = speed_mask.origin[0], speed_mask.resolution[0]
  cap0 = jnp.minimum(speed_cap_xy(speed_cap, m_origin, m_res, pose[0], pose[1]), limit_now)   # every start
  cap_end = speed_cap_xy(speed_cap, m_origin, m_res, x, y)                         # [Nv, Nw, T]
  cap_mid = speed_cap_xy(speed_cap, m_origin, m_res, mx, my)
  cap_start = jnp.concatenate([jnp.broadcast_to(cap0, (nv, nw, 1)), cap_end[..., :-1]], axis=-1)
  interval_cap = jnp.minimum(jnp.minimum(cap_end, cap_start), cap_mid)
  interval_v = jnp.maximum(jnp.abs(v[:, 1:]), jnp.abs(v[:, :-1]))                 # [Nv, T]
  excess = jnp.maximum(interval_v[:, None, :] - interval_cap, 0.0).reshape(nv * nw, -1)
  return jnp.sum(excess, axis=1) * config.planner.rollout_dt
