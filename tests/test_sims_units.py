"""sims/ kernels tested on small hand-built cases: navigation, planner, metrics, scenario, config.

The fleet-level tests (MJX rollouts, compliance on the real maps) live in
tests/test_sims_fleet.py.
"""

from __future__ import annotations

import dataclasses
import functools
import heapq
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfilters import constants
from jaxfilters.grid import OccupancyGrid
from jaxfilters.keepout import KeepoutState, occ_to_cost
from jaxfilters.speed import speed_limit_at_one
from sims.fleet import local_costmap, metrics as metrics_lib, navigation, planner
from sims.fleet.config import FleetConfig, PlannerConfig, RobotConfig
from sims.fleet.scenario import Scenario, speed_limit_host
from sims.fleet.world import build_world, spaced_points

# ----------------------------------------------------------------------------- configs


@pytest.mark.parametrize("make", [
    lambda: RobotConfig(radius=0.0),
    lambda: RobotConfig(max_speed=-1.0),
    lambda: RobotConfig(max_accel=float("nan")),
    lambda: PlannerConfig(num_speeds=1),
    lambda: PlannerConfig(horizon=1.0, rollout_dt=0.3),
    lambda: FleetConfig(robots_per_world=0),
    lambda: FleetConfig(controller_hz=20.0, costmap_hz=3.0),
    lambda: FleetConfig(physics_dt=0.03),
    lambda: FleetConfig(impl="cuda"),
    lambda: FleetConfig(local_costmap_size=1.0),
    lambda: FleetConfig(robot="big"),
])
def test_config_rejects_bad_values(make):
  with pytest.raises(ValueError):
    make()


def test_config_rates_and_hashing():
  cfg = FleetConfig()
  assert (cfg.ticks_per_step, cfg.substeps_per_tick, cfg.step_seconds) == (4, 5, 0.2)
  assert hash(cfg) == hash(FleetConfig()) and cfg == dataclasses.replace(cfg)
  assert cfg.planner.num_rollout_steps == 15


# ----------------------------------------------------------------------------- navigation field


def _dijkstra(weight: np.ndarray, goal: tuple[int, int]) -> np.ndarray:
  """Reference: 8-connected Dijkstra with edge cost = step length x mean weight (float64)."""
  h, w = weight.shape
  dist = np.full((h, w), np.inf)
  dist[goal] = 0.0
  queue = [(0.0, goal)]
  while queue:
    d, (r, c) = heapq.heappop(queue)
    if d > dist[r, c]:
      continue
    for dr in (-1, 0, 1):
      for dc in (-1, 0, 1):
        rr, cc = r + dr, c + dc
        if (dr or dc) and 0 <= rr < h and 0 <= cc < w and np.isfinite(weight[rr, cc]):
          nd = d + math.hypot(dr, dc) * 0.5 * (weight[r, c] + weight[rr, cc])
          if nd < dist[rr, cc]:
            dist[rr, cc] = nd
            heapq.heappush(queue, (nd, (rr, cc)))
  return dist


def test_distance_field_matches_dijkstra():
  rng = np.random.default_rng(3)
  weight = (0.1 * (1.0 + rng.uniform(0, 2, (30, 40)))).astype(np.float32)
  weight[5:25, 12] = np.inf                     # a wall with a gap at the bottom
  weight[25:, 25] = np.inf                      # and one with a gap at the top
  weight[10:12, 30:38] = np.inf
  goals = [(2, 2), (28, 38), (15, 20)]
  out = np.asarray(navigation.distance_field(jnp.asarray(weight), jnp.asarray([g[0] for g in goals], jnp.int32),
                                             jnp.asarray([g[1] for g in goals], jnp.int32)))
  for s, g in enumerate(goals):
    ref = _dijkstra(weight, g)
    assert np.array_equal(np.isfinite(out[s]), np.isfinite(ref))
    np.testing.assert_allclose(out[s][np.isfinite(ref)], ref[np.isfinite(ref)], rtol=1e-5)


