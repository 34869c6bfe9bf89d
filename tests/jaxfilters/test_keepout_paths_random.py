"""Fast paths give the same integers as the exact per-cell keepout path on random inputs.

`keepout_filter` runs the fast paths (the same-frame slice where a robot's mask
cells are consecutive, with `KeepoutConfig(aligned_fast_path=True)`, the default;
otherwise a separable gather; the bracketed other-frame path with a transform);
`process.filter_batch(exact=True)` runs the exact per-cell path on every cell. They
must agree bit for bit, with both batch loops. tests/jaxfilters/test_keepout_paths.py puts
cell centres on mask-cell edges; these fleets are random.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfilters import keepout as ko
from jaxfilters.keepout import common, process, same_frame
from jaxfilters.keepout import reference as keepout_reference
from jaxfilters.grid import OccupancyGrid
from jaxfilters.types import Costmap, FilterInfo, FilterMask
from reference import nav2 as reference

KEEPOUT = FilterInfo.create(0)
B, H, W, HM, WM = 6, 12, 16, 20, 18


def _fleet(seed, *, same_res=True, num_masks=1):
  rng = np.random.default_rng(seed)
  res = np.float32(rng.choice([0.05, 0.1, 0.03, 1.0, 0.025]))
  mres = res if same_res else np.float32(res * rng.choice([0.5, 2.0]))
  # Values outside -1..100 (only reachable through with_data) are unknown to both paths.
  data = rng.choice([-1, 0, 0, 1, 25, 50, 75, 99, 100, 100, 101, -128, 127], (num_masks, HM, WM)).astype(np.int8)
  grids = [OccupancyGrid.create(np.clip(d, -1, 100), float(mres), tuple(rng.uniform(-20, 20, 2))) for d in data]
  mask = FilterMask.create(grids, KEEPOUT).with_data(data)
  morigin = np.asarray(mask.origin)[0]
  # Origins on and off the mask grid, some windows partly or wholly off the mask.
  k = rng.integers(-W - 4, WM + 4, (B, 2))
  frac = np.where(rng.random((B, 1)) < 0.5, 0.0, rng.uniform(0, 1, (B, 2)))
  origin = (morigin + (k + frac) * mres).astype(np.float32)
  cost = rng.choice([0, 0, 10, 100, 200, 252, 253, 254, 255], (B, H, W)).astype(np.uint8)
  cm = Costmap.create(cost, origin, res)
  x0 = rng.integers(-2, W // 2, B)
  y0 = rng.integers(-2, H // 2, B)
  window = np.stack([x0, y0, x0 + rng.integers(1, W + 3, B), y0 + rng.integers(1, H + 3, B)], 1).astype(np.int32)
  state = ko.KeepoutState.create(B)
  state = dataclasses.replace(state, is_pose_lethal=jnp.asarray(rng.random(B) < 0.5))
  mask_index = rng.integers(0, num_masks, B).astype(np.int32) if num_masks > 1 else None
  enabled = jnp.asarray(rng.random(B) < 0.85)
  return cm, mask, state, window, mask_index, enabled


def _run(cm, mask, state, window, mask_index, enabled, config, *, exact=False, loop="auto", transform=None):
  # One module-level jitted program per (config, exact, loop, shapes): no compile per call.
  idx, ok, _, en, win, tf = common.batched_inputs(cm, mask, jnp.zeros((B, 3)), mask_index, enabled,
                                                  jnp.asarray(window), transform, "test")
  out, st = process.filter_batch(cm, mask, idx, ok, common.fill_error(state, B), win, en, tf, config=config,
                                 exact=exact, loop=loop)
  return np.asarray(out.cost), np.asarray(st.last_pose_lethal)


CONFIGS = [ko.KeepoutConfig(), ko.KeepoutConfig(override_lethal_cost=True, lethal_override_cost=200)]


@pytest.mark.parametrize("seed", range(10))
@pytest.mark.parametrize("cfg", CONFIGS, ids=["plain", "override"])
def test_aligned_fast_path_equals_general_path(seed, cfg):
  case = _fleet(seed, num_masks=1 + 2 * (seed % 2))
  exact = _run(*case, cfg, exact=True)
  for aligned in (True, False):
    fast = _run(*case, dataclasses.replace(cfg, aligned_fast_path=aligned))
    np.testing.assert_array_equal(fast[0], exact[0])
    np.testing.assert_array_equal(fast[1], exact[1])


@pytest.mark.parametrize("seed", range(4))
def test_fast_path_matches_float64_reference(seed):
  cm, mask, state, window, mask_index, enabled = _fleet(100 + seed)
  enabled = jnp.ones((B,), bool)
  got, _ = _run(cm, mask, state, window, mask_index, enabled, ko.KeepoutConfig())
  for b in range(B):
    win = np.clip(window[b], 0, [W, H, W, H])
    want, _ = reference.keepout_process(np.asarray(cm.cost[b]), np.asarray(cm.origin[b]), np.asarray(cm.resolution[b]),
                                        np.asarray(mask.data[0]), np.asarray(mask.origin[0]),
                                        np.asarray(mask.resolution[0]), win)
    np.testing.assert_array_equal(got[b], want)


# "vmap" runs the slice on four cells per uint32 word when W % 4 == 0 (W = 16), bytewise otherwise
# (the costmaps cropped to W = 14).
@pytest.mark.parametrize("loop,width", [("map", W), ("vmap", W), ("vmap", W - 2)])
@pytest.mark.parametrize("seed", range(4))
def test_both_batch_loops_agree(seed, loop, width):
  cm, mask, state, window, mask_index, enabled = _fleet(200 + seed, num_masks=3)
  cm = dataclasses.replace(cm, cost=cm.cost[:, :, :width])
  cfg = ko.KeepoutConfig(override_lethal_cost=bool(seed % 2), lethal_override_cost=100)
  idx, ok, _, en, win, _ = common.batched_inputs(cm, mask, jnp.zeros((B, 3)), mask_index, enabled,
                                                 jnp.asarray(window), None, "test")
  state = common.fill_error(state, B)
  cost, st = _same_frame(cm, mask, idx, ok, state, win, en, config=cfg, loop=loop)
  want = _run(cm, mask, state, window, mask_index, enabled, cfg, exact=True)
  np.testing.assert_array_equal(np.asarray(cost), want[0])
  np.testing.assert_array_equal(np.asarray(st.last_pose_lethal), want[1])


_same_frame = jax.jit(same_frame.same_frame_batch, static_argnames=("config", "loop"))


@pytest.mark.parametrize("seed", range(3))
def test_mixed_resolutions_fall_back_to_general_path(seed):
  case = _fleet(300 + seed, same_res=False)
  fast = _run(*case, ko.KeepoutConfig())
  slow = _run(*case, ko.KeepoutConfig(), exact=True)
  np.testing.assert_array_equal(fast[0], slow[0])


@pytest.mark.parametrize("seed", range(3))
def test_other_frame_fast_path_equals_exact_path(seed):
  case = _fleet(500 + seed, same_res=bool(seed % 2), num_masks=3)
  tf = jnp.asarray(np.float32(np.random.default_rng(seed).uniform(-1, 1, (B, 3))))
  for loop in ("map", "vmap"):
    fast = _run(*case, ko.KeepoutConfig(), loop=loop, transform=tf)
    slow = _run(*case, ko.KeepoutConfig(), exact=True, transform=tf)
    np.testing.assert_array_equal(fast[0], slow[0])
    np.testing.assert_array_equal(fast[1], slow[1])


def test_cost_plus_one_table_is_occ_to_cost_plus_one():
  v = np.arange(256, dtype=np.uint8).view(np.int8)
  want = (np.asarray(ko.occ_to_cost(jnp.asarray(v))).astype(np.int32) + 1) % 256
  np.testing.assert_array_equal(ko.mask_cost_plus_one_table(), want)


def test_chunked_general_path_equals_one_vmap(monkeypatch):
  cm, mask, state, window, mask_index, enabled = _fleet(400, same_res=False)
  tf = jnp.asarray(np.float32(np.random.default_rng(1).uniform(-1, 1, (B, 3))))
  idx, ok, _, en, win, tf = common.batched_inputs(cm, mask, jnp.zeros((B, 3)), None, enabled, jnp.asarray(window), tf,
                                               "test")
  state = common.fill_error(state, B)
  # A fresh jit per run: the chunk size is read when the program is traced.
  general = lambda c, s: keepout_reference.general_batch(dataclasses.replace(cm, cost=c), mask, idx, ok, s, win, en,
                                                         tf, config=ko.KeepoutConfig())[0]
  run = lambda: np.asarray(jax.jit(general)(cm.cost, state))
  whole = run()
  monkeypatch.setattr(keepout_reference, "GENERAL_CHUNK_CELLS", 2 * H * W)  # chunks of 2 robots, one remainder
  np.testing.assert_array_equal(run(), whole)
