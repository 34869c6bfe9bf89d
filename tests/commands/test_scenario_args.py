"""`--params` gives the fleet its local costmap's inflation layers (Scenario.layers); what the fleet
cannot run is a one-line usage error."""

from pathlib import Path

import pytest

import jaxfilters as jf
from jaxfilters import cli
from sims.commands import scenario_args

ASSETS = Path(__file__).resolve().parents[2] / "sims" / "assets"
LANES = ASSETS / "nav2_params_lanes.yaml"


def _scenario(*argv):
  args = cli.build_parser().parse_args(["fleet", *argv])
  scenario_args.check_map_args(args)
  return scenario_args.scenario_from_args(args, "fleet")


def test_params_local_costmap_layers_reach_the_scenario():
  sc = _scenario("--map", str(ASSETS / "default_map.yaml"), "--params", str(LANES))
  assert [x.name for x in sc.layers] == ["lane_inflation_layer"]
  assert sc.layers[0].config == jf.AsymmetricInflationConfig(
      inflation_radius=0.8, cost_scaling_factor_left=3.0, cost_scaling_factor_right=6.0,
      goal_distance_threshold=1.0, inscribed_radius=sc.layers[0].config.inscribed_radius, resolution=0.05)
  # The filters come from the global costmap as before; a file whose local costmap lists no
  # inflation layer gives none (the fleet keeps its own inflation).
  assert sc.speed_type == 1 and sc.speed_base == 100.0
  assert _scenario("--map", str(ASSETS / "default_map.yaml"), "--params", str(ASSETS / "nav2_params.yaml")).layers == ()


def test_a_local_costmap_at_another_resolution_runs_at_the_maps_with_a_warning(tmp_path, capsys):
  """Nav2's bringup pairs a 0.05 m local costmap with its 0.03 m warehouse map; the fleet's local
  costmaps are windows of the map, so the layers run at the map's resolution and one line says so."""
  text = LANES.read_text()
  edit = ("resolution: 0.05\n      robot_radius", "resolution: 0.1\n      robot_radius")
  assert edit[0] in text
  params = tmp_path / "p.yaml"
  params.write_text(text.replace(*edit))
  masks = ["--mask", f"keepout_filter_mask_server={ASSETS / 'default_keepout.yaml'}",
           "--mask", f"speed_filter_mask_server={ASSETS / 'default_speed.yaml'}"]
  sc = _scenario("--map", str(ASSETS / "default_map.yaml"), "--params", str(params), *masks)
  warn = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
  assert len(warn) == 1 and "lane_inflation_layer" in warn[0] and "at resolution 0.1 m" in warn[0] \
      and "windows of the map at 0.05 m" in warn[0], warn
  assert sc.layers[0].config.resolution == 0.05 and sc.layers[0].config.inflation_radius == 0.8
  # The same file at the map's resolution: no warning.
  _scenario("--map", str(ASSETS / "default_map.yaml"), "--params", str(LANES))
  assert "warning" not in capsys.readouterr().err


@pytest.mark.parametrize("edit, extra, said", [
    (None, ["--keepout-escape", "center"], "keepout escape"),
], ids=["keepout-escape"])
def test_layers_the_fleet_cannot_run_are_usage_errors(edit, extra, said, tmp_path, capsys):
  params = LANES
  if edit is not None:
    params = tmp_path / "p.yaml"
    text = LANES.read_text()
    assert edit[0] in text
    params.write_text(text.replace(edit[0], edit[1]))
  masks = ["--mask", f"keepout_filter_mask_server={ASSETS / 'default_keepout.yaml'}",
           "--mask", f"speed_filter_mask_server={ASSETS / 'default_speed.yaml'}"]
  rc = cli.main(["fleet", "--map", str(ASSETS / "default_map.yaml"), "--params", str(params), *masks, *extra,
                 "--robots", "1", "--steps", "1", "--out", str(tmp_path / "o")])
  err = [line for line in capsys.readouterr().err.strip().splitlines() if "error" in line]
  assert rc == cli.EXIT_USAGE and len(err) == 1 and said in err[0], err
