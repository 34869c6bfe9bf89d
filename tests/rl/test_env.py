"""sims/rl/env.py: the Playground contract, the speed clip, keepout/collision episodes, goals,
navigation mode against FleetEnv, Brax/Playground wrappers with zone and goal randomisation,
a few rejax PPO iterations (the suite's small training run, tests/rl_small.py), and the soak script.

Jitted functions are shared through module fixtures (each distinct env compiles once).
Robots are placed by editing `state.data.qpos` (same shapes: nothing recompiles), and
expected values come from NumPy on the scenario's own mask arrays.
"""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mujoco_playground._src import mjx_env, wrapper

from sims.commands import soak
from sims.fleet.config import FleetConfig
from sims.rl.randomization import randomize_zones_and_goals
from sims.rl.env import NavEnv, NavEnvConfig, clip_command

TOL = FleetConfig().speed_tolerance


@pytest.fixture(scope="module")
def venv():
  """Velocity mode, 1 robot per env: env, jitted reset and step."""
  env = NavEnv.create()
  return env, jax.jit(env.reset), jax.jit(env.step)


def _place(state, xy, yaw):
  qpos = state.data.qpos.at[0].set(jnp.asarray([xy[0], xy[1], yaw], jnp.float32))
  info = dict(state.info, last_qpos=qpos)
  return state.replace(data=state.data.replace(qpos=qpos), info=info)


def _cell_xy(grid_origin, res, row, col):
  return (float(grid_origin[0]) + (col + 0.5) * res, float(grid_origin[1]) + (row + 0.5) * res)


def _static_inflated(env):
  return np.asarray(env.mjx_model.task.static_inflated)


def test_contract_is_playground(venv):
  env, reset, step = venv
  assert isinstance(env, mjx_env.MjxEnv)
  s = reset(jax.random.PRNGKey(0))
  assert isinstance(s, mjx_env.State)
  assert env.action_size == 2 and env.observation_size == 98 and s.obs.shape == (98,)
  assert s.obs.dtype == jnp.float32 and s.reward.shape == () and s.done.shape == ()
  s2 = step(s, jnp.asarray([0.5, -0.2]))
  assert set(s2.metrics) == set(s.metrics) and set(s2.info) == set(s.info)
  assert jax.tree.structure(s2) == jax.tree.structure(s)           # scan-compatible
  assert bool(jnp.all(jnp.isfinite(s2.obs))) and float(s2.done) == 0.0
  assert env.dt == pytest.approx(0.2) and env.sim_dt == pytest.approx(0.01) and env.n_substeps == 20
  # Keys that wrappers add to metrics survive a step (Brax's EvalWrapper adds "reward").
  extra = s.replace(metrics={**s.metrics, "reward": s.reward})
  assert set(jax.eval_shape(env.step, extra, jnp.zeros((2,))).metrics) == set(extra.metrics)
  # A second call with new values compiles nothing.
  before = step._cache_size()
  step(s2, jnp.asarray([-1.0, 1.0]))
  assert step._cache_size() == before


def test_wrong_actions_raise_clear_errors(venv):
  env, reset, step = venv
  s = reset(jax.random.PRNGKey(1))
  with pytest.raises(ValueError, match=r"action must be float \[2K\] = \(2,\).*got shape \(3,\)"):
    env.step(s, jnp.zeros((3,)))
  with pytest.raises(ValueError, match=r"got shape \(1, 2\)"):
    env.step(s, jnp.zeros((1, 2)))
  with pytest.raises(TypeError, match="floating point"):
    env.step(s, jnp.zeros((2,), jnp.int32))
  # Out-of-range and NaN values are not errors under jit: clipped/zeroed and counted.
  s2 = step(s, jnp.asarray([3.0, jnp.nan]))
  assert float(s2.metrics["bad_action"]) == 2.0
  assert float(s2.info["cmd"][0, 0]) == pytest.approx(4 * 0.05)    # ramped toward +max_speed
  assert float(s2.info["cmd"][0, 1]) == 0.0


def test_clip_command_matches_numpy():
  rng = np.random.default_rng(0)
  cmd = rng.uniform(-1, 1, (64, 2)).astype(np.float32)
  cap = rng.choice([0.1, 0.25, np.inf], 64).astype(np.float32)
  robot = FleetConfig().robot
  for angular in (False, True):
    got = np.asarray(clip_command(jnp.asarray(cmd), jnp.asarray(cap), robot, angular))
    want_v = np.minimum(np.maximum(cmd[:, 0], -cap), cap)
    w_cap = robot.max_yaw_rate * np.minimum(cap / robot.max_speed, 1.0) if angular else np.inf
    want_w = np.clip(cmd[:, 1], -w_cap, w_cap)
    np.testing.assert_array_equal(got, np.stack([want_v, want_w], 1).astype(np.float32))


