"""Internal: error-free float32 arithmetic: sums, products, expansions, exact signs and floors.

Part of `jaxfilters.geometry` (see its docstring for the float32 policy); import it from there.
"""

from __future__ import annotations

from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

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


def expansion(terms: Sequence[jax.Array]) -> list[jax.Array]:
  """Grow-Expansion (Shewchuk 1997) of float32 terms: components of increasing magnitude, same exact sum."""
  comps = [terms[0]]
  for t in terms[1:]:
    q = t
    grown = []
    for comp in comps:
      q, h = two_sum(q, comp)
      grown.append(h)
    grown.append(q)
    comps = grown
  return comps


def expansion_sign(terms: Sequence[jax.Array]) -> jax.Array:
  """Exact sign (-1, 0, +1 as int32) of the real sum of float32 terms.

  Grow-Expansion (Shewchuk 1997): the components stay non-overlapping and
  ordered by magnitude, so the sign of the sum is the sign of the largest
  non-zero component.
  """
  comps = expansion([jnp.asarray(t, _F32) for t in terms])
  sign = jnp.zeros(jnp.shape(comps[0]), jnp.int32)
  for comp in comps:
    sign = jnp.where(comp != 0, jnp.sign(comp).astype(jnp.int32), sign)
  return sign


_LIMB_BITS = 16
_LIMBS = 19          # bits 2**-149 .. 2**155 of the float32 range, with room for the carries


def fixed_point_sign(terms: Sequence[jax.Array]) -> jax.Array:
  """Exact sign (-1, 0, +1 as int32) of the real sum of finite float32 terms, in fixed point.

  Every finite float32 is an integer multiple of 2**-149 below 2**128: m * 2**p with
  m < 2**24, so the sum is an integer of at most ~280 bits. Each term's m, shifted by p,
  is added into 19 signed limbs of 16 bits (at most three limbs per term: plain int32
  sums, exact for up to 2**14 terms); one balanced carry pass then leaves every limb
  in (-2**16, 2**16), where the top non-zero limb decides the sign (the limbs below it
  add up to less than one unit of it). The same sign as `expansion_sign`; its program
  does not grow with the number of terms (a few dozen vectorised operations over
  [limbs, terms]), where Grow-Expansion's grows with their square: it compiles in a
  fraction of the time, which is what counts on the exact reruns that run only for the
  robots a bracket leaves open (the keepout filter's window clip, slice test and index
  vectors, 12 to 24 terms each).
  A term that is inf or NaN gives an unspecified sign (callers mask those inputs).
  """
  terms = [jnp.asarray(t, _F32) for t in terms]
  if len(terms) >= 2 ** 14:
    raise ValueError(f"fixed_point_sign: at most {2 ** 14 - 1} terms; got {len(terms)}")
  shape = jnp.broadcast_shapes(*[t.shape for t in terms])
  t = jnp.stack([jnp.broadcast_to(x, shape) for x in terms])
  bits = jax.lax.bitcast_convert_type(t, jnp.uint32)
  expo = ((bits >> 23) & 0xFF).astype(jnp.int32)
  mant = jnp.where(expo > 0, (bits & 0x7FFFFF) | 0x800000, bits & 0x7FFFFF)
  pos = jnp.maximum(expo, 1) - 1                      # the value is mant * 2**(pos - 149)
  limb, off = pos // _LIMB_BITS, (pos % _LIMB_BITS).astype(jnp.uint32)
  low = (1 << _LIMB_BITS) - 1
  # m * 2**off spans at most three limbs (24 + 15 bits): its bits 0-15, 16-31 and 32 up.
  pieces = [(mant << off) & low, (mant >> (_LIMB_BITS - off)) & low,
            jnp.where(off == 0, jnp.uint32(0), mant >> (2 * _LIMB_BITS - off))]
  sign = jnp.where((bits >> 31) == 1, -1, 1).astype(jnp.int32)
  ids = jnp.arange(_LIMBS, dtype=jnp.int32).reshape((_LIMBS,) + (1,) * (t.ndim - 1))   # against [limbs, *shape]
  limbs = sum(jnp.sum(jnp.where(limb[None] + q == ids[:, None], (piece.astype(jnp.int32) * sign)[None], 0), axis=1)
              for q, piece in enumerate(pieces))
  carry = (limbs + (1 << (_LIMB_BITS - 1))) >> _LIMB_BITS
  limbs = limbs - (carry << _LIMB_BITS) + jnp.concatenate([jnp.zeros_like(carry[:1]), carry[:-1]])
  top = jnp.max(jnp.where(limbs != 0, ids, -1), axis=0)
  lead = jnp.sum(jnp.where(ids == top[None], limbs, 0), axis=0)
  return jnp.sign(lead).astype(jnp.int32)


def as_terms(res) -> list[jax.Array]:
  """A float32 array, or a list of float32 parts (a host double split exactly), as a list of terms."""
  if isinstance(res, (list, tuple)):
    return [jnp.asarray(r, _F32) for r in res]
  return [jnp.asarray(res, _F32)]


