"""Gymnasium interfaces to the fleet RL env (`sims.rl.env.NavEnv`, velocity mode), NumPy in and out.

`NavVectorEnv` is a `gymnasium.vector.VectorEnv` of N envs stepped by one
jitted, vmapped JAX call (CleanRL-style loops, PufferLib); `NavGymEnv` is one
`gymnasium.Env` (what Stable-Baselines3 wraps; it passes
`gymnasium.utils.env_checker.check_env`). Both sit on `sims.rl.adapter.GymnaxAdapter`
(Brax's time limit inside; with `randomize=True`, zones and goals drawn per
episode by `sims.rl.randomization.randomize_zones_and_goals`), so they run the same env as
the JAX trainer:

    import numpy as np
    from sims.rl.gym import NavGymEnv, NavVectorEnv
    from sims.rl.env import NavEnv

    nav = NavEnv.create()                                 # the built-in warehouse, 1 robot per env
    envs = NavVectorEnv(8, episode_length=150, randomize=True, env=nav)
    obs, infos = envs.reset(seed=0)                       # float32 [8, 98]
    rng = np.random.default_rng(0)
    for _ in range(20):                                   # a random policy
        actions = rng.uniform(-1, 1, (8, 2)).astype(np.float32)   # (v, w) per env
        obs, rewards, terminated, truncated, infos = envs.step(actions)
        # Gymnasium's next-step auto-reset: an env that ended here returns its last observation;
        # its next step resets it (reward 0, not done) and ignores that step's action.
    envs.close()

    env = NavGymEnv(episode_length=150, env=nav)          # one env: Gymnasium's Env API
    obs, info = env.reset(seed=0)                         # float32 [98]
    done = False
    while not done:
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        done = terminated or truncated
    env.close()

Stable-Baselines3 (needs torch and stable-baselines3, neither in this
project's extras) takes `NavGymEnv` as it is; envs that share one `NavEnv`
share one compiled program:

    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    model = PPO("MlpPolicy", make_vec_env(lambda: NavGymEnv(env=nav), n_envs=8)).learn(100_000)

PyTorch tensors in and out (where torch is installed) come from Gymnasium's
own wrappers: `gymnasium.wrappers.vector.NumpyToTorch(NavVectorEnv(...),
device="cuda")` and `gymnasium.wrappers.NumpyToTorch(NavGymEnv(...))`. The
JAX-to-Torch wrappers (`gymnasium.wrappers.vector.JaxToTorch`) are for envs
that return JAX arrays; these return NumPy.

Spaces: observation float32 [D] (D = `NavEnv.observation_size`, 98 for one
robot) in a Box of [-OBS_BOUND, OBS_BOUND] (every entry of the velocity-mode
observation is normalised to [-1, 1]: clipped, a ratio to a maximum, or a unit
vector's component; the bound leaves room for float32 rounding in the ratios
and unit vectors); action float32 [A] (A = 2K, each robot's (v, w)) in Box(-1, 1).

Episodes: the time limit (`episode_length` env steps of 0.2 s) sets
`truncated`; a keepout entry (with `NavEnvConfig(keepout="terminate")`, the
default) or a collision with a static obstacle sets `terminated`
(`terminated = done and not time limit`; a terminal on the last step is
`terminated`). Each new episode is a fresh reset (new spawn, goal and, with
`randomize`, a new zone layout), from a JAX PRNG key derived from the seed, so
`reset(seed=s)` is reproducible.

Auto-reset (`NavVectorEnv`, `metadata["autoreset_mode"]`), Gymnasium's
default `AutoresetMode.NEXT_STEP` unless `autoreset_mode=` says otherwise:
the step that ends an episode returns its last observation and
`terminated`/`truncated`; the env's next `step` resets it, returns the new
episode's first observation with reward 0 and `terminated = truncated =
False`, and ignores that env's action (it must still lie in the action space).
This is what `SyncVectorEnv` does by default and what Gymnasium's vector
wrappers (`NormalizeObservation`, `NormalizeReward`,
`RecordEpisodeStatistics`, `ClipAction`) and CleanRL-style loops expect;
`infos` holds only `"metrics"` (zeros for an env that was reset).

With `autoreset_mode=AutoresetMode.SAME_STEP`, an env that ends an episode is
reset inside the same `step` call; the returned observation is the new episode's first, and
`infos["final_obs"]` (float32 [N, D]) holds each env's observation after its
action, before any reset, with `infos["_final_obs"]` (bool [N]) marking the
envs that ended (`terminated | truncated`). Rows not marked equal the
returned observation, so `infos["final_obs"]` is every env's true next
observation (what a value bootstrap on truncation needs). `final_obs` is one
float32 array rather than the object array of `SyncVectorEnv`, so
`NumpyToTorch` converts it like any other array. `infos["final_info"]`
holds, for the marked envs (`infos["_final_info"]`), the ended episode's
`"episode_return"` (float64) and `"episode_length"` (int64).
In this mode `gymnasium.wrappers.vector.RecordEpisodeStatistics` (Gymnasium 1.3)
counts episodes as next-step auto-reset does: it leaves out the first step of
every episode after an env's first, so read the episode figures from
`final_info` instead; and `NormalizeObservation` refuses the env.

Infos of `step`: `infos["metrics"]` is a dict of float32 [N] (`NavEnv`'s
per-step metrics: progress, goals_reached, keepout_entries, collisions,
speed_violation_s, clipped, bad_action) for the step just taken, final steps
included; `reset` returns empty infos. `NavGymEnv.step` returns
`info["metrics"]` as Python floats.

Input checks (host-side, before the device sees the action): an action of
another shape, a non-floating dtype, a NaN or infinity, a value outside
[-1, 1], or a nonzero value float32 would make subnormal or 0 raises `ValueError` naming the problem and what is expected (the env's
own clipping under `jit` would otherwise hide it; clip a Gaussian policy's
samples with `gymnasium.wrappers.vector.ClipAction` / `ClipAction`). `step`
before `reset` (and `NavGymEnv.step` after an episode ended) raises
`gymnasium.error.ResetNeeded`. Neither env renders: `render_mode` must be None.
"""

