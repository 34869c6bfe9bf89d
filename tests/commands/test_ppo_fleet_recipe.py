"""examples/ppo_fleet/recipe.py: its commands are valid `jaxfilters rl` command lines whose sizes pass the
checks `rl train` makes before building anything, and its table goes between the README's markers.

Nothing is trained here (the recipe's own `--smoke` runs the commands end to end, in minutes)."""

import importlib.util
from pathlib import Path

import pytest

from jaxfilters import cli
from sims.commands import rl as rl_cmd
from sims.rl.ppo import plan_training
from tests.commands.test_rl import rl_entry_point  # noqa: F401  (fixture)

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def recipe():
  spec = importlib.util.spec_from_file_location("ppo_fleet_recipe", REPO / "examples" / "ppo_fleet" / "recipe.py")
  module = importlib.util.module_from_spec(spec)
  spec.loader.exec_module(module)
  return module


@pytest.mark.parametrize("smoke", [False, True])
def test_commands_parse_and_pass_the_size_checks(recipe, smoke, tmp_path, rl_entry_point):  # noqa: F811
  parser = cli.build_parser()
  train = parser.parse_args(recipe.train_args(tmp_path / "pol", smoke, 10_000_000, 2048))
  assert train.robots_per_world == recipe.K_TRAIN and train.randomize and train.costmap_stop
  rl_cmd.check_batch(train.num_envs, train.num_steps)
  rl_cmd.check_robot_batch(train, train.robots_per_world)
  calls = plan_training(train.timesteps, train.num_envs, train.num_steps, train.evals)
  assert sum(calls) * train.num_envs * train.num_steps * train.robots_per_world < 2 ** 31
  runs = recipe.eval_runs(tmp_path / "pol", tmp_path / "maps", smoke)
  ks = []
  for _, argv in runs:
    e = parser.parse_args(argv)
    assert e.json and e.policy == tmp_path / "pol"
    ks.append(e.robots_per_world)
  assert ks == [2, 8, 32, 8] and parser.parse_args(runs[-1][1]).map == tmp_path / "maps" / "warehouse.yaml"


def test_table_goes_between_the_readme_markers(recipe, tmp_path):
  readme = tmp_path / "README.md"
  readme.write_text(f"# head\n\n{recipe.BEGIN}\nold\n{recipe.END}\n\ntail\n")
  recipe.write_readme(readme, "| new |\n")
  assert readme.read_text() == f"# head\n\n{recipe.BEGIN}\n| new |\n{recipe.END}\n\ntail\n"
  (tmp_path / "bare.md").write_text("no markers\n")
  with pytest.raises(SystemExit, match="no <!-- RESULTS BEGIN"):
    recipe.write_readme(tmp_path / "bare.md", "x")
  shipped = (REPO / "examples" / "ppo_fleet" / "README.md").read_text()
  assert shipped.count(recipe.BEGIN) == 1 and shipped.count(recipe.END) == 1
