"""sims/rl/registry.py: Playground's registry functions (load, get_default_config,
get_domain_randomizer, ALL_ENVS) for the MJX env, and the Gymnasium ids registered by importing
sims.rl (gymnasium.make / make_vec through string entry points)."""

import subprocess
import sys

import gymnasium
import numpy as np
import pytest
from ml_collections import config_dict

import sims.rl
from sims.rl import registry
from sims.rl.env import NavEnv, NavEnvConfig
from sims.rl.gym import NavGymEnv, NavVectorEnv
from sims.rl.randomization import randomize_zones_and_goals


@pytest.fixture(scope="module")
def nav():
  return registry.load("JaxfiltersNav")


def test_default_configs_hold_what_load_applies():
  for name in registry.ALL_ENVS:
    c = registry.get_default_config(name)
    assert isinstance(c, config_dict.ConfigDict)
    assert set(c.keys()) == {"episode_length", "action_repeat", "robots_per_world", "seed", "layouts",
                             "layout_seed", "env"}
    assert c.env.to_dict() == NavEnvConfig().__dict__
  assert registry.get_default_config("JaxfiltersNav").layouts == 1
  assert registry.get_default_config("JaxfiltersNavRandomized").layouts == 16
  assert registry.get_domain_randomizer("JaxfiltersNavRandomized") is randomize_zones_and_goals
  assert registry.get_domain_randomizer("JaxfiltersNav") is None


def test_load_applies_config_and_overrides(nav):
  assert isinstance(nav, NavEnv) and nav.nav_config == NavEnvConfig()
  config = registry.get_default_config("JaxfiltersNavRandomized")
  env = registry.load("JaxfiltersNavRandomized", config,
                      config_overrides={"env.keepout": "penalty", "layouts": 2, "robots_per_world": 2})
  assert env.nav_config.keepout == "penalty"
  assert env.fleet.config.robots_per_world == 2
  assert env.observation_size == 2 * nav.observation_size
  assert config.env.keepout == "terminate" and config.layouts == 16    # the caller's config is untouched


@pytest.mark.parametrize(("args", "match"), [
    (("Go1Joystick",), "not found. Available envs"),
    (("JaxfiltersNav", {"layouts": 1}), "must be an ml_collections ConfigDict"),
    (("JaxfiltersNav", None, {"env.nope": 1}), r"unknown keys \['env.nope'\]"),
    (("JaxfiltersNav", None, {"layouts": 0}), r"config.layouts must be an integer in \[1, 1,024\]"),
    (("JaxfiltersNav", None, {"seed": -1}), "config.seed must be an integer"),
    (("JaxfiltersNav", None, {"action_repeat": 2}), "config.action_repeat must be an integer in"),
    (("JaxfiltersNav", None, {"env.mode": "navigation"}), "config.env.mode must be 'velocity'"),
    (("JaxfiltersNav", None, {"env.crop_cells": 4}), "crop_cells"),
])
def test_load_refuses_bad_names_configs_and_values(args, match):
  with pytest.raises(ValueError, match=match):
    registry.load(*args)


def test_load_refuses_a_config_with_missing_or_extra_keys():
  c = registry.get_default_config("JaxfiltersNav")
  del c["layout_seed"]
  c.extra = 1
  with pytest.raises(ValueError, match=r"missing \['layout_seed'\], unknown \['extra'\]"):
    registry.load("JaxfiltersNav", c)


def test_importing_sims_rl_registers_the_gym_ids_without_mujoco():
  """String entry points: the registration imports neither MuJoCo nor Playground nor JAX."""
  code = ("import sys, gymnasium, sims.rl; "
          "spec = gymnasium.spec('jaxfilters/Nav-v0'); "
          "assert spec.entry_point == 'sims.rl.gym:NavGymEnv', spec.entry_point; "
          "assert spec.vector_entry_point == 'sims.rl.gym:NavVectorEnv'; "
          "assert gymnasium.spec('jaxfilters/NavRandomized-v0').kwargs == {'randomize': True}; "
          "heavy = [m for m in ('mujoco', 'mujoco_playground', 'jax') if m in sys.modules]; "
          "assert not heavy, heavy; "
          "sims.rl.registry.register_gymnasium()")   # idempotent: no 'overriding' warning
  out = subprocess.run([sys.executable, "-W", "error", "-c", code], capture_output=True, text=True, timeout=120)
  assert out.returncode == 0, out.stderr


def test_gymnasium_make_and_make_vec(nav):
  gymnasium.register_envs(sims.rl)
  env = gymnasium.make("jaxfilters/Nav-v0", env=nav, episode_length=4)
  assert isinstance(env.unwrapped, NavGymEnv)
  obs, _ = env.reset(seed=0)
  assert obs.shape == (nav.observation_size,) and obs.dtype == np.float32
  obs2, reward, terminated, truncated, _ = env.step(np.zeros(2, np.float32))
  assert obs2.shape == obs.shape and np.isfinite(reward)
  env.close()
  envs = gymnasium.make_vec("sims.rl:jaxfilters/NavRandomized-v0", num_envs=2, env=nav, episode_length=4)
  assert isinstance(envs, NavVectorEnv) and envs.num_envs == 2
  obs, _ = envs.reset(seed=1)
  assert obs.shape == (2, nav.observation_size)
  envs.close()
  with pytest.raises(ValueError, match="num_envs must be an integer >= 1"):
    gymnasium.make_vec("jaxfilters/Nav-v0", num_envs=0, env=nav)
