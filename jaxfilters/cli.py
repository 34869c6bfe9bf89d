"""The `jaxfilters` command line.

    jaxfilters --version
    jaxfilters COMMAND --help

Commands come from two places: the library's own (`query`, `jaus`, listed in
`_BUILTIN`) and any installed package that registers a function under the
entry-point group `jaxfilters.commands` (the simulator registers `fleet` and
`bench` from `sims/commands`; the library never imports the simulator). Each
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
import re
import sys
import traceback

from jaxfilters import compile_cache
from jaxfilters._version import __version__

ENTRY_POINT_GROUP = "jaxfilters.commands"
EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_USAGE = 2
EXIT_VIOLATION = 3

# name -> "module:function" of the library's own commands (registered in this order).
_BUILTIN: dict[str, str] = {
    "query": "jaxfilters.cli:register_query",
    "jaus": "jaxfilters.jaus.cli:register",
}


class CliError(Exception):
  """A usage error: a bad option value or input file. Printed as one line, exit code 2."""


class ArgumentParser(argparse.ArgumentParser):
  """argparse with one-line errors (no usage dump) and exit code 2."""

  def error(self, message: str):
    """Prints one line naming the problem and exits with EXIT_USAGE (argparse's hook)."""
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
  _add_no_cache(parser)
  return parser


NO_CACHE_HELP = ("do not use the persistent XLA compilation cache (default: on, in ~/.cache/jaxfilters/xla; "
                 "JAXFILTERS_NO_CACHE=1 also turns it off, JAXFILTERS_CACHE_DIR moves it)")


def _add_no_cache(parser: argparse.ArgumentParser) -> None:
  """Gives every command's parser (nested ones too) the `--no-cache` option, unless it has its own."""
  for action in parser._actions:   # noqa: SLF001 - argparse keeps subparsers only here
    if isinstance(action, argparse._SubParsersAction):   # noqa: SLF001
      for child in action.choices.values():
        has_sub = any(isinstance(a, argparse._SubParsersAction) for a in child._actions)   # noqa: SLF001
        if has_sub:
          _add_no_cache(child)
        elif "--no-cache" not in child._option_string_actions:   # noqa: SLF001
          child.add_argument("--no-cache", action="store_true", help=NO_CACHE_HELP)


def main(argv=None) -> int:
  """Entry point of the `jaxfilters` console script; returns the exit code."""
  argv = list(sys.argv[1:] if argv is None else argv)
  parser = build_parser()
  try:
    args, extra = parser.parse_known_args(argv)
    if extra:
      if not getattr(args, "passthrough", None):
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
      setattr(args, args.passthrough, list(getattr(args, args.passthrough, None) or []) + extra)
  except SystemExit as e:          # --help, --version (0) and argparse usage errors (2)
    return int(e.code or 0) if not isinstance(e.code, str) else EXIT_USAGE
  compile_cache.enable(disable=bool(getattr(args, "no_cache", False)))
  try:
    return int(args.func(args) or 0)
  except CliError as e:
    text = "; ".join(line.strip() for line in str(e).splitlines() if line.strip())
    print(f"jaxfilters {args.command}: error: {text[:500]}", file=sys.stderr)
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


# --------------------------------------------------------------------------- options shared by commands

# The speed mask's CostmapFilterInfo when a command is given a mask file instead of a params file:
# the values Nav2's bringup and system tests give their speed masks (docs/nav2_semantics.md §8.5),
# limit = 100 - d percent. `query --speed` and `fleet --speed` both use them.
SPEED_TYPE_DEFAULT = 1
SPEED_BASE_DEFAULT = 100.0
SPEED_MULTIPLIER_DEFAULT = -1.0

# Pose files are read whole: a regular file of at most this many bytes (about 250,000 poses),
# which parses in seconds and a few hundred MB.
MAX_POSES_BYTES = 4 * 2 ** 20

EXIT_CODES_EPILOG = ("exit codes: 0 ok, 1 internal error (a bug; JAXFILTERS_DEBUG=1 shows the traceback), "
                     "2 bad option or input file (one line on stderr, nothing run)")


def add_params_options(parser, *, transform: bool = False):
  """Adds --params, --costmap, --mask and --set (and --transform) as an option group.

  `query` and `fleet` read a Nav2 params file through these options and
  `params_costmap`, so both accept the same spelling.

  Args:
    parser: an argparse parser.
    transform: also add --transform X,Y,YAW (masks in another frame than the costmap).

  Returns:
    The argument group (for more options).
  """
  g = parser.add_argument_group("filters from a Nav2 params file")
  g.add_argument("--params", metavar="P.yaml", help="a nav2_params.yaml")
  g.add_argument("--costmap", choices=("global_costmap", "local_costmap"),
                 help="which costmap's filters (default global_costmap)")
  g.add_argument("--mask", action="append", default=[], metavar="NODE=MAP.yaml",
                 help="the map YAML a filter mask server serves (its yaml_filename); repeatable")
  g.add_argument("--set", action="append", default=[], dest="substitutions", metavar="PLACEHOLDER=VALUE",
                 help="resolve a launch placeholder such as KEEPOUT_ZONE_ENABLED=True; repeatable")
  if transform:
    g.add_argument("--transform", metavar="X,Y,YAW",
                   help="pose of the costmap's global_frame in the masks' frame (Nav2 takes it from TF), "
                   "needed when they differ, e.g. local_costmap in odom with masks in map")
  return g


def add_speed_options(group) -> None:
  """Adds --speed-type, --speed-base and --speed-multiplier (the speed mask's CostmapFilterInfo).

  They apply to a mask given with --speed; `speed_info` reads them with the
  shared defaults (type 1, base 100, multiplier -1).
  """
  group.add_argument("--speed-type", metavar="1|2",
                     help=f"1 percent, 2 m/s (default {SPEED_TYPE_DEFAULT})")
  group.add_argument("--speed-base", metavar="B",
                     help=f"limit = mask value * multiplier + base (default {SPEED_BASE_DEFAULT:g})")
  group.add_argument("--speed-multiplier", metavar="K", help=f"(default {SPEED_MULTIPLIER_DEFAULT:g})")


def number_option(option: str, text: str) -> float:
  """A number option's value, usable as float32 on the device, or CliError naming the option."""
  from jaxfilters import validate
  try:
    value = float(text)
  except ValueError:
    raise CliError(f"{option} must be a number; got {validate.short_repr(text)}") from None
  try:
    validate.float32_values(value, option)
  except ValueError as e:
    raise CliError(str(e)) from None
  return value


_INT_TEXT = re.compile(r"-?[0-9]+", re.ASCII)
_INT_MAX_DIGITS = 30


def strict_int(text: str) -> int:
  """An integer written plainly: ASCII digits with an optional leading '-', nothing else.

  Python's int() also reads '6_4' (64), ' 2 ', '+2' and non-ASCII digits such as
  full-width '２'; an option value is taken only as the user would read it. At
  most 30 digits (every bounded option lies far below).

  Raises:
    ValueError: any other text (the message says what is expected).
  """
  if not isinstance(text, str) or not _INT_TEXT.fullmatch(text):
    from jaxfilters import validate
    raise ValueError(f"invalid int value: {validate.short_repr(text)} (expected ASCII digits with an "
                     "optional leading '-', such as 64)")
  if len(text.lstrip("-")) > _INT_MAX_DIGITS:
    raise ValueError(f"out of range: {text[:12]}... has {len(text.lstrip('-'))} digits (at most "
                     f"{_INT_MAX_DIGITS})")
  return int(text)


def int_type(low: int | None = None, high: int | None = None):
  """An argparse `type` for an integer option: `strict_int`, then low <= value <= high (None: no bound).

  A refused value is argparse's one-line usage error, exit 2: "argument --x:
  invalid int value: '6_4' (...)" or "argument --x: must lie in [1, 1024]; got 4096".
  """
  def parse(text):
    try:
      value = strict_int(text)
    except ValueError as e:
      raise argparse.ArgumentTypeError(str(e)) from None
    if (low is not None and value < low) or (high is not None and value > high):
      if high is None:
        raise argparse.ArgumentTypeError(f"must be >= {low}; got {value}")
      if low is None:
        raise argparse.ArgumentTypeError(f"must be <= {high:,d}; got {value}")
      raise argparse.ArgumentTypeError(f"must lie in [{low:,d}, {high:,d}]; got {value}")
    return value
  parse.__name__ = "int"
  parse.low, parse.high = low, high      # read by tests and the fuzz harness
  return parse


def path_type(text: str):
  """An argparse `type` for a path option: a non-empty path (''' is refused, not read as '.')."""
  from pathlib import Path
  if not isinstance(text, str) or not text.strip():
    raise argparse.ArgumentTypeError(f"must name a path; got {text!r}")
  if "\x00" in text:
    raise argparse.ArgumentTypeError("must not contain a NUL character")
  return Path(text)


def given_speed_options(args) -> list[str]:
  """The speed options given on the command line, by name."""
  return [o for o, v in (("--speed-type", args.speed_type), ("--speed-base", args.speed_base),
                         ("--speed-multiplier", args.speed_multiplier)) if v is not None]


def speed_info(args) -> tuple[int, float, float]:
  """(type, base, multiplier) of --speed-type/--speed-base/--speed-multiplier with the shared defaults.

  Raises:
    CliError: a type other than 1 or 2, a value that is not a float32 number, or a
      base and multiplier whose limit d * multiplier + base overflows float32 for
      some mask value d (FilterInfo.create's check).
  """
  from jaxfilters.types import FilterInfo
  ftype = SPEED_TYPE_DEFAULT if args.speed_type is None else str(args.speed_type).strip()
  if ftype not in (1, "1", "2"):
    raise CliError(f"--speed-type must be 1 (percent) or 2 (m/s); got {args.speed_type!r}")
  base = SPEED_BASE_DEFAULT if args.speed_base is None else number_option("--speed-base", args.speed_base)
  mult = (SPEED_MULTIPLIER_DEFAULT if args.speed_multiplier is None
          else number_option("--speed-multiplier", args.speed_multiplier))
  try:
    FilterInfo.create(int(ftype), base, mult)
  except ValueError as e:
    raise CliError(f"--speed-base/--speed-multiplier: {str(e).splitlines()[0]}") from None
  return int(ftype), base, mult


def name_value_pairs(option: str, items: list[str]) -> dict[str, str]:
  """NAME=VALUE items of a repeatable option -> dict, or CliError (empty part, a name twice)."""
  out = {}
  for item in items:
    key, sep, value = item.partition("=")
    if not sep or not key.strip() or not value.strip():
      raise CliError(f"{option} must be NAME=VALUE with both parts non-empty; got {item!r}")
    if key.strip() in out:
      raise CliError(f"{option} gives {key.strip()!r} twice")
    out[key.strip()] = value.strip()
  return out


def check_params_options(args) -> None:
  """Without --params, refuses --costmap, --mask, --set (and --transform): they would be ignored."""
  if args.params is not None:
    return
  for option, value in (("--costmap", args.costmap), ("--mask", args.mask), ("--set", args.substitutions),
                        ("--transform", getattr(args, "transform", None))):
    if value:
      raise CliError(f"{option} needs --params")


def params_costmap(args, command: str, *, also: tuple[str, ...] = ()):
  """The Nav2Costmap that --params/--costmap/--mask/--set name; warnings go to stderr as one line each.

  Args:
    args: the namespace of a parser that `add_params_options` filled.
    command: the command's name, for the warning lines.
    also: other costmaps to load with it (e.g. ("local_costmap",) for its
      layers); their problems are refused alike.

  Returns:
    `jaxfilters.Nav2Costmap` of the chosen costmap (at least one filter), or
    with `also` the pair (that costmap, `jaxfilters.Nav2Params` of all loaded).

  Raises:
    CliError: a bad pair, a params file that does not load, or no filters.
  """
  import warnings

  from jaxfilters import nav2
  name = args.costmap or "global_costmap"
  masks = name_value_pairs("--mask", args.mask)
  subs = name_value_pairs("--set", args.substitutions)
  names = tuple(dict.fromkeys((name, *also)))
  with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always", nav2.Nav2ParamsWarning)
    try:
      params = nav2.load_params(args.params, masks=masks, substitutions=subs, costmaps=names)
    except (ValueError, FileNotFoundError) as e:
      raise CliError(str(e).splitlines()[0] if str(e) else type(e).__name__) from None
  for w in caught:
    print(f"jaxfilters {command}: warning: {str(w.message).splitlines()[0]}", file=sys.stderr)
  if getattr(params, name) is None:
    raise CliError(f"--params {args.params}: no {name} node (expected e.g. '{name}: {name}: ros__parameters:')")
  costmap = params.costmap(name)
  if not costmap.filters:
    raise CliError(f"--params {args.params}: {name} has no costmap filters (its 'filters:' list is empty)")
  return (costmap, params) if also else costmap


def prepare_out(out, option: str = "--out"):
  """Creates an output folder and proves it writable before a command does its work.

  Args:
    out: pathlib.Path of the folder (created with its parents).
    option: the option that named it, for the message.

  Returns:
    `out`.

  Raises:
    CliError: the folder cannot be created or written.
  """
  try:
    out.mkdir(parents=True, exist_ok=True)
    probe = out / ".jaxfilters_write_test"
    probe.write_text("ok")
    probe.unlink()
  except OSError as e:
    raise CliError(f"{option} {out}: cannot write there ({e.strerror or e})") from None
  return out


def check_creatable(out, option: str = "--out") -> None:
  """Proves, creating nothing that stays, that a folder can be made (or written) at `out`.

  The nearest existing folder on the way is checked by making and removing a
  probe folder in it, so a read-only place, /proc or a file in the way is refused
  before a command does its work; `prepare_out` creates the folder afterwards.

  Raises:
    CliError: `out` or a parent on its way is not a folder, or nothing can be created there.
  """
  import tempfile
  from pathlib import Path
  try:
    target = Path(out).absolute()
    while not target.exists() and not target.is_symlink():
      target = target.parent
    if not target.is_dir():
      raise CliError(f"{option} {out}: {target} is not a folder")
    os.rmdir(tempfile.mkdtemp(prefix=".jaxfilters_probe_", dir=target))
  except OSError as e:
    raise CliError(f"{option} {out}: cannot create a folder in {target} ({e.strerror or e})") from None
  except ValueError as e:       # an embedded NUL
    raise CliError(f"{option} {out!r}: not a usable path ({e})") from None


def read_text_file(path: str, option: str, *, max_bytes: int) -> str:
  """The UTF-8 text of a regular file of at most `max_bytes`, or CliError naming `option` and the file.

  The file is opened without blocking and checked with fstat before anything
  is read, so a FIFO, a device (/dev/zero) or a directory is refused at once.
  """
  import stat
  try:
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
  except FileNotFoundError:
    raise CliError(f"{option} {path}: file does not exist") from None
  except (OSError, ValueError) as e:
    raise CliError(f"{option} {path}: cannot read it ({getattr(e, 'strerror', None) or e})") from None
  try:
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode):
      raise CliError(f"{option} {path}: not a regular file (a FIFO, device or directory is refused)")
    if st.st_size > max_bytes:
      raise CliError(f"{option} {path}: {st.st_size} bytes; at most {max_bytes} are read")
    chunks, size = [], 0
    while size <= max_bytes:
      chunk = os.read(fd, min(1 << 20, max_bytes + 1 - size))
      if not chunk:
        break
      chunks.append(chunk)
      size += len(chunk)
  except OSError as e:
    raise CliError(f"{option} {path}: cannot read it ({e.strerror or e})") from None
  finally:
    os.close(fd)
  if size > max_bytes:
    raise CliError(f"{option} {path}: more than {max_bytes} bytes; at most {max_bytes} are read")
  try:
    return b"".join(chunks).decode("utf-8")
  except UnicodeDecodeError as e:
    raise CliError(f"{option} {path}: not UTF-8 text (byte {e.start})") from None


