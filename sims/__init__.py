"""sims: an MJX-simulated robot fleet driven through jaxfilters' Nav2 costmap filters.

One world is a warehouse with K differential-drive robots (MuJoCo MJX, planar
base, velocity actuators, no contacts). `FleetEnv.reset(key)` and
`FleetEnv.step(state, action)` act on one world; worlds are batched with one
`jax.vmap` and rolled out with `lax.scan` (`FleetEnv.rollout_fn`). Each step
runs, per robot: speed filter -> navigation field -> local planner on a
rolling local costmap (static layer, other robots, inflation, keepout filter)
-> clip to the speed limit -> mjx.step, and accumulates compliance metrics.

The packages, each a room with one concern (docs/house.md draws them):

* `sims.fleet`: the simulated fleet (config, scenario, layouts, world, navigation, planner,
  local costmap, metrics, env). Imports `jaxfilters` only.
* `sims.scale`: device meshes and throughput benchmarks. Imports `sims.fleet`.
* `sims.rl`: the RL env (Playground contract), PPO, policy files, Gymnasium. Imports
  `sims.fleet` and `sims.scale`.
* `sims.record`: rosbag2/MCAP bags and pictures. Imports `sims.fleet`.
* `sims.tuning`: zone parameters tuned with `jax.grad`. Imports `sims.fleet`.
* `sims.commands`: the `jaxfilters fleet | bench | rl` commands and the scripts, on top of all.

`sims` imports `jaxfilters`; `jaxfilters` never imports `sims`. The public
names below are imported lazily, so a command can set XLA options before
JAX starts, and `import sims` imports neither Gymnasium nor MuJoCo Playground.

The flat module paths of earlier releases (`sims.config`, `sims.env`, `sims.gym_env`,
`sims.scripts.fleet`, ...) moved into these packages; CHANGELOG.md lists each old path
with its new one. Importing `sims` installs no import hook.
"""

import importlib

_EXPORTS = {
    "FleetConfig": "sims.fleet.config", "PlannerConfig": "sims.fleet.config",
    "RobotConfig": "sims.fleet.config",
    "FleetEnv": "sims.fleet.env", "Frame": "sims.fleet.env", "Rollout": "sims.fleet.env",
    "WorldState": "sims.fleet.env",
    "Metrics": "sims.fleet.metrics", "summarize": "sims.fleet.metrics",
    "NavField": "sims.fleet.navigation", "distance_field": "sims.fleet.navigation",
    "Scenario": "sims.fleet.scenario",
    "World": "sims.fleet.world", "WorldParams": "sims.fleet.world", "build_world": "sims.fleet.world",
    "fleet_throughput": "sims.scale.bench",
    "NavGymEnv": "sims.rl.gym", "NavVectorEnv": "sims.rl.gym",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name):
  if name in _EXPORTS:
    return getattr(importlib.import_module(_EXPORTS[name]), name)
  raise AttributeError(f"module 'sims' has no attribute {name!r}")


def __dir__():
  return sorted(list(globals()) + __all__)
