"""AsymmetricInflationLayer: Nav2's lane-keeping inflation (docs/nav2_semantics.md §9.6), batched.

Nav2's `nav2_costmap_2d::AsymmetricInflationLayer` (Nav2 PR #6118,
`plugins/asymmetric_inflation_layer.cpp`) is an InflationLayer whose `updateCosts`
runs two passes over the master costmap:

1. the plain InflationLayer pass (`inflation.inflate_one`) with
   cost_scaling_factor = max(left, right);
2. when the robot's path gives segments near the map and the two factors differ: the
   obstacle cells on the map's boundary with free space (cost 254, plus 255 with
   `inflate_around_unknown`, on the map edge or with a 4-neighbour that is not an
   obstacle) that lie on the path's disfavoured side (the side with the smaller
   factor) are seeds of a second distance transform, whose costs, with
   min(left, right), raise cells (`new > old`, unknown cells never).

A cell's side comes from the nearest path segment whose box, padded by the inflation
radius, holds the cell centre (the first such segment on ties): Neutral beyond the
inflation radius (`dist^2 > r^2`) or on the segment's line, else the sign of the
cross product. Segments are culled against the map padded by the radius; a robot
within `goal_distance_threshold` of the path's last point gets no segments. That
geometry is Nav2's float64 arithmetic, reproduced here in float64 on the device
(`jax.enable_x64` scoped to it, so a caller's program stays float32): the cell
centre `origin + (i + 0.5) * resolution` with the costmap's exact float64 origin and
resolution (`Costmap.origin_lo`, `resolution_lo`), the float32 path points and robot
position upcast exactly. The distance transforms and cost tables are
`jaxfilters.inflation`'s, exact integers.

Each robot runs one `updateCosts` over its whole map (the update window and the ROI
padded by the radius are then the whole map), with its own path. The side of a cell is
found segment by segment; a short segment (a plan's poses about a cell apart) updates only
the window of cells its padded box can hold, a long one the whole map (`_sides`).

`asymmetric_inflate_zones` scopes the layer to zones drawn on a FilterMask (an option
beyond Nav2, whose layer is global): inside the zones each cell gets exactly the global
layer's cost, outside exactly the plain `inflation.inflate` cost with
`config.symmetric` (pass 1). A costmap cell is inside when the mask cell under its
centre holds a value other than 0 (1..100, or -1 unknown), read with the keepout
filter's same-frame rule (`geometry.centres_to_cells_2d`: Nav2's `worldToMap` as an
exact floor on the host doubles); a centre off the mask is outside.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants, geometry, validate
from jaxfilters.inflation import InflationConfig, cost_tables, inflate_one, squared_distance
from jaxfilters.mask_lookup import mask_origin_terms
from jaxfilters.types import Costmap, FilterMask, check_mask, mask_geometry_ok, resolve_mask_index

__all__ = ["AsymmetricInflationConfig", "asymmetric_inflate", "asymmetric_inflate_one", "asymmetric_inflate_zones",
           "zone_cells_one"]

_F64 = jnp.float64
MIN_SEGMENT_LENGTH_SQ = 1e-6
"""Nav2's `min_segment_length_sq` (computeObstacleSide): shorter segments are points with side Neutral."""


def _nonnegative(name: str, value) -> float:
  if isinstance(value, (bool, np.bool_)):
    raise ValueError(f"AsymmetricInflationConfig.{name} must be a float; got {value!r}")
  try:
    v = float(value)
  except (TypeError, ValueError):
    raise ValueError(f"AsymmetricInflationConfig.{name} must be a float; got {value!r}") from None
  if not math.isfinite(v):
    raise ValueError(f"AsymmetricInflationConfig.{name} must be finite; got {value!r}")
  if v < 0.0:   # Nav2's onInitialize throws "AsymmetricInflationLayer: <name> must be >= 0"
    raise ValueError(f"AsymmetricInflationConfig.{name} must be >= 0 (Nav2's AsymmetricInflationLayer "
                     f"throws on a negative value); got {v!r}")
  return v


