"""sims: an MJX-simulated robot fleet driven through jaxfilters' Nav2 costmap filters.

One world is a warehouse with K differential-drive robots (MuJoCo MJX, planar
base, velocity actuators, no contacts). `FleetEnv.reset(key)` and
`FleetEnv.step(state, action)` act on one world; worlds are batched with one
`jax.vmap` and rolled out with `lax.scan` (`FleetEnv.rollout_fn`). Each step
runs, per robot: speed filter -> navigation field -> local planner on a
rolling local costmap (static layer, other robots, inflation, keepout filter)
-> clip to the speed limit -> mjx.step, and accumulates compliance metrics.

`sims` imports `jaxfilters`; `jaxfilters` never imports `sims`. The public
names below are imported lazily, so `sims.cli` can set XLA options before
JAX starts.

Importing `mujoco.mjx` prints "Failed to import warp: No module named 'warp'"
and the same for mujoco_warp on stdout (bare `print` calls in
`mujoco/mjx/warp/__init__.py`) whenever the optional warp-lang is absent,
which is the normal CPU install. Importing `sims` installs a one-shot import
hook that captures what that one module prints while it loads: exactly those
two lines are kept in `MJX_WARP_MESSAGES` (not shown) when warp-lang is not
installed; anything else it prints (warp installed but failing, e.g. a CUDA
error) is passed through to stdout unchanged. `FleetEnv.create` raises with
the kept messages if `impl='warp'` is asked for without warp.
"""

import contextlib
import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import io
import sys

_MJX_WARP = "mujoco.mjx.warp"
_EXPECTED_NOISE = ("Failed to import warp: No module named 'warp'",
                   "Failed to import mujoco_warp: No module named 'warp'")
MJX_WARP_MESSAGES: list[str] = []  # the expected lines mujoco.mjx printed and this package hid


def _pass_through_unexpected(text: str) -> None:
  """Keeps the two expected lines (warp-lang absent) and re-prints every other line."""
  try:
    warp_absent = importlib.util.find_spec("warp") is None
  except (ImportError, ValueError):    # blocked (sys.modules["warp"] = None) or a broken finder
    warp_absent = True
  for line in text.splitlines():
    if warp_absent and line.strip() in _EXPECTED_NOISE:
      MJX_WARP_MESSAGES.append(line.strip())
    else:
      print(line, file=sys.stdout)


class _QuietLoader(importlib.abc.Loader):
  """Runs the real loader of mujoco.mjx.warp with its stdout captured."""

  def __init__(self, loader):
    self._loader = loader

  def create_module(self, spec):
    return self._loader.create_module(spec)

  def exec_module(self, module):
    buf = io.StringIO()
    try:
      with contextlib.redirect_stdout(buf):
        self._loader.exec_module(module)
    finally:
      _pass_through_unexpected(buf.getvalue())

  def __getattr__(self, name):            # resource readers etc. of the real loader
    return getattr(self._loader, name)


class _QuietMjxWarpFinder(importlib.abc.MetaPathFinder):
  """Finds mujoco.mjx.warp with the normal path finder and wraps its loader; then removes itself."""

  def find_spec(self, fullname, path, target=None):
    if fullname != _MJX_WARP:
      return None
    with contextlib.suppress(ValueError):
      sys.meta_path.remove(self)
    spec = importlib.machinery.PathFinder.find_spec(fullname, path, target)
    if spec is not None and spec.loader is not None:
      spec.loader = _QuietLoader(spec.loader)
    return spec


if _MJX_WARP not in sys.modules and not any(isinstance(f, _QuietMjxWarpFinder) for f in sys.meta_path):
  sys.meta_path.insert(0, _QuietMjxWarpFinder())

_EXPORTS = {
    "FleetConfig": "sims.config", "PlannerConfig": "sims.config", "RobotConfig": "sims.config",
    "FleetEnv": "sims.env", "Frame": "sims.env", "Rollout": "sims.env", "WorldState": "sims.env",
    "Metrics": "sims.metrics", "summarize": "sims.metrics",
    "NavField": "sims.navigation", "distance_field": "sims.navigation",
    "Scenario": "sims.scenario",
    "World": "sims.world", "WorldParams": "sims.world", "build_world": "sims.world",
    "fleet_throughput": "sims.bench",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name):
  if name in _EXPORTS:
    return getattr(importlib.import_module(_EXPORTS[name]), name)
  raise AttributeError(f"module 'sims' has no attribute {name!r}")


def __dir__():
  return sorted(list(globals()) + __all__)
