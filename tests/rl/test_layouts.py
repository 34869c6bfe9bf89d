"""Random zone layouts (sims/fleet/layouts.py) and the RL env driving in them (sims/rl/env.py `layouts=`).

One env with three layouts (the built-in warehouse's own zones first) is built once; its reset
and step are compiled once with the model as an argument, so every layout runs the same program.
Expected values come from each layout's own masks on the host.
"""


import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfilters import constants
from sims.fleet import navigation
from sims.fleet.layouts import LayoutConfig, layout_scenarios, random_layout
from sims.rl.randomization import randomize_zones_and_goals
from sims.rl.env import NavEnv, NavEnvConfig
from sims.fleet.scenario import Scenario


def _cell_xy(grid, row, col):
  return (float(grid.origin[0]) + (col + 0.5) * grid.resolution, float(grid.origin[1]) + (row + 0.5) * grid.resolution)


def test_random_layout_masks_are_on_the_scenario_grids():
  sc = Scenario.default()
  a = random_layout(sc, np.random.default_rng(1))
  b = random_layout(sc, np.random.default_rng(1))
  c = random_layout(sc, np.random.default_rng(2))
  np.testing.assert_array_equal(a.keepout.data, b.keepout.data)            # a function of the generator
  assert not np.array_equal(a.keepout.data, c.keepout.data)
  for lay in (a, c):
    assert lay.map is sc.map and lay.keepout.data.shape == sc.keepout.data.shape
    assert lay.keepout.origin == sc.keepout.origin and lay.speed.resolution == sc.speed.resolution
    assert set(np.unique(lay.keepout.data).tolist()) <= {0, 100} and np.any(lay.keepout.data == 100)
    limits = 100 - np.unique(lay.speed.data[lay.speed.data != 0]).astype(int)
    assert limits.size and set(limits.tolist()) <= set(int(v) for v in LayoutConfig().speed_limits)
    assert (lay.speed_type, lay.speed_base, lay.speed_multiplier) == (constants.SPEED_FILTER_PERCENT, 100.0, -1.0)
  first = layout_scenarios(sc, 3, seed=5)
  assert first[0] is sc and len(first) == 3
  assert np.array_equal(layout_scenarios(sc, 3, seed=5)[2].speed.data, first[2].speed.data)


@pytest.mark.parametrize("kwargs, match", [
    ({"keepout_zones": (3, 1)}, "keepout_zones"),
    ({"zone_size": (0.0, 1.0)}, "zone_size"),
    ({"speed_limits": (30.0, 100.0)}, "speed_limits"),
    ({"speed_limits": (33.5,)}, "speed_limits"),
])
def test_layout_config_refuses_bad_ranges(kwargs, match):
  with pytest.raises(ValueError, match=match):
    LayoutConfig(**kwargs)


def test_layouts_need_velocity_mode_and_a_positive_count():
  with pytest.raises(ValueError, match="layouts must be an integer >= 1"):
    NavEnv.create(layouts=0)
  with pytest.raises(ValueError, match="velocity mode"):
    NavEnv.create(config=NavEnvConfig(mode="navigation"), layouts=2)


@pytest.fixture(scope="module")
def bank_env():
  env = NavEnv.create(layouts=3, layout_seed=4)
  reset = jax.jit(lambda model, key: env.with_model(model).reset(key))
  step = jax.jit(lambda model, state, a: env.with_model(model).step(state, a))
  return env, reset, step


def _model(env, layout):
  return env.mjx_model.tree_replace({"task.layout": jnp.asarray(layout, jnp.int32)})


