"""Runs the sandboxed fuzzer (`python -m tests.fuzz.fuzz_inputs`) on one target, as the fuzz tests do."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def run_target(target: str, out: Path, count: int = 150) -> list[str]:
  """stdout lines of `fuzz_inputs --count COUNT --workers 1 --targets TARGET --out OUT`, asserting exit 0."""
  run = subprocess.run([sys.executable, "-m", "tests.fuzz.fuzz_inputs", "--count", str(count), "--workers", "1",
                        "--targets", target, "--out", str(out)], cwd=REPO,
                       capture_output=True, text=True, timeout=300)
  assert run.returncode == 0, run.stdout + run.stderr
  return run.stdout.splitlines()