def read_poses(path: str, *, max_bytes: int = MAX_POSES_BYTES):
  """Reads a pose file: CSV rows x,y or x,y,yaw (m, rad), an optional header line, blank lines skipped.

  Args:
    path: the file (a regular file of at most `max_bytes`, UTF-8).
    max_bytes: the size cap.

  Returns:
    (poses float32 [B, 3] (yaw 0 where absent), line numbers [B], echoed (x, y) as parsed floats).

  Raises:
    CliError: the only error, one line naming the file and the line (the CLI's exit 2):
      not a regular file, too large, not UTF-8, not CSV, a wrong column count, a field
      that is not a number or not finite in float32, or no poses.
  """
  import csv

  import numpy as np

  from jaxfilters import validate
  text = read_text_file(path, "--poses", max_bytes=max_bytes)
  poses, lines, echo = [], [], []
  reader = csv.reader(text.splitlines())
  while True:
    try:
      fields = next(reader)
    except StopIteration:
      break
    except csv.Error as e:
      raise CliError(f"{path} line {reader.line_num}: not CSV ({e})") from None
    line = reader.line_num
    fields = [v.strip() for v in fields]
    if not any(fields):
      continue
    numbers = []
    for v in fields:
      try:
        numbers.append(float(v))
      except ValueError:
        numbers.append(None)
    if line == 1 and all(n is None for n in numbers):
      continue  # header
    if len(fields) not in (2, 3):
      raise CliError(f"{path} line {line}: expected x,y or x,y,yaw (2 or 3 numbers); "
                     f"got {len(fields)} field{'s' if len(fields) != 1 else ''}")
    if None in numbers:
      bad = fields[numbers.index(None)]
      raise CliError(f"{path} line {line}: {validate.short_repr(bad)} is not a number")
    poses.append(numbers + [0.0] * (3 - len(numbers)))
    lines.append(line)
    echo.append((numbers[0], numbers[1]))
  if not poses:
    raise CliError(f"--poses {path}: no poses (expected rows x,y or x,y,yaw)")
  values = np.asarray(poses, np.float64)
  # One vectorised check; the first row it refuses is checked again alone for validate's message.
  with np.errstate(over="ignore", invalid="ignore"):
    f32 = values.astype(np.float32)
  bad = ~np.isfinite(f32) | ((f32 != 0) & (np.abs(f32) < validate.F32_TINY))
  for i in np.flatnonzero(bad.any(axis=1))[:1]:
    try:
      validate.float32_values(values[i, :len(poses[i])], "x,y,yaw", owner=f"{path} line {lines[i]}")
    except ValueError as e:
      raise CliError(str(e)) from None
  return f32, lines, echo


