"""Internal: which mask cells a robot's window reads on the same-frame path.

Same frame, the mask column of master column i depends on i alone (and the row on j):
two exact index vectors per robot, [W] and [H], decide every cell (`axis_cells`). Their
exact division costs a few hundred float32 operations per entry, so the fast path
brackets each entry with `geometry.centre_floor_bracket` (a dozen operations) and uses
the exact division only for a robot with an entry the bracket leaves open.

When both vectors are consecutive (k0 + i: the same resolution in practice, a float32
mask resolution against the costmap's double, or equal) the mask cells are one [H, W]
slice of the mask padded with unknown cells. `slice_test_one` decides that in O(1) per
robot: the exact mask column of master column i is floor(q(i)),
q(i) = (o + (i + 0.5) r - mo) / mr, affine in i with slope r / mr > 0. So
g(i) = q(i) - i is affine too, and if floor(q(a)) = k + a and floor(q(b)) = k + b, both
g(a) and g(b) lie in [k, k + 1), hence every g(i) between does, i.e. floor(q(i)) = k + i
for every i in [a, b]: the two end floors decide the whole run (and the converse is
trivial). Columns outside the update window [x0, x1) are never written, so the ends are
the window's first and last columns; and if the last one's q is < 0 (or the first one's
>= the mask's size) every column between is off the mask on that side, so the window
reads only padding. Same for rows.

`same_frame_prologue` runs the window clip and the slice test for the whole fleet.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from jaxfilters import geometry
from jaxfilters.keepout.common import rerun_as, rerun_capacity, robot_geometry
from jaxfilters.mask_lookup import mask_origin_terms
from jaxfilters.keepout.reference import same_frame_window

_F32 = jnp.float32


def axis_cells(shape, origin, res, mask_origin, mask_res, mshape):
  """The per-column and per-row mask cells, bracketed: (((mx, vx), (my, vy)), all_known).

  Entries are exact where `all_known` (bool []) is True; the caller falls back to
  `geometry.centres_to_cells_2d` (same integers) where it is False.
  """
  h, w = shape
  hm, wm = mshape
  n = max(h, w)
  i = jnp.arange(n, dtype=_F32)
  per_axis = lambda o: jnp.stack([jnp.full((n,), o[0], _F32), jnp.full((n,), o[1], _F32)])
  lo, hi = geometry.centre_floor_bracket(jnp.stack([i, i]), [per_axis(t) for t in geometry.as_terms(origin)],
                                         geometry.as_terms(res),
                                         [per_axis(t) for t in geometry.as_terms(mask_origin)], mask_res)
  size = jnp.asarray([[wm], [hm]], _F32)
  known = (lo == hi) | (hi < 0) | (lo >= size)          # an exact floor, or surely off the mask
  cells = jnp.clip(jnp.where(known, lo, 0.0), 0, size - 1).astype(jnp.int32)
  valid = (lo >= 0) & (lo < size)
  all_known = jnp.all(known[0, :w]) & jnp.all(known[1, :h])
  return ((cells[0, :w], valid[0, :w]), (cells[1, :h], valid[1, :h])), all_known


def exact_axis_cells(shape, origin, res, mask_origin, mask_res, mshape):
  """`geometry.centres_to_cells_2d` with `geometry.fixed_point_sign` (a fallback, so compile time counts more)."""
  return geometry.centres_to_cells_2d(shape, origin, res, mask_origin, mask_res, mshape,
                                      sign_fn=geometry.fixed_point_sign)


def _slice_start(k0, n, size):
  """Start of a window of n entries in an axis padded by n on each side (clipped: all padding)."""
  return jnp.clip(k0, -n, size) + n


def _window_bracket(shape_m, mask_origin, mask_res, origin, res, window):
  """`same_frame_window` from float32 estimates: (overlap, (x0, y0, x1, y1), known bool []).

  Each of the four worldToMapNoBounds quotients (w - o) / res, w = mask origin +
  (0 or size) mask_res + half a mask cell, is bracketed (`geometry.quotient_bracket`;
  the costmap resolution's lower parts enter the error as a relative term). The
  result equals `same_frame_window`'s where `known`: where the bracket's ends give
  the same overlap and clipped window.
  """
  hm, wm = shape_m
  four = lambda o: jnp.stack([o[0], o[1], o[0], o[1]])
  mo = [four(t) for t in geometry.as_terms(mask_origin)]
  o = [four(t) for t in geometry.as_terms(origin)]
  r = geometry.as_terms(res)
  u = 2.0 ** -24
  e = jnp.asarray([0.0, 0.0, wm, hm], _F32) * mask_res
  c1 = mo[0] + e
  c2 = c1 + 0.5 * mask_res
  c = c2 - o[0]
  err = u * (jnp.abs(e) + jnp.abs(c1) + jnp.abs(c2) + jnp.abs(c))
  for t in mo[1:] + o[1:]:
    err = err + jnp.abs(t)
  rel = sum((jnp.abs(t) for t in r[1:]), jnp.zeros((), _F32)) / r[0]
  err = err + 2.0 * rel * (jnp.abs(c) + err)
  lo, hi = geometry.quotient_bracket(c, err, r[0])
  ok = jnp.all(jnp.isfinite(lo) & jnp.isfinite(hi) & (jnp.abs(lo) < 2.0 ** 30) & (jnp.abs(hi) < 2.0 ** 30))
  ok = ok & (rel < 2.0 ** -8)
  glo = jnp.where(ok, jnp.trunc(lo), 0.0).astype(jnp.int32)
  ghi = jnp.where(ok, jnp.trunc(hi), 0.0).astype(jnp.int32)
  min_i, min_j, max_i, max_j = window[0], window[1], window[2], window[3]

  def clip(g0, g1):
    overlap = ~((g0[0] >= max_i) | (g0[1] >= max_j)) & ~((g1[2] <= min_i) | (g1[3] <= min_j))
    return overlap, (jnp.maximum(min_i, g0[0]), jnp.maximum(min_j, g0[1]),
                     jnp.minimum(max_i, g1[2]), jnp.minimum(max_j, g1[3]))

  # Every result is monotone in each quotient (the overlap falls with the lower corner
  # and rises with the upper one, the clipped bounds rise with theirs), so it is known
  # where the bracket's two ends give the same value, even if a quotient is not: a
  # window that lies inside the mask does not need the mask's corners exactly.
  overlap_lo, box_lo = clip(ghi, glo)
  overlap_hi, box_hi = clip(glo, ghi)
  same_box = jnp.all(jnp.stack(box_lo) == jnp.stack(box_hi))
  known = ok & (overlap_lo == overlap_hi) & (~overlap_hi | same_box)
  return overlap_hi, box_hi, known


def box_one(mshape, origin, res, mask_origin, mask_res, window, *, exact=False):
  """The window clip, bracketed or exact: (overlap bool [], (x0, y0, x1, y1) int32 [], known bool [])."""
  if exact:
    overlap, box = same_frame_window(mshape, mask_origin, mask_res, origin, res, window)
    return overlap, box, jnp.asarray(True)
  return _window_bracket(mshape, mask_origin, mask_res, origin, res, window)


def _slice_ends(shape, box):
  """Window end indices: (ends int32 [2 axes, 2] = [[a_x, b_x], [a_y, b_y]], empty bool [])."""
  h, w = shape
  x0, y0, x1, y1 = box
  a = jnp.stack([jnp.maximum(x0, 0), jnp.maximum(y0, 0)])
  b = jnp.stack([jnp.minimum(x1, w), jnp.minimum(y1, h)]) - 1
  return jnp.stack([a, b], axis=1), jnp.any(b < a)


def _slice_decision(ends, empty, lo, hi, known, size, n):
  """(start k0 int32 [2], sliced bool [], decided bool []) from end floors lo <= floor <= hi ([2, 2])."""
  off = (hi[:, 1] < 0) | (lo[:, 0] >= size)                   # whole run off the mask, one side
  both = known[:, 0] & known[:, 1]
  span = (ends[:, 1] - ends[:, 0]).astype(lo.dtype)
  consecutive = both & (lo[:, 1] - lo[:, 0] == span)
  axis_slice = off | consecutive
  axis_gather = both & ~off & ~consecutive
  axis_decided = axis_slice | axis_gather
  k0 = jnp.where(consecutive & ~off, lo[:, 0].astype(jnp.int32) - ends[:, 0], -n)
  sliced = empty | jnp.all(axis_slice)
  decided = empty | jnp.all(axis_decided) | jnp.any(axis_gather)
  return jnp.where(empty, -n, k0), sliced, decided


def slice_test_one(shape, origin, res, mask_origin, mask_res, mshape, box, *, exact=False):
  """Whether one robot's window reads its mask cells as one slice: (sx, sy, sliced, decided).

  `box` (x0, y0, x1, y1) int32 [] is the clipped update window (x1 <= x0 or y1 <= y0:
  nothing to write). The end floors are bracketed (`geometry.centre_floor_bracket`,
  decided where both ends of each axis are known or one axis is surely not
  consecutive) or `exact` (`geometry.floor_div_exact`, always decided).

  Returns:
    sx, sy int32 []: the window's start in the padded table (`_slice_start`; any
      all-padding start for a window that reads no mask cell); sliced bool []: the
      window's mask cells are that slice (same integers as the index vectors); decided
      bool []: `sliced` is proven (False: rerun exactly).
  """
  h, w = shape
  hm, wm = mshape
  n = jnp.asarray([w, h], jnp.int32)
  size = jnp.asarray([wm, hm], jnp.int32)
  ends, empty = _slice_ends(shape, box)
  col = lambda t: jnp.asarray(t, _F32)[:, None]
  o = [col(t) for t in geometry.as_terms(origin)]
  mo = [col(t) for t in geometry.as_terms(mask_origin)]
  idx = ends.astype(_F32)
  if exact:
    terms = geometry.cell_centre_terms(idx, o, res) + [-t for t in mo]
    cells = geometry.floor_div_exact(terms, mask_res, sign_fn=geometry.fixed_point_sign)
    negative = geometry.fixed_point_sign(terms) < 0
    # An exact floor is the floor for |quotient| < 2**22; beyond, its sign and side are still right.
    lo = jnp.where(negative, jnp.minimum(cells, -1), cells)
    k0, sliced, _ = _slice_decision(ends, empty, lo, lo, jnp.ones_like(negative), size, n)
    decided = jnp.asarray(True)
  else:
    lo, hi = geometry.centre_floor_bracket(idx, o, res, mo, mask_res)
    known = (lo == hi) & (jnp.abs(lo) < 2.0 ** 22)
    k0, sliced, decided = _slice_decision(ends, empty, lo, hi, known, size.astype(_F32), n)
  sx, sy = _slice_start(k0[0], w, wm), _slice_start(k0[1], h, hm)
  return sx, sy, sliced, decided


def same_frame_prologue(costmap, mask, idx, idx_ok, window, enabled, *, reruns=("cond", "cond"), flags=False):
  """The same-frame fast path's per-robot scalars, for the whole fleet.

  The window clip is bracketed (`_window_bracket`) and the slice test too
  (`slice_test_one`); the robots whose bracket is open redo that part exactly
  (`rerun`, inside one batch-level `lax.cond` taken only when there are any), so a
  fleet without such robots runs a few fused elementwise passes over [B] scalars and
  no loop.

  Args:
    costmap, mask: as keepout_filter; idx int32 [B], idx_ok bool [B] (mask index in range),
    window int32 [B, 4] (clipped to the costmap), enabled bool [B].

  Returns:
    box (x0, y0, x1, y1) int32 [B] each: the clipped update window, empty ((0, 0, 0, 0))
    where a robot does not run; run bool [B]; sx, sy int32 [B]: the window's start in
    the padded table; sliced bool [B]: the robot's mask cells are that slice.

  `reruns` (window clip, slice test): how the exact reruns run (`common.rerun_as`).
  With `flags` the bracketed results come back with no rerun, and with them
  box_known bool [B] and decided bool [B] (what `plan.make_plan` reads).
  """
  b, h, w = costmap.cost.shape
  hm, wm = mask.data.shape[1:]
  geo = robot_geometry(costmap, mask)
  geo_axes = tuple(None if g is None else 0 for g in geo)

  def batched(fn):
    def one(origin, origin_lo, res, res_lo, i, extra):
      o, r = geometry.origin_terms(origin, origin_lo), geometry.resolution_terms(res, res_lo)
      return fn(o, r, mask_origin_terms(mask, i), mask.resolution[i], extra)
    return lambda args: jax.vmap(one, in_axes=(*geo_axes, 0, 0))(*args)

  box_of = lambda exact: batched(lambda o, r, mo, mr, win: box_one((hm, wm), o, r, mo, mr, win,
                                                                               exact=exact))
  slice_of = lambda exact: batched(lambda o, r, mo, mr, bx: slice_test_one((h, w), o, r, mo, mr, (hm, wm), bx,
                                                                             exact=exact))
  # Robots left open redo that part exactly, `capacity` at a time (few in practice: centres
  # exactly on mask-cell edges, grids whose edges line up).
  capacity = rerun_capacity(b)
  args = (*geo, idx, window)
  overlap, box, box_known = box_of(False)(args)
  if not flags:
    overlap, box = rerun_as(reruns[0], ~box_known, (overlap, box), lambda a: box_of(True)(a)[:2], args, capacity)
  run = enabled & overlap & idx_ok
  box = tuple(jnp.where(run, c, 0) for c in box)      # a robot that does not run: an empty window
  args = (*geo, idx, box)
  sx, sy, sliced, decided = slice_of(False)(args)
  if flags:
    return box, run, sx, sy, sliced, box_known, decided
  sx, sy, sliced = rerun_as(reruns[1], ~decided, (sx, sy, sliced), lambda a: slice_of(True)(a)[:3], args,
                            capacity)
  return box, run, sx, sy, sliced


def index_vectors(costmap, mask, idx, *, need=None, rerun="cond", flags=False):
  """Every robot's exact index vectors ((mx, vx) int32/bool [B, W], (my, vy) [B, H]).

  Bracketed (`axis_cells`), with the exact division rerun (`common.rerun_as` with mode
  `rerun`) for the robots whose bracket left an entry open, of those where `need`
  (bool [B], default all: a robot that reads its cells as a slice does not need them).
  With `flags` the bracketed vectors come back with no rerun, and with them known bool
  [B] (the robot's bracket decided every entry).
  """
  b, h, w = costmap.cost.shape
  mshape = mask.data.shape[1:]
  geo = robot_geometry(costmap, mask)
  geo_axes = tuple(None if g is None else 0 for g in geo)

  def one(origin, origin_lo, res, res_lo, i, exact=False):
    o, r = geometry.origin_terms(origin, origin_lo), geometry.resolution_terms(res, res_lo)
    mo, mr = mask_origin_terms(mask, i), mask.resolution[i]
    if exact:
      return exact_axis_cells((h, w), o, r, mo, mr, mshape), jnp.asarray(True)
    return axis_cells((h, w), o, r, mo, mr, mshape)

  per_robot = lambda fn: jax.vmap(fn, in_axes=(*geo_axes, 0))
  cells, known = per_robot(one)(*geo, idx)
  if flags:
    return cells, known
  exact = lambda a: per_robot(functools.partial(one, exact=True))(*a)[0]
  open_ = ~known if need is None else ~known & need
  return rerun_as(rerun, open_, cells, exact, (*geo, idx), rerun_capacity(b))
