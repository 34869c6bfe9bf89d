"""Runs a Markdown page's Python snippets as a user pastes them into the `python` REPL, line by line.

Shared by the README test (tests/project/test_readme.py) and the guides' tests
(tests/project/test_guides.py, tests/rl/test_guide.py): each snippet in a fresh namespace, from the
repository root, exactly as written.
"""

import code
import contextlib
import io
import re


class Repl(code.InteractiveConsole):
  """The interactive interpreter `python` runs, with everything it would print collected."""

  def __init__(self):
    super().__init__(locals={"__name__": "__console__"})
    self.errors: list[str] = []

  def write(self, data):                       # syntax errors and tracebacks come through here
    self.errors.append(data)


def paste(block: str) -> Repl:
  """Feeds `block` to a fresh REPL one line at a time, as a paste into `python` does, then Enter."""
  repl = Repl()
  with contextlib.redirect_stdout(io.StringIO()):      # expression statements echo their values
    for line in block.splitlines():
      repl.push(line)
    repl.push("")
  return repl


def python_blocks(text: str) -> list[str]:
  """The ```python fenced blocks of a Markdown text, in order."""
  return re.findall(r"```python\n(.*?)```", text, flags=re.S)


def run_page(path) -> list[dict]:
  """Pastes every Python block of the page at `path`; returns each block's namespace, or fails naming the block."""
  scopes = []
  for k, block in enumerate(python_blocks(path.read_text(encoding="utf-8"))):
    repl = paste(block)                       # a fresh namespace: each snippet stands alone
    assert not repl.errors, f"{path.name} python block {k} in the REPL:\n{''.join(repl.errors)}"
    scopes.append(repl.locals)
  return scopes
