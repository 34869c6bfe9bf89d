"""`jaxfilters fleet`: simulate a robot fleet in MJX with Nav2's speed and keepout filters.

    jaxfilters fleet --out out/demo                       # built-in warehouse, 16 robots, 120 s
    jaxfilters fleet --map warehouse.yaml --keepout warehouse_keepout.yaml \\
        --speed warehouse_speed.yaml --robots 12 --seconds 90
    jaxfilters fleet --map warehouse.yaml --params nav2_params.yaml \\
        --mask keepout_filter_mask_server=warehouse_keepout.yaml \\
        --mask speed_filter_mask_server=warehouse_speed.yaml
    jaxfilters fleet --keepout-escape footprint --robots-in-keepout 4 --seconds 30   # Nav2 #6505
    jaxfilters fleet --robot examples/robots/omni_base.xml --robots 8 --seconds 30   # your own base

It writes OUT/summary.json, OUT/trajectories.png (map, zones, paths coloured
by speed) and with --animate OUT/fleet.gif, and prints a summary table. Every
option is checked before anything is simulated (exit 2, one line); the exit
code is 3 if any robot entered a keepout cell or exceeded a speed zone's
limit by more than the stated tolerance (disable with --no-check); with
--keepout-escape, also if a robot's footprint entered a zone from outside or a
robot started in one was still in it at the end (every code: jaxfilters/cli.py).

Registered into the library's CLI through the `jaxfilters.commands`
entry-point group (pyproject.toml).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from pathlib import Path

from jaxfilters import cli as jcli
from jaxfilters.cli import EXIT_OK, EXIT_VIOLATION, CliError
from sims.commands import scenario_args

# Bounds of the size options, checked by the parser (exit 2, one line) and stated in their help.
MAX_ROBOTS = 2 ** 20              # 16 x the 65,536 robots BENCHMARKS.md runs on one GPU
MAX_ROBOTS_PER_WORLD = 1024       # robots in one warehouse (their pairwise checks grow as its square)
MAX_STEPS = 1_000_000             # env steps of 0.2 s (55 h simulated); the pictures keep every step
BAG_MARKER = ".jaxfilters_fleet_bag"   # sims.record.bag.MARKER_NAME (the parser imports no simulator code)


class _Progress:
  """A text progress bar on stderr: redrawn in place on a terminal, a line per 10 % otherwise."""

  def __init__(self, total: float, width: int = 30):
    self.total, self.width = total, width
    self.tty = sys.stderr.isatty()
    self.last_decile = -1

  def update(self, done: float, wall: float) -> None:
    frac = 0.0 if self.total <= 0 else min(1.0, done / self.total)
    bar = "#" * int(round(frac * self.width))
    text = (f"[{bar:<{self.width}}] {100 * frac:5.1f}%  {done:7.1f}/{self.total:.1f} s simulated  "
            f"{wall:6.1f} s wall")
    if self.tty:
      sys.stderr.write("\r" + text + ("\n" if frac >= 1.0 else ""))
    elif int(frac * 10) > self.last_decile:
      self.last_decile = int(frac * 10)
      sys.stderr.write(text + "\n")
    sys.stderr.flush()


_FLEET_EPILOG = f"""\
examples:
  jaxfilters fleet --out out/demo                          # built-in warehouse, 16 robots, 120 s
  jaxfilters fleet --robots 64 --seconds 60 --animate --out out/run
  jaxfilters fleet --map warehouse.yaml --keepout warehouse_keepout.yaml --speed warehouse_speed.yaml \\
      --speed-base 100 --speed-multiplier -1 --out out/mine
  jaxfilters fleet --map warehouse.yaml --params nav2_params.yaml \\
      --mask keepout_filter_mask_server=warehouse_keepout.yaml \\
      --mask speed_filter_mask_server=warehouse_speed.yaml \\
      --set KEEPOUT_ZONE_ENABLED=True --set SPEED_ZONE_ENABLED=True --out out/params
  jaxfilters fleet --keepout-escape footprint --robots-in-keepout 4 --seconds 30
  jaxfilters fleet --seconds 60 --bag out/bag --bag-costmaps 2   # open out/bag in Foxglove
  jaxfilters fleet --robot examples/robots/diff_drive.xml --robots 8 --seconds 30   # your own base

