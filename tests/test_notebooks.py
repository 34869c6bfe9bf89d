"""The notebooks run top to bottom (they read the real Nav2 maps)."""

import json
from pathlib import Path

import pytest

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"


@pytest.mark.parametrize("path", sorted(NOTEBOOKS.glob("*.ipynb")), ids=lambda p: p.name)
def test_notebook_runs(path, nav2_maps, monkeypatch):
  monkeypatch.chdir(path.parent)
  nb = json.loads(path.read_text())
  scope = {}
  for cell in nb["cells"]:
    if cell["cell_type"] == "code":
      exec(compile("".join(cell["source"]), f"{path.name}", "exec"), scope)
  assert "combined" in scope and int((scope["combined"] == 254).sum()) > int((scope["grid"].data == 100).sum())
