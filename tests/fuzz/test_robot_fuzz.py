"""Robot MJCF files through `sims.fleet.robot.robot_from_xml`: the fuzzer's mutations, a few hundred in-process
and a short run of the sandboxed fuzzer (`python -m tests.fuzz.fuzz_inputs --targets robot`), whose long runs
(10**5 inputs) are the same code with a larger --count."""

from __future__ import annotations

import random

from sims.fleet import robot as R
from tests.fuzz import fuzz_inputs, fuzz_robot
from tests.fuzz.sandboxed import run_target


def test_every_seed_loads():
  for data in fuzz_robot.seeds():
    fuzz_robot.run(data)


def test_mutated_robots_load_within_the_interface_or_are_refused():
  outcomes = {"loaded": 0, "refused": 0}
  for i in range(400):
    data, _ = fuzz_inputs.make_input("robot", 0, i)
    try:
      fuzz_robot.run(data)              # checks the oracles of a loaded robot; other errors fail here
      outcomes["loaded"] += 1
    except R.RobotModelError as e:
      assert len(str(e)) < 1000 and "\n" not in str(e), str(e)
      outcomes["refused"] += 1
  assert outcomes["refused"] > 150 and outcomes["loaded"] > 20, outcomes


def test_every_mjcf_mutation_kind_runs():
  """Each MJCF-aware edit, on each seed, gives an input the loader takes or refuses (no other error)."""
  rng = random.Random(1)
  for data in fuzz_robot.seeds():
    for _ in range(60):
      try:
        fuzz_robot.run(fuzz_robot.edit(data, rng))
      except R.RobotModelError:
        pass


def test_the_sandboxed_fuzzer_runs_robots(tmp_path):
  lines = run_target("robot", tmp_path / "f")
  assert lines[1].split()[:2] == ["robot", "150"]
  assert "150 inputs in" in lines[2] and "failures: 0" in lines[2]
