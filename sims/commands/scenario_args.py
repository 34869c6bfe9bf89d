"""The map options of `jaxfilters fleet` and `jaxfilters rl eval`, checked and turned into a `Scenario`.

Three sets, nothing given ignored:

  none of --map/--keepout/--speed/--params   the built-in warehouse
  --map, --keepout and --speed               mask files (speed info from --speed-type/--speed-base/
                                             --speed-multiplier, the defaults of `jaxfilters query --speed`)
  --map and --params [--mask NODE=MAP ...]   the costmap's keepout and speed filters (both enabled), and the
                                             inflation layers of the file's local_costmap for the local costmaps

A parser gets the options from `add_map_options`; `check_map_args` refuses a
bad set before anything is loaded and `scenario_from_args` builds the
Scenario. Every problem is a `jaxfilters.cli.CliError` (one line, exit 2).
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

from jaxfilters import cli as jcli
from jaxfilters.cli import CliError


def add_map_options(parser) -> None:
  """Adds --map/--keepout/--speed (with the speed info options) and the params options to `parser`."""
  m = parser.add_argument_group("maps from files (default: the built-in warehouse)")
  m.add_argument("--map", type=jcli.path_type, default=None, help="Nav2 map YAML of the static map")
  m.add_argument("--keepout", type=jcli.path_type, default=None, help="keepout mask YAML (Nav2 type 0)")
  m.add_argument("--speed", type=jcli.path_type, default=None, help="speed mask YAML")
  jcli.add_speed_options(m)
  jcli.add_params_options(parser)


def check_map_args(args) -> None:
  """The map options form one of the three documented sets; nothing given is ignored.

  Raises:
    CliError: a mix of the sets, a partial set, or a named file that is missing or not a file.
  """
  speed_opts = jcli.given_speed_options(args)
  if args.params is not None:
    given = [f"--{n}" for n in ("keepout", "speed") if getattr(args, n) is not None] + speed_opts
    if given:
      raise CliError(f"{given[0]} cannot be combined with --params (the params file gives the masks and the "
                     "speed filter's type, base and multiplier; give a mask server's file with --mask NODE=MAP.yaml)")
    if args.map is None:
      raise CliError("--params needs --map M.yaml (the static map the robots drive on)")
  else:
    jcli.check_params_options(args)
    maps = (args.map, args.keepout, args.speed)
    if any(m is not None for m in maps) and not all(m is not None for m in maps):
      raise CliError("give all three of --map, --keepout and --speed, or --map with --params "
                     "(or none for the built-in warehouse)")
    if speed_opts and args.speed is None:
      raise CliError(f"{speed_opts[0]} needs --speed M.yaml (the built-in warehouse's speed zones are fixed)")
    if args.speed is not None:
      jcli.speed_info(args)
  for name in ("map", "keepout", "speed", "params"):
    p = getattr(args, name)
    if p is not None and not Path(p).is_file():
      raise CliError(f"--{name} {p}: no such file" if not Path(p).exists() else f"--{name} {p}: not a file")


def scenario_from_params(args, command: str, what: str = "the fleet"):
  """The Scenario of --map with --params' keepout and speed filters (both present and enabled).

  The file's `local_costmap` (when it has one) gives `Scenario.layers`: the
  InflationLayer and AsymmetricInflationLayer its `plugins:` list, which the
  fleet's local costmaps run instead of the fleet's own inflation.

  Args:
    args: the namespace (checked by `check_map_args`).
    command: the command's name, for warning lines.
    what: what runs the filters, for messages ("the fleet", "the RL env").
  """
  from sims.fleet.scenario import Scenario
  costmap, params = jcli.params_costmap(args, command, also=("local_costmap",))
  layers = () if params.local_costmap is None else params.local_costmap.layers
  where = f"--params {args.params}: {costmap.name}"
  for kind, f in (("keepout", costmap.keepout), ("speed", costmap.speed)):
    if f is None:
      raise CliError(f"{where} has no {kind} filter; {what} runs a keepout and a speed filter")
    if not f.enabled:
      raise CliError(f"{where} filter '{f.name}' is disabled (enabled: false); {what} runs it always "
                     "(enable it, e.g. with --set for a launch placeholder)")
  if costmap.foreign_frames():
    raise CliError(f"{where}: its masks are in frame {costmap.foreign_frames()[0]!r}, not the costmap's "
                   f"{costmap.global_frame!r}; {what} simulates one frame")
  speed = costmap.speed
  if speed.percentage is None:
    raise CliError(f"{where} speed filter '{speed.name}': its info type is not 1 or 2 (a speed filter's)")
  import numpy as np
  info = speed.mask.info
  base, mult = float(np.asarray(info.base).reshape(-1)[0]), float(np.asarray(info.multiplier).reshape(-1)[0])
  scenario = Scenario.load(args.map, costmap.keepout.mask_yaml, speed.mask_yaml,
                           speed_type=1 if speed.percentage else 2, speed_base=base, speed_multiplier=mult)
  return dataclasses.replace(scenario, layers=at_map_resolution(layers, scenario.map.resolution, command))


def at_map_resolution(layers, resolution: float, command: str) -> tuple:
  """The local costmap's layers at the map's resolution, with one warning line if they were not.

  Nav2's local costmap has its own `resolution` (Nav2's bringup: 0.05 m beside its 0.03 m
  warehouse map) and resamples the static map into it; the fleet's local costmaps are
  windows of the map itself, so a params file with another local resolution runs its
  inflation layers at the map's resolution, their radii and scaling factors (metres) as the
  file gives them. The library refuses the mismatch (`sims.fleet.world.local_layers`); the
  command says what it does and carries on, so a Nav2 user's own params and map run unchanged.
  """
  import numpy as np
  out = []
  for layer in layers:
    if np.float32(layer.config.resolution) != np.float32(resolution):
      print(f"jaxfilters {command}: warning: local_costmap layer '{layer.name}' is at resolution "
            f"{layer.config.resolution:g} m (the params' local_costmap resolution) but the fleet's local "
            f"costmaps are windows of the map at {resolution:g} m: it runs there, its radii and scaling "
            "factors in metres unchanged", file=sys.stderr)
      layer = dataclasses.replace(layer, config=dataclasses.replace(layer.config, resolution=float(resolution)))
    out.append(layer)
  return tuple(out)


def scenario_from_args(args, command: str, what: str = "the fleet"):
  """The Scenario the map options name (the built-in warehouse when none is given).

  Call `check_map_args` first.

  Raises:
    CliError: a file that does not load or a params file without usable filters.
  """
  from sims.fleet.scenario import Scenario
  try:
    if args.params is not None:
      return scenario_from_params(args, command, what)
    if args.map is None:
      return Scenario.default()
    speed_type, speed_base, speed_multiplier = jcli.speed_info(args)
    return Scenario.load(args.map, args.keepout, args.speed, speed_type=speed_type,
                         speed_base=speed_base, speed_multiplier=speed_multiplier)
  except (FileNotFoundError, ValueError) as e:
    raise CliError(str(e).splitlines()[0] if str(e) else type(e).__name__) from None


def map_label(args) -> str:
  """The map the options name, for reports: the --map path or the built-in warehouse."""
  return str(args.map) if args.map else "built-in (sims/assets/default_map.yaml)"
