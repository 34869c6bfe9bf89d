"""The fleet's local costmaps run a params file's inflation layers (Scenario.layers).

An AsymmetricInflationLayer runs with each robot's own plan (FleetEnv.robot_plans: the
descent of its goal's navigation field) and position; an InflationLayer replaces the
fleet's own inflation; a scenario without layers keeps the fleet's inflation.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfilters as jf
from jaxfilters.grid import OccupancyGrid
from sims.fleet import local_costmap
from sims.fleet.config import FleetConfig
from sims.fleet.env import FleetEnv
from sims.fleet.scenario import Scenario
from tests.nav2_layers import local_layers

RES = 0.05
LAYERS = """\
      lane_layer:
        plugin: "nav2_costmap_2d::AsymmetricInflationLayer"
        inflation_radius: 1.5
        cost_scaling_factor_left: 8.0
        cost_scaling_factor_right: 2.0
        goal_distance_threshold: 0.3
      inflation_layer:
        plugin: "nav2_costmap_2d::InflationLayer"
        inflation_radius: 0.4
        cost_scaling_factor: 5.0
"""


def _grid(data):
  return OccupancyGrid.create(data.astype(np.int8), RES, (0.0, 0.0, 0.0))


def _layers(tmp, plugins):
  return local_layers(tmp, plugins, LAYERS)


def _scenario(layers=()):
  """8 m x 6 m, walls around and pillars every 2 m; no keepout zone, no speed zone."""
  h, w = 120, 160
  occ = np.zeros((h, w))
  occ[:2], occ[-2:], occ[:, :2], occ[:, -2:] = 100, 100, 100, 100
  for r in range(40, h - 20, 40):
    for c in range(40, w - 20, 40):
      occ[r - 2:r + 2, c - 2:c + 2] = 100
  zeros = np.zeros((h, w))
  return Scenario("pillars", _grid(occ), _grid(zeros), _grid(zeros), layers=tuple(layers))


@pytest.fixture(scope="module")
def envs(tmp_path_factory):
  tmp = tmp_path_factory.mktemp("params")
  cfg = FleetConfig(robots_per_world=3, num_stations=6)
  made = {name: FleetEnv.create(_scenario(_layers(tmp, plugins)), cfg, seed=1)
          for name, plugins in (("asym", ["lane_layer"]), ("plain", ["inflation_layer"]))}
  # The same world without layers (the layers change nothing else that build_world makes).
  plain = made["plain"]
  made["none"] = dataclasses.replace(plain, world=dataclasses.replace(
      plain.world, scenario=_scenario(), local_layers=(), plan_points=0))
  state = made["none"].reset(jax.random.PRNGKey(3))   # the same spawns and goals in every world
  return made, state


def _raw(env, state):
  """The windows with the other robots marked, before any inflation layer."""
  w, p = env.world, env.params
  off = dataclasses.replace(w.inflation, enabled=False)
  cm, _ = local_costmap.local_costmaps(p.static_cost, p.map_origin, p.map_resolution, w.pad, p.keepout,
                                       state.data.qpos[:, :3], state.keepout, n=w.window_cells,
                                       robot_radius=env.config.robot.radius, inflation=off)
  return cm


def _sides(cx, cy, path, n):
  """Each cell centre's side of the nearest segment of the path (+1 left, -1 right) and its distance
  to the path (m), float64."""
  a, b = path[:n - 1].astype(np.float64), path[1:n].astype(np.float64)
  ab = b - a
  px, py = cx[None], cy[None]
  ax, ay = a[:, 0, None, None], a[:, 1, None, None]
  abx, aby = ab[:, 0, None, None], ab[:, 1, None, None]
  t = np.clip(((px - ax) * abx + (py - ay) * aby) / np.maximum(abx * abx + aby * aby, 1e-12), 0, 1)
  d = (px - ax - t * abx) ** 2 + (py - ay - t * aby) ** 2
  k = np.argmin(d, axis=0)
  cross = np.take_along_axis(abx * (py - ay) - aby * (px - ax), k[None], 0)[0]
  return np.sign(cross), np.sqrt(d.min(axis=0))


def test_asymmetric_layer_runs_with_each_robots_own_plan(envs):
  made, state = envs
  env = made["asym"]
  cfg = env.world.local_layers[0]
  assert isinstance(cfg, jf.AsymmetricInflationConfig) and cfg.resolution == RES
  got = env.update_costmaps(state).local
  paths, lengths = env.robot_plans(state)
  paths, lengths = np.asarray(paths), np.asarray(lengths)
  poses = np.asarray(state.data.qpos[:, :3])
  np.testing.assert_array_equal(paths[:, 0], poses[:, :2])          # a plan starts at its robot
  assert np.all(lengths >= 2)
  stations = np.asarray(env.params.nav.stations)[np.asarray(state.goal)]
  steps = np.linalg.norm(np.diff(paths, axis=1), axis=-1)
  for i, m in enumerate(lengths):     # one navigation cell per step; a plan that ends early ends at the goal
    np.testing.assert_allclose(steps[i, :m - 2], env.world.plan_step, rtol=1e-4)
    if m < env.world.plan_points:
      np.testing.assert_array_equal(paths[i, m - 1], stations[i])
  raw = _raw(env, state)
  by_hand = jf.asymmetric_inflate(raw, paths=paths, path_lengths=lengths, robot_xy=poses[:, :2], config=cfg)
  np.testing.assert_array_equal(np.asarray(got.cost), np.asarray(by_hand.cost))
  # Against the plain layer of the same radius and max(left, right): higher only on the disfavoured
  # side (cost_scaling_factor_right < left: the right) of the robot's own plan, for every robot.
  plain = np.asarray(jf.inflate(raw.cost, config=cfg.symmetric))
  cost = np.asarray(got.cost)
  assert np.all(cost >= plain)
  n = env.world.window_cells
  centres = (np.arange(n) + 0.5) * RES
  r = cfg.cell_radius
  for i in range(env.num_robots):
    raised = cost[i] > plain[i]
    assert raised.any(), f"robot {i}: no cell on its plan's disfavoured side was raised"
    # Every raised cell is within the radius of an obstacle cell on the disfavoured side of the
    # robot's own plan, within the radius of it (the second pass's seeds).
    ox, oy = np.asarray(got.origin[i], np.float64)
    side, dist = _sides(ox + centres[None, :], oy + centres[:, None], paths[i], lengths[i])
    seeds = (plain[i] == 254) & (side == cfg.disfavoured_side) & (dist <= cfg.inflation_radius)
    rows, cols = np.nonzero(seeds)
    rr, cc = np.nonzero(raised)
    d2 = (rr[:, None] - rows[None, :]) ** 2 + (cc[:, None] - cols[None, :]) ** 2
    assert np.all(d2.min(axis=1) <= r * r)
  # Another robot's plan gives another costmap: each runs with its own.
  swapped = jf.asymmetric_inflate(raw, paths=paths[::-1].copy(), path_lengths=lengths[::-1].copy(),
                                  robot_xy=poses[:, :2], config=cfg)
  assert np.any(np.asarray(swapped.cost) != cost)


def test_inflation_layer_replaces_the_fleets_and_none_keeps_it(envs):
  made, state = envs
  plain_env, none_env = made["plain"], made["none"]
  cfg = plain_env.world.local_layers[0]
  assert cfg == jf.InflationConfig(inflation_radius=0.4, cost_scaling_factor=5.0,
                                   inscribed_radius=cfg.inscribed_radius, resolution=RES)
  assert not plain_env.world.plans_needed and plain_env.world.plan_points == 0
  raw = _raw(plain_env, state)
  got = plain_env.update_costmaps(state).local.cost
  np.testing.assert_array_equal(np.asarray(got), np.asarray(jf.inflate(raw.cost, config=cfg)))
  # No layers: the fleet's own inflation, as before layers existed.
  w, p = none_env.world, none_env.params
  assert w.local_layers == () and w.local_inflation_layers == (w.inflation,)
  today, _ = local_costmap.local_costmaps(p.static_cost, p.map_origin, p.map_resolution, w.pad, p.keepout,
                                          state.data.qpos[:, :3], state.keepout, n=w.window_cells,
                                          robot_radius=none_env.config.robot.radius, inflation=w.inflation)
  none_cost = np.asarray(none_env.update_costmaps(state).local.cost)
  np.testing.assert_array_equal(none_cost, np.asarray(today.cost))
  assert np.any(none_cost != np.asarray(got))
  with pytest.raises(ValueError, match="no AsymmetricInflationLayer"):
    none_env.robot_plans(state)


def test_layers_the_fleet_cannot_run_are_refused(tmp_path):
  layers = _layers(tmp_path, ["lane_layer"])
  coarse = tuple(dataclasses.replace(x, config=dataclasses.replace(x.config, resolution=0.1)) for x in layers)
  with pytest.raises(ValueError, match="resolution 0.1 m.*set local_costmap resolution: 0.05"):
    FleetEnv.create(_scenario(coarse), FleetConfig(robots_per_world=1, num_stations=2))
  with pytest.raises(ValueError, match="keepout escape"):
    FleetEnv.create(_scenario(layers), FleetConfig(robots_per_world=1, num_stations=2, keepout_escape="center"))
  with pytest.raises(ValueError, match="tuple of Nav2InflationLayer"):
    _scenario([x.config for x in layers])
  with pytest.raises(ValueError, match="AsymmetricInflationConfig in layers"):
    w = FleetEnv.create(_scenario(), FleetConfig(robots_per_world=1, num_stations=2)).world
    local_costmap.local_costmaps(w.params.static_cost, w.params.map_origin, w.params.map_resolution, w.pad,
                                 w.params.keepout, jnp.zeros((1, 3)), jf.KeepoutState.create(1),
                                 n=w.window_cells, robot_radius=0.22, inflation=w.inflation,
                                 layers=(layers[0].config,))
