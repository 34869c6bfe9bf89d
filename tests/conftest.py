"""Test-wide settings: strict rank promotion (silent broadcasting raises), hypothesis budget,
and one persistent XLA compilation cache for the session.

The cache: the suite compiles the same programs in several processes (the two xdist workers,
the CLI subprocesses, the notebook kernels: each builds the default fleet world, for one). The
first process to run `pytest` makes a fresh temporary folder, names it in
JAX_COMPILATION_CACHE_DIR (child processes inherit it; JAX reads it when imported, and this
process, which has imported JAX already, sets it in jax.config) and removes it when the session
ends, so nothing is written outside the session and no run sees
another run's executables. The cache key is the compiled program with its compile options,
XLA_FLAGS and jaxlib version, so a hit is the same executable a compile would give; the
compile-count listener of tests/compile_count.py still counts a hit as a compile.
"""

import os
import shutil
import tempfile
from pathlib import Path

SESSION_CACHE_ENV = "JAXFILTERS_TEST_XLA_CACHE"
_OWN_CACHE = None
if os.environ.get(SESSION_CACHE_ENV) is None:       # the first pytest process: xdist workers inherit it
  _OWN_CACHE = tempfile.mkdtemp(prefix="jaxfilters-test-xla-")
  os.environ[SESSION_CACHE_ENV] = _OWN_CACHE
  os.environ["JAX_COMPILATION_CACHE_DIR"] = _OWN_CACHE
  # Programs that compile in 0.5 s or more are written; smaller ones cost more to store than to redo.
  os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0.5"
  os.environ["JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES"] = "-1"

import jaxfilters  # noqa: F401  (first: importing it sets the XLA:CPU flags, jaxfilters/xla_flags.py)

import jax  # noqa: E402
import pytest
from hypothesis import HealthCheck, settings

jax.config.update("jax_numpy_rank_promotion", "raise")
jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
jax.config.update("jax_persistent_cache_min_compile_time_secs",
                  float(os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"]))
jax.config.update("jax_persistent_cache_min_entry_size_bytes",
                  int(os.environ["JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES"]))
# JAX opens its persistent cache at the first compile and keeps that folder for the process; one
# tiny compile now makes it the session's folder, whatever a test later sets (`jaxfilters fleet`
# without --no-cache points jax_compilation_cache_dir at the user's cache).
jax.jit(lambda x: x + 1)(0).block_until_ready()

settings.register_profile(
    "ci", max_examples=60, deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

NAV2_MAPS = Path(__file__).resolve().parents[1].parent / "shared" / "maps" / "nav2"


@pytest.fixture(scope="session")
def nav2_maps() -> Path:
  """The real Nav2 maps folder (../shared/maps/nav2), or skip with the reason."""
  if not NAV2_MAPS.is_dir():
    pytest.skip(f"real Nav2 maps not found at {NAV2_MAPS} (a fresh clone has no ../shared); "
                "these tests need the shared/maps/nav2 folder beside the checkout")
  return NAV2_MAPS


# The files that take longest (paths under tests/) (CPU time on a 2-core machine, longest first). `make test` hands whole
# files to its two workers in the order the collection lists them; these go first, so that the
# short files fill in at the end instead of one worker running a long file alone while the other
# has nothing left. pytest-xdist's default order (files with the most tests first) would start
# these last: most have few tests.
# commands/test_rl.py first: it compiles the suite's small training run (tests/rl_small.py) at once,
# and notebook 04, rl/test_env.py and rl/test_training_counts.py, later, load it from the cache. The
# sharding file runs on the other worker meanwhile, so that notebook 04 starts after test_rl.py has
# written those programs (~2 minutes in) rather than compiling them beside it.
SLOW_FILES = ("commands/test_rl.py", "scale/test_sharding.py", "project/test_notebooks.py", "rl/test_env.py",
              "project/test_readme.py", "fleet/test_env.py", "jaxfilters/test_layers.py",
              "jaxfilters/test_keepout_paths.py", "record/test_bag.py", "fleet/test_keepout_escape.py",
              "jaxfilters/test_keepout_prologue.py", "jaxfilters/test_keepout_paths_random.py",
              "commands/test_cli_matrix.py", "jaxfilters/test_keepout_pallas.py", "commands/test_fleet.py",
              "jaxfilters/test_shapes.py", "rl/test_layouts.py", "rl/test_gym.py",
              "jaxfilters/test_keepout_footprint.py", "fuzz/test_map_files.py", "rl/test_brax_ppo.py",
              "rl/test_registry.py", "fleet/test_one_way_lanes.py", "fleet/test_fleet_layers.py",
              "fleet/test_robot_model.py", "rl/test_own_robot.py", "commands/test_fleet_robot.py",
              "commands/test_rl_fleet.py", "rl/test_fleet_policy.py")
TESTS = Path(__file__).resolve().parent


def pytest_configure(config):
  """Keeps the collection order for --dist loadfile (see SLOW_FILES)."""
  if getattr(config.option, "loadscopereorder", None):
    config.option.loadscopereorder = False


def pytest_collection_modifyitems(config, items):
  """SLOW_FILES first, in that order; the other files after them as collected (a stable sort)."""
  del config
  rank = {name: i for i, name in enumerate(SLOW_FILES)}
  items.sort(key=lambda item: rank.get(item.path.resolve().relative_to(TESTS).as_posix(), len(rank)))


def pytest_unconfigure(config):
  """Removes the session's compilation cache (only in the process that made it)."""
  del config
  if _OWN_CACHE is not None:
    shutil.rmtree(_OWN_CACHE, ignore_errors=True)
