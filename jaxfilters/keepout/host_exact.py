"""Internal: the exact same-frame path for a few robots on the host, in integer arithmetic (no compile).

An eager keepout call redoes the few robots its fast path leaves open (a cell centre or a window
edge within float32 rounding of a mask-cell edge: plan.py; off a CPU their rows are gathered from
the device and scattered back, process.py). The device's exact path
(reference.py) decides every cell with float32 expansions, so it compiles for ~1.5 s on a
2-core CPU, the larger part of an eager call's first run. Here the same integers come from
Python integers: every input is a float32 or a host double carried as float32 parts, so each
is a dyadic rational, and each quantity the exact path decides is a sum of such values and of
their exact products, divided by one of them. Scaled to a common power of two the sums are
integers, and Python's `//` floors them exactly.

For robot r on mask i, same frame (docs/nav2_semantics.md §4.3), with O, R the costmap's host
origin and resolution (the exact sums of their float32 parts), MO, MR the mask's:

* the window clip (`reference.same_frame_window`): g_k = trunc((MO + e_k MR + MR / 2 - O) / R)
  for the corners e = (0, 0) and (Wm, Hm), then Nav2's overlap test and clip;
* the mask cell of column i (`geometry.centres_to_cells_2d`): floor((O + (2 i + 1) R / 2 - MO) / MR),
  valid where the numerator is >= 0 and the cell < Wm (rows the same);
* the write rule and the state update of `reference.keepout_stack_one`.

The device computes those floors exactly for |quotient| < 2^22; a robot with a larger one, a
frame transform, or geometry that `types.mask_geometry_ok` / `costmap_geometry_ok` would refuse
is not taken here (`redo` returns None and the caller runs the device's exact path).
tests/jaxfilters/test_keepout_host_exact.py holds it to the device's exact path.
"""

from __future__ import annotations

import dataclasses
import math
from fractions import Fraction

import numpy as np

from jaxfilters import constants
from jaxfilters.keepout.config import KeepoutConfig, mask_cost_plus_one_table
from jaxfilters.types import costmap_geometry_ok, mask_geometry_ok

_LIMIT = 2 ** 22                 # the device's exact floors are exact below this quotient
_COST = (mask_cost_plus_one_table().astype(np.int32) + 255) % 256     # int8 byte -> cost (255 unknown)


def _parts(*arrays):
  """The exact sum of float32 parts (each array a scalar part, or None) as a Fraction."""
  return sum((Fraction(float(a)) for a in arrays if a is not None), Fraction(0))


