"""The fleet step's faster navigation stack chooses what the straightforward one chose.

reference/planner.py keeps the planner and navigation-field lookups as
they were before the performance work. Here the current code runs on the same
inputs (robots at random free poses of the built-in warehouse, several close
together so the collision monitor and the robots layer matter, some inside or
beside keepout zones and speed zones, random commands, goals, limits in force
and recovery flags) and must make the same decisions: the same collisions, clearance and
violation terms and chosen commands, with the float terms within rounding (the
rollout sums positions in another order; see `_assert_same_decisions`); plus
the parts on their own: the shared-work rollout, the packed lookup table, the
one-gather navigation stencil and the argmin.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfilters import constants
from jaxfilters.keepout import KeepoutState
from sims.fleet import local_costmap, navigation, planner
from sims.fleet.config import FleetConfig, PlannerConfig
from sims.fleet.env import FleetEnv
from reference import planner as ref

K = 6   # robots per cluster (one local costmap build)


@pytest.fixture(scope="module")
def env() -> FleetEnv:
  return FleetEnv.create(config=FleetConfig(robots_per_world=K))


def _situations(env: FleetEnv, seed: int, clusters: int):
  """Robots at random poses with their local costmaps: leaves [clusters, K, ...]."""
  w, p, cfg = env.world, env.params, env.config
  rng = np.random.default_rng(seed)
  cost = np.asarray(w.global_cost)
  res = float(p.map_resolution)
  origin = np.asarray(p.map_origin, np.float64)
  # Centres: free cells, a third of them on the edge of an obstacle, keepout or zone.
  free = np.argwhere(cost < constants.INSCRIBED_INFLATED_OBSTACLE)
  near_wall = np.argwhere((cost > 100) & (cost < constants.INSCRIBED_INFLATED_OBSTACLE))
  assert p.speed_cap.shape == cost.shape and np.array_equal(p.speed.origin[0], p.map_origin)  # one grid
  zone = np.argwhere(np.asarray(p.speed_cap) < 1.0)
  pools = [free, near_wall, zone if zone.size else free]
  poses = np.zeros((clusters, K, 3), np.float32)
  for c in range(clusters):
    pool = pools[c % 3]
    r0, c0 = pool[rng.integers(len(pool))]
    centre = origin + (np.array([c0, r0]) + 0.5) * res
    for k in range(K):
      # 0.3-1.2 m apart: inside each other's windows and the monitor's range.
      poses[c, k, :2] = centre + rng.uniform(-0.9, 0.9, 2) * (k > 0)
      poses[c, k, 2] = rng.uniform(-np.pi, np.pi)
  # One robot in five anywhere on the map (possibly on a wall, in a keepout zone or off the map).
  wild = rng.random((clusters, K)) < 0.2
  lo, hi = origin - 1.0, origin + np.array(cost.shape[::-1]) * res + 1.0
  poses[..., :2] = np.where(wild[..., None], rng.uniform(lo, hi, (clusters, K, 2)), poses[..., :2])

  def build(q):
    cm, _ = local_costmap.local_costmaps(
        p.static_cost, p.map_origin, p.map_resolution, w.pad, p.keepout, q, KeepoutState.create(K),
        n=w.window_cells, robot_radius=cfg.robot.radius, inflation=w.inflation)
    return cm

  cm = jax.jit(jax.vmap(build))(jnp.asarray(poses))
  r = cfg.robot
  cmd = np.stack([rng.uniform(-0.15, r.max_speed, (clusters, K)),
                  rng.uniform(-r.max_yaw_rate, r.max_yaw_rate, (clusters, K))], -1).astype(np.float32)
  cmd[rng.random((clusters, K)) < 0.2] = 0.0
  limit = np.where(rng.random((clusters, K)) < 0.3, rng.choice([0.15, 0.25, 0.35], (clusters, K)), np.inf)
  return dict(pose=jnp.asarray(poses), cmd=jnp.asarray(cmd),
              goal=jnp.asarray(rng.integers(0, p.nav.num_stations, (clusters, K)), jnp.int32),
              limit=jnp.asarray(limit, jnp.float32), recovering=jnp.asarray(rng.random((clusters, K)) < 0.25),
              cost=cm.cost, origin=cm.origin, res=cm.resolution)


def _run_both(env: FleetEnv, s: dict, config: FleetConfig, *, plans: bool = True):
  p = env.params
  extra = env.zone_speeds
  valid = ~jnp.eye(K, dtype=bool)

  def one_cluster(pose, cmd, goal, limit, rec, cost, origin, res):
    def new(q, c, g, lim, rc, cm, o, rs, ok):
      lut = planner.lookup_table(cm)
      ev = planner.evaluate_lut(q, c, g, lim, rc, lut, o, rs, pose[:, :2], ok, p.nav, p.speed, p.speed_cap,
                                config=config, extra_speeds=extra)
      if not plans:
        return ev, _plan_from(ev, c, config)
      out = planner.plan_lut_one(q, c, g, lim, rc, lut, o, rs, pose[:, :2], ok, p.nav, p.speed,
                                 p.speed_cap, config=config, extra_speeds=extra)
      return ev, out

    def old(q, c, g, lim, rc, cm, o, rs, ok):
      hard = ref.hard_cells(cm)
      ev = ref.evaluate(q, c, g, lim, rc, cm, hard, o, rs, pose[:, :2], ok, p.nav, p.speed, p.speed_cap,
                        config=config, extra_speeds=extra)
      if not plans:
        return ev, _plan_from(ev, c, config)
      out = ref.plan_one(q, c, g, lim, rc, cm, hard, o, rs, pose[:, :2], ok, p.nav, p.speed, p.speed_cap,
                         config=config, extra_speeds=extra)
      return ev, out

    args = (pose, cmd, goal, limit, rec, cost, origin, res, valid)
    return jax.vmap(new)(*args), jax.vmap(old)(*args)

  return jax.jit(jax.vmap(one_cluster))(s["pose"], s["cmd"], s["goal"], s["limit"], s["recovering"],
                                        s["cost"], s["origin"], s["res"])


def _plan_from(ev, cmd, config):
  """plan_one's choice from an evaluate dict (the other grid's test compiles evaluate only)."""
  best = jnp.argmin(ev["score"])
  r, dt = config.robot, config.control_dt
  target = ev["targets"][best]
  new = jnp.stack([cmd[0] + jnp.clip(target[0] - cmd[0], -r.max_accel * dt, r.max_accel * dt),
                   cmd[1] + jnp.clip(target[1] - cmd[1], -r.max_yaw_accel * dt, r.max_yaw_accel * dt)])
  stopped = ev["collide"][best]
  return (jnp.where(stopped, 0.0, new), {"stopped": stopped,
                                        "speed_violation": jnp.where(stopped, 0.0, ev["violation"][best])})


def _near_edge(xy, origin, res, tol=2e-5):
  """bool [...]: a point of the candidate (rollout point or interval midpoint) within tol m of a cell edge."""
  pts = np.concatenate([xy[..., 1:, :], 0.5 * (xy[..., 1:, :] + xy[..., :-1, :])], axis=-2)
  u = (pts - origin[..., None, None, :]) / res[..., None, None, None]
  frac = u - np.floor(u)
  return np.any(np.minimum(frac, 1.0 - frac) * res[..., None, None, None] < tol, axis=(-1, -2))


def _assert_same_decisions(new, old, s, env):
  """The current planner against the reference: equal decisions, float terms within rounding.

  Positions are summed in another order (rollout_grid), so points move by float
  rounding (< 1e-5 m); a candidate with a point within 2e-5 m of a costmap or
  speed-mask cell edge may read the neighbouring cell, so its discrete terms are
  compared only when it has none. Commands must be equal wherever the reference's
  best candidate wins by more than 1e-3 (nearly all robots).
  """
  (ev, (cmd, info)), (ev_r, (cmd_r, info_r)) = jax.tree.map(np.asarray, (new, old))
  np.testing.assert_array_equal(ev["targets"], ev_r["targets"])
  np.testing.assert_allclose(ev["xy"], ev_r["xy"], atol=2e-5)
  res = np.asarray(s["res"], np.float64)
  ambiguous = (_near_edge(ev_r["xy"], np.asarray(s["origin"], np.float64), res)
               | _near_edge(ev_r["xy"], np.broadcast_to(np.asarray(env.params.speed.origin[0], np.float64),
                                                        np.shape(s["origin"])),
                            np.broadcast_to(np.asarray(env.params.speed.resolution[0], np.float64), res.shape)))
  assert ambiguous.mean() < 0.5
  clear = ~ambiguous
  for key in ("collide", "clearance"):
    np.testing.assert_array_equal(ev[key][clear], ev_r[key][clear], err_msg=key)
  # The speed excess is a float sum over the intervals; one-pass planning adds it in another order.
  np.testing.assert_allclose(ev["violation"][clear], ev_r["violation"][clear], rtol=1e-6, atol=1e-7)
  np.testing.assert_allclose(ev["progress"], ev_r["progress"], atol=1e-4)
  np.testing.assert_allclose(ev["heading"], ev_r["heading"], atol=2e-3)
  free = ~ev["collide"] & ~ev_r["collide"]
  np.testing.assert_allclose(ev["score"][free], ev_r["score"][free], rtol=1e-5, atol=1e-3)
  top2 = np.sort(ev_r["score"], axis=-1)[..., :2]
  same_terms = np.all((ev["collide"] == ev_r["collide"]) & (ev["clearance"] == ev_r["clearance"])
                      & np.isclose(ev["violation"], ev_r["violation"], rtol=1e-6, atol=1e-7), axis=-1)
  stopped_both = np.all(ev_r["collide"], axis=-1)       # every candidate blocked: the command is 0 anyway
  decided = ((top2[..., 1] - top2[..., 0] > 1e-3) | stopped_both) & same_terms
  assert decided.mean() > 0.8, (decided.mean(), (top2[..., 1] - top2[..., 0]).ravel())
  np.testing.assert_array_equal(cmd[decided], cmd_r[decided])
  np.testing.assert_array_equal(info["stopped"][decided], info_r["stopped"][decided])
  np.testing.assert_allclose(info["speed_violation"][decided], info_r["speed_violation"][decided], atol=1e-6)


def test_planner_matches_reference(env):
  s = _situations(env, seed=0, clusters=12)
  new, old = _run_both(env, s, env.config)
  _assert_same_decisions(new, old, s, env)
  # The cases are not trivial: some candidates collide, some robots stop, some violate, all rules fire.
  ev, (cmd, info) = jax.tree.map(np.asarray, new)
  assert ev["collide"].any() and not ev["collide"].all()
  assert info["stopped"].any() and not info["stopped"].all()
  assert (ev["violation"] > 0).any()
  assert (ev["clearance"] > 0).any()
  assert len(np.unique(cmd.reshape(-1, 2), axis=0)) > 10


def test_one_pass_planner_matches_reference(env, monkeypatch):
  """The GPU's default mode (`planner.one_pass_terms`), run here on the CPU."""
  monkeypatch.setattr(planner, "rollout_mode", lambda: "fused")
  s = _situations(env, seed=3, clusters=8)
  new, old = _run_both(env, s, env.config)
  _assert_same_decisions(new, old, s, env)
  ev, (_, info) = jax.tree.map(np.asarray, new)
  assert ev["collide"].any() and (ev["violation"] > 0).any() and info["stopped"].any()