def test_speed_zone_clips_command_to_the_filter_limit(venv):
  env, reset, step = venv
  sc = env.fleet.world.scenario
  sp = sc.speed.data
  res = sc.speed.resolution
  # The centre of the 50 % zone (limit 0.25 m/s) and a clear path along +x inside it.
  rows, cols = np.nonzero(sp == 50)
  r, c = int(np.median(rows)), int(cols.min()) + 10
  assert np.all(sp[r, c:c + 40] == 50) and np.all(_static_inflated(env)[r, c:c + 40] < 253)
  s = _place(reset(jax.random.PRNGKey(2)), _cell_xy(sc.speed.origin, res, r, c), 0.0)
  cap = 0.5 * 50 / 100
  for _ in range(8):
    s = step(s, jnp.asarray([1.0, 0.0]))
    # Every command is within the limit the filter reports, and the limit is Nav2's 50 %.
    assert float(s.info["cap"][0]) == pytest.approx(cap)
    assert float(s.info["cmd"][0, 0]) <= cap
  assert float(s.info["cmd"][0, 0]) == np.float32(cap)                # ramped up to the cap, clipped
  assert float(jnp.linalg.norm(s.data.qvel[0, :2])) <= cap + TOL
  assert float(s.metrics["clipped"]) > 0 and float(s.metrics["speed_violation_s"]) == 0.0
  assert float(s.obs[81]) == pytest.approx(cap / 0.5) and float(s.obs[82]) == 1.0   # limit in force


def test_speed_excess_outside_entry_counts_only_what_the_clip_did_not_hold(venv):
  env, reset, step = venv
  sc = env.fleet.world.scenario
  sp = sc.speed.data
  res = sc.speed.resolution
  rows, cols = np.nonzero(sp == 50)
  r, c = int(np.median(rows)), int(cols.min())
  assert np.all(sp[r, c - 30:c] == 0) and np.all(_static_inflated(env)[r, c - 30:c + 20] < 253)
  # Full speed from 1.5 m before the 50 % zone into it: above the limit only around the entry.
  s = _place(reset(jax.random.PRNGKey(2)), _cell_xy(sc.speed.origin, res, r, c - 30), 0.0)
  over = outside = 0.0
  for _ in range(25):
    s = step(s, jnp.asarray([1.0, 0.0]))
    over += float(s.metrics["speed_violation_s"])
    outside += float(s.metrics["speed_violation_outside_entry_s"])
  assert sp[r, int((float(s.data.qpos[0, 0]) - float(sc.speed.origin[0])) / res)] == 50     # inside now
  assert over > 0.0 and outside == 0.0
  # Inside the zone at 0.5 m/s with the zone's limit already published (no entry this tick): the
  # robot slowing down after the clip is above the limit outside an entry tick.
  s = _place(reset(jax.random.PRNGKey(2)), _cell_xy(sc.speed.origin, res, r, c + 10), 0.0)
  s = s.replace(data=s.data.replace(qvel=s.data.qvel.at[0, 0].set(0.5)),
                info=dict(s.info, cap=jnp.full_like(s.info["cap"], 0.25), cmd=s.info["cmd"].at[0, 0].set(0.5)))
  s = step(s, jnp.asarray([1.0, 0.0]))
  assert float(s.metrics["speed_violation_outside_entry_s"]) > 0.0
  assert float(s.metrics["speed_violation_outside_entry_s"]) <= float(s.metrics["speed_violation_s"])


def _keepout_approach(env):
  """(start xy, zone first column x) for driving +x into a lethal keepout zone over clear ground."""
  sc = env.fleet.world.scenario
  k = sc.keepout.data
  stat = _static_inflated(env)
  res = sc.keepout.resolution
  for r in range(k.shape[0]):
    cols = np.nonzero(k[r] == 100)[0]
    for c0 in cols:
      if c0 < 30 or k[r, c0 - 1] == 100:
        continue
      lane = slice(c0 - 24, c0)
      if np.all(k[r - 3:r + 4, lane] == 0) and np.all(stat[r - 3:r + 4, lane] < 200) and np.all(k[r, c0:c0 + 8] == 100):
        return _cell_xy(sc.keepout.origin, res, r, c0 - 20), float(sc.keepout.origin[0]) + c0 * res, r
  raise AssertionError("the scenario has no clear approach to a keepout zone")


