"""Test-wide settings: strict rank promotion (STYLE.md habit 11), hypothesis budget."""

import os
from pathlib import Path

# Before JAX starts: XLA:CPU's new fusion emitter recomputes the exact cell-index
# arithmetic inside every fused output cell (keepout 8.5 ms vs 0.17 ms on [8, 60, 60])
# and compiles ~25 % slower; sims/cli.py and benchmarks/run.py set the same flag.
_flag = "--xla_cpu_use_fusion_emitters=false"
if _flag not in os.environ.get("XLA_FLAGS", ""):
  os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " " + _flag).strip()

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
