"""Grid geometry: world -> cell with Nav2's float64 results from float32 arithmetic.

Float32 policy
--------------
Poses, origins and resolutions live on the device as float32. Nav2 computes
`floor((w - o) / res)` in float64; float32 division can round a quotient such as
2.9999999 up to 3.0 and move a point into the next cell (spec §2.2: 0.3 / 0.1).
jaxfilters never trusts a rounded quotient for a cell index. Each index is the
*exact* floor of the real-number quotient of the float32 inputs:

1. the numerator is kept as a list of float32 terms whose exact sum is the
   numerator (products are split with bit masks into 12-bit halves, so every
   partial product is exact, with or without FMA contraction);
2. a float32 estimate q0 of the quotient is corrected to the exact floor by the
   exact sign of `num - q * res`, evaluated as a Shewchuk expansion with
   error-free two-sums.

For float32 inputs with |quotient| < 2**22 (20 km at 5 mm cells) this equals
float64 arithmetic on the same float32 values, which is what Nav2 computes when
given those values (tests/test_geometry.py proves it with hypothesis up to
10 km, including points placed exactly on cell boundaries). XLA flushes
subnormal float32 values to zero, so the guarantee holds for inputs that are 0
or at least 1e-30 in magnitude (no error term of the arithmetic is subnormal). Host-side float64
values (YAML origins such as -15.1, a costmap resolution of 0.05) are *not*
rounded: `validate.split_float64` splits each into three float32 parts whose exact sum
is the double (24 + 24 + 5 bits cover its 53), and the exact arithmetic takes
the parts as extra terms. So a floor decided from Nav2's doubles (the costmap
origin and resolution, the mask origin; the mask resolution is float32 in
nav_msgs) is the floor Nav2 computes (spec §4.3's coarse-mask example: 21 with
the decimal 0.05). Poses stay float32 inputs.

The keepout filter's different-frame path rotates cell centres in float32
before this exact floor (Nav2 rotates in float64), so a cell whose centre maps
within about 1e-6 m of a mask cell boundary can pick the neighbouring mask cell;
see jaxfilters/keepout.py.
"""

from __future__ import annotations

from collections.abc import Sequence

import jax
import jax.numpy as jnp

_F32 = jnp.float32


def two_sum(a: jax.Array, b: jax.Array) -> tuple[jax.Array, jax.Array]:
  """Knuth's error-free sum: s + e == a + b exactly, s = fl(a + b)."""
  s = a + b
  bb = s - a
  e = (a - (s - bb)) + (b - bb)
  return s, e


def split12(x: jax.Array) -> tuple[jax.Array, jax.Array]:
  """Splits float32 x into hi + lo, each with at most 12 significant bits (exact)."""
  x = x.astype(_F32)
  bits = jax.lax.bitcast_convert_type(x, jnp.uint32) & jnp.uint32(0xFFFFF000)
  hi = jax.lax.bitcast_convert_type(bits, _F32)
  return hi, x - hi


def exact_product(a: jax.Array, b: jax.Array) -> list[jax.Array]:
  """Four float32 terms whose exact sum is a * b (each partial product is exact)."""
  ah, al = split12(a)
  bh, bl = split12(b)
  return [ah * bh, ah * bl, al * bh, al * bl]


def expansion_sign(terms: Sequence[jax.Array]) -> jax.Array:
  """Exact sign (-1, 0, +1 as int32) of the real sum of float32 terms.

  Grow-Expansion (Shewchuk 1997): the components stay non-overlapping and
  ordered by magnitude, so the sign of the sum is the sign of the largest
  non-zero component.
  """
  terms = [jnp.asarray(t, _F32) for t in terms]
  expansion = [terms[0]]
  for t in terms[1:]:
    q = t
    grown = []
    for comp in expansion:
      q, h = two_sum(q, comp)
      grown.append(h)
    grown.append(q)
    expansion = grown
  sign = jnp.zeros(jnp.shape(expansion[0]), jnp.int32)
  for comp in expansion:
    sign = jnp.where(comp != 0, jnp.sign(comp).astype(jnp.int32), sign)
  return sign


