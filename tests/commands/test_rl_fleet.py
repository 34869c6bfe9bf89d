"""`jaxfilters rl train/eval --robots-per-world K`: one policy for every robot, trained at one K and
evaluated at another, and the option's bounds (exit 2, one line, nothing built).

One tiny training run (2 worlds of 2 robots, 2 PPO iterations of 4 steps, fixed zones) is shared by
the module; it is evaluated at K = 3.
"""

from __future__ import annotations

import json

import pytest

from sims.rl import policy as P
from tests.commands.test_rl import rl_entry_point, run_cli, write_policy  # noqa: F401  (fixtures)

TRAIN = ["rl", "train", "--timesteps", "16", "--num-envs", "2", "--num-steps", "4", "--episode-length", "4",
         "--evals", "1", "--num-eval", "1", "--hidden", "8", "--minibatches", "2", "--seed", "2"]


@pytest.fixture(scope="module")
def fleet_policy(rl_entry_point, tmp_path_factory):  # noqa: F811
  out = tmp_path_factory.mktemp("fleet") / "pol"
  rc, stdout, stderr = run_cli([*TRAIN, "--robots-per-world", "2", "--costmap-stop", "--out", str(out)])
  assert rc == 0, stderr
  return out, stdout, stderr


def test_train_records_the_per_robot_mode(fleet_policy):
  out, _, stderr = fleet_policy
  pol = P.load_policy(out)
  assert pol.env_config.agents == "per_robot" and pol.env_config.costmap_stop and pol.robots_per_world == 2
  assert (pol.observation_size, pol.action_size) == (98, 2)
  results = json.loads((out / "results.json").read_text())
  # 2 iterations of 2 worlds x 4 steps: 16 world steps, 32 robot-steps, counted on the device.
  assert results["env_steps"] == 16 and results["curve"]["agent_steps"] == [0.0, 32.0]
  assert results["config"]["robots_per_world"] == 2 and "robot_collisions" in results["final"]
  assert "one agent per robot of 2 per world (32 robot-steps)" in stderr and "robot collisions" in stderr


def test_eval_at_another_k_reports_per_robot_episode_figures(fleet_policy, capsys):
  out, _, _ = fleet_policy
  rc, stdout, stderr = run_cli(["rl", "eval", "--policy", str(out), "--episodes", "2", "--seed", "1",
                                "--episode-length", "3", "--robots-per-world", "3", "--json"])
  assert rc == 0, stderr
  r = json.loads(stdout)
  assert r["robots_per_world"] == 3 and r["robot_episodes"] == 6 and r["episodes"] == 2
  assert 0.0 <= r["success"] <= 1.0 and r["steps_per_episode"] <= 3
  assert r["robot_collisions"] == round(r["robot_collisions_per_robot_episode"] * 6)
  assert r["speed_excess_outside_entry_s"] >= 0.0 and r["keepout_entries"] >= 0


BAD = [
    (TRAIN + ["--robots-per-world", "0", "--out", "{tmp}/o"], "argument --robots-per-world: must lie in [1, 64]; got 0"),
    (TRAIN + ["--robots-per-world", "65", "--out", "{tmp}/o"], "argument --robots-per-world: must lie in [1, 64]; got 65"),
    (TRAIN + ["--robots-per-world", "3", "--minibatches", "5", "--out", "{tmp}/o"],
     "--minibatches (5) must divide --num-envs x --robots-per-world x --num-steps (24)"),
    (TRAIN + ["--robots-per-world", "2", "--devices", "2", "--out", "{tmp}/o"], "--devices with --robots-per-world"),
    (TRAIN + ["--robots-per-world", "64", "--num-envs", "2097152", "--out", "{tmp}/o"],
     "--num-envs x --robots-per-world x --num-steps must be at most 2**26"),
    (["rl", "eval", "--policy", "{ok}", "--robots-per-world", "0"], "argument --robots-per-world: must lie in [1, 64]"),
    (["rl", "eval", "--policy", "{ok}", "--robots-per-world", "2"],
     "--robots-per-world 2: the policy at {ok} drives a world of 1 robot(s) as one agent"),
]


@pytest.mark.parametrize("argv, message", BAD, ids=[b[1][:40] for b in BAD])
def test_bad_robots_per_world_exit_2_with_one_line(argv, message, tmp_path, rl_entry_point):  # noqa: F811
  names = {"tmp": tmp_path, "ok": write_policy(tmp_path / "ok")}
  rc, _, stderr = run_cli([a.format(**names) for a in argv])
  lines = [line for line in stderr.splitlines() if line.strip()]
  assert rc == 2 and len(lines) == 1 and message.format(**names) in lines[0], stderr
  assert "Traceback" not in stderr and not (tmp_path / "o").exists()


def test_help_states_the_bound(rl_entry_point):  # noqa: F811
  for sub in ("train", "eval"):
    rc, stdout, _ = run_cli(["rl", sub, "--help"])
    assert rc == 0 and "--robots-per-world K" in stdout and "1 to 64" in " ".join(stdout.split())
