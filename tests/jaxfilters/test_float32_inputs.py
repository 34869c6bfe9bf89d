"""Values are checked in float32 terms where they enter: FilterInfo, FilterMask, Costmap, zone tables, mask stacks.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfilters as jf
from jaxfilters.grid import OccupancyGrid

KEEPOUT = jf.FilterInfo.create(0)


def _grid(data, res=1.0, origin=(0.0, 0.0)):
  return OccupancyGrid.create(np.asarray(data, np.int8), res, origin)


def _keepout_mask(data, res=1.0, origin=(0.0, 0.0)):
  return jf.FilterMask.create(_grid(data, res, origin), KEEPOUT)


@pytest.mark.parametrize("kw", [dict(base=1e39), dict(multiplier=-1e39), dict(base=1e38, multiplier=-1e38),
                                dict(base=float("nan")), dict(base=1e-40)])
def test_filter_info_refuses_values_that_break_in_float32(kw):
  with pytest.raises(ValueError, match="FilterInfo"):
    jf.FilterInfo.create(2, **kw)


@pytest.mark.parametrize("grid, match", [
    (OccupancyGrid(np.zeros((3, 3), np.int8), float("nan"), (0.0, 0.0, 0.0)), "resolution"),
    (OccupancyGrid(np.zeros((3, 3), np.int8), 0.0, (0.0, 0.0, 0.0)), "resolution"),
    (OccupancyGrid(np.zeros((3, 3), np.int8), -0.05, (0.0, 0.0, 0.0)), "resolution"),
    (OccupancyGrid(np.zeros((3, 3), np.int8), 1e-50, (0.0, 0.0, 0.0)), "resolution"),
    (OccupancyGrid(np.zeros((3, 3), np.int8), 0.05, (float("nan"), 0.0, 0.0)), "origin"),
    (OccupancyGrid(np.zeros((0, 0), np.int8), 0.05, (0.0, 0.0, 0.0)), "non-empty"),
    (OccupancyGrid(np.full((3, 3), 300, np.int16), 0.05, (0.0, 0.0, 0.0)), r"\[-128, 127\]"),
    (OccupancyGrid(np.full((3, 3), 0.5), 0.05, (0.0, 0.0, 0.0)), "integers"),
])
def test_filter_mask_revalidates_hand_built_grids(grid, match):
  with pytest.raises(ValueError, match=match):
    jf.FilterMask.create(grid, KEEPOUT)


@pytest.mark.parametrize("data", [np.full((3, 3), 99.9), np.full((3, 3), np.nan), np.full((3, 3), 300)])
def test_with_data_refuses_floats_and_out_of_range(data):
  mask = _keepout_mask(np.zeros((3, 3)))
  with pytest.raises(ValueError, match="new mask data"):
    mask.with_data(data)


@pytest.mark.parametrize("dtype", [np.int32, np.float32])
def test_keepout_refuses_a_costmap_that_is_not_uint8(dtype):
  cm = jf.Costmap.create(np.zeros((1, 3, 3), np.uint8), (0.0, 0.0), 1.0)
  bad = dataclasses.replace(cm, cost=jnp.full((1, 3, 3), 300, dtype))
  with pytest.raises(ValueError, match="uint8"):
    jf.keepout_filter(bad, _keepout_mask(np.full((3, 3), 100)), np.zeros((1, 3), np.float32),
                      jf.KeepoutState.create(1))


def test_keepout_refuses_a_mask_stack_its_int32_indices_would_wrap():
  # M (Hm + 2H) (Wm + 2W) >= 2^31 would wrap the flat int32 mask index and read
  # another cell. The shapes decide it, so an abstract 2.1 GB stack is enough.
  cm = jf.Costmap.create(np.zeros((1, 8, 8), np.uint8), (0.0, 0.0), 1.0)
  small = _keepout_mask(np.full((3, 3), 100))
  args = (np.zeros((1, 3), np.float32), jf.KeepoutState.create(1))

  def run(data):
    return jf.keepout_filter(cm, dataclasses.replace(small, data=data), *args)[0].cost
  big = jax.ShapeDtypeStruct((1, 46_000, 46_700), jnp.int8)   # (46016 * 46716) > 2^31
  with pytest.raises(ValueError, match="int32 and take fewer than 2\\^31"):
    jax.eval_shape(run, big)
  ok = jax.ShapeDtypeStruct((1, 46_000, 46_000), jnp.int8)     # 46016^2 < 2^31
  assert jax.eval_shape(run, ok).shape == (1, 8, 8)


@pytest.mark.parametrize("res", [1e-50, 1e39, 0.0, -1.0, float("inf")])
def test_costmap_refuses_resolutions_the_device_cannot_hold(res):
  with pytest.raises(ValueError, match="resolution"):
    jf.Costmap.create(np.zeros((3, 3), np.uint8), (0.0, 0.0), res)


@pytest.mark.parametrize("value", [float("nan"), 1e39, 1e-40])
def test_zone_table_refuses_values_the_device_cannot_hold(value):
  with pytest.raises(ValueError, match="ZoneTable.create"):
    jf.ZoneTable.create(["v"], {"v": 1.0}, {3: {"v": value}})
  with pytest.raises(ValueError, match="ZoneTable.create"):
    jf.ZoneTable.create(["v"], {"v": value}, {})