def _as_terms(res) -> list[jax.Array]:
  if isinstance(res, (list, tuple)):
    return [jnp.asarray(r, _F32) for r in res]
  return [jnp.asarray(res, _F32)]


def floor_div_exact(num_terms: Sequence[jax.Array], res) -> jax.Array:
  """Exact floor(sum(num_terms) / res) as int32, for res > 0 and |quotient| < 2**22.

  `res` is one float32 array or a list of float32 parts whose exact sum is the
  divisor (a host double carried as `split_float64` parts). Both candidate
  checks (q0 and q0 + 1) run as one stacked expansion, which halves the traced
  program (compile time matters: this sits in every filter).
  """
  num_terms = [jnp.asarray(t, _F32) for t in num_terms]
  res_terms = _as_terms(res)
  shape = jnp.broadcast_shapes(*[r.shape for r in res_terms], *[t.shape for t in num_terms])
  num_terms = [jnp.broadcast_to(t, shape) for t in num_terms]
  res_terms = [jnp.broadcast_to(r, shape) for r in res_terms]
  approx = num_terms[0]
  for t in num_terms[1:]:
    approx = approx + t
  q0 = jnp.floor(approx / res_terms[0])
  q0 = jnp.where(jnp.isfinite(q0), q0, 0.0)
  cands = jnp.stack([q0, q0 + 1.0])
  terms = [jnp.stack([t, t]) for t in num_terms]
  for r in res_terms:
    terms += [-p for p in exact_product(cands, jnp.stack([r, r]))]
  signs = expansion_sign(terms)
  below, above = signs[0] < 0, signs[1] >= 0
  q = jnp.where(below, q0 - 1.0, jnp.where(above, q0 + 1.0, q0))
  return q.astype(jnp.int32)


def trunc_div_exact(num_terms: Sequence[jax.Array], res) -> jax.Array:
  """Exact trunc(sum / res) toward zero as int32 (C++ `static_cast<int>`)."""
  num_terms = [jnp.asarray(t, _F32) for t in num_terms]
  negative = expansion_sign(num_terms) < 0
  q = floor_div_exact([jnp.where(negative, -t, t) for t in num_terms], res)
  return jnp.where(negative, -q, q)


def transform_points(transform: jax.Array, x: jax.Array, y: jax.Array) -> tuple[jax.Array, jax.Array]:
  """Applies an SE2 transform (tx, ty, yaw) to points (float32): R(yaw) p + t."""
  c, s = jnp.cos(transform[2]), jnp.sin(transform[2])
  return c * x - s * y + transform[0], s * x + c * y + transform[1]


def origin_terms(origin: jax.Array, origin_lo: jax.Array | None) -> list[jax.Array]:
  """Float32 terms [2]-shaped whose exact sum is the host origin (x, y).

  Args:
    origin: float32 [2], the float32 rounding of the origin (the `hi` part).
    origin_lo: None (the origin is exactly float32) or float32 [2, 2], the
      (mid, lo) parts from `validate.split_float64`.
  """
  terms = [jnp.asarray(origin, _F32)]
  if origin_lo is not None:
    terms += [jnp.asarray(origin_lo, _F32)[:, 0], jnp.asarray(origin_lo, _F32)[:, 1]]
  return terms


def resolution_terms(resolution: jax.Array, resolution_lo: jax.Array | None) -> list[jax.Array]:
  """Float32 parts whose exact sum is the host resolution (see `origin_terms`)."""
  terms = [jnp.asarray(resolution, _F32)]
  if resolution_lo is not None:
    lo = jnp.asarray(resolution_lo, _F32)
    terms += [lo[..., 0], lo[..., 1]]
  return terms


