"""policy.json through `sims.rl.policy.load_policy`: the fuzzer's mutations, a few hundred in-process and
a short run of the sandboxed fuzzer (`python -m tests.fuzz.fuzz_inputs --targets policy-json`), whose long
runs (10**5 inputs and more) are the same code with a larger --count."""

from __future__ import annotations

import random

from sims.rl import policy as P
from tests.fuzz import fuzz_policy
from tests.fuzz.sandboxed import run_target


def test_mutated_policy_json_loads_within_the_bounds_or_is_refused():
  rng = random.Random(0)
  seeds = fuzz_policy.json_seeds()
  outcomes = {"loaded": 0, "refused": 0}
  for i in range(400):
    data = seeds[i % len(seeds)]
    for _ in range(rng.randint(1, 3)):
      data = fuzz_policy.json_edit(data, rng)
    try:
      fuzz_policy.run_json(data)          # checks the oracles of a loaded policy
      outcomes["loaded"] += 1
    except P.PolicyError as e:
      assert len(str(e)) < 1000 and "\n" not in str(e), str(e)
      outcomes["refused"] += 1
  assert outcomes["refused"] > 200 and outcomes["loaded"] > 5, outcomes


def test_the_sandboxed_fuzzer_runs_policy_json(tmp_path):
  lines = run_target("policy-json", tmp_path / "f")
  assert lines[1].split()[:2] == ["policy-json", "150"]
  assert "150 inputs in" in lines[2] and "failures: 0" in lines[2]