def test_planner_matches_reference_other_grids(env):
  """Another candidate grid (even yaw-rate count, odd rollout length) and angular limits."""
  cfg = dataclasses.replace(env.config, planner=PlannerConfig(num_speeds=4, num_yaw_rates=6, horizon=1.2))
  assert cfg.planner.num_rollout_steps == 12
  s = _situations(env, seed=1, clusters=6)
  new, old = _run_both(env, s, cfg, plans=False)
  _assert_same_decisions(new, old, s, env)


@pytest.mark.parametrize("mode", ["cumsum", "chain"])
def test_rollout_grid_equals_rollout(mode):
  cfg = FleetConfig()
  speeds, rates = planner.target_axes(cfg, (0.2475, 0.1485))
  targets = planner.candidates(cfg, (0.2475, 0.1485))
  rng = np.random.default_rng(3)
  for _ in range(4):
    pose = jnp.asarray(rng.uniform([-10, -10, -np.pi], [10, 10, np.pi]), jnp.float32)
    cmd = jnp.asarray(rng.uniform([-0.15, -1.5], [0.5, 1.5]), jnp.float32)
    xy, head, v = jax.jit(ref.rollout, static_argnums=3)(pose, cmd, jnp.asarray(targets), cfg)
    g = jax.jit(planner.rollout_grid, static_argnums=4, static_argnames="mode")(
        pose, cmd, jnp.asarray(speeds), jnp.asarray(rates), cfg, mode=mode)
    nv, nw = len(speeds), len(rates)
    np.testing.assert_allclose(np.asarray(g["x"]).reshape(nv * nw, -1), np.asarray(xy[:, 1:, 0]), atol=1e-5)
    np.testing.assert_allclose(np.asarray(g["y"]).reshape(nv * nw, -1), np.asarray(xy[:, 1:, 1]), atol=1e-5)
    mids = 0.5 * (xy[:, 1:] + xy[:, :-1])
    np.testing.assert_allclose(np.asarray(g["mx"]).reshape(nv * nw, -1), np.asarray(mids[..., 0]), atol=1e-5)
    np.testing.assert_allclose(np.asarray(g["my"]).reshape(nv * nw, -1), np.asarray(mids[..., 1]), atol=1e-5)
    np.testing.assert_array_equal(np.asarray(g["v"]), np.asarray(v).reshape(nv, nw, -1)[:, 0])
    np.testing.assert_array_equal(np.tile(np.asarray(g["hc"]), nv), np.asarray(head[:, 0]))
    np.testing.assert_array_equal(np.tile(np.asarray(g["hs"]), nv), np.asarray(head[:, 1]))
    np.testing.assert_array_equal(targets, ref.candidates(cfg, (0.2475, 0.1485)))


