"""Draws a fleet bag as a viewer shows it (sims/record/bag_view.py) into a PNG.

    jaxfilters fleet --seconds 60 --bag out/bag --bag-costmaps 4 --out out/bagrun
    python -m sims.commands.bag_picture out/bag docs/bag.png [--robot I]

The README's bag picture (docs/bag.png) is made by these two commands.
Exit codes: 0 written, 2 a bag folder that is missing or not a fleet bag, or an unknown robot.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def main(argv=None) -> int:
  ap = argparse.ArgumentParser(prog="python -m sims.commands.bag_picture",
                               description="Draw a fleet bag (jaxfilters fleet --bag) into a PNG.")
  ap.add_argument("bag", type=Path, help="rosbag2 folder written by jaxfilters fleet --bag")
  ap.add_argument("out", type=Path, help="PNG to write")
  ap.add_argument("--robot", type=int, default=None,
                  help="robot whose costmap and speed are shown (default: the one whose limit changed most)")
  args = ap.parse_args(argv)
  from sims.record import bag_view
  try:
    path = bag_view.render_bag_png(args.bag, args.out, robot=args.robot)
  except (FileNotFoundError, ValueError) as e:
    print(f"bag_picture: {e}", file=sys.stderr)
    return 2
  print(f"wrote {path}")
  return 0


if __name__ == "__main__":
  sys.exit(main())
