"""`jaxfilters rl train` / `rl eval`: every size option bounded in the parser (bound in the help text),
integer options written plainly, empty paths refused, and nothing created by a refused command.

Every case runs in this process through `jaxfilters.cli.main` and is refused before the env or
the trainer is imported, so none compiles anything. The library's own bounds (where the value
enters: NavVectorEnv, GymnaxAdapter, NavEnv.create) are checked without building an env.
"""

from __future__ import annotations

import pytest

from jaxfilters import cli
from sims.commands import rl as rl_cli

pytest.importorskip("rejax")

TRAIN = ["rl", "train", "--timesteps", "64", "--num-envs", "4", "--num-steps", "8"]
# (option, value just past the bound, the bound as the message and the help text write it)
TRAIN_BOUNDS = [
    ("--timesteps", str(2 ** 30 + 1), "[1, 1,073,741,824]"),
    ("--timesteps", "10" + "0" * 29, "at most 30"),
    ("--num-envs", str(2 ** 21 + 1), "[1, 2,097,152]"),
    ("--num-envs", "1000000000000", "[1, 2,097,152]"),
    ("--num-steps", "4097", "[1, 4,096]"),
    ("--num-steps", "1000000000000", "[1, 4,096]"),
    ("--minibatches", "65537", "[1, 65,536]"),
    ("--episode-length", "100001", "[1, 100,000]"),
    ("--episode-length", str(2 ** 31), "[1, 100,000]"),
    ("--layouts", "1025", "[1, 1,024]"),
    ("--layouts", "1000000000", "[1, 1,024]"),
    ("--evals", "1001", "[1, 1,000]"),
    ("--num-eval", str(2 ** 18 + 1), "[1, 262,144]"),
    ("--num-eval", "1000000000000", "[1, 262,144]"),
    ("--seed", str(2 ** 32), "[0, 4,294,967,295]"),
]
EVAL_BOUNDS = [
    ("--episodes", str(2 ** 18 + 1), "[1, 262,144]"),
    ("--episodes", "3000000000", "[1, 262,144]"),
    ("--episodes", "1000000000000", "[1, 262,144]"),
    ("--layouts", "1000000000", "[1, 1,024]"),
    ("--episode-length", str(2 ** 31), "[1, 100,000]"),
    ("--seed", "-1", "[0, 4,294,967,295]"),
]


def _run(argv, capsys):
  rc = cli.main(argv)
  err = capsys.readouterr().err
  lines = [line for line in err.splitlines() if line.strip()]
  return rc, lines


@pytest.mark.parametrize("option, value, bound", TRAIN_BOUNDS, ids=[f"{o}={v[:14]}" for o, v, _ in TRAIN_BOUNDS])
def test_train_sizes_are_refused_in_the_parser(tmp_path, capsys, option, value, bound):
  rc, lines = _run(TRAIN + ["--out", str(tmp_path / "o"), option, value], capsys)
  assert rc == 2 and len(lines) == 1 and f"argument {option}:" in lines[0] and bound in lines[0], lines
  assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("option, value, bound", EVAL_BOUNDS, ids=[f"{o}={v[:14]}" for o, v, _ in EVAL_BOUNDS])
def test_eval_sizes_are_refused_in_the_parser(tmp_path, capsys, option, value, bound):
  rc, lines = _run(["rl", "eval", "--policy", str(tmp_path / "pol"), option, value], capsys)
  assert rc == 2 and len(lines) == 1 and f"argument {option}:" in lines[0] and bound in lines[0], lines


@pytest.mark.parametrize("argv, message", [
    (["--hidden", "2048,2048"], "--hidden must give 1 to 4 layers of 1 to 1024 units"),
    (["--hidden", "64,64,64,64,64"], "--hidden must give 1 to 4 layers of 1 to 1024 units"),
    (["--hidden", "6_4"], "--hidden must be comma-separated integers"),
    (["--hidden", " 64"], "--hidden must be comma-separated integers"),
    (["--num-envs", "2097152", "--num-steps", "64"], "--num-envs x --num-steps must be at most 2**26 = 67,108,864"),
    (["--devices", " 2"], "--devices must be a positive integer or 'all'"),
    (["--devices", "\uff12"], "--devices must be a positive integer or 'all'"),
    (["--devices", "4097", "--num-envs", "4097", "--minibatches", "1"], "--devices must be >= 1 and <= 4096"),
])
def test_train_cross_checks_are_one_line_before_anything(tmp_path, capsys, argv, message):
  rc, lines = _run(TRAIN + ["--out", str(tmp_path / "o")] + argv, capsys)
  assert rc == 2 and len(lines) == 1 and message in lines[0], lines
  assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("option", ["--timesteps", "--num-envs", "--num-steps", "--minibatches", "--episode-length",
                                    "--layouts", "--seed", "--evals", "--num-eval"])
