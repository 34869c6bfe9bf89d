"""XLA options set before JAX starts (imports no JAX, so callers can run it first).

`--xla_cpu_use_fusion_emitters=false` selects XLA:CPU's classic fusion emitters.
With jaxlib 0.10 the new emitter recomputes the keepout filter's exact cell-index
arithmetic inside every fused output cell (8.5 ms vs 0.17 ms on [8, 60, 60]) and
compiles the fleet step ~35 % slower. Newer XLA releases removed the flag and
abort on unknown flags (jaxlib 0.11.2 does), so it is only set on jaxlib 0.10.x.

`import jaxfilters` calls `use_fast_cpu_compile` first thing, so a notebook or a pipeline
runs what the test suite and the commands run; it takes effect where no JAX backend has
started in the process yet (XLA reads the flags once, when the first backend starts).
Like any environment variable it is inherited by child processes: a child running a
newer jaxlib (which aborts on the flag) needs XLA_FLAGS without it.
"""

from __future__ import annotations

import importlib.metadata
import os

FAST_CPU_COMPILE_FLAG = "--xla_cpu_use_fusion_emitters=false"


def _jaxlib_version() -> tuple[int, ...]:
  try:
    text = importlib.metadata.version("jaxlib")
  except importlib.metadata.PackageNotFoundError:
    return ()
  parts = []
  for p in text.split(".")[:2]:
    digits = "".join(ch for ch in p if ch.isdigit())
    parts.append(int(digits) if digits else 0)
  return tuple(parts)


def use_fast_cpu_compile() -> bool:
  """Adds the flag to XLA_FLAGS on jaxlib 0.10.x unless the user already chose; True if set."""
  flags = os.environ.get("XLA_FLAGS", "")
  if "xla_cpu_use_fusion_emitters" in flags:
    return FAST_CPU_COMPILE_FLAG in flags
  if _jaxlib_version()[:2] != (0, 10):
    return False
  os.environ["XLA_FLAGS"] = (flags + " " + FAST_CPU_COMPILE_FLAG).strip()
  return True
