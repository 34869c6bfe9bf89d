"""No silent wrong result: each test failed on the code before its fix.

Covered: escape mode on unknown cells (1), the pipeline's updateBounds pass (2),
the zone filter's type gate (3), out-of-range mask_index eager and under jit
(4), values checked in float32 terms where they enter (5), eager calls that
neither copy the mask per robot nor recompile (10), Nav2's doubles kept exact
(11); the numbers are this file's section headings.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.compile_count import count_compiles
import jaxfilters as jf
from jaxfilters import speed as sp
from jaxfilters.grid import OccupancyGrid
from sims.fleet import metrics

KEEPOUT = jf.FilterInfo.create(0)


def _grid(data, res=1.0, origin=(0.0, 0.0)):
  return OccupancyGrid.create(np.asarray(data, np.int8), res, origin)


def _keepout_mask(data, res=1.0, origin=(0.0, 0.0)):
  return jf.FilterMask.create(_grid(data, res, origin), KEEPOUT)


# --- 1. escape mode: unknown mask cells are not lethal ---------------------------------------

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


# --- 2. the pipeline runs updateBounds before updateCosts ----------------------------------

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


# --- 3. the zone filter refuses masks of another type --------------------------------------

def test_zone_filter_ignores_a_mask_of_type_3():
  table = jf.ZoneTable.create(["v"], {"v": 1.0}, {5: {"v": 0.5}})
  data = np.full((4, 4), 5, np.int8)
  for t, applied in ((3, False), (4, True)):
    mask = jf.FilterMask.create(_grid(data), jf.FilterInfo.create(t))
    state, out = jf.zone_filter(mask, np.array([[1.5, 1.5, 0.0]], np.float32), jf.ZoneState.create(table, 1),
                                table)
    assert bool(out.event[0]) is applied and int(out.zone[0]) == (5 if applied else 0)
    assert float(out.params[0, 0]) == (0.5 if applied else 1.0) and not bool(out.error[0])


# --- 4. mask_index outside [0, M) ------------------------------------------------------------

def _stack(type_code):
  grids = [_grid(np.full((4, 4), v, np.int8)) for v in (100, 40)]
  return jf.FilterMask.create(grids, jf.FilterInfo.create(type_code, 100.0, -1.0) if type_code in (1, 2)
                              else jf.FilterInfo.create(type_code))


def _call(name, idx, jit=False):
  b = len(idx)
  poses = np.full((b, 3), 1.5, np.float32)
  table = jf.ZoneTable.create(["v"], {"v": 1.0}, {100: {"v": 2.0}, 40: {"v": 3.0}})
  cm = jf.Costmap.create(np.zeros((b, 4, 4), np.uint8), (0.0, 0.0), 1.0)
  masks = {k: _stack(t) for k, t in (("keepout", 0), ("speed", 1), ("binary", 3), ("zone", 4))}
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


# --- 5. values checked in float32 terms -------------------------------------------------------

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


# --- 10. eager calls: no per-robot mask copies, no recompiles --------------------------------

def test_eager_speed_filter_compiles_once_without_per_robot_mask_copies():
  b, h, w = 4096, 300, 200
  mask = jf.FilterMask.create(_grid(np.random.default_rng(0).integers(0, 100, (h, w)), 0.05, (0.0, 0.0)),
                              jf.FilterInfo.create(1, 100.0, -1.0))
  poses = np.random.default_rng(1).uniform(0, 9, (b, 3)).astype(np.float32)
  state, out = jf.speed_filter(mask, poses, jf.SpeedState.create(b))
  with count_compiles() as compiles:   # new values, same shapes: nothing compiles
    state, out = jf.speed_filter(mask, poses[::-1].copy(), state)
  assert compiles() == 0
  compiled = jax.jit(jf.speed_filter).lower(mask, poses, state).compile()
  temp = compiled.memory_analysis().temp_size_in_bytes
  assert temp < b * h * w // 10, temp        # a per-robot copy of the mask would be B*H*W bytes


# --- 11. Nav2's doubles kept exact ------------------------------------------------------------

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


@pytest.mark.parametrize("value", [float("nan"), 1e39, 1e-40])
def test_zone_table_refuses_values_the_device_cannot_hold(value):
  with pytest.raises(ValueError, match="ZoneTable.create"):
    jf.ZoneTable.create(["v"], {"v": 1.0}, {3: {"v": value}})
  with pytest.raises(ValueError, match="ZoneTable.create"):
    jf.ZoneTable.create(["v"], {"v": value}, {})


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
