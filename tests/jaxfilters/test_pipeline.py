"""Layers then filters in Nav2's order: keepout zones are not inflated unless run as a layer."""

import numpy as np
import pytest

import jaxfilters as jf


def _setup():
  occ = np.zeros((1, 30, 30), np.int8)
  occ[0, 5, 5] = 100
  mask = jf.FilterMask.create(jf.OccupancyGrid.create(np.pad(np.full((4, 4), 100, np.int8), ((13, 13), (13, 13))),
                                                      0.05, (0, 0)), jf.FilterInfo.create(0))
  infl = jf.InflationConfig(inflation_radius=0.25, cost_scaling_factor=3.0, inscribed_radius=0.1, resolution=0.05)
  return occ, mask, infl


def test_filters_run_after_inflation_on_the_combined_map():
  occ, mask, infl = _setup()
  cfg = jf.LayersConfig(inflation=infl)
  out = jf.costmap_pipeline(occ, np.zeros((1, 2)), np.full((1,), 0.05), np.zeros((1, 3)), config=cfg,
                            keepout_mask=mask, keepout_state=jf.KeepoutState.create(1))
  primary, combined = np.asarray(out.primary.cost[0]), np.asarray(out.combined.cost[0])
  assert primary[5, 5] == 254 and primary[5, 6] == 253        # the static obstacle is inflated
  assert primary[15, 15] == 0 and combined[15, 15] == 254     # keepout only on the combined map
  assert combined[15, 12] == 0                                # ... and not inflated
  np.testing.assert_array_equal(np.where(combined == primary, 0, 1).sum(), 16)


def test_keepout_as_layer_is_inflated():
  occ, mask, infl = _setup()
  cfg = jf.LayersConfig(inflation=infl, keepout_as_layer=True)
  out = jf.costmap_pipeline(occ, np.zeros((1, 2)), np.full((1,), 0.05), np.zeros((1, 3)), config=cfg,
                            keepout_mask=mask, keepout_state=jf.KeepoutState.create(1))
  combined = np.asarray(out.combined.cost[0])
  assert combined[15, 15] == 254 and combined[15, 12] == 253


def test_obstacles_and_speed_in_one_cycle():
  occ, _, infl = _setup()
  speed = jf.FilterMask.create(jf.OccupancyGrid.create(np.full((30, 30), 40, np.int8), 0.05, (0, 0)),
                               jf.FilterInfo.create(1, 100.0, -1.0))
  obstacles = np.zeros((1, 30, 30), bool)
  obstacles[0, 20, 20] = True
  out = jf.costmap_pipeline(occ, np.zeros((1, 2)), np.full((1,), 0.05), np.full((1, 3), 0.5, np.float32),
                            config=jf.LayersConfig(inflation=infl), obstacles=obstacles,
                            speed_mask=speed, speed_state=jf.SpeedState.create(1))
  assert int(out.combined.cost[0, 20, 20]) == 254 and int(out.combined.cost[0, 20, 21]) == 253
  assert float(out.speed.speed_limit[0]) == 60.0 and bool(out.speed.changed[0])


# --- the inflation layers of a params file, in plugins: order (LayersConfig.from_nav2) ---

_LAYERS = """\
local_costmap:
  local_costmap:
    ros__parameters:
      resolution: 0.05
      robot_radius: 0.12
      plugins: [{plugins}]
      lane_layer:
        plugin: "nav2_costmap_2d::AsymmetricInflationLayer"
        inflation_radius: 0.4
        cost_scaling_factor_left: 2.0
        cost_scaling_factor_right: 8.0
        goal_distance_threshold: 0.3
      inflation_layer:
        plugin: "nav2_costmap_2d::InflationLayer"
        inflation_radius: 0.3
        cost_scaling_factor: 5.0
"""


def _nav2_costmap(tmp_path, plugins):
  path = tmp_path / "params.yaml"
  path.write_text(_LAYERS.format(plugins=", ".join(f'"{p}"' for p in plugins)))
  return jf.load_params(path, costmaps=("local_costmap",)).local_costmap


def _walls(b=2, n=40, seed=0):
  rng = np.random.default_rng(seed)
  occ = np.zeros((b, n, n), np.int8)
  occ[:, 12, 4:36] = 100                 # a wall along x, below the path
  occ[:, 28, 4:36] = 100                 # and one above it
  occ[rng.random((b, n, n)) < 0.01] = 100
  return occ