def test_lookup_table_codes():
  """Every cost value, with and without a hard neighbour, against the rules written out in Python."""
  rng = np.random.default_rng(4)
  cost = rng.integers(0, 253, (40, 40)).astype(np.uint8)
  special = rng.random((40, 40))
  cost[special < 0.15] = rng.choice([253, 254, 255], int((special < 0.15).sum())).astype(np.uint8)
  cost[:16, :16] = np.arange(256, dtype=np.uint8).reshape(16, 16)
  hard = np.asarray(ref.hard_cells(jnp.asarray(cost)))
  lut = np.asarray(planner.lookup_table(jnp.asarray(cost)))
  np.testing.assert_array_equal(lut, np.asarray(planner.lookup_table(jnp.asarray(cost), jnp.asarray(hard))))
  assert lut.dtype == np.uint16
  for (i, j), c in np.ndenumerate(cost):
    c = int(c)
    want = ((c if c <= 252 else 0) << 3) | (c >= 254) | (2 if hard[i, j] else 0) | (4 if c == 253 else 0)
    assert lut[i, j] == want, (i, j, c)
  assert 0 < hard.mean() < 1


def test_lut_at_and_speed_cap_xy_match_the_2d_lookups():
  """The flat lookups read the reference's cells (points within 1e-5 m of a cell edge may read either)."""
  rng = np.random.default_rng(5)
  cost = jnp.asarray(rng.integers(0, 256, (30, 30)).astype(np.uint8))
  origin, res = jnp.asarray([1.0, -2.0], jnp.float32), jnp.asarray(0.05, jnp.float32)
  pts = np.asarray(rng.uniform([0.8, -2.2], [2.7, -0.3], (2000, 2)), np.float32)      # some outside
  u = (pts.astype(np.float64) - np.asarray(origin, np.float64)) / 0.05
  pts = jnp.asarray(pts[np.all(np.abs(u - np.round(u)) * 0.05 > 1e-5, axis=1)])
  lut = planner.lookup_table(cost)
  got = np.asarray(planner.lut_at(lut, origin, res, pts[:, 0], pts[:, 1]))
  c = np.asarray(ref.local_cost_at(cost, origin, res, pts))
  h = np.asarray(ref.local_cost_at(ref.hard_cells(cost), origin, res, pts))
  np.testing.assert_array_equal(got & planner.LUT_LETHAL, (c >= 254).astype(int))
  np.testing.assert_array_equal((got & planner.LUT_HARD) > 0, h > 0)
  np.testing.assert_array_equal((got & planner.LUT_INSCRIBED) > 0, c == 253)
  np.testing.assert_array_equal(got >> planner.LUT_CLEARANCE_SHIFT, np.where(c <= 252, c, 0))
  off = np.any((np.asarray(pts) < np.asarray(origin)) | (np.asarray(pts) >= np.asarray(origin) + 1.5), axis=1)
  assert off.sum() > 50 and np.all(got[off] == planner.LUT_OUTSIDE)
  cap = jnp.asarray(rng.uniform(0.1, 0.5, (20, 25)), jnp.float32).at[3, 4].set(jnp.inf)
  np.testing.assert_array_equal(np.asarray(planner.speed_cap_xy(cap, origin, res, pts[:, 0], pts[:, 1])),
                                np.asarray(ref.speed_cap_at(cap, origin, res, pts)))
  nan = planner.lut_at(lut, origin, res, jnp.asarray([jnp.nan, 1.5]), jnp.asarray([-1.0, jnp.nan]))
  assert np.all(np.asarray(nan) == planner.LUT_OUTSIDE)


