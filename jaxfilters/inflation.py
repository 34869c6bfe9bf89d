"""InflationLayer: Nav2's current inflation (exact EDT + 0.01-cell cost LUT, docs/nav2_semantics.md §9.3).

Only the current `nav2_costmap_2d::InflationLayer` (Nav2 PR #5933, the default)
is implemented. The `LegacyInflationLayer` (4-connected wavefront with
inherited sources, docs/nav2_semantics.md §9.4) is not: the two differ by ±1 at some distances.

What Nav2 computes, for a window that is the whole map (the ROI padded by R is
then the whole map too, so a cell near the border sees only in-map obstacles):

1. sources are cells equal to 254, plus 255 with `inflate_around_unknown`;
   253 written by other layers is not a source;
2. `dist` = float32 sqrt of the exact squared Euclidean distance, in cells,
   between cell centres, to the nearest source (Felzenszwalb-Huttenlocher in
   float32; on these integer inputs its squared distances are exact integers);
3. cells with `dist <= R` (float compare) get
   `cost = LUT[min(len - 1, uint(float32(dist * 100) + 0.5f))]`, with
   `LUT[k] = computeCost(k / 100.0)` for k = 0..R*100+1, in float64;
4. write rule: `old == 255 and (inflate_unknown ? cost > 0 : cost >= 253)`
   writes cost, otherwise `max(old, cost)`; cells with `dist > R` are untouched.

Implementation. Every float step above depends only on the integer squared
distance s, so the host folds steps 2-3 into one table `cost_by_sq[s]` built
with NumPy float32/float64 scalar arithmetic in Nav2's order (bit-exact, no FMA
contraction), together with the largest s that Nav2 counts as `dist <= R`.
The device computes s exactly in integers with a separable EDT, capped at
(R+1)^2 because nothing farther is written:

- column pass: g = distance to the nearest source in the same column, capped
  at R+1 (2R shifted compares of a padded boolean grid);
- row pass: s = min over |dx| <= R of g[x+dx]^2 + dx^2, capped at (R+1)^2.

Both passes are O(R) vector work per cell with static shapes (no scans, no
data-dependent loops), so they fuse well under `jit`/`vmap`; integers are
int16 when (R+1)^2 + R^2 fits, else int32. It is exact: every source within
squared distance (R+1)^2 - 1 has |dx| <= R and |dy| <= R, so those s are the
true minimum, and anything farther reads as (R+1)^2, which Nav2 leaves alone.
The 2R shifts are unrolled at trace time, so compile time grows linearly with
R (well under a second at R = 100 on CPU); R is limited to 1024 cells.

Resolution is static. The LUT depends on `resolution` through computeCost, so
it is built on the host per `InflationConfig`; a fleet whose costmaps use
several resolutions compiles once per resolution (group robots by resolution).
Pass the resolution exactly as Nav2 holds it: a costmap sized from a map
message has `double(float32(res))`, e.g. 0.05000000074505806 for 0.05, which
can move a cell across the inscribed boundary (see `compute_cost`).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from jaxfilters.types import Costmap

__all__ = ["InflationConfig", "footprint_radii", "compute_cost", "inflate_one", "inflate"]

COST_LUT_PRECISION = 100  # LUT samples per cell (Nav2's COST_LUT_PRECISION).


# ----------------------------------------------------------------------------
# Radii (docs/nav2_semantics.md §9.1, nav2_costmap_2d/src/footprint.cpp + costmap_math.cpp).


def _sign0(x: float) -> float:
  return -1.0 if x < 0.0 else (1.0 if x > 0.0 else 0.0)


def _distance_to_segment(x0: float, y0: float, x1: float, y1: float) -> float:
  # costmap_math.cpp distanceToLine with the query point at the origin.
  a, b = -x0, -y0
  c, d = x1 - x0, y1 - y0
  len_sq = c * c + d * d
  if len_sq == 0.0:
    # C++ divides 0 by 0: NaN, which std::min/std::max (and Python's) then ignore.
    return math.nan
  param = (a * c + b * d) / len_sq
  if param < 0:
    xx, yy = x0, y0
  elif param > 1:
    xx, yy = x1, y1
  else:
    xx, yy = x0 + param * c, y0 + param * d
  return math.hypot(xx, yy)


def footprint_radii(*, robot_radius: float | None = None,
                    footprint: Sequence[Sequence[float]] | None = None,
                    footprint_padding: float = 0.01) -> tuple[float, float]:
  """Nav2's inscribed and circumscribed radii of a padded footprint, in metres.

  With `robot_radius` r the footprint is Nav2's 16-gon `r (cos t, sin t)`,
  t = 2 pi k / 16. Every footprint is then padded, `x += sign0(x) * pad` and
  likewise for y, in float64 as Nav2 does (so a vertex whose coordinate is
  cos(pi/2) = 6e-17 moves by +pad too). The radii are the min and max over the
  vertices' distances and the clamped vertex-to-edge distances from the origin.
  r = 0.22 with pad 0.01 gives (0.22549849971227903, 0.23414213562373096).

  Nav2 stores footprints given as a string parameter or a Polygon message in
  float32; pass `np.float32`-rounded vertices to reproduce such a robot exactly.

  Args:
    robot_radius: metres, finite and >= 0; exclusive with `footprint`.
    footprint: polygon vertices [(x, y), ...] in metres, at least 3.
    footprint_padding: metres, finite (Nav2's `footprint_padding`, default 0.01).

  Returns:
    (inscribed_radius, circumscribed_radius) as Python floats.

  Raises:
    ValueError: neither or both shapes given, fewer than 3 vertices, a vertex
      that is not an (x, y) pair, or a non-finite number.
  """
  if (robot_radius is None) == (footprint is None):
    raise ValueError("footprint_radii needs exactly one of robot_radius or footprint; got "
                     f"robot_radius={robot_radius!r}, footprint={footprint!r}")
  pad = float(footprint_padding)
  if not math.isfinite(pad):
    raise ValueError(f"footprint_padding must be finite; got {footprint_padding!r}")
  if robot_radius is not None:
    r = float(robot_radius)
    if not math.isfinite(r) or r < 0:
      raise ValueError(f"robot_radius must be finite and >= 0; got {robot_radius!r}")
    n = 16
    pts = [(math.cos(i * 2 * math.pi / n) * r, math.sin(i * 2 * math.pi / n) * r)
           for i in range(n)]
  else:
    pts = []
    for p in footprint:
      p = tuple(p)
      if len(p) != 2:
        raise ValueError(f"footprint vertices must be (x, y) pairs; got {p!r}")
      x, y = float(p[0]), float(p[1])
      if not (math.isfinite(x) and math.isfinite(y)):
        raise ValueError(f"footprint vertices must be finite; got {p!r}")
      pts.append((x, y))
    if len(pts) < 3:
      raise ValueError(f"a footprint needs at least 3 vertices; got {len(pts)}")
  pts = [(x + _sign0(x) * pad, y + _sign0(y) * pad) for x, y in pts]
  lo, hi = math.inf, 0.0
  for i, (x, y) in enumerate(pts):
    nx, ny = pts[(i + 1) % len(pts)]
    vertex = math.hypot(x, y)
    edge = _distance_to_segment(x, y, nx, ny)
    lo = min(lo, vertex, edge)
    hi = max(hi, vertex, edge)
  return lo, hi


# ----------------------------------------------------------------------------
# Configuration and host tables.


def _finite(name: str, value, *, lo: float | None = None, strict: bool = False) -> float:
  if isinstance(value, (bool, np.bool_)):
    raise ValueError(f"InflationConfig.{name} must be a float; got {value!r}")
  try:
    v = float(value)
  except (TypeError, ValueError):
    raise ValueError(f"InflationConfig.{name} must be a float; got {value!r}") from None
  if not math.isfinite(v):
    raise ValueError(f"InflationConfig.{name} must be finite; got {value!r}")
  if lo is not None and (v <= lo if strict else v < lo):
    raise ValueError(f"InflationConfig.{name} must be {'>' if strict else '>='} {lo}; got {v!r}")
  return v


@dataclasses.dataclass(frozen=True, kw_only=True)
class InflationConfig:
  """InflationLayer parameters plus the costmap resolution (static, hashable).

  All floats are float64, like Nav2's parameters; build variants with
  `dataclasses.replace` or `InflationConfig.from_footprint`.

  Attributes:
    inflation_radius: metres, >= 0 (Nav2 default 0.55).
    cost_scaling_factor: 1/metres, finite and >= 0 (default 10.0). Nav2 takes
      any double, but a negative one makes 252 * exp(...) exceed 255, which
      is undefined behaviour in its uint8 cast, so it is rejected here.
    inscribed_radius: metres, >= 0 (`footprint_radii(...)[0]`, or Nav2's
      `custom_inscribed_radius`).
    resolution: metres per cell, > 0, exactly as the costmap stores it.
    inflate_unknown: bool, unknown cells take any cost > 0 (default False).
    inflate_around_unknown: bool, unknown cells are sources (default False).
    enabled: bool; False makes `inflate` the identity.

  Raises:
    ValueError: a field of the wrong type, not finite, or out of range
      (including a cell radius R above 1024).
  """
  inflation_radius: float = 0.55
  cost_scaling_factor: float = 10.0
  inscribed_radius: float
  resolution: float
  inflate_unknown: bool = False
  inflate_around_unknown: bool = False
  enabled: bool = True

  def __post_init__(self):
    # Normalise to Python floats/bools so equal configs hash equally.
    object.__setattr__(self, "inflation_radius",
                       _finite("inflation_radius", self.inflation_radius, lo=0.0))
    object.__setattr__(self, "cost_scaling_factor",
                       _finite("cost_scaling_factor", self.cost_scaling_factor, lo=0.0))
    object.__setattr__(self, "inscribed_radius",
                       _finite("inscribed_radius", self.inscribed_radius, lo=0.0))
    object.__setattr__(self, "resolution",
                       _finite("resolution", self.resolution, lo=0.0, strict=True))
    for name in ("inflate_unknown", "inflate_around_unknown", "enabled"):
      v = getattr(self, name)
      if not isinstance(v, (bool, np.bool_)):
        raise ValueError(f"InflationConfig.{name} must be a bool; got {v!r}")
      object.__setattr__(self, name, bool(v))
    if self.cell_radius > 1024:
      raise ValueError("InflationConfig: inflation_radius / resolution must be at most 1024 "
                       f"cells; got R = {self.cell_radius}")

  @classmethod
  def from_footprint(cls, *, resolution: float, robot_radius: float | None = None,
                     footprint: Sequence[Sequence[float]] | None = None,
                     footprint_padding: float = 0.01, **kwargs) -> "InflationConfig":
    """Builds a config whose inscribed radius comes from `footprint_radii`.

    Args:
      resolution: metres per cell.
      robot_radius, footprint, footprint_padding: as in `footprint_radii`.
      **kwargs: the other InflationConfig fields.
    """
    inscribed, _ = footprint_radii(robot_radius=robot_radius, footprint=footprint,
                                   footprint_padding=footprint_padding)
    return cls(inscribed_radius=inscribed, resolution=resolution, **kwargs)

  @property
  def cell_radius(self) -> int:
    """R = max(0, ceil(inflation_radius / resolution)) in float64 (0.7 / 0.05 -> 14)."""
    return int(max(0.0, math.ceil(self.inflation_radius / self.resolution)))

  @property
  def cost_lut(self) -> np.ndarray:
    """uint8 [R*100 + 2] (read-only): Nav2's `cost_lut_`, LUT[k] = computeCost(k / 100)."""
    return cost_tables(self)[0]


def compute_cost(distance: float, *, config: InflationConfig) -> int:
  """Nav2's `computeCost(distance)` in float64 (docs/nav2_semantics.md §9.2).

  Args:
    distance: distance to the nearest obstacle, in cells.
    config: supplies resolution, inscribed radius and cost scaling factor.

  Returns:
    The cost as an int in 0..254: 254 at 0; 253 while `distance * resolution
    <= inscribed_radius` (so d = 4.4, res 0.05, inscribed 0.22 gives 251: the
    product is 0.22000000000000003); else `uint8(trunc(252 * exp(-csf * (d *
    res - inscribed))))`.
  """
  d = float(distance)
  if d == 0:
    return constants.LETHAL_OBSTACLE
  if d * config.resolution <= config.inscribed_radius:
    return constants.INSCRIBED_INFLATED_OBSTACLE
  factor = math.exp(-1.0 * config.cost_scaling_factor * (d * config.resolution
                                                         - config.inscribed_radius))
  return int((constants.INSCRIBED_INFLATED_OBSTACLE - 1) * factor)


@functools.lru_cache(maxsize=64)
def cost_tables(config: InflationConfig) -> tuple[np.ndarray, np.ndarray, int]:
  """(cost_lut, cost_by_sq, max_sq_written) for one config, on the host.

  cost_by_sq[s] is the cost Nav2 writes at squared distance s (for s <=
  max_sq_written), reproducing its float32 steps: sqrt, `dist <= R`, and
  `uint(dist * 100 + 0.5f)` (float32 ops, each rounded).
  """
  r = config.cell_radius
  lut = np.array([compute_cost(k / COST_LUT_PRECISION, config=config)
                  for k in range(r * COST_LUT_PRECISION + 2)], np.uint8)
  s = np.arange((r + 1) ** 2 + 1, dtype=np.int64)
  dist = np.sqrt(s.astype(np.float32))                        # float32, correctly rounded
  written = dist <= np.float32(r)
  scaled = (dist * np.float32(COST_LUT_PRECISION)).astype(np.float32) + np.float32(0.5)
  idx = np.minimum(scaled.astype(np.float32).astype(np.int64), len(lut) - 1)
  cost_by_sq = np.where(written, lut[idx], 0).astype(np.uint8)
  # sqrt is monotone, so the written set is a prefix of s.
  max_sq = int(np.flatnonzero(written)[-1])
  assert max_sq < (r + 1) ** 2 and np.all(written[:max_sq + 1])
  for a in (lut, cost_by_sq):
    a.setflags(write=False)
  return lut, cost_by_sq, max_sq


# ----------------------------------------------------------------------------
# Device kernels.


def squared_distance(src: jax.Array, r: int, dtype) -> jax.Array:
  """Exact squared distance in cells to the nearest True of src, capped at (R+1)^2.

  Args:
    src: bool [H, W], the sources.
    r: R >= 1, the cell radius.
    dtype: int16 or int32; must hold (R+1)^2 + R^2.

  Returns:
    dtype [H, W]: min(true squared distance, (R+1)^2).
  """
  h, w = src.shape
  cap = r + 1
  # Column pass: vertical distance to the nearest source, capped at R+1.
  g = jnp.where(src, jnp.asarray(0, dtype), jnp.asarray(cap, dtype))
  padded = jnp.pad(src, ((r, r), (0, 0)))
  for dy in range(1, r + 1):
    hit = padded[r - dy:r - dy + h] | padded[r + dy:r + dy + h]
    g = jnp.where(hit, jnp.minimum(g, jnp.asarray(dy, dtype)), g)
  # Row pass: min over |dx| <= R of g^2 + dx^2; off-map columns hold no source.
  g2 = g * g
  padded2 = jnp.pad(g2, ((0, 0), (r, r)), constant_values=cap * cap)
  s = g2
  for dx in range(1, r + 1):
    near = jnp.minimum(padded2[:, r - dx:r - dx + w], padded2[:, r + dx:r + dx + w])
    s = jnp.minimum(s, near + jnp.asarray(dx * dx, dtype))
  return jnp.minimum(s, jnp.asarray(cap * cap, dtype))


def _check_cost(cost, ndim: int, where: str) -> jax.Array:
  cost = jnp.asarray(cost)
  if cost.ndim != ndim or cost.dtype != jnp.uint8:
    dims = "[H, W]" if ndim == 2 else "[B, H, W]"
    raise ValueError(f"{where} expects cost uint8 {dims}; got {cost.dtype}{tuple(cost.shape)}")
  return cost


def inflate_one(cost: jax.Array, *, config: InflationConfig) -> jax.Array:
  """Inflates one costmap over its whole extent (Nav2 InflationLayer::updateCosts).

  Args:
    cost: uint8 [H, W], the master costmap before inflation (row 0 = lowest y).
    config: static inflation parameters (one compile per distinct config).

  Returns:
    uint8 [H, W]: the costmap after inflation. Cells farther than R cells from
    every source are unchanged; with `inflate_around_unknown` unknown cells
    become 254.

  Raises:
    ValueError: cost that is not uint8 [H, W].
  """
  cost = _check_cost(cost, 2, "inflate_one")
  r = config.cell_radius
  if not config.enabled or r == 0:
    return cost
  _, cost_by_sq, max_sq = cost_tables(config)
  src = cost == constants.LETHAL_OBSTACLE
  if config.inflate_around_unknown:
    src = src | (cost == constants.NO_INFORMATION)
  dtype = jnp.int16 if (r + 1) ** 2 + r * r <= np.iinfo(np.int16).max else jnp.int32
  sq = squared_distance(src, r, dtype).astype(jnp.int32)
  new = jnp.asarray(cost_by_sq)[sq]
  unknown = cost == constants.NO_INFORMATION
  if config.inflate_unknown:
    take = unknown & (new > constants.FREE_SPACE)
  else:
    take = unknown & (new >= constants.INSCRIBED_INFLATED_OBSTACLE)
  out = jnp.where(take, new, jnp.maximum(cost, new))
  return jnp.where(sq <= max_sq, out, cost)


def inflate(costmap: Costmap | jax.Array, *, config: InflationConfig) -> Costmap | jax.Array:
  """Inflates a batch of costmaps: `jax.vmap(inflate_one)` over the robots.

  Args:
    costmap: a `Costmap` (cost uint8 [B, H, W]) or a bare uint8 [B, H, W].
    config: static inflation parameters; its `resolution` must be the
      costmaps' resolution (checked when the Costmap's values are concrete;
      under `jit` it is the caller's contract).

  Returns:
    The same type: a Costmap with the inflated cost (origin and resolution
    unchanged), or uint8 [B, H, W].

  Raises:
    ValueError: cost that is not uint8 [B, H, W], or a concrete Costmap whose
      resolution differs from float32(config.resolution).
    TypeError: config that is not an InflationConfig.
  """
  if not isinstance(config, InflationConfig):
    raise TypeError(f"config must be an InflationConfig; got {type(config).__name__}")
  with jax.named_scope("inflate"):
    if isinstance(costmap, Costmap):
      res = costmap.resolution
      if not isinstance(res, jax.core.Tracer):
        res = np.asarray(res)
        if np.any(res != np.float32(config.resolution)):
          raise ValueError(f"Costmap resolution {res} differs from InflationConfig.resolution "
                           f"{config.resolution!r}; inflate each resolution with its own config")
      cost = _check_cost(costmap.cost, 3, "inflate")
      out = jax.vmap(functools.partial(inflate_one, config=config))(cost)
      return dataclasses.replace(costmap, cost=out)
    cost = _check_cost(costmap, 3, "inflate")
    return jax.vmap(functools.partial(inflate_one, config=config))(cost)
