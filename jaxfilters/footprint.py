"""Footprint-aware robot-in-zone test for the keepout filter's escape mode (beyond Nav2).

Nav2's escape mode (`override_lethal_cost`, docs/nav2_semantics.md §4.2) is on while the robot's
*centre* is on a lethal keepout cell. Issue #6505 (open) calls it unusable: half
the footprint can stand in a zone without switching it on, and once the centre
leaves, the zone is lethal again and, inflated as a layer, holds the robot in
its inscribed band. PR #6526 (open) tests the footprint instead. This module is
that test, as an option (`KeepoutConfig(robot_in_zone="footprint")`); Nav2's
centre test stays the default.

The rule:

* The footprint F is a closed set in the robot frame (x forward, y left,
  metres): a polygon (its even-odd interior and its boundary), or the disc of
  radius r (`robot_radius`; Nav2's 16-gon for a radius lies inside it). F grown
  by m >= 0 is every point within distance m of F.
* A mask cell is *covered* at pose (x, y, yaw), given in the mask frame, when
  its centre c = origin + (index + 0.5) * resolution, taken into the robot frame
  q = R(-yaw) (c - (x, y)), lies in F grown by m: the cell-centre rule the
  Vector Object server uses to draw zones (jaxfilters.shapes), applied to the
  footprint. Cells off the mask are never covered.
* The robot is in a zone when Nav2's centre test says so (so this test is never
  weaker than Nav2's, even for a footprint smaller than a cell), or a covered
  cell is lethal: mask cost 253 or 254 (data 100). Unknown and graded cells are
  not lethal, as in Nav2.
* Hysteresis: m = 0 while the robot was not in a zone the cycle before, and
  `escape_clearance` while it was. Escape switches on when the footprint covers
  a zone cell and stays on until the footprint grown by the clearance is clear;
  `band_clearance` gives the clearance after which the robot's centre cell is
  outside the zone's inscribed band once the zone is lethal (and inflated) again.

Precision: the centre, its offset from the pose and the rotation are float32
(products rounded on their own, `geometry.rounded_product`, so XLA's FMA fusion
cannot move them), then the polygon and distance predicates run in float32. A
cell centre within about 1e-6 m (relative to the coordinates' magnitude) of the
boundary of F grown by m can be decided either way; with dyadic numbers (e.g. a
0.25 m grid and yaw 0) every step is exact and the rule holds on the boundary.

Static sizes: the test reads a (2n + 1) x (2n + 1) window of mask cells around
the robot, n = ceil((R + clearance) / min_mask_resolution) + 2, R the largest
distance of F from the robot origin. A mask finer than `min_mask_resolution`
would need a larger window: eager calls raise, and under `jit` the robot's
`KeepoutState.error` is set (the window it read is still tested).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from jaxfilters import geometry
from jaxfilters.inflation import footprint_radii
from jaxfilters.validate import float32_values, resolution_value, short_repr

_F32 = jnp.float32
ROBOT_IN_ZONE = ("center", "footprint")
MAX_WINDOW = 64          # window half-size n in mask cells: (2n + 1)^2 cells per robot per cycle


def _polygon(footprint, owner: str) -> tuple[tuple[float, float], ...]:
  try:
    pts = np.asarray(footprint, dtype=object)
  except Exception:  # noqa: BLE001
    pts = None
  if pts is None or pts.ndim != 2 or pts.shape[1] != 2:
    raise ValueError(f"{owner}: footprint must be a sequence of (x, y) vertices in metres, e.g. "
                     f"((0.3, 0.2), (-0.3, 0.2), (-0.3, -0.2), (0.3, -0.2)); got {short_repr(footprint)}")
  if pts.shape[0] < 3:
    raise ValueError(f"{owner}: footprint needs at least 3 vertices; got {pts.shape[0]}")
  v = float32_values(pts.astype(np.float64), "footprint", owner=owner)
  x, y = v[:, 0].astype(np.float64), v[:, 1].astype(np.float64)
  area = 0.5 * abs(float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)))
  if area == 0.0:
    raise ValueError(f"{owner}: footprint must enclose an area (its vertices are collinear or "
                     f"repeated); got {short_repr(footprint)}")
  return tuple((float(a), float(b)) for a, b in v)


def check_options(robot_in_zone, footprint, robot_radius, min_mask_resolution, escape_clearance,
                  override_lethal_cost, owner: str = "KeepoutConfig") -> dict:
  """Validates the footprint options of a KeepoutConfig on the host (float32 terms).

  Returns:
    dict of normalised values (tuples of Python floats, floats) for the fields.

  Raises:
    ValueError: an unknown mode; footprint options given in 'center' mode;
      'footprint' mode without escape mode, without exactly one of footprint /
      robot_radius, or without min_mask_resolution; a value that is not finite
      in float32, a radius or resolution <= 0, a negative clearance, a polygon
      with fewer than 3 vertices or no area, or a window above MAX_WINDOW cells.
  """
  if robot_in_zone not in ROBOT_IN_ZONE:
    raise ValueError(f"{owner}.robot_in_zone must be one of {ROBOT_IN_ZONE}; got {short_repr(robot_in_zone)}")
  given = {n: v for n, v in (("footprint", footprint), ("robot_radius", robot_radius),
                             ("min_mask_resolution", min_mask_resolution)) if v is not None}
  if robot_in_zone == "center":
    if given or escape_clearance != 0:
      names = ", ".join(list(given) + (["escape_clearance"] if escape_clearance != 0 else []))
      raise ValueError(f"{owner}: {names} only apply with robot_in_zone='footprint'; got "
                       f"robot_in_zone='center' (Nav2's centre-cell test)")
    return dict(footprint=None, robot_radius=None, min_mask_resolution=None, escape_clearance=0.0)
  if not override_lethal_cost:
    raise ValueError(f"{owner}: robot_in_zone='footprint' decides Nav2's escape mode; set "
                     f"override_lethal_cost=True (got False, so the test would never be used)")
  if (footprint is None) == (robot_radius is None):
    raise ValueError(f"{owner}: robot_in_zone='footprint' needs exactly one of footprint (polygon) or "
                     f"robot_radius (disc); got footprint={short_repr(footprint)}, "
                     f"robot_radius={short_repr(robot_radius)}")
  if min_mask_resolution is None:
    raise ValueError(f"{owner}: robot_in_zone='footprint' needs min_mask_resolution (m), the finest mask "
                     "resolution it will meet: it sizes the static window of mask cells the test reads")
  if isinstance(escape_clearance, (bool, np.bool_)):
    raise ValueError(f"{owner}.escape_clearance must be a number of metres >= 0; got {escape_clearance!r}")
  poly = None if footprint is None else _polygon(footprint, owner)
  radius = None
  if robot_radius is not None:
    if isinstance(robot_radius, (bool, np.bool_)):
      raise ValueError(f"{owner}.robot_radius must be a number of metres > 0; got {robot_radius!r}")
    radius = float(float32_values(robot_radius, "robot_radius", owner=owner, positive=True))
  res = float(resolution_value(min_mask_resolution, owner=owner, name="min_mask_resolution"))
  clear = float(float32_values(escape_clearance, "escape_clearance", owner=owner, nonnegative=True))
  n = window_cells(poly, radius, clear, res)
  if n > MAX_WINDOW:
    raise ValueError(f"{owner}: the footprint grown by escape_clearance spans n = {n} mask cells from the "
                     f"robot at min_mask_resolution {res:g} m; at most {MAX_WINDOW} (a coarser "
                     "min_mask_resolution or a smaller footprint)")
  return dict(footprint=poly, robot_radius=radius, min_mask_resolution=res, escape_clearance=clear)


def reach(polygon, radius) -> float:
  """R: the largest distance (m) of the footprint from the robot origin."""
  if radius is not None:
    return float(radius)
  return max(math.hypot(x, y) for x, y in polygon)


def window_cells(polygon, radius, clearance: float, min_mask_resolution: float) -> int:
  """n, the window half-size in mask cells: ceil((R + clearance) / min_mask_resolution) + 2.

  The + 2 covers the float32 anchor cell (off by at most one near a cell edge)
  and the half cell between a centre and its cell's edge.
  """
  return int(math.ceil((reach(polygon, radius) + clearance) / min_mask_resolution)) + 2


def band_clearance(*, inscribed_radius: float, resolution: float, robot_radius: float | None = None,
                   footprint: Sequence[Sequence[float]] | None = None) -> float:
  """The smallest `escape_clearance` after which the robot is out of the zone's inscribed band.

  When escape ends, the zone is lethal again and (run as a layer before
  inflation) its cells within `inscribed_radius` of a cell centre become 253,
  which Nav2's controllers treat as a collision for the robot centre (issue
  #6505: "stuck in the inflated lethal part"). With the returned clearance m,
  escape lasts until every lethal cell centre is farther than (footprint's own
  inscribed radius + m) from the robot, so the robot's centre cell (within
  resolution / sqrt 2 of it) is farther than `inscribed_radius` from each.

  Args:
    inscribed_radius: m, the inflation layer's (`InflationConfig.inscribed_radius`).
    resolution: m per costmap cell.
    robot_radius / footprint: the footprint of the KeepoutConfig (exactly one).

  Returns:
    metres, >= 0 (with 1 mm added for float32 rounding).

  Raises:
    ValueError: as `footprint_radii`, or a polygon that does not contain the
      robot origin (its inscribed radius then bounds nothing).
  """
  own, _ = footprint_radii(robot_radius=robot_radius, footprint=footprint, footprint_padding=0.0)
  if footprint is not None and not _contains_origin(footprint):
    raise ValueError(f"band_clearance: the footprint must contain the robot origin (0, 0) strictly inside; "
                     f"got {short_repr(footprint)}")
  if robot_radius is not None:
    own = float(robot_radius)          # the disc itself, not Nav2's 16-gon
  return max(0.0, float(inscribed_radius) - own) + float(resolution) * math.sqrt(0.5) + 1e-3


def _contains_origin(footprint) -> bool:
  """(0, 0) strictly inside the polygon (even-odd, float64) and not on an edge."""
  pts = [(float(x), float(y)) for x, y in footprint]
  inside = False
  for k, (ax, ay) in enumerate(pts):
    bx, by = pts[(k + 1) % len(pts)]
    if ax * by - ay * bx == 0 and min(ax, bx) <= 0 <= max(ax, bx) and min(ay, by) <= 0 <= max(ay, by):
      return False
    if (ay > 0) != (by > 0) and 0 < ax - ay * (bx - ax) / (by - ay):
      inside = not inside
  return inside


def _covered(qx, qy, dx, dy, polygon, radius, margin):
  """bool [...]: q = (qx, qy) in the footprint grown by margin (float32, see the module rule)."""
  mul = geometry.rounded_product
  if radius is not None:
    rr = jnp.asarray(radius, _F32) + margin
    return mul(dx, dx) + mul(dy, dy) <= mul(rr, rr)
  v = np.asarray(polygon, np.float32)
  inside = jnp.zeros(qx.shape, bool)
  on_edge = jnp.zeros(qx.shape, bool)
  dist2 = jnp.full(qx.shape, jnp.inf, _F32)
  for k in range(v.shape[0]):
    ax, ay = v[k]
    bx, by = v[(k + 1) % v.shape[0]]
    ex, ey = np.float32(bx - ax), np.float32(by - ay)     # float32 differences, as the device forms them
    px, py = qx - ax, qy - ay
    t = mul(px, ey) - mul(py, ex)                          # cross(q - a, b - a); x_inter > qx <=> t * ey < 0
    straddle = (ay > qy) != (by > qy)
    inside = inside ^ (straddle & (t != 0) & ((t < 0) == (ey > 0)))
    on_edge = on_edge | ((t == 0) & (qx >= min(ax, bx)) & (qx <= max(ax, bx))
                         & (qy >= min(ay, by)) & (qy <= max(ay, by)))
    len2 = float(np.float32(ex * ex + ey * ey))
    u = jnp.clip((mul(px, ex) + mul(py, ey)) / np.float32(len2), 0.0, 1.0)
    rx, ry = px - mul(u, ex), py - mul(u, ey)
    dist2 = jnp.minimum(dist2, mul(rx, rx) + mul(ry, ry))
  return inside | on_edge | ((margin > 0) & (dist2 <= mul(margin, margin)))


def footprint_in_zone_one(data, mask_origin, mask_res, pose, *, polygon=None, radius=None, window: int,
                          margin=0.0, mask_origin_lo=None):
  """Whether the footprint at `pose` covers a lethal mask cell (the rule in the module docstring).

  The centre test is not included (the caller ORs Nav2's `pose_in_lethal_zone_one`).

  Args:
    data: int8 [Hm, Wm] the keepout mask.
    mask_origin: float32 [2]; mask_res: float32 [].
    pose: float32 [3] (x, y, yaw) in the mask frame.
    polygon: static tuple of (x, y) vertices (robot frame, m), or None.
    radius: static disc radius (m), or None (exactly one of polygon / radius).
    window: static n, the window half-size in mask cells (`window_cells`).
    margin: float32 [] growth of the footprint (m, >= 0; traced).
    mask_origin_lo: optional float32 [2, 2] parts of a float64 mask origin.

  Returns:
    bool []: a covered cell has mask cost 253 or 254. False for a non-finite
    pose or a footprint wholly off the mask.
  """
  hm, wm = data.shape
  n = window
  o = jnp.asarray(mask_origin, _F32)
  if mask_origin_lo is not None:
    lo = jnp.asarray(mask_origin_lo, _F32)
    o = o + (lo[:, 0] + lo[:, 1])
  res = jnp.asarray(mask_res, _F32)
  pose = jnp.asarray(pose, _F32)
  x, y = pose[0], pose[1]
  # The anchor only places the window; any cell it could miss is > n - 2 cells away.
  af = jnp.floor(jnp.stack([(x - o[0]) / res, (y - o[1]) / res]))
  size = jnp.asarray([wm, hm], _F32)
  near = jnp.all(jnp.isfinite(af) & (af > -n - 2) & (af < size + n + 2)) & jnp.isfinite(pose[2])
  anchor = jnp.where(near, af, -(n + 8.0)).astype(jnp.int32)
  off = jnp.arange(-n, n + 1, dtype=jnp.int32)
  col = anchor[0] + off                                                  # [2n+1]
  row = anchor[1] + off
  cx = o[0] + geometry.rounded_product(col.astype(_F32) + 0.5, res)
  cy = o[1] + geometry.rounded_product(row.astype(_F32) + 0.5, res)
  dx = jnp.broadcast_to((cx - x)[None, :], (2 * n + 1, 2 * n + 1))       # [rows, cols]
  dy = jnp.broadcast_to((cy - y)[:, None], (2 * n + 1, 2 * n + 1))
  margin = jnp.asarray(margin, _F32)
  if polygon is not None:
    c, s = jnp.cos(pose[2]), jnp.sin(pose[2])
    mul = geometry.rounded_product
    qx, qy = mul(c, dx) + mul(s, dy), mul(c, dy) - mul(s, dx)
  else:
    qx = qy = None
  cover = _covered(qx, qy, dx, dy, polygon, radius, margin)
  on_mask = (((col >= 0) & (col < wm))[None, :] & ((row >= 0) & (row < hm))[:, None])
  d = data[jnp.clip(row, 0, hm - 1)[:, None], jnp.clip(col, 0, wm - 1)[None, :]]
  lethal = d == constants.OCC_GRID_OCCUPIED        # occ_to_cost(d) in {253, 254} <=> d == 100 (docs/nav2_semantics.md §1.4)
  return near & jnp.any(cover & on_mask & lethal)


def window_fits(mask_res, min_mask_resolution: float):
  """bool []: this mask's resolution is at least the config's (the window covers the footprint)."""
  return jnp.asarray(mask_res, _F32) >= np.float32(min_mask_resolution)
