"""The RL envs by name: MuJoCo Playground's `registry` functions, and Gymnasium ids.

Playground's users load an env by name (`mujoco_playground.registry.load`); the same four
functions here load this project's MJX env (`sims.rl.env.NavEnv`, velocity mode):

    from sims.rl import registry

    registry.ALL_ENVS                                   # ('JaxfiltersNav', 'JaxfiltersNavRandomized')
    config = registry.get_default_config("JaxfiltersNav")   # an ml_collections ConfigDict
    env = registry.load("JaxfiltersNav", config_overrides={"env.keepout": "penalty"})
    randomizer = registry.get_domain_randomizer("JaxfiltersNavRandomized")   # or None

`JaxfiltersNav` is the built-in warehouse with its own zones; `JaxfiltersNavRandomized` adds
a bank of `layouts` random zone layouts and returns `randomize_zones_and_goals` as its domain
randomizer (Brax's `randomization_fn`: a layout, limits and goals per env). The config holds
what `load` applies (every key is read): `episode_length` and `action_repeat` (read by Brax's
training wrappers, as in Playground's configs), `robots_per_world`, `seed` (stations and
spawns), `layouts`, `layout_seed`, and `env` (the fields of `NavEnvConfig`). `ctrl_dt` is not a
key: the env's step is the fleet's costmap period (`env.dt`, 0.2 s).

Gymnasium (the `rl` extra) knows the same envs by id once this package is imported (Gymnasium
1.x loads no plugins by itself): `import sims.rl` registers `jaxfilters/Nav-v0` and
`jaxfilters/NavRandomized-v0` with string entry points (`sims.rl.gym:NavGymEnv` and, for
`gymnasium.make_vec`, `sims.rl.gym:NavVectorEnv`), so registering imports neither MJX nor
Playground:

    import gymnasium
    import sims.rl
    gymnasium.register_envs(sims.rl)                    # Gymnasium's no-op that names the import
    env = gymnasium.make("jaxfilters/Nav-v0")
    envs = gymnasium.make_vec("jaxfilters/NavRandomized-v0", num_envs=64)

`gymnasium.make("sims.rl:jaxfilters/Nav-v0")` does the import itself.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import numbers

__all__ = ["ALL_ENVS", "GYM_IDS", "get_default_config", "get_domain_randomizer", "load", "register_gymnasium"]

ALL_ENVS = ("JaxfiltersNav", "JaxfiltersNavRandomized")
GYM_IDS = {"jaxfilters/Nav-v0": {}, "jaxfilters/NavRandomized-v0": {"randomize": True}}
DEFAULT_LAYOUTS = 16       # the `jaxfilters rl train --randomize` default


def _check_name(env_name) -> str:
  if env_name not in ALL_ENVS:
    raise ValueError(f"Env {env_name!r} not found. Available envs: {ALL_ENVS}")
  return env_name


def get_default_config(env_name: str):
  """The ConfigDict `load` applies for `env_name` (module docstring).

  Raises:
    ValueError: a name not in `ALL_ENVS`.
  """
  from ml_collections import config_dict

  from sims.rl.env import NavEnvConfig
  from sims.rl.gym import DEFAULT_EPISODE_LENGTH

  _check_name(env_name)
  return config_dict.ConfigDict({
      "episode_length": DEFAULT_EPISODE_LENGTH,
      "action_repeat": 1,
      "robots_per_world": 1,
      "seed": 0,
      "layouts": DEFAULT_LAYOUTS if env_name == "JaxfiltersNavRandomized" else 1,
      "layout_seed": 0,
      "env": dataclasses.asdict(NavEnvConfig()),
  })


def _int(config, key, lo, hi):
  v = config[key]
  if isinstance(v, bool) or not isinstance(v, numbers.Integral) or not lo <= v <= hi:
    raise ValueError(f"registry.load: config.{key} must be an integer in [{lo:,d}, {hi:,d}]; got {v!r}")
  return int(v)


def load(env_name: str, config=None, config_overrides: dict | None = None):
  """A `NavEnv` built from `config` (default: `get_default_config(env_name)`) and overrides.

  Args:
    env_name: one of `ALL_ENVS`.
    config: a ConfigDict with exactly the keys of `get_default_config(env_name)`, or None.
    config_overrides: flattened keys ("env.keepout", "layouts") and values, applied on a copy
      of the config (Playground's `update_from_flattened_dict`).

  Returns:
    sims.rl.env.NavEnv in velocity mode.

  Raises:
    ValueError: an unknown name; a config or override key that the config does not have; a
      value that the config's checks, `NavEnvConfig`, `FleetConfig` or `NavEnv.create` refuse.
  """
  from ml_collections import config_dict

  from sims.fleet.config import FleetConfig
  from sims.rl.env import MAX_LAYOUTS, NavEnv, NavEnvConfig

  default = get_default_config(env_name)
  if config is None:
    config = default
  if not isinstance(config, config_dict.ConfigDict):
    raise ValueError(f"registry.load: config must be an ml_collections ConfigDict (get_default_config's); "
                     f"got {type(config).__name__}")
  config = config_dict.ConfigDict(config.to_dict())   # a copy: overrides never touch the caller's
  want, have = set(default.keys()), set(config.keys())
  if have != want:
    raise ValueError(f"registry.load: config keys must be {sorted(want)}; missing {sorted(want - have)}, "
                     f"unknown {sorted(have - want)}")
  if set(config.env.keys()) != set(default.env.keys()):
    raise ValueError(f"registry.load: config.env keys must be NavEnvConfig's fields {sorted(default.env.keys())}; "
                     f"got {sorted(config.env.keys())}")
  if config_overrides:
    if not isinstance(config_overrides, dict):
      raise ValueError(f"registry.load: config_overrides must be a dict; got {type(config_overrides).__name__}")
    flat = {"env." + k for k in default.env.keys()} | (want - {"env"})
    unknown = sorted(str(k) for k in config_overrides if k not in flat)
    if unknown:
      raise ValueError(f"registry.load: config_overrides has unknown keys {unknown}; known: {sorted(flat)}")
    config.lock()
    config.update_from_flattened_dict(dict(config_overrides))
  _int(config, "episode_length", 1, 2 ** 24)
  _int(config, "action_repeat", 1, 1)          # the env repeats no action: one env step per action
  robots = _int(config, "robots_per_world", 1, 2 ** 20)
  seed = _int(config, "seed", 0, 2 ** 32 - 1)
  layouts = _int(config, "layouts", 1, MAX_LAYOUTS)
  layout_seed = _int(config, "layout_seed", 0, 2 ** 32 - 1)
  try:
    nav = NavEnvConfig(**config.env.to_dict())
  except TypeError as e:
    raise ValueError(f"registry.load: config.env: {e}") from None
  if nav.mode != "velocity":
    raise ValueError(f"registry.load: config.env.mode must be 'velocity' (the registered envs take (v, w) "
                     f"actions); got {nav.mode!r}")
  return NavEnv.create(fleet_config=FleetConfig(robots_per_world=robots), config=nav, seed=seed,
                       layouts=layouts, layout_seed=layout_seed)


def get_domain_randomizer(env_name: str):
  """Brax's `randomization_fn` for `env_name`: `randomize_zones_and_goals` for
  `JaxfiltersNavRandomized`, None for `JaxfiltersNav` (as Playground returns None for envs
  without one).

  Raises:
    ValueError: a name not in `ALL_ENVS`.
  """
  if _check_name(env_name) == "JaxfiltersNavRandomized":
    from sims.rl.randomization import randomize_zones_and_goals
    return randomize_zones_and_goals
  return None


def register_gymnasium() -> bool:
  """Registers `GYM_IDS` with Gymnasium when it is installed (idempotent); False when it is not."""
  if importlib.util.find_spec("gymnasium") is None:
    return False
  import gymnasium

  for gym_id, kwargs in GYM_IDS.items():
    if gym_id not in gymnasium.registry:
      gymnasium.register(id=gym_id, entry_point="sims.rl.gym:NavGymEnv",
                         vector_entry_point="sims.rl.gym:NavVectorEnv", kwargs=dict(kwargs))
  return True
