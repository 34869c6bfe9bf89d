"""Point queries read the filters' cell; traced bad mask geometry is flagged; jit-safe constructors;
soft zones at far, infinite and NaN points. Each test fails on the code before its fix.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from tests.compile_count import count_compiles
import jaxfilters as jf
from jaxfilters.grid import OccupancyGrid

H, W, N = 5, 7, 24                      # fixed shapes: every example reuses one compiled program


def _mask(data, res, origin, info):
  return jf.FilterMask.create(OccupancyGrid.create(np.asarray(data, np.int8), res, origin), info)


# --- one cell rule: a query and a filter at the same pose read the same cell -----------------

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


# --- traced bad mask geometry: valid False, error True ------------------------------------------

BAD = [("resolution", np.nan), ("resolution", np.inf), ("resolution", -0.1), ("resolution", 0.0),
       ("resolution", 1e-40), ("origin", np.nan), ("origin", np.inf)]


def _with(mask, field, value):
  if field == "resolution":
    return dataclasses.replace(mask, resolution=jnp.full_like(mask.resolution, value))
  return dataclasses.replace(mask, origin=mask.origin.at[0, 0].set(value))


@pytest.mark.parametrize("field, value", BAD)
def test_traced_bad_mask_geometry_is_masked_and_flagged_on_every_filter(field, value):
  data = np.full((H, W), 50, np.int8)
  poses = np.array([[1e6, 1e6, 0.0], [0.5, 0.5, 0.0]], np.float32)
  speed = _mask(data, 1.0, (0.0, 0.0), jf.FilterInfo.create(1, 0.0, 1.0))
  binary = _mask(data, 1.0, (0.0, 0.0), jf.FilterInfo.create(3))
  zone = _mask(data, 1.0, (0.0, 0.0), jf.FilterInfo.create(4))
  table = jf.ZoneTable.create(["p"], {"p": 0.0}, {50: {"p": 1.0}})
  value = jnp.float32(value)

  _, out = jax.jit(lambda v: jf.speed_filter(_with(speed, field, v), poses, jf.SpeedState.create(2)))(value)
  assert not np.asarray(out.valid).any() and np.asarray(out.error).all()
  assert not np.asarray(out.speed_limit).any()
  _, out = jax.jit(lambda v: jf.speed_filter_lookahead(
      _with(speed, field, v), poses, jf.SpeedState.create(2), np.zeros((2, 3, 2), np.float32),
      np.array([0, 0], np.int32), np.zeros(2, np.float32)))(value)
  assert not np.asarray(out.valid).any() and np.asarray(out.error).all()
  _, out = jax.jit(lambda v: jf.binary_filter(_with(binary, field, v), poses, jf.BinaryState.create(2)))(value)
  assert not np.asarray(out.in_mask).any() and not np.asarray(out.published).any()
  assert np.asarray(out.error).all()
  _, out = jax.jit(lambda v: jf.zone_filter(_with(zone, field, v), poses, jf.ZoneState.create(table, 2),
                                            table))(value)
  assert not np.asarray(out.event).any() and np.asarray(out.error).all()

  pts = poses[:, :2]
  _, _, valid = jax.jit(lambda v: jf.speed_limit_at(_with(speed, field, v), pts))(value)
  assert not np.asarray(valid).any()
  assert (np.asarray(jax.jit(lambda v: jf.keepout_cost_at(_with(speed, field, v), pts))(value)) == 255).all()
  assert (np.asarray(jax.jit(lambda v: jf.zone_at(_with(zone, field, v), pts))(value)) == -1).all()
  _, valid = jax.jit(lambda v: jf.binary_at(_with(binary, field, v), pts))(value)
  assert not np.asarray(valid).any()


def test_mask_geometry_ok_names_the_usable_masks():
  mask = _mask(np.zeros((2, 2)), 0.5, (-15.1, 0.0), jf.FilterInfo.create(1))
  assert np.asarray(jf.types.mask_geometry_ok(mask)).tolist() == [True]
  assert np.asarray(jf.types.mask_geometry_ok(_with(mask, "resolution", np.nan))).tolist() == [False]


# --- pytree-built masks with bad static shapes: a clear error at trace time ---------------------

def _pytree_mask(data, origin_shape=(1, 2), res_shape=(1,)):
  info = jf.FilterInfo(type=jnp.ones((1,), jnp.int32), base=jnp.zeros((1,)), multiplier=jnp.ones((1,)))
  return jf.FilterMask(data=data, origin=jnp.zeros(origin_shape), resolution=jnp.ones(res_shape), info=info)


@pytest.mark.parametrize("data", [jnp.zeros((1, 0, 0), jnp.int8), jnp.zeros((1, 3, 0), jnp.int8),
                                  jnp.zeros((0, 3, 3), jnp.int8)])
def test_empty_pytree_mask_raises_a_value_error_naming_the_array(data):
  mask = _pytree_mask(data)
  poses = np.zeros((1, 3), np.float32)
  with pytest.raises(ValueError, match=r"mask\.data must be int8 \[M, H, W\] with M, H and W >= 1"):
    jf.speed_filter(mask, poses, jf.SpeedState.create(1))
  with pytest.raises(ValueError, match=r"mask\.data"):
    jax.jit(lambda m: jf.binary_filter(m, poses, jf.BinaryState.create(1)))(mask)
  with pytest.raises(ValueError, match=r"mask\.data"):
    jf.speed_limit_at(mask, np.zeros(2, np.float32))


@pytest.mark.parametrize("origin_shape, res_shape, name", [((2, 2), (1,), "origin"), ((1, 2), (), "resolution"),
                                                           ((1, 3), (1,), "origin")])
def test_pytree_mask_with_mismatched_leaves_names_them(origin_shape, res_shape, name):
  mask = _pytree_mask(jnp.zeros((1, 3, 3), jnp.int8), origin_shape, res_shape)
  with pytest.raises(ValueError, match=rf"mask\.{name} must be floating \("):
    jf.zone_at(mask, np.zeros(2, np.float32))


def test_empty_pytree_costmap_raises_a_value_error_naming_the_array():
  cm = jf.Costmap(cost=jnp.zeros((1, 0, 4), jnp.uint8), origin=jnp.zeros((1, 2)), resolution=jnp.ones((1,)))
  with pytest.raises(ValueError, match=r"costmap\.cost must be uint8 \[B, H, W\] with B, H and W >= 1"):
    jf.types.check_costmap(cm, "test")


# --- constructors inside the user's jit ----------------------------------------------------------

def test_costmap_create_inside_jit_matches_eager():
  cost = np.arange(2 * 3 * 4, dtype=np.uint8).reshape(2, 3, 4)
  origin = np.float32([[1.5, -2.0], [0.25, 3.0]])
  res = np.float32([0.5, 0.05])
  eager = jf.Costmap.create(cost, origin, res)
  jitted = jax.jit(jf.Costmap.create)(cost, origin, res)
  for a, b in zip(jax.tree.leaves(eager), jax.tree.leaves(jitted)):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
  shared = jax.jit(lambda c, o, r: jf.Costmap.create(c, o, r))(cost, origin[0], res[0])
  np.testing.assert_array_equal(np.asarray(shared.origin), np.tile(origin[:1], (2, 1)))
  with pytest.raises(ValueError, match="cost must have dtype uint8"):
    jax.jit(jf.Costmap.create)(cost.astype(np.int32), origin, res)
  with pytest.raises(ValueError, match="origin must be"):
    jax.jit(jf.Costmap.create)(cost, np.zeros((3, 2), np.float32), res)


def test_costmap_geometry_ok_flags_traced_bad_geometry():
  ok = jax.jit(lambda r: jf.types.costmap_geometry_ok(
      jf.Costmap.create(jnp.zeros((2, 2, 2), jnp.uint8), jnp.zeros((2, 2)), r)))(jnp.float32([0.5, np.nan]))
  assert np.asarray(ok).tolist() == [True, False]


def test_with_data_inside_jit_swaps_the_contents_without_a_recompile():
  mask = _mask(np.zeros((3, 4)), 1.0, (-15.1, 0.0), jf.FilterInfo.create(1, 0.0, 1.0))
  pts = np.float32([[-13.6, 1.5]])

  @jax.jit
  def limit_with(d):
    return jf.speed_limit_at(mask.with_data(d), pts)[0]

  d = jnp.zeros((3, 4), jnp.int8).at[1, 1].set(30)
  assert float(limit_with(d)[0]) == 30.0
  with count_compiles() as compiles:
    assert float(limit_with(d.at[1, 1].set(70))[0]) == 70.0
  assert compiles() == 0
  with pytest.raises(ValueError, match="traced new mask data must be int8"):
    jax.jit(lambda d: mask.with_data(d).data)(jnp.zeros((1, 3, 4), jnp.int32))
  with pytest.raises(ValueError, match="must have shape"):
    jax.jit(lambda d: mask.with_data(d).data)(jnp.zeros((1, 4, 3), jnp.int8))


# --- soft zones at far, infinite and NaN points --------------------------------------------------

SHAPES = jf.Shapes.create([jf.Polygon([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], 100),
                           jf.Circle([5.0, 5.0], 1.0, 60)])


@pytest.mark.parametrize("x", [2e19, 1e30, 3e38, np.inf, -np.inf])
def test_soft_zones_far_and_infinite_points_are_outside(x):
  pts = np.float32([[x, 0.5], [0.5, x]])
  cost = np.asarray(jf.soft_keepout_cost(SHAPES, pts, width=0.1))
  np.testing.assert_array_equal(cost, [0.0, 0.0])
  lim = np.asarray(jf.soft_speed_limit(SHAPES, jf.FilterInfo.create(1, 0.0, 0.5), pts, width=0.1, no_limit=100.0))
  np.testing.assert_array_equal(lim, [100.0, 100.0])
  sd = np.asarray(jf.signed_distance(SHAPES, pts))
  assert (sd > 0).all()
  if np.isfinite(x) and abs(x) < 1e38:
    np.testing.assert_allclose(sd, abs(x), rtol=1e-6)
  elif not np.isfinite(x):
    assert np.isinf(sd).all()


def test_soft_zones_nan_points_give_nan():
  pts = np.float32([[np.nan, 0.5], [0.5, 0.5]])
  cost = np.asarray(jf.soft_keepout_cost(SHAPES, pts, width=0.1))
  assert np.isnan(cost[0]) and cost[1] > 250
  lim = np.asarray(jf.soft_speed_limit(SHAPES, jf.FilterInfo.create(1, 0.0, 0.5), pts, width=0.1, no_limit=100.0))
  assert np.isnan(lim[0]) and np.isfinite(lim[1])
  assert np.isnan(np.asarray(jf.signed_distance(SHAPES, pts))[0]).all()


def test_soft_zones_far_point_gradients_are_finite():
  g = jax.grad(lambda p: jf.soft_keepout_cost(SHAPES, p[None], width=0.1)[0])(jnp.float32([2e19, 0.5]))
  assert np.isfinite(np.asarray(g)).all()


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


def test_error_messages_stay_short_and_cheap_for_huge_values():
  """A list bomb shown in an error message: the text is built in bounded time and length."""
  import time
  from jaxfilters import validate
  bomb = [0.0]
  for _ in range(30):
    bomb = [bomb] * 9                   # 9**30 leaves if expanded
  t0 = time.perf_counter()
  text = validate.short_repr(bomb)
  assert time.perf_counter() - t0 < 30.0 and len(text) <= 80   # a blow-up takes far longer; not a speed test
