"""Reinforcement learning on the fleet: MuJoCo Playground's env contract, PPO, policy files, Gymnasium.

Rooms: `env` (NavEnv, NavEnvConfig, NavModel: Playground's MjxEnv), `task` (NavTask, the data every
step reads), `kernels` (the env's per-step kernels), `observation` (what a robot observes), `agents`
(one agent per robot: robot-robot contacts, respawns), `randomization` (zones and goals drawn per
env), `adapter` (the env as a gymnax environment for rejax), `ppo` (training and evaluation),
`fleet` (one policy shared by every robot of a world: its adapter, PPO and evaluation),
`policy` (policy files), `gym` (Gymnasium's Env and VectorEnv; needs the `rl` extra), `registry`
(the envs by name: Playground's `load`/`get_default_config`, Gymnasium ids), `brax_compat` (Brax's
own PPO on this jax).

Imports: `jaxfilters`, `sims.fleet`, `sims.scale` and this package.

`from sims.rl import NavEnv` (and the other names of `sims.rl.env`, the module this package
replaced) keeps working; the names load on first use, so `import sims.rl.policy` does not
import MuJoCo Playground. Importing the package registers the Gymnasium ids of `sims.rl.registry`
(`jaxfilters/Nav-v0`, `jaxfilters/NavRandomized-v0`) where Gymnasium is installed.
"""

import importlib

from sims.rl import registry as _registry

_ENV_NAMES = ("AHEAD", "KEEPOUT_MODES", "MODES", "NavEnv", "NavEnvConfig", "NavModel", "State",
              "clip_command", "nav_model")
__all__ = sorted(_ENV_NAMES + ("NavTask",))


def __getattr__(name):
  if name in _ENV_NAMES:
    return getattr(importlib.import_module("sims.rl.env"), name)
  if name == "NavTask":
    return importlib.import_module("sims.rl.task").NavTask
  raise AttributeError(f"module 'sims.rl' has no attribute {name!r}")


_registry.register_gymnasium()
