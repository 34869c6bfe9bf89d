"""`jaxfilters rl train` and `jaxfilters rl eval`: PPO on the fleet RL env, and a policy's figures on any map.

    jaxfilters rl train --timesteps 3000000 --num-envs 64 --randomize --out out/pol
    jaxfilters rl eval --policy out/pol --episodes 256 --seed 7 --randomize --json

`train` trains rejax's PPO (`sims.rl.ppo`) on the env `sims.rl.randomization.training_env`
builds (the built-in warehouse; zones and goals drawn per episode with
--randomize), prints a progress line on stderr after each evaluation point and
writes into --out: the policy (`sims.rl.policy`: policy.json, policy.msgpack),
results.json (timings, devices, the curve, the final figures, the config) and
learning_curve.png. With --devices the env batch is sharded over that many
devices (`sims.rl.ppo.train_with_curve`'s mesh).

`eval` loads a policy (checked: `sims.rl.policy.load_policy`), builds the env
with the NavEnvConfig it was trained with on the maps given (default the
built-in warehouse), runs one episode on each of --episodes envs with the
policy's mean action (`sims.rl.ppo.evaluate_policy`) and prints the figures: a
table, or one JSON object with --json. Rule breaks (keepout entries,
collisions, time above a speed limit) are reported, not turned into exit
code 3: the command measures a policy, and a script reads its JSON.

`train --robots-per-world K` trains one policy shared by every robot of worlds of K robots
(`NavEnvConfig(agents="per_robot")`, `sims.rl.fleet`); `eval --robots-per-world K` runs such a
policy at any K and reports per robot-episode figures.

Registered into the library's CLI through the `jaxfilters.commands`
entry-point group (pyproject.toml). Every option is checked before anything
is built (exit 2, one line).
"""

from __future__ import annotations

import argparse
import json
import dataclasses
import math
import sys
import time
from pathlib import Path

from jaxfilters import cli as jcli
from jaxfilters.cli import EXIT_OK, CliError
from sims.commands import scenario_args

POLICY_OUTPUTS = ("policy.json", "policy.msgpack", "results.json", "learning_curve.png")

# Bounds of the size options, checked by the parser (exit 2, one line) before anything is built and
# stated in each option's help. Generous for a multi-GPU host, and small enough that no count
# overflows an int32 on the device or sizes an allocation past a GPU's memory:
MAX_TIMESTEPS = 2 ** 30          # rejax counts env steps in an int32 (global_step); with rounding up to
                                 # whole iterations (<= MAX_BATCH) and the split into calls the total
                                 # stays below 2**31
MAX_ENVS = 2 ** 21               # 2,097,152 envs: 8 GPUs x the 262,144 per GPU that BENCHMARKS.md runs
MAX_STEPS = 4096                 # rollout length per PPO iteration
MAX_BATCH = 2 ** 26              # --num-envs x --num-steps: the rollout buffer's rows (obs float32 each)
MAX_MINIBATCHES = 2 ** 16
MAX_HIDDEN_LAYERS = 4            # --hidden: a policy of 4 x 1024 units is what `rl eval` is made to load
MAX_HIDDEN_UNITS = 1024
MAX_EPISODE_LENGTH = 100_000     # env steps of 0.2 s per episode (5.5 h simulated)
MAX_LAYOUTS = 1024               # each layout is a world built on the host (about 0.5 s and a map-sized
                                 # mask each)
MAX_EVALS = 1000                 # evaluation points, each a host round trip and a curve point
MAX_EVAL_EPISODES = 2 ** 18      # episodes run at once on one device (--num-eval, --episodes)
MAX_DEVICES = 4096
MAX_ROBOTS = 64                  # --robots-per-world: sims.rl.policy.MAX_ROBOTS, what a policy file may record

_TRAIN_EPILOG = """\
examples:
  jaxfilters rl train --timesteps 400000 --out out/ppo
  jaxfilters rl train --timesteps 3000000 --num-envs 64 --num-steps 64 --randomize --out out/ppo3m
  jaxfilters rl train --timesteps 50000000 --num-envs 8192 --devices all --randomize --out out/big
  jaxfilters rl train --robots-per-world 8 --timesteps 2000000 --num-envs 1024 --randomize --out out/fleet

--timesteps is rounded up to whole PPO iterations (--num-envs x --num-steps env steps each), split
into --evals training calls as equal as whole iterations allow (--evals at most the iterations), with
an evaluation of --num-eval episodes before the first and after each: --evals + 1 curve points. The
env steps reported (progress lines, results.json) are counted on the device. --out must be empty, missing or a folder of an earlier run (only the files this command
writes: policy.json, policy.msgpack, results.json, learning_curve.png) unless --overwrite.

exit codes: 0 ok, 1 internal error (a bug; JAXFILTERS_DEBUG=1 shows the traceback), 2 bad option
or output folder (one line on stderr, nothing run)"""

