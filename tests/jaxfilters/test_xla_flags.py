"""jaxfilters/xla_flags.py: `import jaxfilters` picks XLA:CPU's classic fusion emitters on jaxlib 0.10 (the
setting the suite and the commands run with), leaves a user's own choice alone, and never sets the flag
on a jaxlib that would abort on it."""

import importlib.metadata
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from jaxfilters import xla_flags

ROOT = Path(__file__).resolve().parents[2]
ON_010 = importlib.metadata.version("jaxlib").split(".")[:2] == ["0", "10"]


def _flags_after_import(flags):
  """XLA_FLAGS in a fresh interpreter after `import jaxfilters` and one jitted call (None: unset)."""
  env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
  if flags is not None:
    env["XLA_FLAGS"] = flags
  env["JAX_PLATFORMS"] = "cpu"
  code = ("import os, jaxfilters, jax, jax.numpy as jnp; jax.jit(lambda x: x + 1)(jnp.zeros(3)).block_until_ready(); "
          "import json; print(json.dumps(os.environ.get('XLA_FLAGS')))")
  out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
  assert out.returncode == 0, out.stderr
  return json.loads(out.stdout.strip().splitlines()[-1])


def test_import_sets_the_classic_emitters_on_jaxlib_010_only():
  got = _flags_after_import(None)
  if ON_010:
    assert got == xla_flags.FAST_CPU_COMPILE_FLAG
  else:
    assert got is None


@pytest.mark.parametrize("flags", ["--xla_cpu_use_fusion_emitters=true",
                                   "--xla_force_host_platform_device_count=2"])
def test_import_keeps_the_users_flags(flags):
  got = _flags_after_import(flags)
  if "fusion_emitters" in flags or not ON_010:
    assert got == flags                      # the user's choice, untouched
  else:
    assert got == f"{flags} {xla_flags.FAST_CPU_COMPILE_FLAG}"   # added after the user's own flags
