"""notebooks/: committed with their outputs, and each runs top to bottom in a fresh `python3` kernel.

The run executes a copy with nbclient in the venv's ipykernel (kernel name `python3`, the one the
notebooks name) from notebooks/ (they read ../BENCHMARKS.md and, when present,
../../shared/maps/nav2), and writes the executed copy to a temporary folder: the committed
notebooks are never rewritten by the tests. Each notebook checks its own numbers against an
independent reference in its cells (asserts), so a wrong result fails here as a cell error.

The kernel gets JAXFILTERS_NOTEBOOK_QUICK=1: notebooks whose sweeps compile one program per
setting (02, 03) then run fewer settings through the same cells, and 04 trains with the suite's small
run (tests/rl_small.py), whose programs the RL tests compile; with the variable unset they run as
committed.
"""

import base64
import os
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

from tests import rl_small

ROOT = Path(__file__).resolve().parents[2]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
EXPECTED = ["01_quickstart.ipynb", "02_fleet_experiment.ipynb", "03_scaling.ipynb", "04_rl.ipynb",
            "05_soft_zones.ipynb"]
MAX_FIGURE_BYTES = 200_000
MAX_NOTEBOOK_BYTES = 1_000_000


def _images(nb):
  return [base64.b64decode(o["data"]["image/png"]) for c in nb.cells if c.cell_type == "code"
          for o in c.get("outputs", []) if "image/png" in o.get("data", {})]


def _errors(nb):
  return [f"{o['ename']}: {o['evalue']}" for c in nb.cells if c.cell_type == "code"
          for o in c.get("outputs", []) if o.get("output_type") == "error"]


def test_the_notebooks_are_there():
  assert [p.name for p in NOTEBOOKS] == EXPECTED


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_committed_with_outputs_that_read_on_a_code_host(path):
  assert path.stat().st_size < MAX_NOTEBOOK_BYTES
  nb = nbformat.read(path, as_version=4)
  nbformat.validate(nb)
  assert nb.metadata["kernelspec"]["name"] == "python3"
  code = [c for c in nb.cells if c.cell_type == "code"]
  assert code and all(c.execution_count is not None for c in code), "committed without running every cell"
  assert [c.execution_count for c in code] == list(range(1, len(code) + 1)), "not run top to bottom once"
  assert not _errors(nb)
  images = _images(nb)
  assert images, "no figure in the committed outputs"
  assert all(len(png) < MAX_FIGURE_BYTES for png in images), [len(png) for png in images]


@pytest.mark.parametrize("quick", [True, False])
def test_rl_notebook_quick_run_is_the_suites_small_run(quick, monkeypatch):
  """04's quick run trains with tests/rl_small.py's sizes (its programs are then the ones the RL tests
  compile, shared through the session's compilation cache); its full run keeps the sizes it shows."""
  monkeypatch.setenv("JAXFILTERS_NOTEBOOK_QUICK", "1" if quick else "0")
  cell = next(c for c in nbformat.read(ROOT / "notebooks" / "04_rl.ipynb", as_version=4).cells
              if c.cell_type == "code").source
  scope = {}
  exec(cell[:cell.index("import jax")], scope)    # noqa: S102 - the parameter lines, before anything is built
  got = (scope["ENVS"], scope["NSTEPS"], scope["EPISODE_LENGTH"], scope["HIDDEN"], scope["NUM_EVAL"])
  want = ((rl_small.NUM_ENVS, rl_small.NUM_STEPS, rl_small.EPISODE_LENGTH, rl_small.HIDDEN, rl_small.NUM_EVAL)
          if quick else (16, 32, 100, (64, 64), 16))
  assert got == want
  assert "training_env(randomize=True, seed=0, layouts=4)" in cell and (rl_small.SEED, rl_small.LAYOUTS) == (0, 4)


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs_top_to_bottom(path, tmp_path, monkeypatch):
  # The kernel is a child process: it inherits PYTHONPATH (this checkout's code first), the
  # XLA_FLAGS tests/conftest.py chose and the quick-run switch.
  monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(ROOT)] + [p for p in [os.environ.get("PYTHONPATH")] if p]))
  monkeypatch.setenv("JAXFILTERS_NOTEBOOK_QUICK", "1")
  nb = nbformat.read(path, as_version=4)
  client = NotebookClient(nb, timeout=600, kernel_name="python3",
                          resources={"metadata": {"path": str(path.parent)}})
  client.execute()                 # raises CellExecutionError with the cell and traceback
  nbformat.write(nb, tmp_path / path.name)
  assert not _errors(nb)
  images = _images(nb)
  assert images and all(len(png) < MAX_FIGURE_BYTES for png in images), [len(png) for png in images]
