"""RL environment throughput on the device: env only, policy in the loop, PPO end to end, scaling.

    python -m benchmarks.rl_bench --json --out rl_bench.json          # GPU: full sizes
    python -m benchmarks.rl_bench --quick                             # CPU smoke sizes (seconds)

Figures (each with `compile_s` apart from the steady state, the device named):

* `env_only`: `lax.scan` of `vmap(NavEnv.step)` over N envs with fixed
  actions; env-steps/s (one env step = 0.2 s simulated = 20 MJX steps of one
  robot, with the speed filter at 20 Hz, keepout/collision/speed checks at
  100 Hz and the observation).
* `policy_loop`: the same with a 2 x 64 tanh MLP (rejax's PPO actor, random
  weights) choosing every action from the observation.
* `ppo_train`: rejax PPO (`sims.rl.ppo.make_ppo`) training calls of N envs
  x 64 steps; agent env-steps/s including the PPO updates.
* `weak_scaling` / `strong_scaling`: `env_only` sharded over 1, 2, 4, ... of
  the available devices (`sims.scale.sharding`): N per device fixed, or N total
  fixed. Efficiency = throughput(d) / (d x throughput(1)) for weak, and
  throughput(d) / throughput(1) / d for strong.

Needs the `rl` extra. `--quick` runs every figure at tiny sizes (the CPU check
that the script works); the full sizes are for a GPU (`RL=1 bash benchmarks/device_run.sh`).
"""

from __future__ import annotations

import json
import math
import sys
import time

import jaxfilters  # noqa: F401  (first: importing it sets the XLA:CPU flags, jaxfilters/xla_flags.py)

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from jaxfilters.cli import ArgumentParser  # noqa: E402


def _sizes(quick: bool, platform: str) -> dict:
  if quick:
    return dict(envs=[8], steps=5, ppo_envs=8, ppo_steps=8, ppo_calls=2, scale_envs=8, scale_steps=5, repeats=2)
  if platform == "cpu":
    return dict(envs=[64, 256], steps=50, ppo_envs=64, ppo_steps=64, ppo_calls=3, scale_envs=64,
                scale_steps=20, repeats=3)
  return dict(envs=[1024, 8192, 32768], steps=100, ppo_envs=8192, ppo_steps=32, ppo_calls=3, scale_envs=8192,
              scale_steps=50, repeats=3)


def _best(fn, args, repeats):
  best = math.inf
  out = None
  for _ in range(repeats):
    t = time.perf_counter()
    out = jax.block_until_ready(fn(*args))
    best = min(best, time.perf_counter() - t)
  return best, out


def _rollout(env, num_steps, policy=None, mesh=None):
  """jitted (states [N], params) -> states after num_steps of vmap(step)."""
  from sims.scale import sharding

  def run(states, params):
    def body(s, _):
      if policy is None:
        act = jnp.broadcast_to(jnp.asarray([0.8, 0.2], jnp.float32), s.obs.shape[:1] + (env.action_size,))
      else:
        act = jnp.clip(policy(params, s.obs), -1.0, 1.0)
      return jax.vmap(env.step)(s, act), None
    return jax.lax.scan(body, states, None, length=num_steps)[0]

  if mesh is None:
    return jax.jit(run)
  w = sharding.worlds_sharding(mesh)
  return jax.jit(run, in_shardings=(w, sharding.replicated(mesh)), out_shardings=w)


def _mlp(obs_size, action_size, key):
  import flax.linen as nn

  class Actor(nn.Module):
    @nn.compact
    def __call__(self, x):
      for h in (64, 64):
        x = nn.tanh(nn.Dense(h)(x))
      return nn.Dense(action_size)(x)

  actor = Actor()
  params = actor.init(key, jnp.zeros((1, obs_size)))
  return actor.apply, params


def bench_env(env, n, steps, repeats, *, policy=False, mesh=None) -> dict:
  from sims.scale import sharding
  reset, _ = sharding.rl_batch_fns(env, mesh)
  keys = jax.random.split(jax.random.PRNGKey(0), n)
  if mesh is not None:
    keys = sharding.put_global(keys, sharding.worlds_sharding(mesh))
  states = reset(keys)
  apply, params = (None, jnp.zeros(()))
  if policy:
    apply, params = _mlp(env.observation_size, env.action_size, jax.random.PRNGKey(1))
  if mesh is not None:
    params = sharding.put_global(params, sharding.replicated(mesh))
  run = _rollout(env, steps, apply, mesh)
  t = time.perf_counter()
  compiled = run.lower(states, params).compile()
  compile_s = time.perf_counter() - t
  jax.block_until_ready(compiled(states, params))
  best, out = _best(compiled, (states, params), repeats)
  assert bool(jnp.all(jnp.isfinite(out.obs))), "non-finite observation"
  k = env.num_robots
  rate = n * steps / best
  return {"envs": n, "steps": steps, "compile_s": compile_s, "steady_s": best, "env_steps_per_s": rate,
          "robot_physics_steps_per_s": rate * k * env.n_substeps,
          "devices": 1 if mesh is None else int(mesh.devices.size)}


