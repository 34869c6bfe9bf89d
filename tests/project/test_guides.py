"""The guides (docs/guides/*.md): every Python snippet runs as written when pasted into the REPL from the
repository root, and does what the page says. The RL guide's snippets run in tests/rl/test_guide.py."""

from pathlib import Path

import numpy as np
import pytest

from tests.repl import python_blocks, run_page

REPO = Path(__file__).resolve().parents[2]
GUIDES = REPO / "docs" / "guides"
ELSEWHERE = {"rl.md"}                          # its snippets need the rl extra: tests/rl/test_guide.py


def test_every_guide_with_code_is_run_somewhere():
  with_code = {p.name for p in GUIDES.glob("*.md") if python_blocks(p.read_text())}
  assert with_code == {"tour.md", "beyond_nav2.md", "robots.md"} | ELSEWHERE, with_code


def test_tour_snippets(monkeypatch):
  monkeypatch.chdir(REPO)
  scopes = run_page(GUIDES / "tour.md")
  assert len(scopes) == 4
  first = scopes[0]
  B = first["B"]
  assert first["out"].speed_limit.shape == (B,) and first["costmaps"].cost.shape == (B, 60, 60)
  params = scopes[1]
  assert params["costmaps"].cost.dtype == np.uint8
  pipeline = next(sc for sc in scopes if "occ" in sc)
  out, B = pipeline["out"], pipeline["B"]
  assert out.combined.cost.shape == (B, 60, 60) and out.combined.cost.dtype == np.uint8
  assert next(sc for sc in scopes if "frames" in sc)["frames"].pose.shape[0] == 50


@pytest.mark.parametrize("page", ["beyond_nav2.md", "robots.md"])
def test_guide_snippets_with_their_own_asserts(page, monkeypatch):
  monkeypatch.chdir(REPO)
  assert run_page(GUIDES / page)          # the snippets assert what the page claims
