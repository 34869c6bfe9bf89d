"""A Playground `MjxEnv` behind gymnax's API (what rejax's PPO calls) and behind Gymnasium's wrappers.

rejax speaks gymnax's env API (its 5-value `step`; gymnax 1.0's own
`Environment.step` returns 6, so the adapter does not subclass it).
`GymnaxAdapter` puts a Playground-contract env behind it: Brax's
`EpisodeWrapper` (time limit) inside, auto-reset outside (to the episode's
first state, or a fresh `reset`), and optionally a Playground
`randomization_fn` drawn per episode.
"""

import math
from typing import Any, Callable

import jax
import jax.numpy as jnp
from brax.envs.wrappers.training import EpisodeWrapper
from flax import struct
from gymnax.environments import spaces

from sims.rl.env import NavEnv

MAX_EPISODE_LENGTH = 2 ** 24   # EpisodeWrapper's step count is float32: exact up to 2**24
RESET_CAPACITY_AUTO = "auto"


def auto_reset_capacity(num_envs: int, episode_length: int) -> int:
  """Fresh resets drawn per pass when `num_envs` envs of `episode_length` steps are stepped together:
  four times the time limit's average (num_envs / episode_length ends per step), at least 8 and at
  most num_envs. More ends in one step than that take more passes (see GymnaxAdapter)."""
  return int(min(num_envs, max(8, math.ceil(4 * num_envs / episode_length))))


@struct.dataclass
class AdapterParams:
  """gymnax env params: only the time limit rejax reads (`max_steps_in_episode`)."""
  max_steps_in_episode: int = struct.field(pytree_node=False, default=200)


@struct.dataclass
class AdapterState:
  """One env's state behind the adapter.

  Attributes:
    env_state: the Playground State (inside Brax's EpisodeWrapper).
    first: the State the episode started from (restored on done unless full_reset).
    model_leaves: the randomised model leaves of this env ([] without a randomization_fn).
  """
  env_state: Any
  first: Any
  model_leaves: Any