def _path(b=2):
  """Along +x between the walls at y = 1.0 m, then some unused points."""
  p = np.zeros((b, 6, 2), np.float32)
  p[:, :4, 0] = np.linspace(0.2, 1.8, 4)
  p[:, :4, 1] = 1.0
  p[:, 4:] = 7.0
  return p, np.asarray([4, 4], np.int32)


def test_params_layers_run_in_plugins_order(tmp_path):
  cm = _nav2_costmap(tmp_path, ["lane_layer", "inflation_layer"])
  cfg = jf.LayersConfig.from_nav2(cm)
  asym, plain = cfg.layers
  assert isinstance(asym, jf.AsymmetricInflationConfig) and isinstance(plain, jf.InflationConfig)
  occ, (paths, lengths) = _walls(), _path()
  poses = np.asarray([[0.2, 1.0, 0.0], [0.6, 0.9, 0.3]], np.float32)
  out = jf.costmap_pipeline(occ, np.zeros((2, 2)), np.full((2,), 0.05), poses, config=cfg,
                            paths=paths, path_lengths=lengths)
  static = jf.static_layer(occ, config=cfg.static)
  by_hand = jf.asymmetric_inflate(static, paths=paths, path_lengths=lengths, robot_xy=poses[:, :2], config=asym)
  by_hand = jf.inflate(by_hand, config=plain)
  np.testing.assert_array_equal(np.asarray(out.primary.cost), np.asarray(by_hand))
  # The asymmetric layer did something: the plain layer alone gives other costs.
  alone = jf.inflate(static, config=plain)
  assert np.any(np.asarray(alone) != np.asarray(by_hand))
  # The other order is another costmap: the order is the file's.
  other = jf.LayersConfig.from_nav2(_nav2_costmap(tmp_path, ["inflation_layer", "lane_layer"]))
  assert other.layers == (plain, asym)
  out2 = jf.costmap_pipeline(occ, np.zeros((2, 2)), np.full((2,), 0.05), poses, config=other,
                             paths=paths, path_lengths=lengths)
  by_hand2 = jf.asymmetric_inflate(jf.inflate(static, config=plain), paths=paths, path_lengths=lengths,
                                   robot_xy=poses[:, :2], config=asym)
  np.testing.assert_array_equal(np.asarray(out2.primary.cost), np.asarray(by_hand2))


def test_params_with_only_the_inflation_layer_is_todays_pipeline(tmp_path):
  cfg = jf.LayersConfig.from_nav2(_nav2_costmap(tmp_path, ["inflation_layer"]))
  occ = _walls(seed=1)
  poses = np.zeros((2, 3), np.float32)
  mask = _setup()[1]
  kw = {"keepout_mask": mask, "keepout_state": jf.KeepoutState.create(2)}
  new = jf.costmap_pipeline(occ, np.zeros((2, 2)), np.full((2,), 0.05), poses, config=cfg, **kw)
  old = jf.costmap_pipeline(occ, np.zeros((2, 2)), np.full((2,), 0.05), poses,
                            config=jf.LayersConfig(inflation=cfg.layers[0]), **kw)
  for a, b in ((new.primary.cost, old.primary.cost), (new.combined.cost, old.combined.cost)):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_asymmetric_layer_needs_paths(tmp_path):
  cfg = jf.LayersConfig.from_nav2(_nav2_costmap(tmp_path, ["inflation_layer", "lane_layer"]))
  occ, (paths, lengths) = _walls(), _path()
  args = (occ, np.zeros((2, 2)), np.full((2,), 0.05), np.zeros((2, 3), np.float32))
  with pytest.raises(ValueError, match="AsymmetricInflationLayer.*pass paths"):
    jf.costmap_pipeline(*args, config=cfg)
  with pytest.raises(ValueError, match="paths and path_lengths go together"):
    jf.costmap_pipeline(*args, config=cfg, paths=paths)
  plain = jf.LayersConfig(layers=(cfg.layers[0],))
  with pytest.raises(ValueError, match="no AsymmetricInflationLayer to read them"):
    jf.costmap_pipeline(*args, config=plain, paths=paths, path_lengths=lengths)
  with pytest.raises(ValueError, match="not both"):
    jf.LayersConfig(inflation=cfg.layers[0], layers=cfg.layers)
  with pytest.raises(ValueError, match="tuple of InflationConfig"):
    jf.LayersConfig(layers=[cfg.layers[0]])
  with pytest.raises(TypeError, match="Nav2Costmap"):
    jf.LayersConfig.from_nav2(cfg)
