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

The fast-path helpers at the end of this module (`rounded_product`,
`quotient_bracket`, `floor_bracket`, `centre_floor_bracket`,
`floor_div_checked`, `world_to_cell_checked`, `world_to_index_checked`,
`expansion_sign_rolled`) decide the same integers with far fewer operations and
say where they could not.
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
  expansion = _expansion([jnp.asarray(t, _F32) for t in terms])
  sign = jnp.zeros(jnp.shape(expansion[0]), jnp.int32)
  for comp in expansion:
    sign = jnp.where(comp != 0, jnp.sign(comp).astype(jnp.int32), sign)
  return sign


def expansion_sign_rolled(terms: Sequence[jax.Array]) -> jax.Array:
  """`expansion_sign` with the outer loop rolled (`lax.fori_loop`): the same exact sign.

  The unrolled version is a program of n**2 / 2 error-free sums that XLA takes seconds
  to compile for the ~23 terms of the keepout window clip; this one compiles n of them
  and runs n short turns (the expansion keeps slots for all n components; slots not yet
  reached hold 0, and two_sum(q, 0) = (q, 0) leaves them so).
  """
  terms = [jnp.asarray(t, _F32) for t in terms]
  shape = jnp.broadcast_shapes(*[t.shape for t in terms])
  t = jnp.stack([jnp.broadcast_to(x, shape) for x in terms])
  n = t.shape[0]

  def grow(k, e):
    q = t[k]
    comps = []
    for i in range(n):
      q, h = two_sum(q, e[i])
      comps.append(h)
    return jnp.stack(comps).at[k].set(q)

  e = jax.lax.fori_loop(1, n, grow, jnp.zeros_like(t).at[0].set(t[0]))
  sign = jnp.zeros(shape, jnp.int32)
  for i in range(n):
    sign = jnp.where(e[i] != 0, jnp.sign(e[i]).astype(jnp.int32), sign)
  return sign


def as_terms(res) -> list[jax.Array]:
  if isinstance(res, (list, tuple)):
    return [jnp.asarray(r, _F32) for r in res]
  return [jnp.asarray(res, _F32)]


def floor_div_exact(num_terms: Sequence[jax.Array], res, *, sign_fn=expansion_sign) -> jax.Array:
  """Exact floor(sum(num_terms) / res) as int32, for res > 0 and |quotient| < 2**22.

  `res` is one float32 array or a list of float32 parts whose exact sum is the
  divisor (a host double carried as `split_float64` parts). Both candidate
  checks (q0 and q0 + 1) run as one stacked expansion, which halves the traced
  program (compile time matters: this sits in every filter). `sign_fn` may be
  `expansion_sign_rolled` (same results, far less to compile, slower to run).
  """
  num_terms = [jnp.asarray(t, _F32) for t in num_terms]
  res_terms = as_terms(res)
  shape = jnp.broadcast_shapes(*[r.shape for r in res_terms], *[t.shape for t in num_terms])
  num_terms = [jnp.broadcast_to(t, shape) for t in num_terms]
  res_terms = [jnp.broadcast_to(r, shape) for r in res_terms]
  approx = num_terms[0]
  for t in num_terms[1:]:
    approx = approx + t
  q0 = jnp.floor(approx / res_terms[0])
  # A quotient beyond float32 (|x| > ~1e37 m at 5 cm) used to restart from 0 and come
  # out as cell 1; start it far off every grid instead (NaN still starts from 0).
  q0 = jnp.where(jnp.isfinite(q0), q0, jnp.where(jnp.isnan(q0), 0.0, jnp.sign(q0) * 2.0 ** 30))
  cands = jnp.stack([q0, q0 + 1.0])
  terms = [jnp.stack([t, t]) for t in num_terms]
  for r in res_terms:
    terms += [-p for p in exact_product(cands, jnp.stack([r, r]))]
  signs = sign_fn(terms)
  below, above = signs[0] < 0, signs[1] >= 0
  q = jnp.where(below, q0 - 1.0, jnp.where(above, q0 + 1.0, q0))
  return q.astype(jnp.int32)


