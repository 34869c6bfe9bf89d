"""`jaxfilters jaus encode|decode`: Nav2 maps <-> JAUS ReportCostMap2D message files.

A message file holds one ReportCostMap2D, or the tiles of a map larger than
one message back to back (docs/jaus.md §12), from each message's uint16 ID on
with no transport header; `--hex` reads and writes them as hex text. Every bad
input (a missing, non-regular or oversized file, a bad --window, a map that
cannot be sent) is one line on stderr and exit code 2, before anything is
written.
"""

from __future__ import annotations

import os
import stat

from jaxfilters.cli import EXIT_OK, ArgumentParser, CliError, int_type


def register(sub) -> None:
  """Adds `jaxfilters jaus encode|decode` to the `jaxfilters` subparsers `sub`."""
  p = sub.add_parser(
      "jaus", help="encode a Nav2 map as JAUS ReportCostMap2D messages, or decode them to a map",
      description="Encode a Nav2 map (YAML + image) as JAUS ReportCostMap2D messages, or decode "
      "such messages to a map YAML and image. A map larger than one message (65535 cells in a "
      "list) is split into tiles, written back to back in one file; decode puts them together. "
      "Bytes are the messages from their uint16 message ID on, with no transport header; --hex "
      "reads/writes them as hex text.")
  jsub = p.add_subparsers(dest="jaus_command", required=True, metavar="{encode,decode}",
                          parser_class=ArgumentParser)
  enc = jsub.add_parser(
      "encode", help="map YAML -> ReportCostMap2D message file",
      description="Encode a Nav2 map, or a window of it, as ReportCostMap2D messages: one when "
      "it fits, otherwise tiles (each a complete message with its own centre).",
      epilog="examples: jaxfilters jaus encode sims/assets/default_keepout.yaml --out map.bin; "
      "... --variant rle --lossy (3-bit costs); ... --window 0 0 200 160 --single. "
      "exit codes: 0 ok, 2 bad option or input file")
  enc.add_argument("map", metavar="MAP.yaml", help="Nav2 map YAML (map_server format)")
  enc.add_argument("--out", required=True, metavar="F.bin", help="output message file")
  enc.add_argument("--variant", choices=("list", "confidence", "rle"), default="list",
                   help="data variant: cost list (lossless), cost + confidence (lossless), "
                   "run-length (3-bit costs: needs --lossy unless every cost survives) "
                   "(default: list)")
  enc.add_argument("--lossy", action="store_true",
                   help="let --variant rle quantise costs to its 8 levels")
  enc.add_argument("--profile", choices=("iop", "design"), default="iop",
                   help="iop: IDs 0xD742/0xD738 (published IOP CostMap2D); design: IDs "
                   "0x4C11/0x2C11 with uint32 sizes (default: iop)")
  enc.add_argument("--window", nargs=4, type=int_type(), metavar=("COL", "ROW", "WIDTH", "HEIGHT"),
                   help="encode only this window of the map, in cells; (COL, ROW) is its "
                   "lower-left cell and row 0 is the lowest y, as in OccupancyGrid")
  enc.add_argument("--single", action="store_true",
                   help="refuse a map that needs more than one message instead of tiling it")
  enc.add_argument("--mapping", choices=("nav2", "fkie"), default="nav2",
                   help="occupancy -> cost: nav2 round(2.54 d) or fkie 2 d (default: nav2)")
  enc.add_argument("--axes", choices=("ros", "ned"), default="ros",
                   help="MapCenterX/Y and MapRotation as map x, y, yaw (ros, the fkie bridge) "
                   "or as north, east, clockwise (ned) (default: ros)")
  enc.add_argument("--hex", action="store_true", help="write hex text instead of raw bytes")
  enc.set_defaults(func=run_encode)
  dec = jsub.add_parser(
      "decode", help="ReportCostMap2D message file -> map YAML + image",
      description="Decode a file of ReportCostMap2D messages (either profile; one message or "
      "the tiles of one map) to a Nav2 map YAML and its image (written as map_saver does).",
      epilog="example: jaxfilters jaus decode map.bin --out decoded.yaml. "
      "exit codes: 0 ok, 2 bad option or input file")
  dec.add_argument("message", metavar="F.bin", help="message file (raw bytes, or hex with --hex)")
  dec.add_argument("--out", required=True, metavar="MAP.yaml",
                   help="output map YAML; the image is written beside it")
  dec.add_argument("--hex", action="store_true", help="read hex text instead of raw bytes")
  dec.add_argument("--mapping", choices=("nav2", "fkie"), default="nav2",
                   help="cost -> occupancy, as used to encode (default: nav2)")
  dec.add_argument("--axes", choices=("ros", "ned"), default="ros",
                   help="pose convention, as used to encode (default: ros)")
  dec.add_argument("--resolution", type=float, metavar="M",
                   help="metres per cell (default: the simplest value the messages allow)")
  dec.add_argument("--mode", choices=("auto", "trinary", "raw", "scale"), default="auto",
                   help="map image mode; auto writes trinary when every cell is -1, 0 or 100 "
                   "and raw (lossless) otherwise (default: auto)")
  dec.set_defaults(func=run_decode)


