"""Nav2's doubles kept exact: the costmap's and the mask's double geometry decide the cell.
"""




import numpy as np
import pytest

import jaxfilters as jf
from jaxfilters.grid import OccupancyGrid

KEEPOUT = jf.FilterInfo.create(0)


def _grid(data, res=1.0, origin=(0.0, 0.0)):
  return OccupancyGrid.create(np.asarray(data, np.int8), res, origin)


def _keepout_mask(data, res=1.0, origin=(0.0, 0.0)):
  return jf.FilterMask.create(_grid(data, res, origin), KEEPOUT)


@pytest.mark.parametrize("res, first", [(0.05, 21), (np.float32(0.05), 20)])
def test_coarse_mask_example_uses_the_costmap_double(res, first):
  """docs/nav2_semantics.md §4.3: master res 0.05 at (0, 0), mask res 0.1 at (1, 1): Nav2 starts at column 21."""
  mask = _keepout_mask(np.full((10, 10), 100), 0.1, (1.0, 1.0))
  cm = jf.Costmap.create(np.zeros((50, 50), np.uint8), (0.0, 0.0), res)
  out, _ = jf.keepout_filter(cm, mask, np.zeros((1, 3), np.float32), jf.KeepoutState.create(1))
  c = np.asarray(out.cost[0])
  cols, rows = np.nonzero(c.max(0))[0], np.nonzero(c.max(1))[0]
  assert (cols.min(), cols.max(), rows.min(), rows.max()) == (first, 39, first, 39)


def test_mask_origin_double_decides_the_cell():
  """Nav2's warehouse origin -15.1 is a double: x = -15.0100002289 lies in cell 2 (float64), not 3.

  With the origin rounded to float32 (-15.1000003815) the same pose falls in cell 3.
  """
  data = np.zeros((1, 6), np.int8)
  data[0, 2], data[0, 3] = 20, 60
  mask = jf.FilterMask.create(_grid(data, np.float32(0.03), (-15.1, -1.0)), jf.FilterInfo.create(1, 100.0, -1.0))
  x = np.float32(-15.010000228881836)
  assert np.floor((float(x) + 15.1) / float(np.float32(0.03))) == 2               # Nav2, in double
  _, out = jf.speed_filter(mask, np.array([[x, -0.99, 0.0]], np.float32), jf.SpeedState.create(1))
  assert bool(out.valid[0]) and float(out.speed_limit[0]) == 80.0                   # cell 2: 100 - 20


@pytest.mark.parametrize("seed", range(6))
def test_aligned_path_with_double_geometry_equals_the_general_path(seed):
  """A double costmap resolution/origin beside a float32 mask: the slice path is taken only when
  every costmap cell maps to consecutive mask cells, and gives the general path's integers."""
  rng = np.random.default_rng(seed)
  res = [0.05, 0.03, 0.1][seed % 3]
  data = rng.choice([-1, 0, 30, 100], (40, 50)).astype(np.int8)
  mask = _keepout_mask(data, res, (-1.3 + 0.01 * seed, 2.17))
  b = 8
  origin = np.stack([rng.uniform(-2.5, 1.0, b), rng.uniform(1.0, 3.5, b)], 1)
  origin = np.round(origin / res) * res + rng.choice([0.0, 1e-9, -1e-9, 0.5 * res], (b, 1))
  cost = rng.choice([0, 50, 253, 255], (b, 24, 32)).astype(np.uint8)
  cm = jf.Costmap.create(cost, origin, res)
  poses = np.zeros((b, 3), np.float32)
  fast, _ = jf.keepout_filter(cm, mask, poses, jf.KeepoutState.create(b))
  slow, _ = jf.keepout_filter(cm, mask, poses, jf.KeepoutState.create(b),
                              config=jf.KeepoutConfig(aligned_fast_path=False))
  np.testing.assert_array_equal(np.asarray(fast.cost), np.asarray(slow.cost))

