"""sims: an MJX-simulated robot fleet driven through jaxfilters' Nav2 costmap filters.

One world is a warehouse with K differential-drive robots (MuJoCo MJX, planar
base, velocity actuators, no contacts). `FleetEnv.reset(key)` and
`FleetEnv.step(state, action)` act on one world; worlds are batched with one
`jax.vmap` and rolled out with `lax.scan` (`FleetEnv.rollout_fn`). Each step
runs, per robot: speed filter -> navigation field -> local planner on a
rolling local costmap (static layer, other robots, inflation, keepout filter)
-> clip to the speed limit -> mjx.step, and accumulates compliance metrics.

`sims` imports `jaxfilters`; `jaxfilters` never imports `sims`. The public
names below are imported lazily, so a command can set XLA options before
JAX starts.

The fleet library is the modules of this package; its entry points (the
`fleet` and `bench` commands and the scripts) live in `sims/scripts/`.
`NavGymEnv` and `NavVectorEnv` (Gymnasium interfaces to the RL env) need the
`rl` extra; `import sims` imports neither Gymnasium nor MuJoCo Playground.
`sims/quiet_mjx.py` says how the two lines mujoco.mjx prints without
warp-lang are kept off the screen.
"""

import importlib

_EXPORTS = {
    "FleetConfig": "sims.config", "PlannerConfig": "sims.config", "RobotConfig": "sims.config",
    "FleetEnv": "sims.env", "Frame": "sims.env", "Rollout": "sims.env", "WorldState": "sims.env",
    "Metrics": "sims.metrics", "summarize": "sims.metrics",
    "NavField": "sims.navigation", "distance_field": "sims.navigation",
    "Scenario": "sims.scenario",
    "World": "sims.world", "WorldParams": "sims.world", "build_world": "sims.world",
    "fleet_throughput": "sims.bench",
    "NavGymEnv": "sims.gym_env", "NavVectorEnv": "sims.gym_env",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name):
  if name in _EXPORTS:
    return getattr(importlib.import_module(_EXPORTS[name]), name)
  raise AttributeError(f"module 'sims' has no attribute {name!r}")


def __dir__():
  return sorted(list(globals()) + __all__)
