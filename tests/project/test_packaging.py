"""Packaging: what the wheel installs, the extras, `jaxfilters bench` without the harness, import noise."""

import importlib.util
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
import setuptools

from jaxfilters import cli

ROOT = Path(__file__).resolve().parents[2]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def _names(requirements):
  return {r.split(";")[0].split("[")[0].split("=")[0].split("<")[0].split(">")[0].strip().lower()
          for r in requirements}


def test_wheel_installs_only_jaxfilters_and_sims():
  find = PYPROJECT["tool"]["setuptools"]["packages"]["find"]
  packages = setuptools.find_packages(where=str(ROOT), include=find["include"])
  assert {p.split(".")[0] for p in packages} == {"jaxfilters", "sims"}, packages
  assert (ROOT / "benchmarks" / "run.py").is_file()          # still in the checkout


def test_extras_are_named_for_what_they_bring():
  project = PYPROJECT["project"]
  extras = project["optional-dependencies"]
  assert set(extras) == {"test", "notebook", "ros", "rl", "warp", "docs"}
  assert {"mkdocs", "mkdocstrings"} <= _names(extras["docs"])
  assert {"mcap", "mcap-ros2-support"} <= _names(extras["test"])     # tests/record/test_bag.py's independent readers
  assert {"ipykernel", "nbclient", "nbformat", "matplotlib"} <= _names(extras["notebook"])
  assert {"pytest", "hypothesis", "chex", "jaxfilters"} <= _names(extras["test"])   # jaxfilters[notebook]
  assert any("jaxfilters[notebook]" in r for r in extras["test"])
  assert "rosbags==0.11.9" in extras["ros"]
  main = _names(project["dependencies"])
  assert "matplotlib" in main and "chex" not in main          # chex is used by the tests only
  for dep in project["dependencies"]:
    name = _names([dep]).pop()
    assert "<" in dep or "==" in dep, f"{dep}: no upper bound"
    assert name in (ROOT / "constraints.txt").read_text().lower(), f"{name} not pinned in constraints.txt"


def test_bench_outside_a_checkout_is_a_one_line_usage_error(monkeypatch, capsys):
  monkeypatch.setenv("XLA_FLAGS", os.environ.get("XLA_FLAGS", ""))
  from sims.commands import bench as sims_bench
  monkeypatch.setattr(sims_bench, "harness_root", lambda: None)
  monkeypatch.setattr(sims_bench.importlib.util, "find_spec", lambda name: None)
  assert cli.main(["bench", "--quick"]) == cli.EXIT_USAGE
  err = capsys.readouterr().err
  assert "source checkout" in err and len(err.strip().splitlines()) == 1


def test_harness_is_found_beside_the_sims_package():
  from sims.commands import bench as sims_bench
  assert sims_bench.harness_root() == ROOT


_BLOCK_WARP = """
import importlib.abc, sys
class _NoWarp(importlib.abc.MetaPathFinder):   # as if warp-lang were not installed
  def find_spec(self, name, path, target=None):
    if name == "warp" or name.startswith("warp."):
      raise ModuleNotFoundError("No module named 'warp'", name="warp")
    return None
sys.meta_path.insert(0, _NoWarp())
"""


@pytest.mark.parametrize("warp", ["absent", "as installed"])
def test_importing_the_simulator_prints_nothing(warp):
  code = (_BLOCK_WARP if warp == "absent" else "") + (
      "import sims.fleet.env, sims.scale.bench, sims, sims.fleet.quiet_mjx as q, mujoco.mjx.warp as w\n"
      "print('kept', len(q.WARP_MESSAGES), 'warp', w.WARP_INSTALLED)")
  proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT,
                        env=dict(os.environ, PYTHONPATH=str(ROOT)))
  assert proc.returncode == 0, proc.stderr[-2000:]
  if warp == "absent":
    want = "kept 2 warp False"              # both expected lines captured, nothing printed
  else:
    installed = importlib.util.find_spec("warp") is not None
    want = "kept 0 warp True" if installed else "kept 2 warp False"
  assert proc.stdout.strip() == want, proc.stdout
  assert "Failed to import" not in proc.stderr


def test_unexpected_mjx_import_messages_pass_through(capsys, monkeypatch):
  from sims.fleet import quiet_mjx
  monkeypatch.setattr(quiet_mjx, "WARP_MESSAGES", [])
  quiet_mjx.pass_through_unexpected("Failed to import warp: CUDA driver version is insufficient\n")
  assert capsys.readouterr().out == "Failed to import warp: CUDA driver version is insufficient\n"
  assert quiet_mjx.WARP_MESSAGES == []


def test_importing_sims_installs_no_import_hook():
  code = ("import sys; before = list(sys.meta_path); import sims, sims.fleet.config; "
          "print(sys.meta_path == before)")
  proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT,
                        env=dict(os.environ, PYTHONPATH=str(ROOT)))
  assert proc.returncode == 0 and proc.stdout.strip() == "True", proc.stderr[-2000:]


def test_every_entry_point_lives_in_sims_commands():
  """The library modules of sims hold no `__main__` block; the commands are registered from sims/commands."""
  for path in sorted((ROOT / "sims").rglob("*.py")):
    if path.parent.name == "commands":
      continue
    assert "__main__" not in path.read_text(), path
  commands = PYPROJECT["project"]["entry-points"]["jaxfilters.commands"]
  assert all(v.startswith("sims.commands.") for v in commands.values()), commands
