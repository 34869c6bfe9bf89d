"""Lane keeping in the fleet: Nav2's AsymmetricInflationLayer against the plain InflationLayer.

    python -m sims.commands.lane_keeping --out docs/lane_keeping.png     # about 3 min on 2 CPU cores

A 20 m corridor 2.4 m wide (walls above and below), robots driving between goal stations along
it in both directions. Two runs from the same spawns and goals, each a local costmap params file,
with the same planner: its mean-cost critic on (`PlannerConfig.cost_weight`, 8 by default; the
fleet's default planner scores only the highest cost along a candidate, which gives a robot
standing in a band of raised costs no way out of it):

* plain: Nav2's InflationLayer (radius 1.4 m, cost_scaling_factor 6);
* lanes: Nav2's AsymmetricInflationLayer (radius 1.4 m, left 1.5, right 6, so its pass 1 is the
  plain run's layer), each robot with its own plan (the descent of its goal's navigation field).

For every recorded step where a robot drives along the corridor (|vx| > 0.1 m/s) its offset to
the right of the corridor's centre line, seen in its direction of travel, is measured; the figure
draws both runs' trajectories coloured by direction and prints the mean offset and the share of
such steps on the right half. Keepout entries and contacts are printed from the fleet's metrics.
"""

from __future__ import annotations

import math
import sys
import tempfile
from pathlib import Path

import jax
import numpy as np

import jaxfilters as jf
from jaxfilters import cli as jcli
from jaxfilters.grid import OccupancyGrid
from sims.fleet.config import FleetConfig, PlannerConfig
from sims.fleet.env import FleetEnv
from sims.fleet.metrics import summarize
from sims.fleet.scenario import Scenario

RES = 0.05
LENGTH, WIDTH, WALL = 20.0, 2.4, 0.3
LAYERS = {
    "plain": ('plugin: "nav2_costmap_2d::InflationLayer"\n        inflation_radius: 1.4\n'
              '        cost_scaling_factor: 6.0'),
    "lanes": ('plugin: "nav2_costmap_2d::AsymmetricInflationLayer"\n        inflation_radius: 1.4\n'
              '        cost_scaling_factor_left: 1.5\n        cost_scaling_factor_right: 6.0\n'
              '        goal_distance_threshold: 0.5'),
}
PARAMS = """\
local_costmap:
  local_costmap:
    ros__parameters:
      resolution: {res}
      robot_radius: 0.22
      plugins: ["layer"]
      layer:
        {layer}
"""


def corridor() -> tuple[OccupancyGrid, OccupancyGrid, float]:
  """The corridor map (walls 100, free 0), an empty mask of its shape, and the centre line's y."""
  h = int(round((WIDTH + 2 * WALL) / RES))
  w = int(round((LENGTH + 2 * WALL) / RES))
  wall = int(round(WALL / RES))
  occ = np.zeros((h, w), np.int8)
  occ[:wall], occ[-wall:], occ[:, :wall], occ[:, -wall:] = 100, 100, 100, 100
  grid = OccupancyGrid.create(occ, RES, (0.0, 0.0, 0.0))
  return grid, OccupancyGrid.create(np.zeros_like(occ), RES, (0.0, 0.0, 0.0)), h * RES / 2


def layers(name: str, folder: Path):
  path = folder / f"{name}.yaml"
  path.write_text(PARAMS.format(res=RES, layer=LAYERS[name]))
  return jf.load_params(path, costmaps=("local_costmap",)).local_costmap.layers


def run(name: str, folder: Path, *, robots: int, steps: int, seed: int, cost_weight: float):
  """(poses [T, K, 3], velocities [T, K, 2] in the world frame, fleet summary) of one run."""
  grid, empty, _ = corridor()
  scenario = Scenario("corridor", grid, empty, empty, layers=layers(name, folder))
  config = FleetConfig(robots_per_world=robots, num_stations=10,
                       planner=PlannerConfig(cost_weight=cost_weight))
  env = FleetEnv.create(scenario, config, seed=seed)
  states = env.reset_fn()(env.params, env.world_keys(jax.random.PRNGKey(seed), 1))
  states, frames = env.rollout_fn(steps)(env.params, states)
  pose = np.asarray(frames.pose)[:, 0]                           # [T, K, 3]
  step_s = env.config.step_seconds
  vel = np.gradient(pose[..., :2], step_s, axis=0)
  summary = summarize(states.metrics, zone_labels=env.world.zone_labels, zone_limits=env.world.zone_limits,
                      zone_speed=env.world.zone_speed, speed_tolerance=env.config.speed_tolerance,
                      seconds=steps * step_s)
  return pose, vel, summary


def right_offsets(pose: np.ndarray, vel: np.ndarray, centre: float) -> np.ndarray:
  """Offsets (m) right of the centre line in the direction of travel, where |vx| > 0.1 m/s."""
  moving = np.abs(vel[..., 0]) > 0.1
  return ((centre - pose[..., 1]) * np.sign(vel[..., 0]))[moving]


