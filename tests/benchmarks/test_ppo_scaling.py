"""benchmarks/ppo_scaling.py: --reset-capacity values are checked before anything is built."""

from __future__ import annotations

import pytest

from benchmarks import ppo_scaling


@pytest.mark.parametrize("value", ["0", "-3", "zero", "²", "4.5", ""])
def test_bad_reset_capacity_exits_2_naming_the_allowed_values(value, capsys):
  with pytest.raises(SystemExit) as e:
    ppo_scaling.main(["--devices", "1", "--num-envs", "64", "--reset-capacity", "auto", value])
  assert e.value.code == 2
  assert "--reset-capacity: each value must be auto, none or an integer >= 1" in capsys.readouterr().err