@pytest.mark.parametrize("value", ["6_4", " 2 ", "2 ", "\uff16\uff14", "\u0664", "+2", "0x10", "2.0", "1e3", ""])
def test_integer_options_take_plain_ascii_digits_only(tmp_path, capsys, option, value):
  rc, lines = _run(TRAIN + ["--out", str(tmp_path / "o"), option, value], capsys)
  assert rc == 2 and len(lines) == 1 and f"argument {option}: invalid int value" in lines[0], lines


@pytest.mark.parametrize("argv, message", [
    (TRAIN + ["--out", ""], "argument --out: must name a path"),
    (["rl", "eval", "--policy", ""], "argument --policy: must name a path"),
    (["rl", "eval", "--policy", "pol", "--map", ""], "argument --map: must name a path"),
])
def test_empty_paths_are_refused_not_read_as_the_current_folder(capsys, argv, message):
  rc, lines = _run(argv, capsys)
  assert rc == 2 and len(lines) == 1 and message in lines[0], lines


def test_refused_devices_leave_no_out_folder(tmp_path, capsys):
  """More devices than the host has: refused, and --out (not there before) is still not there."""
  import jax
  n = len(jax.devices()) + 1
  out = tmp_path / "o"
  rc, lines = _run(["rl", "train", "--timesteps", "64", "--num-envs", str(4 * n), "--num-steps", "8",
                    "--minibatches", "1", "--evals", "1", "--devices", str(n), "--out", str(out)], capsys)
  assert rc == 2 and len(lines) == 1 and "--devices" in lines[0], lines
  assert not out.exists()


def test_help_states_every_bound(capsys):
  for sub, options in (("train", ["1,073,741,824", "2,097,152", "4,096", "67,108,864", "65,536", "100,000", "1,024",
                                  "1,000", "262,144", "4 layers of 1 to 1024 units", "4,096"]),
                       ("eval", ["262,144", "1,024", "100,000"])):
    assert cli.main(["rl", sub, "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    for bound in options:
      assert bound in text, (sub, bound)


def test_parser_bounds_are_the_librarys():
  """What the commands accept, the library accepts (the CLI names the bounds without importing the env)."""
  from sims.rl import adapter, gym as gym_env, env as rl
  assert rl_cli.MAX_LAYOUTS == rl.MAX_LAYOUTS
  from sims.rl import policy
  assert (rl_cli.MAX_HIDDEN_LAYERS, rl_cli.MAX_HIDDEN_UNITS) == (policy.MAX_LAYERS, policy.MAX_HIDDEN)
  assert rl_cli.MAX_EPISODE_LENGTH == policy.MAX_EPISODE_LENGTH
  assert rl_cli.MAX_ENVS == gym_env.MAX_NUM_ENVS
  assert rl_cli.MAX_EPISODE_LENGTH <= min(adapter.MAX_EPISODE_LENGTH, gym_env.MAX_EPISODE_LENGTH)
  assert rl_cli.MAX_TIMESTEPS * 3 // 2 + rl_cli.MAX_BATCH < 2 ** 31     # rounded up and split: still an int32


@pytest.mark.parametrize("num_envs", [2 ** 21 + 1, 2 ** 31, 10 ** 12])
def test_nav_vector_env_refuses_sizes_with_value_error(num_envs):
  from sims.rl.gym import NavVectorEnv
  with pytest.raises(ValueError, match=r"num_envs must be at most 2\*\*21 = 2,097,152"):
    NavVectorEnv(num_envs)


@pytest.mark.parametrize("length", [0, 2 ** 24 + 1, 2 ** 31])
def test_episode_length_is_bounded_where_it_enters(length):
  from sims.rl.adapter import GymnaxAdapter
  from sims.rl.gym import NavGymEnv
  with pytest.raises(ValueError, match=r"episode_length must be an integer in \[1, 2\*\*24\]"):
    GymnaxAdapter(None, length)
  with pytest.raises(ValueError, match=r"episode_length must be an integer in \[1, 2\*\*24\]"):
    NavGymEnv(episode_length=length)


@pytest.mark.parametrize("layouts", [1025, 10 ** 9])
def test_nav_env_layouts_are_bounded_before_anything_is_built(layouts):
  from sims.rl.env import NavEnv
  with pytest.raises(ValueError, match=r"layouts must be at most 1024"):
    NavEnv.create(None, layouts=layouts)
