"""jaxfilters.query: point queries against a plain-Python reference (exact rationals), four ways.

The reference decodes each point with Nav2's rules in exact arithmetic on the
float32 values the device sees (fractions.Fraction), so cell-edge points are
checked exactly: floor((x - origin) / res) of the real quotient.
"""

import fractions
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.compile_count import count_compiles
import jaxfilters as jf
from jaxfilters import constants
from jaxfilters.grid import OccupancyGrid
from jaxfilters.query import binary_at, keepout_cost_at, speed_limit_at, zone_at

F = fractions.Fraction
H, W = 7, 9


def _grid(data, origin, res):
  return OccupancyGrid(data=np.asarray(data, np.int8), resolution=res, origin=(origin[0], origin[1], 0.0))


def _stack(rng, types, bases, mults):
  """M masks with random data (incl. -1, 0, 100 and out-of-range bytes), origins and resolutions."""
  grids, infos = [], []
  for t, b, m in zip(types, bases, mults):
    data = rng.choice(np.array([-1, 0, 1, 20, 35, 50, 99, 100, 101, 120, -5], np.int8), size=(H, W))
    grids.append(_grid(data, (float(rng.uniform(-3, 3)), float(rng.uniform(-3, 3))),
                       float(rng.choice([0.05, 0.1, 0.3]))))
    infos.append(jf.FilterInfo.create(t, b, m))
  return jf.FilterMask.create(grids, infos)


def _cell_ref(mask, i, x, y):
  """(d, inside) by exact rationals on the values Nav2 holds: the host float64 origin (all its parts)."""
  ox, oy = (F(float(v)) for v in np.asarray(mask.origin[i]))
  if mask.origin_lo is not None:
    lo = np.asarray(mask.origin_lo[i], np.float64)
    ox, oy = ox + F(lo[0, 0]) + F(lo[0, 1]), oy + F(lo[1, 0]) + F(lo[1, 1])
  res = F(float(np.asarray(mask.resolution[i])))
  if not (math.isfinite(x) and math.isfinite(y)):
    return None, False
  fx, fy = F(x), F(y)
  mx, my = math.floor((fx - ox) / res), math.floor((fy - oy) / res)
  if fx < ox or fy < oy or mx >= W or my >= H:
    return None, False
  return int(np.asarray(mask.data[i, my, mx])), True


def _points(rng, mask, n):
  """Random points: inside, outside, on cell edges (and one ulp below), NaN and inf."""
  pts = []
  m = mask.num_masks
  idx = rng.integers(0, m, size=n)
  for k in range(n):
    i = idx[k]
    o = np.asarray(mask.origin[i], np.float32)
    r = np.float32(np.asarray(mask.resolution[i]))
    kind = k % 4
    if kind == 0:
      p = o + rng.uniform(-0.5, 1.2, size=2).astype(np.float32) * np.float32([W, H]) * r
    else:
      cell = rng.integers(-1, [W + 2, H + 2])
      p = (o + cell.astype(np.float32) * r).astype(np.float32)
      if kind == 2:
        p = np.nextafter(p, np.float32(-np.inf))
    pts.append(p.astype(np.float32))
  pts = np.stack(pts)
  pts[1] = [np.nan, 0.0]
  pts[5] = [np.inf, np.float32(np.asarray(mask.origin[idx[5], 1]))]
  return pts, idx.astype(np.int32)


def _speed_ref(mask, i, x, y):
  d, inside = _cell_ref(mask, i, x, y)
  t = int(np.asarray(mask.info.type[i]))
  pct = t == constants.SPEED_FILTER_PERCENT
  if not inside or d == -1 or t not in (1, 2):
    return 0.0, pct, False
  if d == 0:
    return 0.0, pct, True
  raw = d * F(float(np.asarray(mask.info.multiplier[i]))) + F(float(np.asarray(mask.info.base[i])))
  if raw < 0 or (pct and raw > 100):
    return 0.0, pct, True
  return float(np.float32(float(raw))), pct, True


def _keepout_ref(mask, i, x, y):
  d, inside = _cell_ref(mask, i, x, y)
  if not inside or not 0 <= d <= 100:
    return 255
  return math.floor(F(254 * d, 100) + F(1, 2))


def _zone_ref(mask, i, x, y):
  d, inside = _cell_ref(mask, i, x, y)
  return d if inside and d >= 0 else -1


