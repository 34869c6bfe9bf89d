"""The fleet step's faster navigation stack chooses what the straightforward one chose.

tests/planner_reference.py keeps the planner and navigation-field lookups as
they were before the performance work. Here the current code runs on the same
inputs (robots at random free poses of the built-in warehouse, several close
together so the collision monitor and the robots layer matter, some inside or
beside keepout zones and speed zones, random commands, goals, limits in force
and recovery flags) and must give the same candidate scores, collisions,
violations and chosen commands, bit for bit on this CPU; plus the parts on their
own: the shared-work rollout, the packed lookup table and the argmin.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfilters import constants
from jaxfilters.keepout import KeepoutState
from sims import local_costmap, planner
from sims.config import FleetConfig, PlannerConfig
from sims.env import FleetEnv
from tests import planner_reference as ref

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


def _run_both(env: FleetEnv, s: dict, config: FleetConfig):
  p = env.params
  extra = env.zone_speeds
  valid = ~jnp.eye(K, dtype=bool)

  def one_cluster(pose, cmd, goal, limit, rec, cost, origin, res):
    def new(q, c, g, lim, rc, cm, o, rs, ok):
      lut = planner.lookup_table(cm)
      ev = planner.evaluate_lut(q, c, g, lim, rc, lut, o, rs, pose[:, :2], ok, p.nav, p.speed, p.speed_cap,
                                config=config, extra_speeds=extra)
      out = planner.plan_lut_one(q, c, g, lim, rc, lut, o, rs, pose[:, :2], ok, p.nav, p.speed,
                                 p.speed_cap, config=config, extra_speeds=extra)
      return ev, out

    def old(q, c, g, lim, rc, cm, o, rs, ok):
      hard = ref.hard_cells(cm)
      ev = ref.evaluate(q, c, g, lim, rc, cm, hard, o, rs, pose[:, :2], ok, p.nav, p.speed, p.speed_cap,
                        config=config, extra_speeds=extra)
      out = ref.plan_one(q, c, g, lim, rc, cm, hard, o, rs, pose[:, :2], ok, p.nav, p.speed, p.speed_cap,
                         config=config, extra_speeds=extra)
      return ev, out

    args = (pose, cmd, goal, limit, rec, cost, origin, res, valid)
    return jax.vmap(new)(*args), jax.vmap(old)(*args)

  return jax.jit(jax.vmap(one_cluster))(s["pose"], s["cmd"], s["goal"], s["limit"], s["recovering"],
                                        s["cost"], s["origin"], s["res"])


def _assert_same(new, old):
  (ev, (cmd, info)), (ev_r, (cmd_r, info_r)) = jax.tree.map(np.asarray, (new, old))
  for key in ("targets", "xy", "collide", "violation", "progress", "heading", "clearance", "score"):
    np.testing.assert_array_equal(ev[key], ev_r[key], err_msg=key)
  np.testing.assert_array_equal(cmd, cmd_r)
  np.testing.assert_array_equal(info["stopped"], info_r["stopped"])
  np.testing.assert_array_equal(info["speed_violation"], info_r["speed_violation"])


def test_planner_matches_reference_bit_for_bit(env):
  s = _situations(env, seed=0, clusters=12)
  new, old = _run_both(env, s, env.config)
  _assert_same(new, old)
  # The cases are not trivial: some candidates collide, some robots stop, some violate, all rules fire.
  ev, (cmd, info) = jax.tree.map(np.asarray, new)
  assert ev["collide"].any() and not ev["collide"].all()
  assert info["stopped"].any() and not info["stopped"].all()
  assert (ev["violation"] > 0).any()
  assert (ev["clearance"] > 0).any()
  assert len(np.unique(cmd.reshape(-1, 2), axis=0)) > 10


def test_planner_matches_reference_other_grids(env):
  """Another candidate grid (even yaw-rate count, odd rollout length) and angular limits."""
  cfg = dataclasses.replace(env.config, planner=PlannerConfig(num_speeds=4, num_yaw_rates=6, horizon=1.2))
  assert cfg.planner.num_rollout_steps == 12
  s = _situations(env, seed=1, clusters=6)
  new, old = _run_both(env, s, cfg)
  _assert_same(new, old)


def test_rollout_grid_equals_rollout():
  cfg = FleetConfig()
  speeds, rates = planner.target_axes(cfg, (0.2475, 0.1485))
  targets = planner.candidates(cfg, (0.2475, 0.1485))
  rng = np.random.default_rng(3)
  for _ in range(4):
    pose = jnp.asarray(rng.uniform([-10, -10, -np.pi], [10, 10, np.pi]), jnp.float32)
    cmd = jnp.asarray(rng.uniform([-0.15, -1.5], [0.5, 1.5]), jnp.float32)
    xy, head, v = jax.jit(planner.rollout, static_argnums=3)(pose, cmd, jnp.asarray(targets), cfg)
    g = jax.jit(planner.rollout_grid, static_argnums=4)(pose, cmd, jnp.asarray(speeds), jnp.asarray(rates), cfg)
    nv, nw = len(speeds), len(rates)
    np.testing.assert_array_equal(np.asarray(g["x"]).reshape(nv * nw, -1), np.asarray(xy[:, 1:, 0]))
    np.testing.assert_array_equal(np.asarray(g["y"]).reshape(nv * nw, -1), np.asarray(xy[:, 1:, 1]))
    mids = 0.5 * (xy[:, 1:] + xy[:, :-1])
    np.testing.assert_array_equal(np.asarray(g["mx"]).reshape(nv * nw, -1), np.asarray(mids[..., 0]))
    np.testing.assert_array_equal(np.asarray(g["v"]), np.asarray(v).reshape(nv, nw, -1)[:, 0])
    np.testing.assert_array_equal(np.tile(np.asarray(g["hc"]), nv), np.asarray(head[:, 0]))
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
  rng = np.random.default_rng(5)
  cost = jnp.asarray(rng.integers(0, 256, (30, 30)).astype(np.uint8))
  origin, res = jnp.asarray([1.0, -2.0], jnp.float32), jnp.asarray(0.05, jnp.float32)
  pts = jnp.asarray(rng.uniform([0.8, -2.2], [2.7, -0.3], (500, 2)), jnp.float32)      # some outside
  lut = planner.lookup_table(cost)
  got = np.asarray(planner.lut_at(lut, origin, res, pts[:, 0], pts[:, 1]))
  c = np.asarray(ref.local_cost_at(cost, origin, res, pts))
  h = np.asarray(ref.local_cost_at(ref.hard_cells(cost), origin, res, pts))
  np.testing.assert_array_equal(got & planner.LUT_LETHAL, (c >= 254).astype(int))
  np.testing.assert_array_equal((got & planner.LUT_HARD) > 0, h > 0)
  np.testing.assert_array_equal(got >> planner.LUT_CLEARANCE_SHIFT, np.where(c <= 252, c, 0))
  assert ((c == 255) & (got == planner.LUT_OUTSIDE)).sum() > 0
  cap = jnp.asarray(rng.uniform(0.1, 0.5, (20, 25)), jnp.float32).at[3, 4].set(jnp.inf)
  np.testing.assert_array_equal(np.asarray(planner.speed_cap_xy(cap, origin, res, pts[:, 0], pts[:, 1])),
                                np.asarray(ref.speed_cap_at(cap, origin, res, pts)))


@pytest.mark.parametrize("values", [
    [3.0, 1.0, 2.0, 1.0], [5.0], [2.0, 2.0], [1.0, np.nan, 0.0, np.nan], [np.inf, np.inf, 1e9],
    [-0.0, 0.0, -0.0], [np.nan]])
def test_first_argmin_is_argmin(values):
  x = jnp.asarray(values, jnp.float32)
  assert int(planner._first_argmin(x)) == int(jnp.argmin(x))
  rng = np.random.default_rng(6)
  x = jnp.asarray(rng.integers(0, 4, (200, 9)).astype(np.float32))
  np.testing.assert_array_equal(jax.vmap(planner._first_argmin)(x), jnp.argmin(x, axis=1))