@dataclasses.dataclass(frozen=True, kw_only=True)
class AsymmetricInflationConfig:
  """AsymmetricInflationLayer parameters plus the costmap resolution (static, hashable).

  Nav2's defaults; floats are float64 like Nav2's parameters. The layer has no
  `custom_inscribed_radius`: `inscribed_radius` is the padded footprint's
  (`footprint_radii(...)[0]`).

  Attributes:
    inflation_radius: metres, >= 0 (default 2.0).
    cost_scaling_factor_left: 1/metres, >= 0 (default 4.0): decay on the path's left.
    cost_scaling_factor_right: 1/metres, >= 0 (default 4.0): decay on the path's right.
    goal_distance_threshold: metres, >= 0 (default 1.5): a robot this close to the
      path's last point (Euclidean, `<=`) gets the symmetric pass only.
    inscribed_radius: metres, >= 0.
    resolution: metres per cell, > 0, exactly as the costmap stores it.
    inflate_unknown, inflate_around_unknown, enabled: as `InflationConfig`.

  Raises:
    ValueError: a negative radius, factor or threshold (Nav2's `onInitialize`
      throws), a value that is not a finite float or bool, or what
      `InflationConfig` rejects (a resolution <= 0, a cell radius above 1024).
  """
  inflation_radius: float = 2.0
  cost_scaling_factor_left: float = 4.0
  cost_scaling_factor_right: float = 4.0
  goal_distance_threshold: float = 1.5
  inscribed_radius: float
  resolution: float
  inflate_unknown: bool = False
  inflate_around_unknown: bool = False
  enabled: bool = True

  def __post_init__(self):
    for name in ("inflation_radius", "cost_scaling_factor_left", "cost_scaling_factor_right",
                 "goal_distance_threshold", "inscribed_radius"):
      object.__setattr__(self, name, _nonnegative(name, getattr(self, name)))
    for name in ("inflate_unknown", "inflate_around_unknown", "enabled"):
      v = getattr(self, name)
      if not isinstance(v, (bool, np.bool_)):
        raise ValueError(f"AsymmetricInflationConfig.{name} must be a bool; got {v!r}")
      object.__setattr__(self, name, bool(v))
    try:
      self.symmetric   # the resolution and the cell radius, checked by InflationConfig
    except ValueError as e:
      raise ValueError(f"AsymmetricInflationConfig: {e}") from None
    object.__setattr__(self, "resolution", self.symmetric.resolution)

  def _inflation(self, factor: float) -> InflationConfig:
    return InflationConfig(inflation_radius=self.inflation_radius, cost_scaling_factor=factor,
                           inscribed_radius=self.inscribed_radius, resolution=self.resolution,
                           inflate_unknown=self.inflate_unknown,
                           inflate_around_unknown=self.inflate_around_unknown, enabled=self.enabled)

  @property
  def symmetric(self) -> InflationConfig:
    """Pass 1: the InflationConfig with max(left, right) (Nav2's `cost_scaling_factor_`)."""
    return self._inflation(max(self.cost_scaling_factor_left, self.cost_scaling_factor_right))

  @property
  def disfavoured(self) -> InflationConfig:
    """Pass 2's cost table: min(left, right) (Nav2's `cost_lut_disfavored_`)."""
    return self._inflation(min(self.cost_scaling_factor_left, self.cost_scaling_factor_right))

  @property
  def disfavoured_side(self) -> int:
    """+1 (left) when left < right, else -1 (right): Nav2's `disfavored_side`."""
    return 1 if self.cost_scaling_factor_left < self.cost_scaling_factor_right else -1

  @property
  def cell_radius(self) -> int:
    """R = max(0, ceil(inflation_radius / resolution)) (Nav2's `cell_inflation_radius_`)."""
    return self.symmetric.cell_radius


def _sum64(terms) -> jax.Array:
  """The exact float64 value of float32 parts (hi first): hi + mid + lo in float64."""
  out = terms[0].astype(_F64)
  for t in terms[1:]:
    out = out + t.astype(_F64)
  return out


def _segments(path, n, robot_xy, origin, res, h, w, config):
  """Per segment k (from point k to k + 1): float64 (ax, ay, bx, by) [S] and valid bool [S]
  (Nav2's extractLocalPathSegments with the path in the costmap frame)."""
  p = path.astype(_F64)
  s = p.shape[0] - 1
  ax, ay, bx, by = p[:-1, 0], p[:-1, 1], p[1:, 0], p[1:, 1]
  r = config.inflation_radius
  goal = p[jnp.clip(n - 1, 0, p.shape[0] - 1)]
  dx = goal[0] - robot_xy[0].astype(_F64)
  dy = goal[1] - robot_xy[1].astype(_F64)
  far = jnp.sqrt(dx * dx + dy * dy) > config.goal_distance_threshold
  map_min_x, map_min_y = origin[0], origin[1]
  map_max_x = map_min_x + float(w) * res
  map_max_y = map_min_y + float(h) * res
  culled = ((jnp.maximum(ax, bx) + r < map_min_x) | (jnp.minimum(ax, bx) - r > map_max_x)
            | (jnp.maximum(ay, by) + r < map_min_y) | (jnp.minimum(ay, by) - r > map_max_y))
  valid = (jnp.arange(s) + 1 < n) & (n >= 2) & (n <= p.shape[0]) & far & ~culled
  return (ax, ay, bx, by), valid


