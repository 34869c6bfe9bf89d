"""The `jaxfilters` command line.

    jaxfilters --version
    jaxfilters COMMAND --help

Commands come from two places: the library's own (`query`, `jaus`, listed in
`_BUILTIN`) and any installed package that registers a function under the
entry-point group `jaxfilters.commands` (the simulator registers `fleet` and
`bench` from `sims.cli`; the library never imports the simulator). Each
registered function receives argparse's subparsers object, adds its parser
and sets `func` (a callable `args -> int`) as a default; a command that passes
unknown options through to another program also sets `passthrough` to the name
of the attribute that receives them.

Exit codes, the same for every command:

  0  success
  1  internal error (a bug: one line on stderr; JAXFILTERS_DEBUG=1 shows the traceback)
  2  usage error: a bad option value, or an input file that is missing or invalid
  3  the run finished but a robot broke a rule (keepout entry or speed violation)
"""

from __future__ import annotations

import argparse
import importlib
import importlib.metadata
import os
import sys
import traceback

from jaxfilters import _xla_flags
from jaxfilters._version import __version__

ENTRY_POINT_GROUP = "jaxfilters.commands"
EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_USAGE = 2
EXIT_VIOLATION = 3

# name -> "module:function" of the library's own commands (registered in this order).
_BUILTIN: dict[str, str] = {
    "jaus": "jaxfilters.cli:register_jaus",
}


class CliError(Exception):
  """A usage error: a bad option value or input file. Printed as one line, exit code 2."""


class ArgumentParser(argparse.ArgumentParser):
  """argparse with one-line errors (no usage dump) and exit code 2."""

  def error(self, message: str):
    self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _registrars():
  """Yields (name, register function) for the built-in and the entry-point commands."""
  seen = set()
  for name, target in _BUILTIN.items():
    module, _, attr = target.partition(":")
    seen.add(name)
    yield name, getattr(importlib.import_module(module), attr)
  try:
    eps = importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)
  except Exception:  # noqa: BLE001 - broken metadata of another package must not break the CLI
    eps = ()
  for ep in sorted(eps, key=lambda e: e.name):
    if ep.name in seen:
      continue
    seen.add(ep.name)
    try:
      yield ep.name, ep.load()
    except Exception as e:  # noqa: BLE001
      print(f"jaxfilters: warning: command {ep.name!r} from {ep.value} could not be loaded "
            f"({type(e).__name__}: {e})", file=sys.stderr)


def build_parser() -> ArgumentParser:
  """The top-level parser with every registered command."""
  parser = ArgumentParser(prog="jaxfilters",
                          description="Nav2 costmap filters as batched JAX functions.",
                          epilog="exit codes: 0 ok, 1 internal error, 2 usage error (bad option or "
                          "input file), 3 a robot broke a rule")
  parser.add_argument("--version", action="version", version=f"jaxfilters {__version__}")
  sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND",
                              parser_class=ArgumentParser)
  for _, register in _registrars():
    register(sub)
  return parser


def main(argv=None) -> int:
  """Entry point of the `jaxfilters` console script; returns the exit code."""
  argv = list(sys.argv[1:] if argv is None else argv)
  _xla_flags.use_fast_cpu_compile()   # before any JAX backend starts
  parser = build_parser()
  args, extra = parser.parse_known_args(argv)
  if extra:
    if not getattr(args, "passthrough", None):
      parser.error(f"unrecognized arguments: {' '.join(extra)}")
    setattr(args, args.passthrough, list(getattr(args, args.passthrough, None) or []) + extra)
  try:
    return int(args.func(args) or 0)
  except CliError as e:
    print(f"jaxfilters {args.command}: error: {e}", file=sys.stderr)
    return EXIT_USAGE
  except KeyboardInterrupt:
    print(f"jaxfilters {args.command}: interrupted", file=sys.stderr)
    return 130
  except Exception as e:  # noqa: BLE001 - one line, not a traceback; the bug is still reported
    if os.environ.get("JAXFILTERS_DEBUG"):
      traceback.print_exc()
    msg = str(e).splitlines()[0] if str(e) else ""
    print(f"jaxfilters {args.command}: internal error: {type(e).__name__}: {msg[:300]} "
          "(set JAXFILTERS_DEBUG=1 for the traceback)", file=sys.stderr)
    return EXIT_INTERNAL


