"""Keepout under jit with unusable traced geometry, and batch mismatches (no silent wrong results).

A mask or costmap whose resolution or origin arrives traced as NaN, inf, a negative,
zero or subnormal value leaves that robot's costmap and state untouched and sets
`KeepoutState.error`, on every path of `keepout_filter` and in `keepout_update_bounds`.
A state, pose or per-robot array whose batch differs from the costmaps' raises a
ValueError naming both sizes at trace time.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfilters as jf
from jaxfilters.grid import OccupancyGrid
from jaxfilters.keepout import KeepoutConfig, PallasTuning
from jaxfilters.keepout.process import filter_batch

KEEPOUT = jf.FilterInfo.create(0)
BAD_RES = [float("nan"), float("inf"), -0.1, 0.0, 1e-40]
PALLAS_RES = [float("nan"), -0.1]
BAD_ORIGIN = [float("nan"), float("inf"), -float("inf")]


def _stack(res=1.0):
  grids = [OccupancyGrid.create(np.full((6, 6), 100, np.int8), res, (0.0, 0.0, 0.0))] * 2
  return jf.FilterMask.create(grids, KEEPOUT)


def _costmap(b=3):
  return jf.Costmap.create(np.zeros((b, 6, 6), np.uint8), (0.0, 0.0), 1.0)


def _bad_mask(mask, res=None, ox=None):
  """Mask 1's resolution or origin x replaced by a traced value."""
  if res is not None:
    mask = dataclasses.replace(mask, resolution=mask.resolution.at[1].set(res))
  if ox is not None:
    mask = dataclasses.replace(mask, origin=mask.origin.at[1, 0].set(ox))
  return mask


IDX = np.array([0, 1, 0], np.int32)
POSES = np.full((3, 3), 2.5, np.float32)

PATHS = {
    "same_frame": dict(mask_res=1.0, kw={}),
    "other_resolution": dict(mask_res=0.5, kw={}),
    "other_frame": dict(mask_res=1.0, kw=dict(transform=np.array([0.1, 0.0, 0.05], np.float32))),
    "pallas": dict(mask_res=1.0, kw=dict(config=KeepoutConfig(kernel="pallas",
                                                               pallas=PallasTuning(interpret=True)))),
}


def _check_robot_1_untouched(cost, state):
  cost = np.asarray(cost)
  assert np.all(cost[1] == 0), "robot 1's costmap was written from a garbage geometry"
  assert cost[0].max() == 254 and cost[2].max() == 254      # robots 0 and 2: their good mask
  np.testing.assert_array_equal(np.asarray(state.error), [False, True, False])


@functools.cache
def _filter_runner(path):
  """One jitted program per path: mask 1's resolution and origin x are its traced arguments, so every
  bad value of a path runs through the same compiled program."""
  p = PATHS[path]
  mask = _stack(p["mask_res"])

  @jax.jit
  def run(r, ox):
    return jf.keepout_filter(_costmap(), _bad_mask(mask, res=r, ox=ox), POSES, jf.KeepoutState.create(3),
                             mask_index=IDX, **p["kw"])
  return run, p["mask_res"]


@pytest.mark.parametrize("path, res", [(p, r) for p in PATHS for r in (PALLAS_RES if p == "pallas" else BAD_RES)])
def test_traced_bad_mask_resolution_is_masked_and_flagged(path, res):
  run, _ = _filter_runner(path)
  cm, state = run(jnp.float32(res), jnp.float32(0.0))
  _check_robot_1_untouched(cm.cost, state)


@pytest.mark.parametrize("path", ["same_frame", "other_frame"])
@pytest.mark.parametrize("ox", BAD_ORIGIN)
def test_traced_bad_mask_origin_is_masked_and_flagged(path, ox):
  run, mask_res = _filter_runner(path)
  cm, state = run(jnp.float32(mask_res), jnp.float32(ox))
  _check_robot_1_untouched(cm.cost, state)


@pytest.mark.parametrize("res", [float("nan"), -0.1, 1e-40])
def test_exact_reference_path_masks_bad_geometry(res):
  mask = _bad_mask(_stack(), res=jnp.float32(res))
  cm = _costmap()
  b = 3
  state = jf.KeepoutState.create(b)
  window = jnp.tile(jnp.asarray([0, 0, 6, 6], jnp.int32), (b, 1))
  out, st = filter_batch(cm, mask, jnp.asarray(IDX), jnp.ones((b,), bool), state, window,
                         jnp.ones((b,), bool), None, config=KeepoutConfig(), exact=True)
  _check_robot_1_untouched(out.cost, st)


@jax.jit
def _run_bad_costmap(r, ox):
  cm = _costmap()
  cm = dataclasses.replace(cm, resolution=cm.resolution.at[1].set(r), origin=cm.origin.at[1, 0].set(ox))
  return jf.keepout_filter(cm, _stack(), POSES, jf.KeepoutState.create(3), mask_index=np.zeros(3, np.int32))


