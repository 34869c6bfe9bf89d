"""benchmarks/fleet_breakdown.py: the part arithmetic, the patches, the argument checks and one small run."""

from __future__ import annotations

import json

import pytest

from benchmarks import fleet_breakdown as fb
from sims.fleet import navigation, planner


def _r(ns, **kw):
  return {"ns_per_robot_step": ns, **kw}


def test_parts_are_differences_of_the_variants():
  results = {"bare_mjx": _r(10.0), "physics": _r(12.0), "metrics": _r(15.0), "speed_clip": _r(16.0),
             "costmap": _r(20.0), "full": _r(100.0, candidates=81), "candidates_half": _r(64.0, candidates=45),
             "const_lookups": _r(40.0), "reference_planner": _r(180.0), "controller_10hz": _r(60.0),
             "const_speed_lookups": "RuntimeError: out of memory"}
  p = fb.parts(results)
  assert p["physics"] == 12.0 and p["fleet_loop_over_bare_mjx"] == 2.0
  assert (p["metrics"], p["speed_filter_goals_clip"], p["local_costmap"], p["planner"]) == (3.0, 1.0, 4.0, 80.0)
  assert p["reference_planner"] == 160.0 and p["all_lookups"] == 60.0 and p["controller_half_rate_saves"] == 40.0
  assert p["per_candidate"] == pytest.approx(1.0) and p["planner_fixed_part"] == pytest.approx(80.0 - 81.0)
  assert p["full_fraction_of_bare"] == pytest.approx(0.1)
  assert "speed_cap_lookups" not in p          # a failed variant leaves its part out
  cpu = fb.parts({"physics": _r(12.0, cpu_ns_per_robot_step=20.0), "metrics": _r(15.0, cpu_ns_per_robot_step=26.0),
                  "bare_mjx": _r(10.0)}, "cpu_ns_per_robot_step")
  assert cpu == {"physics": 20.0, "metrics": 6.0}      # bare_mjx has no CPU figure: no fraction


def test_patches_are_undone_and_missing_names_listed():
  before = (planner.lut_at, planner.speed_cap_xy, navigation.value_and_direction, planner.rollout_mode)
  with fb.patched_lookups(("costmap", "speed", "nav", "rollout_chain")) as missing:
    assert planner.lut_at is not before[0] and planner.rollout_mode() == "chain"
    assert missing == []
  assert (planner.lut_at, planner.speed_cap_xy, navigation.value_and_direction, planner.rollout_mode) == before
  saved = planner.lut_at
  try:
    del planner.lut_at
    with fb.patched_lookups(("costmap",)) as missing:
      assert missing == ["sims.fleet.planner.lut_at"]
  finally:
    planner.lut_at = saved


@pytest.mark.parametrize("argv, message", [
    (["60"], "multiple of robots_per_world"),
    (["64", "--only", "physiks"], "unknown variant"),
    (["64", "--steps", "0"], ">= 1"),
    (["64", "--time-budget", "0"], "--time-budget must be > 0"),
])
def test_bad_arguments_exit_2(argv, message, capsys):
  with pytest.raises(SystemExit) as e:
    fb.main(argv)
  assert e.value.code == 2 and message in capsys.readouterr().err


def test_small_run_prints_one_json_line(capsys):
  assert fb.main(["16", "--steps", "20", "--repeats", "1", "--only", "physics,metrics",
                  "--time-budget", "1e-9"]) == 0
  out = capsys.readouterr().out.strip().splitlines()
  assert len(out) == 1
  report = json.loads(out[0])
  phys = report["variants"]["physics"]
  assert phys["robot_steps_per_s"] > 0 and phys["ns_per_robot_step"] == pytest.approx(1e9 / phys["robot_steps_per_s"])
  assert phys["robot_seconds_per_s"] == pytest.approx(phys["robot_steps_per_s"] * 0.01)
  assert report["variants"]["metrics"].startswith("skipped: --time-budget")
  assert report["num_robots"] == 16 and report["physics_steps"] == 20 and report["parts_ns"]["physics"] > 0
  assert report["parts_cpu_ns"]["physics"] > 0              # this test runs on the CPU backend
