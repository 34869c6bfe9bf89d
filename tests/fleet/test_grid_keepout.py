"""The local costmaps' keepout on the map's own grid (sims/fleet/local_costmap.py `KeepoutGrid`,
`grid_keepout`): the integers and the state `keepout_filter` gives, for masks on the map's grid,
and `keepout_filter` itself where the grid cannot be proven."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfilters import constants
from jaxfilters.keepout import KeepoutState
from jaxfilters.types import FilterInfo, FilterMask, OccupancyGrid
from sims.fleet import local_costmap
from sims.fleet.config import FleetConfig
from sims.fleet.scenario import Scenario
from sims.fleet.world import build_world, local_keepout_config

K = 16


@pytest.fixture(scope="module")
def world():
  return build_world(Scenario.default(), FleetConfig())


def _mask(world, shift_cells, shape, seed, *, extra=0.0):
  """A random keepout mask (unknown, free, graded and lethal cells) whose origin is the map's moved by
  shift_cells (x, y) cells, plus `extra` metres."""
  rng = np.random.default_rng(seed)
  data = rng.choice(np.array([-1, 0, 0, 0, 30, 99, 100, 100], np.int8), size=shape)
  res = float(world.params.map_resolution)
  o = np.asarray(world.params.map_origin, np.float64)
  origin = (o[0] + shift_cells[0] * res + extra, o[1] + shift_cells[1] * res + extra, 0.0)
  grid = OccupancyGrid.create(data, res, origin)
  return FilterMask.create(grid, FilterInfo.create(constants.KEEPOUT_FILTER))


def _grid(world, mask):
  h, w = world.params.static_cost.shape
  p = world.pad
  return local_costmap.keepout_grid(world.params.map_origin, world.params.map_resolution, mask,
                                    (-p, w - 2 * p), (-p, h - 2 * p))


def _poses(world, seed):
  """K poses over the map and beyond its edges (windows partly or wholly off the mask)."""
  rng = np.random.default_rng(seed)
  h, w = world.scenario.map.data.shape
  res = float(world.params.map_resolution)
  o = np.asarray(world.params.map_origin, np.float64)
  x = o[0] + rng.uniform(-0.3, 1.3, K) * w * res
  y = o[1] + rng.uniform(-0.3, 1.3, K) * h * res
  return jnp.asarray(np.stack([x, y, rng.uniform(-np.pi, np.pi, K)], axis=1), jnp.float32)


def _state(seed):
  rng = np.random.default_rng(seed)
  s = KeepoutState.create(K)
  return dataclasses.replace(s, is_pose_lethal=jnp.asarray(rng.random(K) < 0.5),
                             last_pose_lethal=jnp.asarray(rng.random(K) < 0.5))


def _run(world, mask, poses, state, grid, keepout_config):
  p = world.params
  fn = jax.jit(lambda mask, poses, state: local_costmap.local_costmaps(
      p.static_cost, p.map_origin, p.map_resolution, world.pad, mask, poses, state, n=world.window_cells,
      robot_radius=world.config.robot.radius, inflation=world.inflation, keepout_config=keepout_config,
      grid=grid))
  return fn(mask, poses, state)


def _assert_same(a, b):
  (cost_a, state_a), (cost_b, state_b) = a, b
  np.testing.assert_array_equal(np.asarray(cost_a.cost), np.asarray(cost_b.cost))
  np.testing.assert_array_equal(np.asarray(cost_a.origin), np.asarray(cost_b.origin))
  for leaf in ("is_pose_lethal", "last_pose_lethal", "acc_box", "error"):
    np.testing.assert_array_equal(np.asarray(getattr(state_a, leaf)), np.asarray(getattr(state_b, leaf)),
                                  err_msg=leaf)


# One mask shape (the world's), so the general path compiles once per escape mode; the shifts move the
# mask's origin by whole cells (the map's grid).
CASES = [("off", (0, 0), 1), ("off", (-7, 3), 2), ("off", (25, -40), 3), ("center", (-7, 3), 4),
         ("footprint", (25, -40), 5)]


@pytest.mark.parametrize("escape,shift,seed", CASES)
def test_grid_keepout_equals_keepout_filter(world, escape, shift, seed):
  mask = _mask(world, shift, world.params.keepout.data.shape[1:], seed)
  grid = _grid(world, mask)
  assert grid is not None and grid.offset == (-shift[0], -shift[1])
  cfg = None if escape == "off" else local_keepout_config(float(world.params.map_resolution),
                                                          FleetConfig(keepout_escape=escape), world.inflation)
  poses, state = _poses(world, seed), _state(seed)
  fast = _run(world, mask, poses, state, grid, cfg)
  _assert_same(fast, _run(world, mask, poses, state, None, cfg))
  # The comparison means something: zones were written (the poses reach 30 % past the map on each side).
  cost = np.asarray(fast[0].cost)
  assert np.any(cost == constants.LETHAL_OBSTACLE)


def test_off_grid_masks_are_not_taken_for_grid_masks(world):
  res = float(world.params.map_resolution)
  assert _grid(world, _mask(world, (3, 3), (50, 50), 4, extra=0.5 * res)) is None       # half a cell off
  assert _grid(world, _mask(world, (3, 3), (50, 50), 4, extra=0.3 * res)) is None
  other_res = FilterMask.create(OccupancyGrid.create(np.zeros((40, 40), np.int8), 2 * res, (0.0, 0.0, 0.0)),
                                FilterInfo.create(constants.KEEPOUT_FILTER))
  assert _grid(world, other_res) is None
  assert _grid(world, _mask(world, (0, 0), (50, 50), 4, extra=3.0e5)) is None     # 6 million cells away
  # A map far from its origin: float32 rounds a window's origin there by more than the slack.
  far = jnp.asarray([3.0e5, -3.0e5], jnp.float32)
  mask = FilterMask.create(OccupancyGrid.create(np.zeros((40, 40), np.int8), res, (3.0e5, -3.0e5, 0.0)),
                           FilterInfo.create(constants.KEEPOUT_FILTER))
  assert local_costmap.keepout_grid(far, world.params.map_resolution, mask, (-60, 400), (-60, 400)) is None
  near = jnp.asarray([30.0, -30.0], jnp.float32)
  mask = FilterMask.create(OccupancyGrid.create(np.zeros((40, 40), np.int8), res, (30.0, -30.0, 0.0)),
                           FilterInfo.create(constants.KEEPOUT_FILTER))
  assert local_costmap.keepout_grid(near, world.params.map_resolution, mask, (-60, 400), (-60, 400)) is not None
  # A tiny misfit (a hundredth of a cell) is still proven: each sample is half a cell from an edge.
  assert _grid(world, _mask(world, (3, 3), (50, 50), 4, extra=0.01 * res)) is not None


def test_swapped_params_on_another_grid_are_flagged_not_misread(world):
  mask = world.params.keepout
  grid = _grid(world, mask)
  moved = dataclasses.replace(mask, origin=mask.origin + jnp.float32(0.5 * float(world.params.map_resolution)))
  poses, state = _poses(world, 5), _state(5)
  (cost, out) = _run(world, moved, poses, state, grid, None)
  assert np.all(np.asarray(out.error))
  np.testing.assert_array_equal(np.asarray(out.last_pose_lethal), np.asarray(state.last_pose_lethal))
  # Nothing written: the costmaps are those of a world without the keepout mask's cells.
  empty = dataclasses.replace(mask, data=jnp.full_like(mask.data, -1))
  (plain, _) = _run(world, empty, poses, state, grid, None)
  np.testing.assert_array_equal(np.asarray(cost.cost), np.asarray(plain.cost))


def test_the_default_world_runs_the_grid_path(world):
  assert world.keepout_grid is not None and world.keepout_grid.offset == (0, 0)
  poses, state = _poses(world, 6), _state(6)
  _assert_same(_run(world, world.params.keepout, poses, state, world.keepout_grid, None),
               _run(world, world.params.keepout, poses, state, None, None))
