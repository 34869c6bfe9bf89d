"""One policy for every robot (`NavEnvConfig(agents="per_robot")`, sims/rl/agents.py, sims/rl/fleet.py):
per-robot shapes, the exact disc contact test, respawns, the world's time limit, a few PPO iterations
with the agents folded into the batch, and the world mode left as it was.

One env of K = 3 robots on the built-in warehouse is compiled once (module fixture); robots are
placed by editing `state.data.qpos` (same shapes: nothing recompiles).
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfilters import constants
from sims.fleet.config import FleetConfig
from sims.rl import agents, kernels
from sims.rl.env import NavEnv, NavEnvConfig
from sims.rl.fleet import FleetAdapter, FleetPPO, evaluate_fleet_policy, make_fleet_ppo

K = 3
R = FleetConfig().robot.radius


@pytest.fixture(scope="module")
def fleet():
  """Per-robot env of K robots with the costmap stop off (contacts are the policy's): env, reset, step."""
  env = NavEnv.create(fleet_config=FleetConfig(robots_per_world=K), config=NavEnvConfig(agents="per_robot"))
  return env, jax.jit(env.reset), jax.jit(env.step)


def _place(state, qpos):
  qpos = jnp.asarray(qpos, jnp.float32)
  return state.replace(data=state.data.replace(qpos=qpos), info=dict(state.info, last_qpos=qpos))


def _free(env, xy) -> bool:
  task = env.mjx_model.task
  p = task.world
  static = int(kernels.grid_value(task.static_inflated, p.map_origin, p.map_resolution, jnp.asarray(xy, jnp.float32),
                                  constants.NO_INFORMATION))
  keep = int(kernels.keepout_cost(task, jnp.asarray(xy, jnp.float32)))
  return static < constants.INSCRIBED_INFLATED_OBSTACLE and keep in (0, constants.NO_INFORMATION)


def _pair_and_far(env, gap):
  """Poses [K, 3]: robots 0 and 1 `gap` m apart facing away from each other on free cells, robot 2 far away."""
  spawns = np.asarray(env.mjx_model.task.bank.spawns[0][:int(env.mjx_model.task.bank.spawn_count[0])])
  for a in spawns:
    b = a + np.array([gap, 0.0])
    if _free(env, b) and _free(env, a + np.array([-0.3, 0.0])) and _free(env, b + np.array([0.3, 0.0])):
      far = spawns[np.argmax(np.linalg.norm(spawns - a, axis=1))]
      return np.array([[*a, np.pi], [*b, 0.0], [*far, 0.0]], np.float32)
  raise AssertionError("no free pair of cells on the built-in warehouse")


def test_per_robot_shapes_and_action_checks(fleet):
  env, reset, step = fleet
  assert env.observation_size == 98 and env.action_size == 2
  s = reset(jax.random.PRNGKey(0))
  assert s.obs.shape == (K, 98) and s.reward.shape == (K,) and s.done.shape == (K,)
  assert all(v.shape == (K,) for v in s.metrics.values()) and "robot_collisions" in s.metrics
  s2 = step(s, jnp.full((K, 2), 0.3, jnp.float32))
  assert jax.tree.structure(s2) == jax.tree.structure(s)
  assert s2.reward.shape == (K,) and bool(jnp.all(jnp.isfinite(s2.obs)))
  # Each robot's row is its own view: the world mode's concatenation of the same robots.
  world = NavEnv(env.fleet, NavEnvConfig())
  np.testing.assert_array_equal(np.asarray(jax.jit(world.reset)(jax.random.PRNGKey(0)).obs),
                                np.asarray(s.obs).reshape(-1))
  with pytest.raises(ValueError, match=r"action must be float \[K, 2\] = \(3, 2\).*got shape \(6,\)"):
    env.step(s, jnp.zeros((2 * K,)))
  with pytest.raises(TypeError, match="floating point"):
    env.step(s, jnp.zeros((K, 2), jnp.int32))
  # A NaN or out-of-range action is counted for the robot that sent it.
  s3 = step(s, jnp.asarray([[jnp.nan, 0.0], [0.0, 0.0], [2.0, -3.0]], jnp.float32))
  np.testing.assert_array_equal(np.asarray(s3.metrics["bad_action"]), [1.0, 0.0, 2.0])


def test_agents_option_is_checked():
  with pytest.raises(ValueError, match=r"agents must be one of \('world', 'per_robot'\).*'navigation' mode"):
    NavEnvConfig(mode="navigation", agents="per_robot")
  with pytest.raises(ValueError, match="got 'robot'"):
    NavEnvConfig(agents="robot")


def test_robot_contacts_is_the_exact_disc_test():
  rng = np.random.default_rng(0)
  xy = rng.uniform(0, 3, (40, 2)).astype(np.float32)
  d = np.linalg.norm(xy[:, None].astype(np.float64) - xy[None], axis=-1) + np.diag(np.full(40, np.inf))
  margin = np.abs(d - 2 * R).min()
  assert margin > 1e-4                      # no pair so close to 2r that float32 could flip it
  want = (d < 2 * R).any(axis=1)
  np.testing.assert_array_equal(np.asarray(agents.robot_contacts(jnp.asarray(xy), R)), want)
  assert want.any() and not want.all()
  for eps, touch in ((-1e-3, True), (1e-3, False)):
    pair = jnp.asarray([[0.0, 0.0], [2 * R + eps, 0.0]], jnp.float32)
    assert np.asarray(agents.robot_contacts(pair, R)).tolist() == [touch, touch]


def test_robot_stop_blocks_driving_into_another_robot_only():
  qpos = jnp.asarray([[0.0, 0.0, 0.0], [2 * R + 0.05, 0.0, 0.0], [5.0, 5.0, 0.0]], jnp.float32)
  cmd = jnp.asarray([[0.5, 0.3], [0.5, 0.0], [0.5, 0.0]], jnp.float32)
  out, blocked = agents.robot_stop(qpos, cmd, 0.05, R)
  # Robot 0 drives at robot 1 (its look-ahead reaches its disc): stopped, still turning; robot 1
  # drives away and robot 2 is alone: both go on.
  assert np.asarray(blocked).tolist() == [True, False, False]
  np.testing.assert_array_equal(np.asarray(out), np.float32([[0.0, 0.3], [0.5, 0.0], [0.5, 0.0]]))
  _, back = agents.robot_stop(qpos, cmd.at[0, 0].set(-0.5), 0.05, R)      # reversing away: free
  assert not bool(back[0])


@pytest.mark.parametrize("eps, touch", [(-1e-3, True), (1e-3, False)], ids=["2r-eps", "2r+eps"])
def test_contact_is_counted_penalised_and_respawns_both_robots(fleet, eps, touch):
  env, reset, step = fleet
  s = reset(jax.random.PRNGKey(1))
  qpos = _pair_and_far(env, 2 * R + eps)
  s = _place(s, np.concatenate([qpos, np.asarray(s.data.qpos[:, 3:])], axis=1))
  s2 = step(s, jnp.zeros((K, 2), jnp.float32))
  hit = [touch, touch, False]
  np.testing.assert_array_equal(np.asarray(s2.metrics["robot_collisions"]), np.float32(hit))
  np.testing.assert_array_equal(np.asarray(s2.done), np.float32(hit))
  np.testing.assert_array_equal(np.asarray(s2.metrics["collisions"]), 0.0)       # no wall touched
  assert float(s2.metrics["keepout_entries"].sum()) == 0.0
  # The contact costs collision_penalty on top of the step's other terms (time penalty only here).
  penalty = env.nav_config.collision_penalty * np.float32(hit)
  np.testing.assert_allclose(np.asarray(s2.reward), -env.nav_config.time_penalty - penalty, atol=1e-6)
  xy = np.asarray(s2.data.qpos[:, :2])
  if touch:
    # Both robots start a new episode elsewhere, clear of the robot that drove on and of each other.
    assert np.linalg.norm(xy[:2] - qpos[:2, :2], axis=1).min() > 0.0
    assert np.linalg.norm(xy[:2] - xy[2], axis=1).min() > agents.RESPAWN_CLEARANCE
    assert np.linalg.norm(xy[0] - xy[1]) >= 2 * R
    assert all(_free(env, p) for p in xy[:2])
    np.testing.assert_array_equal(np.asarray(s2.data.qvel[:2]), 0.0)
    np.testing.assert_array_equal(np.asarray(s2.info["last_qpos"]), np.asarray(s2.data.qpos))
  else:
    np.testing.assert_allclose(xy[:2], qpos[:2, :2], atol=1e-6)
  np.testing.assert_allclose(xy[2], qpos[2, :2], atol=1e-6)     # the third robot is untouched
  # The next step does not take the respawn for an auto-reset: the robots keep their new places.
  s3 = step(s2, jnp.zeros((K, 2), jnp.float32))
  np.testing.assert_allclose(np.asarray(s3.data.qpos[:, :2]), xy, atol=1e-5)
  assert float(s3.metrics["robot_collisions"].sum()) == 0.0 and float(s3.done.sum()) == 0.0


def test_world_time_limit_ends_every_robot_episode(fleet):
  env, _, _ = fleet
  adapter = FleetAdapter(env, episode_length=2)
  reset, step = jax.jit(adapter.reset), jax.jit(adapter.step)
  obs0, st = reset(jax.random.PRNGKey(2))
  assert obs0.shape == (K, 98)
  a = jnp.full((K, 2), 0.2, jnp.float32)
  obs, st, reward, done, info = step(jax.random.PRNGKey(3), st, a)
  assert reward.shape == (K,) and not bool(done.any()) and int(st.steps) == 1
  obs, st, reward, done, info = step(jax.random.PRNGKey(4), st, a)
  assert bool(done.all()) and bool(info["truncation"].all()) and int(st.steps) == 0
  np.testing.assert_array_equal(np.asarray(obs), np.asarray(obs0))        # the world restarted
  assert adapter.observation_space().shape == (98,) and adapter.action_space().shape == (2,)
  with pytest.raises(ValueError, match="agents='per_robot'"):
    FleetAdapter(NavEnv(env.fleet, NavEnvConfig()), 4)


def test_ppo_folds_the_robots_into_the_batch(fleet):
  from sims.rl.ppo import mean_policy, train_program
  env, _, _ = fleet
  adapter = FleetAdapter(env, episode_length=4)
  algo = make_fleet_ppo(adapter, num_worlds=2, num_steps=4, num_minibatches=2, num_epochs=1, hidden=(8,))
  assert isinstance(algo, FleetPPO) and algo.num_envs == 2 * K and algo.robots_per_world == K
  with jax.numpy_rank_promotion("allow"):
    ts0, train = train_program(algo, jax.random.PRNGKey(0))
    ts = train(ts0, np.int32(2))
    out = jax.jit(lambda k: evaluate_fleet_policy(adapter, mean_policy(algo, ts), k, 2))(jax.random.PRNGKey(1))
  assert int(ts.global_step) == 2 * 2 * K * 4                # robot-steps of two iterations
  assert ts.last_obs.shape == (2 * K, 98) and ts.obs_rms_state.mean.shape == (98,)
  leaves = jax.tree.leaves(ts.actor_ts.params) + jax.tree.leaves(ts.critic_ts.params)
  assert all(bool(jnp.all(jnp.isfinite(x))) for x in leaves)
  moved = jax.tree.map(lambda a, b: float(jnp.max(jnp.abs(a - b))), ts.actor_ts.params, ts0.actor_ts.params)
  assert max(jax.tree.leaves(moved)) > 1e-4
  assert {n: v.shape for n, v in out.items()} == {n: (2 * K,) for n in out} and "robot_collisions" in out
  assert np.all(np.asarray(out["length"]) <= 4) and np.all(np.isfinite(np.asarray(out["return"])))
  with pytest.raises(ValueError, match=r"num_minibatches \(5\) must divide"):
    make_fleet_ppo(adapter, num_worlds=2, num_steps=4, num_minibatches=5)


def test_world_mode_is_unchanged_by_the_option(fleet):
  cfg = NavEnvConfig()
  assert cfg.agents == "world" and dataclasses.replace(cfg, agents="per_robot").agents == "per_robot"
  env = NavEnv(fleet[0].fleet, cfg)
  key = jax.ShapeDtypeStruct((2,), jnp.uint32)
  s = jax.eval_shape(env.reset, key)
  assert s.obs.shape == (K * 98,) and s.reward.shape == () and "robot_collisions" not in s.metrics
  assert env.action_size == 2 * K
  s2 = jax.eval_shape(env.step, s, jax.ShapeDtypeStruct((2 * K,), jnp.float32))
  assert s2.done.shape == () and all(v.shape == () for v in s2.metrics.values())


def test_gymnasium_envs_refuse_the_per_robot_mode(fleet):
  from sims.rl.gym import NavGymEnv, NavVectorEnv
  with pytest.raises(ValueError, match=r"NavGymEnv: env must be one agent per env.*'per_robot'.*sims.rl.fleet"):
    NavGymEnv(env=fleet[0])
  with pytest.raises(ValueError, match="one agent per env"):
    NavVectorEnv(2, env=fleet[0])
