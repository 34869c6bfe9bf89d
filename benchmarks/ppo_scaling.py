"""PPO training throughput over several devices against one, the same training program in one process.

    python -m benchmarks.ppo_scaling --num-envs 65536 262144 --devices 4 --json --out ppo_scaling.json

For each --num-envs N: `jaxfilters rl train --randomize`'s training call
(`sims.rl.ppo.train_program`: rejax PPO, the env batch sharded over D devices with
the per-device minibatch shuffle) is compiled for D = --devices and for one
device, then timed: one warm-up call and --calls timed calls of --iters PPO
iterations (N envs x --num-steps steps each). Agent env-steps per second are
the median over the timed calls; `speedup` = D devices / one device at the
same N (the same algorithm and batch, so the same learning curve per sample:
`jaxfilters rl train --devices` checks that on its own curve). Each N also gets
one device at N / D envs (`per_device_ceiling`: D x that is what D devices
could reach with no communication at all; below it, the loss is in the
sharded program, above the one-device figure, the gain is from splitting).

Same env as `rl train --randomize` (the built-in warehouse, --layouts layouts,
seed 0) and its defaults (--num-steps 32, 8 minibatches, 4 epochs, 64 x 64).
`--reset-capacity auto none` times each N both ways (one device, `--devices 1`): the fresh resets
drawn only for the envs whose episode ended (`GymnaxAdapter`'s default, "auto") and for every env
at every step ("none", the adapter before 2026-12-07); an integer sets the capacity. Over D > 1
devices every run, the one-device ones included, resets every env: the sharded program does
(`sims.rl.ppo.block_shuffle`), and `speedup` compares the same program.
Every timed call's train state is checked: replicas identical across devices.
"""

from __future__ import annotations

import json
import statistics
import sys
import time

import jax
import numpy as np
from jaxfilters.cli import ArgumentParser  # one-line errors, exit code 2