def trunc_div_exact(num_terms: Sequence[jax.Array], res, *, sign_fn=expansion_sign) -> jax.Array:
  """Exact trunc(sum / res) toward zero as int32 (C++ `static_cast<int>`); `sign_fn` as floor_div_exact."""
  num_terms = [jnp.asarray(t, _F32) for t in num_terms]
  negative = sign_fn(num_terms) < 0
  q = floor_div_exact([jnp.where(negative, -t, t) for t in num_terms], res, sign_fn=sign_fn)
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
  parts = as_terms(origin)
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
  terms = list(as_terms(origin))
  for r in as_terms(resolution):
    terms += exact_product(half_steps, 0.5 * r)
  return terms


def centres_to_cells_2d(shape: tuple[int, int], origin, resolution,
                        target_origin, target_resolution: jax.Array,
                        target_shape: tuple[int, int], *, sign_fn=expansion_sign):
  """Maps the cell centres of a grid's columns and rows onto another grid's cells.

  For same-frame grids the x and y mappings are separable, so the 2-D lookup is
  a gather with two 1-D index vectors computed exactly once per robot; both
  axes run as one stacked exact division.

  Args:
    shape: (H, W) of the source grid; origin [2] (or a list of [2] parts),
      resolution [] (or a list of [] parts) its geometry.
    target_origin [2] (or parts), target_resolution [], target_shape (Ht, Wt):
      the target grid.
    sign_fn: as `floor_div_exact` (same integers either way).

  Returns:
    ((mx int32 [W], vx bool [W]), (my int32 [H], vy bool [H])).
  """
  h, w = shape
  ht, wt = target_shape
  n = max(h, w)
  i = jnp.arange(n, dtype=_F32)
  idx = jnp.stack([i, i])
  per_axis = lambda o: jnp.stack([jnp.full((n,), o[0], _F32), jnp.full((n,), o[1], _F32)])
  o = [per_axis(t) for t in as_terms(origin)]
  res = [jnp.broadcast_to(r, idx.shape) for r in as_terms(resolution)]
  terms = cell_centre_terms(idx, o, res) + [-per_axis(t) for t in as_terms(target_origin)]
  cells = floor_div_exact(terms, target_resolution, sign_fn=sign_fn)
  nonneg = sign_fn(terms) >= 0
  size = jnp.asarray([[wt], [ht]], jnp.int32)
  valid = nonneg & (cells < size)
  cells = jnp.clip(cells, 0, size - 1)
  return (cells[0, :w], valid[0, :w]), (cells[1, :h], valid[1, :h])


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


# ----------------------------------------------------------------------------- edge thresholds
#
# A float32 point x lies at or above a grid edge e (a real number) iff x >= T, where T is the
# smallest float32 >= e. So the exact floor((x - origin) / res) of a float32 x needs no
# arithmetic on x beyond an estimate good to one cell: a table of the thresholds T_n of the
# edges origin + n res (n = 0..size), computed exactly once per grid, settles the rest with two
# float32 comparisons, which round nothing. `edge_thresholds` builds the table,
# `floor_by_edges` reads it.

_EDGE_MIN_RES = 2.0 ** -40    # edge tables are trusted only for resolutions in [2**-40, 2**60],
_EDGE_MAX_RES = 2.0 ** 60
_EDGE_MIN_T = 2.0 ** -102     # thresholds 0 or with a magnitude in [2**-102, 2**100]
_EDGE_MAX_T = 2.0 ** 100


def float32_key(x: jax.Array) -> jax.Array:
  """int32 keys ordered like the float32 values (-0 and +0 share key 0; NaN unordered).

  Consecutive keys are consecutive float32 values, so key + 1 is the next float up.
  """
  b = jax.lax.bitcast_convert_type(jnp.asarray(x, _F32), jnp.int32)
  return jnp.where(b < 0, -(b & jnp.int32(0x7FFFFFFF)), b)


def key_float32(k: jax.Array) -> jax.Array:
  """The inverse of `float32_key` (key 0 gives +0)."""
  k = jnp.asarray(k, jnp.int32)
  b = jnp.where(k < 0, (-k) | jnp.int32(-2 ** 31), k)
  return jax.lax.bitcast_convert_type(b, _F32)


