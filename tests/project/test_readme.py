"""README.md is a front page: its title and the two commands first, its snippet runs as written when pasted
into the Python REPL from the repository root, its links lead to pages that exist, its picture is the
`make demo` run's, and it stays short."""

import json
import re
from pathlib import Path

import numpy as np

from tests.repl import paste, run_page

REPO = Path(__file__).resolve().parents[2]


def test_readme_python_snippet_pastes_into_the_repl(monkeypatch):
  monkeypatch.chdir(REPO)
  scopes = run_page(REPO / "README.md")
  assert len(scopes) == 1
  sc = scopes[0]
  assert sc["costmaps"].cost.shape == (64, 60, 60) and sc["costmaps"].cost.dtype == np.uint8
  assert int((np.asarray(sc["costmaps"].cost) == 254).sum()) > 0          # some windows hold keepout cells
  assert sc["out"].speed_limit.shape == (64,)


def test_the_repl_check_catches_a_decorated_def_without_a_blank_line():
  """A statement right after an indented body is a SyntaxError in the REPL (a script would accept it)."""
  bad = "def f(x):\n  return x\ny = f(1)\n"
  assert paste(bad).errors and "SyntaxError" in "".join(paste(bad).errors)
  good = paste("def f(x):\n  return x\n\ny = f(1)\n")
  assert not good.errors and good.locals["y"] == 1


def test_readme_starts_with_its_title_and_the_two_commands():
  text = (REPO / "README.md").read_text()
  assert text.startswith("# jaxfilters\n\n```\nmake demo\nmake test\n```\n")
  assert (REPO / "docs" / "demo.png").is_file()


def test_readme_is_a_front_page_whose_links_exist():
  text = (REPO / "README.md").read_text()
  assert len(text.splitlines()) <= 150
  links = re.findall(r"\]\(([^)#]+)\)", text)
  assert links and all((REPO / link).is_file() for link in links), [x for x in links if not (REPO / x).is_file()]
  guides = sorted(p.relative_to(REPO).as_posix() for p in (REPO / "docs" / "guides").glob("*.md"))
  assert set(guides) <= set(links), f"guides the README does not link: {set(guides) - set(links)}"


def test_readme_picture_is_the_make_demo_run():
  """docs/demo.png was written by sims/commands/readme_picture.py from a run with the demo's defaults."""
  from PIL import Image

  from sims.commands import readme_picture
  with Image.open(REPO / "docs" / "demo.png") as im:
    text = json.loads(im.text[readme_picture.TEXT_KEY])
  want = readme_picture.demo_defaults()
  assert {k: text[k] for k in want} == want
  assert text["command"] == "jaxfilters fleet --out out/demo"
  assert "$(VENV)/bin/jaxfilters fleet --out out/demo" in (REPO / "Makefile").read_text()
  assert text["keepout_entries"] == 0 and text["speed_compliant"] and text["goals_reached"] > 0
