"""Keepout fleets for the fast-path tests: random costmaps over a stack of masks.

`fleet` builds B costmaps at given origins over M masks at given origins, with the
shapes below, so that every test file using it compiles each path once.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from jaxfilters.grid import OccupancyGrid
from jaxfilters.keepout import KeepoutState
from jaxfilters.types import Costmap, FilterInfo, FilterMask

KEEPOUT = FilterInfo.create(0)
B, H, W, M, HM, WM = 6, 12, 16, 2, 20, 18       # one shape: each path compiles once


def fleet(rng, res, mres, origins, mask_origins, *, windows=None, b=B):
  """b costmaps at `origins` [b, 2] (float64), M masks at `mask_origins` [M, 2].

  Returns:
    (costmap, mask, state, windows int32 [b, 4], mask_index int32 [b], enabled bool [b]).
  """
  data = rng.choice([-1, 0, 0, 1, 25, 50, 75, 99, 100, 100, 101, -128], (M, HM, WM)).astype(np.int8)
  grids = [OccupancyGrid.create(np.clip(d, -1, 100), float(mres), tuple(o)) for d, o in zip(data, mask_origins)]
  mask = FilterMask.create(grids, KEEPOUT).with_data(data)
  cost = rng.choice([0, 0, 10, 100, 200, 252, 253, 254, 255], (b, H, W)).astype(np.uint8)
  cm = Costmap.create(cost, np.asarray(origins, np.float64), res)
  if windows is None:
    x0, y0 = rng.integers(-2, W // 2, b), rng.integers(-2, H // 2, b)
    windows = np.stack([x0, y0, x0 + rng.integers(1, W + 3, b), y0 + rng.integers(1, H + 3, b)], 1)
    windows[0] = (0, 0, W, H)
  state = dataclasses.replace(KeepoutState.create(b), is_pose_lethal=jnp.asarray(rng.random(b) < 0.5))
  enabled = jnp.asarray(rng.random(b) < 0.9).at[0].set(True)
  return cm, mask, state, np.asarray(windows, np.int32), rng.integers(0, M, b).astype(np.int32), enabled


def fleet_with_lower_parts(rng, res, mres, origins, mask_origins, *, b, windows=None):
  """`fleet` with zero lower parts where the geometry is exactly float32 (same sums), so that every
  such fleet has one pytree layout and each path compiles once."""
  cm, mask, state, windows, idx, enabled = fleet(rng, res, mres, origins, mask_origins, windows=windows, b=b)
  z = lambda a, shape: jnp.zeros(shape, jnp.float32) if a is None else a
  cm = dataclasses.replace(cm, origin_lo=z(cm.origin_lo, (b, 2, 2)), resolution_lo=z(cm.resolution_lo, (b, 2)))
  mask = dataclasses.replace(mask, origin_lo=z(mask.origin_lo, (M, 2, 2)))
  return cm, mask, state, windows, idx, enabled
