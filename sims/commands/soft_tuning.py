"""Tunes a corner's speed-zone limit with jax.grad and re-checks it with the real filters (sims.tuning.corner_speed).

    python -m sims.commands.soft_tuning [figure.png]

Prints the optimisation history and the hard re-runs; with a path, draws them.
"""

from __future__ import annotations

import sys

from sims.tuning.corner_speed import CornerScenario, hard_check, plot_tuning, tune


def main(argv=None) -> int:
  """Runs the tuning; argv[0], when given, is the figure to write. Returns the exit code."""
  argv = sys.argv[1:] if argv is None else list(argv)
  if argv and argv[0].startswith("-"):
    print(__doc__.strip(), file=sys.stderr if argv[0] not in ("-h", "--help") else sys.stdout)
    return 0 if argv[0] in ("-h", "--help") else 2
  scenario = CornerScenario()
  hist = tune(scenario)
  best = hist.best_limit
  print(f"{scenario.num_robots} robots, {scenario.duration:.1f} s, route {scenario.route_length:.1f} m")
  for k in range(len(hist.limit)):
    print(f"  iter {k:2d}: limit {hist.limit[k]:.3f} m/s  objective {hist.objective[k]:7.3f}  "
          f"progress {hist.progress[k]:6.3f} m  exposure {hist.exposure[k]:.4f}  grad {hist.gradient[k]:+.3f}")
  checks = {}
  for name, lim in (("start", hist.limit[0]), ("tuned", best), ("top speed", scenario.robot.max_speed)):
    chk = checks[name] = hard_check(scenario, lim)
    print(f"hard re-run, {name}: d = {chk.mask_value} ({chk.hard_limit:.2f} m/s): progress {chk.progress:.3f} m, "
          f"clearance {chk.clearance:+.3f} m, cells entered {chk.cells_entered}, margin held {chk.margin_held}")
  if argv:
    plot_tuning(scenario, hist, checks, argv[0])
    print(f"figure: {argv[0]}")
  return 0


if __name__ == "__main__":
  sys.exit(main())