def floor_div_exact(num_terms: Sequence[jax.Array], res, *, sign_fn=expansion_sign) -> jax.Array:
  """Exact floor(sum(num_terms) / res) as int32, for res > 0 and |quotient| < 2**22.

  `res` is one float32 array or a list of float32 parts whose exact sum is the
  divisor (a host double carried as `split_float64` parts). Both candidate
  checks (q0 and q0 + 1) run as one stacked expansion, which halves the traced
  program (compile time matters: this sits in every filter). `sign_fn` may be
  `fixed_point_sign` (same results, far less to compile where there are many terms).
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
  # A quotient beyond float32 (|x| > ~1e37 m at 5 cm) starts far off every grid (2**30),
  # so it never lands on a cell; NaN starts from 0 (callers mask non-finite points).
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


def exact_sign_affine(d, multiplier, base, offset):
  """Exact sign of d * multiplier + base - offset (int32 [...]) for float32 inputs.

  The filters' range checks and the binary threshold are decided with it, as Nav2
  decides them on the float64 value of the float32 fields.
  """
  terms = [*exact_product(jnp.asarray(d).astype(_F32), multiplier), base, -jnp.asarray(offset, _F32)]
  return expansion_sign(terms)


# ----------------------------------------------------------------------------- long sums
#
# `expansion_sign` unrolls Grow-Expansion over a handful of terms. The shape rasteriser's
# predicates sum hundreds of exact partial products per lane; `exact_sign` takes those as
# one stacked array and runs error-free passes in a loop instead.

_SIGN_MAX_PASSES = 48                # error-free summation passes (domain inputs need < 20)
_SIGN_MARGIN = np.float32(1.0 + 2.0 ** -10)
_FAR_QUOTIENT = 2.0 ** 21            # beyond this a `floor_quotient` is off the grid for sure


def stack_terms(*parts, shape):
  """float32 [n, *shape]: scalars, [*shape] arrays and [k, *shape] term arrays stacked."""
  out = []
  for a in parts:
    a = jnp.asarray(a, _F32)
    out.append(jnp.broadcast_to(a, (a.shape[0], *shape)) if a.ndim == len(shape) + 1
               else jnp.broadcast_to(a, shape)[None])
  return jnp.concatenate(out, axis=0)


def _vec_sum(p):
  """One error-free pass (Ogita-Rump-Oishi VecSum) over the leading axis: same exact sum."""
  def step(s, x):
    t, e = two_sum(x, s)
    return t, e
  s, errs = lax.scan(step, p[0], p[1:])
  return jnp.concatenate([errs, s[None]], axis=0)


def _last_dominates(p):
  """The last term's sign is the sum's sign: it outweighs all others (with margin)."""
  rest = jnp.sum(jnp.abs(p[:-1]), axis=0)
  return (rest == 0) | (jnp.abs(p[-1]) > rest * _SIGN_MARGIN)


def exact_sign(p: jax.Array) -> tuple[jax.Array, jax.Array]:
  """Exact sign of the real sum of many float32 terms, per lane.

  A float filter settles most lanes (|float sum| far above its error bound);
  the rest run error-free VecSum passes until the last term outweighs the
  others. Each pass keeps the exact sum and shrinks the others by about n
  * 2**-24, so inputs of the rasteriser's domain settle within a few passes
  (exact zeros too).

  Args:
    p: float32 [n, L] terms (n < 2**13), all 0 or normal with no product of
      the arithmetic below 2**-126.

  Returns:
    (sign int32 [L] in {-1, 0, 1}, resolved bool [L]: False where 48 passes did
    not settle the lane).
  """
  n = p.shape[0]
  approx = jnp.sum(p, axis=0)
  bound = jnp.sum(jnp.abs(p), axis=0) * np.float32(2.0 * n * 2.0 ** -24)
  filtered = jnp.abs(approx) > bound
  # Lanes the filter settles are frozen as one term: the loop sees them as done.
  p = jnp.where(filtered[None], jnp.zeros_like(p).at[-1].set(approx), p)

  def cond(st):
    _, done, it = st
    return (it < _SIGN_MAX_PASSES) & ~jnp.all(done)

  def body(st):
    q, done, it = st
    q = jnp.where(done[None], q, _vec_sum(q))
    return q, done | _last_dominates(q), it + 1

  p, done, _ = lax.while_loop(cond, body, (p, _last_dominates(p), jnp.int32(0)))
  return jnp.sign(p[-1]).astype(jnp.int32), done


def floor_quotient(terms, res, lo, hi):
  """Exact floor(sum(terms) / res) clipped to [lo, hi], and resolved; safe far off the grid.

  The float32 estimate is within 0.4 of the quotient when |quotient| <= 2**21
  (three correctly rounded operations), so the floor is q0 - 1, q0 or q0 + 1:
  the exact signs (`exact_sign`) of sum - q0 res and sum - (q0 + 1) res decide.
  Beyond 2**21 the quotient is off the grid for sure and only its side matters.

  Returns:
    (int32 floor clipped to [lo, hi], resolved bool), shaped like the terms.
  """
  shape = jnp.broadcast_shapes(*[jnp.shape(t) for t in terms])
  approx = sum(terms[1:], terms[0]) / res
  far = ~(jnp.abs(approx) <= _FAR_QUOTIENT)
  q0 = jnp.floor(jnp.where(far, 0.0, approx))
  cand = jnp.stack([q0, q0 + 1.0])                                    # [2, *shape]
  diff = stack_terms(*[jnp.broadcast_to(t, shape)[None] for t in terms],
                     -jnp.stack(exact_product(cand, res)), shape=(2, *shape))
  sign, resolved = exact_sign(diff.reshape(diff.shape[0], -1))
  sign, resolved = sign.reshape(2, *shape), resolved.reshape(2, *shape)
  q = q0.astype(jnp.int32) - (sign[0] < 0) + (sign[1] >= 0)
  q = jnp.where(far, jnp.where(approx > 0, hi, lo), q)
  return jnp.clip(q, lo, hi), far | jnp.all(resolved, axis=0)
