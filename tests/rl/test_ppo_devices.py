"""The block minibatch shuffle of PPO over several devices (`sims.rl.ppo.BlockShufflePPO`).

Each device's samples stay on the device: minibatch m takes an equal slice of every
device's block, and the whole iteration is still a permutation of the batch.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

rejax = pytest.importorskip("rejax", reason="the rl extra (rejax) is not installed")

from sims.rl.ppo import BlockShufflePPO


def _algo(num_envs, num_steps, num_minibatches, blocks):
  algo = BlockShufflePPO.create(env="CartPole-v1", num_envs=num_envs, num_steps=num_steps,
                                num_minibatches=num_minibatches)
  return algo.replace(shuffle_blocks=blocks)


@pytest.mark.parametrize("blocks", [2, 4])
def test_each_minibatch_takes_an_equal_share_of_every_block(blocks):
  t, n, m = 6, 8, 4
  algo = _algo(n, t, m, blocks)
  ids = jnp.arange(t * n).reshape(t, n)                     # sample id = step * n + env
  data = {"id": ids, "obs": jnp.stack([ids, -ids], axis=-1).astype(jnp.float32)}
  out = jax.jit(algo.shuffle_and_split)(data, jax.random.PRNGKey(3))
  got = np.asarray(out["id"])
  assert got.shape == (m, t * n // m)
  np.testing.assert_array_equal(np.sort(got.ravel()), np.arange(t * n))          # a permutation
  np.testing.assert_array_equal(np.asarray(out["obs"])[..., 0], got)            # leaves move together
  np.testing.assert_array_equal(np.asarray(out["obs"])[..., 1], -got)
  block_of = (got % n) // (n // blocks)                     # env -> its device block
  per = t * n // m // blocks
  for mb in range(m):
    # The minibatch is `blocks` contiguous slices, slice d from block d.
    np.testing.assert_array_equal(block_of[mb], np.repeat(np.arange(blocks), per))
  assert not np.array_equal(got.ravel(), np.sort(got.ravel()))                   # shuffled


def test_one_block_is_rejax_shuffle():
  algo = _algo(8, 6, 4, 1)
  data = {"x": jnp.arange(48.0).reshape(6, 8)}
  key = jax.random.PRNGKey(0)
  got = algo.shuffle_and_split(data, key)["x"]
  want = rejax.PPO.shuffle_and_split(algo, data, key)["x"]
  np.testing.assert_array_equal(np.asarray(got), np.asarray(want))