def bench_ppo(env, n, num_steps, calls) -> dict:
  from sims.rl.ppo import GymnaxAdapter, make_ppo
  adapter = GymnaxAdapter(env, episode_length=200)
  algo = make_ppo(adapter, timesteps_per_call=n * num_steps, num_envs=n, num_steps=num_steps,
                  num_minibatches=4 if n * num_steps >= 64 else 1)
  with jax.numpy_rank_promotion("allow"):
    ts = jax.jit(algo.init_state)(jax.random.PRNGKey(0))
    train = jax.jit(lambda ts: algo.train(train_state=ts)[0])
    t = time.perf_counter()
    compiled = train.lower(ts).compile()
    compile_s = time.perf_counter() - t
    ts = jax.block_until_ready(compiled(ts))
    t = time.perf_counter()
    for _ in range(calls):
      ts = compiled(ts)
    jax.block_until_ready(ts)
    dt = time.perf_counter() - t
  steps = calls * n * num_steps
  return {"envs": n, "rollout_steps": num_steps, "calls": calls, "compile_s": compile_s, "steady_s": dt,
          "agent_steps_per_s": steps / dt}


def main(argv=None) -> int:
  ap = ArgumentParser(prog="python -m benchmarks.rl_bench", description=__doc__.splitlines()[0])
  ap.add_argument("--quick", action="store_true", help="tiny sizes (a CPU check that everything runs)")
  ap.add_argument("--json", action="store_true", help="print the JSON report on stdout")
  ap.add_argument("--out", default=None, help="also write the JSON report to this file")
  ap.add_argument("--only", default=None, help="comma list of env_only,policy_loop,ppo_train,scaling")
  args = ap.parse_args(argv)
  from sims.scale import sharding
  from sims.rl.env import NavEnv
  dev = jax.devices()
  sz = _sizes(args.quick, dev[0].platform)
  only = set(args.only.split(",")) if args.only else {"env_only", "policy_loop", "ppo_train", "scaling"}
  report = {"device": dev[0].device_kind, "platform": dev[0].platform, "num_devices": len(dev),
            "jax": jax.__version__, "quick": args.quick, "figures": {}}
  log = lambda s: print(s, file=sys.stderr, flush=True)
  log(f"rl_bench on {len(dev)} x {dev[0].device_kind} (jax {jax.__version__}){' [quick]' if args.quick else ''}")
  env = NavEnv.create()
  fig = report["figures"]
  if "env_only" in only:
    fig["env_only"] = [bench_env(env, n, sz["steps"], sz["repeats"]) for n in sz["envs"]]
    for r in fig["env_only"]:
      log(f"env_only     N={r['envs']:>6}: {r['env_steps_per_s']:.3g} env-steps/s "
          f"({r['robot_physics_steps_per_s']:.3g} robot physics steps/s), compile {r['compile_s']:.1f} s")
  if "policy_loop" in only:
    fig["policy_loop"] = [bench_env(env, n, sz["steps"], sz["repeats"], policy=True) for n in sz["envs"]]
    for r in fig["policy_loop"]:
      log(f"policy_loop  N={r['envs']:>6}: {r['env_steps_per_s']:.3g} env-steps/s, compile {r['compile_s']:.1f} s")
  if "ppo_train" in only:
    r = bench_ppo(env, sz["ppo_envs"], sz["ppo_steps"], sz["ppo_calls"])
    fig["ppo_train"] = r
    log(f"ppo_train    N={r['envs']:>6}: {r['agent_steps_per_s']:.3g} agent-steps/s, compile {r['compile_s']:.1f} s")
  if "scaling" in only:
    counts = [d for d in (1, 2, 4, 8, 16) if d <= len(dev)]
    weak, strong = [], []
    for d in counts:
      mesh = sharding.make_mesh(d)
      weak.append(bench_env(env, sz["scale_envs"] * d, sz["scale_steps"], sz["repeats"], mesh=mesh))
      if sz["scale_envs"] % d == 0:
        strong.append(bench_env(env, sz["scale_envs"], sz["scale_steps"], sz["repeats"], mesh=mesh))
    for rows, kind in ((weak, "weak"), (strong, "strong")):
      base = rows[0]["env_steps_per_s"]
      for r in rows:
        d = r["devices"]
        r["efficiency"] = r["env_steps_per_s"] / (d * base)
        log(f"{kind:<6} scaling d={d} N={r['envs']:>6}: {r['env_steps_per_s']:.3g} env-steps/s, "
            f"efficiency {r['efficiency']:.2f}")
    fig["weak_scaling"], fig["strong_scaling"] = weak, strong
  text = json.dumps(report, indent=2)
  if args.out:
    with open(args.out, "w") as f:
      f.write(text)
  if args.json:
    print(text)
  return 0


if __name__ == "__main__":
  sys.exit(main())