import functools
import numbers
from typing import Any, Callable

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
from gymnasium import spaces
from gymnasium.error import ResetNeeded
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from sims.rl.adapter import AdapterState, GymnaxAdapter
from sims.rl.randomization import randomize_zones_and_goals, training_env
from sims.rl.env import NavEnv

OBS_BOUND = 1.0 + 1e-4      # Box bound of every observation entry (normalised to [-1, 1], plus rounding room)
DEFAULT_EPISODE_LENGTH = 150  # env steps of 0.2 s (30 s), the PPO trainer's default
MAX_NUM_ENVS = 2 ** 21        # envs of one NavVectorEnv (`jaxfilters rl train --num-envs` has the same bound)
MAX_EPISODE_LENGTH = 2 ** 24  # Brax's EpisodeWrapper counts an episode's steps in float32 (exact to 2**24)


# ----------------------------------------------------------------------------- shared checks


def _resolve(env, episode_length, randomize, randomization_fn, render_mode, who):
  """Checks the constructor arguments; returns (env, randomization_fn or None)."""
  if render_mode is not None:
    raise ValueError(f"{who}: render_mode must be None (the env does not render); got {render_mode!r}")
  if not isinstance(randomize, bool):
    raise ValueError(f"{who}: randomize must be True or False; got {randomize!r}")
  if randomization_fn is not None and not callable(randomization_fn):
    raise ValueError(f"{who}: randomization_fn must be callable (Playground's fn(model, rng) -> "
                     f"(model_v, in_axes)); got {type(randomization_fn).__name__}")
  if randomization_fn is not None and not randomize:
    raise ValueError(f"{who}: randomization_fn is used only with randomize=True; pass both")
  if isinstance(episode_length, bool) or not isinstance(episode_length, numbers.Integral) or \
      not 1 <= episode_length <= MAX_EPISODE_LENGTH:
    raise ValueError(f"{who}: episode_length must be an integer in [1, 2**24] (env steps, counted in "
                     f"float32); got {episode_length!r}")
  if env is None:     # the rl commands' env: with randomize, the built-in warehouse and 16 zone layouts
    env, _ = training_env(randomize=randomize, seed=0)
  if not isinstance(env, NavEnv):
    raise ValueError(f"{who}: env must be a sims.rl.env.NavEnv; got {type(env).__name__}")
  if env.nav_config.mode != "velocity":
    raise ValueError(f"{who}: env must be in velocity mode (NavEnvConfig(mode='velocity')); "
                     f"got mode {env.nav_config.mode!r}")
  if env.nav_config.agents != "world":
    raise ValueError(f"{who}: env must be one agent per env (NavEnvConfig(agents='world')); got agents "
                     f"{env.nav_config.agents!r} (the per-robot mode trains through sims.rl.fleet)")
  fn = (randomization_fn or randomize_zones_and_goals) if randomize else None
  return env, fn