_EVAL_EPILOG = f"""\
examples:
  jaxfilters rl eval --policy out/pol --episodes 256 --seed 7 --randomize --json
  jaxfilters rl eval --policy out/fleet --robots-per-world 32 --episodes 64 --seed 7 --randomize --json
  jaxfilters rl eval --policy out/pol --episodes 64 --seed 1 --map warehouse.yaml \\
      --keepout warehouse_keepout.yaml --speed warehouse_speed.yaml
  jaxfilters rl eval --policy out/pol --episodes 64 --seed 1 --map warehouse.yaml --params nav2_params.yaml \\
      --mask keepout_filter_mask_server=warehouse_keepout.yaml \\
      --mask speed_filter_mask_server=warehouse_speed.yaml \\
      --set KEEPOUT_ZONE_ENABLED=True --set SPEED_ZONE_ENABLED=True

Maps, one of three sets (a mix is refused):
  none of --map/--keepout/--speed/--params   the built-in warehouse
  --map, --keepout and --speed               speed mask type {jcli.SPEED_TYPE_DEFAULT}, base {jcli.SPEED_BASE_DEFAULT:g}, multiplier {jcli.SPEED_MULTIPLIER_DEFAULT:g} unless
                                             --speed-type/--speed-base/--speed-multiplier say otherwise
  --map and --params                         the costmap's keepout and speed filters (both enabled); the
                                             local_costmap's InflationLayer inflates the static layer (an
                                             AsymmetricInflationLayer is refused: the env has no plan)

JSON keys: episodes, success (fraction of episodes that reached a goal), goals_per_episode,
keepout_entries and collisions (totals over all episodes), speed_excess_s (mean seconds per
episode above the limit in force), speed_excess_after_clip_s (total seconds above the limit the
speed filter published at the current 20 Hz tick: the robot slowing down after the clip),
speed_excess_outside_entry_s (total seconds above the limit in force outside the 20 Hz ticks in
which a slower zone is entered: 0 when the clip holds from the tick after each entry), bad_action_steps
(steps whose action had a NaN, replaced by 0 in the env: 0 for a sound policy; a policy whose actions
are not finite on the episodes' first observations is refused, exit 2), mean_return, clipped_per_episode (m of command the speed filter clipped),
steps_per_episode, policy, seed, map, params, randomize, episode_length, device, wall_s. A policy
trained with --robots-per-world runs one episode on each of --episodes worlds of --robots-per-world
robots (any K; each robot's first episode is counted, the robot respawned after it ends so the
others keep K robots around them), every figure above is per robot-episode, and robots_per_world,
robot_episodes, robot_collisions (robot-robot contacts, total) and
robot_collisions_per_robot_episode are added.

exit codes: 0 ok (rule breaks are reported, not an exit code), 1 internal error (a bug;
JAXFILTERS_DEBUG=1 shows the traceback), 2 bad option, policy or map file (one line on stderr,
nothing run)"""


