"""BENCHMARKS.md's current tables are what benchmarks/tables.py makes of benchmarks/results/*.json."""

from __future__ import annotations

import json
import re

import pytest

from benchmarks import tables


def test_benchmarks_md_top_is_the_generated_tables():
  top, _ = tables.split(tables.BENCHMARKS_MD.read_text())
  assert top == tables.generate(), "run python -m benchmarks.tables --write after editing benchmarks/results/"


def test_every_run_names_its_date_command_and_baseline():
  for device in tables.DEVICES:
    data = tables.load(device)
    assert data["device"] and data["environment"]
    for run in data["runs"]:
      assert re.fullmatch(r"\d{4}-\d{2}-\d{2}", run["date"]), run
      assert run["command"] and run["baseline"] and run["source"] and run["id"]
      assert run["harness"] in ("benchmarks.run", "benchmarks.rl_bench", "benchmarks.ppo_scaling", "rl_train")


def test_one_table_per_device_with_the_fleet_rows_notebook_03_reads():
  top = tables.generate()
  for device in ("NVIDIA H100", "NVIDIA H200", "CPU"):
    assert re.search(rf"^## {device}", top, re.M), device
  fleet = [line for line in top.splitlines() if line.startswith("| fleet,")]
  assert len(fleet) == 6 and all(re.search(r"[\d.]+ [KMG] robot-steps/s", line) for line in fleet)


def test_a_newer_run_replaces_the_figures_it_measured(tmp_path):
  data = tables.load("cpu")
  newer = {"id": "N", "harness": "benchmarks.run", "date": "2099-01-01", "command": "python -m benchmarks --json",
           "baseline": "b", "source": "s",
           "results": {"inflation": {"label": "inflation (R=14)", "params": {"B": 64, "H": 200, "W": 200},
                                     "compile_s": 0.5, "steady_s": 0.004, "throughput": 640e6, "unit": "cells/s"}}}
  data["runs"].insert(0, newer)
  for device in tables.DEVICES:
    (tmp_path / f"{device}.json").write_text(json.dumps(data if device == "cpu" else tables.load(device)))
  text = tables.generate(tmp_path)
  rows = [line for line in text.splitlines() if line.startswith("| inflation")]
  assert "| inflation (R=14) | B=64, 200x200 | 0.5 s | 4 ms | 640 Mcell/s |  |  | N |" in rows
  assert not any("476 Mcell/s" in r for r in rows)


@pytest.mark.parametrize("x, unit, want", [(701e9, "cells/s", "701 Gcell/s"), (26.7e6, "robot-steps/s", "26.7 M robot-steps/s"),
                                           (71.9e3, "robot-steps/s", "71.9 K robot-steps/s"), (4.24e12, "bytes/s", "4.24 TB/s")])
def test_rates_print_the_recorded_digits(x, unit, want):
  assert tables.rate(x, unit) == want


def test_check_fails_on_a_stale_file(tmp_path, monkeypatch):
  stale = tmp_path / "BENCHMARKS.md"
  fresh = tables.generate()
  row = "| keepout, same frame, aligned (XLA) |"
  assert row in fresh
  stale.write_text(fresh.replace(row, "| keepout, same frame, aligned (XLA), an old label |", 1) + "history\n")
  monkeypatch.setattr(tables, "BENCHMARKS_MD", stale)
  assert tables.main(["--check"]) == 1
  assert tables.main(["--write"]) == 0
  assert stale.read_text() == tables.generate() + "history\n"