WINDOW_SLACK = 8
"""Cells a segment's padded box may exceed 2R + 1 by and still take the windowed pass (see `_sides`)."""


def _segment_update(k, cxw, cyw, seg, use, r, carry):
  """Folds segment k into (min_d, best_k, best_cross) over one window of cell centres: Nav2's
  computeObstacleSide arithmetic per cell, the smallest dist^2 winning, the lowest k on ties (Nav2
  walks the segments in order and keeps the first strict minimum)."""
  min_d, best_k, best_c = carry
  ki = k.astype(jnp.int32)
  ax, ay, bx, by = (a[ki] for a in seg)
  inside = (use[ki] & (cxw >= jnp.minimum(ax, bx) - r) & (cxw <= jnp.maximum(ax, bx) + r)
            & (cyw >= jnp.minimum(ay, by) - r) & (cyw <= jnp.maximum(ay, by) + r))
  abx, aby = bx - ax, by - ay
  len_sq = abx * abx + aby * aby
  acx, acy = cxw - ax, cyw - ay
  point = len_sq < MIN_SEGMENT_LENGTH_SQ
  t = jnp.clip((acx * abx + acy * aby) / jnp.where(point, 1.0, len_sq), 0.0, 1.0)
  pdx, pdy = acx - t * abx, acy - t * aby
  dist_sq = jnp.where(point, acx * acx + acy * acy, pdx * pdx + pdy * pdy)
  cross = jnp.where(point, 0.0, abx * acy - aby * acx)
  take = inside & ((dist_sq < min_d) | ((dist_sq == min_d) & (k < best_k)))
  return jnp.where(take, dist_sq, min_d), jnp.where(take, k, best_k), jnp.where(take, cross, best_c)


def _cell_span(lo, hi, o, res, n):
  """Cells [a, b] (clipped to [0, n - 1]) whose centres o + (i + 0.5) res may lie in [lo, hi]: one
  cell of margin each side, so float64 rounding of the estimate never drops a cell."""
  a = jnp.floor(jnp.clip((lo - o) / res - 0.5, -4.0, n + 4.0)) - 1
  b = jnp.ceil(jnp.clip((hi - o) / res - 0.5, -4.0, n + 4.0)) + 1
  return jnp.maximum(a, 0).astype(jnp.int32), jnp.minimum(b, n - 1).astype(jnp.int32)