def test_distance_field_is_a_navigation_function():
  """Every reachable non-goal cell has a neighbour strictly closer to the goal."""
  weight = np.full((20, 20), 0.1, np.float32)
  weight[3:17, 10] = np.inf
  d = np.asarray(navigation.distance_field(jnp.asarray(weight), jnp.asarray([10], jnp.int32),
                                           jnp.asarray([2], jnp.int32)))[0]
  padded = np.pad(d, 1, constant_values=np.inf)
  best = np.min([padded[1 + dr:21 + dr, 1 + dc:21 + dc] for dr in (-1, 0, 1) for dc in (-1, 0, 1)
                 if dr or dc], axis=0)
  reach = np.isfinite(d)
  reach[10, 2] = False
  assert np.all(best[reach] < d[reach])


def test_nav_value_and_descent_direction():
  weight = jnp.full((20, 20), 0.1, jnp.float32)
  dist = navigation.distance_field(weight, jnp.asarray([10], jnp.int32), jnp.asarray([10], jnp.int32))
  field = navigation.NavField(dist=dist, origin=jnp.zeros(2), resolution=jnp.asarray(0.1, jnp.float32),
                              stations=jnp.asarray([[1.05, 1.05]]))
  goal = jnp.asarray(0)
  assert float(navigation.nav_value(field, goal, jnp.asarray([1.05, 1.05]))) == pytest.approx(0.0, abs=1e-6)
  assert float(navigation.nav_value(field, goal, jnp.asarray([1.55, 1.05]))) == pytest.approx(0.5, rel=1e-5)
  direction = np.asarray(navigation.descent_direction(field, goal, jnp.asarray([1.55, 1.07])))
  assert direction[0] < -0.95 and np.linalg.norm(direction) == pytest.approx(1.0, abs=1e-5)
  far = navigation.nav_value(field, goal, jnp.asarray([50.0, 50.0]))
  assert float(far) == navigation.UNREACHABLE


# ----------------------------------------------------------------------------- a tiny hand-built world


def _grid(data: np.ndarray, res: float = 0.05) -> OccupancyGrid:
  return OccupancyGrid.create(data.astype(np.int8), res, (0.0, 0.0, 0.0))


@pytest.fixture(scope="module")
def tiny():
  """8 m x 4 m, walls around; keepout x in [5, 6], y < 2.5; a 50 % speed zone x in [2, 3]."""
  h, w = 80, 160
  occ = np.zeros((h, w))
  occ[:2], occ[-2:], occ[:, :2], occ[:, -2:] = 100, 100, 100, 100
  keep = np.zeros((h, w))
  keep[:50, 100:120] = 100
  speed = np.zeros((h, w))
  speed[:, 40:60] = 50                       # 100 - 50 = 50 %
  sc = Scenario("tiny", _grid(occ), _grid(keep), _grid(speed))
  cfg = FleetConfig(robots_per_world=2, num_stations=4)
  return build_world(sc, cfg)


def _field_to(world, xy, *, through_keepout: bool = False) -> navigation.NavField:
  """A NavField with one goal at xy, optionally ignoring keepout zones (to push robots at them)."""
  nav = world.params.nav
  res = float(nav.resolution)
  factor = world.nav_factor
  cost = np.asarray(world.global_cost)
  if through_keepout:
    data = world.scenario.map.data
    cost = np.where(data == 100, 254, 0).astype(np.uint8)
  blocked, weight = navigation.pool_costmap(cost, factor)
  weight = np.where(blocked, np.inf, weight * res).astype(np.float32)
  c, r = int(xy[0] / res), int(xy[1] / res)
  dist = navigation.distance_field(jnp.asarray(weight), jnp.asarray([r], jnp.int32), jnp.asarray([c], jnp.int32))
  return dataclasses.replace(nav, dist=dist, stations=jnp.asarray([xy], jnp.float32))