def _check_seed(seed, who):
  if seed is None:
    return None
  if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
    raise ValueError(f"{who}.reset: seed must be None or an integer >= 0; got {seed!r}")
  return int(seed)


def _check_options(options, who):
  if options is not None and (not hasattr(options, "keys") or len(options)):
    raise ValueError(f"{who}.reset takes no options (None or {{}}); got {options!r}")


def check_actions(actions, shape: tuple[int, ...], who: str) -> np.ndarray:
  """Host-side check of a batch of velocity actions; returns them as float32.

  Args:
    actions: array-like of (v, w) per robot, `shape`.
    shape: the expected shape ([N, A] or [A]).
    who: the caller's name for the messages.

  Returns:
    float32 array of `shape`.

  Raises:
    ValueError: another shape, a non-floating dtype, a NaN or infinity, a value outside [-1, 1], or a
      nonzero value below float32's smallest normal number in magnitude.
  """
  a = np.asarray(actions)
  want = f"float32 {list(shape)} of (v, w) per robot in [-1, 1]"
  if a.shape != shape:
    raise ValueError(f"{who}: actions must be {want}; got shape {list(a.shape)}")
  if not np.issubdtype(a.dtype, np.floating):
    raise ValueError(f"{who}: actions must be {want}; got dtype {a.dtype}")
  bad = ~np.isfinite(a)
  if bad.any():
    i = tuple(int(v) for v in np.argwhere(bad)[0])
    raise ValueError(f"{who}: actions must be finite ({want}); got {a[i]} at index {list(i)}")
  out = np.abs(a) > 1.0
  if out.any():
    i = tuple(int(v) for v in np.argwhere(out)[0])
    raise ValueError(f"{who}: actions must lie in [-1, 1] (the action space; clip a policy's samples "
                     f"with gymnasium's ClipAction wrapper); got {a[i]} at index {list(i)}")
  tiny = (a != 0) & (np.abs(a) < np.finfo(np.float32).tiny)
  if tiny.any():
    i = tuple(int(v) for v in np.argwhere(tiny)[0])
    raise ValueError(f"{who}: actions must be 0 or at least {np.finfo(np.float32).tiny:.3g} in magnitude "
                     f"(float32 would make {a[i]} at index {list(i)} subnormal or 0)")
  return a.astype(np.float32)


def observation_space(env: NavEnv) -> spaces.Box:
  """Box of one env's observation: float32 [observation_size] in [-OBS_BOUND, OBS_BOUND]."""
  return spaces.Box(-OBS_BOUND, OBS_BOUND, (env.observation_size,), np.float32)


def action_space(env: NavEnv) -> spaces.Box:
  """Box of one env's action: float32 [action_size] in [-1, 1]."""
  return spaces.Box(-1.0, 1.0, (env.action_size,), np.float32)


def _key(words):
  """A PRNG key from two uint32 words (64 bits of the host seed), for any default PRNG impl."""
  return jax.random.fold_in(jax.random.fold_in(jax.random.PRNGKey(0), words[0]), words[1])


def _seed_words(rng: np.random.Generator) -> np.ndarray:
  return rng.integers(0, 2**32, size=2, dtype=np.uint32)


# ----------------------------------------------------------------------------- compiled programs