# --------------------------------------------------------------------------- jaus


def register_jaus(sub) -> None:
  """Adds `jaxfilters jaus encode|decode` (JAUS CostMap2D messages <-> Nav2 maps)."""
  p = sub.add_parser(
      "jaus", help="encode a Nav2 map as a JAUS ReportCostMap2D, or decode one to a map",
      description="Encode a Nav2 map (YAML + image) as one JAUS ReportCostMap2D message, or "
      "decode such a message to a map YAML and image. Bytes are the message from its uint16 "
      "message ID on, with no transport header; --hex reads/writes them as hex text.")
  jsub = p.add_subparsers(dest="jaus_command", required=True, metavar="{encode,decode}",
                          parser_class=ArgumentParser)
  enc = jsub.add_parser("encode", help="map YAML -> ReportCostMap2D bytes",
                        description="Encode a Nav2 map, or a window of it, as one ReportCostMap2D.")
  enc.add_argument("map", metavar="MAP.yaml", help="Nav2 map YAML (map_server format)")
  enc.add_argument("--out", required=True, metavar="F.bin", help="output message file")
  enc.add_argument("--variant", choices=("list", "confidence", "rle"), default="list",
                   help="data variant: cost list (lossless), cost + confidence (lossless), "
                   "run-length (3-bit costs) (default: list)")
  enc.add_argument("--profile", choices=("iop", "design"), default="iop",
                   help="iop: IDs 0xD742/0xD738 (published IOP CostMap2D); design: IDs "
                   "0x4C11/0x2C11 with uint32 sizes (default: iop)")
  enc.add_argument("--window", nargs=4, type=int, metavar=("COL", "ROW", "WIDTH", "HEIGHT"),
                   help="encode only this window of the map, in cells; (COL, ROW) is its "
                   "lower-left cell and row 0 is the lowest y, as in OccupancyGrid")
  enc.add_argument("--mapping", choices=("nav2", "fkie"), default="nav2",
                   help="occupancy -> cost: nav2 round(2.54 d) or fkie 2 d (default: nav2)")
  enc.add_argument("--axes", choices=("ros", "ned"), default="ros",
                   help="MapCenterX/Y and MapRotation as map x, y, yaw (ros, the fkie bridge) "
                   "or as north, east, clockwise (ned) (default: ros)")
  enc.add_argument("--hex", action="store_true", help="write hex text instead of raw bytes")
  enc.set_defaults(func=_run_jaus_encode)
  dec = jsub.add_parser("decode", help="ReportCostMap2D bytes -> map YAML + image",
                        description="Decode one ReportCostMap2D (either profile) to a Nav2 map "
                        "YAML and its image (written as map_saver does).")
  dec.add_argument("message", metavar="F.bin", help="message file (raw bytes, or hex with --hex)")
  dec.add_argument("--out", required=True, metavar="MAP.yaml",
                   help="output map YAML; the image is written beside it")
  dec.add_argument("--hex", action="store_true", help="read hex text instead of raw bytes")
  dec.add_argument("--mapping", choices=("nav2", "fkie"), default="nav2",
                   help="cost -> occupancy, as used to encode (default: nav2)")
  dec.add_argument("--axes", choices=("ros", "ned"), default="ros",
                   help="pose convention, as used to encode (default: ros)")
  dec.add_argument("--resolution", type=float, metavar="M",
                   help="metres per cell (default: the simplest value the message allows)")
  dec.add_argument("--mode", choices=("auto", "trinary", "raw", "scale"), default="auto",
                   help="map image mode; auto writes trinary when every cell is -1, 0 or 100 "
                   "and raw (lossless) otherwise (default: auto)")
  dec.set_defaults(func=_run_jaus_decode)