@pytest.mark.parametrize("mode", ["terminate", "penalty"])
def test_keepout_entry_ends_or_costs(mode, venv):
  env, reset, step = venv
  if mode == "penalty":
    env = NavEnv(env.fleet, NavEnvConfig(keepout="penalty"))
    reset, step = jax.jit(env.reset), jax.jit(env.step)
  start, edge_x, _ = _keepout_approach(env)
  s = _place(reset(jax.random.PRNGKey(3)), start, 0.0)
  entered_at = None
  for t in range(30):
    prev_x = float(s.data.qpos[0, 0])
    s = step(s, jnp.asarray([1.0, 0.0]))
    x = float(s.data.qpos[0, 0])
    if float(s.metrics["keepout_entries"]) > 0:
      entered_at = t
      break
    assert x < edge_x                                   # no entry reported while still outside
  assert entered_at is not None and prev_x < edge_x <= x    # reported on the step that crossed the edge
  assert float(s.done) == (1.0 if mode == "terminate" else 0.0)
  assert float(s.reward) < -9.0                        # the 10.0 penalty dominates the step


def test_costmap_stop_holds_a_robot_driving_at_a_zone(venv):
  env, _, _ = venv
  env = NavEnv(env.fleet, NavEnvConfig(costmap_stop=True))
  reset, step = jax.jit(env.reset), jax.jit(env.step)
  start, edge_x, _ = _keepout_approach(env)
  s = _place(reset(jax.random.PRNGKey(3)), start, 0.0)
  stops = 0.0
  for _ in range(40):                                   # 8 s at full speed from 1 m before the zone
    s = step(s, jnp.asarray([1.0, 0.0]))
    assert float(s.metrics["keepout_entries"]) == 0.0 and float(s.done) == 0.0
    stops += float(s.metrics["costmap_stops"])
  x = float(s.data.qpos[0, 0])
  assert stops > 0 and x < edge_x and edge_x - x < 0.6  # held near the zone, not short of it
  assert float(jnp.linalg.norm(s.data.qvel[0, :2])) < 0.02
  yaw0 = float(s.data.qpos[0, 2])
  s = step(s, jnp.asarray([0.0, 1.0]))                  # turning stays free
  assert abs(float(s.data.qpos[0, 2]) - yaw0) > 0.05
  s = _place(s, (x, float(s.data.qpos[0, 1])), 0.0)
  for _ in range(3):
    s = step(s, jnp.asarray([-1.0, 0.0]))               # and so does backing away
  assert float(s.data.qpos[0, 0]) < x - 0.05 and float(s.metrics["costmap_stops"]) == 0.0


@pytest.mark.parametrize("costmap_stop", [False, True])
def test_wall_collision_ends_episode(costmap_stop, venv):
  env, reset, step = venv
  if costmap_stop:
    env = NavEnv(env.fleet, NavEnvConfig(costmap_stop=True))
    reset, step = jax.jit(env.reset), jax.jit(env.step)
  sc = env.fleet.world.scenario
  stat = _static_inflated(env)
  keep = sc.keepout.data
  res = sc.map.resolution
  # A free cell whose +x lane (5 rows wide) reaches an inscribed/lethal static cell within 1.5 m.
  for r in range(40, stat.shape[0] - 40, 5):
    for c in range(40, stat.shape[1] - 40, 5):
      if stat[r, c] != 0:
        continue
      hit = np.nonzero(stat[r, c:c + 30] >= 253)[0]
      if not len(hit) or hit[0] < 8:
        continue
      j = int(hit[0])
      if np.any(stat[r - 2:r + 3, c:c + j] >= 253) or np.any(keep[r - 5:r + 6, c:c + j + 5] != 0):
        continue
      s = _place(reset(jax.random.PRNGKey(4)), _cell_xy(sc.map.origin, res, r, c), 0.0)
      x_wall = float(sc.map.origin[0]) + (c + j) * res
      if costmap_stop:                      # held short of the wall: no collision, the episode goes on
        stops = 0.0
        for _ in range(25):
          s = step(s, jnp.asarray([1.0, 0.0]))
          assert float(s.done) == 0.0 and float(s.metrics["collisions"]) == 0.0
          stops += float(s.metrics["costmap_stops"])
        assert stops > 0 and x_wall - 0.6 < float(s.data.qpos[0, 0]) < x_wall
        return
      for _ in range(25):
        s = step(s, jnp.asarray([1.0, 0.0]))
        if float(s.done):
          break
      assert float(s.done) == 1.0 and float(s.metrics["collisions"]) == 1.0
      assert float(s.metrics["keepout_entries"]) == 0.0 and float(s.reward) < -9.0
      # The episode ended at the inscribed boundary, not before it.
      assert float(s.data.qpos[0, 0]) >= x_wall - 0.5 * 0.2
      return
  raise AssertionError("no wall approach found")


