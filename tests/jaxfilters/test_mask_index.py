"""`mask_index` outside [0, M): eager calls raise naming the robots, jitted calls mask and flag.
"""


import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfilters as jf
from jaxfilters.grid import OccupancyGrid


def _grid(data, res=1.0, origin=(0.0, 0.0)):
  return OccupancyGrid.create(np.asarray(data, np.int8), res, origin)


TYPE_CODES = {"keepout": 0, "speed": 1, "binary": 3, "zone": 4}


def _stack(type_code, shape=(4, 4)):
  grids = [_grid(np.full(shape, v, np.int8)) for v in (100, 40)]
  return jf.FilterMask.create(grids, jf.FilterInfo.create(type_code, 100.0, -1.0) if type_code in (1, 2)
                              else jf.FilterInfo.create(type_code))


def _table():
  return jf.ZoneTable.create(["v"], {"v": 1.0}, {100: {"v": 2.0}, 40: {"v": 3.0}})


def _call(name, idx, jit=False):
  b = len(idx)
  poses = np.full((b, 3), 1.5, np.float32)
  table = _table()
  cm = jf.Costmap.create(np.zeros((b, 4, 4), np.uint8), (0.0, 0.0), 1.0)
  masks = {k: _stack(t) for k, t in TYPE_CODES.items()}
  fns = {
      "keepout": lambda m, i: jf.keepout_filter(cm, m, poses, jf.KeepoutState.create(b), mask_index=i),
      "speed": lambda m, i: jf.speed_filter(m, poses, jf.SpeedState.create(b), mask_index=i),
      "binary": lambda m, i: jf.binary_filter(m, poses, jf.BinaryState.create(b), mask_index=i),
      "zone": lambda m, i: jf.zone_filter(m, poses, jf.ZoneState.create(table, b), table, mask_index=i),
  }
  fn = jax.jit(fns[name]) if jit else fns[name]
  return fn(masks[name], idx)


@pytest.mark.parametrize("name", ["keepout", "speed", "binary", "zone"])
@pytest.mark.parametrize("bad", [2, -1, 7])
def test_eager_out_of_range_mask_index_raises_naming_robots(name, bad):
  with pytest.raises(ValueError, match=r"mask_index must lie in \[0, 2\).*robots \[1\]"):
    _call(name, np.array([0, bad, 1], np.int32))


@pytest.mark.parametrize("name", ["keepout", "speed", "binary", "zone"])
def test_jitted_out_of_range_mask_index_is_masked_and_flagged(name):
  out = _call(name, jnp.asarray([0, 2, 1, -1], jnp.int32), jit=True)
  state, res = out
  if name == "keepout":
    cost = np.asarray(state.cost)
    assert np.all(cost[0] == 254) and np.all(cost[2] == 102)     # robots 0 and 2: their own mask
    assert np.all(cost[1] == 0) and np.all(cost[3] == 0)         # bad index: nothing written
    np.testing.assert_array_equal(np.asarray(res.error), [False, True, False, True])
    return
  np.testing.assert_array_equal(np.asarray(res.error), [False, True, False, True])
  if name == "speed":
    np.testing.assert_array_equal(np.asarray(res.valid), [True, False, True, False])
    np.testing.assert_array_equal(np.asarray(res.speed_limit), [0.0, 0.0, 60.0, 0.0])
  if name == "binary":
    np.testing.assert_array_equal(np.asarray(res.in_mask), [True, False, True, False])
  if name == "zone":
    np.testing.assert_array_equal(np.asarray(res.zone), [100, 0, 40, 0])


def _lowered_text(name):
  """StableHLO of a jitted reader of a 2-mask stack of 6 x 7 cells at 3 points, each with its own mask."""
  mask = _stack(TYPE_CODES[name.split("_")[0]], (6, 7))
  table = _table()
  poses = jnp.full((3, 3), 1.5, jnp.float32)
  fns = {
      "keepout_at": lambda m, i: jf.keepout_cost_at(m, poses[:, :2], mask_index=i),
      "speed_at": lambda m, i: jf.speed_limit_at(m, poses[:, :2], mask_index=i),
      "binary_at": lambda m, i: jf.binary_at(m, poses[:, :2], mask_index=i),
      "zone_at": lambda m, i: jf.zone_at(m, poses[:, :2], mask_index=i),
      "speed_filter": lambda m, i: jf.speed_filter(m, poses, jf.SpeedState.create(3), mask_index=i),
      "binary_filter": lambda m, i: jf.binary_filter(m, poses, jf.BinaryState.create(3), mask_index=i),
      "zone_filter": lambda m, i: jf.zone_filter(m, poses, jf.ZoneState.create(table, 3), table, mask_index=i),
  }
  return jax.jit(fns[name]).lower(mask, jnp.asarray([0, 1, 0], jnp.int32)).as_text()


@pytest.mark.parametrize("name", ["keepout_at", "speed_at", "binary_at", "zone_at", "speed_filter", "binary_filter",
                                  "zone_filter"])
def test_per_point_readers_gather_cells_not_whole_masks(name):
  # mask_lookup.MaskView: a point reads stack[i, my, mx]; a [6, 7] slice per point would be a copy of
  # the mask per point (constant-folded at compile time where the caller closes over the stack).
  text = _lowered_text(name)
  assert "gather" in text
  assert "slice_sizes = array<i64: 1, 6, 7>" not in text
