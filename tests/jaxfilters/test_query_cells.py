"""One cell rule: a point query and a filter at the same pose read the same mask cell (Nav2's worldToMap).
"""

import dataclasses

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxfilters as jf
from jaxfilters.grid import OccupancyGrid

H, W, N = 5, 7, 24                      # fixed shapes: every example reuses one compiled program


def _mask(data, res, origin, info):
  return jf.FilterMask.create(OccupancyGrid.create(np.asarray(data, np.int8), res, origin), info)


def test_speed_query_reads_the_filters_cell_at_origin_minus_15_1():
  """Origin -15.1 (a double), 1 m cells: x = float32(-12.1) is in cell 2 (exact), not 3 (float32 origin)."""
  data = np.zeros((1, 6), np.int8)
  data[0, 3] = 40
  mask = _mask(data, 1.0, (-15.1, 0.0), jf.FilterInfo.create(1, 0.0, 1.0))
  x = np.float32(-12.1)
  _, out = jf.speed_filter(mask, np.array([[x, 0.5, 0.0]], np.float32), jf.SpeedState.create(1))
  limit, _, valid = jf.speed_limit_at(mask, np.array([x, 0.5], np.float32))
  assert bool(out.valid[0]) and float(out.speed_limit[0]) == 0.0            # cell 2: no limit
  assert bool(valid) and float(limit) == 0.0
  limit, _, _ = jf.speed_limit_at(mask, np.array([np.float32(-11.1), 0.5], np.float32))
  _, out = jf.speed_filter(mask, np.array([[np.float32(-11.1), 0.5, 0.0]], np.float32), jf.SpeedState.create(1))
  assert float(limit) == float(out.speed_limit[0])


def _points(origin, res, draws):
  """Points on and one float32 step either side of cell edges (and random interior points)."""
  pts = []
  for kind, cx, cy, fx, fy in draws:
    x = origin[0] + cx * res
    y = origin[1] + cy * res
    p = np.float32([x + fx * res, y + fy * res]) if kind == 0 else np.float32([x, y])
    if kind == 1:
      p = np.nextafter(p, np.float32(-np.inf))
    elif kind == 2:
      p = np.nextafter(p, np.float32(np.inf))
    pts.append(p)
  return np.stack(pts).astype(np.float32)


_origin = st.floats(-40.0, 40.0).map(lambda v: round(v, 2)).filter(lambda v: float(np.float32(v)) != v)


_draw = st.tuples(st.integers(0, 3), st.integers(-1, W + 1), st.integers(-1, H + 1),
                  st.floats(0.0, 1.0), st.floats(0.0, 1.0))


@settings(max_examples=25, deadline=None)
@given(ox=_origin, oy=_origin, res=st.sampled_from([0.05, 0.1, 0.3, 1.0]),
       seed=st.integers(0, 2 ** 31 - 1), draws=st.lists(_draw, min_size=N, max_size=N))
def test_queries_and_filters_agree_at_every_pose(ox, oy, res, seed, draws):
  rng = np.random.default_rng(seed)
  data = rng.choice(np.array([-1, 0, 1, 20, 50, 51, 99, 100], np.int8), size=(H, W))
  pts = _points((ox, oy), float(np.float32(res)), draws)
  poses = np.concatenate([pts, np.zeros((N, 1), np.float32)], axis=1)

  speed = _mask(data, res, (ox, oy), jf.FilterInfo.create(1, 0.0, 1.0))
  assert speed.origin_lo is not None                          # the origin is not a float32
  _, out = jf.speed_filter(speed, poses, jf.SpeedState.create(N))
  limit, _, valid = jf.speed_limit_at(speed, pts)
  np.testing.assert_array_equal(np.asarray(valid), np.asarray(out.valid))
  np.testing.assert_array_equal(np.asarray(limit), np.asarray(out.speed_limit))

  binary = dataclasses.replace(speed, info=jf.FilterMask.create(
      OccupancyGrid.create(data, res, (ox, oy)), jf.FilterInfo.create(3)).info)
  _, bout = jf.binary_filter(binary, poses, jf.BinaryState.create(N))
  state, bvalid = jf.binary_at(binary, pts)
  np.testing.assert_array_equal(np.asarray(bvalid), np.asarray(bout.in_mask))
  np.testing.assert_array_equal(np.asarray(state), np.asarray(bout.binary_state))

  zone = dataclasses.replace(speed, info=jf.FilterMask.create(
      OccupancyGrid.create(data, res, (ox, oy)), jf.FilterInfo.create(4)).info)
  table = jf.ZoneTable.create(["p"], {"p": 0.0}, {z: {"p": float(z)} for z in range(1, 101)})
  _, zout = jf.zone_filter(zone, poses, jf.ZoneState.create(table, N), table)
  zid = np.asarray(jf.zone_at(zone, pts))
  np.testing.assert_array_equal(np.asarray(zout.event), zid >= 0)
  np.testing.assert_array_equal(np.asarray(zout.zone)[zid >= 0], zid[zid >= 0])

  keep = dataclasses.replace(speed, info=jf.FilterMask.create(
      OccupancyGrid.create(data, res, (ox, oy)), jf.FilterInfo.create(0)).info)
  cost = np.asarray(jf.keepout_cost_at(keep, pts))
  cm = jf.Costmap.create(np.zeros((N, 4, 4), np.uint8), np.zeros((N, 2)), 1.0)
  st_, _ = jf.keepout_update_bounds(cm, keep, poses, jf.KeepoutState.create(N),
                                    np.zeros((N, 4), np.float32),
                                    config=jf.KeepoutConfig(override_lethal_cost=True))
  np.testing.assert_array_equal(np.asarray(st_.is_pose_lethal), (cost == 253) | (cost == 254))


def test_nav2_costmap_readout_reads_the_keepout_filters_cell_at_origin_minus_15_1():
  """The params bundle's keepout readout goes through the same cell rule as keepout_filter's zone test."""
  data = np.zeros((1, 6), np.int8)
  data[0, 3] = 100                                   # cell 3 lethal, cell 2 free
  keepout = _mask(data, 1.0, (-15.1, 0.0), jf.FilterInfo.create(0))
  costmap = jf.Nav2Costmap.from_masks(keepout=keepout)
  poses = np.array([[np.float32(-12.1), 0.5, 0.0], [np.float32(-11.1), 0.5, 0.0]], np.float32)
  got = np.asarray(costmap.readout(poses).keepout_cost)
  assert got.tolist() == [0, 254]                    # exact floor: cell 2, then cell 3
  assert got.tolist() == np.asarray(jf.keepout_cost_at(keepout, poses[:, :2])).tolist()

