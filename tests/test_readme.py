"""README.md's Python snippets run as written, eagerly, in order, from the repository root."""

import os
import re
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def test_readme_python_snippets_run(monkeypatch):
  monkeypatch.chdir(REPO)
  text = (REPO / "README.md").read_text()
  blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
  assert len(blocks) >= 5
  scope: dict = {}
  for k, block in enumerate(blocks):
    t0 = time.perf_counter()
    exec(compile(block, f"README.md python block {k}", "exec"), scope)
  # What the snippets claim.
  out, B = scope["out"], scope["B"]
  assert out.combined.cost.shape == (B, 60, 60) and out.combined.cost.dtype == np.uint8
  assert scope["frames"].pose.shape[0] == 50


def test_readme_starts_with_the_two_commands():
  text = (REPO / "README.md").read_text()
  assert text.startswith("```\nmake demo\nmake test\n```\n")
  assert (REPO / "docs" / "demo.png").is_file()