@functools.lru_cache(maxsize=8)
def _programs(env: NavEnv, episode_length: int, randomization_fn, num_envs: int | None,
              autoreset_mode: AutoresetMode = AutoresetMode.SAME_STEP):
  """Jitted (reset, step) for one env (num_envs None) or a batch; cached so that wrappers of one
  NavEnv with the same settings share one compile."""
  adapter = GymnaxAdapter(env, episode_length, randomization_fn, full_reset=True)

  def step_one(state: AdapterState, action):
    """One env step without auto-reset."""
    st = adapter.run_with_model(state.model_leaves, lambda: adapter.wrapped.step(state.env_state, action))
    return (AdapterState(st, state.first, state.model_leaves), st.obs, st.reward, st.done > 0,
            st.info["truncation"] > 0, st.metrics)

  if num_envs is None:
    def reset(words):
      return adapter.reset(_key(words))

    return jax.jit(reset), jax.jit(step_one)

  def reset_v(words):
    keys = jax.random.split(_key(words), num_envs + 1)
    obs, state = jax.vmap(adapter.reset)(keys[1:])
    return keys[0], obs, state

  def step_v(key, state, actions):
    keys = jax.random.split(key, num_envs + 1)
    obs, state, reward, done, info = jax.vmap(adapter.step)(keys[1:], state, actions)
    return keys[0], state, obs, reward, done, info["truncation"] > 0, info["final_obs"], info["metrics"]

  def step_next(key, state, actions, autoreset):
    """Gymnasium's next-step auto-reset: envs marked in `autoreset` (bool [N], those that ended at
    the previous call) are reset and their actions ignored (reward 0, not done); the others step."""
    keys = jax.random.split(key, num_envs + 1)
    stepped, _, reward, done, trunc, metrics = jax.vmap(step_one)(state, actions)
    # Only the envs in `autoreset` are reset (GymnaxAdapter.reset_where); the state's obs is the
    # stepped one elsewhere.
    state = jax.vmap(adapter.reset_where)(keys[1:], autoreset, stepped)
    metrics = {k: jnp.where(autoreset, jnp.zeros_like(v), v) for k, v in metrics.items()}
    return (keys[0], state, state.env_state.obs, jnp.where(autoreset, 0.0, reward).astype(reward.dtype),
            done & ~autoreset, trunc & ~autoreset, metrics)

  step = step_next if autoreset_mode == AutoresetMode.NEXT_STEP else step_v
  return jax.jit(reset_v), jax.jit(step)


# ----------------------------------------------------------------------------- vector env