def _binary_ref(mask, i, x, y, default, thr):
  d, inside = _cell_ref(mask, i, x, y)
  valid = inside and d != -1 and int(np.asarray(mask.info.type[i])) == constants.BINARY_FILTER
  if not valid:
    return default, False
  v = F(float(np.asarray(mask.info.base[i]))) + d * F(float(np.asarray(mask.info.multiplier[i])))
  return (not default) if v > F(float(np.float32(thr))) else default, True


@pytest.fixture(scope="module")
def case():
  rng = np.random.default_rng(7)
  mask = _stack(rng, types=[1, 2, 1, 3], bases=[100.0, 0.0, 0.1, 0.0], mults=[-1.0, 0.02, 1.3, 1.0])
  pts, idx = _points(rng, mask, 240)
  return mask, pts, idx


def _ref_all(fn, mask, pts, idx, *extra):
  return [fn(mask, int(i), float(p[0]), float(p[1]), *extra) for p, i in zip(pts, idx)]


def test_speed_limit_at_matches_reference_eager_jit_vmap(case):
  mask, pts, idx = case
  ref = _ref_all(_speed_ref, mask, pts, idx)
  want_l = np.float32([r[0] for r in ref])
  want_p = np.array([r[1] for r in ref])
  want_v = np.array([r[2] for r in ref])
  assert want_v.any() and (~want_v).any() and (want_l > 0).any()      # the cases are all exercised
  eager = speed_limit_at(mask, pts, mask_index=idx)
  jitted = jax.jit(lambda m, p, i: speed_limit_at(m, p, mask_index=i))(mask, pts, idx)
  vmapped = jax.vmap(lambda p, i: speed_limit_at(mask, p, mask_index=i))(pts, idx)
  for got in (eager, jitted, vmapped):
    np.testing.assert_array_equal(np.asarray(got[0]), want_l)
    np.testing.assert_array_equal(np.asarray(got[1]), want_p)
    np.testing.assert_array_equal(np.asarray(got[2]), want_v)


def test_keepout_zone_binary_match_reference(case):
  mask, pts, idx = case
  np.testing.assert_array_equal(np.asarray(keepout_cost_at(mask, pts, mask_index=idx)),
                                np.uint8(_ref_all(_keepout_ref, mask, pts, idx)))
  np.testing.assert_array_equal(np.asarray(zone_at(mask, pts, mask_index=idx)),
                                np.int32(_ref_all(_zone_ref, mask, pts, idx)))
  for default, thr in ((False, 50.0), (True, 0.0)):
    ref = _ref_all(_binary_ref, mask, pts, idx, default, thr)
    state, valid = binary_at(mask, pts, mask_index=idx, default_state=default, flip_threshold=thr)
    np.testing.assert_array_equal(np.asarray(state), np.array([r[0] for r in ref]))
    np.testing.assert_array_equal(np.asarray(valid), np.array([r[1] for r in ref]))
  jitted = jax.jit(lambda p, i: keepout_cost_at(mask, p, mask_index=i))(pts, idx)
  np.testing.assert_array_equal(np.asarray(jitted), np.asarray(keepout_cost_at(mask, pts, mask_index=idx)))


def test_shapes_single_point_and_leading_axes(case):
  mask, pts, idx = case
  single = _stack(np.random.default_rng(1), [1], [100.0], [-1.0])
  p = np.asarray(single.origin[0]) + 0.5 * np.asarray(single.resolution[0])
  limit, pct, valid = speed_limit_at(single, p)                          # [2] -> scalars
  assert limit.shape == pct.shape == valid.shape == ()
  want = _speed_ref(single, 0, float(p[0]), float(p[1]))
  assert (float(limit), bool(pct), bool(valid)) == (np.float32(want[0]), want[1], want[2])
  grid = pts[:24].reshape(4, 3, 2, 2)
  out = keepout_cost_at(mask, grid, mask_index=idx[:24].reshape(4, 3, 2))
  assert out.shape == (4, 3, 2) and out.dtype == jnp.uint8
  np.testing.assert_array_equal(np.asarray(out).ravel(), np.uint8(_ref_all(_keepout_ref, mask, pts[:24], idx[:24])))
  assert zone_at(single, np.zeros((0, 2), np.float32)).shape == (0,)
  assert zone_at(single, [0, 0]).dtype == jnp.int32                        # python ints are points too


