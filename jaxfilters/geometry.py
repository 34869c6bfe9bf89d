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
values (YAML origins such as -15.1) are rounded to float32 once when a mask or
costmap is built; the reference tests use those rounded values.

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


def floor_div_exact(num_terms: Sequence[jax.Array], res: jax.Array) -> jax.Array:
  """Exact floor(sum(num_terms) / res) as int32, for res > 0 and |quotient| < 2**22.

  Both candidate checks (q0 and q0 + 1) run as one stacked expansion, which
  halves the traced program (compile time matters: this sits in every filter).
  """
  num_terms = [jnp.asarray(t, _F32) for t in num_terms]
  res = jnp.asarray(res, _F32)
  shape = jnp.broadcast_shapes(res.shape, *[t.shape for t in num_terms])
  num_terms = [jnp.broadcast_to(t, shape) for t in num_terms]
  res = jnp.broadcast_to(res, shape)
  approx = num_terms[0]
  for t in num_terms[1:]:
    approx = approx + t
  q0 = jnp.floor(approx / res)
  q0 = jnp.where(jnp.isfinite(q0), q0, 0.0)
  cands = jnp.stack([q0, q0 + 1.0])
  terms = [jnp.stack([t, t]) for t in num_terms] + [-p for p in exact_product(cands, jnp.stack([res, res]))]
  signs = expansion_sign(terms)
  below, above = signs[0] < 0, signs[1] >= 0
  q = jnp.where(below, q0 - 1.0, jnp.where(above, q0 + 1.0, q0))
  return q.astype(jnp.int32)


def trunc_div_exact(num_terms: Sequence[jax.Array], res: jax.Array) -> jax.Array:
  """Exact trunc(sum / res) toward zero as int32 (C++ `static_cast<int>`)."""
  num_terms = [jnp.asarray(t, _F32) for t in num_terms]
  negative = expansion_sign(num_terms) < 0
  q = floor_div_exact([jnp.where(negative, -t, t) for t in num_terms], res)
  return jnp.where(negative, -q, q)


def transform_points(transform: jax.Array, x: jax.Array, y: jax.Array) -> tuple[jax.Array, jax.Array]:
  """Applies an SE2 transform (tx, ty, yaw) to points (float32): R(yaw) p + t."""
  c, s = jnp.cos(transform[2]), jnp.sin(transform[2])
  return c * x - s * y + transform[0], s * x + c * y + transform[1]


def world_to_cell(wx: jax.Array, wy: jax.Array, origin: jax.Array, resolution: jax.Array,
                  width: int, height: int) -> tuple[jax.Array, jax.Array, jax.Array]:
  """Nav2 `worldToMap` (spec §2.2): bounded, half-open [o, o + size*res).

  Args:
    wx, wy: float32 world coordinates (any matching shape).
    origin: float32 [2], lower-left corner of cell (0, 0).
    resolution: float32 scalar, metres per cell.
    width, height: grid size in cells (static).

  Returns:
    (mx, my, valid): int32 cells (clipped into the grid so they can index it)
    and a bool that is False off the grid or for a non-finite point.
  """
  wx = jnp.asarray(wx, _F32)
  wy = jnp.asarray(wy, _F32)
  wx, wy = jnp.broadcast_arrays(wx, wy)
  ox, oy = origin[0].astype(_F32), origin[1].astype(_F32)
  o = jnp.stack([jnp.broadcast_to(ox, wx.shape), jnp.broadcast_to(oy, wx.shape)])
  mx, my = floor_div_exact([jnp.stack([wx, wy]), -o], resolution)
  valid = ((wx >= ox) & (wy >= oy) & (mx < width) & (my < height)
           & jnp.isfinite(wx) & jnp.isfinite(wy))
  return (jnp.clip(mx, 0, width - 1), jnp.clip(my, 0, height - 1), valid)


def cell_centre_terms(index: jax.Array, origin: jax.Array, resolution: jax.Array) -> list[jax.Array]:
  """Float32 terms summing exactly to the world centre origin + (index + 0.5) * res."""
  half_steps = 2.0 * jnp.asarray(index, _F32) + 1.0      # exact for index < 2**23
  return [jnp.asarray(origin, _F32), *exact_product(half_steps, 0.5 * jnp.asarray(resolution, _F32))]


def centres_to_cells_2d(shape: tuple[int, int], origin: jax.Array, resolution: jax.Array,
                        target_origin: jax.Array, target_resolution: jax.Array,
                        target_shape: tuple[int, int]):
  """Maps the cell centres of a grid's columns and rows onto another grid's cells.

  For same-frame grids the x and y mappings are separable, so the 2-D lookup is
  a gather with two 1-D index vectors computed exactly once per robot; both
  axes run as one stacked exact division.

  Args:
    shape: (H, W) of the source grid; origin [2], resolution [] its geometry.
    target_origin [2], target_resolution [], target_shape (Ht, Wt): the target grid.

  Returns:
    ((mx int32 [W], vx bool [W]), (my int32 [H], vy bool [H])).
  """
  h, w = shape
  ht, wt = target_shape
  n = max(h, w)
  i = jnp.arange(n, dtype=_F32)
  idx = jnp.stack([i, i])
  o = jnp.stack([jnp.full((n,), origin[0], _F32), jnp.full((n,), origin[1], _F32)])
  to = jnp.stack([jnp.full((n,), target_origin[0], _F32), jnp.full((n,), target_origin[1], _F32)])
  res = jnp.broadcast_to(jnp.asarray(resolution, _F32), idx.shape)
  terms = cell_centre_terms(idx, o, res) + [-to]
  cells = floor_div_exact(terms, target_resolution)
  nonneg = expansion_sign(terms) >= 0
  size = jnp.asarray([[wt], [ht]], jnp.int32)
  valid = nonneg & (cells < size)
  cells = jnp.clip(cells, 0, size - 1)
  return (cells[0, :w], valid[0, :w]), (cells[1, :h], valid[1, :h])