def world_to_cell(wx: jax.Array, wy: jax.Array, origin, resolution: jax.Array,
                  width: int, height: int, origin_lo: jax.Array | None = None
                  ) -> tuple[jax.Array, jax.Array, jax.Array]:
  """Nav2 `worldToMap` (spec §2.2): bounded, half-open [o, o + size*res).

  Args:
    wx, wy: float32 world coordinates (any matching shape).
    origin: float32 [2], lower-left corner of cell (0, 0), or a list of [2]
      float32 parts whose exact sum is the origin.
    resolution: float32 scalar, metres per cell.
    width, height: grid size in cells (static).
    origin_lo: optional float32 [2, 2] extra parts of a float64 origin
      (`validate.split_float64`); the comparison and the floor then use the double.

  Returns:
    (mx, my, valid): int32 cells (clipped into the grid so they can index it)
    and a bool that is False off the grid or for a non-finite point.
  """
  wx = jnp.asarray(wx, _F32)
  wy = jnp.asarray(wy, _F32)
  wx, wy = jnp.broadcast_arrays(wx, wy)
  parts = _as_terms(origin)
  if origin_lo is not None:
    parts += origin_terms(parts[0], origin_lo)[1:]
  o_terms = [-jnp.stack([jnp.broadcast_to(t[0], wx.shape), jnp.broadcast_to(t[1], wx.shape)])
             for t in parts]
  terms = [jnp.stack([wx, wy]), *o_terms]
  mx, my = floor_div_exact(terms, resolution)
  if len(parts) == 1:
    inside_lo = (wx >= parts[0][0]) & (wy >= parts[0][1])
  else:
    nonneg = expansion_sign(terms) >= 0
    inside_lo = nonneg[0] & nonneg[1]
  valid = inside_lo & (mx < width) & (my < height) & jnp.isfinite(wx) & jnp.isfinite(wy)
  return (jnp.clip(mx, 0, width - 1), jnp.clip(my, 0, height - 1), valid)


def cell_centre_terms(index: jax.Array, origin, resolution) -> list[jax.Array]:
  """Float32 terms summing exactly to the world centre origin + (index + 0.5) * res.

  `origin` and `resolution` are float32 arrays or lists of parts (host doubles).
  """
  half_steps = 2.0 * jnp.asarray(index, _F32) + 1.0      # exact for index < 2**23
  terms = list(_as_terms(origin))
  for r in _as_terms(resolution):
    terms += exact_product(half_steps, 0.5 * r)
  return terms


def centres_to_cells_2d(shape: tuple[int, int], origin, resolution,
                        target_origin, target_resolution: jax.Array,
                        target_shape: tuple[int, int]):
  """Maps the cell centres of a grid's columns and rows onto another grid's cells.

  For same-frame grids the x and y mappings are separable, so the 2-D lookup is
  a gather with two 1-D index vectors computed exactly once per robot; both
  axes run as one stacked exact division.

  Args:
    shape: (H, W) of the source grid; origin [2] (or a list of [2] parts),
      resolution [] (or a list of [] parts) its geometry.
    target_origin [2] (or parts), target_resolution [], target_shape (Ht, Wt):
      the target grid.

  Returns:
    ((mx int32 [W], vx bool [W]), (my int32 [H], vy bool [H])).
  """
  h, w = shape
  ht, wt = target_shape
  n = max(h, w)
  i = jnp.arange(n, dtype=_F32)
  idx = jnp.stack([i, i])
  per_axis = lambda o: jnp.stack([jnp.full((n,), o[0], _F32), jnp.full((n,), o[1], _F32)])
  o = [per_axis(t) for t in _as_terms(origin)]
  res = [jnp.broadcast_to(r, idx.shape) for r in _as_terms(resolution)]
  terms = cell_centre_terms(idx, o, res) + [-per_axis(t) for t in _as_terms(target_origin)]
  cells = floor_div_exact(terms, target_resolution)
  nonneg = expansion_sign(terms) >= 0
  size = jnp.asarray([[wt], [ht]], jnp.int32)
  valid = nonneg & (cells < size)
  cells = jnp.clip(cells, 0, size - 1)
  return (cells[0, :w], valid[0, :w]), (cells[1, :h], valid[1, :h])
