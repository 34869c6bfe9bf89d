"""NavEnv inflates its static layer with a params file's local costmap InflationLayer
(Scenario.layers) and refuses an AsymmetricInflationLayer, for which it has no plan."""

import numpy as np
import pytest

import jaxfilters as jf
from jaxfilters.grid import OccupancyGrid
from jaxfilters.static_layer import static_layer
from sims.fleet.scenario import Scenario
from sims.fleet.world import STATIC_LAYER
from sims.rl.env import NavEnv
from tests.nav2_layers import local_layers

LAYERS = """\
      lane_layer:
        plugin: "nav2_costmap_2d::AsymmetricInflationLayer"
        cost_scaling_factor_left: 8.0
        cost_scaling_factor_right: 2.0
      inflation_layer:
        plugin: "nav2_costmap_2d::InflationLayer"
        inflation_radius: 0.45
        cost_scaling_factor: 6.0
"""


def _layers(tmp_path, plugins):
  return local_layers(tmp_path, plugins, LAYERS)


def _scenario(layers=()):
  """6 m x 4 m, walls around and one pillar; no zones."""
  occ = np.zeros((80, 120))
  occ[:2], occ[-2:], occ[:, :2], occ[:, -2:] = 100, 100, 100, 100
  occ[38:42, 58:62] = 100
  grid = lambda d: OccupancyGrid.create(d.astype(np.int8), 0.05, (0.0, 0.0, 0.0))
  zeros = np.zeros_like(occ)
  return Scenario("pillar", grid(occ), grid(zeros), grid(zeros), layers=tuple(layers))


def test_inflation_layer_inflates_the_static_layer(tmp_path):
  layers = _layers(tmp_path, ["inflation_layer"])
  env = NavEnv.create(_scenario(layers))
  static = static_layer(np.asarray(env.fleet.world.scenario.map.data)[None], config=STATIC_LAYER)
  got = np.asarray(env.mjx_model.task.static_inflated)
  np.testing.assert_array_equal(got, np.asarray(jf.inflate(static, config=layers[0].config)[0]))
  default = np.asarray(jf.inflate(static, config=env.fleet.world.inflation)[0])
  assert np.any(got != default)       # the params' radius and factor, not the fleet's


def test_asymmetric_layer_is_refused_at_creation(tmp_path):
  with pytest.raises(ValueError, match="the RL env has no plan for AsymmetricInflationLayer 'lane_layer'"):
    NavEnv.create(_scenario(_layers(tmp_path, ["inflation_layer", "lane_layer"])))