def _sides(cx, cy, seg, valid, config, origin, res):
  """int8 [H, W]: each cell centre's side (+1 left, -1 right, 0 neutral), Nav2's computeObstacleSide
  over the segments whose padded box holds the centre, in segment order (first minimum wins).

  A segment's padded box spans at most `2R + 1 + WINDOW_SLACK` cells each way when it is short
  (Nav2's planners space poses about a cell apart): such a segment updates only a window of that
  size around it. Longer segments update the whole map, in a loop that runs once per long segment.
  The winner per cell is the smallest dist^2, then the lowest segment index, so the order of the
  two loops does not matter and the result is the in-order walk's.
  """
  r = config.inflation_radius
  h, w = cy.shape[0], cx.shape[1]
  n_seg = valid.shape[0]
  ws = 2 * config.cell_radius + 1 + WINDOW_SLACK
  wsx, wsy = min(ws, w), min(ws, h)
  ax, ay, bx, by = seg
  x0, x1 = _cell_span(jnp.minimum(ax, bx) - r, jnp.maximum(ax, bx) + r, origin[0], res, w)
  y0, y1 = _cell_span(jnp.minimum(ay, by) - r, jnp.maximum(ay, by) + r, origin[1], res, h)
  fits = ((x1 - x0 < wsx) | (wsx == w)) & ((y1 - y0 < wsy) | (wsy == h))
  sx = jnp.clip(x0, 0, w - wsx)
  sy = jnp.clip(y0, 0, h - wsy)
  small = valid & fits
  large = valid & ~fits
  cx_row, cy_col = cx[0], cy[:, 0]

  def windowed(k, acc):
    # One float64 [3, H, W] carry (min_d, best_k, best_cross): the window is read and written back
    # in place (three arrays would each need the others' old window, and XLA copies them all).
    at = (jnp.int32(0), sy[k], sx[k])
    part = jax.lax.dynamic_slice(acc, at, (3, wsy, wsx))
    cxw = jax.lax.dynamic_slice(cx_row, (sx[k],), (wsx,))[None, :]
    cyw = jax.lax.dynamic_slice(cy_col, (sy[k],), (wsy,))[:, None]
    md, bk, bc = _segment_update(k.astype(_F64), cxw, cyw, seg, small, r, (part[0], part[1], part[2]))
    return jax.lax.dynamic_update_slice(acc, jnp.stack([md, bk, bc]), at)

  order = jnp.argsort(~large, stable=True).astype(jnp.int32)   # the long segments first, in order
  n_large = jnp.sum(large)

  def whole(state):
    i, acc = state
    k = order[i]
    md, bk, bc = _segment_update(k.astype(_F64), cx, cy, seg, large, r, (acc[0], acc[1], acc[2]))
    return i + 1, jnp.stack([md, bk, bc])

  init = jnp.stack([jnp.full((h, w), np.finfo(np.float64).max, _F64), jnp.full((h, w), float(n_seg), _F64),
                    jnp.zeros((h, w), _F64)])
  acc = jax.lax.fori_loop(0, n_seg, windowed, init)
  _, acc = jax.lax.while_loop(lambda s: s[0] < n_large, whole, (jnp.int32(0), acc))
  min_d, best = acc[0], acc[2]
  side = jnp.where(best > 0.0, 1, jnp.where(best < 0.0, -1, 0)).astype(jnp.int8)
  return jnp.where(min_d > r * r, jnp.int8(0), side)


def asymmetric_inflate_one(cost: jax.Array, path: jax.Array, path_length: jax.Array, robot_xy: jax.Array,
                           origin_terms, resolution_terms, *, config: AsymmetricInflationConfig,
                           inside: jax.Array | None = None) -> jax.Array:
  """One robot's `AsymmetricInflationLayer::updateCosts` over its whole map.

  Args:
    cost: uint8 [H, W], the master costmap before the layer (row 0 = lowest y).
    path: float32 [P, 2], the robot's plan in the costmap frame (metres), P >= 1.
    path_length: int32 [], the points of `path` in use; < 2 (or > P) means no path.
    robot_xy: float32 [2], the robot position `updateBounds` receives.
    origin_terms: list of float32 [2] parts whose exact sum is the costmap origin
      (`geometry.origin_terms`).
    resolution_terms: list of float32 [] parts whose exact sum is the resolution.
    config: static AsymmetricInflationConfig.
    inside: bool [H, W] or None (everywhere): the cells pass 2 may raise; the
      others keep pass 1's cost (`asymmetric_inflate_zones`).

  Returns:
    uint8 [H, W].
  """
  h, w = cost.shape
  r = config.cell_radius
  if not config.enabled or r == 0:
    return cost
  out = inflate_one(cost, config=config.symmetric)
  if config.cost_scaling_factor_left == config.cost_scaling_factor_right:
    return out
  lethal = constants.LETHAL_OBSTACLE
  unknown = constants.NO_INFORMATION
  obstacle = out == lethal
  open_ = out != lethal
  if config.inflate_around_unknown:
    obstacle = obstacle | (out == unknown)
    open_ = open_ & (out != unknown)
  padded = jnp.pad(open_, 1)
  touches_open = padded[1:-1, :-2] | padded[1:-1, 2:] | padded[:-2, 1:-1] | padded[2:, 1:-1]
  ii = jnp.arange(w)[None, :]
  jj = jnp.arange(h)[:, None]
  on_edge = (ii == 0) | (ii == w - 1) | (jj == 0) | (jj == h - 1)
  boundary = obstacle & (on_edge | touches_open)
  with jax.enable_x64(True):
    origin = _sum64([jnp.asarray(t) for t in origin_terms])
    res = _sum64([jnp.asarray(t) for t in resolution_terms])
    seg, valid = _segments(jnp.asarray(path), jnp.asarray(path_length), jnp.asarray(robot_xy), origin, res, h, w,
                           config)
    cx = origin[0] + (jnp.arange(w, dtype=_F64)[None, :] + 0.5) * res
    cy = origin[1] + (jnp.arange(h, dtype=_F64)[:, None] + 0.5) * res
    side = _sides(cx, cy, seg, valid, config, origin, res)
    active = jnp.any(valid)
  seeds = boundary & (side == config.disfavoured_side) & active
  _, cost_by_sq, max_sq = cost_tables(config.disfavoured)
  dtype = jnp.int16 if (r + 1) ** 2 + r * r <= np.iinfo(np.int16).max else jnp.int32
  sq = squared_distance(seeds, r, dtype).astype(jnp.int32)
  new = jnp.asarray(cost_by_sq)[sq]
  raise_ = (sq <= max_sq) & (new > out)
  if inside is not None:
    raise_ = raise_ & inside
  return jnp.where(raise_, new, out)


