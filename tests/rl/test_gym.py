"""sims/rl/gym.py: Gymnasium's env checker on NavGymEnv; NavVectorEnv's spaces, seeding, time limit,
terminals, same-step auto-reset (the option; next-step, the default, is tests/rl/test_gym_autoreset.py),
input checks and per-episode randomisation.

One NavEnv serves every env here, and each wrapper compiles once (module fixtures): a single env
with a 4-step limit and a randomised vector env of 3 envs with a 4-step limit. Robots are placed
through `NavVectorEnv.state` (same shapes: nothing recompiles) on cells chosen from the scenario's
own arrays.
"""

import subprocess
import sys
import warnings

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from gymnasium.error import ResetNeeded
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode

from jaxfilters import constants
from sims.rl.gym import OBS_BOUND, NavGymEnv, NavVectorEnv
from sims.rl.env import NavEnv

N, T = 3, 4
LETHAL = constants.INSCRIBED_INFLATED_OBSTACLE


@pytest.fixture(scope="module")
def nav():
  return NavEnv.create()


@pytest.fixture(scope="module")
def venv(nav):
  envs = NavVectorEnv(N, episode_length=T, randomize=True, env=nav, autoreset_mode=AutoresetMode.SAME_STEP)
  yield envs
  envs.close()


def _cell_xy(origin, res, row, col):
  return float(origin[0]) + (col + 0.5) * res, float(origin[1]) + (row + 0.5) * res


