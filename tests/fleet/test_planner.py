"""sims/fleet/world.py tables and sims/fleet/planner.py on a tiny hand-built world: spawn spacing, speed caps, slowing before zones, stopping before keepout, rollouts.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfilters.grid import OccupancyGrid
from jaxfilters.keepout import KeepoutState, occ_to_cost
from jaxfilters.speed import speed_limit_at_one
from sims.fleet import local_costmap, navigation, planner
from sims.fleet import metrics as metrics_lib
from sims.fleet.config import FleetConfig
from sims.fleet.scenario import Scenario, speed_limit_host
from sims.fleet.world import build_world, spaced_points


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


@pytest.mark.parametrize("fused", [False, True], ids=["cpu", "fused"])
def test_cost_weight_steers_to_the_low_side_of_a_cost_band(tiny, monkeypatch, fused):
  """PlannerConfig.cost_weight scores the mean cost along each rollout: with a robot in a band of cost 120
  that reaches to its left, heading +x toward its goal, the default planner drives straight on (every
  candidate meets the same highest cost), the weighted one turns right, out of the band;
  the CPU's rollout and the GPU's one-pass form give the same terms."""
  if fused:
    monkeypatch.setattr(planner, "rollout_mode", lambda: "fused")
  nav = _field_to(tiny, (7.0, 3.0))
  p, n = tiny.params, tiny.window_cells
  res = float(p.map_resolution)
  pose = jnp.asarray([0.6, 3.0, 0.0], jnp.float32)
  origin = pose[:2] - n * res / 2
  cost = np.zeros((n, n), np.uint8)
  rows_y = float(origin[1]) + (np.arange(n) + 0.5) * res
  cost[rows_y > 2.9] = 120                                       # under the robot and to its left
  chosen = {}
  for weight in (0.0, 8.0):
    cfg = dataclasses.replace(tiny.config, planner=dataclasses.replace(tiny.config.planner, cost_weight=weight))
    ev = jax.jit(lambda pose: planner.evaluate(
        pose, jnp.asarray([0.5, 0.0]), jnp.asarray(0), jnp.asarray(jnp.inf), jnp.asarray(False),
        jnp.asarray(cost), planner.hard_cells(jnp.asarray(cost)), origin, jnp.asarray(res, jnp.float32),
        jnp.zeros((1, 2)), jnp.zeros((1,), bool), nav, p.speed, p.speed_cap, config=cfg))(pose)
    best = int(np.argmin(np.asarray(ev["score"])))
    chosen[weight] = np.asarray(ev["targets"])[best]
    if weight:
      mean_cost = np.asarray(ev["mean_cost"])
      straight = int(np.argmin(np.abs(np.asarray(ev["targets"])[:, 1]) + 10 * (np.asarray(ev["targets"])[:, 0] < 0.5)))
      assert mean_cost[best] < mean_cost[straight]
      # The mean cost is the rollout points' costs, counted exactly: here 0 or 120 per point.
      np.testing.assert_allclose(mean_cost * 252.0 * tiny.config.planner.num_rollout_steps % 120, 0, atol=1e-3)
    else:
      assert "mean_cost" not in ev
  assert chosen[0.0][1] == 0.0 and chosen[0.0][0] > 0
  assert chosen[8.0][1] < 0.0                                       # right turn, away from the band


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

