"""load_params reads a costmap's InflationLayer and AsymmetricInflationLayer (docs/nav2_semantics.md §9).

Nav2's bringup params file (../shared/maps/nav2/nav2_params.yaml; skipped with the reason
when absent) loads unchanged with its layers; params files shaped like Nav2's with the new
plugin load with the layer's parameters, Nav2's defaults, the costmap's resolution and the
padded footprint's inscribed radius, or `custom_inscribed_radius` (Nav2 PR #6223) with
Nav2's warning; bad values raise Nav2ParamsError naming the layer and key.
"""

import dataclasses
import textwrap
import warnings

import numpy as np
import pytest

import jaxfilters as jf
from jaxfilters import nav2
from jaxfilters.nav2.layers import parse_footprint

_ENABLE = {"KEEPOUT_ZONE_ENABLED": "True", "SPEED_ZONE_ENABLED": "True"}
# Costmap2DROS keeps footprint_padding in a float: 0.01 is float32(0.01) when padded.
PAD = float(np.float32(0.01))


def test_bringup_file_layers(nav2_maps):
  masks = {"keepout_filter_mask_server": nav2_maps / "warehouse_keepout.yaml",
           "speed_filter_mask_server": nav2_maps / "warehouse_speed.yaml"}
  with warnings.catch_warnings():
    warnings.simplefilter("error")        # still not a single warning
    p = nav2.load_params(nav2_maps / "nav2_params.yaml", masks=masks, substitutions=_ENABLE)
  inscribed = jf.footprint_radii(robot_radius=0.22, footprint_padding=PAD)[0]
  for cm, radius in ((p.local_costmap, 0.70), (p.global_costmap, 0.7)):
    assert [x.name for x in cm.layers] == ["inflation_layer"]     # voxel, static, obstacle: not read
    assert cm.asymmetric_inflation is None
    assert cm.inflation.config == jf.InflationConfig(inflation_radius=radius, cost_scaling_factor=3.0,
                                                     inscribed_radius=inscribed, resolution=0.05)
    assert cm.inflation.plan_topic is None
  assert len(p.global_costmap.filters) == 2     # the filters are read as before


def _write(tmp_path, costmap_body, name="params.yaml"):
  text = "local_costmap:\n  local_costmap:\n    ros__parameters:\n" + textwrap.indent(
      textwrap.dedent(costmap_body), " " * 6)
  path = tmp_path / name
  path.write_text(text)
  return path


ASYM = """\
global_frame: odom
rolling_window: true
resolution: 0.025
footprint: "[[0.3, 0.2], [0.3, -0.2], [-0.3, -0.2], [-0.3, 0.2]]"
footprint_padding: 0.02
plugins: ["voxel_layer", "lane_layer", "inflation_layer"]
voxel_layer:
  plugin: "nav2_costmap_2d::VoxelLayer"
  enabled: true
lane_layer:
  plugin: "nav2_costmap_2d::AsymmetricInflationLayer"
  inflation_radius: 1.2
  cost_scaling_factor_left: 2.5
  cost_scaling_factor_right: 6.0
  goal_distance_threshold: 0.8
  inflate_around_unknown: true
  plan_topic: "global_plan"
inflation_layer:
  plugin: "nav2_costmap_2d::InflationLayer"
"""


def test_asymmetric_layer_params_and_defaults(tmp_path):
  with warnings.catch_warnings():
    warnings.simplefilter("error")
    cm = nav2.load_params(_write(tmp_path, ASYM)).local_costmap
  pts = [(0.3, 0.2), (0.3, -0.2), (-0.3, -0.2), (-0.3, 0.2)]
  inscribed = jf.footprint_radii(footprint=[tuple(float(np.float32(v)) for v in p) for p in pts],
                                 footprint_padding=float(np.float32(0.02)))[0]
  assert [x.name for x in cm.layers] == ["lane_layer", "inflation_layer"]
  lane = cm.asymmetric_inflation
  assert lane.plugin == nav2.ASYMMETRIC_INFLATION_PLUGIN and lane.plan_topic == "/global_plan"
  assert lane.config == jf.AsymmetricInflationConfig(
      inflation_radius=1.2, cost_scaling_factor_left=2.5, cost_scaling_factor_right=6.0,
      goal_distance_threshold=0.8, inscribed_radius=inscribed, resolution=0.025, inflate_around_unknown=True)
  # Nav2's InflationLayer defaults, the same costmap geometry.
  assert cm.inflation.config == jf.InflationConfig(inflation_radius=0.55, cost_scaling_factor=10.0,
                                                   inscribed_radius=inscribed, resolution=0.025)
  # The loaded config runs as is.
  cost = np.zeros((1, 20, 20), np.uint8)
  cost[0, 10, 10] = 254
  out = jf.asymmetric_inflate(jf.Costmap.create(cost, (0.0, 0.0), 0.025), paths=np.zeros((1, 2, 2), np.float32),
                              path_lengths=np.zeros(1, np.int32), robot_xy=np.zeros((1, 2), np.float32),
                              config=lane.config)
  assert out.cost[0, 10, 11] == 253


