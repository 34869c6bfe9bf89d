"""Where the fleet step's time goes: the whole step with the default config and with the
planner or the controller rate changed, one figure each (robot-steps/s, all filters on).

    python benchmarks/fleet_breakdown.py 65536
"""

import dataclasses
import json
import sys

from sims.bench import fleet_throughput
from sims.config import FleetConfig


def main(argv=None) -> int:
  argv = sys.argv[1:] if argv is None else argv
  num_robots = int(argv[0]) if argv else 1024
  base = FleetConfig()
  variants = {
      "default": base,
      "planner_3x5": dataclasses.replace(base, planner=dataclasses.replace(base.planner, num_speeds=3,
                                                                           num_yaw_rates=5)),
      "controller_10hz": dataclasses.replace(base, controller_hz=10.0),
  }
  out = {}
  for name, cfg in variants.items():
    try:
      out[name] = fleet_throughput(num_robots, 100, filters=True, config=cfg)["robot_steps_per_s"]
    except Exception as e:  # noqa: BLE001 - report and go on
      out[name] = f"{type(e).__name__}: {e}"[:300]
    print(name, out[name], file=sys.stderr, flush=True)
  print(json.dumps(out))
  return 0


if __name__ == "__main__":
  sys.exit(main())