@functools.lru_cache(maxsize=4)
def _tick_fn(world):
  """One jitted closed-loop tick (planner + ideal unicycle at 20 Hz) for one robot of `world`."""
  cfg, p = world.config, world.params
  n = world.window_cells

  @jax.jit
  def tick(pose, cmd, nav):
    cm, _ = local_costmap.local_costmaps(p.static_cost, p.map_origin, p.map_resolution, world.pad, p.keepout,
                                         pose[None], KeepoutState.create(1), n=n, robot_radius=cfg.robot.radius,
                                         inflation=world.inflation)
    new, info = planner.plan_one(pose, cmd, jnp.asarray(0), jnp.asarray(jnp.inf), jnp.asarray(False),
                                 cm.cost[0], planner.hard_cells(cm.cost[0]), cm.origin[0], cm.resolution[0],
                                 jnp.zeros((1, 2)), jnp.zeros((1,), bool), nav, p.speed, p.speed_cap,
                                 config=cfg, extra_speeds=(0.2475,))
    dt = cfg.control_dt
    th = pose[2] + 0.5 * new[1] * dt
    nxt = jnp.stack([pose[0] + new[0] * jnp.cos(th) * dt, pose[1] + new[0] * jnp.sin(th) * dt,
                     pose[2] + new[1] * dt])
    return nxt, new, info["stopped"]

  return tick


def _drive(world, nav, pose, cmd, ticks):
  """Closed loop of plan_one + ideal unicycle motion for one robot; returns poses, commands, stops."""
  tick = _tick_fn(world)
  poses, cmds, stops = [np.asarray(pose)], [], []
  pose, cmd = jnp.asarray(pose, jnp.float32), jnp.asarray(cmd, jnp.float32)
  for _ in range(ticks):
    pose, cmd, stopped = tick(pose, cmd, nav)
    poses.append(np.asarray(pose))
    cmds.append(np.asarray(cmd))
    stops.append(bool(stopped))
  return np.stack(poses), np.stack(cmds), np.asarray(stops)


