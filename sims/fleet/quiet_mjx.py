"""Internal: imports `mujoco.mjx` without the two lines it prints when warp-lang is absent.

Importing `mujoco.mjx` imports `mujoco.mjx.warp`, whose `__init__` prints
"Failed to import warp: No module named 'warp'" and the same for mujoco_warp
on stdout whenever the optional warp-lang is not installed, which is the
normal CPU install. The modules of sims that import mjx do it inside
`expected_warp_lines()`: exactly those two lines are kept in `WARP_MESSAGES`
(not shown) when warp-lang is absent; anything else printed meanwhile (warp
installed but failing, e.g. a CUDA error) is passed through to stdout.
`FleetEnv.create` raises with the kept lines if `impl='warp'` is asked for
without warp. Nothing is hooked: an import of mujoco.mjx elsewhere, before
sims, prints as mujoco wrote it.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import sys

EXPECTED_LINES = ("Failed to import warp: No module named 'warp'",
                  "Failed to import mujoco_warp: No module named 'warp'")
WARP_MESSAGES: list[str] = []  # the expected lines mujoco.mjx printed while sims imported it


def pass_through_unexpected(text: str) -> None:
  """Keeps the expected lines (when warp-lang is absent) in WARP_MESSAGES and prints every other line."""
  try:
    warp_absent = importlib.util.find_spec("warp") is None
  except (ImportError, ValueError):    # blocked (sys.modules["warp"] = None) or a broken finder
    warp_absent = True
  for line in text.splitlines():
    if warp_absent and line.strip() in EXPECTED_LINES:
      WARP_MESSAGES.append(line.strip())
    else:
      print(line, file=sys.stdout)


@contextlib.contextmanager
def expected_warp_lines():
  """Captures stdout while mujoco.mjx is first imported; see the module docstring.

  Use as `with expected_warp_lines(): from mujoco import mjx`. When mjx is
  already imported the block prints nothing anyway and nothing is captured.
  """
  buf = io.StringIO()
  try:
    with contextlib.redirect_stdout(buf):
      yield
  finally:
    pass_through_unexpected(buf.getvalue())
