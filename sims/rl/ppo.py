"""PPO on the fleet RL env (`sims.rl.env.NavEnv`) with rejax's PPO, and its learning curve.

    jaxfilters rl train --timesteps 400000 --out out/ppo   # needs the `rl` extra

The trainer is rejax 0.1.3 (`rejax.PPO`, maintained, pure JAX: rollouts,
GAE and updates are one jitted `lax.scan`), chosen because it runs on the
pinned jax 0.10.2. Brax 0.14.2's PPO trainer (the newest release) stops on jax
0.10 with `AttributeError: jax.device_put_replicated is deprecated` (removed in
jax 0.10; brax/training/agents/ppo/train.py:756); on jax 0.9.2 it trains this
env unchanged (`ppo.train(environment=NavEnv.create(), wrap_env_fn=
wrapper.wrap_for_brax_training)`). rejax speaks gymnax's env API (its 5-value
`step`; gymnax 1.0's own `Environment.step` returns 6, so the adapter does not
subclass it), so `GymnaxAdapter` puts a Playground-contract env behind it:
Brax's `EpisodeWrapper` (time limit) inside, auto-reset outside (to the
episode's first state, or a fresh `reset`), and optionally a Playground
`randomization_fn` drawn per episode.

examples/ppo_nav/ has a 3 M-step run with its learning curve and results.

Evaluation (`evaluate_policy`) runs the policy's mean action (no sampling
noise) on `num_eval` envs for one episode each and reports, per episode:
return, success (a goal reached before the episode ended), goals reached,
keepout entries, collisions, seconds above a speed limit, and the command the
speed filter had to clip. `jaxfilters rl train` (sims/commands/rl.py) writes
the policy (`sims.rl.policy`), OUT/learning_curve.png and OUT/results.json.

Several devices (`train_with_curve(..., mesh=sims.scale.sharding.make_mesh(N))`):
the train state's per-env leaves (`env_state`, `last_obs`, `last_done`, leading
axis num_envs) are split over the mesh axis and everything else (networks,
optimiser, observation statistics, keys) is replicated; rejax's jitted
training program is compiled with those shardings and GSPMD partitions it:
each device steps its own envs, and sums over the env axis (the gradient of a
minibatch, the observation statistics, the advantage normalisation) become
all-reduces. The one change to rejax's program is the minibatch shuffle
(`BlockShufflePPO`): each device's samples are shuffled among themselves and
every minibatch takes an equal share from each device, so no device gathers
another's samples. A minibatch holds the same number of samples, drawn evenly
from all envs, and every other step is rejax's, so the learning curve per
sample is the same algorithm's; the numbers differ from a one-device run only
through which samples share a minibatch and the order of float sums.
"""

import concurrent.futures
import copy
import dataclasses
import time
from pathlib import Path
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np
import rejax
from flax import struct

from sims.rl.adapter import AdapterParams, AdapterState, GymnaxAdapter  # noqa: F401  (re-exported)

_F32 = jnp.float32


EVAL_KEYS = ("return", "success", "goals_reached", "keepout_entries", "collisions",
             "speed_violation_s", "speed_violation_after_clip_s", "speed_violation_outside_entry_s", "clipped",
             "costmap_stops", "bad_action", "length")


def evaluate_policy(adapter: GymnaxAdapter, act: Callable, key: jax.Array, num_eval: int) -> dict:
  """One episode on each of `num_eval` envs with `act(obs) -> action` (jittable).

  Returns:
    dict of float32 [num_eval] per episode: see EVAL_KEYS (success = at least
    one goal reached before the episode ended; bad_action = steps whose action had a NaN or
    a value outside [-1, 1], which the env replaced by 0 or clipped).
  """
  return episode_sums(adapter, adapter.wrapped, act, key, num_eval, EVAL_KEYS, ())


