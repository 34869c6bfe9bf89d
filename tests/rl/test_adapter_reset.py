"""GymnaxAdapter with full_reset under vmap: only the ended envs' resets are drawn (`reset_capacity`).

Episodes staggered so that a few envs end at each step (the time limit and early ends): with a
capacity of 1 (one pass per ended env) the batch's states equal those of resetting every env at
every step and keeping the ended ones (reset_capacity=None): integers and flags exactly, floats to
a few float32 ulps (XLA rounds a reset computed in a batch of 1 slightly differently from one in
a batch of 6, e.g. a sine in the observation: 3e-6 apart).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sims.rl.adapter import GymnaxAdapter, auto_reset_capacity
from sims.rl.env import NavEnv

N, L, STEPS = 6, 4, 7


@pytest.fixture(scope="module")
def env():
  return NavEnv.create()


def _run(env, capacity):
  ad = GymnaxAdapter(env, L, full_reset=True, reset_capacity=capacity)
  _, st = jax.jit(jax.vmap(ad.reset, in_axes=(0, None)))(jax.random.split(jax.random.PRNGKey(0), N), None)
  info = dict(st.env_state.info, steps=jnp.arange(N, dtype=jnp.float32) % L)   # staggered time limits
  st = st.replace(env_state=st.env_state.replace(info=info))
  step = jax.jit(jax.vmap(ad.step, in_axes=(0, 0, 0, None)))
  actions = jnp.tile(jnp.asarray([[1.0, 0.5]]), (N, 1))
  states, dones = [], []
  for i in range(STEPS):
    _, st, _, done, _ = step(jax.random.split(jax.random.PRNGKey(i + 1), N), st, actions, None)
    states.append(st)
    dones.append(np.asarray(done))
  return states, np.stack(dones)


def test_resets_of_the_ended_envs_only_equal_resetting_every_env(env):
  every, done_every = _run(env, None)
  some, done_some = _run(env, 1)
  np.testing.assert_array_equal(done_some, done_every)
  ends = done_every.sum(axis=1)
  assert (ends > 0).sum() >= 4 and ends.max() < N       # a few envs end at most steps, never all
  assert ends.max() > 1                                   # some step needs more than one pass
  for i, (a, b) in enumerate(zip(every, some)):
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
      x, y = np.asarray(x), np.asarray(y)
      if np.issubdtype(x.dtype, np.floating):
        np.testing.assert_allclose(y, x, rtol=1e-5, atol=1e-5, err_msg=f"step {i}")
      else:
        np.testing.assert_array_equal(y, x, err_msg=f"step {i}")


def test_auto_capacity_and_bad_values():
  assert auto_reset_capacity(16384, 300) == 219 and auto_reset_capacity(4, 6) == 4
  assert auto_reset_capacity(1000, 10000) == 8 and auto_reset_capacity(64, 1) == 64
  assert GymnaxAdapter(None, 5).reset_capacity == "auto"
  for bad in (0, -1, True, 1.5, "all", "Auto"):
    with pytest.raises(ValueError, match="reset_capacity must be an integer >= 1, 'auto' or None"):
      GymnaxAdapter(None, 5, reset_capacity=bad)


def test_sharded_training_resets_every_env():
  """block_shuffle (the sharded trainer) hands rejax an adapter with reset_capacity None; the
  caller's adapter keeps its own."""
  from sims.rl.ppo import block_shuffle, make_ppo
  from sims.scale import sharding
  adapter = GymnaxAdapter(NavEnv.create(), L, full_reset=True)
  algo = make_ppo(adapter, timesteps_per_call=4 * 8, num_envs=4, num_steps=8, num_minibatches=2, hidden=(4,))
  blocked = block_shuffle(algo, sharding.make_mesh(1))
  inner = blocked.env.env                       # rejax's FloatObsWrapper around the adapter
  assert isinstance(inner, GymnaxAdapter) and inner.reset_capacity is None and inner.full_reset
  assert adapter.reset_capacity == "auto" and algo.env.env.reset_capacity == "auto"