class GymnaxAdapter:
  """A Playground `MjxEnv` behind gymnax's API (what rejax's algorithms call).

  `reset(key, params) -> (obs, state)`, `step(key, state, action, params) ->
  (obs, state, reward, done, info)` with auto-reset on done (terminal or time
  limit), `action_space`, `observation_space`. Auto-reset restores the
  episode's first state (Playground's default, `full_reset=False`; cheap) or
  calls `reset` with a fresh key (`full_reset=True`: new spawn, goal and
  randomised model every episode). With `full_reset`, a batch of envs stepped under `jax.vmap`
  (what rejax does) draws the fresh resets only for the envs whose episode ended
  (`reset_capacity`, default "auto": `auto_reset_capacity`): up to that many at a time in a loop
  that runs while ended envs are left (none: no reset is computed), gathered by index and written
  back; each env's reset is the one it would get alone (its own key), so the batch's states equal
  those of resetting every env and keeping the ended ones (`reset_capacity=None`, the cost of a
  full reset at every step). With `randomization_fn` (Playground's
  `fn(model, rng=[N, 2]) -> (model_v, in_axes)`) each env draws its own model
  at reset and only the randomised leaves are carried in its state; the model
  is swapped in the way Playground's `BraxDomainRandomizationVmapWrapper` does.
  """

  def __init__(self, env: NavEnv, episode_length: int,
               randomization_fn: Callable | None = None, *, full_reset: bool = False,
               reset_capacity: int | str | None = RESET_CAPACITY_AUTO):
    if isinstance(episode_length, bool) or int(episode_length) != episode_length or \
        not 1 <= episode_length <= MAX_EPISODE_LENGTH:
      raise ValueError(f"episode_length must be an integer in [1, 2**24] (EpisodeWrapper counts the steps in "
                       f"float32, exact to 2**24); got {episode_length!r}")
    if not (reset_capacity is None or reset_capacity == RESET_CAPACITY_AUTO or
            (isinstance(reset_capacity, int) and not isinstance(reset_capacity, bool) and reset_capacity >= 1)):
      raise ValueError(f"reset_capacity must be an integer >= 1, 'auto' or None (reset every env at every step); "
                       f"got {reset_capacity!r}")
    self.reset_capacity = reset_capacity
    self.env = env
    self.wrapped = EpisodeWrapper(env, int(episode_length), 1)
    self.episode_length = int(episode_length)
    self.randomization_fn = randomization_fn
    self.full_reset = bool(full_reset)

  @property
  def default_params(self) -> AdapterParams:
    return AdapterParams(max_steps_in_episode=self.episode_length)

  def _axes(self, base):
    """in_axes of the randomization_fn, flattened alongside `base` (None subtrees of the model
    count as leaves in both, so the two lists line up even where mjx.Model has None fields)."""
    _, in_axes = self.randomization_fn(base, rng=jnp.zeros((1, 2), jnp.uint32))
    is_none = lambda x: x is None
    axes = jax.tree.leaves(in_axes, is_leaf=is_none)
    leaves, treedef = jax.tree.flatten(base, is_leaf=is_none)
    if len(axes) != len(leaves):
      raise ValueError(f"randomization_fn returned in_axes with {len(axes)} leaves for a model with "
                       f"{len(leaves)}: in_axes must mirror the model's structure")
    return axes, leaves, treedef

  def draw_model(self, key):
    """Draws one env's model: the randomised leaves only (list; empty without a randomization_fn).

    Carry these in the env's state and pass them to `model_for` / `run_with_model`.
    """
    if self.randomization_fn is None:
      return []
    base = self.env.unwrapped._mjx_model
    axes, _, _ = self._axes(base)
    model_v, _ = self.randomization_fn(base, rng=key[None])
    leaves = jax.tree.leaves(model_v, is_leaf=lambda x: x is None)
    return [jnp.take(x, 0, axis=ax) for x, ax in zip(leaves, axes) if ax is not None]

  def model_for(self, model_leaves):
    """The env's whole model with `model_leaves` (from `draw_model`) in place of the randomised fields."""
    base = self.env.unwrapped._mjx_model
    if self.randomization_fn is None:
      return base
    axes, leaves, treedef = self._axes(base)
    it = iter(model_leaves)
    return jax.tree.unflatten(treedef, [x if ax is None else next(it) for x, ax in zip(leaves, axes)])

  def run_with_model(self, model_leaves, fn):
    """Calls `fn()` (which resets or steps `self.wrapped`) with the env's model swapped for
    `model_for(model_leaves)`, the way Playground's domain-randomisation wrapper does."""
    env = self.env.unwrapped
    old = env._mjx_model
    env._mjx_model = self.model_for(model_leaves)
    try:
      return fn()
    finally:
      env._mjx_model = old

  def reset(self, key, params=None):
    del params
    k_model, k_env = jax.random.split(key)
    leaves = self.draw_model(k_model)
    st = self.run_with_model(leaves, lambda: self.wrapped.reset(k_env))
    return st.obs, AdapterState(st, None if self.full_reset else st, leaves)

  def step(self, key, state: AdapterState, action, params=None):
    st = self.run_with_model(state.model_leaves, lambda: self.wrapped.step(state.env_state, action))
    done = st.done > 0
    info = {"metrics": st.metrics, "truncation": st.info["truncation"], "final_obs": st.obs}
    current = AdapterState(st, state.first, state.model_leaves)
    if self.full_reset:
      new = self.reset_where(key, done, current)
    else:
      new = _where(done, AdapterState(state.first, state.first, state.model_leaves), current)
    return new.env_state.obs, new, st.reward, done, info

  def reset_where(self, key, done, current: AdapterState) -> AdapterState:
    """`current` with a fresh `reset(key)`'s state where `done` (bool), else `current`.

    Under `jax.vmap` (keys [N], done [N], states [N]) only the envs where `done` are reset, up to
    `reset_capacity` at a time (see the class docstring); unbatched, or with reset_capacity None,
    the reset is computed and selected.
    """
    fresh = lambda k: self.reset(k)[1]
    if self.reset_capacity is None:
      return _where(done, fresh(key), current)

    @jax.custom_batching.custom_vmap
    def fresh_where_done(key, done, current):
      return _where(done, fresh(key), current)

    @fresh_where_done.def_vmap
    def batched(axis_size, in_batched, key, done, current):
      along = lambda x, b: x if b else jnp.broadcast_to(x, (axis_size,) + jnp.shape(x))
      key_b, done_b, current_b = in_batched
      key, done = along(key, key_b), along(done, done_b)
      current = jax.tree.map(along, current, current_b)
      cap = auto_reset_capacity(axis_size, self.episode_length) if self.reset_capacity == RESET_CAPACITY_AUTO \
          else min(int(self.reset_capacity), axis_size)

      def one_pass(carry):
        states, left = carry
        idx = jnp.nonzero(left, size=cap, fill_value=axis_size)[0]      # axis_size: no env (dropped)
        new = jax.vmap(fresh)(key[jnp.minimum(idx, axis_size - 1)])
        states = set_rows(states, idx, jax.tree.map(lambda s, n: n.astype(s.dtype), states, new))
        return states, left.at[idx].set(False, mode="drop")

      states, _ = jax.lax.while_loop(lambda c: jnp.any(c[1]), one_pass, (current, done))
      return states, jax.tree.map(lambda _: True, states)

    return fresh_where_done(key, done, current)

  def action_space(self, params=None):
    return spaces.Box(low=-1.0, high=1.0, shape=(self.env.action_size,))

  def observation_space(self, params=None):
    return spaces.Box(low=-jnp.inf, high=jnp.inf, shape=(self.env.observation_size,))

  @property
  def num_actions(self) -> int:
    return self.env.action_size

  @property
  def name(self) -> str:
    return type(self.env.unwrapped).__name__