def zone_cells_one(shape: tuple[int, int], origin_terms, resolution_terms, zones: FilterMask,
                   i: jax.Array) -> jax.Array:
  """Which cells of one robot's costmap lie in the zones of mask `i`: bool [H, W].

  A cell is inside when the mask cell under its centre holds a value other than 0
  (1..100, or -1 unknown); a centre off the mask is outside. Same frame, exact:
  the keepout filter's `geometry.centres_to_cells_2d` on the host doubles.

  Args:
    shape: (H, W) of the costmap.
    origin_terms, resolution_terms: the costmap's geometry as float32 parts
      (as `asymmetric_inflate_one`).
    zones: FilterMask stack; i: int32 [] the mask this robot uses.

  Returns:
    bool [H, W].
  """
  h, w = shape
  hm, wm = zones.shape
  (mx, vx), (my, vy) = geometry.centres_to_cells_2d((h, w), origin_terms, resolution_terms,
                                                    mask_origin_terms(zones, i), zones.resolution[i], (hm, wm))
  value = zones.data[i][my[:, None], mx[None, :]]
  return vy[:, None] & vx[None, :] & (value != 0)


def _concrete(x) -> bool:
  return not isinstance(x, jax.core.Tracer)


def _check_inputs(b, paths, path_lengths, robot_xy):
  """Static checks of the per-robot inputs, and value checks where they are concrete."""
  # The dtypes as given: jnp.asarray would turn a float64 host array into float32 silently.
  dtypes = [np.dtype(x.dtype) if hasattr(x, "dtype") else np.asarray(x).dtype for x in (paths, path_lengths, robot_xy)]
  paths, path_lengths, robot_xy = jnp.asarray(paths), jnp.asarray(path_lengths), jnp.asarray(robot_xy)
  if paths.ndim != 3 or paths.shape[0] != b or paths.shape[2] != 2 or paths.shape[1] < 1:
    raise ValueError(f"asymmetric_inflate: paths must be float32 [B, P, 2] with B = {b} (the costmaps') and "
                     f"P >= 1; got {paths.dtype}{tuple(paths.shape)}")
  if dtypes[0] != np.float32:
    raise ValueError(f"asymmetric_inflate: paths must be float32 (metres); got {dtypes[0]}")
  if path_lengths.shape != (b,) or not np.issubdtype(dtypes[1], np.integer):
    raise ValueError(f"asymmetric_inflate: path_lengths must be int32 [B] with B = {b}; "
                     f"got {dtypes[1]}{tuple(path_lengths.shape)}")
  if robot_xy.shape != (b, 2) or dtypes[2] != np.float32:
    raise ValueError(f"asymmetric_inflate: robot_xy must be float32 [B, 2] with B = {b}; "
                     f"got {dtypes[2]}{tuple(robot_xy.shape)}")
  p = paths.shape[1]
  if _concrete(path_lengths):
    n = np.asarray(path_lengths)
    if np.any((n < 0) | (n > p)):
      raise ValueError(f"asymmetric_inflate: path_lengths must be in [0, P] = [0, {p}]; got {n.tolist()}")
    if _concrete(paths):
      pts = np.asarray(paths)
      used = np.arange(p)[None, :] < n[:, None]
      if not np.all(np.isfinite(pts[used])):
        raise ValueError("asymmetric_inflate: paths must be finite within path_lengths; got a NaN or inf point")
  if _concrete(robot_xy) and not np.all(np.isfinite(np.asarray(robot_xy))):
    raise ValueError(f"asymmetric_inflate: robot_xy must be finite; got {np.asarray(robot_xy).tolist()}")
  return paths, path_lengths.astype(jnp.int32), robot_xy