def test_defaults_without_parameters(tmp_path):
  body = """\
  plugins: ["lane"]
  lane:
    plugin: "nav2_costmap_2d::AsymmetricInflationLayer"
  """
  cm = nav2.load_params(_write(tmp_path, body)).local_costmap
  want = jf.AsymmetricInflationConfig(inscribed_radius=jf.footprint_radii(robot_radius=0.1, footprint_padding=PAD)[0],
                                      resolution=0.1)
  assert cm.asymmetric_inflation.config == want and cm.asymmetric_inflation.plan_topic == "/plan"
  assert cm.inflation is None


def test_custom_inscribed_radius(tmp_path):
  body = """\
  robot_radius: 0.22
  resolution: 0.05
  plugins: ["inflation_layer"]
  inflation_layer:
    plugin: "nav2_costmap_2d::InflationLayer"
    inflation_radius: 0.7
    custom_inscribed_radius: {}
  """
  with pytest.warns(nav2.Nav2ParamsWarning, match="POTENTIAL SAFETY ISSUE.*custom_inscribed_radius 0.35"):
    cm = nav2.load_params(_write(tmp_path, body.format(0.35))).local_costmap
  assert cm.inflation.config.inscribed_radius == 0.35
  with warnings.catch_warnings():
    warnings.simplefilter("error")
    cm = nav2.load_params(_write(tmp_path, body.format(-1.0))).local_costmap
  assert cm.inflation.config.inscribed_radius == jf.footprint_radii(robot_radius=0.22, footprint_padding=PAD)[0]
  # The asymmetric layer does not read it (Nav2 declares no such parameter there): said, not used.
  asym = body.replace("InflationLayer", "AsymmetricInflationLayer")
  with pytest.warns(nav2.Nav2ParamsWarning, match="does not read custom_inscribed_radius"):
    cm = nav2.load_params(_write(tmp_path, asym.format(0.35))).local_costmap
  assert cm.asymmetric_inflation.config.inscribed_radius == \
      jf.footprint_radii(robot_radius=0.22, footprint_padding=PAD)[0]


def test_nav2_warnings_it_logs_and_carries_on(tmp_path):
  body = """\
  robot_radius: 0.5
  footprint: "[[0.3, 0.2], [0.3]]"
  plugins: ["inflation_layer"]
  inflation_layer:
    plugin: "nav2_costmap_2d::InflationLayer"
    inflation_radius: 0.3
  """
  with pytest.warns(nav2.Nav2ParamsWarning) as record:
    cm = nav2.load_params(_write(tmp_path, body)).local_costmap
  said = " | ".join(str(w.message) for w in record)
  assert "footprint parameter is invalid" in said and "smaller than the computed/custom inscribed" in said
  assert cm.inflation.config.inscribed_radius == jf.footprint_radii(robot_radius=0.5, footprint_padding=PAD)[0]


@pytest.mark.parametrize("key,value,match", [
    ("cost_scaling_factor_left", "-1.0", "cost_scaling_factor_left must be >= 0"),
    ("cost_scaling_factor_right", "-0.5", "cost_scaling_factor_right must be >= 0"),
    ("inflation_radius", "-2.0", "inflation_radius must be >= 0"),
    ("goal_distance_threshold", "-0.1", "goal_distance_threshold must be >= 0"),
    ("num_threads", "-2", "num_threads' must be -1"),
    ("cost_scaling_factor_left", '"fast"', "cost_scaling_factor_left"),
    ("enabled", "3", "enabled"),
    ("plan_topic", '""', "plan_topic"),
])
def test_bad_asymmetric_parameters_raise(tmp_path, key, value, match):
  body = f"""\
  plugins: ["lane"]
  lane:
    plugin: "nav2_costmap_2d::AsymmetricInflationLayer"
    {key}: {value}
  """
  with pytest.raises(nav2.Nav2ParamsError, match=match) as e:
    nav2.load_params(_write(tmp_path, body))
  assert "layer 'lane'" in str(e.value) or "'lane." in str(e.value)