def set_rows(states, idx, new, *, packed: bool | None = None):
  """`states` with rows `idx` (int [cap]; entries out of range dropped) set to `new`'s, every leaf.

  XLA:CPU expands each scatter into a loop of its own: with one per leaf of the env state (~90)
  they were a large part of the PPO training program's compile on a CPU. There (`packed` None:
  the default backend is a CPU), the leaves of one dtype go through one scatter (flattened per
  row and concatenated: the same values, bit for bit); elsewhere each leaf is scattered in place.
  """
  if packed is None:
    packed = jax.default_backend() == "cpu"
  if not packed:
    return jax.tree.map(lambda s, n: s.at[idx].set(n, mode="drop"), states, new)
  leaves, treedef = jax.tree.flatten(states)
  new_leaves = treedef.flatten_up_to(new)
  groups = {}
  for i, x in enumerate(leaves):
    groups.setdefault(x.dtype, []).append(i)
  out = list(leaves)
  for members in groups.values():
    n_rows = leaves[members[0]].shape[0]
    flat = lambda xs: jnp.concatenate([x.reshape(x.shape[0], math.prod(x.shape[1:])) for x in xs], axis=1)
    packed = flat([leaves[i] for i in members]).at[idx].set(flat([new_leaves[i] for i in members]), mode="drop")
    at = 0
    for i in members:
      size = math.prod(leaves[i].shape[1:])
      out[i] = packed[:, at:at + size].reshape((n_rows,) + leaves[i].shape[1:])
      at += size
  return jax.tree.unflatten(treedef, out)


def _where(done, a, b):
  return jax.tree.map(lambda x, y: jnp.where(done, x, y), a, b)


__all__ = ["AdapterParams", "AdapterState", "GymnaxAdapter", "RESET_CAPACITY_AUTO", "auto_reset_capacity",
           "set_rows"]