def test_mask_index_out_of_range_raises_eagerly_and_is_invalid_under_jit(case):
  mask, pts, idx = case
  bad = idx.copy()
  bad[3] = 4                                                               # M = 4: valid 0..3
  bad[7] = -1
  for fn in (speed_limit_at, keepout_cost_at, zone_at, binary_at):
    with pytest.raises(ValueError, match=r"mask_index must lie in \[0, 4\).*\[4, -1\].*\(3,\), \(7,\)"):
      fn(mask, pts, mask_index=bad)
  limit, _, valid = jax.jit(lambda i: speed_limit_at(mask, pts, mask_index=i))(bad)
  assert not bool(valid[3]) and not bool(valid[7]) and float(limit[3]) == 0.0
  cost = jax.jit(lambda i: keepout_cost_at(mask, pts, mask_index=i))(bad)
  assert int(cost[3]) == 255 and int(cost[7]) == 255
  zone = jax.jit(lambda i: zone_at(mask, pts, mask_index=i))(bad)
  assert int(zone[3]) == -1 and int(zone[7]) == -1
  state, valid = jax.jit(lambda i: binary_at(mask, pts, mask_index=i, default_state=True))(bad)
  assert bool(state[3]) and not bool(valid[3])
  # The other points are untouched by the bad ones.
  ok = np.ones(len(pts), bool)
  ok[[3, 7]] = False
  np.testing.assert_array_equal(np.asarray(cost)[ok], np.asarray(keepout_cost_at(mask, pts, mask_index=idx))[ok])


def test_input_errors_are_clear(case):
  mask, pts, idx = case
  single = _stack(np.random.default_rng(2), [0], [0.0], [1.0])
  with pytest.raises(ValueError, match=r"stack of 4 masks needs mask_index"):
    keepout_cost_at(mask, pts)
  with pytest.raises(ValueError, match=r"leading shape \(240,\); got \(239,\)"):
    keepout_cost_at(mask, pts, mask_index=idx[:-1])
  with pytest.raises(TypeError, match="mask_index must be integers"):
    keepout_cost_at(mask, pts, mask_index=idx.astype(np.float32))
  with pytest.raises(ValueError, match=r"shape \[\.\.\., 2\].*got shape \(3,\)"):
    keepout_cost_at(single, [1.0, 2.0, 3.0])
  with pytest.raises(TypeError, match="real numbers"):
    keepout_cost_at(single, np.array([True, False]))
  with pytest.raises(ValueError, match="float32"):
    keepout_cost_at(single, np.array([1e-50, 0.0]))                      # would become 0.0
  with pytest.raises(ValueError, match="float32"):
    zone_at(single, np.array([1e39, 0.0]))                               # would become inf
  with pytest.raises(TypeError, match="FilterMask"):
    zone_at(np.zeros((3, 3)), [0.0, 0.0])
  with pytest.raises(TypeError, match="default_state"):
    binary_at(single, [0.0, 0.0], default_state=1)
  with pytest.raises(ValueError, match="flip_threshold"):
    binary_at(single, [0.0, 0.0], flip_threshold=float("nan"))


def test_second_call_with_new_values_compiles_nothing(case):
  mask, pts, idx = case
  speed_limit_at(mask, pts, mask_index=idx)
  new_mask = mask.with_data(np.asarray(mask.data)[:, ::-1])
  with count_compiles() as compiles:
    speed_limit_at(new_mask, pts + 0.01, mask_index=idx[::-1].copy())
  assert compiles() == 0


def test_speed_limit_at_agrees_with_the_speed_filter_on_nav2_warehouse(nav2_maps):
  grid = jf.load_map(nav2_maps / "warehouse_speed.yaml")
  mask = jf.FilterMask.create(grid, jf.FilterInfo.create(1, 100.0, -1.0))
  rng = np.random.default_rng(3)
  h, w = grid.data.shape
  o = np.float32(grid.origin[:2])
  xy = (o + rng.uniform(-0.05, 1.05, size=(500, 2)) * np.float32([w, h]) * np.float32(grid.resolution))
  xy = xy.astype(np.float32)
  _, res = jf.speed_filter(mask, np.concatenate([xy, np.zeros((500, 1), np.float32)], 1),
                           jf.SpeedState.create(500))
  limit, pct, valid = speed_limit_at(mask, xy)
  np.testing.assert_array_equal(np.asarray(valid), np.asarray(res.valid))
  # The filter keeps its previous limit (0.0 at start) where invalid; the query reports 0.0 there.
  np.testing.assert_array_equal(np.asarray(limit), np.asarray(res.speed_limit))
  assert bool(np.all(np.asarray(pct)))
  assert np.asarray(valid).sum() > 100 and (np.asarray(limit) > 0).sum() > 10