def _prepare(costmap, paths, path_lengths, robot_xy, config, where):
  """Checks the common inputs; returns (cost, paths, path_lengths, robot_xy, geometry 4-tuple)."""
  if not isinstance(config, AsymmetricInflationConfig):
    raise TypeError(f"config must be an AsymmetricInflationConfig; got {type(config).__name__}")
  if isinstance(costmap, Costmap):
    cost = costmap.cost
    res = costmap.resolution
    if _concrete(res) and np.any(np.asarray(res) != np.float32(config.resolution)):
      raise ValueError(f"Costmap resolution {np.asarray(res)} differs from AsymmetricInflationConfig.resolution "
                       f"{config.resolution!r}; inflate each resolution with its own config")
    geometry_ = (costmap.origin, costmap.origin_lo, costmap.resolution, costmap.resolution_lo)
  else:
    cost = jnp.asarray(costmap)
    geometry_ = None
  if cost.ndim != 3 or cost.dtype != jnp.uint8:
    raise ValueError(f"{where} expects cost uint8 [B, H, W]; got {cost.dtype}{tuple(cost.shape)}")
  b = cost.shape[0]
  paths, path_lengths, robot_xy = _check_inputs(b, paths, path_lengths, robot_xy)
  if geometry_ is None:
    parts = validate.split_float64(np.asarray([config.resolution], np.float64))
    geometry_ = (jnp.zeros((b, 2), jnp.float32), None, jnp.full((b,), parts[0, 0], jnp.float32),
                 jnp.tile(jnp.asarray(parts[:, 1:], jnp.float32), (b, 1)))
  return cost, paths, path_lengths, robot_xy, geometry_


def asymmetric_inflate(costmap: Costmap | jax.Array, *, paths, path_lengths, robot_xy,
                       config: AsymmetricInflationConfig) -> Costmap | jax.Array:
  """Nav2's AsymmetricInflationLayer over a fleet, each robot with its own path.

  Per robot one `updateCosts` over the whole map (module docstring). Jitted at the
  edge with `config` static: paths of any values, lengths and robot positions run in
  one compiled program per shape.

  Args:
    costmap: a `Costmap` (cost uint8 [B, H, W], its exact float64 origin and
      resolution), or a bare uint8 [B, H, W] whose origin is (0, 0) and resolution
      `config.resolution`.
    paths: float32 [B, P, 2], each robot's plan in world metres in the costmap's frame.
    path_lengths: int32 [B], the points of each path in use; < 2 means no path (the
      symmetric pass only). Concrete values outside [0, P] raise; traced ones there
      count as no path.
    robot_xy: float32 [B, 2], the robot position `updateBounds` receives.
    config: static AsymmetricInflationConfig; its `resolution` must be the
      costmaps' (checked where the Costmap's values are concrete).

  Returns:
    The same type: a Costmap with the new cost (geometry unchanged), or uint8 [B, H, W].

  Raises:
    TypeError: config that is not an AsymmetricInflationConfig.
    ValueError: cost that is not uint8 [B, H, W]; paths, path_lengths or robot_xy of
      the wrong shape or dtype; concrete path lengths outside [0, P], non-finite
      path points in use or robot positions; a concrete Costmap whose resolution
      differs from float32(config.resolution).
  """
  cost, paths, path_lengths, robot_xy, geometry_ = _prepare(costmap, paths, path_lengths, robot_xy, config,
                                                            "asymmetric_inflate")
  out = _batch(cost, paths, path_lengths, robot_xy, *geometry_, config=config)
  return dataclasses.replace(costmap, cost=out) if isinstance(costmap, Costmap) else out


