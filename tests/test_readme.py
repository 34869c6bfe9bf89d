"""README.md's Python snippets run as written, eagerly, each on its own, from the repository root."""

import re
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def test_readme_python_snippets_run(monkeypatch):
  monkeypatch.chdir(REPO)
  text = (REPO / "README.md").read_text()
  blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
  assert len(blocks) >= 4
  scopes = []
  for k, block in enumerate(blocks):
    scope: dict = {}                      # a fresh namespace: each snippet stands alone
    exec(compile(block, f"README.md python block {k}", "exec"), scope)
    scopes.append(scope)
  # What the snippets claim.
  pipeline = next(sc for sc in scopes if "occ" in sc)
  out, B = pipeline["out"], pipeline["B"]
  assert out.combined.cost.shape == (B, 60, 60) and out.combined.cost.dtype == np.uint8
  assert next(sc for sc in scopes if "frames" in sc)["frames"].pose.shape[0] == 50


def test_readme_starts_with_the_two_commands():
  text = (REPO / "README.md").read_text()
  assert text.startswith("```\nmake demo\nmake test\n```\n")
  assert (REPO / "docs" / "demo.png").is_file()