# --------------------------------------------------------------------------- query

_QUERY_EPILOG = f"""\
examples:
  jaxfilters query --params nav2_params.yaml \\
      --mask keepout_filter_mask_server=warehouse_keepout.yaml \\
      --mask speed_filter_mask_server=warehouse_speed.yaml \\
      --set KEEPOUT_ZONE_ENABLED=True --set SPEED_ZONE_ENABLED=True --poses poses.csv
  jaxfilters query --params sims/assets/nav2_params.yaml --poses poses.csv
  jaxfilters query --speed warehouse_speed.yaml --speed-base 0 --speed-multiplier 1 --poses poses.csv

poses.csv holds rows x,y or x,y,yaw (a header line is allowed), e.g.
  x,y,yaw
  1.5,-2.0,0.0

Each pose is a fresh robot's first filter cycle, as Nav2's filters run it: an unknown cell, a cell off
the mask and a computed limit of 0 all give speed_limit null (no limit). A filter that is absent or
disabled gives null. Poses are rounded to float32 like every pose in jaxfilters. The pose file must be a
regular UTF-8 file of at most {MAX_POSES_BYTES >> 20} MiB. A speed mask given with --speed uses type
{SPEED_TYPE_DEFAULT}, base {SPEED_BASE_DEFAULT:g} and multiplier {SPEED_MULTIPLIER_DEFAULT:g} unless told
(the values Nav2's bringup gives its speed masks; `jaxfilters fleet --speed` uses the same). Write a value
that starts with '-' as --transform=-1,2,0.

{EXIT_CODES_EPILOG}"""


