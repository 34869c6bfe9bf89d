"""Internal: edge tables: exact floors of float32 points by two float32 comparisons.

Part of `jaxfilters.geometry`; import it from there.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxfilters.geometry.exact import as_terms, exact_product, expansion, expansion_sign

_F32 = jnp.float32


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



def _expansion_estimate(terms):
  """A float32 close to the exact sum: the expansion's components added smallest first."""
  total = jnp.zeros_like(terms[0])
  for comp in expansion(terms):
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
