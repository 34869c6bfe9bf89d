"""Draws a trained policy driving in zone layouts it never saw, into a PNG.

    jaxfilters rl train --randomize ... --out out/policy
    python -m sims.commands.rl_picture out/policy docs/rl_policy.png [--seed 1001] [--layouts 4] [--steps 300]

Each panel is one random layout of the built-in warehouse (`sims.fleet.layouts`, drawn with --seed: pick
a seed training did not use) with its keepout zones, speed zones and goal stations, and one
episode of the policy's mean action from a spawn point of that layout: the track coloured by the
speed limit in force, goals reached marked. The README's RL picture is made by these commands.
Exit codes: 0 written, 2 a policy folder that cannot be loaded or a bad option.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from jaxfilters.cli import ArgumentParser  # one-line errors, exit code 2


def rollout(env, policy, layout: int, key, steps: int):
  """One episode of `policy` in `layout` of `env`'s bank: (xy [T + 1, 2], goals reached xy [G, 2], metrics)."""
  import jax
  import jax.numpy as jnp

  model = env.mjx_model.tree_replace({"task.layout": jnp.asarray(layout, jnp.int32)})
  reset = jax.jit(lambda m, k: env.with_model(m).reset(k))
  step = jax.jit(lambda m, s: env.with_model(m).step(s, policy.act(s.obs)))
  st = reset(model, key)
  xy, goals = [np.asarray(st.data.qpos[0, :2])], []
  totals = {"keepout_entries": 0.0, "collisions": 0.0, "goals_reached": 0.0, "speed_violation_s": 0.0}
  stations = np.asarray(env.mjx_model.task.bank.nav.stations)
  for _ in range(steps):
    goal = int(st.info["goal"][0])
    st = step(model, st)
    xy.append(np.asarray(st.data.qpos[0, :2]))
    for k in totals:
      totals[k] += float(st.metrics[k])
    if float(st.metrics["goals_reached"]) > 0:
      goals.append(stations[goal])
    if float(st.done) > 0:
      break
  return np.asarray(xy), np.asarray(goals).reshape(-1, 2), totals


def main(argv=None) -> int:
  ap = ArgumentParser(prog="python -m sims.commands.rl_picture",
                               description="Draw a policy's episodes in zone layouts it never saw into a PNG.")
  ap.add_argument("policy", type=Path, help="policy folder written by jaxfilters rl train")
  ap.add_argument("out", type=Path, help="PNG to write")
  ap.add_argument("--seed", type=int, default=1001, help="seed of the random layouts (default 1001)")
  ap.add_argument("--layouts", type=int, default=4, help="panels, 1..8 (default 4)")
  ap.add_argument("--steps", type=int, default=300, help="env steps of 0.2 s per episode, >= 1 (default 300)")
  args = ap.parse_args(argv)
  if not 1 <= args.layouts <= 8:
    ap.error(f"--layouts must lie in 1..8; got {args.layouts}")
  if args.steps < 1:
    ap.error(f"--steps must be >= 1; got {args.steps}")

  from sims.rl.policy import PolicyError, load_policy
  try:
    policy = load_policy(args.policy)
  except (PolicyError, FileNotFoundError) as e:
    print(f"rl_picture: {e}", file=sys.stderr)
    return 2

  import jax
  import matplotlib
  matplotlib.use("Agg")
  import matplotlib.pyplot as plt
  from matplotlib.collections import LineCollection

  from sims.record.render import draw_scenario
  from sims.rl.env import NavEnv

  env = NavEnv.create(config=policy.env_config, fleet_config=policy.fleet_config, layouts=args.layouts + 1,
                      layout_seed=args.seed)
  cols = min(args.layouts, 2)
  rows = -(-args.layouts // cols)
  fig, axes = plt.subplots(rows, cols, figsize=(6.4 * cols, 4.6 * rows), dpi=90, squeeze=False)
  max_speed = env.fleet_config.robot.max_speed
  for i in range(args.layouts):
    ax = axes[i // cols][i % cols]
    world = env.layout_worlds[i + 1]
    draw_scenario(ax, world.scenario, max_speed=max_speed)
    xy, goals, totals = rollout(env, policy, i + 1, jax.random.PRNGKey(args.seed + i), args.steps)
    seg = np.stack([xy[:-1], xy[1:]], axis=1)
    speed = np.linalg.norm(xy[1:] - xy[:-1], axis=1) / env.fleet_config.step_seconds
    lc = LineCollection(seg, cmap="viridis", linewidths=2.2)
    lc.set_array(speed)
    lc.set_clim(0.0, max_speed)
    ax.add_collection(lc)
    ax.plot(*world.stations.T, "k+", ms=5, alpha=0.5, label="goal stations")
    ax.plot(*xy[0], "o", color="tab:blue", ms=7, label="start")
    if len(goals):
      ax.plot(*goals.T, "*", color="gold", mec="k", ms=13, label="goal reached")
    ax.set_title(f"layout {i + 1} (seed {args.seed}): {int(totals['goals_reached'])} goals, "
                 f"{int(totals['keepout_entries'])} keepout entries, {int(totals['collisions'])} collisions",
                 fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
  for j in range(args.layouts, rows * cols):
    axes[j // cols][j % cols].axis("off")
  fig.colorbar(lc, ax=axes, shrink=0.6, label="speed (m/s)")
  fig.suptitle(f"policy {args.policy.name}: {args.steps * env.fleet_config.step_seconds:g} s episodes in layouts "
               "it never saw (red: keepout, tinted: speed zones)", fontsize=10)
  args.out.parent.mkdir(parents=True, exist_ok=True)
  fig.savefig(args.out)
  plt.close(fig)
  print(f"wrote {args.out}")
  return 0


if __name__ == "__main__":
  sys.exit(main())
