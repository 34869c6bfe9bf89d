"""The `jaxfilters` commands of this checkout, whatever the installed entry points name.

An editable install made from another checkout (or before a module moved) registers the commands
(`rl`, `fleet`, `bench`) under module paths this tree may not have, or whose code differs from this
tree's; the command tests here must run this tree's code, so each entry point of the group is
pointed at the module of this tree that defines its register function.
"""

import importlib.metadata
from pathlib import Path

import pytest

from jaxfilters import cli

REPO = Path(__file__).resolve().parents[2]


def _local(ep):
  """The entry point moved to this checkout's sims/commands or sims/scripts module of its name."""
  attr = ep.value.partition(":")[2]
  for package in ("sims.commands", "sims.scripts"):
    module = f"{package}.{ep.name}"
    if (REPO / (module.replace(".", "/") + ".py")).is_file():
      return importlib.metadata.EntryPoint(name=ep.name, value=f"{module}:{attr}", group=ep.group)
  return ep


@pytest.fixture(autouse=True)
def commands_of_this_checkout(monkeypatch):
  real = importlib.metadata.entry_points

  def entry_points(**kw):
    eps = real(**kw)
    if kw.get("group") != cli.ENTRY_POINT_GROUP:
      return eps
    return importlib.metadata.EntryPoints([_local(ep) for ep in eps])

  monkeypatch.setattr(cli.importlib.metadata, "entry_points", entry_points)