def _keepout_value(sc, xy):
  k = sc.keepout
  col = int((xy[0] - float(k.origin[0])) // k.resolution)
  row = int((xy[1] - float(k.origin[1])) // k.resolution)
  return int(k.data[row, col]) if 0 <= row < k.data.shape[0] and 0 <= col < k.data.shape[1] else -1


def _inside_keepout(nav):
  """A point deep inside a keepout zone (5 x 5 cells at 100) on free static ground."""
  sc = nav.fleet.world.scenario
  k = sc.keepout.data
  for r, c in zip(*np.nonzero(k == 100)):
    if np.all(k[r - 2:r + 3, c - 2:c + 3] == 100):
      xy = _cell_xy(sc.keepout.origin, sc.keepout.resolution, r, c)
      if _static_value(nav, xy) == 0:
        return xy
  raise AssertionError("the scenario has no keepout zone on free ground")


def _static_value(nav, xy):
  sc = nav.fleet.world.scenario
  stat = np.asarray(nav.mjx_model.task.static_inflated)
  col = int((xy[0] - float(sc.map.origin[0])) // sc.map.resolution)
  row = int((xy[1] - float(sc.map.origin[1])) // sc.map.resolution)
  return int(stat[row, col])


def _on_obstacle(nav):
  """A point on a lethal cell of the inflated static layer, away from keepout zones."""
  sc = nav.fleet.world.scenario
  stat = np.asarray(nav.mjx_model.task.static_inflated)
  for r, c in zip(*np.nonzero(stat == constants.LETHAL_OBSTACLE)):
    xy = _cell_xy(sc.map.origin, sc.map.resolution, r, c)
    if _keepout_value(sc, xy) == 0:
      return xy
  raise AssertionError("the scenario has no static obstacle outside the keepout zones")


def _place(envs, placements):
  """Puts robot 0 of env i at (x, y), yaw 0, for each (i, (x, y)) in placements."""
  st = envs.state
  qpos = st.env_state.data.qpos
  for i, xy in placements:
    qpos = qpos.at[i, 0].set(jnp.asarray([xy[0], xy[1], 0.0], qpos.dtype))
  es = st.env_state
  es = es.replace(data=es.data.replace(qpos=qpos), info={**es.info, "last_qpos": qpos})
  envs.state = st.replace(env_state=es)


def test_sims_exports_the_envs_lazily():
  import sims
  assert sims.NavVectorEnv is NavVectorEnv and sims.NavGymEnv is NavGymEnv
  assert {"NavGymEnv", "NavVectorEnv"} <= set(sims.__all__)
  code = "import sys, sims; assert 'gymnasium' not in sys.modules and 'jax' not in sys.modules"
  subprocess.run([sys.executable, "-c", code], check=True)


def test_single_env_passes_gymnasium_check_env(nav):
  env = NavGymEnv(episode_length=T, env=nav)
  assert env.action_space == gymnasium.spaces.Box(-1.0, 1.0, (2,), np.float32)
  assert env.observation_space.dtype == np.float32 and env.observation_space.shape == (98,)
  with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    check_env(env, skip_render_check=True)
  # The checker reports some problems (an observation outside its space, ...) only as warnings,
  # through gymnasium.logger ("WARN: ...").
  assert not [m for w in caught if "WARN:" in (m := str(w.message))]
  obs, info = env.reset(seed=7)
  assert obs.dtype == np.float32 and info == {}
  for t in range(T):
    obs, reward, terminated, truncated, info = env.step(np.zeros(2, np.float32))
    assert isinstance(reward, float) and type(terminated) is bool and type(truncated) is bool
    assert obs in env.observation_space and set(info["metrics"]) >= {"keepout_entries", "collisions"}
  assert (terminated, truncated) == (False, True)                 # at rest: the time limit ends it
  with pytest.raises(ResetNeeded, match="reset"):
    env.step(np.zeros(2, np.float32))
  env.reset()
  with pytest.raises(ValueError, match=r"actions must be float32 \[2\].*got shape \[1, 2\]"):
    env.step(np.zeros((1, 2), np.float32))
  env.close()


def test_vector_spaces_and_metadata(venv):
  assert venv.metadata["autoreset_mode"] is AutoresetMode.SAME_STEP
  assert venv.render_mode is None
  assert venv.single_observation_space == gymnasium.spaces.Box(-OBS_BOUND, OBS_BOUND, (98,), np.float32)
  assert venv.single_action_space == gymnasium.spaces.Box(-1.0, 1.0, (2,), np.float32)
  assert venv.observation_space.shape == (N, 98) and venv.observation_space.dtype == np.float32
  assert venv.action_space.shape == (N, 2) and venv.action_space.dtype == np.float32
  with pytest.raises(ValueError, match="render_mode must be None"):
    NavVectorEnv(N, render_mode="rgb_array")
  with pytest.raises(ValueError, match="num_envs must be an integer >= 1; got 0"):
    NavVectorEnv(0)
  with pytest.raises(ValueError, match="randomization_fn is used only with randomize=True"):
    NavVectorEnv(N, randomization_fn=lambda model, rng: (model, None))


def test_vector_reset_is_seeded(venv):
  a, info = venv.reset(seed=1)
  assert info == {} and a.shape == (N, 98) and a.dtype == np.float32 and a in venv.observation_space
  a_next, _ = venv.reset()                                     # continues the seeded RNG
  b, _ = venv.reset(seed=1)
  b_next, _ = venv.reset()
  c, _ = venv.reset(seed=2)
  np.testing.assert_array_equal(a, b)
  np.testing.assert_array_equal(a_next, b_next)
  assert not np.array_equal(a, c) and not np.array_equal(a, a_next)
  assert not np.array_equal(a[0], a[1])                        # the envs differ from each other
  with pytest.raises(ValueError, match="seed must be None or an integer >= 0; got -1"):
    venv.reset(seed=-1)
  with pytest.raises(ValueError, match="takes no options"):
    venv.reset(options={"reset_mask": np.ones(N, bool)})


def test_vector_wrong_actions_raise(venv):
  venv.reset(seed=3)
  ok = np.zeros((N, 2), np.float32)
  cases = [(np.zeros((N, 3), np.float32), r"float32 \[3, 2\].*got shape \[3, 3\]"),
           (np.zeros(2, np.float32), r"got shape \[2\]"),
           (ok.astype(np.int32), "got dtype int32"),
           (ok.astype(bool), "got dtype bool"),
           (np.where(np.eye(N, 2, dtype=bool), np.nan, ok), r"must be finite .* got nan at index \[0, 0\]"),
           (np.where(np.eye(N, 2, k=1, dtype=bool), -np.inf, ok), r"got -inf at index \[0, 1\]"),
           (np.full((N, 2), 0.5) + np.eye(N, 2), r"must lie in \[-1, 1\].*got 1.5 at index \[0, 0\]"),
           (np.where(np.eye(N, 2, k=1, dtype=bool), 1e-50, 0.25), r"float32 would make 1e-50 at index \[0, 1\] subnormal or 0"),
           (np.full((N, 2), -2e-39), r"at least 1.18e-38 in magnitude")]
  for bad, match in cases:
    with pytest.raises(ValueError, match=match):
      venv.step(bad)
  with pytest.raises(ValueError, match="structure of the current state"):
    venv.state = venv.state.replace(model_leaves=[])
  qpos = venv.state.env_state.data.qpos
  with pytest.raises(ValueError, match="shape/dtype"):
    venv.state = venv.state.replace(env_state=venv.state.env_state.replace(
        data=venv.state.env_state.data.replace(qpos=qpos[:1])))
  fresh = NavVectorEnv(N, episode_length=T, randomize=True, env=venv.env,   # shares the compiled programs
                       autoreset_mode=AutoresetMode.SAME_STEP)
  with pytest.raises(ResetNeeded, match="before reset"):
    fresh.step(ok)


def test_vector_terminals_truncation_and_same_step_autoreset(venv, nav):
  obs0, _ = venv.reset(seed=4)
  leaves0 = [np.asarray(x) for x in venv.state.model_leaves]
  # Randomised per env: each env drew its own zone scale (at least one leaf differs between envs).
  assert any(not np.array_equal(x[0], x[1]) for x in leaves0)
  centre = nav.nav_config.crop_cells ** 2 // 2                 # the crop cell under the robot
  assert np.all(obs0[:, centre] < LETHAL / 255)
  _place(venv, [(0, _on_obstacle(nav)), (1, _inside_keepout(nav))])
  rewards = np.zeros(N)
  zero = np.zeros((N, 2), np.float32)
  obs, reward, terminated, truncated, infos = venv.step(zero)
  rewards += reward
  assert reward.dtype == np.float32 and terminated.dtype == bool and truncated.dtype == bool
  np.testing.assert_array_equal(terminated, [True, True, False])
  np.testing.assert_array_equal(truncated, [False, False, False])
  m = infos["metrics"]
  np.testing.assert_array_equal(m["collisions"], [1, 0, 0])
  np.testing.assert_array_equal(m["keepout_entries"], [0, 1, 0])
  assert np.all(reward[:2] < -9.0)                             # the 10.0 penalties
  np.testing.assert_array_equal(infos["_final_obs"], [True, True, False])
  fo = infos["final_obs"]
  assert fo.shape == (N, 98) and fo.dtype == np.float32
  assert np.all(fo[:2, centre] >= LETHAL / 255)                # the observation before the reset
  assert np.all(obs[:2, centre] < LETHAL / 255)                # the new episode's first
  np.testing.assert_array_equal(fo[2], obs[2])                 # a running env: its next observation
  fi = infos["final_info"]
  np.testing.assert_array_equal(infos["_final_info"], [True, True, False])
  np.testing.assert_array_equal(fi["episode_length"][:2], [1, 1])
  np.testing.assert_allclose(fi["episode_return"][:2], reward[:2], rtol=1e-6)
  # The ended envs drew a new model (full reset); the running one kept its own.
  leaves1 = [np.asarray(x) for x in venv.state.model_leaves]
  assert any(not np.array_equal(a[0], b[0]) for a, b in zip(leaves0, leaves1))
  assert all(np.array_equal(a[2], b[2]) for a, b in zip(leaves0, leaves1))
  rewards[:2] = 0.0
  for t in range(2, T + 1):
    obs, reward, terminated, truncated, infos = venv.step(zero)
    rewards += reward
    assert obs in venv.observation_space and infos["final_obs"] in venv.observation_space
    assert not terminated.any()
    np.testing.assert_array_equal(truncated, [False, False, t == T])
  np.testing.assert_array_equal(infos["_final_obs"], [False, False, True])
  assert infos["final_info"]["episode_length"][2] == T
  assert infos["final_info"]["episode_return"][2] == pytest.approx(rewards[2], rel=1e-6)
  assert not np.array_equal(infos["final_obs"][2], obs[2])
  obs, _, _, truncated, _ = venv.step(zero)                    # envs 0 and 1 reach the limit a step later
  np.testing.assert_array_equal(truncated, [True, True, False])


def test_vector_random_policy_stays_in_the_spaces_and_replays(venv):
  venv.action_space.seed(5)
  actions = [venv.action_space.sample() for _ in range(12)]
  runs = []
  for _ in range(2):                                           # same seed, same actions: same episodes
    venv.reset(seed=5)
    run = []
    for a in actions:
      obs, reward, terminated, truncated, infos = venv.step(a)
      assert obs in venv.observation_space and infos["final_obs"] in venv.observation_space
      assert np.all(np.isfinite(reward)) and not np.any(terminated & truncated)
      assert np.all(infos["metrics"]["bad_action"] == 0)
      run.append((obs, reward, terminated, truncated))
    runs.append(run)
  for x, y in zip(jax.tree.leaves(runs[0]), jax.tree.leaves(runs[1])):
    np.testing.assert_array_equal(x, y)


def test_torch_wrapper(venv):
  torch = pytest.importorskip("torch")
  from gymnasium.wrappers.vector import NumpyToTorch
  envs = NumpyToTorch(venv)
  obs, _ = envs.reset(seed=6)
  obs, reward, terminated, truncated, infos = envs.step(torch.zeros((N, 2)))
  assert isinstance(obs, torch.Tensor) and obs.shape == (N, 98) and isinstance(infos["final_obs"], torch.Tensor)
