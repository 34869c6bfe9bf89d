"""The house's layout rules, checked: sims/ in rooms by concern, imports one way, no circles, tests mirror the rooms.

docs/house.md describes the layers; this file is what keeps them true.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

# What each sims package may import besides itself and jaxfilters (docs/house.md, the packages' docstrings).
ALLOWED = {
    "fleet": set(),
    "scale": {"fleet"},
    "rl": {"fleet", "scale"},
    "record": {"fleet"},
    "tuning": {"fleet"},
    "commands": {"fleet", "scale", "rl", "record", "tuning", "commands"},
}
TEST_ROOMS = {"jaxfilters", "fleet", "rl", "record", "scale", "tuning", "commands", "benchmarks", "project", "fuzz"}


def _module(path: Path, root: Path = ROOT) -> str:
  parts = list(path.relative_to(root).with_suffix("").parts)
  return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> set[str]:
  """Project modules named by the file's imports (anywhere in the file, lazy ones included)."""
  out = set()
  for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
    if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
      out.add(node.module)
      out.update(f"{node.module}.{a.name}" for a in node.names)
    elif isinstance(node, ast.Import):
      out.update(a.name for a in node.names)
  return {m for m in out if m.split(".")[0] in ("jaxfilters", "sims", "benchmarks")}


def _sims_modules():
  return sorted(p for p in (ROOT / "sims").rglob("*.py"))


def test_every_sims_module_sits_in_a_package_named_for_its_concern():
  loose = [p.name for p in (ROOT / "sims").glob("*.py") if p.name != "__init__.py"]
  assert loose == [], f"modules directly under sims/: {loose}"
  packages = {p.name for p in (ROOT / "sims").iterdir() if (p / "__init__.py").is_file()}
  assert packages == set(ALLOWED), packages
  for name in packages:
    doc = ast.get_docstring(ast.parse((ROOT / "sims" / name / "__init__.py").read_text(encoding="utf-8")))
    if name != "commands":
      assert doc and "Imports:" in doc, f"sims/{name}/__init__.py must say what it holds and may import"


@pytest.mark.parametrize("path", _sims_modules(), ids=lambda p: p.relative_to(ROOT).as_posix())
def test_sims_imports_run_one_way(path):
  rel = path.relative_to(ROOT / "sims").parts
  if len(rel) == 1:
    return                                         # sims/__init__.py: the face, lazy names only
  room = rel[0]
  bad = []
  for mod in _imports(path):
    parts = mod.split(".")
    if parts[0] == "benchmarks" and room != "commands":     # `jaxfilters bench` runs a checkout's harness
      bad.append(mod)
    elif parts[0] == "sims" and len(parts) > 1 and parts[1] in ALLOWED:
      if parts[1] != room and parts[1] not in ALLOWED[room]:
        bad.append(mod)
  assert not bad, f"sims/{'/'.join(rel)} ({room}) imports {bad}; {room} may import {sorted(ALLOWED[room]) or 'none'}"


def test_jaxfilters_never_imports_sims_or_benchmarks():
  bad = [(p.relative_to(ROOT).as_posix(), m) for p in (ROOT / "jaxfilters").rglob("*.py")
         for m in _imports(p) if m.split(".")[0] in ("sims", "benchmarks")]
  assert bad == []


def _circles(paths, root: Path = ROOT) -> list[list[str]]:
  files = {_module(p, root): p for p in paths if p.name != "__init__.py"}
  graph = {m: {i for i in _imports(p) if i in files and i != m} for m, p in files.items()}
  index, low, stack, on, groups = {}, {}, [], set(), []

  def visit(v):
    index[v] = low[v] = len(index)
    stack.append(v)
    on.add(v)
    for w in graph[v]:
      if w not in index:
        visit(w)
        low[v] = min(low[v], low[w])
      elif w in on:
        low[v] = min(low[v], index[w])
    if low[v] == index[v]:
      group = []
      while True:
        w = stack.pop()
        on.discard(w)
        group.append(w)
        if w == v:
          break
      if len(group) > 1:
        groups.append(sorted(group))

  for v in sorted(graph):
    if v not in index:
      visit(v)
  return groups


def test_no_import_circles():
  paths = [p for r in ("jaxfilters", "sims", "benchmarks") for p in (ROOT / r).rglob("*.py")]
  assert _circles(paths) == []


def test_the_circle_finder_finds_a_circle(tmp_path):
  """The check above is not vacuous: two modules importing each other are one circle."""
  pkg = tmp_path / "sims" / "fleet"
  pkg.mkdir(parents=True)
  (pkg / "a.py").write_text("from sims.fleet import b\n")
  (pkg / "b.py").write_text("import sims.fleet.a\n")
  (pkg / "c.py").write_text("import sims.fleet.a\n")
  assert _circles(sorted(pkg.glob("*.py")), tmp_path) == [["sims.fleet.a", "sims.fleet.b"]]


def test_tests_mirror_the_rooms():
  """Test files live in tests/<room>/ named by subject; tests/ itself holds shared fixtures and helpers."""
  top = sorted(p.name for p in (ROOT / "tests").glob("test_*.py"))
  assert top == [], f"test files directly under tests/: {top}"
  rooms = {p.name for p in (ROOT / "tests").iterdir() if p.is_dir() and any(p.glob("test_*.py"))}
  assert rooms <= TEST_ROOMS, rooms - TEST_ROOMS
  history = [p.relative_to(ROOT).as_posix() for p in (ROOT / "tests").rglob("test_*.py")
             if any(w in p.stem for w in ("trust", "regression", "issue", "bug", "fixes", "review"))]
  assert history == [], f"test files named by the history of the work: {history}"
  fuzzers = [p.relative_to(ROOT).as_posix() for p in (ROOT / "tests").rglob("fuzz_*.py") if p.parent.name != "fuzz"]
  assert fuzzers == [], f"fuzz targets outside tests/fuzz/: {fuzzers}"