Maps, one of three sets (no option is ignored: a mix is refused):
  none of --map/--keepout/--speed/--params   the built-in warehouse (its speed zones are fixed)
  --map, --keepout and --speed               speed mask type {jcli.SPEED_TYPE_DEFAULT}, base {jcli.SPEED_BASE_DEFAULT:g}, multiplier {jcli.SPEED_MULTIPLIER_DEFAULT:g} unless
                                             --speed-type/--speed-base/--speed-multiplier say otherwise
                                             (the defaults of `jaxfilters query --speed`)
  --map and --params                         the costmap's keepout and speed filters (both enabled),
                                             with their type, base and multiplier; the local costmaps run
                                             the file's local_costmap InflationLayer/AsymmetricInflationLayer
                                             (each robot with its own plan), e.g. sims/assets/nav2_params_lanes.yaml
--seconds is rounded to whole env steps of 0.2 s (a note says so when it moves); the last chunk
is shorter when --chunk-seconds does not divide the run.

exit codes: 0 ok, 1 internal error (a bug; JAXFILTERS_DEBUG=1 shows the traceback), 2 bad option or
input file (one line on stderr, checked before anything is simulated), 3 a robot broke a rule
(a keepout entry or a speed violation; --no-check exits 0 anyway)"""


def register_fleet(sub) -> argparse.ArgumentParser:
  """Adds `jaxfilters fleet` to the library CLI's subparsers.

  Args:
    sub: argparse's subparsers object (from `jaxfilters.cli.build_parser`).

  Returns:
    The `fleet` parser (its `func` default is `run_fleet`).
  """
  p = sub.add_parser("fleet", help="simulate a robot fleet in MJX with speed and keepout filters",
                     description="Simulate a fleet of robots in MJX (the built-in base, or your own with --robot). "
                     "Every velocity command is clipped by the Nav2 speed filter and keepout zones are never "
                     "entered.",
                     epilog=_FLEET_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
  int_ = jcli.int_type
  p.add_argument("--robots", type=int_(1, MAX_ROBOTS), default=16,
                 help=f"total robots, 1 to 2**20 = {MAX_ROBOTS:,d} (default 16)")
  p.add_argument("--robots-per-world", type=int_(1, MAX_ROBOTS_PER_WORLD), default=None,
                 help=f"robots sharing one warehouse, 1 to {MAX_ROBOTS_PER_WORLD:,d} (default: all of them up to 64, "
                 "else the largest divisor of --robots up to 16); worlds are independent and batched")
  g = p.add_mutually_exclusive_group()
  g.add_argument("--seconds", type=float, default=None,
                 help=f"simulated seconds, rounded to whole env steps of 0.2 s, at most {MAX_STEPS:,d} steps "
                 "(default 120)")
  g.add_argument("--steps", type=int_(1, MAX_STEPS), default=None,
                 help=f"env steps of 1/costmap_hz (0.2 s) each, 1 to {MAX_STEPS:,d}")
  scenario_args.add_map_options(p)
  p.add_argument("--seed", type=int_(0, 2 ** 32 - 1), default=0, help="PRNG seed in [0, 2**32) (default 0)")
  p.add_argument("--out", type=jcli.path_type, default=Path("out/fleet"),
                 help="output folder (default out/fleet); created once every option is checked")
  p.add_argument("--animate", action="store_true", help="also write fleet.gif")
  p.add_argument("--chunk-seconds", type=float, default=10.0,
                 help="simulated seconds per jitted chunk (progress granularity; default 10)")
  p.add_argument("--record-robots", type=int_(1, MAX_ROBOTS_PER_WORLD), default=64,
                 help=f"robots drawn in the pictures, 1 to {MAX_ROBOTS_PER_WORLD:,d} (default 64)")
  p.add_argument("--impl", choices=("jax", "warp"), default="jax", help="MJX implementation (default jax)")
  p.add_argument("--devices", default=None, metavar="N|all",
                 help="shard the worlds over N devices (or all); the world count must be a multiple "
                 "(default: one device, no sharding)")
  p.add_argument("--keepout-escape", choices=("off", "center", "footprint"), default="off",
                 help="keepout as a layer before inflation with escape mode (Nav2 override_lethal_cost): "
                 "'center' is Nav2's centre-cell test, 'footprint' the footprint test (Nav2 #6505); the "
                 "planner then treats an inscribed cell under the robot as a collision, as Nav2's controllers "
                 "do (default off: Nav2's filter after inflation)")
  p.add_argument("--robot", type=jcli.path_type, default=None, metavar="ROBOT.xml",
                 help="your own base: an MJCF file with a body 'base', a site 'base_link', velocity actuators "
                 "(v, no_slip, wz: differential drive; vx, vy, wz: omni) and its footprint radius "
                 "(docs/guides/robots.md; e.g. examples/robots/diff_drive.xml); its radius replaces the "
                 "built-in robot's 0.22 m everywhere (default: the built-in robot)")
  p.add_argument("--robots-in-keepout", type=int_(0, MAX_ROBOTS_PER_WORLD), default=0,
                 help="robots per world started with their footprint in a keepout zone (needs --keepout-escape)")
  b = p.add_argument_group("rosbag2 (MCAP) of the run, for Foxglove, RViz and PlotJuggler (needs the ros extra)")
  b.add_argument("--bag", type=jcli.path_type, default=None, metavar="DIR",
                 help="write the run as a rosbag2 folder in MCAP storage (map, masks, filter info, /tf, "
                 "cmd_vel, speed_limit per robot; sims/record/bag.py lists the topics): a new or empty folder, not "
                 "a symbolic link, apart from --out (neither inside the other)")
  b.add_argument("--bag-robots", type=int_(1, MAX_ROBOTS), default=None, metavar="N",
                 help="robots recorded in the bag, the first N (default: up to 8)")
  b.add_argument("--bag-costmaps", type=int_(0, MAX_ROBOTS), default=0, metavar="N",
                 help="also record the local costmaps of the first N bag robots (default 0)")
  b.add_argument("--overwrite", action="store_true",
                 help="replace a --bag folder an earlier `jaxfilters fleet --bag` wrote (proved by its "
                 f"{BAG_MARKER} file; a folder holding anything else is refused, nothing deleted)")
  p.add_argument("--no-check", action="store_true",
                 help="exit 0 even with keepout entries or speed violations")
  p.set_defaults(func=run_fleet)
  return p


def _check_fleet_args(args) -> None:
  """Every option value checked before anything is loaded or simulated (one-line errors)."""
  def finite_positive(name, v):
    if v is not None and not (math.isfinite(v) and v > 0):
      raise CliError(f"{name} must be a finite number > 0; got {v!r}")
  if args.robots < 1:
    raise CliError(f"--robots must be >= 1; got {args.robots}")
  if args.robots_per_world is not None and args.robots_per_world < 1:
    raise CliError(f"--robots-per-world must be >= 1; got {args.robots_per_world}")
  finite_positive("--seconds", args.seconds)
  finite_positive("--chunk-seconds", args.chunk_seconds)
  if args.seconds is not None and args.seconds > MAX_STEPS * 0.2:
    raise CliError(f"--seconds must be at most {MAX_STEPS * 0.2:,.0f} ({MAX_STEPS:,d} env steps of 0.2 s); "
                   f"got {args.seconds!r}")
  if args.steps is not None and args.steps < 1:
    raise CliError(f"--steps must be >= 1; got {args.steps}")
  if not 0 <= args.seed < 2 ** 32:
    raise CliError(f"--seed must lie in [0, 2**32); got {args.seed}")
  if args.record_robots < 1:
    raise CliError(f"--record-robots must be >= 1 (the pictures draw at least one robot); got {args.record_robots}")
  if args.robots_in_keepout < 0:
    raise CliError(f"--robots-in-keepout must be >= 0; got {args.robots_in_keepout}")
  if args.robots_in_keepout and args.keepout_escape == "off":
    raise CliError("--robots-in-keepout needs --keepout-escape center or footprint (without escape mode a "
                   "robot started in a zone is deadlocked)")
  scenario_args.check_map_args(args)
  _check_robot_arg(args)
  _check_bag_args(args)
  jcli.check_creatable(Path(args.out))


def _check_robot_arg(args) -> None:
  """--robot read and checked against the interface (sims/fleet/robot.py): args.robot_model, or CliError."""
  args.robot_model = None
  if args.robot is None:
    return
  from sims.fleet.robot import RobotModelError, load_robot   # mujoco only: no simulator imports yet
  try:
    args.robot_model = load_robot(args.robot)
  except RobotModelError as e:
    raise CliError(f"--robot {e}") from None


def _nested(a: Path, b: Path) -> bool:
  """a and b name the same folder, or one lies inside the other (symbolic links on the way resolved)."""
  ra, rb = a.resolve(), b.resolve()
  return ra == rb or ra in rb.parents or rb in ra.parents


def _check_bag_args(args) -> None:
  """--bag and its options: refused when they would be ignored, the folder checked before simulating."""
  if args.bag is None:
    for flag, value, unset in (("--bag-robots", args.bag_robots, None), ("--bag-costmaps", args.bag_costmaps, 0),
                               ("--overwrite", args.overwrite, False)):
      if value != unset:
        raise CliError(f"{flag} needs --bag DIR (nothing else records a bag)")
    return
  from sims.record.bag import BagError, check_bag_dir
  try:
    import rosbags  # noqa: F401, PLC0415 - the optional dependency the bag writer needs
  except ImportError:
    raise CliError("--bag needs the rosbags package: pip install 'jaxfilters[ros]'") from None
  if args.devices is not None:
    raise CliError("--bag records on one device: drop --devices")
  n = min(8, args.robots) if args.bag_robots is None else args.bag_robots
  if not 1 <= n <= args.robots:
    raise CliError(f"--bag-robots must lie in [1, --robots = {args.robots}]; got {n}")
  if not 0 <= args.bag_costmaps <= n:
    raise CliError(f"--bag-costmaps must lie in [0, bag robots = {n}]; got {args.bag_costmaps}")
  args.bag_robots = n
  try:
    check_bag_dir(args.bag, overwrite=args.overwrite)
    if _nested(Path(args.bag), Path(args.out)):
      raise CliError(f"--bag {args.bag} and --out {args.out} must be separate folders, neither inside the "
                     "other (the run writes into --out; the bag folder holds only the bag)")
  except BagError as e:
    raise CliError(str(e)) from None
  except (OSError, RuntimeError) as e:      # resolving a path (a loop of symbolic links)
    raise CliError(f"--bag {args.bag} / --out {args.out}: cannot resolve ({e})") from None


def _steps_and_chunks(args, step_s: float) -> tuple[int, int]:
  """(total env steps, steps per chunk) of --seconds/--steps and --chunk-seconds; a note if --seconds moved."""
  if args.steps is not None:
    total = args.steps
  else:
    seconds = 120.0 if args.seconds is None else args.seconds
    total = int(round(seconds / step_s))
    if total < 1:
      raise CliError(f"--seconds must be at least one env step ({step_s:g} s); got {seconds!r}")
    if not math.isclose(total * step_s, seconds, rel_tol=1e-9, abs_tol=1e-9):
      print(f"jaxfilters fleet: note: --seconds {seconds:g} is not a whole number of {step_s:g} s env steps; "
            f"simulating {total} steps ({total * step_s:g} s)", file=sys.stderr)
  chunk = max(1, min(total, int(round(args.chunk_seconds / step_s))))
  return total, chunk


def _table(summary: dict, header: str) -> str:
  f = summary["fleet"]
  lines = [header, f"{'zone':<10}{'limit':>12}{'time in zone':>16}{'max speed':>13}  compliant"]
  for z in f["zones"]:
    limit = "-" if z["limit_mps"] is None else f"{z['limit_mps']:.3f} m/s"
    lines.append(f"{z['zone']:<10}{limit:>12}{z['time_s']:>14.1f} s{z['max_speed_mps']:>9.3f} m/s  "
                 f"{'yes' if z['compliant'] else 'NO'}")
  sep = "-" if f["min_separation_m"] is None else f"{f['min_separation_m']:.2f} m"
  entries = (f"keepout entries {f['keepout_entries']}" if f.get("footprint_entries") is None else
             f"keepout entries from outside {f['keepout_entries_started_outside']}")
  lines.append(f"distance {f['distance_m']:.1f} m | goals reached {f['goals_reached']} | "
               f"{entries} | contacts {f['contacts']} | "
               f"near misses {f['near_misses']} | min separation {sep} | "
               f"stuck > {summary['config']['progress_timeout_s']:g} s: {f['stuck_events']} | "
               f"emergency stops {f['emergency_stops']}")
  if f.get("footprint_entries") is not None:
    t = f["escape_time_max_s"]
    lines.append(f"keepout escape ({summary['config']['keepout_escape']} test): started in zones "
                 f"{f['robots_started_in_keepout']}, escaped {f['robots_escaped']}"
                 f"{'' if t is None else f' (last after {t:.1f} s)'}, still in a zone "
                 f"{f['robots_in_keepout_at_end']} | footprint entries from outside {f['footprint_entries']}")
  lines.append(f"speed compliance (tolerance {f['speed_tolerance_mps']} m/s): "
               f"{'PASS' if f['speed_compliant'] else 'FAIL'}; keepout: "
               f"{'PASS' if _keepout_pass(f) else 'FAIL'}")
  return "\n".join(lines)


def _mesh(devices, num_worlds: int):
  """--devices N|all -> a 1-D mesh over the world axis (None: no sharding), or CliError."""
  if devices is None:
    return None
  from sims.scale import sharding
  text = str(devices).lower()
  if text != "all":
    try:
      n = jcli.strict_int(text)
    except ValueError:
      raise CliError(f"--devices must be a positive integer or 'all'; got {devices!r}") from None
  else:
    n = "all"
  try:
    mesh = sharding.make_mesh(n)
  except ValueError as e:
    raise CliError(f"--devices: {e}") from None
  try:
    sharding.check_divisible(num_worlds, mesh)
  except ValueError as e:
    raise CliError(f"--devices: {e} (worlds = --robots / --robots-per-world)") from None
  return mesh


def run_fleet(args) -> int:
  """Runs `jaxfilters fleet` with parsed arguments.

  Writes OUT/summary.json, OUT/trajectories.png, with --animate OUT/fleet.gif and with
  --bag a rosbag2 (MCAP) folder, and prints the summary table on stdout (progress on stderr).

  Args:
    args: the argparse namespace of the `fleet` parser.

  Returns:
    The exit code: 0, or 3 if a robot entered a keepout cell or broke a speed
    limit (0 anyway with --no-check).

  Raises:
    CliError: an inconsistent option (--robots, --robots-per-world, a partial set of maps).
  """
  t_start = time.perf_counter()
  _check_fleet_args(args)       # before the simulator's imports: a refusal comes in seconds
  import jax
  import numpy as np
  from sims.fleet.config import FleetConfig, PlannerConfig
  from sims.fleet.env import FleetEnv
  from sims.fleet.metrics import summarize
  from sims.record.render import render_gif, render_png

  k = args.robots_per_world or (args.robots if args.robots <= 64 else
                                max(d for d in range(1, 17) if args.robots % d == 0))
  if args.robots % k:
    raise CliError(f"--robots ({args.robots}) must be a multiple of --robots-per-world ({k})")
  if args.robots_in_keepout > k:
    raise CliError(f"--robots-in-keepout ({args.robots_in_keepout}) counts robots per world; it must be <= the "
                   f"robots per world ({k})")
  scenario = scenario_args.scenario_from_args(args, "fleet")
  escape = args.keepout_escape != "off"
  try:
    config = FleetConfig(robots_per_world=k, impl=args.impl, keepout_escape=args.keepout_escape,
                         robots_in_keepout=args.robots_in_keepout,
                         planner=PlannerConfig(inscribed_is_collision=escape))
    if args.robot_model is not None:
      config = args.robot_model.configure(config)
  except ValueError as e:
    raise CliError(str(e)) from None
  num_worlds = args.robots // k
  mesh = _mesh(args.devices, num_worlds)
  step_s = config.step_seconds
  total_steps, chunk = _steps_and_chunks(args, step_s)
  # Full chunks, then one shorter chunk (compiled on its own) when `chunk` does not divide the run.
  lengths = [chunk] * (total_steps // chunk) + ([total_steps % chunk] if total_steps % chunk else [])
  out = jcli.prepare_out(Path(args.out))      # every option checked: only now is --out created

  print(f"jaxfilters fleet: {scenario.name}, {args.robots} robots ({num_worlds} world(s) x {k}), "
        f"{total_steps * step_s:g} s simulated, device {jax.devices()[0].device_kind}", file=sys.stderr)
  t0 = time.perf_counter()
  try:
    env = FleetEnv.create(scenario, config, seed=args.seed, robot=args.robot_model)
  except ValueError as e:      # the maps cannot host this fleet (mask resolution, free space)
    raise CliError(f"{scenario.name}: {e}") from None
  states = env.reset_fn(mesh=mesh)(env.params, env.world_keys(jax.random.PRNGKey(args.seed), num_worlds))
  t1 = time.perf_counter()
  bag = args.bag is not None
  compiled = {n: env.rollout_fn(n, mesh=mesh, record_ticks=bag, record_costmaps=args.bag_costmaps if bag else 0)
              .compile(env.params, states) for n in sorted(set(lengths))}
  compile_s = time.perf_counter() - t1
  setup_s = t1 - t0
  rec = min(args.record_robots, args.robots)
  poses, speeds = [], []
  t_run = time.perf_counter()
  progress = _Progress(total_steps * step_s)
  progress.update(0.0, time.perf_counter() - t_start)
  done = 0
  recordings = []
  for n in lengths:
    states, frames = compiled[n](env.params, states)
    if bag:
      recordings.append(jax.tree.map(np.asarray, frames))
      frames = frames.frame
    poses.append(np.asarray(frames.pose).reshape(n, -1, 3)[:, :rec])
    speeds.append(np.asarray(frames.speed).reshape(n, -1)[:, :rec])
    done += n
    progress.update(done * step_s, time.perf_counter() - t_start)
  jax.block_until_ready(states)
  run_s = time.perf_counter() - t_run

  w = env.world
  seconds = total_steps * step_s
  summary = summarize(states.metrics, zone_labels=w.zone_labels, zone_limits=w.zone_limits,
                      zone_speed=w.zone_speed, speed_tolerance=config.speed_tolerance, seconds=seconds,
                      footprint=escape)
  summary["scenario"] = {
      "name": scenario.name,
      "map": scenario_args.map_label(args),
      "params": None if args.params is None else str(args.params),
      "resolution_m": scenario.map.resolution, "size_cells": list(scenario.map.data.shape[::-1]),
      "speed_filter": {"type": scenario.speed_type, "base": scenario.speed_base,
                       "multiplier": scenario.speed_multiplier},
      "stations": np.asarray(w.stations).round(3).tolist(),
      # The params' local costmap inflation layers the local costmaps ran (empty: the fleet's inflation).
      "local_layers": [{"name": x.name, "plugin": x.plugin, **dataclasses.asdict(c)}
                       for x, c in zip(scenario.layers, w.local_layers, strict=True)],
  }
  summary["config"] = {
      "robots": args.robots, "robots_per_world": k, "worlds": num_worlds, "seed": args.seed,
      "controller_hz": config.controller_hz, "costmap_hz": config.costmap_hz,
      "physics_dt_s": config.physics_dt, "robot_radius_m": config.robot.radius,
      "robot": None if args.robot_model is None else {"file": args.robot_model.name,
                                                      "drive": args.robot_model.drive},
      "max_speed_mps": config.robot.max_speed, "max_accel_mps2": config.robot.max_accel,
      "local_costmap_m": config.local_costmap_size, "progress_timeout_s": config.progress_timeout,
      "impl": config.impl, "devices": 1 if mesh is None else int(mesh.devices.size),
      "keepout_escape": config.keepout_escape, "robots_in_keepout": config.robots_in_keepout,
      "inscribed_radius_m": w.inflation.inscribed_radius,
      "escape_clearance_m": None if w.keepout_config is None else w.keepout_config.escape_clearance,
  }
  summary["timing"] = {"setup_s": setup_s, "compile_s": compile_s, "run_s": run_s,
                       "robot_steps_per_s": args.robots * total_steps * config.ticks_per_step
                       * config.substeps_per_tick / run_s,
                       "device": str(jax.devices()[0].device_kind)}
  (out / "summary.json").write_text(json.dumps(summary, indent=2))
  pose = np.concatenate(poses)
  speed = np.concatenate(speeds)
  render_png(w, pose, speed, out / "trajectories.png", summary=summary)
  written = [out / "summary.json", out / "trajectories.png"]
  if args.animate:
    written.append(render_gif(w, pose, speed, out / "fleet.gif", summary=summary,
                                seconds_per_frame=step_s))
  if bag:
    from sims.record.bag import BagError, host_recording, write_fleet_bag
    recording = host_recording(recordings, robots=args.bag_robots, step_seconds=step_s)
    try:
      written.append(write_fleet_bag(args.bag, scenario, recording, max_speed=config.robot.max_speed,
                                     summary=summary, overwrite=args.overwrite))
    except BagError as e:       # the folder changed during the run; nothing in it was removed
      raise CliError(f"{e} (it changed during the run; the summary and pictures are in {out})") from None
  header = (f"{scenario.name}: {args.robots} robots, {seconds:g} s simulated in {run_s:.1f} s "
            f"(setup {setup_s:.1f} s, compile {compile_s:.1f} s; "
            f"{summary['timing']['robot_steps_per_s']:.3g} robot-steps/s)")
  print(_table(summary, header))
  print("wrote " + ", ".join(str(p) for p in written))
  ok = summary["fleet"]["speed_compliant"] and _keepout_pass(summary["fleet"])
  return EXIT_OK if ok or args.no_check else EXIT_VIOLATION


def _keepout_pass(f: dict) -> bool:
  """No keepout entry or step; with keepout escape (footprint metrics) `keepout_ok` (robots started in
  zones step there and may move their centre while they escape)."""
  if f.get("footprint_entries") is None:
    return f["keepout_entries"] == 0 and f["keepout_steps"] == 0
  return bool(f["keepout_ok"])
