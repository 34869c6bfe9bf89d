"""Training counts: --timesteps and --evals do what the help text says, and the env steps reported
(results.json, the curve, the progress lines) are the ones the device counted.

One tiny run goes through the command line (tests/rl_small.py's: 4 envs x 8 steps, one hidden layer
of 16, 6-step episodes, the programs tests/commands/test_rl.py's run compiles); the plan and the
refusals are plain arithmetic.
"""

from __future__ import annotations

import json

import pytest

from sims.rl.ppo import MAX_ENV_STEPS, plan_training
from tests import rl_small
from tests.cli_run import run_cli


@pytest.mark.parametrize("timesteps, envs, steps, evals, calls", [
    (80, 4, 8, 2, [2, 1]),          # 3 iterations in 2 calls: 96 env steps
    (96, 4, 8, 3, [1, 1, 1]),
    (1, 4, 8, 1, [1]),
    (400_000, 32, 64, 20, [10] * 16 + [9] * 4),     # the defaults: 196 iterations
    (65, 4, 8, 3, [1, 1, 1]),
])
def test_plan_rounds_up_to_whole_iterations_in_evals_calls(timesteps, envs, steps, evals, calls):
  plan = plan_training(timesteps, envs, steps, evals)
  assert plan == calls
  per_iter = envs * steps
  assert sum(plan) * per_iter >= timesteps > (sum(plan) - 1) * per_iter     # the least whole iterations


@pytest.mark.parametrize("args, message", [
    ((10 ** 30, 32, 64, 20), "must be at most 2,147,483,647"),
    ((MAX_ENV_STEPS, 32, 64, 20), "rounded up to whole PPO iterations"),
    ((64, 4, 8, 3), r"evals \(3\) must be at most the PPO iterations \(2"),
    ((0, 4, 8, 1), "timesteps must be an integer >= 1"),
    ((64, 4, 8, 0), "evals must be an integer >= 1"),
    ((64.0, 4, 8, 1), "timesteps must be an integer"),
])
def test_plan_refuses_what_it_cannot_run(args, message):
  with pytest.raises(ValueError, match=message):
    plan_training(*args)


def test_huge_timesteps_exit_2_before_anything_is_built(tmp_path):
  rc, stdout, stderr = run_cli(["rl", "train", "--timesteps", str(10 ** 30), "--out", str(tmp_path / "o")])
  assert rc == 2 and len(stderr.strip().splitlines()) == 1, stderr
  assert "argument --timesteps" in stderr and not (tmp_path / "o").exists()      # the parser's bound
  rc, _, stderr = run_cli(["rl", "train", "--timesteps", "64", "--num-envs", "4", "--num-steps", "8",
                           "--evals", "3", "--out", str(tmp_path / "o")])
  assert rc == 2 and "--evals (3) must be at most" not in stderr and "evals (3) must be at most" in stderr
  assert not (tmp_path / "o").exists()


def test_timesteps_and_evals_do_what_the_help_says(tmp_path):
  out = tmp_path / "pol"
  rl_small.fresh_trace_caches()
  # The suite's small run (4 envs x 8 steps: 32 env steps per PPO iteration), whose programs are compiled once.
  rc, stdout, stderr = run_cli(["rl", "train", "--timesteps", "80", "--evals", "2", *rl_small.TRAIN_ARGS,
                                "--out", str(out)])
  assert rc == 0, stderr
  res = json.loads((out / "results.json").read_text())
  assert res["env_steps"] == 96                             # 80 rounded up to 3 iterations of 32
  assert res["curve"]["env_steps"] == [0.0, 64.0, 96.0]     # before training and after each of 2 calls
  assert all(len(v) == 3 for v in res["curve"].values())
  assert res["config"]["calls"] == 2 and res["config"]["iterations_per_call"] == [2, 1]
  progress = [line for line in stderr.splitlines() if "env steps " in line and "steps/s" in line]
  assert [line.split("/")[0].split()[-1] for line in progress] == ["0", "64", "96"], stderr
  assert all("/96 env steps" in line for line in progress)
  assert "96 env steps (2 calls of 2 or 1 iterations" in stderr
  assert res["timing"]["env_steps_per_s"] == pytest.approx(96 / res["timing"]["train_s"])