def episode_sums(adapter: GymnaxAdapter, env, act: Callable, key: jax.Array, num_eval: int,
                 keys: tuple[str, ...], shape: tuple[int, ...]) -> dict:
  """Per-episode sums of `keys` over one episode of `adapter.episode_length` steps on each of `num_eval` envs.

  Each env draws its model (`adapter.draw_model`), resets `env` and steps it with `act(obs)`; a step
  counts while no earlier step of its episode was done. `shape` is that of the env's reward and
  done: () for one agent per env, (K,) for one per robot (`sims.rl.fleet`). The sums are the env's
  metrics of those names, plus return (the reward), bad_action (steps whose action was replaced or
  clipped), length (steps) and success (a goal reached). Jittable.

  Returns:
    dict of float32 [num_eval, *shape], one entry per name in `keys`.
  """
  def one(k):
    k_model, k_reset = jax.random.split(k)
    model = adapter.draw_model(k_model)
    st = adapter.run_with_model(model, lambda: env.reset(k_reset))

    def body(carry, _):
      st, alive, acc = carry
      nst = adapter.run_with_model(model, lambda: env.step(st, act(st.obs)))
      m = nst.metrics
      add = {n: m[n] for n in keys if n in m}
      add.update({"return": nst.reward, "bad_action": (m["bad_action"] > 0).astype(_F32),
                  "length": jnp.ones(shape, _F32)})
      acc = {n: acc[n] + jnp.where(alive, add[n], 0.0) for n in acc}
      return (nst, alive & (nst.done == 0), acc), None

    acc0 = {n: jnp.zeros(shape, _F32) for n in keys if n != "success"}
    (_, _, acc), _ = jax.lax.scan(body, (st, jnp.ones(shape, bool), acc0), None, length=adapter.episode_length)
    acc["success"] = (acc["goals_reached"] > 0).astype(_F32)
    return acc

  return jax.vmap(one)(jax.random.split(key, num_eval))


def first_actions_finite(adapter: GymnaxAdapter, act: Callable, key: jax.Array, num: int) -> jax.Array:
  """Whether `act(obs)` is finite on each of `num` first observations (the resets `evaluate_policy`
  starts from with the same key): bool [num] (jittable).

  A policy whose weights overflow float32 gives NaN or inf actions; the env replaces a NaN action by
  0 and counts it as `bad_action`, so an evaluation would measure a robot at rest, not the policy.
  """
  def one(k):
    k_model, k_reset = jax.random.split(k)
    model = adapter.draw_model(k_model)
    st = adapter.run_with_model(model, lambda: adapter.wrapped.reset(k_reset))
    return jnp.all(jnp.isfinite(act(st.obs)))

  return jax.vmap(one)(jax.random.split(key, num))


def make_ppo(adapter: GymnaxAdapter, *, timesteps_per_call: int, num_envs: int = 32, num_steps: int = 64,
             num_epochs: int = 4, num_minibatches: int = 8, learning_rate: float = 3e-4,
             hidden=(64, 64), ent_coef: float = 0.0, gamma: float = 0.99) -> "rejax.PPO":
  """rejax.PPO on the adapter; each `algo.train(train_state=ts)` call trains `timesteps_per_call` steps.

  rejax's own evaluation (which would compile the env step a second and third
  time inside the training program) is switched off; `train_with_curve`
  evaluates between calls with `evaluate_policy`, compiled once.
  """
  per_iter = num_envs * num_steps
  if timesteps_per_call % per_iter:
    raise ValueError(f"timesteps_per_call ({timesteps_per_call}) must be a multiple of num_envs * num_steps "
                     f"({per_iter})")
  algo = rejax.PPO.create(
      env=adapter, env_params=adapter.default_params, total_timesteps=int(timesteps_per_call),
      num_envs=num_envs, num_steps=num_steps, num_epochs=num_epochs, num_minibatches=num_minibatches,
      learning_rate=learning_rate, gamma=gamma, gae_lambda=0.95, clip_eps=0.2, ent_coef=ent_coef,
      vf_coef=0.5, max_grad_norm=0.5, normalize_observations=True, normalize_rewards=False,
      eval_freq=int(timesteps_per_call), skip_initial_evaluation=True,
      agent_kwargs={"hidden_layer_sizes": tuple(hidden), "activation": "tanh"})
  return algo.replace(eval_callback=lambda algo, ts, rng: jnp.zeros((), _F32))


def mean_policy(algo, ts) -> Callable:
  """The policy's mean action (deterministic), with rejax's observation normalisation.

  `act(obs)` takes one observation float32 [D] or a batch [..., D] (each robot's, for one agent per
  robot) and returns float32 [A] or [..., A] in [-1, 1].
  """
  def act(obs):
    if algo.normalize_observations:
      obs = algo.normalize_obs(ts.obs_rms_state, obs)
    rows = obs.reshape(-1, obs.shape[-1])           # rejax's networks flatten all but the first axis
    mean = algo.actor.apply(ts.actor_ts.params, rows, method="_action_dist").mean()
    return jnp.clip(mean.reshape(*obs.shape[:-1], mean.shape[-1]), -1.0, 1.0)
  return act