def _write_output(path: str, payload: bytes | str, flag: str = "--out") -> None:
  try:
    if isinstance(payload, str):
      with open(path, "w", encoding="ascii") as f:
        f.write(payload)
    else:
      with open(path, "wb") as f:
        f.write(payload)
  except OSError as e:
    raise CliError(f"{flag} {path}: cannot write ({e.strerror or e})") from None


def _run_jaus_encode(args) -> int:
  from jaxfilters import jaus, map_io

  try:
    grid = map_io.load_map(args.map)
  except (FileNotFoundError, ValueError) as e:
    raise CliError(f"MAP.yaml: {e}") from None
  try:
    report = jaus.grid_to_report(grid, window=args.window, profile=args.profile,
                                 variant=args.variant, mapping=args.mapping, axes=args.axes)
  except ValueError as e:
    where = "--window" if args.window is not None else args.map
    raise CliError(f"{where}: {e}") from None
  data = jaus.encode_report(report)
  _write_output(args.out, jaus.to_hex(data) if args.hex else data)
  prof = jaus.PROFILES[args.profile]
  print(f"wrote {args.out}: ReportCostMap2D 0x{prof.report_id:04X} ({args.profile}), "
        f"{args.variant}, {report.rows} rows x {report.cols} columns, {len(data)} bytes")
  return EXIT_OK


def _run_jaus_decode(args) -> int:
  import numpy as np

  from jaxfilters import jaus, map_io

  try:
    with open(args.message, "rb") as f:
      raw = f.read()
  except OSError as e:
    raise CliError(f"F.bin {args.message}: cannot read ({e.strerror or e})") from None
  if args.hex:
    try:
      raw = jaus.from_hex(raw.decode("ascii"))
    except (UnicodeDecodeError, ValueError) as e:
      raise CliError(f"{args.message}: not hex text ({e}); drop --hex for raw bytes") from None
  try:
    msg = jaus.decode(raw)
  except jaus.JausDecodeError as e:
    hint = ""
    if not args.hex and raw and all(chr(b) in "0123456789abcdefABCDEF \t\r\n" for b in raw):
      hint = " (the file looks like hex text: add --hex)"
    raise CliError(f"{args.message}: {e}{hint}") from None
  if not isinstance(msg, jaus.CostMap2DReport):
    raise CliError(f"{args.message}: is a QueryCostMap2D (profile {msg.profile}); decode "
                   "expects a ReportCostMap2D")
  try:
    grid = jaus.report_to_grid(msg, mapping=args.mapping, axes=args.axes,
                               resolution=args.resolution)
  except ValueError as e:
    raise CliError(f"{args.message}: {e}") from None
  mode = args.mode
  if mode == "auto":
    mode = "trinary" if set(np.unique(grid.data).tolist()) <= {-1, 0, 100} else "raw"
  try:
    yaml_path, image_path = map_io.save_map(grid, args.out, mode=mode)
  except ValueError as e:
    raise CliError(f"--out {args.out}: {e}") from None
  except OSError as e:
    raise CliError(f"--out {args.out}: cannot write ({e.strerror or e})") from None
  print(f"wrote {yaml_path} and {image_path}: {grid.height} rows x {grid.width} columns, "
        f"resolution {grid.resolution:g} m, origin ({grid.origin[0]:g}, {grid.origin[1]:g}, "
        f"{grid.origin[2]:g}), mode {mode}")
  return EXIT_OK


if __name__ == "__main__":
  # Through the imported module, so `python -m jaxfilters.cli` and the console script share one
  # CliError class with the commands registered as "jaxfilters.cli:...".
  from jaxfilters import cli as _cli
  sys.exit(_cli.main())