def asymmetric_inflate_zones(costmap: Costmap | jax.Array, zones: FilterMask, *, paths, path_lengths, robot_xy,
                             config: AsymmetricInflationConfig,
                             zone_index=None) -> tuple[Costmap | jax.Array, jax.Array]:
  """The AsymmetricInflationLayer scoped to zones (beyond Nav2; docs/guides/beyond_nav2.md).

  Inside the zones of `zones` every cell gets exactly `asymmetric_inflate`'s cost;
  outside, exactly `inflate(costmap, config=config.symmetric)`'s (the plain
  InflationLayer with max(left, right)). The obstacles on the disfavoured side
  seed the asymmetric pass wherever they are; only the cells it may raise are
  scoped. A costmap cell is inside when the mask cell under its centre holds a
  value other than 0 (1..100, or -1 unknown: the higher cost is kept where the
  mask does not know); a centre off the mask is outside. The mask is in the
  costmap's frame; its origin and resolution are its own (any map_server mask:
  `FilterMask.create(load_map(...), FilterInfo.create(...))`, any info type).
  Jitted at the edge with `config` static: new paths, zones of the same shape and
  zone indices compile nothing.

  Args:
    costmap: as `asymmetric_inflate` (cost uint8 [B, H, W]).
    zones: FilterMask, M = 1 shared or a stack picked per robot by `zone_index`.
    paths, path_lengths, robot_xy, config: as `asymmetric_inflate`.
    zone_index: optional int [B], which mask of the stack each robot uses.

  Returns:
    (the same type as `costmap` with the new cost, error bool [B]). `error` is True
    for a robot whose zone mask could not be read: a traced `zone_index` outside
    [0, M), or a mask whose traced geometry is unusable (`types.mask_geometry_ok`).
    Such a robot gets the global layer's cost everywhere (never the lower, plain one).

  Raises:
    TypeError: zones that is not a FilterMask, or config that is not an
      AsymmetricInflationConfig.
    ValueError: what `asymmetric_inflate` rejects; zones whose leaves have the
      wrong shapes or dtypes; a stack of several masks without `zone_index`; a
      `zone_index` that is not int [B], or (concrete) outside [0, M).
  """
  check_mask(zones, "asymmetric_inflate_zones: zones")
  cost, paths, path_lengths, robot_xy, geometry_ = _prepare(costmap, paths, path_lengths, robot_xy, config,
                                                            "asymmetric_inflate_zones")
  try:
    idx, idx_ok = resolve_mask_index(zones, zone_index, cost.shape[0])
  except ValueError as e:
    raise ValueError(f"asymmetric_inflate_zones: {str(e).replace('mask_index', 'zone_index')}") from None
  out, error = _batch_zones(cost, paths, path_lengths, robot_xy, *geometry_, zones, idx, idx_ok, config=config)
  return (dataclasses.replace(costmap, cost=out) if isinstance(costmap, Costmap) else out), error


@functools.partial(jax.jit, static_argnames=("config",))
def _batch(cost, paths, path_lengths, robot_xy, origin, origin_lo, resolution, resolution_lo, *, config):
  with jax.named_scope("asymmetric_inflate"):
    def one(c, p, n, xy, o, o_lo, r, r_lo):
      o_terms = [o] if o_lo is None else [o, o_lo[:, 0], o_lo[:, 1]]
      r_terms = [r] if r_lo is None else [r, r_lo[0], r_lo[1]]
      return asymmetric_inflate_one(c, p, n, xy, o_terms, r_terms, config=config)
    axes = (0, 0, 0, 0, 0, None if origin_lo is None else 0, 0, None if resolution_lo is None else 0)
    return jax.vmap(one, in_axes=axes)(cost, paths, path_lengths, robot_xy, origin, origin_lo, resolution,
                                       resolution_lo)


@functools.partial(jax.jit, static_argnames=("config",))
def _batch_zones(cost, paths, path_lengths, robot_xy, origin, origin_lo, resolution, resolution_lo, zones, idx,
                 idx_ok, *, config):
  with jax.named_scope("asymmetric_inflate_zones"):
    ok = idx_ok & mask_geometry_ok(zones)[idx]
    h, w = cost.shape[1:]

    def one(c, p, n, xy, o, o_lo, r, r_lo, i, good):
      o_terms = [o] if o_lo is None else [o, o_lo[:, 0], o_lo[:, 1]]
      r_terms = [r] if r_lo is None else [r, r_lo[0], r_lo[1]]
      inside = zone_cells_one((h, w), o_terms, r_terms, zones, i) | ~good
      return asymmetric_inflate_one(c, p, n, xy, o_terms, r_terms, config=config, inside=inside)
    axes = (0, 0, 0, 0, 0, None if origin_lo is None else 0, 0, None if resolution_lo is None else 0, 0, 0)
    out = jax.vmap(one, in_axes=axes)(cost, paths, path_lengths, robot_xy, origin, origin_lo, resolution,
                                      resolution_lo, idx, ok)
    return out, ~ok
