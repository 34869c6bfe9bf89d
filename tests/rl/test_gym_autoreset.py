"""NavVectorEnv on Gymnasium's default next-step auto-reset, under Gymnasium's own vector wrappers
and a CleanRL-style rollout loop.

Gymnasium 1.x (gymnasium/vector/sync_vector_env.py, `SyncVectorEnv.step`, NEXT_STEP branch): the
step that ends an episode returns its last observation with terminated/truncated; the env's next
step resets it, returns the reset observation with reward 0 and terminated = truncated = False,
and ignores the action. One vector env of 2 envs with a 3-step limit serves every test here (one
compile, a module fixture).
"""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from sims.rl.gym import NavVectorEnv
from sims.rl.env import NavEnv

N, T = 2, 3


@pytest.fixture(scope="module")
def venv():
  envs = NavVectorEnv(N, episode_length=T, env=NavEnv.create())
  yield envs
  envs.close()


def test_next_step_is_the_default_and_the_modes_are_checked(venv):
  assert venv.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
  assert NavVectorEnv.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
  same = NavVectorEnv(N, episode_length=T, env=venv.env, autoreset_mode=AutoresetMode.SAME_STEP)
  assert same.metadata["autoreset_mode"] is AutoresetMode.SAME_STEP and venv.metadata is not same.metadata
  for bad in (AutoresetMode.DISABLED, "NextStep", None):
    with pytest.raises(ValueError, match="autoreset_mode must be gymnasium.vector.AutoresetMode.NEXT_STEP"):
      NavVectorEnv(N, episode_length=T, env=venv.env, autoreset_mode=bad)


def _to_the_limit(venv, seed):
  obs, _ = venv.reset(seed=seed)
  zero = np.zeros((N, 2), np.float32)
  for t in range(1, T + 1):
    obs, reward, terminated, truncated, infos = venv.step(zero)
    assert not terminated.any()
    np.testing.assert_array_equal(truncated, [t == T] * N)
  return obs, reward


def test_the_step_after_a_done_resets_with_reward_0_and_ignores_the_action(venv):
  last, reward = _to_the_limit(venv, seed=1)
  assert np.all(reward != 0)                                   # the time penalty at least
  runs = []
  for action in (np.full((N, 2), 0.9, np.float32), np.full((N, 2), -0.7, np.float32)):
    assert np.array_equal(_to_the_limit(venv, seed=1)[0], last)          # the same episodes (seeded)
    obs, reward, terminated, truncated, infos = venv.step(action)        # the reset step
    np.testing.assert_array_equal(reward, np.zeros(N, np.float32))
    assert reward.dtype == np.float32
    assert not terminated.any() and not truncated.any()
    assert obs in venv.observation_space and not np.array_equal(obs, last)   # a new episode's first
    assert all(np.all(v == 0) for v in infos["metrics"].values())
    nxt = venv.step(np.full((N, 2), 0.5, np.float32))                    # the new episode's first step
    runs.append((obs, nxt[0], nxt[1]))
  for a, b in zip(runs[0], runs[1]):                          # the reset step's action changed nothing
    np.testing.assert_array_equal(a, b)
  assert np.all(runs[0][2] != 0)                              # the step after the reset is a real step


def test_gymnasium_vector_wrappers(venv):
  envs = gym.wrappers.vector.RecordEpisodeStatistics(venv)
  envs = gym.wrappers.vector.NormalizeObservation(envs)
  envs = gym.wrappers.vector.NormalizeReward(envs)
  envs = gym.wrappers.vector.ClipAction(envs)
  obs, _ = envs.reset(seed=2)
  rng = np.random.default_rng(2)
  count, prev_done, episodes = np.zeros(N, int), np.zeros(N, bool), 0
  for _ in range(3 * (T + 1)):
    actions = rng.uniform(-3, 3, (N, 2)).astype(np.float32)            # ClipAction brings them into [-1, 1]
    obs, reward, terminated, truncated, infos = envs.step(actions)
    assert np.all(np.isfinite(obs)) and np.all(np.isfinite(reward))
    count = np.where(prev_done, 0, count + 1)                 # the reset step is not an episode step
    done = terminated | truncated
    np.testing.assert_array_equal(infos.get("_episode", np.zeros(N, bool)), done)
    if done.any():
      np.testing.assert_array_equal(infos["episode"]["l"][done], count[done])
      episodes += int(done.sum())
    prev_done = done
  assert episodes >= 2 * N
  assert envs.env.env.obs_rms.count > 3 * (T + 1) * N - 1        # NormalizeObservation saw every step


def test_cleanrl_style_rollout(venv):
  """The rollout half of CleanRL's ppo_continuous_action.py (Gymnasium 1.x): its wrappers, buffers and
  episode logging, with a fixed Gaussian policy in place of the network."""
  num_steps = 4 * (T + 1)
  envs = gym.wrappers.vector.RecordEpisodeStatistics(venv)
  envs = gym.wrappers.vector.ClipAction(envs)
  envs = gym.wrappers.vector.NormalizeObservation(envs)
  envs = gym.wrappers.vector.TransformObservation(envs, lambda o: np.clip(o, -10, 10))
  envs = gym.wrappers.vector.NormalizeReward(envs, gamma=0.99)
  envs = gym.wrappers.vector.TransformReward(envs, lambda r: np.clip(r, -10, 10))
  d = envs.single_observation_space.shape[0]
  obs_buf = np.zeros((num_steps, N, d), np.float32)
  rewards, dones = np.zeros((num_steps, N), np.float32), np.zeros((num_steps, N), bool)
  rng = np.random.default_rng(3)
  next_obs, _ = envs.reset(seed=3)
  next_done = np.zeros(N, bool)
  returns, lengths = [], []
  for step in range(num_steps):
    obs_buf[step], dones[step] = next_obs, next_done
    action = rng.normal(0.0, 0.05, (N, 2)).astype(np.float32)
    next_obs, reward, terminations, truncations, infos = envs.step(action)
    next_done = np.logical_or(terminations, truncations)
    rewards[step] = reward
    if "episode" in infos:
      returns += list(infos["episode"]["r"][infos["_episode"]])
      lengths += list(infos["episode"]["l"][infos["_episode"]])
  assert lengths == [T] * len(lengths) and len(lengths) == 4 * N          # slow robots: the time limit, every T + 1 steps
  assert np.all(np.isfinite(returns)) and np.all(np.isfinite(obs_buf)) and np.all(np.abs(rewards) <= 10)
  # A step that follows a done is the reset step: reward 0 before normalisation, so 0 after it too.
  np.testing.assert_array_equal(rewards[dones], 0.0)          # dones[t]: the step before t ended