def test_bank_holds_each_layouts_masks_stations_and_spawns(bank_env):
  env, _, _ = bank_env
  bank = env.mjx_model.task.bank
  assert env.num_layouts == 3 and bank.keepout.data.shape[0] == 3 and bank.speed.data.shape[0] == 3
  s = bank.stations_per_layout
  assert bank.nav.stations.shape[0] == 3 * s and bank.nav.dist.shape[0] == 3 * s
  assert env.layout_worlds[0].scenario is env.fleet.world.scenario          # layout 0: the scenario's own zones
  for l, w in enumerate(env.layout_worlds):
    np.testing.assert_array_equal(np.asarray(bank.keepout.data[l]), w.scenario.keepout.data)
    np.testing.assert_array_equal(np.asarray(bank.speed.data[l]), w.scenario.speed.data)
    np.testing.assert_array_equal(np.asarray(bank.nav.stations[l * s:(l + 1) * s]), w.stations)
    # Spawns and stations are clear of that layout's keepout zones (global cost below inscribed).
    g = w.scenario.map
    for xy in np.concatenate([np.asarray(bank.spawns[l, :int(bank.spawn_count[l])]), w.stations]):
      col, row = int((xy[0] - g.origin[0]) // g.resolution), int((xy[1] - g.origin[1]) // g.resolution)
      assert w.global_cost[row, col] < constants.INSCRIBED_INFLATED_OBSTACLE, (l, xy)
  assert not np.array_equal(np.asarray(bank.keepout.data[1]), np.asarray(bank.keepout.data[2]))


def test_randomisation_draws_a_layout_and_goals_of_that_layout(bank_env):
  env, reset, _ = bank_env
  n = 24
  model_v, axes = randomize_zones_and_goals(env.mjx_model, jax.random.split(jax.random.PRNGKey(2), n))
  layouts = np.asarray(model_v.task.layout)
  assert set(layouts.tolist()) == {0, 1, 2}
  s = env.mjx_model.task.bank.stations_per_layout
  logits = np.asarray(model_v.task.goal_logits).reshape(n, 3, s)
  for i in range(n):
    finite = np.isfinite(logits[i])
    assert finite[layouts[i]].sum() >= 2 and finite.sum() == finite[layouts[i]].sum()
  assert axes.task.layout == 0 and axes.task.bank.keepout.data is None     # the masks are shared, not copied
  bank = env.mjx_model.task.bank
  for i in range(4):
    model = jax.tree.map(lambda x, ax: x if ax is None else x[i], model_v, axes, is_leaf=lambda x: x is None)
    st = reset(model, jax.random.PRNGKey(10 + i))
    l = int(layouts[i])
    xy = np.asarray(st.data.qpos[0, :2])
    spawns = np.asarray(bank.spawns[l, :int(bank.spawn_count[l])])
    assert np.min(np.linalg.norm(spawns - xy, axis=1)) < 1e-5              # one of its layout's spawns
    goal = int(st.info["goal"][0])
    assert l * s <= goal < (l + 1) * s and np.isfinite(logits[i].reshape(-1)[goal])
    d = float(navigation.nav_value(bank.nav, jnp.int32(goal), jnp.asarray(xy)))
    assert d <= env.nav_config.goal_max_distance + 1e-3 or not np.any(np.isfinite(logits[i][l]) & (
        np.asarray([float(navigation.nav_value(bank.nav, jnp.int32(l * s + j), jnp.asarray(xy))) for j in range(s)])
        <= env.nav_config.goal_max_distance))


def test_step_reads_the_envs_own_layout(bank_env):
  env, reset, step = bank_env
  worlds = env.layout_worlds
  k1 = worlds[1].scenario.keepout
  # A cell of layout 1's keepout that is free in layouts 0 and 2 and far from walls.
  rows, cols = np.nonzero(k1.data == 100)
  ok = [(r, c) for r, c in zip(rows, cols)
        if worlds[0].scenario.keepout.data[r, c] == 0 and worlds[2].scenario.keepout.data[r, c] == 0
        and worlds[0].global_cost[r, c] == 0]
  assert ok, "layout 1 has no keepout cell free elsewhere"
  r, c = ok[len(ok) // 2]
  xy = _cell_xy(k1, r, c)
  entries = {}
  for l in (1, 0, 2):
    model = _model(env, l)
    st = reset(model, jax.random.PRNGKey(0))
    qpos = st.data.qpos.at[0].set(jnp.asarray([xy[0], xy[1], 0.0], jnp.float32))
    st = st.replace(data=st.data.replace(qpos=qpos), info=dict(st.info, last_qpos=qpos))
    out = step(model, st, jnp.zeros((2,), jnp.float32))
    entries[l] = (float(out.metrics["keepout_entries"]), float(out.done))
  assert entries == {1: (1.0, 1.0), 0: (0.0, 0.0), 2: (0.0, 0.0)}, entries


def test_stations_and_spawns_keep_off_a_free_map_edge():
  # A map whose free space runs to its edge (Nav2's warehouse does at its bottom row) had stations and
  # spawn points a few cm from the edge: a robot started there left the map in its first step.
  from jaxfilters.grid import OccupancyGrid
  from sims.fleet.config import FleetConfig
  from sims.fleet.world import build_world
  free = OccupancyGrid.create(np.zeros((160, 200), np.int8), 0.05, (-5.0, -4.0, 0.0))
  sc = Scenario(name="open", map=free, keepout=free, speed=free)
  cfg = FleetConfig(robots_per_world=2, num_stations=8)
  w = build_world(sc, cfg, seed=0)
  for pts in (w.stations, w.spawns):
    edge = np.minimum.reduce([pts[:, 0] + 5.0, 5.0 - pts[:, 0], pts[:, 1] + 4.0, 4.0 - pts[:, 1]])
    assert edge.min() >= cfg.inflation_radius - 1e-6, edge.min()


def test_goals_in_a_chosen_layout_are_that_layouts_stations(bank_env):
  # An env put in layout 2 without the randomisation had every goal weight -inf there: it drew
  # station 0 of the layout forever and counted a goal on every step spent on it.
  env, reset, step = bank_env
  s = env.mjx_model.task.bank.stations_per_layout
  model = _model(env, 2)
  st = reset(model, jax.random.PRNGKey(7))
  goals = set()
  for i in range(3):
    goal = int(st.info["goal"][0])
    goals.add(goal)
    assert 2 * s <= goal < 3 * s
    target = np.asarray(env.mjx_model.task.bank.nav.stations[goal])
    qpos = st.data.qpos.at[0, :2].set(jnp.asarray(target))
    st = st.replace(data=st.data.replace(qpos=qpos), info=dict(st.info, last_qpos=qpos))
    st = step(model, st, jnp.zeros((2,), jnp.float32))
    assert float(st.metrics["goals_reached"]) == 1.0
    assert int(st.info["goal"][0]) != goal                      # a new goal, not the one just reached