def register_rl(sub) -> argparse.ArgumentParser:
  """Adds `jaxfilters rl` (subcommands `train` and `eval`) to the library CLI's subparsers.

  Args:
    sub: argparse's subparsers object (from `jaxfilters.cli.build_parser`).

  Returns:
    The `rl` parser; each subcommand sets `func` (`run_train`, `run_eval`).
  """
  p = sub.add_parser("rl", help="train a PPO policy on the fleet RL env, or evaluate one on any map",
                     description="Reinforcement learning on the fleet env: `train` a PPO policy (rejax), "
                     "`eval` a saved policy on the built-in warehouse or your maps.")
  rsub = p.add_subparsers(dest="rl_command", required=True, metavar="SUBCOMMAND",
                          parser_class=jcli.ArgumentParser)

  t = rsub.add_parser("train", help="train PPO and write the policy, results.json and learning_curve.png",
                      description="Train PPO (rejax) on the fleet RL env (the built-in warehouse) with "
                      "progress lines on stderr; write the policy, results.json and learning_curve.png.",
                      epilog=_TRAIN_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
  int_ = jcli.int_type
  t.add_argument("--timesteps", type=int_(1, MAX_TIMESTEPS), default=400_000,
                 help="env steps to train, rounded up to whole PPO iterations, 1 to 2**30 = "
                 f"{MAX_TIMESTEPS:,d} (the trainer counts env steps in an int32; default 400000)")
  t.add_argument("--num-envs", type=int_(1, MAX_ENVS), default=32,
                 help=f"parallel envs, 1 to 2**21 = {MAX_ENVS:,d} (default 32)")
  t.add_argument("--num-steps", type=int_(1, MAX_STEPS), default=64,
                 help=f"rollout length per PPO iteration, 1 to {MAX_STEPS:,d}; --num-envs x --num-steps at most "
                 f"2**26 = {MAX_BATCH:,d} (default 64)")
  t.add_argument("--minibatches", type=int_(1, MAX_MINIBATCHES), default=8,
                 help=f"minibatches per epoch, 1 to {MAX_MINIBATCHES:,d}; must divide --num-envs x --num-steps "
                 "(default 8)")
  t.add_argument("--hidden", default="64,64", metavar="H1,H2,...",
                 help=f"hidden layer sizes of the actor and critic, 1 to {MAX_HIDDEN_LAYERS} layers of 1 to "
                 f"{MAX_HIDDEN_UNITS} units (default 64,64)")
  t.add_argument("--episode-length", type=int_(1, MAX_EPISODE_LENGTH), default=300,
                 help=f"env steps of 0.2 s per episode, 1 to {MAX_EPISODE_LENGTH:,d} (default 300)")
  t.add_argument("--keepout", choices=("terminate", "penalty"), default="terminate",
                 help="a keepout entry ends the episode (terminate) or only costs reward (default terminate)")
  t.add_argument("--costmap-stop", action="store_true",
                 help="the env stops a robot's linear command when its footprint would touch a keepout zone "
                      "or a static obstacle within the next control tick's travel plus 0.1 m (turning stays "
                      "free), as a Nav2 controller checks its trajectories against the costmap; recorded in "
                      "the policy, so rl eval applies it too")
  t.add_argument("--randomize", action="store_true",
                 help="draw a zone layout (keepout and speed rectangles at random places, sizes and limits), "
                 "a scale of the limits and the goals per episode, from --layouts layouts seeded by --seed")
  t.add_argument("--layouts", type=int_(1, MAX_LAYOUTS), default=16,
                 help=f"zone layouts with --randomize, the map's own first, 1 to {MAX_LAYOUTS:,d} (each is a "
                 "world built on the host; default 16)")
  t.add_argument("--robots-per-world", type=int_(1, MAX_ROBOTS), default=None, metavar="K",
                 help=f"train one policy shared by every robot of worlds of K robots, 1 to {MAX_ROBOTS}: each robot "
                 "is an agent with its own observation (98 values, the nearest robot included), reward and done; "
                 "a robot whose episode ends is respawned while its world goes on, and robot-robot contacts are "
                 "penalised and counted (sims.rl.agents). --num-envs then counts worlds, --timesteps world steps, "
                 "and --num-envs x K x --num-steps robot-steps per PPO iteration. rl eval runs the policy at any "
                 "K (default: no flag, one robot per env and the env is the agent)")
  t.add_argument("--devices", default=None, metavar="N|all",
                 help=f"shard the env batch over the first N devices (1 to {MAX_DEVICES:,d}) or all; --num-envs "
                 "must be a multiple (default: one device)")
  t.add_argument("--seed", type=int_(0, 2 ** 32 - 1), default=0, help="PRNG seed in [0, 2**32) (default 0)")
  t.add_argument("--evals", type=int_(1, MAX_EVALS), default=20,
                 help=f"evaluation points after the start, 1 to {MAX_EVALS:,d} (default 20)")
  t.add_argument("--num-eval", type=int_(1, MAX_EVAL_EPISODES), default=32,
                 help=f"episodes per evaluation, run at once, 1 to 2**18 = {MAX_EVAL_EPISODES:,d} (default 32)")
  t.add_argument("--out", type=jcli.path_type, required=True, metavar="DIR", help="output folder")
  t.add_argument("--overwrite", action="store_true", help="write into a non-empty --out folder anyway")
  t.set_defaults(func=run_train)

  e = rsub.add_parser("eval", help="evaluate a saved policy (success, goals, rule breaks)",
                      description="Evaluate a saved policy: one episode on each of --episodes envs with "
                      "its mean action, on the built-in warehouse or the maps given.",
                      epilog=_EVAL_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
  e.add_argument("--policy", type=jcli.path_type, required=True, metavar="DIR",
                 help="policy folder (policy.json and policy.msgpack, as `rl train` writes)")
  e.add_argument("--episodes", type=int_(1, MAX_EVAL_EPISODES), default=256,
                 help=f"episodes, one per env, run at once, 1 to 2**18 = {MAX_EVAL_EPISODES:,d} (default 256)")
  e.add_argument("--seed", type=int_(0, 2 ** 32 - 1), default=0,
                 help="PRNG seed of spawns, goals and layouts, in [0, 2**32) (default 0)")
  e.add_argument("--randomize", action="store_true",
                 help="draw a zone layout, a scale of the limits and the goals per episode, from --layouts "
                 "layouts seeded by --seed (never the layouts `rl train --seed` drew)")
  e.add_argument("--layouts", type=int_(1, MAX_LAYOUTS), default=16,
                 help=f"zone layouts with --randomize, the map's own first, 1 to {MAX_LAYOUTS:,d} (default 16)")
  e.add_argument("--robots-per-world", type=int_(1, MAX_ROBOTS), default=None, metavar="K",
                 help=f"robots per world, 1 to {MAX_ROBOTS}, for a policy trained with rl train --robots-per-world "
                 "(any K: the figures are then per robot-episode); a policy of one agent per env runs only at "
                 "the K it was trained with (default: the policy's K)")
  e.add_argument("--episode-length", type=int_(1, MAX_EPISODE_LENGTH), default=None,
                 help=f"env steps of 0.2 s per episode, 1 to {MAX_EPISODE_LENGTH:,d} (default: the policy's "
                 "training episode length)")
  scenario_args.add_map_options(e)
  e.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
  e.set_defaults(func=run_eval)
  return p


# ----------------------------------------------------------------------------- checks


def _at_least_one(args, names) -> None:
  for name in names:
    v = getattr(args, name)
    if v is not None and v < 1:
      raise CliError(f"--{name.replace('_', '-')} must be >= 1; got {v}")


def _check_seed(seed: int) -> None:
  if not 0 <= seed < 2 ** 32:
    raise CliError(f"--seed must lie in [0, 2**32); got {seed}")


def parse_hidden(text: str) -> tuple[int, ...]:
  """--hidden H1,H2,... -> sizes (1 to MAX_HIDDEN_LAYERS layers of 1 to MAX_HIDDEN_UNITS units), or CliError."""
  try:
    sizes = tuple(jcli.strict_int(x) for x in str(text).split(","))
  except ValueError:
    raise CliError(f"--hidden must be comma-separated integers such as 64,64; got {text!r}") from None
  if not 1 <= len(sizes) <= MAX_HIDDEN_LAYERS or not all(1 <= h <= MAX_HIDDEN_UNITS for h in sizes):
    raise CliError(f"--hidden must give 1 to {MAX_HIDDEN_LAYERS} layers of 1 to {MAX_HIDDEN_UNITS} units; "
                   f"got {text!r}")
  return sizes


def parse_devices(text, num_envs: int):
  """--devices N|all -> None (one device, unsharded) or the device count asked for ("all" or int), checked
  against --num-envs where it is a number."""
  if text is None:
    return None
  if str(text).lower() == "all":
    return "all"
  try:
    n = jcli.strict_int(str(text))
  except ValueError:
    raise CliError(f"--devices must be a positive integer or 'all'; got {text!r}") from None
  if not 1 <= n <= MAX_DEVICES:
    raise CliError(f"--devices must be >= 1 and <= {MAX_DEVICES}; got {n}" if n > 0 else
                   f"--devices must be >= 1; got {n}")
  if num_envs % n:
    raise CliError(f"--num-envs ({num_envs}) must be a multiple of --devices ({n}): each device steps "
                   "an equal share of the envs")
  return n


def check_batch(num_envs: int, num_steps: int) -> None:
  """--num-envs x --num-steps (the rollout buffer's rows) at most MAX_BATCH, or CliError."""
  if num_envs * num_steps > MAX_BATCH:
    raise CliError(f"--num-envs x --num-steps must be at most 2**26 = {MAX_BATCH:,d} (the rollout buffer's "
                   f"rows); got {num_envs} x {num_steps} = {num_envs * num_steps:,d}")


def check_robot_batch(args, robots: int) -> None:
  """rl train --robots-per-world K: the rollout's robot rows (--num-envs x K x --num-steps) at most
  MAX_BATCH and split by --minibatches, and no --devices (one device trains the per-robot policy); else
  CliError."""
  rows = args.num_envs * robots * args.num_steps
  if rows > MAX_BATCH:
    raise CliError(f"--num-envs x --robots-per-world x --num-steps must be at most 2**26 = {MAX_BATCH:,d} (the "
                   f"rollout buffer's rows, one per robot); got {args.num_envs} x {robots} x {args.num_steps} = "
                   f"{rows:,d}")
  if rows % args.minibatches:
    raise CliError(f"--minibatches ({args.minibatches}) must divide --num-envs x --robots-per-world x --num-steps "
                   f"({rows}): every robot-step is a sample")
  if args.devices is not None:
    raise CliError("--devices with --robots-per-world: the per-robot policy trains on one device (the worlds "
                   "are not sharded yet); leave out --devices")


def _check_device_minibatches(args, n_dev: int) -> None:
  if (args.num_envs // n_dev * args.num_steps) % args.minibatches:
    raise CliError(f"--minibatches ({args.minibatches}) must divide each device's batch, --num-envs / "
                   f"--devices x --num-steps ({args.num_envs // n_dev} x {args.num_steps}): each device "
                   "splits its own share into minibatches")


def check_out_dir(out: Path, overwrite: bool) -> None:
  """--out is missing, empty, an earlier run's folder (only POLICY_OUTPUTS) or --overwrite; else CliError.

  Nothing is created here (a command refused later leaves no folder behind): the
  nearest existing folder is proved writable, and `run_train` creates --out once
  every option, the devices included, has been checked.
  """
  if out.exists() and not out.is_dir():
    raise CliError(f"--out {out}: exists and is not a folder")
  if out.is_dir() and not overwrite:
    try:
      others = sorted(p.name for p in out.iterdir() if p.name not in POLICY_OUTPUTS)
    except OSError as e:
      raise CliError(f"--out {out}: cannot list it ({e.strerror or e})") from None
    if others:
      raise CliError(f"--out {out}: not empty and not an earlier policy folder (it holds {others[0]!r}); "
                     "pass --overwrite to write into it anyway")
  jcli.check_creatable(out)


def _finite(v):
  """JSON-safe copy: non-finite floats become None."""
  if isinstance(v, float):
    return v if math.isfinite(v) else None
  if isinstance(v, dict):
    return {k: _finite(x) for k, x in v.items()}
  if isinstance(v, (list, tuple)):
    return [_finite(x) for x in v]
  return v


# ----------------------------------------------------------------------------- train


def _progress_line(point: dict, total: int) -> str:
  return (f"jaxfilters rl train: {int(point['env_steps']):>12,d}/{total:,d} env steps  "
          f"{point['steps_per_s']:>10,.0f} steps/s  return {point['return']:8.2f}  "
          f"success {100 * point['success']:5.1f}%  goals/episode {point['goals_reached']:5.2f}  "
          f"keepout entries {point['keepout_entries']:.3f}  collisions {point['collisions']:.3f}  "
          f"speed-excess {point['speed_violation_s']:.3f} s"
          + (f"  robot collisions {point['robot_collisions']:.3f}" if "robot_collisions" in point else ""))


def run_train(args) -> int:
  """Runs `jaxfilters rl train` with parsed arguments; returns the exit code (0).

  Raises:
    CliError: a bad option value or output folder (before anything is built).
  """
  t_start = time.perf_counter()
  _at_least_one(args, ("timesteps", "layouts", "num_envs", "num_steps", "minibatches", "episode_length", "evals",
                       "num_eval"))
  _check_seed(args.seed)
  hidden = parse_hidden(args.hidden)
  check_batch(args.num_envs, args.num_steps)
  robots = args.robots_per_world
  if robots is None:
    if (args.num_envs * args.num_steps) % args.minibatches:
      raise CliError(f"--minibatches ({args.minibatches}) must divide --num-envs x --num-steps "
                     f"({args.num_envs * args.num_steps})")
  else:
    check_robot_batch(args, robots)
  devices = parse_devices(args.devices, args.num_envs)
  if isinstance(devices, int):
    _check_device_minibatches(args, devices)
  from sims.rl.ppo import MAX_ENV_STEPS, plan_training
  try:
    calls = plan_training(args.timesteps, args.num_envs, args.num_steps, args.evals)
  except ValueError as e:
    raise CliError(f"--timesteps {args.timesteps} --evals {args.evals} --num-envs {args.num_envs} "
                   f"--num-steps {args.num_steps}: {e}") from None
  if robots is not None and sum(calls) * args.num_envs * args.num_steps * robots > MAX_ENV_STEPS:
    raise CliError(f"--timesteps {args.timesteps} rounded up to whole PPO iterations is "
                   f"{sum(calls) * args.num_envs * args.num_steps:,d} world steps, x --robots-per-world {robots} = "
                   f"{sum(calls) * args.num_envs * args.num_steps * robots:,d} robot-steps, above {MAX_ENV_STEPS:,d} "
                   "(the trainer counts robot-steps in an int32)")
  out = Path(args.out)
  check_out_dir(out, args.overwrite)

  import jax

  from sims.scale import sharding

  mesh = None
  if devices is not None:
    try:
      mesh = sharding.make_mesh(devices)
      sharding.check_divisible(args.num_envs, mesh)
    except ValueError as e:
      raise CliError(f"--devices: {e} (the envs are --num-envs)") from None
  n_dev = 1 if mesh is None else int(mesh.devices.size)
  if devices == "all":                # a device count given as a number was checked before --out
    _check_device_minibatches(args, n_dev)
  jcli.prepare_out(out)               # every option checked: only now is --out created
  from sims.rl.policy import save_policy
  from sims.rl.ppo import EVAL_KEYS, GymnaxAdapter, make_ppo, plot_curve, replicas_identical, train_with_curve
  from sims.rl.randomization import training_env
  from sims.rl.env import NavEnvConfig

  env, fn = training_env(None, randomize=args.randomize, seed=args.seed, layouts=args.layouts,
                         robots_per_world=robots or 1,
                         config=NavEnvConfig(keepout=args.keepout, costmap_stop=args.costmap_stop,
                                             agents="world" if robots is None else "per_robot"))
  per_iter = args.num_envs * args.num_steps
  evaluate = {}
  if robots is None:
    adapter = GymnaxAdapter(env, args.episode_length, fn, full_reset=args.randomize)
    algo = make_ppo(adapter, timesteps_per_call=per_iter, num_envs=args.num_envs,
                    num_steps=args.num_steps, num_minibatches=args.minibatches, hidden=hidden)
  else:
    from sims.rl.fleet import FleetAdapter, evaluate_fleet_policy, make_fleet_ppo
    adapter = FleetAdapter(env, args.episode_length, fn, full_reset=args.randomize)
    algo = make_fleet_ppo(adapter, num_worlds=args.num_envs, num_steps=args.num_steps,
                          num_minibatches=args.minibatches, hidden=hidden)
    evaluate = {"evaluate": evaluate_fleet_policy}
  planned = sum(calls) * per_iter
  sizes = f"{calls[0]}" if len(set(calls)) == 1 else f"{calls[0]} or {calls[-1]}"
  dev = jax.devices()[0]
  agents = "" if robots is None else f", one agent per robot of {robots} per world ({planned * robots:,d} robot-steps)"
  print(f"jaxfilters rl train: PPO (rejax) on NavEnv, {planned:,d} env steps ({len(calls)} calls of {sizes} "
        f"iterations of {args.num_envs} envs x {args.num_steps} steps{agents}), "
        f"{'randomised' if args.randomize else 'fixed'} zones and goals, {n_dev} x {dev.device_kind}; compiling",
        file=sys.stderr, flush=True)

  def progress(point):
    print(_progress_line(point, planned), file=sys.stderr, flush=True)

  ts, evals, timing = train_with_curve(adapter, algo, jax.random.PRNGKey(args.seed), calls=calls,
                                       num_eval=args.num_eval, callback=progress, mesh=mesh, **evaluate)
  steps = int(evals["env_steps"][-1])          # counted on the device (the train state's global_step)
  final = {k: v[-1] for k, v in evals.items()}
  per_env = getattr(ts.last_obs.sharding, "spec", None)     # the env batch's sharding after training
  placement = {"env_batch": None if per_env is None else [None if a is None else str(a) for a in per_env],
               "envs_per_device": int(ts.last_obs.addressable_shards[0].data.shape[0]) // (robots or 1)}
  if mesh is not None:
    # Data-parallel PPO keeps the networks identical on every device; a difference is a bug.
    placement["replicas_identical"] = replicas_identical(ts)
    if not placement["replicas_identical"]:
      raise RuntimeError("rl train --devices: the devices' copies of the policy differ after training "
                         "(data-parallel updates must keep them identical); nothing was saved")
  config = {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items() if k != "func"}
  config.update(hidden=list(hidden), env_config=_finite(dataclasses.asdict(env.nav_config)),
                robots_per_world=env.num_robots, env_steps=steps, calls=len(calls), iterations_per_call=calls)
  save_policy(out, algo, ts, env_config=env.nav_config, fleet_config=env.fleet_config,
              episode_length=args.episode_length,
              extra=_finite({"seed": args.seed, "randomize": args.randomize, "env_steps": steps,
                             "final": final}))
  wall = time.perf_counter() - t_start
  compile_s = timing["compile_s"]
  result = {"trainer": "rejax.PPO", "jax": jax.__version__,
            "device": {"kind": dev.device_kind, "platform": dev.platform, "count": n_dev, **placement},
            "timing": {**timing, "wall_s": wall,
                       "env_steps_per_s": steps / timing["train_s"] if timing["train_s"] else None},
            "env_steps": steps, "final": final, "initial": {k: v[0] for k, v in evals.items()},
            "curve": evals, "config": config}
  (out / "results.json").write_text(json.dumps(_finite(result), indent=2) + "\n")
  png = plot_curve(evals, out / "learning_curve.png",
                   f"PPO (rejax) on NavEnv, {n_dev} x {dev.device_kind}: {steps / 1e3:.0f}k env steps in "
                   f"{timing['train_s']:.0f} s")
  print(f"compile {compile_s:.1f} s, train {timing['train_s']:.1f} s "
        f"({result['timing']['env_steps_per_s'] or 0:,.0f} env steps/s), wall {wall:.1f} s")
  for name in (*EVAL_KEYS, *(("robot_collisions",) if robots else ())):
    print(f"  {name:<18} start {result['initial'][name]:9.3f}   end {final[name]:9.3f}")
  print(f"wrote {out / 'policy.json'}, {out / 'policy.msgpack'}, {out / 'results.json'}, {png}")
  return EXIT_OK


# ----------------------------------------------------------------------------- eval

# evaluate_policy's per-episode metrics other than the headline ones, by their output name (a metric
# not named here is reported as NAME_per_episode).
_HEADLINE = ("success", "goals_reached", "keepout_entries", "collisions", "speed_violation_s",
             "speed_violation_after_clip_s", "speed_violation_outside_entry_s", "bad_action", "robot_collisions")
_OTHER_METRICS = {"return": "mean_return", "clipped": "clipped_per_episode", "length": "steps_per_episode",
                  "costmap_stops": "costmap_stops_per_episode"}


def run_eval(args) -> int:
  """Runs `jaxfilters rl eval` with parsed arguments; returns the exit code (0, rule breaks included).

  Raises:
    CliError: a bad option, policy folder or map file (before anything runs).
  """
  t_start = time.perf_counter()
  _at_least_one(args, ("episodes", "layouts", "episode_length"))
  _check_seed(args.seed)
  scenario_args.check_map_args(args)
  from sims.rl.policy import PolicyError, load_policy
  try:
    policy = load_policy(args.policy)
  except PolicyError as e:
    raise CliError(f"--policy: {str(e).splitlines()[0]}") from None
  per_robot = policy.env_config.agents == "per_robot"
  robots = args.robots_per_world or policy.robots_per_world
  if not per_robot and robots != policy.robots_per_world:
    raise CliError(f"--robots-per-world {robots}: the policy at {args.policy} drives a world of "
                   f"{policy.robots_per_world} robot(s) as one agent (trained without --robots-per-world) and runs "
                   "only at that number")
  scenario = scenario_args.scenario_from_args(args, "rl eval", "the RL env")

  import jax
  import numpy as np

  from sims.rl.ppo import GymnaxAdapter, evaluate_policy, first_actions_finite
  from sims.rl.randomization import training_env
  try:
    env, fn = training_env(scenario, randomize=args.randomize, seed=args.seed, config=policy.env_config,
                           layouts=args.layouts, evaluation=True, robots_per_world=robots)
  except ValueError as e:      # the maps cannot host the env (mask resolution, free space)
    raise CliError(f"{scenario.name}: {str(e).splitlines()[0]}") from None
  if not per_robot and env.num_robots != policy.robots_per_world:
    raise CliError(f"--policy {args.policy}: trained with {policy.robots_per_world} robots per world; "
                   f"the env has {env.num_robots}")
  if env.observation_size != policy.observation_size or env.action_size != policy.action_size:
    raise CliError(f"--policy {args.policy}: the policy expects observations of {policy.observation_size} "
                   f"values and gives actions of {policy.action_size}; this env's are {env.observation_size} "
                   f"and {env.action_size} (trained with another observation)")
  length = args.episode_length or policy.episode_length
  if per_robot:
    from sims.rl.fleet import FleetAdapter
    from sims.rl.fleet import evaluate_fleet_policy as evaluate
    adapter = FleetAdapter(env, length, fn, full_reset=args.randomize)
  else:
    evaluate = evaluate_policy
    adapter = GymnaxAdapter(env, length, fn, full_reset=args.randomize)
  key = jax.random.PRNGKey(args.seed)
  # One program: whether the policy's (unclipped) mean action is finite on the first observations of
  # the episodes, and the episodes. A policy whose action is NaN or inf there has weights that
  # overflow float32; the env zeroes its NaN actions and the figures would describe a robot at rest,
  # so none are reported.
  # The weights go in as arguments, not as constants: the compilation cache then serves every policy
  # of the same architecture on the same env (a new checkpoint compiles nothing).
  weights = lambda p: dataclasses.replace(policy, params=p)

  def evaluation(k, p):
    pol = weights(p)
    return (first_actions_finite(adapter, pol.raw_action, k, args.episodes),
            evaluate(adapter, pol.act, k, args.episodes))

  with jax.numpy_rank_promotion("allow"):
    finite, per_episode = jax.jit(evaluation)(key, policy.params)
  finite = np.asarray(finite)
  if not finite.all():
    raise CliError(f"--policy {args.policy}: the policy's actions are not finite (NaN or inf) on "
                   f"{int((~finite).sum())} of the {args.episodes} episodes' first observations (its weights "
                   "overflow float32); no figures reported")
  m = {k: np.asarray(v, np.float64) for k, v in jax.device_get(per_episode).items()}
  result = {
      "episodes": args.episodes,
      "success": float(m["success"].mean()),
      "goals_per_episode": float(m["goals_reached"].mean()),
      "keepout_entries": int(round(m["keepout_entries"].sum())),
      "collisions": int(round(m["collisions"].sum())),
      "speed_excess_s": float(m["speed_violation_s"].mean()),
      # Above the limit the speed filter published at the current controller tick (the robot still
      # slowing down after the clip).
      "speed_excess_after_clip_s": float(m["speed_violation_after_clip_s"].sum()),
      # Above the limit in force outside the ticks where a slower zone is entered: 0 when the clip
      # holds from the tick after every entry.
      "speed_excess_outside_entry_s": float(m["speed_violation_outside_entry_s"].sum()),
      # Steps whose action had a NaN (the env replaced it by 0): a sound policy has none.
      "bad_action_steps": int(round(m["bad_action"].sum())),
      **{_OTHER_METRICS.get(key, f"{key}_per_episode"): float(v.mean()) for key, v in m.items()
         if key not in _HEADLINE},
      "policy": str(args.policy), "seed": args.seed, "map": scenario_args.map_label(args),
      "params": None if args.params is None else str(args.params), "randomize": bool(args.randomize),
      "episode_length": length, "device": jax.devices()[0].device_kind,
  }
  if per_robot:     # each figure above is per robot-episode (each robot's first episode in each world)
    result.update(robots_per_world=robots, robot_episodes=int(m["success"].size),
                  robot_collisions=int(np.rint(m["robot_collisions"].sum())),
                  robot_collisions_per_robot_episode=float(m["robot_collisions"].mean()))
  result["wall_s"] = time.perf_counter() - t_start
  if args.json:
    print(json.dumps(_finite(result)))
    return EXIT_OK
  what = f"{args.episodes} worlds of {robots} robots ({args.episodes * robots} robot-episodes)" if per_robot else \
      f"{args.episodes} episodes"
  print(f"{scenario.name}: {what} of up to {length} steps, seed {args.seed}, "
        f"{'randomised' if args.randomize else 'fixed'} zones and goals ({result['device']}, "
        f"{result['wall_s']:.1f} s)")
  ep = "robot-episode" if per_robot else "episode"       # what each figure is per
  rows = (("success", f"{100 * result['success']:.1f} % of {ep}s reached a goal"),
          (f"goals per {ep}", f"{result['goals_per_episode']:.3f}"),
          ("keepout entries", f"{result['keepout_entries']} in all"),
          ("collisions", f"{result['collisions']} in all"),
          ("bad actions", f"{result['bad_action_steps']} steps in all (NaN actions the env replaced by 0)"),
          ("above speed limit", f"{result['speed_excess_s']:.4f} s per {ep}"),
          ("mean return", f"{result['mean_return']:.3f}"),
          ("clipped command", f"{result['clipped_per_episode']:.4f} m per {ep}"),
          (f"steps per {ep}", f"{result['steps_per_episode']:.1f}"))
  if per_robot:
    rows += (("robot collisions", (f"{result['robot_collisions']} in all, "
                                   f"{result['robot_collisions_per_robot_episode']:.4f} per robot-episode")),)
  for name, value in rows:
    print(f"  {name:<18} {value}")
  return EXIT_OK


__all__ = ["POLICY_OUTPUTS", "check_out_dir", "parse_devices", "parse_hidden", "register_rl", "run_eval",
           "run_train"]
