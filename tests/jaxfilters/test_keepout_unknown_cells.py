"""Unknown mask cells in the keepout filter's escape mode and the layered pipeline: never lethal, never over a real zone.

Each test failed on the code before its fix (the history is in git log).
"""



import jax.numpy as jnp
import numpy as np
import pytest

import jaxfilters as jf
from jaxfilters.grid import OccupancyGrid
from sims.fleet import metrics

KEEPOUT = jf.FilterInfo.create(0)


def _grid(data, res=1.0, origin=(0.0, 0.0)):
  return OccupancyGrid.create(np.asarray(data, np.int8), res, origin)


def _keepout_mask(data, res=1.0, origin=(0.0, 0.0)):
  return jf.FilterMask.create(_grid(data, res, origin), KEEPOUT)


@pytest.mark.parametrize("value, lethal", [(-1, False), (100, True), (99, False), (50, False), (0, False)])
def test_robot_in_zone_test_only_costs_253_254(value, lethal):
  data = np.zeros((4, 4), np.int8)
  data[1, 1] = value
  mask = _keepout_mask(data)
  cm = jf.Costmap.create(np.zeros((4, 4), np.uint8), (0.0, 0.0), 1.0)
  cfg = jf.KeepoutConfig(override_lethal_cost=True)
  pose = np.array([[1.5, 1.5, 0.0]], np.float32)
  bounds = np.array([[0.0, 0.0, 4.0, 4.0]], np.float32)
  state, _ = jf.keepout_update_bounds(cm, mask, pose, jf.KeepoutState.create(1), bounds, config=cfg)
  assert bool(state.is_pose_lethal[0]) is lethal
  assert bool(metrics.in_keepout(mask, jnp.asarray(pose[0, :2]))) is lethal


def test_unknown_cell_does_not_override_real_zones():
  data = np.full((6, 6), -1, np.int8)
  data[4:, 4:] = 100                                   # a real zone; the robot stands on unknown
  mask = _keepout_mask(data)
  cm = jf.Costmap.create(np.zeros((6, 6), np.uint8), (0.0, 0.0), 1.0)
  cfg = jf.KeepoutConfig(override_lethal_cost=True, lethal_override_cost=200)
  pose = np.array([[0.5, 0.5, 0.0]], np.float32)
  st, _ = jf.keepout_update_bounds(cm, mask, pose, jf.KeepoutState.create(1),
                                   np.array([[0, 0, 6, 6]], np.float32), config=cfg)
  out, _ = jf.keepout_filter(cm, mask, pose, st, config=cfg)
  assert np.all(np.asarray(out.cost[0, 4:, 4:]) == 254)


def test_pipeline_escape_mode_end_to_end_on_a_nav2_mask(nav2_maps):
  grid = jf.load_map(nav2_maps / "warehouse_keepout.yaml")
  mask = jf.FilterMask.create(grid, KEEPOUT)
  rows, cols = np.nonzero(grid.data == 100)
  h, w = grid.data.shape
  inner = (rows >= 20) & (rows < h - 20) & (cols >= 20) & (cols < w - 20)
  rows, cols = rows[inner], cols[inner]
  k = len(rows) // 2
  r0, c0 = rows[k], cols[k]
  # A 40x40 local costmap around a robot standing inside a real keepout zone, mask cells aligned.
  res = grid.resolution
  origin = np.array(grid.origin[:2]) + np.array([c0 - 20, r0 - 20]) * res
  pose = np.array([[grid.origin[0] + (c0 + 0.5) * res, grid.origin[1] + (r0 + 0.5) * res, 0.0]], np.float32)
  occ = np.zeros((1, 40, 40), np.int8)
  cfg = jf.LayersConfig(keepout=jf.KeepoutConfig(override_lethal_cost=True, lethal_override_cost=200))
  state = jf.KeepoutState.create(1)
  zone = grid.data[r0 - 20:r0 + 20, c0 - 20:c0 + 20] == 100
  for cycle in range(2):
    out = jf.costmap_pipeline(occ, origin[None], np.full((1,), res), pose, config=cfg,
                              keepout_mask=mask, keepout_state=state)
    state = out.keepout_state
    combined = np.asarray(out.combined.cost[0])
    assert bool(state.is_pose_lethal[0])
    assert np.all(combined[zone] == 200) and not np.any(combined == 254)
  # Once the robot is out, the zones are lethal again.
  free_r, free_c = np.nonzero(grid.data == 0)
  away = np.array([[grid.origin[0] + (free_c[0] + 0.5) * res, grid.origin[1] + (free_r[0] + 0.5) * res, 0.0]],
                  np.float32)
  out = jf.costmap_pipeline(occ, origin[None], np.full((1,), res), away, config=cfg,
                            keepout_mask=mask, keepout_state=state)
  assert not bool(out.keepout_state.is_pose_lethal[0])
  assert np.all(np.asarray(out.combined.cost[0])[zone] == 254)

