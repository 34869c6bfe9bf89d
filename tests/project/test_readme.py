"""README.md: its Python snippets run as written when pasted into the Python REPL line by line, each
on its own, from the repository root; it opens with its title and the two commands; its picture is
the `make demo` run's."""

import code
import contextlib
import io
import json
import re
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]


class _Repl(code.InteractiveConsole):
  """The interactive interpreter `python` runs, with everything it would print collected."""

  def __init__(self):
    super().__init__(locals={"__name__": "__console__"})
    self.errors: list[str] = []

  def write(self, data):                       # syntax errors and tracebacks come through here
    self.errors.append(data)


def paste(block: str) -> _Repl:
  """Feeds `block` to a fresh REPL one line at a time, as a paste into `python` does, then Enter."""
  repl = _Repl()
  with contextlib.redirect_stdout(io.StringIO()):      # expression statements echo their values
    for line in block.splitlines():
      repl.push(line)
    repl.push("")
  return repl


def _blocks(text: str) -> list[str]:
  return re.findall(r"```python\n(.*?)```", text, flags=re.S)


def test_readme_python_snippets_paste_into_the_repl(monkeypatch):
  monkeypatch.chdir(REPO)
  blocks = _blocks((REPO / "README.md").read_text())
  assert len(blocks) >= 4
  scopes = []
  for k, block in enumerate(blocks):
    repl = paste(block)                       # a fresh namespace: each snippet stands alone
    assert not repl.errors, f"README.md python block {k} in the REPL:\n{''.join(repl.errors)}"
    scopes.append(repl.locals)
  # What the snippets claim.
  pipeline = next(sc for sc in scopes if "occ" in sc)
  out, B = pipeline["out"], pipeline["B"]
  assert out.combined.cost.shape == (B, 60, 60) and out.combined.cost.dtype == np.uint8
  assert next(sc for sc in scopes if "frames" in sc)["frames"].pose.shape[0] == 50


def test_the_repl_check_catches_a_decorated_def_without_a_blank_line():
  """The README's first block once failed in the REPL: a statement right after an indented body."""
  bad = "def f(x):\n  return x\ny = f(1)\n"
  assert paste(bad).errors and "SyntaxError" in "".join(paste(bad).errors)
  good = paste("def f(x):\n  return x\n\ny = f(1)\n")
  assert not good.errors and good.locals["y"] == 1


def test_readme_starts_with_its_title_and_the_two_commands():
  text = (REPO / "README.md").read_text()
  assert text.startswith("# jaxfilters\n\n```\nmake demo\nmake test\n```\n")
  assert (REPO / "docs" / "demo.png").is_file()


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