def test_goal_reached_gives_bonus_and_a_new_goal(venv):
  env, reset, step = venv
  s = reset(jax.random.PRNGKey(5))
  goal = int(s.info["goal"][0])
  station = np.asarray(env.fleet.world.stations[goal])
  s = _place(s, station, 0.0)
  s = step(s, jnp.zeros((2,)))
  assert float(s.metrics["goals_reached"]) == 1.0 and float(s.reward) > 4.0
  assert int(s.info["goal"][0]) != goal
  assert np.linalg.norm(np.asarray(env.fleet.world.stations[int(s.info["goal"][0])]) - station) > 2.0


def test_cached_auto_reset_restarts_episode_state(venv):
  """Playground's BraxAutoResetWrapper(full_reset=False) swaps data only: step must notice."""
  env, reset, step = venv
  s0 = reset(jax.random.PRNGKey(6))
  s = s0
  for _ in range(5):
    s = step(s, jnp.asarray([1.0, 0.5]))
  assert float(jnp.abs(s.info["cmd"][0, 0])) > 0.1
  swapped = s.replace(data=s0.data, obs=s0.obs)               # what the wrapper does on done
  s2 = step(swapped, jnp.zeros((2,)))
  assert float(jnp.abs(s2.info["cmd"][0, 0])) == 0.0          # ramped from rest, not from 0.25 m/s
  assert abs(float(s2.metrics["progress"])) < 0.05           # no jump of the progress reward


def test_navigation_mode_is_the_fleet_step():
  fc = FleetConfig(robots_per_world=2)
  env = NavEnv.create(fleet_config=fc, config=NavEnvConfig(mode="navigation"))
  assert env.action_size == 2
  s = jax.jit(env.reset)(jax.random.PRNGKey(7))
  s_stations = env.num_stations
  with pytest.raises(TypeError, match="integer station ids"):
    env.step(s, jnp.zeros((2,), jnp.float32))
  with pytest.raises(ValueError, match=r"int \[K\] = \(2,\)"):
    env.step(s, jnp.zeros((3,), jnp.int32))
  action = jnp.asarray([3, s_stations + 5], jnp.int32)       # the second id is out of range
  # One program computes both (one compile): the env step and FleetEnv.step with the bad id as -1.
  got, want = jax.jit(lambda s, a, b: (env.step(s, a), env.fleet.step(s.info["world"], b)))(
      s, action, jnp.asarray([3, -1], jnp.int32))
  np.testing.assert_array_equal(np.asarray(got.data.qpos), np.asarray(want.data.qpos))
  np.testing.assert_array_equal(np.asarray(got.info["world"].goal), np.asarray(want.goal))
  assert int(got.info["world"].goal[1]) == int(s.info["world"].goal[1])   # kept, not clamped
  assert float(got.metrics["bad_action"]) == 1.0
  assert got.obs.shape == (env.observation_size,) == (2 * 8 + 2 * s_stations,)


def test_brax_wrappers_with_zone_and_goal_randomisation():
  fc = FleetConfig(robots_per_world=2)
  env = NavEnv.create(fleet_config=fc)
  assert env.action_size == 4 and env.observation_size == 2 * 98
  n = 4
  keys = jax.random.split(jax.random.PRNGKey(8), n)
  fn = functools.partial(randomize_zones_and_goals, rng=keys, limit_scale=(0.5, 0.9), goal_keep=0.3)
  model_v, _ = fn(env.mjx_model)
  logits = np.asarray(model_v.task.goal_logits)
  mult = np.asarray(model_v.task.bank.speed.info.multiplier)[:, 0]   # velocity mode: the bank's masks
  assert len(set(mult.tolist())) == n and np.all((mult <= -0.5) & (mult >= -0.9))
  assert np.all(np.isfinite(logits).sum(1) >= 2)
  wrapped = wrapper.wrap_for_brax_training(env, episode_length=3, randomization_fn=fn, full_reset=True)
  s = jax.jit(wrapped.reset)(keys)
  step = jax.jit(wrapped.step)
  active = np.isfinite(logits)
  for t in range(4):                                   # crosses the episode limit: auto-reset
    goals = np.asarray(s.info["goal"])                 # [n, K]
    for i in range(n):
      assert active[i, goals[i]].all(), (i, goals[i], np.nonzero(active[i]))
    s = step(s, jnp.zeros((n, 4)))
    assert s.obs.shape == (n, 2 * 98) and bool(jnp.all(jnp.isfinite(s.obs)))
  assert np.asarray(s.info["AutoResetWrapper_done_count"]).tolist() == [1] * n
  # Each env's filter saw its own zone limits: the 50 % zone scaled by that env's factor.
  from jaxfilters.query import speed_limit_at
  sc = env.fleet.world.scenario
  rows, cols = np.nonzero(sc.speed.data == 50)
  xy = np.float32(_cell_xy(sc.speed.origin, sc.speed.resolution, int(np.median(rows)), int(np.median(cols))))
  speed = model_v.task.bank.speed
  lim = [float(speed_limit_at(dataclasses.replace(speed, origin=speed.origin[i],
                                                  info=jax.tree.map(lambda a: a[i], speed.info)), xy)[0])
         for i in range(n)]
  np.testing.assert_allclose(lim, 50.0 * (-mult), rtol=1e-6)


