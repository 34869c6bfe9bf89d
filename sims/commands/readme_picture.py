"""Copies the demo's picture to the README's (docs/demo.png), with the numbers it shows as PNG text.

    make readme-picture                                   # runs `make demo`, then:
    python -m sims.commands.readme_picture out/demo docs/demo.png

The source must be a run of `make demo` (`jaxfilters fleet --out out/demo` with the defaults):
its summary.json is checked against the `fleet` command's defaults, so the README never shows
another run. The copy carries a PNG text chunk "jaxfilters-demo" (JSON: the command, robots,
seconds, seed, goals reached, keepout entries, speed compliance, device) that
tests/project/test_readme.py checks against the `fleet` defaults.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from jaxfilters.cli import ArgumentParser  # one-line errors, exit code 2

DEMO_COMMAND = ["fleet", "--out", "out/demo"]     # what `make demo` runs after `jaxfilters`
TEXT_KEY = "jaxfilters-demo"


def demo_defaults() -> dict:
  """robots, seconds and seed of `jaxfilters fleet --out out/demo` (the fleet parser's defaults)."""
  from jaxfilters import cli
  args = cli.build_parser().parse_args(DEMO_COMMAND)
  return {"robots": args.robots, "seconds": 120.0 if args.seconds is None else args.seconds, "seed": args.seed}


def picture_text(summary: dict) -> dict:
  """The numbers the picture shows, from the demo's summary.json."""
  f = summary["fleet"]
  return {"command": "jaxfilters " + " ".join(DEMO_COMMAND), "robots": summary["config"]["robots"],
          "seconds": f["seconds"], "seed": summary["config"]["seed"], "scenario": summary["scenario"]["name"],
          "goals_reached": f["goals_reached"], "keepout_entries": f["keepout_entries"],
          "speed_compliant": f["speed_compliant"], "device": summary["timing"]["device"]}


def main(argv=None) -> int:
  """Checks the demo run, writes the copy; returns the exit code (2: not a `make demo` run)."""
  ap = ArgumentParser(prog="python -m sims.commands.readme_picture", description=__doc__.splitlines()[0],
                               epilog="exit codes: 0 ok, 2 the folder is not a `make demo` run")
  ap.add_argument("demo", type=Path, help="the demo's output folder (out/demo)")
  ap.add_argument("dest", type=Path, help="the README's picture (docs/demo.png)")
  args = ap.parse_args(argv)
  from PIL import Image
  from PIL.PngImagePlugin import PngInfo
  try:
    summary = json.loads((args.demo / "summary.json").read_text())
    image = Image.open(args.demo / "trajectories.png")
  except (OSError, ValueError) as e:
    print(f"readme_picture: error: {args.demo}: no demo output ({e}); run `make demo` first", file=sys.stderr)
    return 2
  text = picture_text(summary)
  want = demo_defaults()
  got = {k: text[k] for k in want}
  if got != want:
    print(f"readme_picture: error: {args.demo} is not a `make demo` run: {got} where the demo has {want}",
          file=sys.stderr)
    return 2
  info = PngInfo()
  info.add_text(TEXT_KEY, json.dumps(text, sort_keys=True))
  args.dest.parent.mkdir(parents=True, exist_ok=True)
  image.save(args.dest, pnginfo=info, optimize=True)
  print(f"wrote {args.dest}: {json.dumps(text, sort_keys=True)}")
  return 0


if __name__ == "__main__":
  sys.exit(main())
