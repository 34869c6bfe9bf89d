"""The benchmark and developer commands refuse a bad argument as the `jaxfilters` commands do: one
line on stderr naming it, exit code 2 (jaxfilters.cli.ArgumentParser), not argparse's usage dump."""

from __future__ import annotations

import importlib

import pytest

MODULES = ["benchmarks.run", "benchmarks.asymmetric", "benchmarks.fleet_breakdown", "benchmarks.latency",
           "benchmarks.mjx_impl_compare", "benchmarks.ppo_scaling", "benchmarks.rl_bench", "benchmarks.tables",
           "sims.commands.make_default_scenario", "sims.commands.readme_picture", "sims.commands.rl_picture",
           "sims.commands.sharding", "sims.commands.soak"]


@pytest.mark.parametrize("module", MODULES)
def test_an_unknown_option_is_one_line_and_exit_2(module, capsys):
  """Each module's `main(argv)` (what `python -m` runs; `python -m benchmarks` is benchmarks.run's)."""
  with pytest.raises(SystemExit) as e:
    importlib.import_module(module).main(["--no-such-option"])
  assert e.value.code == 2
  err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
  # the unknown option, or the required arguments argparse checks first
  assert len(err) == 1 and ("unrecognized arguments: --no-such-option" in err[0]
                            or "the following arguments are required" in err[0]), err
  assert err[0].endswith("--help)"), err
