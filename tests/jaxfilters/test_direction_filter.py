"""Direction filter (one-way lanes, docs/nav2_semantics.md §13): encoding, per-robot headings, boundaries, errors."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfilters as jf
from jaxfilters import constants
from jaxfilters.direction import lane_direction
from tests.compile_count import count_compiles

BASE, MULT = -5.0, 5.0           # d = 1 east, 19 north, 37 west, 55 south (5 degree steps)
EAST, NORTH, WEST, SOUTH = 1, 19, 37, 55


def _mask(data, res=0.5, origin=(0.0, 0.0), ftype=constants.DIRECTION_FILTER):
  return jf.FilterMask.create(jf.OccupancyGrid.create(np.asarray(data, np.int8), res, origin),
                              jf.FilterInfo.create(ftype, BASE, MULT))


def _costmaps(b, shape, res=0.5, origin=(0.0, 0.0), seed=0):
  cost = np.random.default_rng(seed).integers(0, 256, (b, *shape)).astype(np.uint8)
  return cost, jf.Costmap.create(cost, origin, res)


def _reference(cost, cm_origin, cm_res, data, m_origin, m_res, yaws, half_deg):
  """float64 loops over robots and cells: (new cost, near-boundary cells to skip)."""
  out = cost.copy()
  skip = np.zeros(cost.shape, bool)
  hm, wm = data.shape
  for r in range(cost.shape[0]):
    for i in range(cost.shape[1]):
      for j in range(cost.shape[2]):
        x = cm_origin[0] + (j + 0.5) * cm_res
        y = cm_origin[1] + (i + 0.5) * cm_res
        mx, my = math.floor((x - m_origin[0]) / m_res), math.floor((y - m_origin[1]) / m_res)
        if not (0 <= mx < wm and 0 <= my < hm) or data[my, mx] < 1:
          continue
        centre = math.radians(data[my, mx] * MULT + BASE)
        off = abs((float(yaws[r]) - centre + math.pi) % (2 * math.pi) - math.pi)
        skip[r, i, j] = abs(off - math.radians(half_deg)) < 1e-4
        if off > math.radians(half_deg):
          out[r, i, j] = constants.LETHAL_OBSTACLE
  return out, skip


def test_encoding_round_trip_through_a_raw_pgm_and_the_strict_loader(tmp_path):
  # A 4 x 3 raw-mode PGM: image rows top (y high) to bottom; byte = occupancy value in raw mode.
  img = np.array([[0, NORTH, 255, 0],          # 255 -> -1 (unknown) in raw mode
                  [EAST, EAST, EAST, EAST],
                  [WEST, SOUTH, 0, 0]], np.uint8)
  (tmp_path / "lanes.pgm").write_bytes(b"P5\n4 3\n255\n" + img.tobytes())
  (tmp_path / "lanes.yaml").write_text("image: lanes.pgm\nmode: raw\nresolution: 0.5\n"
                                       "origin: [1.0, 2.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\n"
                                       "free_thresh: 0.196\n")
  grid = jf.load_map(tmp_path / "lanes.yaml")
  want_data = img[::-1].astype(np.int16)
  want_data[want_data == 255] = -1                          # raw mode: bytes wrap to int8
  np.testing.assert_array_equal(grid.data, want_data)
  mask = jf.FilterMask.create(grid, jf.FilterInfo.create(constants.DIRECTION_FILTER, BASE, MULT))
  info = jax.tree.map(lambda x: x[0], mask.info)
  centre, constrained, bad = lane_direction(jnp.asarray(grid.data, jnp.int32), info)
  want = {EAST: 0.0, NORTH: 90.0, WEST: -180.0, SOUTH: -90.0}   # centres in [-180, 180)
  for (r, c), d in np.ndenumerate(np.asarray(grid.data)):
    assert bool(constrained[r, c]) == (d >= 1) and not bool(bad[r, c])
    if d >= 1:
      assert abs(math.degrees(float(centre[r, c])) - want[int(d)]) < 1e-4, (r, c, d)
  # Grid rows, bottom up: [W, S, 0, 0], [E, E, E, E], [0, N, -1, 0]; half-width 100 deg: only the opposite lanes.
  cm = jf.Costmap.create(np.zeros((2, 3, 4), np.uint8), (1.0, 2.0), 0.5)
  out, res = jf.direction_filter(cm, mask, np.array([[1.2, 2.7, np.pi], [1.2, 2.7, 0.0]], np.float32),
                                 config=jf.DirectionConfig(half_width_deg=100.0))
  lethal = np.asarray(out.cost) == constants.LETHAL_OBSTACLE
  np.testing.assert_array_equal(lethal[0], [[0, 0, 0, 0], [1, 1, 1, 1], [0, 0, 0, 0]])   # facing west
  np.testing.assert_array_equal(lethal[1], [[1, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0]])   # facing east
  assert res.wrong_way.tolist() == [True, False] and res.constrained.tolist() == [True, True]
  assert not res.error.any()


def test_per_robot_headings_in_one_batch_match_the_float64_reference():
  rng = np.random.default_rng(1)
  data = rng.choice([-1, 0, 0, EAST, NORTH, WEST, SOUTH, 10, 28, 46, 64, 72], (9, 11)).astype(np.int8)
  m_origin, m_res = (-1.25, 0.5), 0.5
  mask = _mask(data, m_res, m_origin)
  b, shape, cm_origin, cm_res = 8, (14, 12), (-1.5, 0.25), 0.25
  cost, cm = _costmaps(b, shape, cm_res, cm_origin)
  yaws = np.float32(rng.uniform(-np.pi, np.pi, b))
  poses = np.stack([np.full(b, 1.0), np.full(b, 1.5), yaws], axis=1).astype(np.float32)
  for half in (90.0, 30.0):
    out, _ = jf.direction_filter(cm, mask, poses, config=jf.DirectionConfig(half_width_deg=half))
    want, skip = _reference(cost, cm_origin, cm_res, data, m_origin, m_res, yaws, half)
    got = np.asarray(out.cost)
    np.testing.assert_array_equal(got[~skip], want[~skip])
    assert (got != cost).any(), "some cell must be blocked for some robot"
    # Robots differ: at least two robots see different costmaps.
    assert len({got[r].tobytes() for r in range(b)}) > 1


@pytest.mark.parametrize("half_deg", [90.0, 45.0, 10.0])
def test_exact_sector_boundary_is_allowed_one_ulp_beyond_is_not(half_deg):
  mask = _mask(np.full((2, 2), EAST, np.int8))              # centre exactly 0 rad
  hw = np.float32(math.radians(half_deg))
  assert jf.DirectionConfig(half_width_deg=half_deg).half_width == hw
  yaws = np.array([hw, -hw, np.nextafter(hw, np.float32(np.inf)), -np.nextafter(hw, np.float32(np.inf))],
                  np.float32)
  poses = np.stack([np.full(4, 0.5), np.full(4, 0.5), yaws], axis=1).astype(np.float32)
  _, cm = _costmaps(4, (2, 2))
  out, res = jf.direction_filter(jf.Costmap.create(np.zeros((4, 2, 2), np.uint8), (0.0, 0.0), 0.5), mask, poses,
                                 config=jf.DirectionConfig(half_width_deg=half_deg))
  blocked = np.asarray(out.cost).reshape(4, -1).max(axis=1) == constants.LETHAL_OBSTACLE
  assert blocked.tolist() == [False, False, True, True]
  assert res.wrong_way.tolist() == [False, False, True, True]
  # Wrap-around: a lane to the west (centre +-pi) and headings just either side of +-pi are on it.
  west = _mask(np.full((2, 2), WEST, np.int8))
  near_pi = np.array([np.pi - 0.01, -np.pi + 0.01, 0.0, np.pi / 2 - 0.01], np.float32)
  poses = np.stack([np.full(4, 0.5), np.full(4, 0.5), near_pi], axis=1).astype(np.float32)
  _, res = jf.direction_filter(cm, west, poses, config=jf.DirectionConfig(half_width_deg=half_deg))
  assert res.wrong_way.tolist() == [False, False, True, True]


def test_unconstrained_cells_and_other_mask_types_are_untouched():
  data = np.array([[0, -1, EAST], [-1, 0, EAST]], np.int8)
  cost, cm = _costmaps(3, (2, 3))
  poses = np.array([[0.5, 0.5, np.pi], [0.2, 0.2, 0.0], [1.4, 0.7, np.pi]], np.float32)
  out, res = jf.direction_filter(cm, _mask(data), poses)
  got = np.asarray(out.cost)
  np.testing.assert_array_equal(got[:, :, :2], cost[:, :, :2])            # 0 and -1: never written
  np.testing.assert_array_equal(got[0, :, 2], [254, 254])
  np.testing.assert_array_equal(got[1], cost[1])                           # eastbound: nothing
  assert res.constrained.tolist() == [False, False, True] and res.wrong_way.tolist() == [False, False, True]
  assert res.blocked_cells.tolist() == [int((cost[0, :, 2] != 254).sum()), 0, int((cost[2, :, 2] != 254).sum())]
  # A keepout-typed mask with the same bytes changes nothing and is flagged, never silent.
  out, res = jf.direction_filter(cm, _mask(data, ftype=constants.KEEPOUT_FILTER), poses)
  np.testing.assert_array_equal(np.asarray(out.cost), cost)
  assert not res.wrong_way.any() and not res.constrained.any() and res.error.all()


def test_velocity_direction_decides_wrong_way_motion():
  mask = _mask(np.full((2, 2), EAST, np.int8))
  _, cm = _costmaps(3, (2, 2))
  poses = np.array([[0.5, 0.5, 0.0]] * 3, np.float32)                     # all facing east
  vel = np.array([[-0.3, 0.0], [0.3, 0.0], [-0.01, 0.0]], np.float32)      # reversing, forward, creeping back
  _, res = jf.direction_filter(cm, mask, poses, velocities=vel, config=jf.DirectionConfig(min_speed=0.05))
  assert res.wrong_way.tolist() == [True, False, False]


def test_frame_transform_turns_the_heading_and_the_cells():
  data = np.zeros((8, 8), np.int8)
  data[:, 4:] = NORTH
  mask = _mask(data, 0.5, (-2.0, -2.0))
  cost, cm = _costmaps(2, (6, 6), 0.5, (-1.5, -1.5))
  poses = np.array([[0.2, -0.6, 0.0], [0.2, -0.6, np.pi]], np.float32)     # (0.6, 0.2) on the mask: a lane cell
  # T_mask_from_global: a quarter turn; a robot facing +x in the costmap faces +y (north) on the mask.
  out, res = jf.direction_filter(cm, mask, poses, transform=np.array([0.0, 0.0, np.pi / 2], np.float32))
  same, _ = jf.direction_filter(cm, mask, np.array([[0.6, 0.2, np.pi / 2], [0.6, 0.2, -np.pi / 2]], np.float32))
  assert res.wrong_way.tolist() == [False, True]
  np.testing.assert_array_equal(np.asarray(out.cost)[0], cost[0])
  assert (np.asarray(out.cost)[1] == 254).sum() > 0 and (np.asarray(same.cost)[1] == 254).sum() > 0


def test_jit_and_eager_agree_and_a_second_call_compiles_nothing():
  rng = np.random.default_rng(3)
  data = rng.choice([-1, 0, EAST, NORTH, WEST, SOUTH], (6, 7)).astype(np.int8)
  mask = _mask(data, 0.5, (0.25, -0.25))
  _, cm = _costmaps(5, (8, 8), 0.375, (0.0, -0.5))
  poses = np.concatenate([rng.uniform(0, 3, (5, 2)), rng.uniform(-4, 4, (5, 1))], axis=1).astype(np.float32)
  eager = jf.direction_filter(cm, mask, poses)
  jitted = jax.jit(lambda c, m, p: jf.direction_filter(c, m, p))(cm, mask, jnp.asarray(poses))
  for a, b in zip(jax.tree.leaves(eager), jax.tree.leaves(jitted)):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
  with count_compiles() as compiles:
    jf.direction_filter(cm, mask, poses + np.float32(0.1))
    jf.direction_filter(cm, mask.with_data(np.asarray(data)[::-1]), poses)
  assert compiles() == 0


@pytest.mark.parametrize("kwargs, match", [
    ({"half_width_deg": 0.0}, r"\(0, 180\]"),
    ({"half_width_deg": 181.0}, r"\(0, 180\]"),
    ({"half_width_deg": float("nan")}, "finite"),
    ({"min_speed": -0.1}, ">= 0"),
    ({"min_speed": float("inf")}, "finite"),
])
def test_bad_config_raises(kwargs, match):
  with pytest.raises(ValueError, match=match):
    jf.DirectionConfig(**kwargs)


def test_a_config_value_that_is_not_a_number_is_a_type_error():
  with pytest.raises(TypeError, match="must be a number"):
    jf.DirectionConfig(half_width_deg=True)
  with pytest.raises(TypeError, match="must be a number"):
    jf.DirectionConfig(min_speed="0.1")


def test_bad_inputs_raise_with_what_was_expected():
  mask = _mask(np.full((2, 2), EAST, np.int8))
  _, cm = _costmaps(2, (2, 2))
  ok = np.zeros((2, 3), np.float32)
  with pytest.raises(ValueError, match=r"poses must be \[B, 3\] = \(2, 3\)"):
    jf.direction_filter(cm, mask, np.zeros((3, 3), np.float32))
  with pytest.raises(ValueError, match=r"velocities must be float \[B, 2\]"):
    jf.direction_filter(cm, mask, ok, velocities=np.zeros((2, 3), np.float32))
  with pytest.raises(ValueError, match=r"mask_index must lie in \[0, 1\)"):
    jf.direction_filter(cm, mask, ok, mask_index=np.array([0, 1]))
  with pytest.raises(TypeError, match="DirectionConfig"):
    jf.direction_filter(cm, mask, ok, config={"half_width_deg": 90})
  with pytest.raises(ValueError, match="costmap.cost must be uint8"):
    jf.direction_filter(jf.Costmap(cm.cost.astype(jnp.int32), cm.origin, cm.resolution), mask, ok)
  with pytest.raises(ValueError, match="type must be one of"):
    jf.FilterInfo.create(6)


def test_value_problems_under_jit_are_masked_and_flagged():
  data = np.full((2, 2), EAST, np.int8)
  data[1, 1] = -5                                        # a raw-mode byte 251: not a direction
  mask = _mask(np.full((2, 2), EAST, np.int8)).with_data(data)
  cost, cm = _costmaps(4, (2, 2))
  poses = np.array([[0.2, 0.2, np.pi], [0.2, 0.2, np.nan], [0.2, 0.2, np.pi], [0.2, 0.2, 0.0]], np.float32)
  run = jax.jit(lambda c, m, p, i: jf.direction_filter(c, m, p, mask_index=i))
  out, res = run(cm, mask, jnp.asarray(poses), jnp.asarray([0, 0, 3, 0], jnp.int32))
  got = np.asarray(out.cost)
  # Robot 0: the east-lane cells blocked, the bad cell left as it was and flagged.
  assert got[0, 0, 0] == got[0, 0, 1] == got[0, 1, 0] == 254 and got[0, 1, 1] == cost[0, 1, 1]
  # Robot 1 (NaN yaw) and robot 2 (mask_index 3 of 1): untouched, flagged, never wrong-way.
  np.testing.assert_array_equal(got[1], cost[1])
  np.testing.assert_array_equal(got[2], cost[2])
  assert res.error.tolist() == [True, True, True, True]  # robot 3 also sees the bad cell in its costmap
  assert res.wrong_way.tolist() == [True, False, False, False]
  # Eager, the same NaN yaw is a value problem too: flagged, not raised.
  out, res = jf.direction_filter(cm, _mask(np.full((2, 2), EAST, np.int8)), poses[:2][[1, 1]].repeat(2, 0))
  np.testing.assert_array_equal(np.asarray(out.cost), cost)
  assert res.error.all() and not res.wrong_way.any()