@pytest.mark.parametrize("res", BAD_RES)
def test_traced_bad_costmap_geometry_is_masked_and_flagged(res):
  run = _run_bad_costmap
  cm, state = run(jnp.float32(res), jnp.float32(0.0))
  _check_robot_1_untouched(cm.cost, state)
  cm, state = run(jnp.float32(1.0), jnp.float32(np.nan))
  _check_robot_1_untouched(cm.cost, state)


BOUNDS = np.tile(np.array([1.0, 1.0, 2.0, 2.0], np.float32), (3, 1))


@functools.cache
def _bounds_runner(robot_in_zone):
  """One jitted updateBounds per zone test; mask 1's resolution is the traced argument."""
  mask = _stack()
  config = KeepoutConfig(override_lethal_cost=True)
  if robot_in_zone == "footprint":
    config = KeepoutConfig(override_lethal_cost=True, robot_in_zone="footprint", robot_radius=0.3,
                           min_mask_resolution=0.5)

  @jax.jit
  def run(r):
    return jf.keepout_update_bounds(_costmap(), _bad_mask(mask, res=r), POSES, jf.KeepoutState.create(3),
                                    BOUNDS, mask_index=IDX, config=config)
  return run


@pytest.mark.parametrize("res", BAD_RES)
@pytest.mark.parametrize("robot_in_zone", ["center", "footprint"])
def test_update_bounds_with_bad_traced_mask_geometry_is_untouched_and_flagged(res, robot_in_zone):
  bounds = BOUNDS
  state, out = _bounds_runner(robot_in_zone)(jnp.float32(res))
  np.testing.assert_array_equal(np.asarray(state.error), [False, True, False])
  np.testing.assert_array_equal(np.asarray(state.is_pose_lethal), [True, False, True])
  np.testing.assert_array_equal(np.asarray(out[1]), bounds[1])


def test_update_bounds_with_bad_traced_costmap_geometry_is_untouched_and_flagged():
  mask = _stack()
  bounds = np.tile(np.array([1.0, 1.0, 2.0, 2.0], np.float32), (3, 1))

  @jax.jit
  def run(r):
    cm = _costmap()
    cm = dataclasses.replace(cm, resolution=cm.resolution.at[1].set(r))
    return jf.keepout_update_bounds(cm, mask, POSES, jf.KeepoutState.create(3), bounds,
                                    new_mask=True, mask_index=np.zeros(3, np.int32))
  state, out = run(jnp.float32(np.nan))
  np.testing.assert_array_equal(np.asarray(state.error), [False, True, False])
  np.testing.assert_array_equal(np.asarray(out[1]), bounds[1])
  assert np.all(np.isfinite(np.asarray(out)))


# --- batch mismatches ----------------------------------------------------------------------------

def test_keepout_state_of_another_batch_names_both_sizes():
  mask = _stack()
  with pytest.raises(ValueError, match=r"KeepoutState has 3 robots \(is_pose_lethal \[3\]\) but costmaps have "
                                       r"4 \(cost \[4, 6, 6\]\)"):
    jf.keepout_filter(_costmap(4), mask, np.zeros((4, 3), np.float32), jf.KeepoutState.create(3),
                      mask_index=np.zeros(4, np.int32))
  with pytest.raises(ValueError, match=r"KeepoutState has 3 robots.*costmaps have 4"):
    jf.keepout_update_bounds(_costmap(4), mask, np.zeros((4, 3), np.float32), jf.KeepoutState.create(3),
                             np.zeros((4, 4), np.float32), mask_index=np.zeros(4, np.int32))


def test_keepout_state_with_leaves_of_different_batches_is_refused_under_jit():
  st = jf.KeepoutState.create(4)
  st = dataclasses.replace(st, acc_box=st.acc_box[:3])
  with pytest.raises(ValueError, match=r"acc_box \[3, 4\].*costmaps have 4"):
    jax.jit(lambda s: jf.keepout_filter(_costmap(4), _stack(), np.zeros((4, 3), np.float32), s,
                                        mask_index=np.zeros(4, np.int32)))(st)


@pytest.mark.parametrize("name", ["speed", "binary", "zone"])
def test_other_filters_name_state_and_poses_sizes(name):
  mask1 = jf.FilterMask.create(OccupancyGrid.create(np.zeros((4, 4), np.int8), 1.0), jf.FilterInfo.create(1))
  poses = np.zeros((4, 3), np.float32)
  table = jf.ZoneTable.create(["v"], {"v": 1.0}, {100: {"v": 2.0}})
  fns = {"speed": lambda: jf.speed_filter(mask1, poses, jf.SpeedState.create(3)),
         "binary": lambda: jf.binary_filter(mask1, poses, jf.BinaryState.create(3)),
         "zone": lambda: jf.zone_filter(mask1, poses, jf.ZoneState.create(table, 3), table)}
  state_name = {"speed": "SpeedState", "binary": "BinaryState", "zone": "ZoneState"}[name]
  with pytest.raises(ValueError, match=rf"{state_name} has 3 robots .* but poses have 4 \(poses \[4, 3\]\)"):
    fns[name]()