class NavVectorEnv(gymnasium.vector.VectorEnv):
  """N fleet RL envs (velocity mode) as one `gymnasium.vector.VectorEnv`, one jitted JAX call per step.

  Args:
    num_envs: N in [1, MAX_NUM_ENVS].
    episode_length: env steps of 0.2 s per episode (the time limit; `truncated`).
    randomize: draw zones and goals per episode (`randomization_fn`, by default
      `sims.rl.randomization.randomize_zones_and_goals`).
    env: the `NavEnv` to batch (default: the built-in warehouse, 1 robot; with randomize, 16 zone layouts, as `sims.rl.randomization.training_env`).
    randomization_fn: Playground `fn(model, rng) -> (model_v, in_axes)`; only with randomize=True.
    render_mode: None (the env does not render).
    autoreset_mode: `gymnasium.vector.AutoresetMode.NEXT_STEP` (Gymnasium's default, what its
      vector wrappers and CleanRL-style loops expect) or `SAME_STEP`; see the module docstring.

  `reset(seed=s)` -> (obs float32 [N, D], {}); `step(actions float32 [N, A])` ->
  (obs float32 [N, D], rewards float32 [N], terminated bool [N], truncated
  bool [N], infos); see the module docstring for infos and auto-reset.

  Raises:
    ValueError: a bad argument (named, with what is expected).
  """

  metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

  def __init__(self, num_envs: int, *, episode_length: int = DEFAULT_EPISODE_LENGTH, randomize: bool = False,
               env: NavEnv | None = None, randomization_fn: Callable | None = None, render_mode: None = None,
               autoreset_mode: AutoresetMode = AutoresetMode.NEXT_STEP):
    if isinstance(num_envs, bool) or not isinstance(num_envs, numbers.Integral) or num_envs < 1:
      raise ValueError(f"NavVectorEnv: num_envs must be an integer >= 1; got {num_envs!r}")
    if num_envs > MAX_NUM_ENVS:
      raise ValueError(f"NavVectorEnv: num_envs must be at most 2**21 = {MAX_NUM_ENVS:,d}; got {num_envs!r}")
    modes = (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP)
    if not isinstance(autoreset_mode, AutoresetMode) or autoreset_mode not in modes:
      raise ValueError(f"NavVectorEnv: autoreset_mode must be gymnasium.vector.AutoresetMode.NEXT_STEP or "
                       f"SAME_STEP; got {autoreset_mode!r}")
    self.env, fn = _resolve(env, episode_length, randomize, randomization_fn, render_mode, "NavVectorEnv")
    self.autoreset_mode = autoreset_mode
    self.metadata = {**type(self).metadata, "autoreset_mode": autoreset_mode}
    self.num_envs = int(num_envs)
    self.episode_length = int(episode_length)
    self.render_mode = None
    self.single_observation_space = observation_space(self.env)
    self.single_action_space = action_space(self.env)
    self.observation_space = batch_space(self.single_observation_space, self.num_envs)
    self.action_space = batch_space(self.single_action_space, self.num_envs)
    self._reset, self._step = _programs(self.env, self.episode_length, fn, self.num_envs, autoreset_mode)
    self._key = self._state = None
    self._autoreset = np.zeros(self.num_envs, bool)     # NEXT_STEP: envs that ended at the last step
    self._returns = np.zeros(self.num_envs)
    self._lengths = np.zeros(self.num_envs, np.int64)

  def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
    """Resets every env; `seed` (int >= 0) makes the episodes reproducible, None continues the RNG.

    Returns:
      (obs float32 [N, D], {}).
    """
    seed = _check_seed(seed, "NavVectorEnv")
    _check_options(options, "NavVectorEnv")
    super().reset(seed=seed)
    self._key, obs, self._state = self._reset(_seed_words(self.np_random))
    self._returns[:] = 0.0
    self._lengths[:] = 0
    self._autoreset[:] = False
    return np.array(obs), {}

  def step(self, actions):
    """Steps every env with `actions` float32 [N, A] in [-1, 1]; ended episodes restart at the next call
    (NEXT_STEP) or in this one (SAME_STEP).

    Returns:
      (obs float32 [N, D], rewards float32 [N], terminated bool [N], truncated bool [N], infos).

    Raises:
      ValueError: actions of another shape or dtype, non-finite or outside [-1, 1].
      gymnasium.error.ResetNeeded: `step` before `reset` (or after `close`).
    """
    if self._state is None:
      raise ResetNeeded("NavVectorEnv.step called before reset(); call reset(seed=...) first")
    a = check_actions(actions, (self.num_envs, self.single_action_space.shape[0]), "NavVectorEnv.step")
    if self.autoreset_mode == AutoresetMode.NEXT_STEP:
      self._key, self._state, *out = self._step(self._key, self._state, jnp.asarray(a),
                                                jnp.asarray(self._autoreset))
      obs, reward, done, trunc, metrics = jax.tree.map(np.array, jax.device_get(out))
      truncated = done & trunc
      terminated = done & ~trunc
      self._autoreset = done.copy()
      return obs, reward, terminated, truncated, {"metrics": metrics}
    self._key, self._state, *out = self._step(self._key, self._state, jnp.asarray(a))
    obs, reward, done, trunc, final_obs, metrics = jax.tree.map(np.array, jax.device_get(out))
    truncated = done & trunc
    terminated = done & ~trunc
    self._returns += reward
    self._lengths += 1
    infos = {"metrics": metrics, "final_obs": final_obs, "_final_obs": done.copy(),
             "final_info": {"episode_return": np.where(done, self._returns, 0.0),
                            "episode_length": np.where(done, self._lengths, 0),
                            "_episode_return": done.copy(), "_episode_length": done.copy()},
             "_final_info": done.copy()}
    self._returns[done] = 0.0
    self._lengths[done] = 0
    return obs, reward, terminated, truncated, infos

  @property
  def state(self) -> AdapterState | None:
    """The batched device state (`sims.rl.adapter.AdapterState`, leading axis N; None before `reset`).

    Assigning a state of the same structure, shapes and dtypes replaces it (nothing recompiles):
    tests and debugging place robots this way, e.g. by editing `state.env_state.data.qpos`
    ([N, K, 3]: x, y, yaw) and `state.env_state.info["last_qpos"]` alike.

    Raises:
      ValueError: on assignment, another structure, shape or dtype (or before `reset`).
    """
    return self._state

  @state.setter
  def state(self, new: AdapterState) -> None:
    if self._state is None:
      raise ValueError("NavVectorEnv.state: call reset() before assigning a state")
    want = jax.tree.structure(self._state)
    if jax.tree.structure(new) != want:
      raise ValueError(f"NavVectorEnv.state must have the structure of the current state; got "
                       f"{jax.tree.structure(new)}, expected {want}")
    shapes = lambda t: [(jnp.shape(x), jnp.result_type(x)) for x in jax.tree.leaves(t)]
    for got, exp in zip(shapes(new), shapes(self._state)):
      if got != exp:
        raise ValueError(f"NavVectorEnv.state: a leaf of shape/dtype {got} where {exp} is expected")
    self._state = new

  def close_extras(self, **kwargs):
    """Drops the device state; a later `step` needs a `reset`."""
    self._key = self._state = None

  def __repr__(self) -> str:
    return (f"NavVectorEnv(num_envs={self.num_envs}, episode_length={self.episode_length}, "
            f"autoreset_mode={self.autoreset_mode.name})")