def test_value_and_direction_matches_nav_value_and_descent_direction(env):
  """One gather for the five stencil points; the same values, directions within rounding."""
  nav = env.params.nav
  rng = np.random.default_rng(7)
  lo = np.asarray(nav.origin) - 1.0
  hi = np.asarray(nav.origin) + np.asarray(nav.dist.shape[:0:-1]) * float(nav.resolution) + 1.0
  xy = jnp.asarray(rng.uniform(lo, hi, (3000, 2)), jnp.float32)        # some off the grid, some on walls
  goal = jnp.asarray(rng.integers(0, nav.num_stations, 3000), jnp.int32)
  val, d = jax.jit(jax.vmap(lambda g, q: navigation.value_and_direction(nav, g, q)))(goal, xy)
  val_r = jax.vmap(lambda g, q: ref.nav_value(nav, g, q))(goal, xy)
  d_r = jax.vmap(lambda g, q: ref.descent_direction(nav, g, q))(goal, xy)
  np.testing.assert_allclose(np.asarray(val), np.asarray(val_r), rtol=1e-6)   # XLA may contract a*b+c (FMA)
  np.testing.assert_allclose(np.asarray(d), np.asarray(d_r), atol=1e-4)
  assert (np.asarray(val) == navigation.UNREACHABLE).any() and (np.asarray(val) < 50).any()
  # The elementwise form of the one-pass planner.
  val_e, dx, dy = jax.jit(jax.vmap(lambda g, q: navigation.value_and_direction_xy(nav, g, q[0], q[1])))(goal, xy)
  np.testing.assert_allclose(np.asarray(val_e), np.asarray(val_r), rtol=1e-6)
  np.testing.assert_allclose(np.stack([dx, dy], 1), np.asarray(d_r), atol=1e-4)


