"""Zones as polygons and circles, rasterised into OccupancyGrid masks on the device.

Nav2's Vector Object server (`nav2_map_server/src/vo_server`, PR #5479) turns
polygons and circles into an OccupancyGrid that any costmap filter can use as
its mask. This module does the same on the device, for a fixed maximum number
of shapes, so zones can be moved, added or removed between steps without a
recompile (`Shapes.active`, `Shapes.order` and the geometry are traced leaves).

The rule matched (read from navigation2 at a3a97043, `vector_object_server.cpp`
`putVectorObjectsOnMap`, `vector_object_shapes.cpp`, `geometry_utils.hpp`):

* The map starts as `default_value` everywhere (-1, unknown, by default).
* A filled shape marks a cell when the cell's **centre**
  `origin + (m + 0.5) * resolution` is inside it. Nothing is area-weighted.
* Polygon: `isPointInsidePolygon`, the even-odd ray-crossing test (Shimrat
  1962) with a ray towards +x. Edge (i, j) is crossed when
  `(py <= y_i) == (py > y_j)` and `x_inter > px`, `x_inter` the edge's x at
  height py. At edges this gives a half-open rule: for an axis-aligned
  rectangle [x0, x1] x [y0, y1] a centre on the left (x = x0) or top
  (y = y1) edge is inside, one on the right (x = x1) or bottom (y = y0) edge
  is outside. A self-intersecting polygon is filled by the even-odd rule.
* Circle: `(px - cx)^2 + (py - cy)^2 <= r^2`: a centre on the circle is inside.
* Shapes are applied in their arrival order (`Shapes.order`), each cell with
  `processVal`: OVERLAY_SEQ (0, the default) writes the shape's value, so the
  last covering shape wins; OVERLAY_MAX (1) keeps the larger of map and shape
  value (-1 counts as -1); OVERLAY_MIN (2) keeps the smaller known value, a
  known value always replaces unknown (-1), and a -1 shape never writes.
* Vertices and centres are float32 (`geometry_msgs/Point32`), the radius is
  float32 (`CircleObject.radius`), the map resolution is float32
  (`MapMetaData.resolution`).

Nav2 evaluates these predicates in double. Here each one is decided exactly on
the real numbers the float32 inputs stand for (error-free products and sums,
the same approach as `jaxfilters.geometry`). This equals Nav2's double result
except where double rounding itself decides (a centre within ~1e-15 relative of
an edge without being on it); centres exactly on an edge or circle follow the
rule above.

Not matched, on purpose:

* The Vector Object server sizes its own map to the shapes' bounding box
  (origin = lower-left corner of the shapes). Here the grid is given (a
  FilterMask's origin, resolution and size): a shape that reaches past the grid
  marks only the cells on it.
* Unfilled shapes (`closed: false` polylines, `fill: false` circle outlines,
  drawn with Bresenham and Horn's circle generator) are not supported.
* Shapes in another frame (moved by TF every `update_frequency`): transform the
  vertices yourself; moving them never recompiles.

Exactness domain: every non-zero coordinate, radius, origin and resolution has
magnitude in [2**-32, 2**32] (2.3e-10 m to 4.3e6 km), the grid is below 2**21
cells per side. `Shapes.create` refuses shapes outside it; under `jit` a grid
or an active shape outside it (or non-finite, or with fewer than 3 vertices)
is not drawn and clears `RasterResult.valid`.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from jaxfilters import constants
from jaxfilters import geometry
from jaxfilters.geometry import exact_sign, floor_quotient, stack_terms
from jaxfilters.types import FilterMask, pytree_dataclass
from jaxfilters.validate import short_repr
# The zones drawn here (jaxfilters.vector_objects), importable from this module too.
from jaxfilters.vector_objects import (COORD_MAX, COORD_MIN, OVERLAY_MAX, OVERLAY_MIN, OVERLAY_SEQ,
                                       OVERLAY_TYPES, Circle, Polygon, Shapes, check_overlay_params,
                                       check_shapes)

_F32 = jnp.float32
MAX_CELLS = 2 ** 21             # grid rows or columns must be below this


@pytree_dataclass
class RasterResult:
  """A rasterised mask and whether it is exact.

  Attributes:
    data: int8 [..., H, W] OccupancyGrid values, row 0 the lowest y.
    valid: bool [...]; False when the grid geometry or an active shape was
      outside the exactness domain (such shapes are not drawn), non-finite,
      a polygon had a vertex count outside 3..V, or an exact decision did
      not converge (never seen for domain inputs).
  """
  data: jax.Array
  valid: jax.Array


# ----------------------------------------------------------------------------- exact predicates


def _in_domain(x):
  a = jnp.abs(x)
  return jnp.isfinite(x) & ((a == 0) | ((a >= COORD_MIN) & (a <= COORD_MAX)))


def _value_ok(v):
  v = v.astype(jnp.int32)
  return (v >= constants.OCC_GRID_UNKNOWN) & (v <= constants.OCC_GRID_OCCUPIED)


def _times(x, y):
  """Exact product of two term arrays [n, ...] and [m, ...]: [4 n m, ...] terms."""
  parts = geometry.exact_product(x[:, None], y[None, :])
  return jnp.stack(parts).reshape(4 * x.shape[0] * y.shape[0], *x.shape[1:])


def _square(x):
  """Exact square of a term array [n, ...]: [2 n (n + 1), ...] terms (cross terms doubled)."""
  i, j = np.triu_indices(x.shape[0])
  twice = np.where(i == j, 1.0, 2.0).astype(np.float32).reshape(-1, *([1] * (x.ndim - 1)))
  parts = geometry.exact_product(x[i] * twice, x[j])
  return jnp.stack(parts).reshape(4 * len(i), *x.shape[1:])


def _centre(index, origin, half_res):
  """float32 [5, *index.shape] terms summing exactly to origin + (index + 0.5) * res."""
  shape = index.shape
  return stack_terms(origin, jnp.stack(geometry.exact_product(2.0 * index.astype(_F32) + 1.0, half_res)),
                shape=shape)


def _first_true(pred, lo, hi, guess):
  """Smallest c in [lo, hi) with pred(c), for pred monotone F..F T..T there; hi if none.

  Every round probes two columns per lane: first `guess - 1` and `guess` (they
  settle the lane when the guess is within a cell, the usual case), then the
  thirds of the open interval, until every lane is settled. One loop body keeps
  the compiled program small (`pred` is traced once). `pred` takes int32
  [2, *lanes] columns and returns (bool, resolved) of that shape.

  Returns:
    (c int32 [*lanes], resolved bool [*lanes]).
  """
  def cond(st):
    lo, hi, _, it = st
    return jnp.any(lo < hi) & (it < 64)

  def body(st):
    lo, hi, ok, it = st
    live = lo < hi
    last = jnp.maximum(hi - 1, lo)
    third = (hi - lo) // 3
    a = jnp.where(it == 0, guess - 1, lo + third)
    b = jnp.where(it == 0, guess, hi - 1 - third)
    probes = jnp.stack([jnp.clip(a, lo, last), jnp.clip(b, lo, last)])
    t, res = pred(probes)
    for k in range(2):
      hi = jnp.where(live & t[k], jnp.minimum(hi, probes[k]), hi)
      lo = jnp.where(live & ~t[k], jnp.maximum(lo, probes[k] + 1), lo)
    return lo, hi, ok & (jnp.all(res, axis=0) | ~live), it + 1

  ok = jnp.ones(jnp.shape(lo), bool)
  lo, hi, ok, _ = lax.while_loop(cond, body, (lo, hi, ok, jnp.int32(0)))
  return lo, ok & (lo == hi)


def _guess(t, size):
  t = jnp.where(jnp.isfinite(t), t, 0.0)
  return jnp.clip(t, -1.0, size + 1.0).astype(jnp.int32)


# ----------------------------------------------------------------------------- polygons


def _polygon_cover(shapes: Shapes, origin, res, h: int, w: int):
  """bool [P, H, W] cells whose centre is inside each polygon (even-odd), and ok bool [P]."""
  verts = shapes.vertices
  p, v = verts.shape[:2]
  n = shapes.num_vertices
  k = jnp.arange(v, dtype=jnp.int32)
  used = k[None, :] < n[:, None]                                     # [P, V] vertex/edge used
  shape_ok = (shapes.polygon_active & (n >= 3) & (n <= v) & _value_ok(shapes.polygon_value)
              & jnp.all(jnp.where(used[..., None], _in_domain(verts), True), axis=(1, 2)))
  lane_ok = used & shape_ok[:, None]
  verts = jnp.where(lane_ok[..., None], verts, 0.0)                   # dead slots: exact zeros
  wraps = (k + 1)[None, :] >= n[:, None]                              # edge k closes to vertex 0
  nxt = jnp.where(wraps[..., None], verts[:, :1], jnp.roll(verts, -1, axis=1))
  xi, yi = verts[..., 0], verts[..., 1]
  xj, yj = nxt[..., 0], nxt[..., 1]
  ox, oy = origin[0], origin[1]
  hs = 0.5 * res

  # Rows r with py <= y_v are r <= R_v (exact floor); edge (i, j) is active on rows in
  # (min(R_i, R_j), max(R_i, R_j)], which is Nav2's (py <= y_i) == (py > y_j).
  row_cut, cut_ok = floor_quotient([verts[..., 1], -oy, -hs], res, -1, h)   # [P, V]
  row_cut_j = jnp.where(wraps, row_cut[:, :1], jnp.roll(row_cut, -1, axis=1))
  rows = jnp.arange(h, dtype=jnp.int32)
  r_lo = jnp.minimum(row_cut, row_cut_j)[..., None]
  r_hi = jnp.maximum(row_cut, row_cut_j)[..., None]
  active = lane_ok[..., None] & (rows[None, None] > r_lo) & (rows[None, None] <= r_hi)        # [P, V, H]

  shape3 = (p, v, h)
  b = lambda a: jnp.broadcast_to(a[..., None], shape3)
  xi3, yi3, xj3, yj3 = (jnp.where(active, b(a), 0.0) for a in (xi, yi, xj, yj))
  r3 = jnp.broadcast_to(rows, shape3)
  sign_b = jnp.sign(yj3 - yi3).astype(jnp.int32)
  # (py - y_i)(x_j - x_i) is the same for every column probe of a lane.
  ey_a = _times(stack_terms(_centre(r3, oy, hs), -yi3, shape=shape3), stack_terms(xj3, -xi3, shape=shape3))
  dy = stack_terms(yj3, -yi3, shape=shape3)[:, None]                      # [2, 1, P, V, H]

  def crossed_not(c):
    # c int32 [K, P, V, H]. x_inter > px  <=>
    # sign((x_i - px)(y_j - y_i) + (py - y_i)(x_j - x_i)) == sign(y_j - y_i).
    lanes = c.shape
    ex = stack_terms(xi3[None], -_centre(c, ox, hs), shape=lanes)
    terms = jnp.concatenate([_times(ex, jnp.broadcast_to(dy, (2, *lanes))),
                             jnp.broadcast_to(ey_a[:, None], (ey_a.shape[0], *lanes))])
    sign, resolved = exact_sign(terms.reshape(terms.shape[0], -1))
    crossed = sign.reshape(lanes) == sign_b[None]
    return ~crossed, resolved.reshape(lanes)

  py = oy + (r3.astype(_F32) + 0.5) * res
  ratio = (xj3 - xi3) / jnp.where(yj3 != yi3, yj3 - yi3, 1.0)
  guess = _guess(jnp.ceil((xi3 + (py - yi3) * ratio - ox) / res - 0.5), w)
  zero = jnp.zeros(shape3, jnp.int32)
  lo = zero
  hi = jnp.where(active, w, zero)
  bnd, ok = _first_true(crossed_not, lo, hi, guess)                   # columns c < bnd are crossed
  # Parity of the crossings right of each centre: count edges with c < bnd via a
  # scatter of +1 at bnd and a running sum along the row.
  pidx = jnp.broadcast_to(jnp.arange(p)[:, None, None], shape3)
  counts = jnp.zeros((p, h, w + 1), jnp.int32).at[pidx, r3, bnd].add(active.astype(jnp.int32))
  at_or_left = jnp.cumsum(counts, axis=-1)[..., :w]                   # edges with bnd <= c
  total = jnp.sum(active, axis=1).astype(jnp.int32)[..., None]        # [P, H, 1]
  inside = ((total - at_or_left) % 2) == 1
  ok_p = jnp.all(ok | ~active, axis=(1, 2)) & jnp.all(cut_ok | ~lane_ok, axis=1)
  drawn = shape_ok & ok_p
  return inside & drawn[:, None, None], ~shapes.polygon_active | drawn


# ----------------------------------------------------------------------------- circles


def _circle_cover(shapes: Shapes, origin, res, h: int, w: int):
  """bool [C, H, W] cells whose centre is inside each circle (boundary inclusive), ok [C]."""
  c = shapes.center.shape[0]
  shape_ok = (shapes.circle_active & jnp.all(_in_domain(shapes.center), axis=1) & _value_ok(shapes.circle_value)
              & _in_domain(shapes.radius) & (shapes.radius >= 0))
  cen = jnp.where(shape_ok[:, None], shapes.center, 0.0)
  rad = jnp.where(shape_ok, shapes.radius, 0.0)
  ox, oy = origin[0], origin[1]
  hs = 0.5 * res
  shape2 = (c, h)
  b = lambda a: jnp.broadcast_to(a[:, None], shape2)
  cx, cy, r = b(cen[:, 0]), b(cen[:, 1]), b(rad)
  rows = jnp.broadcast_to(jnp.arange(h, dtype=jnp.int32), shape2)
  live = b(shape_ok)
  cx, cy, r = (jnp.where(live, a, 0.0) for a in (cx, cy, r))
  dy2 = _square(stack_terms(_centre(rows, oy, hs), -cy, shape=shape2))   # [84, C, H]
  rr = jnp.stack(geometry.exact_product(r, r))                         # [4, C, H]
  fixed = jnp.concatenate([rr, -dy2])                                  # [88, C, H]

  def inside_at(col):
    # col int32 [..., C, H]: r^2 - (px - cx)^2 - (py - cy)^2 >= 0, exactly.
    lanes = col.shape
    dx2 = _square(stack_terms(_centre(col, ox, hs), -cx, shape=lanes))
    lead = (1,) * (len(lanes) - 2)
    fix = jnp.broadcast_to(fixed.reshape(fixed.shape[0], *lead, c, h), (fixed.shape[0], *lanes))
    terms = jnp.concatenate([fix, -dx2])
    sign, resolved = exact_sign(terms.reshape(terms.shape[0], -1))
    return sign.reshape(lanes) >= 0, resolved.reshape(lanes)

  # Columns with px <= cx: [0, m). Left of the centre "inside" grows with c, right of it shrinks.
  m, m_ok = floor_quotient([cx, -ox, -hs], res, -1, w - 1)
  m = m + 1                                                            # [C, H] in [0, w]
  m = jnp.where(live, m, 0)
  py = oy + (rows.astype(_F32) + 0.5) * res
  half = jnp.sqrt(jnp.maximum(r * r - (py - cy) ** 2, 0.0))
  # One search for both ends: lanes [2, C, H], side 0 finds the first inside column of
  # [0, m), side 1 the first outside column of [m, W) (pred flipped).
  zero = jnp.zeros(shape2, jnp.int32)
  lo = jnp.stack([zero, m])
  hi = jnp.stack([m, jnp.where(live, w, m)])
  guess = jnp.stack([_guess(jnp.ceil((cx - half - ox) / res - 0.5), w),
                     _guess(jnp.floor((cx + half - ox) / res - 0.5) + 1.0, w)])
  right_side = jnp.asarray([False, True]).reshape(1, 2, 1, 1)

  def pred(col):                                                       # col [2 probes, 2 sides, C, H]
    inside, resolved = inside_at(col)
    return inside != right_side, resolved

  ends, ok = _first_true(pred, lo, hi, guess)
  left, right = ends[0], ends[1]
  ok_l, ok_r = ok[0], ok[1]
  cols = jnp.arange(w, dtype=jnp.int32)
  inside = (cols[None, None] >= left[..., None]) & (cols[None, None] < right[..., None])
  ok_c = jnp.all((ok_l & ok_r & m_ok) | ~live, axis=1)
  drawn = shape_ok & ok_c
  return inside & drawn[:, None, None], ~shapes.circle_active | drawn


# ----------------------------------------------------------------------------- overlay


def _overlay(cover, value, order, default_value, overlay_type):
  """Combines cover bool [S, H, W], value int32 [S], order int32 [S] into int32 [H, W].

  All three of Nav2's overlay rules are cheap next to the cover, so they are all
  computed and `overlay_type` (traced) picks one: no recompile per setting.
  """
  bg = default_value
  h, w = cover.shape[1:]
  if cover.shape[0] == 0:
    return jnp.full((h, w), bg)
  v = value[:, None, None]
  # OVERLAY_SEQ: the last covering shape wins (largest order, ties by the later slot).
  top = jnp.max(jnp.where(cover, order[:, None, None], jnp.iinfo(jnp.int32).min), axis=0)
  slot = jnp.arange(cover.shape[0], dtype=jnp.int32)[:, None, None]
  last = jnp.max(jnp.where(cover & (order[:, None, None] == top[None]), slot, -1), axis=0)
  seq = jnp.where(last >= 0, value[jnp.maximum(last, 0)], bg)
  # OVERLAY_MAX: `if (shape_val > map_val) map_val = shape_val`, from the background.
  high = jnp.maximum(bg, jnp.max(jnp.where(cover, v, -128), axis=0))
  # OVERLAY_MIN: a known value replaces unknown, then the smaller known value wins.
  known = cover & (v != constants.OCC_GRID_UNKNOWN)
  low = jnp.min(jnp.where(known, v, 127), axis=0)
  merged = jnp.where(bg == constants.OCC_GRID_UNKNOWN, low, jnp.minimum(bg, low))
  low = jnp.where(jnp.any(known, axis=0), merged, bg)
  return jnp.where(overlay_type == OVERLAY_SEQ, seq, jnp.where(overlay_type == OVERLAY_MAX, high, low))


def rasterize_one(shapes: Shapes, origin, resolution, default_value=constants.OCC_GRID_UNKNOWN,
                  overlay_type=OVERLAY_SEQ, *, shape: tuple[int, int]) -> RasterResult:
  """Rasterises one set of shapes onto one grid (the per-grid kernel).

  Args:
    shapes: Shapes without a leading [M].
    origin: float32 [2] world (x, y) of the lower-left corner of cell (0, 0).
    resolution: float32 [] metres per cell.
    default_value: int [] background (-1..100).
    overlay_type: int [] OVERLAY_SEQ, OVERLAY_MAX or OVERLAY_MIN.
    shape: static (H, W).

  Returns:
    RasterResult with data int8 [H, W] and valid bool []. An out-of-range
    default_value or overlay_type gives data all -1 and valid False.
  """
  h, w = shape
  origin = jnp.asarray(origin, _F32)
  res = jnp.asarray(resolution, _F32)
  bg = jnp.asarray(default_value).astype(jnp.int32)
  overlay = jnp.asarray(overlay_type).astype(jnp.int32)
  params_ok = (bg >= -1) & (bg <= 100) & (overlay >= 0) & (overlay <= 2)
  grid_ok = jnp.all(_in_domain(origin)) & _in_domain(res) & (res > 0)
  # A bad grid still runs on safe numbers (its result is flagged), so no lane loops forever.
  origin = jnp.where(grid_ok, origin, 0.0)
  res = jnp.where(grid_ok, res, 1.0)
  pin, pok = _polygon_cover(shapes, origin, res, h, w)
  cin, cok = _circle_cover(shapes, origin, res, h, w)
  cover = jnp.concatenate([pin, cin], axis=0)
  value = jnp.concatenate([shapes.polygon_value, shapes.circle_value]).astype(jnp.int32)
  order = jnp.concatenate([shapes.polygon_order, shapes.circle_order]).astype(jnp.int32)
  data = jnp.where(params_ok, _overlay(cover, value, order, bg, overlay), constants.OCC_GRID_UNKNOWN)
  valid = params_ok & grid_ok & jnp.all(pok) & jnp.all(cok)
  return RasterResult(data.astype(jnp.int8), valid)


@functools.partial(jax.jit, static_argnames=("shape",))
def _rasterize(shapes, origin, resolution, default_value, overlay_type, *, shape):
  origin = jnp.asarray(origin)
  resolution = jnp.asarray(resolution)
  for name, a in (("origin", origin), ("resolution", resolution)):
    if not jnp.issubdtype(a.dtype, jnp.floating):
      raise ValueError(f"{name} must be floating point; got {a.dtype}")
  for name, a in (("default_value", default_value), ("overlay_type", overlay_type)):
    a = jnp.asarray(a)
    if a.shape != () or not jnp.issubdtype(a.dtype, jnp.integer):
      raise ValueError(f"{name} must be an integer scalar; got {a.dtype}{tuple(a.shape)}")
  origin, resolution = origin.astype(_F32), resolution.astype(_F32)
  if origin.shape == (2,) and resolution.shape == ():
    check_shapes(shapes, None)
    return rasterize_one(shapes, origin, resolution, default_value, overlay_type, shape=shape)
  if origin.ndim != 2 or origin.shape[1] != 2 or resolution.shape != origin.shape[:1]:
    raise ValueError(f"origin and resolution must be [2] and [] (one grid) or [M, 2] and [M]; "
                     f"got {tuple(origin.shape)} and {tuple(resolution.shape)}")
  m = origin.shape[0]
  if shapes.vertices.ndim == 4:
    check_shapes(shapes, m)
  else:
    # Shared shapes: broadcast (they are small) so stacks with and without per-grid
    # shapes run one program.
    check_shapes(shapes, None)
    shapes = jax.tree.map(lambda x: jnp.broadcast_to(x, (m, *x.shape)), shapes)
  kernel = functools.partial(rasterize_one, shape=shape)
  return jax.vmap(kernel, in_axes=(0, 0, 0, None, None))(shapes, origin, resolution, default_value,
                                                          overlay_type)


def rasterize(shapes: Shapes, origin, resolution, *, shape: tuple[int, int],
              default_value=constants.OCC_GRID_UNKNOWN, overlay_type=OVERLAY_SEQ) -> RasterResult:
  """Rasterises shapes onto one grid or a stack of M grids, on the device (jitted).

  Moving, adding (`active`) or removing shapes, changing the grid's origin and
  resolution, the background or the overlay rule never recompiles: only
  `shape` and the slot counts are static.

  Args:
    shapes: Shapes; leaves with a leading [M] give each grid its own shapes,
      without it the shapes are shared by every grid.
    origin: float32 [2] or [M, 2], lower-left corner of cell (0, 0) (metres).
    resolution: float32 [] or [M], metres per cell.
    shape: static (H, W) of each grid, each in [1, 2**21).
    default_value: int, the background, -1..100 (Vector Object server
      `default_value`, -1 unknown by default).
    overlay_type: int, OVERLAY_SEQ (0, default), OVERLAY_MAX (1) or
      OVERLAY_MIN (2) (server `overlay_type`).

  Returns:
    RasterResult: data int8 [H, W] or [M, H, W]; valid bool [] or [M]. A
    grid or an active shape outside the exactness domain, non-finite, with a
    vertex count outside 3..V or a value outside -1..100 is not drawn and
    clears `valid`; traced default_value / overlay_type out of range give all
    -1 and valid False.

  Raises:
    ValueError: a bad `shape`, mismatched batch sizes, Shapes leaves of the
      wrong shape or dtype, or (when given as plain numbers) default_value
      or overlay_type out of range.
    TypeError: shapes that are not a Shapes.
  """
  if (not isinstance(shape, tuple) or len(shape) != 2
      or not all(isinstance(s, (int, np.integer)) and not isinstance(s, bool) and 0 < s < MAX_CELLS
                 for s in shape)):
    raise ValueError(f"shape must be a tuple (H, W) of ints in [1, {MAX_CELLS}); got {short_repr(shape)}")
  if not isinstance(shapes, Shapes):
    raise TypeError(f"shapes must be a jaxfilters.shapes.Shapes (see Shapes.create); got {type(shapes).__name__}")
  if not isinstance(default_value, jax.core.Tracer) and not isinstance(overlay_type, jax.core.Tracer):
    check_overlay_params(_host_int(default_value, "default_value"), _host_int(overlay_type, "overlay_type"))
  with jax.named_scope("rasterize"):
    return _rasterize(shapes, origin, resolution, default_value, overlay_type,
                      shape=tuple(int(s) for s in shape))


def _host_int(v, name: str) -> int:
  a = np.asarray(v)
  if a.shape != () or a.dtype == bool or not np.issubdtype(a.dtype, np.integer):
    raise ValueError(f"{name} must be an integer scalar; got {short_repr(v)}")
  return int(a)


def rasterize_mask(shapes: Shapes, mask: FilterMask, *, default_value=constants.OCC_GRID_UNKNOWN,
                   overlay_type=OVERLAY_SEQ) -> tuple[FilterMask, jax.Array]:
  """A FilterMask whose data are the shapes rasterised on each mask's own grid.

  The mask's origin, resolution, size and FilterInfo are kept; only `data`
  changes, so filters that took the old mask do not recompile.

  Args:
    shapes: Shapes shared by the M masks, or with a leading [M].
    mask: FilterMask [M, H, W] giving the geometry and info.
    default_value, overlay_type: as `rasterize`.

  Returns:
    (FilterMask with data int8 [M, H, W], valid bool [M]).
  """
  if not isinstance(mask, FilterMask):
    raise TypeError(f"mask must be a FilterMask; got {type(mask).__name__}")
  shape = tuple(int(s) for s in mask.shape)
  if mask.num_masks == 1 and isinstance(shapes, Shapes) and shapes.vertices.ndim == 3:
    # One mask: the single-grid program (the same one plain `rasterize` calls use).
    out = rasterize(shapes, mask.origin[0], mask.resolution[0], shape=shape,
                    default_value=default_value, overlay_type=overlay_type)
    out = RasterResult(out.data[None], out.valid[None])
  else:
    out = rasterize(shapes, mask.origin, mask.resolution, shape=shape, default_value=default_value,
                    overlay_type=overlay_type)
  return dataclasses.replace(mask, data=out.data), out.valid


__all__ = ["COORD_MAX", "COORD_MIN", "MAX_CELLS", "OVERLAY_MAX", "OVERLAY_MIN", "OVERLAY_SEQ",
           "OVERLAY_TYPES", "Circle", "Polygon", "RasterResult", "Shapes", "check_overlay_params",
           "check_shapes", "rasterize", "rasterize_mask", "rasterize_one"]