def register_query(sub) -> None:
  """Adds `jaxfilters query`: what the costmap filters say at given poses, as JSON lines."""
  p = sub.add_parser(
      "query", help="speed limit, keepout cost, binary state and zone at poses (JSON lines)",
      description="Prints one JSON object per pose, in order, with keys x, y, speed_limit (a number, or\n"
      "null for no limit), speed_limit_type (percent / absolute), keepout_cost (0..255, the cost of the\n"
      "keepout mask under the pose; 255 off the mask or on an unknown cell), binary_state and zone.",
      epilog=_QUERY_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument("--poses", required=True, metavar="F.csv",
                 help="rows x,y or x,y,yaw in the costmap's global frame (m, rad); a header line is allowed")
  add_params_options(p, transform=True)
  m = p.add_argument_group("filters from mask files (instead of --params), with Nav2's default parameters")
  m.add_argument("--keepout", metavar="M.yaml", help="keepout mask (type 0)")
  m.add_argument("--speed", metavar="M.yaml", help="speed mask")
  add_speed_options(m)
  m.add_argument("--binary", metavar="M.yaml", help="binary mask (type 3, flip_threshold 50, default_state false)")
  m.add_argument("--zone", metavar="M.yaml", help="zone mask (type 4; every id 1..127 is a zone)")
  p.set_defaults(func=run_query)


def _query_costmap_from_params(args):
  costmap = params_costmap(args, "query")
  name = costmap.name
  for f in costmap.filters:
    if not f.enabled:
      print(f"jaxfilters query: warning: {name} filter '{f.name}' is disabled (enabled: false); "
            "its columns are null", file=sys.stderr)
  return costmap


def _query_costmap_from_masks(args):
  from jaxfilters import nav2, validate
  from jaxfilters.map_io import load_map
  from jaxfilters.types import FilterInfo, FilterMask

  def mask(option, path, info):
    try:
      grid = load_map(path)
      validate.resolution_value(grid.resolution, owner=f"{option} {path}")
      validate.float32_values(grid.origin[:2], "origin", owner=f"{option} {path}")
      return FilterMask.create(grid, info)
    except (ValueError, FileNotFoundError) as e:
      raise CliError(f"{option}: {str(e).splitlines()[0]}") from None

  masks = {}
  if args.keepout:
    masks["keepout"] = mask("--keepout", args.keepout, FilterInfo.create(0))
  if args.speed:
    masks["speed"] = mask("--speed", args.speed, FilterInfo.create(*speed_info(args)))
  if args.binary:
    masks["binary"] = mask("--binary", args.binary, FilterInfo.create(3))
  if args.zone:
    masks["zone"] = mask("--zone", args.zone, FilterInfo.create(4))
  return nav2.Nav2Costmap.from_masks(**masks)


def _query_zone_id(f, x: float, y: float) -> int:
  """The zone mask value under (x, y), for an error message (host float64 of the float32 values)."""
  import math

  import numpy as np
  data = np.asarray(f.mask.data[0])
  ox, oy = (float(v) for v in np.asarray(f.mask.origin[0]))
  res = float(np.asarray(f.mask.resolution[0]))
  mx, my = math.floor((float(np.float32(x)) - ox) / res), math.floor((float(np.float32(y)) - oy) / res)
  return int(data[min(max(my, 0), data.shape[0] - 1), min(max(mx, 0), data.shape[1] - 1)])


def run_query(args) -> int:
  """`jaxfilters query`: validates the options, evaluates every pose in one jitted call, prints JSON lines."""
  import json

  import numpy as np

  direct = [o for o in ("keepout", "speed", "binary", "zone") if getattr(args, o)]
  if args.params is not None and direct:
    raise CliError(f"--{direct[0]} cannot be combined with --params (the params file names the masks; "
                   "give a mask server's file with --mask NODE=MAP.yaml)")
  if args.params is None and not direct:
    raise CliError("give --params P.yaml, or mask files with --keepout/--speed/--binary/--zone")
  check_params_options(args)
  speed_opts = given_speed_options(args)
  if speed_opts and not args.speed:
    raise CliError(f"{speed_opts[0]} needs --speed M.yaml")
  if args.speed:
    speed_info(args)                     # bad values are refused before any file is read
  transform = None
  if args.transform is not None:
    parts = args.transform.split(",")
    if len(parts) != 3:
      raise CliError(f"--transform must be X,Y,YAW (3 numbers); got {args.transform!r}")
    transform = [number_option("--transform", v) for v in parts]
  poses, lines, echo = read_poses(args.poses)

  costmap = _query_costmap_from_params(args) if args.params is not None else _query_costmap_from_masks(args)
  foreign = costmap.foreign_frames()
  if foreign and transform is None:
    raise CliError(f"--costmap {costmap.name}: its global_frame is {costmap.global_frame!r} but masks are in "
                   f"{foreign[0]!r}; Nav2 takes that transform from TF at run time: give --transform X,Y,YAW "
                   f"(the pose of {costmap.global_frame!r} in {foreign[0]!r})")
  if transform is not None and not foreign:
    raise CliError(f"--transform: every enabled mask of {costmap.name} is in its global_frame "
                   f"{costmap.global_frame!r}; --transform is only for masks in another frame")
  try:
    out = costmap.readout(poses, transform=transform)
  except ValueError as e:
    raise CliError(str(e).splitlines()[0]) from None

  speed, zone = costmap.speed, costmap.zone
  if out.zone is not None:
    bad = np.nonzero(np.asarray(out.zone.error))[0]
    if bad.size:
      i = int(bad[0])
      configured = [s.id for s in zone.states]
      raise CliError(f"{args.poses} line {lines[i]}: the zone mask gives zone id "
                     f"{_query_zone_id(zone, *echo[i])} there, which '{zone.name}' does not configure "
                     f"(configured ids: {configured or 'none'}); Nav2 throws on it "
                     f"({bad.size} pose(s) affected)")
  cols = {}
  if out.speed is not None and speed.percentage is not None:
    limit = np.asarray(out.speed.speed_limit)
    valid = np.asarray(out.speed.valid) & (limit != 0)
    cols["speed_limit"] = [float(str(np.float32(v))) if ok else None for v, ok in zip(limit, valid)]
    cols["speed_limit_type"] = ["percent" if speed.percentage else "absolute"] * len(lines)
  if out.keepout_cost is not None:
    cols["keepout_cost"] = [int(v) for v in np.asarray(out.keepout_cost)]
  if out.binary is not None:
    cols["binary_state"] = [bool(v) for v in np.asarray(out.binary.binary_state)]
  if out.zone is not None:
    cols["zone"] = [int(v) for v in np.asarray(out.zone.zone)]
  rows = []
  for i, (x, y) in enumerate(echo):
    row = {"x": x, "y": y}
    for key in ("speed_limit", "speed_limit_type", "keepout_cost", "binary_state", "zone"):
      row[key] = cols[key][i] if key in cols else None
    rows.append(json.dumps(row))
  sys.stdout.write("\n".join(rows) + "\n")
  return EXIT_OK


if __name__ == "__main__":
  # `python -m jaxfilters.cli` runs this file as `__main__`, a second copy of the module whose
  # CliError is not the jaxfilters.cli.CliError commands raise: run the imported module's main.
  from jaxfilters import cli as _cli
  sys.exit(_cli.main())
