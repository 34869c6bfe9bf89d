"""One process of a multi-process (jax.distributed) sharded fleet rollout (see sims/scale/sharding.py).

    XLA_FLAGS=--xla_force_host_platform_device_count=2 JAX_PLATFORMS=cpu \\
      python -m sims.commands.sharding --coordinator 127.0.0.1:12355 --num-processes 2 \\
        --process-id 0 --worlds 8 --steps 5 --out out/dist_0.npz
"""

from __future__ import annotations

import sys

import numpy as np

from sims.scale import sharding
from jaxfilters.cli import ArgumentParser  # one-line errors, exit code 2


def main(argv=None) -> int:
  """One process of a multi-process sharded rollout; returns the exit code."""
  ap = ArgumentParser(prog="python -m sims.commands.sharding",
                               description="One process of a multi-process (jax.distributed) sharded fleet rollout.")
  ap.add_argument("--coordinator", required=True, help="host:port of process 0 (e.g. 127.0.0.1:12355)")
  ap.add_argument("--num-processes", type=int, required=True, help="processes in the run")
  ap.add_argument("--process-id", type=int, required=True, help="this process, 0 .. num-processes - 1")
  ap.add_argument("--worlds", type=int, default=8, help="worlds in total (default 8)")
  ap.add_argument("--steps", type=int, default=5, help="env steps (default 5)")
  ap.add_argument("--robots-per-world", type=int, default=2, help="(default 2)")
  ap.add_argument("--seed", type=int, default=0, help="PRNG seed (default 0)")
  ap.add_argument("--out", required=True, help="npz file for this process's shards")
  args = ap.parse_args(argv)
  if not 0 <= args.process_id < args.num_processes:
    ap.error(f"--process-id must lie in [0, {args.num_processes}); got {args.process_id}")
  out = sharding.distributed_rollout(args.coordinator, args.num_processes, args.process_id, num_worlds=args.worlds,
                            num_steps=args.steps, robots_per_world=args.robots_per_world, seed=args.seed)
  np.savez(args.out, **{f"{k}_index": v[0] for k, v in out.items()}, **{k: v[1] for k, v in out.items()})
  print(f"process {args.process_id}: saved {sorted(out)} for worlds {out['goal'][0].tolist()}")
  return 0


if __name__ == "__main__":
  sys.exit(main())
