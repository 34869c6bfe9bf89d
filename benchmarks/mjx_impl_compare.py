"""MJX `impl='jax'` against `impl='warp'` (MuJoCo Warp) for the fleet, bare and with all filters.

    python -m benchmarks.mjx_impl_compare --robots 65536 --steps 100 [--out FILE]

GPU only for 'warp' (needs the warp-lang wheel, pinned 1.18.0 by mujoco-mjx[warp]).
Each figure is run in its own try block so one failing implementation still
reports the others; the JSON names the error.
"""

from __future__ import annotations

import json
import sys
import traceback
from jaxfilters.cli import ArgumentParser  # one-line errors, exit code 2


def main(argv=None) -> int:
  parser = ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument("--robots", type=int, default=65536)
  parser.add_argument("--steps", type=int, default=100)
  parser.add_argument("--impls", default="jax,warp")
  parser.add_argument("--out")
  args = parser.parse_args(argv)
  from sims.scale.bench import fleet_throughput  # noqa: PLC0415 - after argument parsing

  results = {}
  for impl in args.impls.split(","):
    for filters in (False, True):
      key = f"{impl}_{'filters' if filters else 'bare'}"
      try:
        results[key] = fleet_throughput(args.robots, args.steps, filters=filters, impl=impl)
      except Exception as e:  # noqa: BLE001 - report and go on
        results[key] = dict(error=f"{type(e).__name__}: {e}", trace=traceback.format_exc(limit=6))
      r = results[key]
      print(f"{key:16s} " + (f"{r['robot_steps_per_s']:.4g} robot-steps/s, compile {r['compile_s']:.1f} s"
                             if "robot_steps_per_s" in r else r["error"][:300]), file=sys.stderr, flush=True)
  text = json.dumps(results, default=str)
  if args.out:
    with open(args.out, "w") as f:
      f.write(text)
  print(text)
  return 0


if __name__ == "__main__":
  sys.exit(main())
