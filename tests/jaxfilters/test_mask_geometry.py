"""Mask and costmap geometry: traced bad values masked and flagged on every filter, pytree-built masks with bad shapes named at trace time, constructors inside jit, short error messages.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfilters as jf
from jaxfilters.grid import OccupancyGrid
from tests.compile_count import count_compiles

H, W, N = 5, 7, 24                      # fixed shapes: every example reuses one compiled program


def _mask(data, res, origin, info):
  return jf.FilterMask.create(OccupancyGrid.create(np.asarray(data, np.int8), res, origin), info)


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