def test_spaced_points_is_the_greedy_all_pairs_rule():
  """Each candidate, in order, is kept iff it is >= spacing from every point kept so far (brute force)."""
  def brute(pts, chosen, spacing, limit):
    kept = [tuple(q) for q in chosen]
    for p in pts:
      if len(kept) >= limit:
        break
      if all((p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2 >= spacing ** 2 for q in kept):
        kept.append(tuple(p))
    return np.asarray(kept, np.float64).reshape(-1, 2)

  rng = np.random.default_rng(0)
  for t in range(60):
    spacing = float(rng.choice([0.05, 0.3, 0.8]))
    pts = rng.uniform(-4.0, 4.0, (int(rng.integers(0, 300)), 2))
    if t % 2:                        # cell centres on a 5 cm grid: exact ties at the spacing
      pts = np.round(pts / 0.05) * 0.05 + 0.025
    chosen = rng.uniform(-4.0, 4.0, (int(rng.integers(0, 3)), 2))
    limit = int(rng.integers(1, 150))
    got = spaced_points(pts, chosen, spacing, limit)
    np.testing.assert_array_equal(got, brute(pts, chosen, spacing, limit))
    d2 = np.sum((got[:, None] - got[None]) ** 2, axis=-1) + np.eye(len(got)) * 1e9
    assert len(got) <= max(limit, len(chosen))
    assert np.all(d2[len(chosen):] >= spacing ** 2 * (1 - 1e-12))


def test_world_tables(tiny):
  assert tiny.zone_labels == ("none", "50%")
  assert tiny.zone_speed[1] == pytest.approx(0.25)
  # The shared navigation grid keeps every keepout cell blocked.
  nav = np.asarray(tiny.params.nav.dist)
  f = tiny.nav_factor
  keep = np.asarray(occ_to_cost(tiny.scenario.keepout.data)) >= 253
  rows, cols = np.nonzero(keep)
  assert np.all(np.isinf(nav[:, rows // f, cols // f]))
  # Stations and spawns are clear of obstacles and keepout zones.
  cost = tiny.global_cost
  for x, y in np.concatenate([tiny.stations, tiny.spawns]):
    assert cost[int(y / 0.05), int(x / 0.05)] == 0


def test_speed_cap_table_matches_speed_limit_at_one():
  """The planner's per-cell cap (before dilation) is speed_limit_at_one's limit in m/s."""
  sc = Scenario.default()
  world_cfg = FleetConfig()
  from sims.fleet.world import zone_tables
  table, _, _, speeds = zone_tables(sc, world_cfg.robot.max_speed)
  speeds = np.asarray(speeds, np.float32)
  data = sc.speed.data
  rng = np.random.default_rng(0)
  idx = np.concatenate([rng.integers(0, data.size, 300), np.flatnonzero(data != 0)[::97]])
  rows, cols = np.unravel_index(idx, data.shape)
  from jaxfilters.types import FilterInfo
  info = FilterInfo.create(sc.speed_type, sc.speed_base, sc.speed_multiplier)
  xy = np.stack([sc.speed.origin[0] + (cols + 0.5) * sc.speed.resolution,
                 sc.speed.origin[1] + (rows + 0.5) * sc.speed.resolution], axis=1).astype(np.float32)
  lim, ok = jax.jit(jax.vmap(lambda q: speed_limit_at_one(
      jnp.asarray(data), jnp.asarray(np.float32(sc.speed.origin[:2])),
      jnp.asarray(np.float32(sc.speed.resolution)), info, q)))(jnp.asarray(xy))
  ms = np.asarray(planner.limit_to_speed(lim, jnp.asarray(True), ok, world_cfg.robot.max_speed))
  np.testing.assert_allclose(speeds[table[data[rows, cols].astype(np.uint8)]], ms, rtol=1e-6)
  for d in (-1, 0, 30, 50, 100, 101):
    lim_h, ok_h = speed_limit_host(d, 1, 100.0, -1.0)
    assert (lim_h, ok_h) == {-1: (0.0, False), 0: (0.0, True), 30: (70.0, True), 50: (50.0, True),
                             100: (0.0, True), 101: (0.0, True)}[d]


def test_planner_slows_down_before_a_speed_zone(tiny):
  """At full speed toward a 50 % zone, the robot is at or under 0.25 m/s before its centre enters."""
  nav = _field_to(tiny, (7.0, 1.0))
  poses, cmds, stops = _drive(tiny, nav, [0.8, 1.0, 0.0], [0.5, 0.0], 220)
  assert cmds[:5, 0].max() == pytest.approx(0.5, abs=1e-6)          # full speed at first
  inside = (poses[1:, 0] >= 2.0) & (poses[1:, 0] < 3.0)
  assert inside.any() and not stops.any()
  first = int(np.argmax(inside))
  assert np.all(cmds[first - 1:, 0][inside[first - 1:]] <= 0.25 + 1e-6)
  assert cmds[first - 1, 0] <= 0.25 + 1e-6                           # already slow one tick before entry
  assert poses[-1, 0] > 3.2                                          # and it gets through


def test_planner_stops_rather_than_enter_keepout(tiny):
  """A navigation field that ignores the keepout pulls the robot at it; it never enters a keepout cell."""
  nav = _field_to(tiny, (7.0, 1.0), through_keepout=True)
  poses, cmds, stops = _drive(tiny, nav, [4.0, 1.0, 0.0], [0.5, 0.0], 80)
  p = tiny.params
  inside = jax.jit(jax.vmap(lambda q: metrics_lib.in_keepout(p.keepout, q)))(jnp.asarray(poses[:, :2]))
  assert not np.asarray(inside).any()
  assert poses[:, 0].max() < 5.0


@pytest.mark.parametrize("mode", ["cumsum", "chain"])
def test_rollout_grid_matches_a_unicycle_in_doubles(mode):
  cfg = FleetConfig()
  speeds, rates = planner.target_axes(cfg)
  targets = planner.candidates(cfg)
  nw = len(rates)
  pose = jnp.asarray([1.0, -2.0, 0.7])
  cmd = jnp.asarray([0.3, -0.5])
  g = planner.rollout_grid(pose, cmd, jnp.asarray(speeds), jnp.asarray(rates), cfg, mode=mode)
  r, dt = cfg.robot, cfg.planner.rollout_dt
  for c in (0, 7, 20, len(targets) - 1):
    i, j = divmod(c, nw)
    x, y, th, vv, ww = 1.0, -2.0, 0.7, 0.3, -0.5
    for t in range(cfg.planner.num_rollout_steps):
      vv += np.clip(float(targets[c, 0]) - vv, -r.max_accel * dt, r.max_accel * dt)
      ww += np.clip(float(targets[c, 1]) - ww, -r.max_yaw_accel * dt, r.max_yaw_accel * dt)
      mid = th + 0.5 * ww * dt
      x, y, th = x + vv * math.cos(mid) * dt, y + vv * math.sin(mid) * dt, th + ww * dt
      np.testing.assert_allclose([float(g["x"][i, j, t]), float(g["y"][i, j, t])], [x, y], atol=2e-5)
      assert float(g["v"][i, t + 1]) == pytest.approx(vv, abs=1e-6)
    np.testing.assert_allclose([float(g["hc"][j]), float(g["hs"][j])], [math.cos(th), math.sin(th)], atol=2e-5)


# ----------------------------------------------------------------------------- metric kernels


def test_physics_update_hand_built():
  m = metrics_lib.Metrics.zeros(3, 3)
  prev = jnp.asarray([False, True, False])
  speed = jnp.asarray([0.5, 0.2, 0.1])
  zone = jnp.asarray([0, 2, 1])
  keep = jnp.asarray([False, True, True])
  step = jnp.asarray([0.005, 0.002, 0.001])
  for _ in range(4):
    m, prev = metrics_lib.physics_update(m, prev, jnp.zeros((3, 2)), step, speed, zone, keep, 0.01)
  np.testing.assert_allclose(np.asarray(m.distance), [0.02, 0.008, 0.004], rtol=1e-6)
  np.testing.assert_allclose(np.asarray(m.zone_time), [[0.04, 0, 0], [0, 0, 0.04], [0, 0.04, 0]], atol=1e-7)
  np.testing.assert_allclose(np.asarray(m.zone_max_speed), [[0.5, 0, 0], [0, 0, 0.2], [0, 0.1, 0]])
  assert np.asarray(m.keepout_steps).tolist() == [0, 4, 4]
  assert np.asarray(m.keepout_entries).tolist() == [0, 0, 1]     # robot 1 was already inside


def test_proximity_update_hand_built():
  m = metrics_lib.Metrics.zeros(4, 1)
  xy = jnp.asarray([[0.0, 0.0], [0.40, 0.0], [5.0, 0.0], [5.47, 0.0]])
  c, n = jnp.zeros(4, bool), jnp.zeros(4, bool)
  for _ in range(3):                                   # a standing pair counts once
    m, c, n = metrics_lib.proximity_update(m, c, n, xy, 0.22, 0.05)
  assert np.asarray(m.contacts).tolist() == [1, 1, 0, 0]
  assert np.asarray(m.near_misses).tolist() == [1, 1, 1, 1]
  np.testing.assert_allclose(np.asarray(m.min_separation), [0.4, 0.4, 0.47, 0.47], rtol=1e-5)
  m, c, n = metrics_lib.proximity_update(m, c, n, xy.at[1, 0].set(3.0), 0.22, 0.05)
  m, c, n = metrics_lib.proximity_update(m, c, n, xy, 0.22, 0.05)   # apart, then back: a new event
  assert np.asarray(m.contacts).tolist() == [2, 2, 0, 0]


def test_zone_and_keepout_lookups_on_default_maps():
  from jaxfilters.types import FilterInfo, FilterMask
  from sims.fleet.world import zone_tables
  sc = Scenario.default()
  table, labels, _, _ = zone_tables(sc, 0.5)
  speed = FilterMask.create(sc.speed, FilterInfo.create(1, 100.0, -1.0))
  keepout = FilterMask.create(sc.keepout, FilterInfo.create(0))
  pts = jnp.asarray([[0.0, 0.0], [13.0, 5.0], [-10.0, 5.0], [8.0, 2.5], [100.0, 0.0], [-0.99, -2.99],
                     [-1.0, -3.0]], jnp.float32)
  zones = np.asarray(jax.jit(jax.vmap(lambda q: metrics_lib.zone_at(speed, jnp.asarray(table), q)))(pts))
  keep = np.asarray(jax.jit(jax.vmap(lambda q: metrics_lib.in_keepout(keepout, q)))(pts))
  assert labels == ("none", "50%", "30%")
  # The zone's lower-left corner cell starts at (-1, -3) in decimal, but float32(0.05) > 0.05, so
  # Nav2's floor((w - o) / res) puts the point (-1, -3) itself one cell outside.
  assert zones.tolist() == [1, 2, 0, 0, 0, 1, 0]
  assert keep.tolist() == [False, False, False, True, False, False, False]


def test_summarize_flags_violations():
  m = metrics_lib.Metrics.zeros(2, 2)
  m = dataclasses.replace(m, zone_max_speed=jnp.asarray([[0.5, 0.27], [0.4, 0.2]]),
                          keepout_entries=jnp.asarray([0, 1]))
  out = metrics_lib.summarize(jax.tree.map(lambda a: a[None], m), zone_labels=("none", "50%"),
                              zone_limits=(0.0, 50.0), zone_speed=(np.inf, 0.25), speed_tolerance=0.01,
                              seconds=1.0)
  f = out["fleet"]
  assert [z["compliant"] for z in f["zones"]] == [True, False]
  assert not f["speed_compliant"] and f["keepout_entries"] == 1 and len(out["robots"]) == 2


# ----------------------------------------------------------------------------- scenario files


def test_default_scenario_files_are_small_and_reproducible(tmp_path):
  from sims.commands import make_default_scenario
  shipped = Path(make_default_scenario.ASSETS)
  total = sum((shipped / f"default_{n}.{e}").stat().st_size for n in ("map", "keepout", "speed")
              for e in ("yaml", "pgm"))
  assert total < 1_000_000
  make_default_scenario.write(tmp_path)
  for n in ("map", "keepout", "speed"):
    for e in ("yaml", "pgm"):
      assert (tmp_path / f"default_{n}.{e}").read_bytes() == (shipped / f"default_{n}.{e}").read_bytes()


def test_default_scenario_loads_through_map_io():
  sc = Scenario.default()
  assert sc.map.data.shape == (400, 600) and sc.map.resolution == pytest.approx(0.05)
  assert sorted(np.unique(sc.keepout.data).tolist()) == [0, 100]
  assert sorted(np.unique(sc.speed.data).tolist()) == [0, 50, 70]     # none, 50 %, 30 %
  assert sorted(np.unique(sc.map.data).tolist()) == [-1, 0, 100]


def test_limit_to_speed_percent_absolute_and_none():
  lim = jnp.asarray([50.0, 0.3, 0.0, 30.0, 80.0])
  percent = jnp.asarray([True, False, True, True, False])
  valid = jnp.asarray([True, True, True, False, True])
  out = np.asarray(planner.limit_to_speed(lim, percent, valid, 0.5))
  np.testing.assert_allclose(out, [0.25, 0.3, np.inf, np.inf, 80.0])   # 0.0 and invalid mean no limit


def test_absolute_speed_mask_zones():
  h, w = 40, 60
  occ = np.zeros((h, w))
  occ[:1], occ[-1:], occ[:, :1], occ[:, -1:] = 100, 100, 100, 100
  speed = np.zeros((h, w))
  speed[:, 20:30] = 3                                     # 3 * 0.1 + 0 = 0.3 m/s (type 2)
  speed[:, 40:45] = 9                                     # 0.9 m/s: above max speed, still a zone
  sc = Scenario("abs", _grid(occ, 0.1), _grid(np.zeros((h, w)), 0.1), _grid(speed, 0.1),
                speed_type=constants.SPEED_FILTER_ABSOLUTE, speed_base=0.0, speed_multiplier=0.1)
  world = build_world(sc, FleetConfig(robots_per_world=1, num_stations=2, local_costmap_size=3.0))
  assert world.zone_labels == ("none", "0.9 m/s", "0.3 m/s")
  np.testing.assert_allclose(world.zone_speed[1:], [0.9, 0.3], rtol=1e-6)
  cap = np.asarray(world.params.speed_cap)
  assert cap[20, 25] == pytest.approx(0.3) and np.isinf(cap[20, 5]) and cap[20, 19] == pytest.approx(0.3)
