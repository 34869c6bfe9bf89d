"""Differentiable soft zones: signed distances to Shapes, a soft keepout cost, a soft speed limit.

The hard path (`jaxfilters.shapes.rasterize` into a FilterMask, then
`keepout_filter` / `speed_filter`) is exact and piecewise constant, so its
gradient with respect to a zone's geometry or limit is zero almost everywhere.
These functions are its smooth counterparts, for tuning zones with `jax.grad`:

* `signed_distance`: metres from each point to each shape's boundary,
  negative inside (polygon inside by the same even-odd rule as the
  rasteriser, evaluated in float32: the sign may differ from the hard
  rasteriser only where the distance is ~1e-6 m, where the value is ~0 anyway).
* membership `m = sigmoid((margin - sd) / width)`: 1 deep inside, 0 far
  outside, 1/2 on the boundary pushed out by `margin`.
* shapes are composited in the rasteriser's overlay order with the
  memberships as opacities (OVERLAY_SEQ: `v <- m v_k + (1 - m) v`, so the
  last covering shape wins as width -> 0; OVERLAY_MAX for keepout:
  `v <- v + m relu(v_k - v)`).

As width -> 0 the soft keepout cost at a point whose distance to every
boundary is much larger than `width` tends to the cost the hard keepout filter
writes at that point's cell over a free costmap, and the soft speed limit to
the hard SpeedFilter's limit (tests/jaxfilters/test_soft.py checks both at cell centres).
Differences from the hard path, by design: the soft functions read the zone at
the point itself (the hard path at the centre of its mask cell); a shape with
value -1 (unknown) is transparent (the hard SpeedFilter instead keeps its
previous limit on unknown cells); OVERLAY_MIN has no soft counterpart.

Widths, margins and points are traced; a traced width that is not finite and
> 0 gives NaN results (a concrete one raises ValueError). Points may be
anywhere: far points (2e19 m) get finite, correct results (distances are
scaled before squaring), a point with an infinite coordinate lies outside every
zone, and a point with a NaN coordinate gives NaN (no answer, visibly).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from jaxfilters.vector_objects import OVERLAY_MAX, OVERLAY_MIN, OVERLAY_SEQ, Shapes, check_shapes
from jaxfilters.types import FilterInfo
from jaxfilters.validate import float32_values, short_repr

_F32 = jnp.float32


def _safe_sqrt(x):
  """sqrt with a zero (not NaN) gradient at 0."""
  pos = x > 0
  return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


_FAR = 2.0 ** 60     # offsets beyond this are scaled down before squaring (float32 squares overflow at 1.8e19)
_FAR_SCALE = 2.0 ** 100   # their scale: a power of two whose reciprocal is a normal float32 (XLA flushes
                          # subnormals, so dividing by the offset itself could give 0)


def _scale_of(offset_max):
  """1 for ordinary offsets (results bit for bit unscaled), else 2**100 (no gradient).

  Offsets up to 3.4e38 (2**128) scale to at most 2**28, whose squares fit float32;
  offsets above 2**60 scale to at least 2**-40, whose squares stay normal.
  """
  return jax.lax.stop_gradient(jnp.where(offset_max > _FAR, jnp.float32(_FAR_SCALE), jnp.float32(1.0)))


def polygon_signed_distance_one(vertices, num_vertices, point):
  """Signed distance from one point to one polygon (negative inside, even-odd rule).

  Far points are handled without overflow: offsets above 2**60 m are scaled
  down before any product, so a point at x = 2e19 gets its true distance (about
  2e19), not an overflowed one. The inside test runs only for points inside the
  polygon's bounding box (a point outside it is outside the polygon), whose
  coordinates are as small as the vertices' and cannot overflow.

  Args:
    vertices: float32 [V, 2]; only the first `num_vertices` are used.
    num_vertices: int32 [] (>= 3 for a meaningful result).
    point: float32 [2].

  Returns:
    float32 [] metres; +inf for a point with an infinite coordinate (and none
    NaN): it lies outside every bounded shape; NaN for a point with a NaN
    coordinate (there is no answer: callers pass the NaN on).
  """
  v = vertices.shape[0]
  k = jnp.arange(v)
  used = k < num_vertices
  has_nan = jnp.any(jnp.isnan(point))
  infinite = ~has_nan & ~jnp.all(jnp.isfinite(point))
  point = jnp.where(jnp.isfinite(point), point, 0.0)
  a = vertices
  b = jnp.where(((k + 1) < num_vertices)[:, None], jnp.roll(vertices, -1, axis=0), vertices[:1])
  ab = b - a
  ap = point[None, :] - a
  scale = _scale_of(jnp.max(jnp.where(used[:, None], jnp.abs(ap), 0.0)))
  ap_s = ap / scale
  len2 = jnp.sum(ab * ab, axis=-1)
  dot = jnp.sum(ap_s * ab, axis=-1)                   # (ap . ab) / scale
  r = len2 / scale
  t = jnp.where(dot > 0, jnp.where(dot >= r, 1.0, dot / jnp.where(r > 0, r, 1.0)), 0.0)
  d = ap_s - t[:, None] * (ab / scale)
  d2 = jnp.where(used, jnp.sum(d * d, axis=-1), jnp.inf)
  dist = _safe_sqrt(jnp.min(d2)) * scale
  # Nav2's crossing test (isPointInsidePolygon), in float32, inside the bounding box only.
  px, py = point[0], point[1]
  lo = jnp.min(jnp.where(used[:, None], a, jnp.inf), axis=0)
  hi = jnp.max(jnp.where(used[:, None], a, -jnp.inf), axis=0)
  in_box = (px >= lo[0]) & (px <= hi[0]) & (py >= lo[1]) & (py <= hi[1])
  xi, yi, xj, yj = a[:, 0], a[:, 1], b[:, 0], b[:, 1]
  span = (py <= yi) == (py > yj)
  x_inter = xi + (py - yi) * (xj - xi) / jnp.where(yj != yi, yj - yi, 1.0)
  crossings = jnp.sum(used & span & (x_inter > px))
  sd = jnp.where(in_box & (crossings % 2 == 1), -dist, dist)
  return jnp.where(has_nan, jnp.nan, jnp.where(infinite, jnp.inf, sd))


def circle_signed_distance_one(center, radius, point):
  """Signed distance from one point to one circle: |p - c| - r (float32 []).

  Far points get their true distance (offsets above 2**60 m are scaled before
  squaring); +inf for a point with an infinite coordinate, NaN for a NaN one.
  """
  has_nan = jnp.any(jnp.isnan(point))
  infinite = ~has_nan & ~jnp.all(jnp.isfinite(point))
  d = jnp.where(jnp.isfinite(point), point, 0.0) - center
  scale = _scale_of(jnp.max(jnp.abs(d)))
  d = d / scale
  sd = _safe_sqrt(jnp.sum(d * d)) * scale - radius
  return jnp.where(has_nan, jnp.nan, jnp.where(infinite, jnp.inf, sd))


def signed_distance_one(shapes: Shapes, point):
  """float32 [P + C]: signed distance from one point to every slot (polygons, then circles).

  Inactive slots, polygons with fewer than 3 vertices and non-finite shapes give
  +inf with a zero gradient. A point with a NaN coordinate gives NaN for every
  slot; one with an infinite coordinate +inf (outside every shape).
  """
  n = shapes.num_vertices
  ok_p = (shapes.polygon_active & (n >= 3) & (n <= shapes.vertices.shape[1])
          & jnp.all(jnp.isfinite(shapes.vertices), axis=(1, 2)))
  verts = jnp.where(ok_p[:, None, None], shapes.vertices, 0.0)
  # Dead slots run on a safe triangle so their (discarded) gradients stay finite.
  tri = jnp.asarray([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], _F32)
  verts = jnp.where(ok_p[:, None, None], verts, jnp.zeros_like(verts).at[:, :3].set(tri))
  nv = jnp.where(ok_p, n, 3)
  sd_p = jax.vmap(polygon_signed_distance_one, in_axes=(0, 0, None))(verts, nv, point)
  ok_c = (shapes.circle_active & jnp.all(jnp.isfinite(shapes.center), axis=1) & jnp.isfinite(shapes.radius)
          & (shapes.radius >= 0))
  cen = jnp.where(ok_c[:, None], shapes.center, 0.0)
  rad = jnp.where(ok_c, shapes.radius, 1.0)
  sd_c = jax.vmap(circle_signed_distance_one, in_axes=(0, 0, None))(cen, rad, point)
  sd = jnp.concatenate([jnp.where(ok_p, sd_p, jnp.inf), jnp.where(ok_c, sd_c, jnp.inf)])
  return jnp.where(jnp.any(jnp.isnan(point)), jnp.nan, sd)


def _check_points(points):
  pts = jnp.asarray(points)
  if pts.ndim != 2 or pts.shape[1] != 2 or not jnp.issubdtype(pts.dtype, jnp.floating):
    raise ValueError(f"points must be float [N, 2] (x, y); got {pts.dtype}{tuple(pts.shape)}")
  return pts.astype(_F32)


def _check_width(width, margin):
  if not isinstance(width, jax.core.Tracer):
    w = float32_values(width, "width", owner="soft zones", positive=True)
    if w.shape != ():
      raise ValueError(f"soft zones: width must be a scalar (metres); got shape {w.shape}")
  if not isinstance(margin, jax.core.Tracer):
    m = float32_values(margin, "margin", owner="soft zones")
    if m.shape != ():
      raise ValueError(f"soft zones: margin must be a scalar (metres); got shape {m.shape}")


def _check_overlay(overlay_type, allowed):
  if isinstance(overlay_type, (bool, np.bool_)) or overlay_type not in allowed:
    names = {OVERLAY_SEQ: "0 sequential", OVERLAY_MAX: "1 max", OVERLAY_MIN: "2 min"}
    raise ValueError(f"overlay_type must be one of {[names[a] for a in allowed]} for this soft function "
                     f"(OVERLAY_MIN has no smooth counterpart); got {short_repr(overlay_type)}")


@jax.jit
def _signed_distance(shapes, points):
  return jax.vmap(signed_distance_one, in_axes=(None, 0))(shapes, points)


def signed_distance(shapes: Shapes, points) -> jax.Array:
  """Signed distance from points to every shape slot (jitted).

  Args:
    shapes: Shapes without a leading [M].
    points: float [N, 2] (x, y) metres.

  Returns:
    float32 [N, P + C] metres, polygons first then circles; negative inside;
    +inf (zero gradient) for inactive or malformed slots. Far points get their
    true (finite) distance; a point with an infinite coordinate gets +inf
    (outside every shape) and one with a NaN coordinate NaN in every column.

  Raises:
    ValueError: points not [N, 2] floats; Shapes leaves of the wrong shape.
  """
  check_shapes(shapes, None)
  return _signed_distance(shapes, _check_points(points))


def _membership(sd, width, margin):
  """Soft membership of signed distances: 0 for +inf (outside) and, by convention, for NaN."""
  m = jax.nn.sigmoid((margin - sd) / width)
  return jnp.where(jnp.isfinite(sd), m, 0.0)


def _nan_points(points, out):
  """NaN where a point has a NaN coordinate: no answer exists there, and it must not look like one."""
  return jnp.where(jnp.any(jnp.isnan(points), axis=-1), jnp.nan, out)


def _sorted_slots(shapes: Shapes):
  """Slot indices in overlay order (order, then slot: the rasteriser's tie rule)."""
  order = jnp.concatenate([shapes.polygon_order, shapes.circle_order]).astype(jnp.int32)
  slot = jnp.arange(order.shape[0], dtype=jnp.int32)
  return jnp.lexsort((slot, order))


def _composite(m, values, background, perm, overlay_type: int):
  """Soft overlay of values [S] with memberships m [S] over a background, in order `perm`."""
  out = background
  for i in range(values.shape[0]):
    k = perm[i]
    mk, vk = m[k], values[k]
    if overlay_type == OVERLAY_SEQ:
      out = mk * vk + (1.0 - mk) * out
    else:
      out = out + mk * jax.nn.relu(vk - out)
  return out


def _cost_of(value):
  """Nav2 mask cost round-half-away(2.54 d) as float32 (docs/nav2_semantics.md §1.4); -1..100 only."""
  d = value.astype(jnp.int32)
  return ((d * 254 + 50) // 100).astype(_F32)


@functools.partial(jax.jit, static_argnames=("overlay_type",))
def _keepout_cost(shapes, points, width, margin, default_value, overlay_type):
  values = jnp.concatenate([shapes.polygon_value, shapes.circle_value]).astype(jnp.int32)
  known = values >= 0
  # SEQ: an unknown (-1) shape makes the keepout filter skip the cell (cost 0 over a free
  # map); MAX: -1 never wins, so it is transparent.
  cost = jnp.where(known, _cost_of(jnp.maximum(values, 0)), 0.0)
  bg = jnp.where(default_value >= 0, _cost_of(jnp.maximum(default_value, 0)), 0.0)
  perm = _sorted_slots(shapes)

  def one(point):
    m = _membership(signed_distance_one(shapes, point), width, margin)
    if overlay_type == OVERLAY_MAX:
      m = jnp.where(known, m, 0.0)
    return _composite(m, cost, bg, perm, overlay_type)

  out = _nan_points(points, jax.vmap(one)(points))
  return jnp.where((width > 0) & jnp.isfinite(width), out, jnp.nan)


def soft_keepout_cost(shapes: Shapes, points, *, width, margin=0.0,
                      default_value=constants.OCC_GRID_UNKNOWN, overlay_type: int = OVERLAY_SEQ) -> jax.Array:
  """Smooth keepout cost at points: the zones' Nav2 costs blended by soft membership.

  Each shape of value d in 0..100 contributes its keepout cost round(2.54 d)
  (254 for 100) with opacity sigmoid((margin - sd) / width); shapes are
  composited in overlay order over the background's cost. A positive margin
  grows every zone by `margin` metres (a safety margin around keepouts).

  Args:
    shapes: Shapes (no leading [M]).
    points: float [N, 2] metres.
    width: metres, > 0: the blend's length scale (-> 0: the hard cost).
    margin: metres the zones are grown by (may be negative).
    default_value: the raster background, -1 (no cost) or 0..100.
    overlay_type: static, OVERLAY_SEQ or OVERLAY_MAX (as rasterised).

  Returns:
    float32 [N], Nav2 cost units in [0, 254]: what the keepout filter would
    write over a free (0) costmap as width -> 0. Far points and points with
    an infinite coordinate lie outside every zone (the background's cost,
    0 by default). NaN for a point with a NaN coordinate and for a traced
    width that is not finite and > 0.

  Raises:
    ValueError: bad points, width <= 0, OVERLAY_MIN, default_value out of range.
  """
  _check_overlay(overlay_type, (OVERLAY_SEQ, OVERLAY_MAX))
  _check_width(width, margin)
  check_shapes(shapes, None)
  if not isinstance(default_value, jax.core.Tracer) and not (
      isinstance(default_value, (int, np.integer)) and -1 <= int(default_value) <= 100):
    raise ValueError(f"default_value must be an integer in -1..100; got {short_repr(default_value)}")
  return _keepout_cost(shapes, _check_points(points), jnp.asarray(width, _F32), jnp.asarray(margin, _F32),
                       jnp.asarray(default_value, jnp.int32), overlay_type=int(overlay_type))


def zone_speed_limits(shapes: Shapes, info: FilterInfo, no_limit) -> jax.Array:
  """Each slot's speed limit by Nav2's SpeedFilter rule, "no limit" replaced by `no_limit`.

  Limit = d * multiplier + base for the slot's value d; d == 0, a limit of 0,
  a percent limit outside [0, 100] or an absolute limit < 0 mean no limit
  (docs/nav2_semantics.md §5). Slots of value -1 get NaN (they are transparent in the blend).

  Args:
    shapes: Shapes (no leading [M]).
    info: FilterInfo with scalar leaves, type 1 (percent) or 2 (m/s).
    no_limit: float, the value standing for "no limit" (100 for percent, the
      robot's max speed for m/s).

  Returns:
    float32 [P + C] in the filter's unit.
  """
  values = jnp.concatenate([shapes.polygon_value, shapes.circle_value]).astype(jnp.int32)
  return _limits_of(values, info, jnp.asarray(no_limit, _F32))


def _limits_of(d, info, no_limit):
  raw = d.astype(_F32) * info.multiplier + info.base
  percent = info.type == constants.SPEED_FILTER_PERCENT
  none = (d == constants.SPEED_MASK_NO_LIMIT) | (raw <= 0.0) | (percent & (raw > 100.0))
  return jnp.where(d == constants.SPEED_MASK_UNKNOWN, jnp.nan, jnp.where(none, no_limit, raw))


@jax.jit
def _speed_limit(shapes, info, points, width, margin, no_limit, default_value, limits):
  values = jnp.concatenate([shapes.polygon_value, shapes.circle_value]).astype(jnp.int32)
  known = values != constants.SPEED_MASK_UNKNOWN
  lim = jnp.where(known, limits, no_limit)
  bg = _limits_of(default_value, info, no_limit)
  bg = jnp.where(jnp.isnan(bg), no_limit, bg)
  perm = _sorted_slots(shapes)

  def one(point):
    m = jnp.where(known, _membership(signed_distance_one(shapes, point), width, margin), 0.0)
    return _composite(m, lim, bg, perm, OVERLAY_SEQ)

  out = _nan_points(points, jax.vmap(one)(points))
  return jnp.where((width > 0) & jnp.isfinite(width), out, jnp.nan)


def soft_speed_limit(shapes: Shapes, info: FilterInfo, points, *, width, no_limit, margin=0.0,
                     default_value=constants.SPEED_MASK_NO_LIMIT, limits=None) -> jax.Array:
  """Smooth speed limit at points: zone limits blended by soft membership (OVERLAY_SEQ).

  Args:
    shapes: Shapes (no leading [M]) of a speed mask.
    info: FilterInfo (scalar leaves), type 1 (percent) or 2 (m/s), with the
      mask's base and multiplier.
    points: float [N, 2] metres.
    width: metres, > 0.
    no_limit: what "no limit" blends as: 100 for percent, the robot's top
      speed for m/s.
    margin: metres the zones are grown by.
    default_value: the raster background (0: no limit, the usual speed-mask
      choice; -1 is treated as no limit here).
    limits: optional float [P + C] per-slot limits in the filter's unit,
      replacing the value-derived ones (differentiable: tune a zone's limit
      with it; `zone_speed_limits` gives the value-derived defaults).

  Returns:
    float32 [N] in the filter's unit (percent or m/s); tends to the hard
    SpeedFilter limit (its 0.0 "no limit" read as `no_limit`) as width -> 0.
    Far points and points with an infinite coordinate lie outside every zone
    (the background's limit). NaN for a point with a NaN coordinate and for
    a traced width that is not finite and > 0.

  Raises:
    ValueError: bad points, width <= 0, info type not 1 or 2, limits of the
      wrong shape, default_value out of range.
  """
  _check_width(width, margin)
  check_shapes(shapes, None)
  if not isinstance(info, FilterInfo):
    raise ValueError(f"info must be a FilterInfo; got {type(info).__name__}")
  if not isinstance(info.type, jax.core.Tracer) and int(info.type) not in (
      constants.SPEED_FILTER_PERCENT, constants.SPEED_FILTER_ABSOLUTE):
    raise ValueError(f"info.type must be 1 (speed %) or 2 (speed m/s); got {int(info.type)}")
  if not isinstance(default_value, jax.core.Tracer) and not (
      isinstance(default_value, (int, np.integer)) and -1 <= int(default_value) <= 100):
    raise ValueError(f"default_value must be an integer in -1..100; got {short_repr(default_value)}")
  if not isinstance(no_limit, jax.core.Tracer):
    float32_values(no_limit, "no_limit", owner="soft_speed_limit", positive=True)
  s = shapes.max_polygons + shapes.max_circles
  if limits is None:
    limits = zone_speed_limits(shapes, info, no_limit)
  limits = jnp.asarray(limits)
  if limits.shape != (s,) or not jnp.issubdtype(limits.dtype, jnp.floating):
    raise ValueError(f"limits must be float [P + C] = ({s},); got {limits.dtype}{tuple(limits.shape)}")
  return _speed_limit(shapes, info, _check_points(points), jnp.asarray(width, _F32), jnp.asarray(margin, _F32),
                      jnp.asarray(no_limit, _F32), jnp.asarray(default_value, jnp.int32), limits.astype(_F32))
