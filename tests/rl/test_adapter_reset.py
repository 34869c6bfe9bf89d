"""GymnaxAdapter / FleetAdapter with full_reset under vmap: only the ended envs' (worlds') resets
are drawn (`reset_capacity`).

Episodes staggered so that a few envs end at each step (the time limit and early ends). From the
same states, a capacity of 1 (one pass per ended env) gives the states of resetting every env at
every step and keeping the ended ones (reset_capacity=None): integers and flags exactly, floats
to a few float32 ulps (XLA rounds a reset computed in a batch of 1 slightly differently from one
in a batch of 6, e.g. a sine in the observation: 3e-6 apart). Both adapters step in one program.
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


def _assert_same(a, b, what):
  for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
    x, y = np.asarray(x), np.asarray(y)
    if np.issubdtype(x.dtype, np.floating):
      np.testing.assert_allclose(y, x, rtol=1e-5, atol=1e-5, err_msg=what)
    else:
      np.testing.assert_array_equal(y, x, err_msg=what)


def _both(every, some, n):
  """One program stepping both adapters from the same states (XLA shares the env step): each
  step's states are compared from equal inputs, so one compile serves both."""
  def run(keys, st, actions):
    return (jax.vmap(every.step, in_axes=(0, 0, 0, None))(keys, st, actions, None),
            jax.vmap(some.step, in_axes=(0, 0, 0, None))(keys, st, actions, None))
  reset = jax.jit(jax.vmap(every.reset, in_axes=(0, None)))
  return reset(jax.random.split(jax.random.PRNGKey(0), n), None)[1], jax.jit(run)


def test_resets_of_the_ended_envs_only_equal_resetting_every_env(env):
  st, run = _both(GymnaxAdapter(env, L, full_reset=True, reset_capacity=None),
                  GymnaxAdapter(env, L, full_reset=True, reset_capacity=1), N)
  info = dict(st.env_state.info, steps=jnp.arange(N, dtype=jnp.float32) % L)   # staggered time limits
  st = st.replace(env_state=st.env_state.replace(info=info))
  actions = jnp.tile(jnp.asarray([[1.0, 0.5]]), (N, 1))
  ends = []
  for i in range(STEPS):
    (_, a, _, done_a, _), (_, b, _, done_b, _) = run(jax.random.split(jax.random.PRNGKey(i + 1), N), st, actions)
    np.testing.assert_array_equal(np.asarray(done_b), np.asarray(done_a))
    _assert_same(a, b, f"step {i}")
    ends.append(int(np.asarray(done_a).sum()))
    st = a
  assert sum(e > 0 for e in ends) >= 4 and max(ends) < N      # a few envs end at most steps, never all
  assert max(ends) > 1                                         # some step needs more than one pass


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


def test_fleet_worlds_whose_time_is_up_are_reset_alone():
  """FleetAdapter (one agent per robot): the worlds whose time limit is up restart from a fresh
  reset; computing only those (capacity 1) gives the states of resetting every world."""
  from sims.fleet.config import FleetConfig
  from sims.rl.env import NavEnvConfig
  from sims.rl.fleet import FleetAdapter
  worlds, length = 4, 3
  env = NavEnv.create(fleet_config=FleetConfig(robots_per_world=2), config=NavEnvConfig(agents="per_robot"))
  st, run = _both(FleetAdapter(env, length, full_reset=True, reset_capacity=None),
                  FleetAdapter(env, length, full_reset=True, reset_capacity=1), worlds)
  st = st.replace(steps=jnp.arange(worlds, dtype=jnp.int32) % length)      # staggered time limits
  actions = jnp.tile(jnp.asarray([[[1.0, 0.5]]]), (worlds, env.num_robots, 1))
  for i in range(5):
    (_, a, _, done_a, _), (_, b, _, done_b, _) = run(jax.random.split(jax.random.PRNGKey(i + 1), worlds), st,
                                                     actions)
    np.testing.assert_array_equal(np.asarray(done_b), np.asarray(done_a))
    _assert_same(a, b, f"step {i}")
    restarts = int((np.asarray(a.steps) == 0).sum())
    assert 1 <= restarts < worlds                           # some worlds restart at every step, never all
    st = a


@pytest.mark.parametrize("packed", [True, False], ids=["one_scatter_per_dtype", "one_per_leaf"])
def test_set_rows_writes_the_chosen_rows_of_every_leaf(packed):
  # The write-back of the fresh resets (`set_rows`), both forms, on leaves of every kind an env state
  # has: float32 of several shapes, int32, bool, uint32 keys, a zero-size leaf; indices past the batch
  # (the unused slots) dropped.
  from sims.rl.adapter import set_rows
  rng = np.random.default_rng(0)
  n = 6
  states = {"pos": rng.normal(size=(n, 3)).astype(np.float32), "m": rng.normal(size=(n, 2, 2)).astype(np.float32),
            "steps": rng.integers(0, 9, n).astype(np.int32), "done": rng.random(n) < 0.5,
            "key": rng.integers(0, 2 ** 32, (n, 2), dtype=np.uint64).astype(np.uint32),
            "empty": np.zeros((n, 0), np.float32), "scalar": rng.normal(size=n).astype(np.float32)}
  idx = np.asarray([4, 1, n, n], np.int32)
  new = {k: (np.asarray(v)[:4] + 1).astype(v.dtype) if v.dtype != bool else ~np.asarray(v)[:4]
         for k, v in states.items()}
  got = jax.jit(lambda s, i, x: set_rows(s, i, x, packed=packed))(states, idx, new)
  for k, v in states.items():
    want = np.array(v)
    want[4], want[1] = new[k][0], new[k][1]
    assert got[k].dtype == v.dtype and got[k].shape == v.shape, k
    np.testing.assert_array_equal(np.asarray(got[k]), want, err_msg=k)