def _floor_cells(origin, res, mask_origin, mask_res, n, size):
  """(cells int64 [n] clipped to [0, size), valid bool [n]) for columns 0..n-1, or None past 2^22."""
  a, half = origin - mask_origin, res / 2
  den = math.lcm(a.denominator, half.denominator)
  a_i, h_i = int(a * den), int(half * den)          # exact: den is a multiple of both denominators
  p, q = mask_res.numerator, mask_res.denominator
  nums = [a_i + (2 * k + 1) * h_i for k in range(n)]
  cells = [(v * q) // (den * p) for v in nums]      # floor((a + (2k + 1) half) / mask_res)
  if cells and max(abs(cells[0]), abs(cells[-1])) >= _LIMIT:  # increasing in k: the ends bound every entry
    return None
  cells = np.asarray(cells, np.int64)
  valid = np.asarray([v >= 0 for v in nums], bool) & (cells < size)
  return np.clip(cells, 0, size - 1), valid


def _trunc(num: Fraction, res: Fraction):
  v = num / res
  return None if abs(v) >= _LIMIT else int(v)           # int() of a Fraction truncates toward zero


def _one(cost, origin, res, data, mask_origin, mask_res, is_lethal, window, enabled, config):
  """(new cost uint8 [H, W], run bool) for one usable robot, or None outside the exact domain."""
  h, w = cost.shape
  hm, wm = data.shape
  min_i, min_j, max_i, max_j = (int(v) for v in window)
  half = mask_res / 2
  g = [_trunc(mask_origin[a] + e * mask_res + half - origin[a], res)
       for a, e in ((0, 0), (1, 0), (0, wm), (1, hm))]
  if None in g:
    return None
  overlap = not (g[0] >= max_i or g[1] >= max_j) and not (g[2] <= min_i or g[3] <= min_j)
  x0, y0, x1, y1 = max(min_i, g[0]), max(min_j, g[1]), min(max_i, g[2]), min(max_j, g[3])
  cx = _floor_cells(origin[0], res, mask_origin[0], mask_res, w, wm)
  cy = _floor_cells(origin[1], res, mask_origin[1], mask_res, h, hm)
  if cx is None or cy is None:
    return None
  (mx, vx), (my, vy) = cx, cy
  cols, rows = np.arange(w), np.arange(h)
  visit = (((cols >= x0) & (cols < x1) & vx)[None, :] & ((rows >= y0) & (rows < y1) & vy)[:, None])
  mask_cost = _COST[data.view(np.uint8)[my[:, None], mx[None, :]]]
  old = cost.astype(np.int32)
  unknown_old = old == constants.NO_INFORMATION
  if config.unknown_overwrite == "inscribed":
    unknown_old = unknown_old & (mask_cost >= constants.INSCRIBED_INFLATED_OBSTACLE)
  write = visit & (mask_cost != constants.NO_INFORMATION) & ((mask_cost > old) | unknown_old)
  value = mask_cost
  if config.override_lethal_cost and is_lethal:
    value = np.full_like(mask_cost, config.lethal_override_cost)
  run = bool(enabled) and overlap
  new = np.where(write, value, old).astype(np.uint8) if run else cost
  return new, run


def redo(costmap, idx, idx_ok, state, window, enabled, transform, *, mask, config: KeepoutConfig):
  """The exact path's (costmap with its new cost, new state) for a sub-fleet of host (NumPy) inputs,
  the same integers as `process.filter_batch(..., exact=True)`; None where a robot is outside this
  module's domain (a transform, unusable geometry, a quotient past 2^22: the module docstring)."""
  if transform is not None:
    return None
  cost = np.asarray(costmap.cost)
  origin, res = np.asarray(costmap.origin), np.asarray(costmap.resolution)
  origin_lo = None if costmap.origin_lo is None else np.asarray(costmap.origin_lo)
  res_lo = None if costmap.resolution_lo is None else np.asarray(costmap.resolution_lo)
  m = mask.data.shape[0]
  data = {}                         # the masks the robots read, copied to the host once each
  m_origin, m_res = np.asarray(mask.origin), np.asarray(mask.resolution)
  m_origin_lo = None if mask.origin_lo is None else np.asarray(mask.origin_lo)
  # The device path's test (common.usable_geometry) in NumPy: no device op to compile per sub-fleet size.
  geometry_ok = costmap_geometry_ok(dataclasses.replace(costmap, origin=origin, resolution=res, origin_lo=origin_lo,
                                                        resolution_lo=res_lo), xp=np)
  mask_ok = mask_geometry_ok(dataclasses.replace(mask, origin=m_origin, resolution=m_res, origin_lo=m_origin_lo),
                             xp=np)
  idx, idx_ok = np.asarray(idx), np.asarray(idx_ok)
  lethal, last = np.asarray(state.is_pose_lethal), np.asarray(state.last_pose_lethal)
  window, enabled = np.asarray(window), np.asarray(enabled)
  new_cost, new_last = cost.copy(), last.copy()
  error = np.zeros(cost.shape[0], bool)
  for r in range(cost.shape[0]):
    i = int(idx[r])
    if not (bool(idx_ok[r]) and 0 <= i < m and mask_ok[i] and geometry_ok[r]):
      error[r] = True        # left untouched, as a robot with an out-of-range mask index
      continue
    r_lo = None if res_lo is None else res_lo[r]
    o_lo = None if origin_lo is None else origin_lo[r]
    mo_lo = None if m_origin_lo is None else m_origin_lo[i]
    o = [_parts(origin[r, a], *(() if o_lo is None else o_lo[a])) for a in (0, 1)]
    mo = [_parts(m_origin[i, a], *(() if mo_lo is None else mo_lo[a])) for a in (0, 1)]
    if i not in data:
      data[i] = np.asarray(mask.data[i])
    out = _one(cost[r], o, _parts(res[r], *(() if r_lo is None else r_lo)), data[i], mo, Fraction(float(m_res[i])),
               bool(lethal[r]), window[r], enabled[r], config)
    if out is None:
      return None
    new_cost[r], run = out
    if run:
      new_last[r] = lethal[r]
  new_state = dataclasses.replace(state, last_pose_lethal=new_last, error=error)
  return dataclasses.replace(costmap, cost=new_cost), new_state
