"""Draws a fleet bag as a viewer shows it (sims/record/bag_view.py) into a PNG.

    jaxfilters fleet --seconds 60 --bag out/bag --bag-costmaps 4 --out out/bagrun
    python -m sims.commands.bag_picture out/bag docs/bag.png [--robot I]

The README's bag picture (docs/bag.png) is made by these two commands.
Exit codes: 0 written, 2 a bag folder that is missing or not a fleet bag (a file in it that is
not a regular file, such as a FIFO, is refused before anything is opened; a malformed
metadata.yaml is one line), or an unknown robot.
"""

from __future__ import annotations

import sys

from jaxfilters import cli as jcli


def main(argv=None) -> int:
  ap = jcli.ArgumentParser(prog="python -m sims.commands.bag_picture",
                           description="Draw a fleet bag (jaxfilters fleet --bag) into a PNG.")
  ap.add_argument("bag", type=jcli.path_type, help="rosbag2 folder written by jaxfilters fleet --bag")
  ap.add_argument("out", type=jcli.path_type, help="PNG to write (a new or a regular file)")
  ap.add_argument("--robot", type=jcli.int_type(0), default=None,
                  help="robot whose costmap and speed are shown (default: the one whose limit changed most)")
  args = ap.parse_args(argv)
  if (args.out.exists() or args.out.is_symlink()) and not args.out.is_file():
    print(f"bag_picture: {args.out} exists and is not a regular file (a FIFO, device or folder is refused)",
          file=sys.stderr)
    return 2
  from sims.record import bag_view
  try:
    path = bag_view.render_bag_png(args.bag, args.out, robot=args.robot)
  except (OSError, ValueError) as e:
    text = " ".join(line.strip() for line in str(e).splitlines() if line.strip())
    print(f"bag_picture: {text[:500]}", file=sys.stderr)      # one line, whatever a reader raised
    return 2
  print(f"wrote {path}")
  return 0


if __name__ == "__main__":
  sys.exit(main())
