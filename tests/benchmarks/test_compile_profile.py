"""benchmarks/compile_profile.py: a child process's compiles are logged and summed per file and program."""

from __future__ import annotations

import json
import sys

from benchmarks import compile_profile as cp

PROGRAM = "import jax, jax.numpy as jnp; f = jax.jit(lambda x: jnp.sin(x) * 2); f(1.0); f(2.0); f(jnp.ones(3))"


def test_a_child_process_compiles_are_logged_and_summed(tmp_path, capsys):
  log = tmp_path / "log"
  assert cp.main(["--log", str(log), "--", sys.executable, "-c", PROGRAM]) == 0
  out = capsys.readouterr().out
  rows = cp.read_log(log)
  mine = [r for r in rows if r["event"] == cp.COMPILE and r["fun"] == "jit(<lambda>)"]
  assert len(mine) == 2                      # a scalar and a [3]: two compiles, the second call reused one
  # The child inherits pytest's PYTEST_CURRENT_TEST: its events carry this test's name.
  here = "tests/benchmarks/test_compile_profile.py::test_a_child_process_compiles_are_logged_and_summed"
  assert all(r["test"].startswith(here) and r["s"] >= 0 for r in mine)
  assert list(cp.summarise(rows)["files"]) == ["tests/benchmarks/test_compile_profile.py"]
  s = cp.summarise(rows)
  assert s["programs"]["jit(<lambda>)"][0] == 2
  assert s["totals"]["compile"] >= sum(r["s"] for r in mine)
  assert "jit(<lambda>)" in out and "all: compile" in out


def test_summary_by_test_file_and_a_cut_line_skipped(tmp_path):
  log = tmp_path / "log"
  log.mkdir()
  lines = [{"test": "tests/a.py::test_x (call)", "event": cp.COMPILE, "s": 2.0, "fun": "jit(f)", "t": 0},
           {"test": "tests/a.py::test_y[1] (setup)", "event": cp.TRACE, "s": 0.5, "fun": "f", "t": 0},
           {"test": "tests/b.py::test_z (call)", "event": cp.COMPILE, "s": 3.0, "fun": "jit(f)", "t": 0}]
  (log / "1.jsonl").write_text("\n".join(json.dumps(r) for r in lines) + '\n{"test": "cut')
  # Another tool's lines in the folder (the summary once stopped on them with a KeyError).
  (log / "2.jsonl").write_text('{"name": "x", "dur": 1}\n[1, 2]\n{"test": "t", "event": "e", "fun": "f", "s": "2"}\n')
  s = cp.summarise(cp.read_log(log))
  assert list(s["files"]) == ["tests/b.py", "tests/a.py"]           # most compile first
  assert s["files"]["tests/a.py"] == {"compile": 2.0, "trace": 0.5, "lower": 0.0}
  assert s["programs"]["jit(f)"] == [2, 5.0, 3.0]


def test_a_used_log_folder_is_refused(tmp_path, capsys):
  (tmp_path / "old.jsonl").write_text("")
  assert cp.main(["--log", str(tmp_path), "--", sys.executable, "-c", "pass"]) == 2
  assert "must be an empty folder" in capsys.readouterr().err
  assert cp.main(["--log", str(tmp_path / "none")]) == 2
