"""Test-wide settings: strict rank promotion (silent broadcasting raises), hypothesis budget."""

import os
from pathlib import Path

from jaxfilters import xla_flags

# Before JAX starts (see jaxfilters/xla_flags.py); the CLI and the benchmarks do the same.
xla_flags.use_fast_cpu_compile()

import jax  # noqa: E402
import pytest
from hypothesis import HealthCheck, settings

jax.config.update("jax_numpy_rank_promotion", "raise")

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
