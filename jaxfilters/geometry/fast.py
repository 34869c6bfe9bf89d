"""Internal: fast paths that decide the exact floors in a few float32 operations, and prove it.

Part of `jaxfilters.geometry`; import it from there.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxfilters.geometry.exact import as_terms, exact_product, split12, two_sum

_F32 = jnp.float32


# ----------------------------------------------------------------------------- fast paths
#
# The exact arithmetic above costs a few hundred float32 operations per index. The keepout
# filter's fast paths decide most indices with a handful instead, and prove when they may:
# every helper below returns, beside its answer, a flag that is True only where the answer
# is the one `floor_div_exact` / `world_to_cell` give; the caller runs the exact arithmetic
# where the flag is False. The bounds assume float32 round-to-nearest for + - * (XLA on CPU
# and GPU), allow a division error up to 2**-21 relative (2 ulp, looser than IEEE) and
# absorb flush-to-zero: each flushed result errs by less than 2**-126, which `_TINY` covers
# many times over for resolutions >= 2**-100 (smaller ones are never trusted).

_U = 2.0 ** -24          # unit roundoff of float32
_TINY = 2.0 ** -100      # absolute slack for flush-to-zero errors
_MIN_RES = 2.0 ** -100   # a fast bound is only trusted for resolutions at least this large


def rounded_product(a: jax.Array, b: jax.Array) -> jax.Array:
  """A float32 product that FMA contraction cannot change: a * b summed from its exact parts.

  XLA fuses a product with a following sum into one FMA in some programs and not in
  others, so `a * b + c` can take two values an ulp apart within one jitted program.
  Here the four partial products of `exact_product` are exact, so contracting any of
  them with a sum changes nothing, and their sum, small terms first, is the same float32
  on every backend and in every fusion: within (1/2 + 2**-11) ulp of the real product.
  """
  p = exact_product(a, b)
  return p[0] + ((p[1] + p[2]) + p[3])


def quotient_bracket(num: jax.Array, num_err: jax.Array, resolution) -> tuple[jax.Array, jax.Array]:
  """Float32 bounds (lo, hi) with lo <= N / res <= hi for any real N within num_err of num.

  Proof: q = fl(num / res) errs from num / res by at most 8u|num / res| (u = 2**-24;
  2 ulp covers a non-IEEE division) plus a flushed subnormal (< 2**-126), so
  |q - N / res| <= 8u|num / res| + num_err / res + 2**-126. The half-width used,
  eps = 2 num_err / res + 16u|q| + 2**-20, exceeds that by more than the rounding of
  eps itself and of q -+ eps (each at most u|q| + u eps), so fl(q - eps) <= N / res <=
  fl(q + eps). NaN or inf in, NaN or inf out (callers treat that as undecided).

  Args:
    num: float32 array, an approximation of the numerator.
    num_err: float32 array (broadcasts with num), a bound on |num - N|.
    resolution: float32 scalar or array > 0, the divisor (exact float32 value).

  Returns:
    (lo, hi) float32 arrays.
  """
  r = jnp.asarray(resolution, _F32)
  q = num / r
  eps = 2.0 * num_err / r + 16.0 * _U * jnp.abs(q) + 2.0 ** -20
  eps = jnp.where(r >= _MIN_RES, eps, jnp.inf)
  return q - eps, q + eps


def floor_bracket(num: jax.Array, num_err: jax.Array, resolution) -> tuple[jax.Array, jax.Array]:
  """Floors of `quotient_bracket`: lo <= floor(N / res) <= hi (the floor is known where equal)."""
  lo, hi = quotient_bracket(num, num_err, resolution)
  return jnp.floor(lo), jnp.floor(hi)


def centre_floor_bracket(index: jax.Array, origin, resolution, target_origin, target_resolution):
  """Brackets the exact floor(((origin + (index + 0.5) res) - target_origin) / target_res).

  The float32 estimate c = fl(fl(o0 - t0) + fl((index + 0.5) r0)) uses the leading
  parts of the host doubles; |c - N| <= u(|a| + |p| + |c|) + (the other parts, the
  resolution's multiplied by index + 0.5) + 3 flushed subnormals, and `floor_bracket`
  turns that into floors (the 2**-20 it adds covers the flushes).

  Args:
    index: float32 array of cell indices (< 2**23).
    origin, resolution: the source grid's, float32 arrays or lists of float32 parts
      broadcasting with index (exact sums are the host doubles).
    target_origin, target_resolution: the target grid's (parts for the origin; the
      resolution is one float32 value, nav_msgs' type).

  Returns:
    (lo, hi) float32 floors, lo <= exact floor <= hi; the floor is known where lo == hi.
  """
  o, r, t = as_terms(origin), as_terms(resolution), as_terms(target_origin)
  h = jnp.asarray(index, _F32) + 0.5
  p = h * r[0]
  a = o[0] - t[0]
  c = a + p
  err = _U * (jnp.abs(a) + jnp.abs(p) + jnp.abs(c))
  for extra in o[1:] + t[1:]:
    err = err + jnp.abs(extra)
  for extra in r[1:]:
    err = err + h * jnp.abs(extra)
  return floor_bracket(c, err, target_resolution)


def _floor_checked(x, origin, resolution, size: int):
  """`floor_div_checked` before clipping: (k float32, inside, certain); see there."""
  if not 0 < size <= 2 ** 17:
    raise ValueError(f"floor_div_checked needs 0 < size <= 2**17; got {size}")
  parts = as_terms(origin)
  r = jnp.asarray(resolution, _F32)
  x = jnp.asarray(x, _F32)
  s, e = two_sum(x, -parts[0])
  n = jnp.round(jnp.clip(s * (1.0 / r), -1.0, size + 1.0))   # NaN stays NaN: undecided
  if size + 1 < 2 ** 12:                               # n and the halves of res: 12 bits each
    rh, rl = split12(r)
    prods = [n * rh, n * rl]
  else:
    rl = split12(r)[1]
    prods = exact_product(n, r)
  t = s - prods[0]
  small = jnp.abs(e)
  if len(prods) == 2:
    t = (t - prods[1]) + e
  else:
    t, e2 = two_sum(t, -prods[1])
    t, e3 = two_sum(t, -prods[2])
    t = (((t - prods[3]) + e) + e2) + e3
    small = small + jnp.abs(e2) + jnp.abs(e3)
  rest = jnp.abs(rl)
  for o in parts[1:]:
    t = t - o
    rest = rest + jnp.abs(o)
  guard = (r >= _MIN_RES) & (rest <= r * 0.0625)
  certain = (jnp.abs(t) > 2.0 ** -21 * (small + rest) + _TINY) & guard
  k = jnp.where(t < 0, n - 1.0, n)
  return k, (k >= 0) & (k < size), certain


def floor_div_checked(x: jax.Array, origin, resolution, size: int):
  """floor((x - origin) / res) of float32 x in about 30 float32 operations, and whether it is proven.

  With s + e = x - o0 exactly (`two_sum`) and n = round(s * fl(1 / res)) clipped into
  [-1, size + 1], the residual R = (x - origin) - n res decides: the floor is n where
  R >= 0, else n - 1, provided |real quotient - n| < 1; and where the estimate was
  clipped, the point is off the grid on that side either way (k then lands outside
  [0, size) too). The parts of n res are exact products (12-bit halves); s minus the
  leading one is exact (Sterbenz) for |n| >= 2 or n = 0, and for |n| = 1 errs by at
  most u(|T| + |rl| + S) (rl the low half of res); the at most 7 other float32
  operations each err by at most u|their result| <= u(|T| + S), T being the computed
  residual and S the small terms added last (e, two_sum errors, the origin's other
  parts). So |T - R| <= 8u(|T| + |rl| + S) (u = 2**-24) plus flushes, and
  |T| > 2**-21 (S + |rl|) + 2**-100 proves sign(T) = sign(R). The quotient condition:
  with |n| <= size + 1 <= 2**17 + 1 the reciprocal estimate errs by < 0.05 and the
  guard (|o1| + |o2|) / res <= 1/16 bounds the left-out parts. Undecided are only
  residuals within about 1e-13 relative of 0 (in practice a point exactly on a cell
  edge) and NaN or inf.

  Args:
    x: float32 array. origin: float32 scalar or list of float32 parts (exact sum).
    resolution: float32 scalar > 0. size: static cell count on this axis, <= 2**17.

  Returns:
    (k int32 clipped into [0, size), inside bool: 0 <= floor < size, certain bool: k
    and inside are proven).
  """
  k, inside, certain = _floor_checked(x, origin, resolution, size)
  return jnp.clip(k, 0, size - 1).astype(jnp.int32), inside, certain


def world_to_cell_checked(wx: jax.Array, wy: jax.Array, origin, resolution, width: int, height: int):
  """`world_to_cell` through `floor_div_checked`: (mx, my, valid, certain).

  Where `certain` is True, (mx, my, valid) equal `world_to_cell`'s for the same
  inputs (the cell, and whether the point is on the grid); elsewhere they are
  unproven and the caller must use `world_to_cell`. A coordinate that is proven
  off the grid makes the point certain whatever the other coordinate is.

  Args:
    wx, wy: float32 arrays of one shape. origin: float32 [2] or a list of [2] parts.
    resolution: float32 scalar. width, height: static grid size, each <= 2**17.
  """
  parts = as_terms(origin)
  mx, vx, cx = floor_div_checked(wx, [p[0] for p in parts], resolution, width)
  my, vy, cy = floor_div_checked(wy, [p[1] for p in parts], resolution, height)
  return mx, my, vx & vy, (cx & cy) | (cx & ~vx) | (cy & ~vy)


def world_to_index_checked(wx: jax.Array, wy: jax.Array, origin, resolution, width: int, height: int):
  """`world_to_cell_checked` as a row-major flat index: (my * width + mx int32, valid, certain).

  The index is meaningful only where valid (computed in float32, exact below 2**24
  cells); fewer operations per point than clipping both coordinates. `certain`
  needs both coordinates proven (a point proven off the grid in one of them but
  undecided in the other, which `world_to_cell_checked` calls certain, is left to
  the caller's exact path: rarer than 1 in 10**7 points, and one operation less per point).
  """
  if width * height >= 2 ** 24:
    raise ValueError(f"world_to_index_checked needs width * height < 2**24; got {width} x {height}")
  parts = as_terms(origin)
  kx, vx, cx = _floor_checked(wx, [p[0] for p in parts], resolution, width)
  ky, vy, cy = _floor_checked(wy, [p[1] for p in parts], resolution, height)
  valid = vx & vy
  index = jnp.where(valid, ky * width + kx, 0.0).astype(jnp.int32)
  return index, valid, cx & cy
