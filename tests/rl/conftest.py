"""The `jaxfilters rl` command of this checkout, whatever the installed entry point names.

An editable install made from another checkout (or before a module moved) registers `rl` under a
module path this tree may not have; the command tests here must run this tree's code, so the
entry point is pointed at the module of this tree that defines `register_rl`.
"""

import importlib.metadata
import importlib.util
from pathlib import Path

import pytest

from jaxfilters import cli

REPO = Path(__file__).resolve().parents[2]
_CANDIDATES = ("sims.commands.rl", "sims.scripts.rl")


def _local_module() -> str:
  for name in _CANDIDATES:
    if (REPO / (name.replace(".", "/") + ".py")).is_file():
      return name
  raise AssertionError(f"no rl command module in {REPO} ({_CANDIDATES})")


@pytest.fixture(autouse=True)
def rl_command_of_this_checkout(monkeypatch):
  module = _local_module()
  ep = importlib.metadata.EntryPoint(name="rl", value=f"{module}:register_rl", group=cli.ENTRY_POINT_GROUP)
  real = importlib.metadata.entry_points

  def entry_points(**kw):
    eps = real(**kw)
    if kw.get("group") != cli.ENTRY_POINT_GROUP:
      return eps
    return importlib.metadata.EntryPoints([e for e in eps if e.name != "rl"] + [ep])

  monkeypatch.setattr(cli.importlib.metadata, "entry_points", entry_points)