def main(argv=None) -> int:
  p = jcli.ArgumentParser(prog="python -m sims.commands.lane_keeping", description=__doc__.split("\n")[0])
  p.add_argument("--out", type=jcli.path_type, default=Path("out/lane_keeping.png"), help="the picture (PNG)")
  p.add_argument("--robots", type=jcli.int_type(2, 16), default=6, help="robots in the corridor, 2 to 16 (default 6)")
  p.add_argument("--seconds", type=jcli.int_type(10, 600), default=90, help="simulated seconds, 10 to 600 (default 90)")
  p.add_argument("--seed", type=jcli.int_type(0, 2 ** 32 - 1), default=0,
                 help="seed of stations, spawns and goals, in [0, 2**32) (default 0)")
  p.add_argument("--cost-weight", type=float, default=8.0,
                 help="the planner's mean-cost critic (PlannerConfig.cost_weight; the fleet's default 0), the "
                 "same in both runs, 0 to 100 (default 8)")
  args = p.parse_args(argv)
  if not (math.isfinite(args.cost_weight) and 0 <= args.cost_weight <= 100):
    p.error(f"argument --cost-weight: must lie in [0, 100]; got {args.cost_weight}")
  if args.out.suffix.lower() != ".png" or args.out.is_symlink() or (args.out.exists() and not args.out.is_file()):
    p.error(f"argument --out: must name a .png file (not a folder or a link); got {args.out}")
  args.out.parent.mkdir(parents=True, exist_ok=True)
  steps = int(round(args.seconds / FleetConfig().step_seconds))
  _, _, centre = corridor()
  results = {}
  with tempfile.TemporaryDirectory() as tmp:
    for name in ("plain", "lanes"):
      pose, vel, summary = run(name, Path(tmp), robots=args.robots, steps=steps, seed=args.seed,
                               cost_weight=args.cost_weight)
      off = right_offsets(pose, vel, centre)
      f = summary["fleet"]
      results[name] = (pose, vel, off)
      print(f"{name:5s}: mean offset right of the centre line {off.mean():+.3f} m, {np.mean(off > 0):.0%} of "
            f"{off.size} moving robot-steps on the right half; goals {f['goals_reached']}, keepout entries "
            f"{f['keepout_entries']}, contacts {f['contacts']}")
  import matplotlib
  matplotlib.use("Agg")
  import matplotlib.pyplot as plt
  grid, _, _ = corridor()
  extent = (0.0, grid.width * RES, 0.0, grid.height * RES)
  fig, axes = plt.subplots(3, 1, figsize=(10, 6.2), layout="constrained", height_ratios=[1, 1, 1.2])
  titles = {"plain": "InflationLayer (radius 1.4 m, factor 6)",
            "lanes": "AsymmetricInflationLayer (left 1.5, right 6)"}
  for ax, name in zip(axes[:2], ("plain", "lanes")):
    pose, vel, off = results[name]
    ax.imshow(np.where(grid.data == 100, 0.25, 1.0), origin="lower", extent=extent, cmap="gray", vmin=0, vmax=1)
    for k in range(pose.shape[1]):
      east = vel[:, k, 0] > 0.1
      west = vel[:, k, 0] < -0.1
      ax.scatter(pose[east, k, 0], pose[east, k, 1], s=2, color="tab:blue")
      ax.scatter(pose[west, k, 0], pose[west, k, 1], s=2, color="tab:orange")
    ax.axhline(centre, color="0.6", lw=0.8, ls="--")
    ax.set_title(f"{titles[name]}: mean {off.mean():+.2f} m right of centre, {np.mean(off > 0):.0%} of steps "
                 "on the right", fontsize=9)
    ax.set_aspect("equal")
    ax.set_ylabel("y (m)")
  axes[1].set_xlabel("x (m)   (blue: driving east, +x; orange: driving west)")
  bins = np.linspace(-WIDTH / 2, WIDTH / 2, 25)
  for name, colour in (("plain", "0.5"), ("lanes", "tab:red")):
    axes[2].hist(results[name][2], bins=bins, density=True, histtype="step", lw=1.5, color=colour,
                 label=titles[name].split(":")[0])
  axes[2].axvline(0.0, color="0.6", lw=0.8, ls="--")
  axes[2].set_xlabel("offset right of the centre line, in the direction of travel (m)")
  axes[2].set_ylabel("share of steps")
  axes[2].legend(fontsize=8)
  fig.suptitle(f"Lane keeping in the fleet: {args.robots} robots, {args.seconds:g} s in a {LENGTH:g} m x "
               f"{WIDTH:g} m corridor, each robot's local costmap with its own plan (cost_weight "
               f"{args.cost_weight:g})", fontsize=10)
  fig.savefig(args.out, dpi=80)
  print(f"wrote {args.out}")
  return 0


if __name__ == "__main__":
  sys.exit(main())
