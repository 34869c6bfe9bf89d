"""Brax's own PPO (`brax.training.agents.ppo.train`) on this project's pins: the smallest shim.

MuJoCo Playground's users train with Brax's PPO. Brax 0.14.2, the newest release, calls
`jax.device_put_replicated` (in `brax.training.pmap.bcast_local_devices` and where PPO, APG and
SAC replicate their training state over the local devices); JAX removed that function after
deprecating it in 0.8.1 (on this project's jax 0.10.2, reading it raises AttributeError), so
`ppo.train` stops before its first step. Everything else Brax's PPO uses (`jax.pmap`, now built
on `shard_map`) still works.

`install()` gives those Brax modules, and only them, a `jax` whose `device_put_replicated` is
JAX's documented drop-in replacement (a `device_put` of the value stacked once per device onto a
`NamedSharding` over a one-axis mesh of the devices, the definition chex and flax in-lined when
the function went away). The `jax` module itself is not touched: no other code sees a change.
It does nothing where `jax.device_put_replicated` still exists.

    from brax.training.agents.ppo import train as ppo
    from mujoco_playground import wrapper
    from sims.rl import brax_compat, registry

    brax_compat.install()
    env = registry.load("JaxfiltersNavRandomized", config_overrides={"layouts": 8})
    make_policy, params, metrics = ppo.train(
        environment=env, num_timesteps=1_000_000, episode_length=150, num_envs=256, batch_size=256,
        wrap_env_fn=wrapper.wrap_for_brax_training,
        randomization_fn=registry.get_domain_randomizer("JaxfiltersNavRandomized"))

The project's own trainer (`jaxfilters rl train`, rejax's PPO, `sims.rl.ppo`) does not need it.
"""

from __future__ import annotations

import importlib
import types

import jax
import numpy as np

__all__ = ["BRAX_MODULES", "device_put_replicated", "install", "installed", "jax_has_device_put_replicated"]

BRAX_MODULES = ("brax.training.pmap", "brax.training.agents.ppo.train", "brax.training.agents.apg.train",
                "brax.training.agents.sac.train")
"""The Brax modules that call `jax.device_put_replicated` (Brax 0.14.2)."""


def device_put_replicated(x, devices):
  """JAX's drop-in replacement for the removed `jax.device_put_replicated`.

  Args:
    x: an array, scalar or pytree of them.
    devices: a non-empty sequence of devices.

  Returns:
    The pytree with each leaf stacked len(devices) times along a new leading axis, slice i on
    devices[i] (a `NamedSharding` over a one-axis mesh of the devices).

  Raises:
    ValueError: an empty `devices`.
  """
  devices = list(devices)
  if not devices:
    raise ValueError("device_put_replicated: devices must be a non-empty sequence of devices")
  mesh = jax.sharding.Mesh(np.array(devices), ("_device_put_replicated",))
  sharding = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("_device_put_replicated"))
  return jax.tree_util.tree_map(lambda v: jax.device_put(np.stack([np.asarray(v)] * len(devices)), sharding), x)


class _JaxForBrax(types.ModuleType):
  """`jax` as Brax's modules see it after `install()`: every name is jax's, plus
  `device_put_replicated`."""

  def __getattr__(self, name):
    return getattr(jax, name)


_PROXY = _JaxForBrax("jax", "jax, with device_put_replicated for Brax (sims.rl.brax_compat)")
_PROXY.device_put_replicated = device_put_replicated


def jax_has_device_put_replicated() -> bool:
  """True where this jax still has `jax.device_put_replicated` (then Brax needs no shim)."""
  try:
    return callable(jax.device_put_replicated)
  except AttributeError:
    return False


def installed() -> bool:
  """True when Brax's PPO can replicate its state: JAX still has the function, or `install()` ran."""
  return jax_has_device_put_replicated() or importlib.import_module("brax.training.agents.ppo.train").jax is _PROXY


def install() -> bool:
  """Gives Brax's modules (`BRAX_MODULES`) the shimmed `jax`; idempotent. False when JAX still has
  `device_put_replicated` (nothing to do).

  Raises:
    ImportError: Brax is not installed (the `rl` extra).
    RuntimeError: one of those modules' `jax` was already replaced by something else.
  """
  if jax_has_device_put_replicated():
    return False
  for name in BRAX_MODULES:
    module = importlib.import_module(name)
    if module.jax is not jax and module.jax is not _PROXY:
      raise RuntimeError(f"brax_compat.install: {name}.jax is neither jax nor this shim ({module.jax!r}); "
                         f"another patch is in place")
    module.jax = _PROXY
  return True