def _time_program(algo, mesh, calls: int) -> dict:
  from sims.rl.ppo import replicas_identical, train_program
  t0 = time.perf_counter()
  ts, train = train_program(algo, jax.random.PRNGKey(0), mesh)
  iters = np.int32(algo.total_timesteps // (algo.num_envs * algo.num_steps))
  compiled = train.lower(ts, iters).compile()
  compile_s = time.perf_counter() - t0
  ts = jax.block_until_ready(compiled(ts, iters))      # warm-up call
  times = []
  for _ in range(calls):
    t = time.perf_counter()
    ts = jax.block_until_ready(compiled(ts, iters))
    times.append(time.perf_counter() - t)
  if mesh is not None and not replicas_identical(ts):
    raise RuntimeError("the devices' copies of the networks differ after training")
  return {"compile_s": compile_s, "call_s": times, "env_steps_per_call": int(algo.total_timesteps)}


def main(argv=None) -> int:
  ap = ArgumentParser(description=__doc__.split("\n\n")[0])
  ap.add_argument("--num-envs", type=int, nargs="+", default=[65536])
  ap.add_argument("--devices", type=int, default=None, help="devices to shard over (default all)")
  ap.add_argument("--num-steps", type=int, default=32)
  ap.add_argument("--minibatches", type=int, default=8)
  ap.add_argument("--iters", type=int, default=1, help="PPO iterations per timed call")
  ap.add_argument("--calls", type=int, default=3, help="timed calls (after one warm-up)")
  ap.add_argument("--layouts", type=int, default=16)
  ap.add_argument("--skip-ceiling", action="store_true", help="no one-device run at N / D envs")
  ap.add_argument("--reset-capacity", nargs="+", default=None,
                  help="with --devices 1: GymnaxAdapter reset_capacity values to time: auto, none or an integer "
                       ">= 1 (default auto); over more devices every run resets every env")
  ap.add_argument("--json", action="store_true")
  ap.add_argument("--out", default=None)
  args = ap.parse_args(argv)

  from sims.scale import sharding
  from sims.rl.ppo import GymnaxAdapter, make_ppo
  from sims.rl.randomization import training_env
  from sims.rl.env import NavEnvConfig

  for name in ("num_steps", "minibatches", "iters", "calls", "layouts"):
    if getattr(args, name) < 1:
      ap.error(f"--{name.replace('_', '-')} must be >= 1; got {getattr(args, name)}")
  capacities = []
  for c in args.reset_capacity or ["auto"]:
    if c in ("auto", "none"):
      capacities.append(None if c == "none" else c)
    elif c.isascii() and c.isdigit() and int(c) >= 1:
      capacities.append(int(c))
    else:
      ap.error(f"--reset-capacity: each value must be auto, none or an integer >= 1; got {c!r}")
  d = args.devices if args.devices is not None else len(jax.devices())
  if d > 1:
    if args.reset_capacity is not None:
      ap.error(f"--reset-capacity times one-device runs (--devices 1); over {d} devices every run resets "
               f"every env, as the sharded program does, so that the speedup compares the same program")
    capacities = [None]
  try:
    mesh = sharding.make_mesh(d) if d != 1 else None
  except ValueError as e:
    ap.error(f"--devices: {e}")
  for n in args.num_envs:
    if n < 1 or n % d or (n // d * args.num_steps) % args.minibatches:
      ap.error(f"--num-envs {n}: must be a positive multiple of the {d} devices whose per-device batch "
               f"({n // d if n > 0 else n} envs x {args.num_steps} steps) splits into {args.minibatches} minibatches")
  t = time.perf_counter()
  env, fn = training_env(None, randomize=True, seed=0, layouts=args.layouts, config=NavEnvConfig())
  adapters = {c: GymnaxAdapter(env, 300, fn, full_reset=True, reset_capacity=c) for c in capacities}
  report = {"device": jax.devices()[0].device_kind, "devices": d, "num_steps": args.num_steps,
            "minibatches": args.minibatches, "iters_per_call": args.iters, "build_env_s": time.perf_counter() - t,
            "runs": []}

  def save():
    text = json.dumps(report, indent=1)
    if args.out:
      with open(args.out, "w") as f:
        f.write(text + "\n")
    return text

  with jax.numpy_rank_promotion("allow"):
    for n in args.num_envs:
      plan = [(n, 1, None)] if d == 1 else (
          [(n, d, mesh), (n, 1, None)] + ([] if args.skip_ceiling else [(n // d, 1, None)]))
      for envs, devs, m in plan:
        for cap, adapter in adapters.items():
          algo = make_ppo(adapter, timesteps_per_call=args.iters * envs * args.num_steps, num_envs=envs,
                          num_steps=args.num_steps, num_minibatches=args.minibatches)
          r = _time_program(algo, m, args.calls)
          r.update(num_envs=envs, devices=devs, reset_capacity=cap,
                   env_steps_per_s=r["env_steps_per_call"] / statistics.median(r["call_s"]))
          report["runs"].append(r)
          print(f"N={envs:>8d} devices={devs} reset_capacity={r['reset_capacity']}: "
                f"{r['env_steps_per_s'] / 1e6:7.3f} M env-steps/s "
                f"(compile {r['compile_s']:.1f} s, calls {', '.join(f'{c:.3f}' for c in r['call_s'])} s)",
                file=sys.stderr, flush=True)
          save()
      if d > 1:
        by = {(r["num_envs"], r["devices"]): r["env_steps_per_s"] for r in report["runs"]}
        s = {"num_envs": n, "speedup": by[(n, d)] / by[(n, 1)]}
        if (n // d, 1) in by:
          s["per_device_ceiling"] = d * by[(n // d, 1)] / by[(n, 1)]
        report.setdefault("speedups", []).append(s)
        print(f"N={n}: {d} devices / 1 = x{s['speedup']:.2f}"
              + (f" (ceiling without communication x{s['per_device_ceiling']:.2f})" if "per_device_ceiling" in s
                 else ""), file=sys.stderr, flush=True)
  text = save()
  if args.json:
    print(text)
  return 0


if __name__ == "__main__":
  sys.exit(main())
