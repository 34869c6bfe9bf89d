"""benchmarks/latency.py: its command line refuses what it cannot run, and the dispatch-floor row
times the add it names (the row the device table compares one robot's call against)."""

from __future__ import annotations

import pytest

from benchmarks import latency


@pytest.mark.parametrize("argv, says", [(["--paths", "floor,nope"], "--paths: unknown ['nope']"),
                                        (["--sizes", "1,x"], "--sizes must be comma-separated integers"),
                                        (["--sizes", "0"], "--sizes must be >= 1"),
                                        (["--entries", "nope"], "--entries: choose from")])
def test_wrong_arguments_exit_2_with_one_line(argv, says, capsys):
  with pytest.raises(SystemExit) as e:
    latency.main(argv)
  assert e.value.code == 2
  err = capsys.readouterr().err.strip().splitlines()
  assert says in err[-1]


def test_floor_row_times_eager_and_jitted_calls(monkeypatch):
  monkeypatch.setattr(latency, "MASK", 100)           # the costmaps only; the mask is not read
  row = latency.floor_rows(3)
  assert row["filter"] == "floor" and row["B"] == 3
  assert row["eager_us"] > 0 and row["jit_us"] > 0 and row["eager_n"] >= 7 and row["jit_n"] >= 7


def test_keepout_row_times_the_jitted_first_call_and_the_table_shows_it(monkeypatch):
  # A small mask and window: the row's set-up, checks and columns, not its figures. The escape row has
  # no C++ peer, so nothing is built here (tests/benchmarks/test_cpp_peers.py builds it).
  monkeypatch.setattr(latency, "MASK", 200)
  monkeypatch.setattr(latency, "HW", 12)
  row = latency.keepout_rows("aligned_escape", 2)
  assert row["filter"] == "keepout_aligned_escape" and row["B"] == 2
  assert row["jit_first_call_s"] > 0 and row["eager_us"] > 0 and row["jit_us"] > 0
  line = latency.table([row]).splitlines()[-1]
  assert line.endswith(f"| {row['jit_first_call_s']:.2f} |")
