"""A short run of tests/fuzz/fuzz_cli_values.py (the full run: `python -m tests.fuzz.fuzz_cli_values`)."""

from __future__ import annotations

import pytest

from tests.fuzz import fuzz_cli_values as fuzz

pytest.importorskip("rosbags")


@pytest.mark.parametrize("seed", [1, 2])
def test_option_values_follow_the_rule(seed):
  counts = fuzz.fuzz_values(400, seed)
  assert counts["type_checks"] >= 400 * 30 and counts["whole_parses"] > 0 and counts["values_accepted"] > 0


@pytest.mark.parametrize("seed", [1, 2])
def test_bag_folder_states_follow_the_rule(seed):
  counts = fuzz.fuzz_folders(600, seed)
  assert counts["folder_checks"] == 600 and counts["folders_accepted"] > 0 and counts["refused_removals"] > 0