def _check_out(path: str, flag: str = "--out") -> None:
  """Refuses an output path that exists and is not a regular file (a FIFO would block)."""
  try:
    st = os.stat(path)
  except OSError:
    return
  if not stat.S_ISREG(st.st_mode):
    kind = "a directory" if stat.S_ISDIR(st.st_mode) else "not a regular file"
    raise CliError(f"{flag} {path}: is {kind}; give a file name")


def _write_output(path: str, payload: bytes | str, flag: str = "--out") -> None:
  _check_out(path, flag)
  try:
    if isinstance(payload, str):
      with open(path, "w", encoding="ascii") as f:
        f.write(payload)
    else:
      with open(path, "wb") as f:
        f.write(payload)
  except OSError as e:
    raise CliError(f"{flag} {path}: cannot write ({e.strerror or e})") from None


def run_encode(args) -> int:
  """`jaxfilters jaus encode`: returns the exit code (CliError for bad input)."""
  from jaxfilters import jaus, map_io

  try:
    grid = map_io.load_map(args.map)
  except (FileNotFoundError, ValueError) as e:
    raise CliError(f"MAP.yaml: {e}") from None
  _check_out(args.out)
  try:
    tiles = jaus.grid_to_reports(grid, window=args.window, profile=args.profile,
                                 variant=args.variant, mapping=args.mapping, axes=args.axes,
                                 tiles=not args.single, lossy=args.lossy)
  except ValueError as e:
    where = "--window" if args.window is not None else args.map
    text = str(e).replace("pass lossy=True (CLI: --lossy)", "pass --lossy")
    raise CliError(f"{where}: {text}") from None
  data = b"".join(jaus.encode_report(t.report) for t in tiles)
  _write_output(args.out, jaus.to_hex(data) if args.hex else data)
  prof = jaus.PROFILES[args.profile]
  cells = sum(t.report.rows * t.report.cols for t in tiles)
  what = ("1 message" if len(tiles) == 1 else
          f"{len(tiles)} messages (tiles, back to back; the map needs more than one)")
  print(f"wrote {args.out}: ReportCostMap2D 0x{prof.report_id:04X} ({args.profile}), "
        f"{args.variant}, {what}, {grid.width if args.window is None else args.window[2]} x "
        f"{grid.height if args.window is None else args.window[3]} cells ({cells} in all), "
        f"{len(data)} bytes" + (", costs quantised to 3-bit levels" if args.variant == "rle"
                                else ""))
  return EXIT_OK


def run_decode(args) -> int:
  """`jaxfilters jaus decode`: returns the exit code (CliError for bad input)."""
  import numpy as np

  from jaxfilters import jaus, map_io

  try:
    msgs = jaus.load_messages(args.message, hex=args.hex)
  except jaus.JausDecodeError as e:
    if e.offset is None:
      raise CliError(f"F.bin: cannot read: {e.reason}") from None
    raise CliError(f"{args.message}: {e}") from None
  queries = [m for m in msgs if not isinstance(m, jaus.CostMap2DReport)]
  if queries:
    raise CliError(f"{args.message}: holds a QueryCostMap2D (profile {queries[0].profile}); "
                   "decode expects ReportCostMap2D messages")
  _check_out(args.out)
  try:
    grid = jaus.reports_to_grid(msgs, mapping=args.mapping, axes=args.axes,
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
  quantised = sum(m.quantised for m in msgs)
  print(f"wrote {yaml_path} and {image_path}: {len(msgs)} message{'s' * (len(msgs) > 1)}, "
        f"{grid.height} rows x {grid.width} columns, resolution {grid.resolution:g} m, origin "
        f"({grid.origin[0]:g}, {grid.origin[1]:g}, {grid.origin[2]:g}), mode {mode}"
        + (f"; quantised: {quantised} run-length message{'s' * (quantised > 1)} carry 3-bit "
           "costs, not the costs sent" if quantised else ""))
  return EXIT_OK