def test_planner_stops_a_robot_with_a_non_finite_pose(env):
  """A NaN or infinite pose reads as off the costmap: every candidate is blocked, the robot stops (flagged)."""
  s = _situations(env, seed=2, clusters=1)
  p, cfg = env.params, env.config
  pose = np.array(s["pose"][0])
  pose[0, 0], pose[1, 2], pose[2, 1] = np.nan, np.nan, np.inf
  lut = jax.vmap(planner.lookup_table)(s["cost"][0])
  plan = jax.jit(jax.vmap(lambda q, c, g, lut, o, rs, ok: planner.plan_lut_one(
      q, c, g, jnp.inf, False, lut, o, rs, jnp.asarray(pose[:, :2]), ok, p.nav, p.speed, p.speed_cap,
      config=cfg, extra_speeds=env.zone_speeds)))
  cmd, info = plan(jnp.asarray(pose), s["cmd"][0], s["goal"][0], lut, s["origin"][0], s["res"][0],
                   ~jnp.eye(K, dtype=bool))
  cmd, stopped = np.asarray(cmd), np.asarray(info["stopped"])
  assert stopped[:3].all() and np.all(cmd[:3] == 0.0)
  assert np.all(np.isfinite(cmd))


def test_rollout_grid_rejects_an_unknown_mode():
  cfg = FleetConfig()
  with pytest.raises(ValueError, match="'cumsum', 'chain' or None; got 'scan'"):
    planner.rollout_grid(jnp.zeros(3), jnp.zeros(2), jnp.zeros(2), jnp.zeros(3), cfg, mode="scan")


@pytest.mark.parametrize("values", [
    [3.0, 1.0, 2.0, 1.0], [5.0], [2.0, 2.0], [1.0, np.nan, 0.0, np.nan], [np.inf, np.inf, 1e9],
    [-0.0, 0.0, -0.0], [np.nan]])
def test_first_argmin_is_argmin(values):
  x = jnp.asarray(values, jnp.float32)
  assert int(planner.first_argmin(x)) == int(jnp.argmin(x))
  rng = np.random.default_rng(6)
  x = jnp.asarray(rng.integers(0, 4, (200, 9)).astype(np.float32))
  np.testing.assert_array_equal(jax.vmap(planner.first_argmin)(x), jnp.argmin(x, axis=1))