# ----------------------------------------------------------------------------- single env


class NavGymEnv(gymnasium.Env):
  """One fleet RL env (velocity mode) as a `gymnasium.Env`, jitted reset and step.

  Args:
    episode_length: env steps of 0.2 s per episode (the time limit; `truncated`).
    randomize: draw zones and goals at each reset (`randomization_fn`, by default
      `sims.rl.randomization.randomize_zones_and_goals`).
    env: the `NavEnv` (default: as NavVectorEnv); wrappers of one NavEnv with the
      same settings share one compiled program.
    randomization_fn: Playground `fn(model, rng) -> (model_v, in_axes)`; only with randomize=True.
    render_mode: None (the env does not render).

  `reset(seed=s)` -> (obs float32 [D], {}); `step(action float32 [A])` ->
  (obs float32 [D], reward float, terminated bool, truncated bool,
  {"metrics": {name: float}}). No auto-reset: call `reset` after an episode ends.

  Raises:
    ValueError: a bad argument (named, with what is expected).
  """

  metadata = {"render_modes": []}

  def __init__(self, *, episode_length: int = DEFAULT_EPISODE_LENGTH, randomize: bool = False,
               env: NavEnv | None = None, randomization_fn: Callable | None = None, render_mode: None = None):
    self.env, fn = _resolve(env, episode_length, randomize, randomization_fn, render_mode, "NavGymEnv")
    self.episode_length = int(episode_length)
    self.render_mode = None
    self.observation_space = observation_space(self.env)
    self.action_space = action_space(self.env)
    self._reset, self._step = _programs(self.env, self.episode_length, fn, None)
    self._state = None

  def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
    """A new episode; `seed` (int >= 0) makes it reproducible, None continues the RNG.

    Returns:
      (obs float32 [D], {}).
    """
    seed = _check_seed(seed, "NavGymEnv")
    _check_options(options, "NavGymEnv")
    super().reset(seed=seed)
    obs, self._state = self._reset(_seed_words(self.np_random))
    return np.array(obs), {}

  def step(self, action):
    """One env step (0.2 s) with `action` float32 [A] in [-1, 1].

    Returns:
      (obs float32 [D], reward float, terminated bool, truncated bool, {"metrics": {name: float}}).

    Raises:
      ValueError: an action of another shape or dtype, non-finite or outside [-1, 1].
      gymnasium.error.ResetNeeded: `step` before `reset`, after the episode ended, or after `close`.
    """
    if self._state is None:
      raise ResetNeeded("NavGymEnv.step needs reset() first (before the first step, after an episode "
                        "ended, after close())")
    a = check_actions(action, self.action_space.shape, "NavGymEnv.step")
    state, *out = self._step(self._state, jnp.asarray(a))
    obs, reward, done, trunc, metrics = jax.device_get(out)
    self._state = None if done else state
    info = {"metrics": {k: float(v) for k, v in metrics.items()}}
    return np.array(obs), float(reward), bool(done and not trunc), bool(trunc), info

  def close(self):
    """Drops the device state; a later `step` needs a `reset`."""
    self._state = None
    super().close()


__all__ = ["DEFAULT_EPISODE_LENGTH", "NavGymEnv", "NavVectorEnv", "OBS_BOUND", "action_space",
           "check_actions", "observation_space"]
