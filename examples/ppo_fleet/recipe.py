"""The recipe of examples/ppo_fleet: one PPO policy for every robot, trained at K = 8, evaluated at K = 2, 8, 32
and on Nav2's warehouse.

    python examples/ppo_fleet/recipe.py --out examples/ppo_fleet --nav2-maps /path/to/maps/nav2   # one H200
    python examples/ppo_fleet/recipe.py --out /tmp/fleet --nav2-maps /path/to/maps/nav2 --smoke   # CPU, minutes

It runs `jaxfilters rl train --robots-per-world 8 ...` and then `jaxfilters rl eval --json` on layouts
and episodes of evaluation seeds training never draws (K = 2, 8, 32 on the built-in warehouse's random
layouts; K = 8 on Nav2's own warehouse map and masks), each as its own process with the exact command
recorded, and writes OUT/results.json (every command, its wall time and JSON output, the targets met or
not) and the table between the RESULTS markers of OUT/README.md. `--stage train` or `--stage eval` runs
one half (eval reads the policy train wrote into OUT). `--smoke` runs the same commands at a tiny size
(a few steps, one world per evaluation) to check the recipe end to end on a CPU; its figures mean nothing.

Settings (from examples/ppo_nav's single-robot recipe, 99 % success after 24.9 M env steps of 8,192 envs
x 32 steps in 8 minibatches): 2,048 worlds x 8 robots = 16,384 agents, the same 32-step rollouts, 16
minibatches (the same 32,768 samples each), 10 M world steps = 80 M robot-steps, about three times the
single-robot run's samples for a task that adds robot avoidance. Everything else is `rl train`'s
default (2 x 64 tanh MLPs, lr 3e-4, 4 epochs, gamma 0.99, 300-step episodes of 60 s).
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import time
from pathlib import Path

K_TRAIN = 8
TARGETS = {"success": (">=", 0.95), "keepout_entries": ("==", 0), "robot_collisions_per_robot_episode": ("<=", 0.01),
           "speed_excess_outside_entry_s": ("==", 0.0)}
TRAIN_BUDGET_S = 300.0
BEGIN, END = "<!-- RESULTS BEGIN (written by recipe.py) -->", "<!-- RESULTS END -->"


def train_args(out: Path, smoke: bool, timesteps: int, num_envs: int) -> list[str]:
  common = ["--robots-per-world", str(K_TRAIN), "--randomize", "--costmap-stop", "--seed", "0", "--out", str(out),
            "--overwrite"]
  if smoke:
    return ["rl", "train", *common, "--timesteps", "32", "--num-envs", "2", "--num-steps", "4", "--minibatches", "2",
            "--episode-length", "4", "--evals", "1", "--num-eval", "1", "--hidden", "8", "--layouts", "2"]
  return ["rl", "train", *common, "--timesteps", str(timesteps), "--num-envs", str(num_envs), "--num-steps", "32",
          "--minibatches", "16", "--evals", "4", "--num-eval", "64", "--layouts", "16"]


def eval_runs(out: Path, maps: Path, smoke: bool) -> list[tuple[str, list[str]]]:
  """(label, argv) of each evaluation: about 2,048 robot-episodes each (one world each with --smoke)."""
  # Nav2's map and masks as three files, the speed mask read as Nav2's bringup params give it (type 1,
  # base 100, multiplier -1: `rl eval`'s defaults), with the fleet's inflation the policy trained with
  # (`--params nav2_params.yaml` would add bringup's 0.70 m local inflation layer).
  nav2 = ["--map", str(maps / "warehouse.yaml"), "--keepout", str(maps / "warehouse_keepout.yaml"),
          "--speed", str(maps / "warehouse_speed.yaml"), "--speed-type", "1", "--speed-base", "100",
          "--speed-multiplier", "-1"]
  runs = [("random layouts, K = 2", 2, 1024, 1, ["--randomize"]),
          ("random layouts, K = 8", 8, 256, 1, ["--randomize"]),
          ("random layouts, K = 32", 32, 64, 1, ["--randomize"]),
          ("Nav2's warehouse, K = 8", 8, 256, 3, nav2)]
  tiny = ["--episode-length", "3", "--layouts", "2"] if smoke else []
  return [(label, ["rl", "eval", "--policy", str(out), "--robots-per-world", str(k), "--episodes",
                   str(1 if smoke else worlds), "--seed", str(seed), *maps_args, *tiny, "--json"])
          for label, k, worlds, seed, maps_args in runs]


def run(argv: list[str]) -> tuple[float, str]:
  """Runs `python -m jaxfilters ARGV`, passing its stderr through; returns (wall s, stdout)."""
  print("$ jaxfilters " + " ".join(argv), file=sys.stderr, flush=True)
  t = time.perf_counter()
  proc = subprocess.run([sys.executable, "-m", "jaxfilters", *argv], stdout=subprocess.PIPE, text=True, check=False)
  wall = time.perf_counter() - t
  if proc.returncode != 0:
    raise SystemExit(f"recipe.py: `jaxfilters {' '.join(argv)}` exited {proc.returncode}; stopping")
  return wall, proc.stdout


def met(value, op: str, bound) -> bool:
  return {">=": value >= bound, "<=": value <= bound, "==": value == bound}[op]


def table(results: dict) -> str:
  rows = [("| evaluation | robot-episodes | success | goals / robot-episode | keepout entries | robot collisions "
           "/ robot-episode | wall collisions | s above a limit outside entry ticks | command |"),
          "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |"]
  for e in results["evaluations"]:
    r = e["result"]
    rows.append(f"| {e['label']} | {r['robot_episodes']:,d} | {100 * r['success']:.1f} % | "
                f"{r['goals_per_episode']:.2f} | {r['keepout_entries']} | "
                f"{r['robot_collisions_per_robot_episode']:.4f} ({r['robot_collisions']}) | {r['collisions']} | "
                f"{r['speed_excess_outside_entry_s']:.3f} | `jaxfilters {' '.join(e['argv'])}` |")
  t = results.get("train")
  lines = []
  if t:
    timing = t["results"]["timing"]
    lines.append(f"Trained on {t['results']['device']['kind']} by `jaxfilters {' '.join(t['argv'])}`: "
                 f"{t['results']['env_steps']:,d} world steps ({t['results']['curve']['agent_steps'][-1]:,.0f} "
                 f"robot-steps) in **{t['wall_s']:.1f} s from the interpreter's start to its exit** "
                 f"({timing['compile_s']:.1f} s compiling, {timing['train_s']:.1f} s training).")
  if t:
    lines.append(f"Training within {TRAIN_BUDGET_S:.0f} s: {'met' if t['within_budget'] else 'NOT met'}.")
  lines.append(f"Targets at K = {K_TRAIN} on held-out layouts: " + ", ".join(
      f"{name} {op} {bound}: {'met' if ok else 'NOT met'}" for name, (op, bound, ok) in results["targets"].items()))
  if results["smoke"]:
    lines.insert(0, "**Smoke run (--smoke): a few steps at a tiny size; the figures mean nothing.**")
  return "\n\n".join(lines) + "\n\n" + "\n".join(rows) + "\n"


def write_readme(readme: Path, text: str) -> None:
  if not readme.is_file():
    readme.write_text(f"# examples/ppo_fleet\n\n{BEGIN}\n{text}{END}\n")
    return
  body = readme.read_text()
  if BEGIN not in body or END not in body:
    raise SystemExit(f"recipe.py: {readme} has no {BEGIN} ... {END} section to write the table into")
  head, rest = body.split(BEGIN, 1)
  readme.write_text(head + BEGIN + "\n" + text + END + rest.split(END, 1)[1])


def main(argv=None) -> int:
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("--out", type=Path, required=True, help="folder of the policy, results.json and README.md")
  p.add_argument("--nav2-maps", type=Path, required=True,
                 help="folder with Nav2's warehouse.yaml, warehouse_keepout.yaml, warehouse_speed.yaml "
                      "(and their images)")
  p.add_argument("--stage", choices=("all", "train", "eval"), default="all", help="(default all)")
  p.add_argument("--smoke", action="store_true", help="the same commands at a tiny size (CPU check)")
  p.add_argument("--timesteps", type=int, default=10_000_000, help="world steps to train (default 10,000,000)")
  p.add_argument("--num-envs", type=int, default=2048, help="worlds of 8 robots trained at once (default 2,048)")
  args = p.parse_args(argv)
  needed = ("warehouse.yaml", "warehouse_keepout.yaml", "warehouse_speed.yaml")
  missing = [n for n in needed if not (args.nav2_maps / n).is_file()]
  if args.stage != "train" and missing:
    p.error(f"--nav2-maps {args.nav2_maps}: missing {', '.join(missing)}")
  args.out.mkdir(parents=True, exist_ok=True)
  path = args.out / "results.json"
  results = json.loads(path.read_text()) if args.stage == "eval" and path.is_file() else {}
  results.update(smoke=args.smoke, k_train=K_TRAIN)
  if args.stage in ("all", "train"):
    argv_t = train_args(args.out, args.smoke, args.timesteps, args.num_envs)
    wall, _ = run(argv_t)
    train_results = json.loads((args.out / "results.json").read_text())     # what rl train wrote
    results = {"smoke": args.smoke, "k_train": K_TRAIN,
               "train": {"argv": argv_t, "wall_s": wall, "within_budget": wall <= TRAIN_BUDGET_S,
                         "results": train_results}}
    path.write_text(json.dumps(results, indent=1) + "\n")
  if args.stage in ("all", "eval"):
    evaluations = []
    for label, argv_e in eval_runs(args.out, args.nav2_maps, args.smoke):
      wall, stdout = run(argv_e)
      evaluations.append({"label": label, "argv": argv_e, "wall_s": wall, "result": json.loads(stdout)})
    results["evaluations"] = evaluations
    k8 = next(e["result"] for e in evaluations if re.match(r"random layouts, K = 8$", e["label"]))
    results["targets"] = {name: (op, bound, met(k8[name], op, bound)) for name, (op, bound) in TARGETS.items()}
    path.write_text(json.dumps(results, indent=1) + "\n")
    write_readme(args.out / "README.md", table(results))
    print(table(results))
  return 0


if __name__ == "__main__":
  sys.exit(main())