def _expansion(terms):
  """Grow-Expansion (Shewchuk 1997) of float32 terms: components, increasing magnitude, exact sum."""
  expansion = [terms[0]]
  for t in terms[1:]:
    q = t
    grown = []
    for comp in expansion:
      q, h = two_sum(q, comp)
      grown.append(h)
    grown.append(q)
    expansion = grown
  return expansion


def _expansion_estimate(terms):
  """A float32 close to the exact sum: the expansion's components added smallest first."""
  total = jnp.zeros_like(terms[0])
  for comp in _expansion(terms):
    total = total + comp
  return total


def edge_thresholds(origin, resolution, size: int) -> tuple[jax.Array, jax.Array]:
  """The float32 thresholds of a grid axis's edges, exact, with a flag saying they are.

  Entry n + 1 of the table (n = 0..size) is T_n, the smallest float32 >= origin + n res
  (real arithmetic on the float32 parts: a host double origin is carried exactly); entry 0
  is -inf and entry size + 2 is +inf, so the table has size + 3 entries and
  `floor_by_edges` never reads past it.

  Each T_n is found by testing five consecutive float32 values around an estimate
  (`_expansion_estimate`, refined once on its own residual) with the exact sign of
  v - (origin + n res) (`expansion_sign`): T_n is the first that is not below the edge,
  and the table is trusted only where the first is below and the last is not, so an
  estimate that missed can only make the table untrusted, never wrong. An edge exactly
  at 0 gives T_n = 0 (x >= 0 iff x >= the edge, for x = -0 too).

  The signs are exact when no sum or error term of the expansion is subnormal (XLA
  flushes those): that holds when every term is a multiple of 2**-126 (then so is every
  exact sum and error, and a non-zero one is at least 2**-126). A float32 of magnitude
  2**-102 or more is such a multiple. `trusted` demands what makes that so and what
  `floor_by_edges`' proof needs: res in [2**-40, 2**60] (the products n res are then
  multiples of 2**-63), each origin part a multiple of 2**-126, the origin's lower parts
  at most res / 4, and every T_n 0 or of a magnitude in [2**-102, 2**100] (so are the
  candidates tested beside it). Grids outside that (none that a map file describes)
  must use the exact arithmetic.

  Args:
    origin: float32 [...] (one axis of the origin, for a batch of grids) or a list of
      float32 parts whose exact sum is the origin.
    resolution: float32 [...] > 0, the grids' resolutions.
    size: static number of cells on this axis (< 2**24).

  Returns:
    (table float32 [..., size + 3], trusted bool [...]).
  """
  if not 0 < size < 2 ** 24:
    raise ValueError(f"edge_thresholds needs 0 < size < 2**24; got {size}")
  parts = [jnp.asarray(t, _F32) for t in as_terms(origin)]
  r = jnp.asarray(resolution, _F32)
  shape = jnp.broadcast_shapes(r.shape, *[p.shape for p in parts])
  parts = [jnp.broadcast_to(p, shape)[..., None] for p in parts]
  r = jnp.broadcast_to(r, shape)[..., None]
  full = shape + (size + 1,)
  n = jnp.broadcast_to(jnp.arange(size + 1, dtype=_F32), full)
  parts = [jnp.broadcast_to(p, full) for p in parts]
  terms = parts + exact_product(n, jnp.broadcast_to(r, full))
  c = _expansion_estimate(terms)
  c = c + _expansion_estimate(terms + [-c])
  k = float32_key(c)
  steps = jnp.arange(-2, 3, dtype=jnp.int32).reshape((5,) + (1,) * k.ndim)
  cand = key_float32(k[None] + steps)
  below = expansion_sign([cand] + [-jnp.broadcast_to(t, cand.shape) for t in terms]) < 0
  t_n = key_float32(k - 2 + jnp.sum(below.astype(jnp.int32), axis=0))
  found = below[0] & ~below[-1]
  zero = expansion_sign(terms) == 0
  t_n = jnp.where(zero, jnp.float32(0), t_n)
  good = (found & (jnp.abs(t_n) >= _EDGE_MIN_T) & (jnp.abs(t_n) <= _EDGE_MAX_T)) | zero
  part_ok = jnp.ones(shape, bool)
  for p in parts:      # a multiple of 2**-126: every float32 of at least 2**-102 is one
    p = p[..., 0]
    scaled = jnp.where(jnp.abs(p) < _EDGE_MIN_T, p, 0.0) * jnp.float32(2.0 ** 126)
    part_ok = part_ok & (jnp.floor(scaled) == scaled)
  lower = sum((jnp.abs(p[..., 0]) for p in parts[1:]), jnp.zeros(shape, _F32))
  r0 = r[..., 0]
  trusted = (jnp.all(good, axis=-1) & part_ok & (r0 >= _EDGE_MIN_RES) & (r0 <= _EDGE_MAX_RES)
             & (lower <= 0.25 * r0))
  inf = jnp.full(shape + (1,), jnp.inf, _F32)
  return jnp.concatenate([-inf, t_n, inf], axis=-1), trusted


