"""Layers then filters in Nav2's order: keepout zones are not inflated unless run as a layer."""

import numpy as np

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
