"""Training and evaluating one shared policy for every robot of a world (`NavEnvConfig(agents="per_robot")`).

    env, fn = training_env(randomize=True, seed=0, robots_per_world=8,
                           config=NavEnvConfig(agents="per_robot", costmap_stop=True))
    adapter = FleetAdapter(env, 300, fn, full_reset=True)
    algo = make_fleet_ppo(adapter, num_worlds=1024, num_steps=32, num_minibatches=8)
    ts, evals, timing = train_with_curve(adapter, algo, key, calls=[...], num_eval=64,
                                         evaluate=evaluate_fleet_policy)

The agents are folded into the batch, as multi-agent JAX RL does it (JaxMARL, PufferLib): rejax's
PPO sees N worlds x K robots as N x K envs whose observations are each robot's own 98 values
(`sims.rl.agents`), so one actor and one critic with shared parameters learn from every robot's
transitions, with rejax's GAE, minibatches and observation statistics unchanged (`FleetPPO`
only changes how the batch of envs is reset and stepped: K agents at a time through one world).
rejax's step counter (`global_step`) then counts robot-steps; `train_with_curve` reports env
(world) steps and robot-steps.

`FleetAdapter` is the world behind gymnax's API with per-robot rewards and dones: a robot whose
episode ends is respawned by the env while its world goes on; the world resets at the time limit
(every robot's episode ends there). `evaluate_fleet_policy` reports per robot-episode figures,
each robot's first episode of each world.
"""

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import rejax
from flax import struct
from gymnax.environments import spaces

from sims.rl.adapter import RESET_CAPACITY_AUTO, GymnaxAdapter
from sims.rl.env import NavEnv
from sims.rl.ppo import EVAL_KEYS, episode_sums, make_ppo

_F32 = jnp.float32
FLEET_EVAL_KEYS = EVAL_KEYS + ("robot_collisions",)


@struct.dataclass
class FleetState:
  """One world's state behind `FleetAdapter`.

  Attributes:
    env_state: the env's State (per-robot mode: reward, done and metrics [K]).
    steps: int32 [], env steps since the world's reset.
    first: the State the world started from (restored at the time limit unless full_reset).
    model_leaves: the randomised model leaves of this world ([] without a randomization_fn).
  """
  env_state: Any
  steps: jax.Array
  first: Any
  model_leaves: Any


class FleetAdapter(GymnaxAdapter):
  """A per-robot `NavEnv` (agents "per_robot") behind gymnax's API, one world per env.

  `reset(key) -> (obs float32 [K, 98], state)`; `step(key, state, action [K, 2]) -> (obs [K, 98],
  state, reward [K], done bool [K], info)`. done marks the end of each robot's episode: its own
  end (the env has respawned it; its obs row is the new episode's first) or the world's time
  limit after `episode_length` steps, when the world restarts (its first state, or a fresh
  `reset` with a new model when `full_reset`, computed under vmap only for the worlds whose time
  is up: `reset_capacity`, as in GymnaxAdapter). `info["truncation"]` (bool [K]) marks the robots
  whose episode the time limit ended. The spaces are one robot's: action (2,), observation (98,).

  Raises:
    ValueError: an env that is not in the per-robot mode, or a bad episode_length.
  """

  def __init__(self, env: NavEnv, episode_length: int, randomization_fn: Callable | None = None, *,
               full_reset: bool = False, reset_capacity: int | str | None = RESET_CAPACITY_AUTO):
    if env.nav_config.agents != "per_robot":
      raise ValueError(f"FleetAdapter needs a NavEnv with NavEnvConfig(agents='per_robot'); got agents "
                       f"{env.nav_config.agents!r} (GymnaxAdapter takes a world env)")
    super().__init__(env, episode_length, randomization_fn, full_reset=full_reset, reset_capacity=reset_capacity)

  def reset(self, key, params=None):
    del params
    k_model, k_env = jax.random.split(key)
    leaves = self.draw_model(k_model)
    st = self.run_with_model(leaves, lambda: self.env.reset(k_env))
    return st.obs, FleetState(st, jnp.zeros((), jnp.int32), None if self.full_reset else st, leaves)

  def step(self, key, state: FleetState, action, params=None):
    del params
    st = self.run_with_model(state.model_leaves, lambda: self.env.step(state.env_state, action))
    steps = state.steps + 1
    time_up = steps >= self.episode_length
    ended = st.done > 0
    info = {"metrics": st.metrics, "truncation": time_up & ~ended, "final_obs": st.obs}
    current = FleetState(st, steps, state.first, state.model_leaves)
    if self.full_reset:        # under vmap only the worlds whose time is up are reset (GymnaxAdapter.reset_where)
      new = self.reset_where(key, time_up, current)
    else:
      restart = FleetState(state.first, jnp.zeros((), jnp.int32), state.first, state.model_leaves)
      new = jax.tree.map(lambda a, b: jnp.where(time_up, a, b), restart, current)
    return new.env_state.obs, new, st.reward, ended | time_up, info

  def action_space(self, params=None):
    return spaces.Box(low=-1.0, high=1.0, shape=(2,))

  def observation_space(self, params=None):
    return spaces.Box(low=-jnp.inf, high=jnp.inf, shape=(self.env.observation_size,))

  @property
  def num_actions(self) -> int:
    return 2