def edge_reciprocal(resolution: jax.Array) -> tuple[jax.Array, jax.Array]:
  """(fl(1 / res), ok): ok where the reciprocal is within 9 float32 rounding units of 1 / res.

  The product fl(inv * res) is checked against 1 (within 2**-21), so a device whose
  division is not correctly rounded still passes `floor_by_edges` a proven reciprocal.
  """
  r = jnp.asarray(resolution, _F32)
  inv = 1.0 / r
  return inv, jnp.isfinite(inv) & (jnp.abs(inv * r - 1.0) <= 2.0 ** -21)


def floor_by_edges(x: jax.Array, origin_hi: jax.Array, inv: jax.Array, table: jax.Array, offset, size: int):
  """Exact floor((x - origin) / res) of float32 x, clipped into [-1, size], by an edge table.

  Args:
    x: float32 array (points on this axis; XLA reads a subnormal as 0, as every path does).
    origin_hi: float32 [] the origin's leading part. inv: float32 [] from `edge_reciprocal`.
    table: float32 flat array holding `edge_thresholds` tables (size + 3 entries each);
      offset: int32 [] where this grid's table starts. size: static cell count (<= 2**17).

  Returns:
    int32 like x: n with 0 <= n < size where x lies on the grid, in cell n; -1 below
    it, or for NaN; size above it (+inf: size + 1). Exact where the table is trusted
    and `edge_reciprocal`'s flag holds: the one decision is a comparison of two float32
    values, so no rounding, FMA contraction or fusion choice can move a point across an
    edge. One table read per point.

  Proof: with q = (x - origin) / res and q' = (x - origin_hi) / res, the trusted table
  gives |q' - q| <= 1/4. The float32 value e of (x - origin_hi) * inv - 0.5, with or
  without FMA contraction, satisfies |e - (q' - 1/2)| <= 13u(|q'| + 1) (u = 2**-24: the
  difference, the product and the sum each round once, the reciprocal errs by 9u; a
  flushed subnormal difference is a quotient below 2**-86). Let f = floor(q) and
  n* = clip(f, -1, size). If |q| <= 2**18, |e - (q - 1/2)| < 0.21 + 0.25 < 1/2, so e lies
  in (q - 1, q), floor(e) is f - 1 or f, and n0 = clip(floor(e), -1, size) is n* - 1 or
  n* (clip is monotone and 1-Lipschitz). If q > 2**18 (or x = +inf), e > 2**18 - 1 >=
  size and n0 = n* = size; if q < -2**18, e < 0 and n0 = n* = -1. Since x >= T_n iff
  f >= n, and entry size + 1 is +inf, [x >= table(n0 + 1)] = [n* >= n0 + 1] for every
  n0 in [-1, size], so n0 + [x >= table(n0 + 1)] is n* either way (the +inf point alone
  lands on size + 1).
  """
  if not 0 < size <= 2 ** 17:
    raise ValueError(f"floor_by_edges needs 0 < size <= 2**17; got {size}")
  x = jnp.asarray(x, _F32)
  est = jnp.floor((x - origin_hi) * inv - 0.5)
  n0 = jnp.where(x == x, jnp.clip(est, -1.0, float(size)), -1.0).astype(jnp.int32)
  return n0 + (x >= table[offset + n0 + 2]).astype(jnp.int32)