@pytest.mark.parametrize("body,match", [
    ("resolution: 0.0\nplugins: [\"i\"]\ni:\n  plugin: \"nav2_costmap_2d::InflationLayer\"\n", "resolution"),
    ("plugins: [\"i\"]\ni:\n  plugin: \"nav2_costmap_2d::InflationLayer\"\n  cost_scaling_factor: -3.0\n",
     "cost_scaling_factor must be >= 0"),
    ("footprint_padding: 1.0e300\nplugins: [\"i\"]\ni:\n  plugin: \"nav2_costmap_2d::InflationLayer\"\n",
     "footprint_padding"),
    ("transform_tolerance: -1.0\nplugins: [\"i\"]\ni:\n  plugin: \"nav2_costmap_2d::AsymmetricInflationLayer\"\n",
     "transform_tolerance' must be >= 0"),
])
def test_bad_costmap_or_inflation_parameters_raise(tmp_path, body, match):
  with pytest.raises(nav2.Nav2ParamsError, match=match):
    nav2.load_params(_write(tmp_path, body))


def test_two_layers_of_one_kind():
  layer = nav2.Nav2InflationLayer(name="a", plugin=nav2.INFLATION_PLUGIN,
                                  config=jf.InflationConfig(inscribed_radius=0.1, resolution=0.05))
  cm = nav2.Nav2Costmap(name="c", node="/c", global_frame="map", resolution=0.05, filters=(),
                        layers=(layer, dataclasses.replace(layer, name="b")))
  with pytest.raises(ValueError, match="2 nav2_costmap_2d::InflationLayer layers"):
    cm.inflation


def test_parse_footprint():
  assert parse_footprint("[[0.1, 0.2], [-0.1, 0.2], [0, -1e-1]]") == [
      (float(np.float32(0.1)), float(np.float32(0.2))), (float(np.float32(-0.1)), float(np.float32(0.2))),
      (0.0, float(np.float32(-0.1)))]
  for bad in ("[]", "[[0.1, 0.2], [0.3, 0.4]]", "[[0.1, 0.2, 0.3], [1, 2], [3, 4]]", "[[a, 1], [1, 2], [3, 4]]",
              "0.1, 0.2", "[[1, 2] [3, 4], [5, 6]]"):
    assert parse_footprint(bad) is None, bad


def test_bringup_file_switched_to_the_new_plugin(nav2_maps, tmp_path):
  """Nav2's bringup file with the local costmap's inflation layer switched to the AsymmetricInflationLayer
  (plugin line and the lane parameters added, as a user would) loads without a warning."""
  text = (nav2_maps / "nav2_params.yaml").read_text()
  old = '''      inflation_layer:
        plugin: "nav2_costmap_2d::InflationLayer"
        cost_scaling_factor: 3.0
        inflation_radius: 0.70
'''
  assert text.count(old) == 1
  new = '''      inflation_layer:
        plugin: "nav2_costmap_2d::AsymmetricInflationLayer"
        cost_scaling_factor_left: 3.0
        cost_scaling_factor_right: 6.0
        inflation_radius: 0.70
        goal_distance_threshold: 1.0
'''
  path = tmp_path / "nav2_params.yaml"
  path.write_text(text.replace(old, new))
  masks = {"keepout_filter_mask_server": nav2_maps / "warehouse_keepout.yaml",
           "speed_filter_mask_server": nav2_maps / "warehouse_speed.yaml"}
  with warnings.catch_warnings():
    warnings.simplefilter("error")
    p = nav2.load_params(path, masks=masks, substitutions=_ENABLE)
  lane = p.local_costmap.asymmetric_inflation
  assert p.local_costmap.inflation is None and lane.name == "inflation_layer" and lane.plan_topic == "/plan"
  assert lane.config == jf.AsymmetricInflationConfig(
      inflation_radius=0.70, cost_scaling_factor_left=3.0, cost_scaling_factor_right=6.0,
      goal_distance_threshold=1.0, inscribed_radius=jf.footprint_radii(robot_radius=0.22, footprint_padding=PAD)[0],
      resolution=0.05)
  assert p.global_costmap.inflation.config.cost_scaling_factor == 3.0