class FleetPPO(rejax.PPO):
  """rejax.PPO over N worlds x K robots as N x K envs (`robots_per_world` = K).

  rejax resets and steps its envs through `vmap_reset` / `vmap_step` only; here they reset
  and step N = num_envs / K worlds of `FleetAdapter` and flatten the robot axis into the env
  axis (robot k of world n is env n x K + k). Everything else is rejax's PPO.
  """
  robots_per_world: int = struct.field(pytree_node=False, default=1)

  @property
  def vmap_reset(self):
    k = self.robots_per_world

    def reset(keys, params):
      obs, st = jax.vmap(self.env.reset, in_axes=(0, None))(keys[::k], params)
      return obs.reshape(-1, obs.shape[-1]), st
    return reset

  @property
  def vmap_step(self):
    k = self.robots_per_world

    def step(keys, st, action, params):
      a = action.reshape(-1, k, action.shape[-1])
      obs, st, reward, done, info = jax.vmap(self.env.step, in_axes=(0, 0, 0, None))(keys[::k], st, a, params)
      return obs.reshape(-1, obs.shape[-1]), st, reward.reshape(-1), done.reshape(-1), info
    return step


def make_fleet_ppo(adapter: FleetAdapter, *, num_worlds: int, num_steps: int = 64, **kwargs) -> FleetPPO:
  """`FleetPPO` on N = `num_worlds` worlds of K robots: `sims.rl.ppo.make_ppo`'s PPO with N x K envs.

  Args:
    adapter: a FleetAdapter.
    num_worlds: N worlds stepped at once.
    num_steps: rollout length per PPO iteration.
    **kwargs: `make_ppo`'s other settings (num_epochs, num_minibatches, learning_rate, hidden,
      ent_coef, gamma); num_minibatches must divide N x K x num_steps.

  Raises:
    TypeError: adapter is not a FleetAdapter.
    ValueError: num_worlds < 1, or minibatches that do not divide the batch.
  """
  if not isinstance(adapter, FleetAdapter):
    raise TypeError(f"make_fleet_ppo needs a FleetAdapter; got {type(adapter).__name__}")
  if isinstance(num_worlds, bool) or not isinstance(num_worlds, int) or num_worlds < 1:
    raise ValueError(f"num_worlds must be an integer >= 1; got {num_worlds!r}")
  k = adapter.env.num_robots
  batch = num_worlds * k * num_steps
  m = kwargs.get("num_minibatches", 8)
  if batch % m:
    raise ValueError(f"num_minibatches ({m}) must divide num_worlds x robots_per_world x num_steps "
                     f"({num_worlds} x {k} x {num_steps} = {batch})")
  algo = make_ppo(adapter, timesteps_per_call=batch, num_envs=num_worlds * k, num_steps=num_steps, **kwargs)
  fields = {name: getattr(algo, name) for name in algo.__dataclass_fields__}
  return FleetPPO(**fields, robots_per_world=k)


def evaluate_fleet_policy(adapter: FleetAdapter, act: Callable, key: jax.Array, num_eval: int) -> dict:
  """One episode of `adapter.episode_length` steps on each of `num_eval` worlds with `act(obs [K, D]) -> [K, 2]`.

  Every robot's first episode is counted, from the world's reset to the robot's own end or
  the time limit; a robot whose episode ended is respawned and drives on (the others still
  share the floor with K robots) but its later episodes are not counted. Jittable.

  Returns:
    dict of float32 [num_eval x K], per robot-episode (world-major): FLEET_EVAL_KEYS as
    `sims.rl.ppo.evaluate_policy`'s, plus robot_collisions (1 where the episode ended in a
    robot-robot contact); success = a goal reached before the robot's episode ended.
  """
  out = episode_sums(adapter, adapter.env, act, key, num_eval, FLEET_EVAL_KEYS, (adapter.env.num_robots,))
  return {n: v.reshape(-1) for n, v in out.items()}


__all__ = ["FLEET_EVAL_KEYS", "FleetAdapter", "FleetPPO", "FleetState", "evaluate_fleet_policy", "make_fleet_ppo"]