PER_ENV_FIELDS = ("env_state", "last_obs", "last_done")   # rejax train-state fields with leading axis num_envs


def train_state_shardings(ts, mesh):
  """NamedShardings of a rejax on-policy train state over a 1-D mesh (`sims.scale.sharding.make_mesh`).

  The per-env fields (PER_ENV_FIELDS, leading axis num_envs) are split over the
  mesh axis; every other leaf is replicated.

  Raises:
    ValueError: num_envs is not a multiple of the mesh's device count.
  """
  from sims.scale import sharding
  num_envs = ts.last_done.shape[0]
  sharding.check_divisible(num_envs, mesh)
  rep = sharding.replicated(mesh)
  split = sharding.worlds_sharding(mesh)
  out = jax.tree.map(lambda _: rep, ts)
  return out.replace(**{f: jax.tree.map(lambda _: split, getattr(ts, f)) for f in PER_ENV_FIELDS})


class BlockShufflePPO(rejax.PPO):
  """rejax.PPO whose minibatches take an equal share of samples from each of `shuffle_blocks` env blocks.

  rejax shuffles the whole batch (num_steps x num_envs samples) with one permutation;
  with the env axis split over D devices, that gathers every minibatch from all
  devices. Here the env axis is cut into D equal blocks (a device's envs), each
  block's samples are shuffled with one permutation, and minibatch m is the m-th
  slice of every block: each device keeps its own samples, and a minibatch still
  holds num_envs x num_steps / num_minibatches samples drawn evenly from all envs.
  Everything else (losses over the whole minibatch, the gradient, the observation
  statistics) is rejax's program; GSPMD turns the sums over the sharded axis into
  all-reduces. D = 1 is rejax's own shuffle.
  """
  shuffle_blocks: int = struct.field(pytree_node=False, default=1)
  block_sharding: object = struct.field(pytree_node=False, default=None)   # NamedSharding over the blocks, or None

  def shuffle_and_split(self, data, rng):
    d = self.shuffle_blocks
    if d == 1:
      return super().shuffle_and_split(data, rng)
    n_local = self.num_envs // d
    size = self.num_steps * n_local
    m = self.num_minibatches
    perm = jax.random.permutation(rng, size)
    constrain = (lambda x, spec: x) if self.block_sharding is None else (
        lambda x, spec: jax.lax.with_sharding_constraint(
            x, jax.sharding.NamedSharding(self.block_sharding.mesh, spec)))
    axis = None if self.block_sharding is None else self.block_sharding.mesh.axis_names[0]
    P = jax.sharding.PartitionSpec

    def split(x):                                    # x: [num_steps, num_envs, ...]
      t, rest = x.shape[0], x.shape[2:]
      x = jnp.moveaxis(x.reshape(t, d, n_local, *rest), 1, 0).reshape(d, size, *rest)
      x = constrain(jnp.take(constrain(x, P(axis)), perm, axis=1), P(axis))
      x = jnp.moveaxis(x.reshape(d, m, size // m, *rest), 1, 0)          # [m, d, size / m, ...]
      return constrain(x.reshape(m, d * (size // m), *rest), P(None, axis))

    return jax.tree.map(split, data)


def block_shuffle(algo, mesh):
  """`algo` (rejax.PPO from `make_ppo`) as a BlockShufflePPO with one block per device of `mesh`.

  Its env (a GymnaxAdapter) resets every env at every step (`reset_capacity=None`): gathering the
  ended envs by index across the sharded env axis would move env states between devices.

  Raises:
    ValueError: num_envs not a multiple of the devices, or a device's samples per iteration
      (num_envs / D x num_steps) not a multiple of num_minibatches.
  """
  d = int(mesh.devices.size)
  if algo.num_envs % d:
    raise ValueError(f"num_envs ({algo.num_envs}) must be a multiple of the devices ({d})")
  if (algo.num_envs // d * algo.num_steps) % algo.num_minibatches:
    raise ValueError(f"each device's batch ({algo.num_envs // d} envs x {algo.num_steps} steps) must split into "
                     f"num_minibatches = {algo.num_minibatches} equal parts")
  from sims.scale import sharding
  fields = {f.name: getattr(algo, f.name) for f in dataclasses.fields(algo)}
  fields["env"] = _reset_every_env(fields["env"])
  return BlockShufflePPO(**fields, shuffle_blocks=d, block_sharding=sharding.worlds_sharding(mesh))


def _reset_every_env(env):
  """`env` (a GymnaxAdapter, or rejax's FloatObsWrapper around one) with reset_capacity None."""
  inner = env.__dict__.get("env") if not isinstance(env, GymnaxAdapter) else None
  if isinstance(inner, GymnaxAdapter):
    return type(env)(_reset_every_env(inner))
  if isinstance(env, GymnaxAdapter) and env.reset_capacity is not None:
    env = copy.copy(env)
    env.reset_capacity = None
  return env


def replicas_identical(ts) -> bool:
  """True when every replicated leaf of a sharded train state holds the same bits on every device.

  Data-parallel training keeps the networks, optimiser and observation statistics
  identical on all devices; a difference is a bug, not noise.
  """
  for leaf in jax.tree.leaves(ts):
    if not isinstance(leaf, jax.Array) or not leaf.sharding.is_fully_replicated:
      continue
    shards = [np.asarray(s.data) for s in leaf.addressable_shards]
    if any(not np.array_equal(shards[0], x, equal_nan=True) for x in shards[1:]):
      return False
  return True


MAX_ENV_STEPS = 2 ** 31 - 1   # rejax counts env steps on the device in an int32 (`global_step`)


def plan_training(timesteps: int, num_envs: int, num_steps: int, evals: int) -> list[int]:
  """PPO iterations of each training call: `timesteps` rounded up to whole iterations, in `evals` calls.

  An iteration is `num_envs` x `num_steps` env steps. The calls are as equal as whole
  iterations allow (the first ones one iteration longer), so the run is exactly
  ceil(timesteps / (num_envs x num_steps)) iterations with an evaluation before the first
  call and after each of the `evals` calls.

  Returns:
    iterations per call: a list of `evals` integers >= 1.

  Raises:
    ValueError: a count below 1, more calls than iterations, or a rounded total above
      MAX_ENV_STEPS (the device's int32 step counter).
  """
  for name, v in (("timesteps", timesteps), ("num_envs", num_envs), ("num_steps", num_steps), ("evals", evals)):
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
      raise ValueError(f"{name} must be an integer >= 1; got {v!r}")
  per_iter = int(num_envs) * int(num_steps)
  if timesteps > MAX_ENV_STEPS or per_iter > MAX_ENV_STEPS:
    raise ValueError(f"timesteps ({timesteps:,d}) and num_envs x num_steps ({per_iter:,d}) must be at most "
                     f"{MAX_ENV_STEPS:,d} (the env-step counter on the device is an int32)")
  iters = -(-int(timesteps) // per_iter)
  if iters * per_iter > MAX_ENV_STEPS:
    raise ValueError(f"timesteps ({timesteps:,d}) rounded up to whole PPO iterations of {per_iter:,d} env steps "
                     f"is {iters * per_iter:,d}, above {MAX_ENV_STEPS:,d} (the int32 env-step counter)")
  if evals > iters:
    raise ValueError(f"evals ({evals}) must be at most the PPO iterations ({iters}: timesteps {timesteps:,d} "
                     f"rounded up to whole iterations of num_envs x num_steps = {per_iter:,d} env steps); "
                     "each evaluation follows at least one iteration")
  q, r = divmod(iters, int(evals))
  return [q + (i < r) for i in range(int(evals))]


def train_with_curve(adapter: GymnaxAdapter, algo, key: jax.Array, *, calls, num_eval: int,
                     callback: Callable | None = None, mesh=None, evaluate: Callable = evaluate_policy):
  """Trains `sum(calls)` PPO iterations in `len(calls)` calls, evaluating before and after each call.

  The env steps reported are the train state's own counter (`global_step`, counted on the
  device), read back after each call and checked against the iterations asked for.

  Args:
    adapter, algo: from `make_ppo` (its `timesteps_per_call` is not used here).
    key: PRNG key (init and evaluation keys are split from it).
    calls: PPO iterations of each training call (integers >= 1; `plan_training` makes them).
    num_eval: episodes per evaluation.
    callback: optional `callback(point)` after each evaluation, with `point` a dict
      of that evaluation's means (EVAL_KEYS), `env_steps` (counted on the device), `index`
      (0 = before training), `train_s` (cumulative) and `steps_per_s` (the last call's env
      steps per second; 0.0 at index 0).
    mesh: optional 1-D device mesh: the env batch is sharded over it (see the
      module docstring); num_envs must be a multiple of its size.
    evaluate: `evaluate(adapter, act, key, num_eval) -> dict of per-episode arrays`
      (`evaluate_policy`; `sims.rl.fleet.evaluate_fleet_policy` for one agent per robot, whose
      `algo` has `robots_per_world` K: the device counts robot-steps, the curve's env_steps are
      those / K and its agent_steps the robot-steps).

  Returns:
    (final train state, evals: dict name -> float list [len(calls) + 1], timing dict
    with compile_s (wall time of both compiles, run side by side), compile_train_s and
    compile_eval_s (each from the start of compiling to its end), train_s).

  Raises:
    ValueError: an empty `calls`, a count below 1, or more env steps than MAX_ENV_STEPS.
    RuntimeError: the device's step counter disagrees with the iterations run (a bug).
  """
  calls = list(calls)
  if not calls or any(isinstance(c, bool) or not isinstance(c, (int, np.integer)) or c < 1 for c in calls):
    raise ValueError(f"calls must be a non-empty list of PPO iterations >= 1 per call; got {calls!r}")
  if sum(calls) * algo.num_envs * algo.num_steps > MAX_ENV_STEPS:
    raise ValueError(f"{sum(calls):,d} PPO iterations of {algo.num_envs * algo.num_steps:,d} env steps exceed "
                     f"{MAX_ENV_STEPS:,d} (the int32 env-step counter)")
  with jax.numpy_rank_promotion("allow"):     # rejax broadcasts [N, D] - [D] internally
    return _train_with_curve(adapter, algo, key, calls=calls, num_eval=num_eval, callback=callback, mesh=mesh,
                             evaluate=evaluate)


def train_program(algo, key: jax.Array, mesh=None):
  """(initial train state, jitted `train(ts, num_iterations) -> ts`), the env batch sharded over `mesh`.

  `train` runs `num_iterations` (an int32 scalar, traced: one compile serves every count)
  of rejax's PPO iterations (`algo.train_iteration`, what `algo.train` loops over; rejax's
  own evaluation is off in `make_ppo`). Without a mesh: on the default device. With a 1-D
  mesh (`sims.scale.sharding.make_mesh`): the state placed with `train_state_shardings` and the
  iterations of `block_shuffle(algo, mesh)`, compiled for those shardings. Call it under
  `jax.numpy_rank_promotion("allow")` (rejax broadcasts internally).

  Raises:
    ValueError: see `block_shuffle`.
  """
  ts = jax.jit(algo.init_state)(key)

  def iterations(program):
    return lambda ts, n: jax.lax.fori_loop(0, n, lambda _, t: program.train_iteration(t), ts)

  if mesh is None:
    return ts, jax.jit(iterations(algo))
  shardings = train_state_shardings(ts, mesh)
  blocked = block_shuffle(algo, mesh)
  return jax.device_put(ts, shardings), jax.jit(iterations(blocked), in_shardings=(shardings, None),
                                                out_shardings=shardings)


def _train_with_curve(adapter, algo, key, *, calls, num_eval, callback, mesh, evaluate):
  k_init, k_eval = jax.random.split(key)
  per_episode = evaluate
  evaluate = jax.jit(lambda ts, k: {n: jnp.mean(v) for n, v in
                                    per_episode(adapter, mean_policy(algo, ts), k, num_eval).items()})
  ts, train = train_program(algo, k_init, mesh)
  n0 = np.int32(calls[0])
  # The two programs compile at the same time (XLA compiles outside the GIL): the wall time is
  # the longer compile, not the sum.
  # jax's config contexts are per thread: each compile thread sets rejax's rank promotion again.
  def compile_in_thread(fn, *args):
    with jax.numpy_rank_promotion("allow"):
      return fn.lower(*args).compile(), time.perf_counter()

  t0 = time.perf_counter()
  with concurrent.futures.ThreadPoolExecutor(2) as pool:
    train_f = pool.submit(compile_in_thread, train, ts, n0)
    eval_f = pool.submit(compile_in_thread, evaluate, ts, k_eval)
    (train_c, t_train), (eval_c, t_eval) = train_f.result(), eval_f.result()
  agents = getattr(algo, "robots_per_world", None)      # one agent per robot: the device counts robot-steps
  evals = {n: [] for n in (*EVAL_KEYS, "env_steps")}   # an evaluate's other figures follow
  train_s = 0.0
  per_iter = algo.num_envs * algo.num_steps
  start = int(ts.global_step)

  def record(ts, i, call_s):
    out = eval_c(ts, jax.random.fold_in(k_eval, i))
    for n, v in out.items():
      evals.setdefault(n, []).append(float(v))
    done = int(ts.global_step) - start              # counted on the device
    want = sum(calls[:i]) * per_iter
    if done != want:
      raise RuntimeError(f"the train state counted {done:,d} env steps after {sum(calls[:i])} PPO iterations "
                         f"of {per_iter:,d}; expected {want:,d} (nothing was saved)")
    evals["env_steps"].append(float(done // (agents or 1)))
    if agents:
      evals.setdefault("agent_steps", []).append(float(done))
    if callback is not None:
      point = {n: v[-1] for n, v in evals.items()}
      per_call = evals["env_steps"][-1] - (evals["env_steps"][-2] if i else evals["env_steps"][-1])
      callback({**point, "index": i, "train_s": train_s, "steps_per_s": per_call / call_s if call_s else 0.0})

  record(ts, 0, 0.0)
  for i, n in enumerate(calls):
    t = time.perf_counter()
    ts = train_c(ts, np.int32(n))
    jax.block_until_ready(ts)
    call_s = time.perf_counter() - t
    train_s += call_s
    record(ts, i + 1, call_s)
  timing = {"compile_s": max(t_train, t_eval) - t0, "compile_train_s": t_train - t0, "compile_eval_s": t_eval - t0,
            "train_s": train_s}
  return ts, evals, timing


def plot_curve(evals: dict, path: Path, title: str) -> Path:
  """Learning curve PNG: return, success rate and rule breaks against env steps."""
  import matplotlib
  matplotlib.use("Agg")
  import matplotlib.pyplot as plt

  x = np.asarray(evals["env_steps"]) / 1e3
  fig, axes = plt.subplots(1, 3, figsize=(12, 3.4), dpi=90)
  axes[0].plot(x, evals["return"], color="tab:blue")
  axes[0].set_ylabel("episode return")
  axes[1].plot(x, 100 * np.asarray(evals["success"]), color="tab:green", label="success (%)")
  axes[1].set_ylabel("episodes reaching a goal (%)")
  axes[1].set_ylim(0, 100)
  twin = axes[1].twinx()
  twin.plot(x, evals["goals_reached"], color="tab:olive", linestyle="--", label="goals / episode")
  twin.set_ylabel("goals per episode", color="tab:olive")
  twin.set_ylim(0, max(1.0, 1.1 * max(evals["goals_reached"])))
  axes[1].legend(handles=axes[1].get_lines() + twin.get_lines(), fontsize=8, loc="upper left")
  axes[2].plot(x, evals["keepout_entries"], color="tab:red", label="keepout entries")
  axes[2].plot(x, evals["collisions"], color="tab:gray", label="collisions")
  axes[2].plot(x, evals["speed_violation_s"], color="tab:orange", label="s above speed limit")
  axes[2].plot(x, evals["clipped"], color="tab:purple", linestyle=":", label="clipped command (m)")
  axes[2].set_ylabel("per episode")
  top = max(max(evals[k]) for k in ("keepout_entries", "collisions", "speed_violation_s", "clipped"))
  axes[2].set_ylim(0, 1.45 * max(top, 0.1))
  axes[2].legend(fontsize=7, loc="upper left", ncol=2)
  for ax in axes:
    ax.set_xlabel("env steps (thousands)")
    ax.grid(alpha=0.3)
  fig.suptitle(title, fontsize=10)
  fig.tight_layout()
  path.parent.mkdir(parents=True, exist_ok=True)
  fig.savefig(path)
  plt.close(fig)
  return path