def test_ppo_iterations_train_the_policy():
  # The suite's small training run (tests/rl_small.py): the programs `rl train` compiles for it,
  # so the session's compilation cache compiles them once for the run.
  from sims.rl.ppo import train_with_curve
  from tests import rl_small
  rl_small.fresh_trace_caches()
  _, adapter, algo = rl_small.training_run()
  key = jax.random.PRNGKey(0)
  with jax.numpy_rank_promotion("allow"):              # rejax broadcasts [N, D] - [D] internally
    ts0 = jax.jit(algo.init_state)(jax.random.split(key)[0])    # the initial state train_with_curve starts from
  ts, evals, _ = train_with_curve(adapter, algo, key, calls=[3], num_eval=rl_small.NUM_EVAL)
  per_iter = rl_small.NUM_ENVS * rl_small.NUM_STEPS
  assert int(ts.global_step) == 3 * per_iter                  # three PPO iterations
  assert evals["env_steps"] == [0.0, 3.0 * per_iter]
  moved = jax.tree.map(lambda a, b: float(jnp.max(jnp.abs(a - b))), ts.actor_ts.params, ts0.actor_ts.params)
  assert max(jax.tree.leaves(moved)) > 1e-4
  # Episodes ended by the step limit were reset by the adapter (EpisodeWrapper counts steps).
  assert np.all(np.asarray(ts.env_state.env_state.info["steps"]) < rl_small.EPISODE_LENGTH)
  # The evaluations before and after training: every figure, finite, episodes within the limit.
  assert set(evals) >= {"return", "success", "keepout_entries", "speed_violation_s", "length"}
  assert all(len(v) == 2 and np.all(np.isfinite(v)) for v in evals.values())
  assert all(1 <= n <= rl_small.EPISODE_LENGTH for n in evals["length"])


def test_soak_short():
  report = soak.run_soak(num_worlds=2, robots_per_world=2, chunk_steps=2, num_chunks=4)
  assert report["ok"], report
  assert report["env_steps"] == 2 * 2 * 4 and len(report["memory"]) == 4
  assert report["memory_kind"] in ("bytes_in_use", "live_arrays")
  assert report["keepout_entries"] == 0 and report["nan"] == 0 and report["speed_compliant"]


def test_adapter_randomises_each_env_model():
  # The adapter once paired the randomised leaves with the wrong model fields (mjx.Model's None
  # fields shifted the flattened lists): `train_ppo --randomize` stopped at the first reset.
  from sims.rl.ppo import GymnaxAdapter
  env = NavEnv.create()
  adapter = GymnaxAdapter(env, episode_length=4, randomization_fn=randomize_zones_and_goals)
  reset = jax.jit(jax.vmap(adapter.reset))
  obs, st = reset(jax.random.split(jax.random.PRNGKey(3), 3))
  assert obs.shape == (3, env.observation_size) and bool(jnp.all(jnp.isfinite(obs)))
  models = [adapter.model_for(jax.tree.map(lambda x: x[i], st.model_leaves)) for i in range(3)]
  mults = [float(m.task.bank.speed.info.multiplier[0]) for m in models]
  assert len(set(mults)) == 3
  base = env.mjx_model
  assert models[0].task.bank.speed.data.shape == base.task.bank.speed.data.shape
  assert models[0].task.bank.speed.resolution.shape == base.task.bank.speed.resolution.shape
