"""sims/rl/brax_compat.py: Brax's own PPO (brax.training.agents.ppo.train) on this project's jax pin.

Without the shim Brax 0.14.2's PPO stops at `jax.device_put_replicated` (removed from JAX); with it,
a few PPO iterations run on the RL env through Playground's `wrap_for_brax_training`, with the
env's own domain randomizer. The `jax` module itself stays as it was.
"""

import functools

import jax
import numpy as np
import pytest
from brax.training.agents.ppo import networks as ppo_networks
from brax.training.agents.ppo import train as ppo
from mujoco_playground import wrapper

from sims.rl import brax_compat, registry

pytestmark = pytest.mark.skipif(brax_compat.jax_has_device_put_replicated(),
                                reason="this jax still has device_put_replicated: Brax needs no shim")

TINY = dict(num_timesteps=256, episode_length=8, num_envs=4, batch_size=4, num_minibatches=2, unroll_length=4,
            num_updates_per_batch=1, num_evals=1, num_eval_envs=4, seed=0, wrap_env_fn=wrapper.wrap_for_brax_training,
            network_factory=functools.partial(ppo_networks.make_ppo_networks, policy_hidden_layer_sizes=(16,),
                                              value_hidden_layer_sizes=(16,)))


@pytest.fixture(scope="module")
def env():
  return registry.load("JaxfiltersNavRandomized", config_overrides={"layouts": 2})


def test_device_put_replicated_is_jax_drop_in():
  devices = jax.local_devices()
  tree = {"a": np.arange(6, dtype=np.float32).reshape(2, 3), "b": np.int32(7)}
  out = brax_compat.device_put_replicated(tree, devices)
  n = len(devices)
  np.testing.assert_array_equal(np.asarray(out["a"]), np.stack([tree["a"]] * n))
  np.testing.assert_array_equal(np.asarray(out["b"]), np.full(n, 7, np.int32))
  assert out["a"].sharding.spec == jax.sharding.PartitionSpec("_device_put_replicated")
  assert [s.device for s in out["a"].addressable_shards] == devices
  with pytest.raises(ValueError, match="non-empty sequence"):
    brax_compat.device_put_replicated(tree, [])


def test_brax_ppo_stops_without_the_shim_and_trains_with_it(env):
  assert not brax_compat.installed()
  randomizer = registry.get_domain_randomizer("JaxfiltersNavRandomized")
  # The same call both times: the env reset Brax compiles before it stops is the one the run below
  # reuses (from the session's compilation cache).
  with jax.numpy_rank_promotion("allow"), pytest.raises(AttributeError, match="device_put_replicated"):
    ppo.train(environment=env, randomization_fn=randomizer, **TINY)
  assert brax_compat.install() is True
  assert brax_compat.install() is True and brax_compat.installed()      # idempotent
  with pytest.raises(AttributeError):
    jax.device_put_replicated       # noqa: B018 - the jax module itself is untouched
  progress = []
  with jax.numpy_rank_promotion("allow"):   # the suite raises on it; Brax's normalizer broadcasts [T, B, D] - [D]
    make_policy, params, metrics = ppo.train(
        environment=env, randomization_fn=randomizer,
        progress_fn=lambda step, m: progress.append((step, dict(m))), **TINY)
  assert [s for s, _ in progress][-1] >= TINY["num_timesteps"]
  assert np.isfinite(float(metrics["eval/episode_reward"]))
  assert "eval/episode_keepout_entries" in metrics          # the env's own metrics come through
  policy = make_policy(params, deterministic=True)
  obs = np.zeros((1, env.observation_size), np.float32)
  with jax.numpy_rank_promotion("allow"):
    action, _ = policy(obs, jax.random.PRNGKey(0))
  assert action.shape == (1, env.action_size) and np.all(np.abs(np.asarray(action)) <= 1.0)
