"""The float32 policy: exact world->cell against float64 maths, up to 10 km (hypothesis)."""

import math
from fractions import Fraction

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given, strategies as st

from jaxfilters import geometry
from reference import nav2 as reference

f32 = lambda v: float(np.float32(v))
# The guaranteed domain: |v| <= 10 km, and 0 or |v| >= 1e-30 (so no error term is subnormal).
coords = st.floats(-1.0e4, 1.0e4, allow_nan=False, width=32).filter(lambda v: v == 0 or abs(v) >= 1e-30)
resolutions = st.sampled_from([0.01, 0.025, 0.03, 0.05, 0.1, 0.3, 1.0]).map(f32) | st.floats(
    f32(0.005), 2.0, width=32)

_floor = jax.jit(lambda x, o, r: geometry.floor_div_exact([x, -o], r))
_trunc = jax.jit(lambda x, o, r: geometry.trunc_div_exact([x, -o], r))


def _ref_quotient(x, o, r):
  # The exact real quotient of the float32 values (the library's promise). A float64 quotient
  # rounds to the next integer when o is tiny beside x: x = 0.01f, o = 1.007e-26, r = 0.01f is
  # 1 - 1e-24, floor 0, which float64 rounds to 1.0 (hypothesis found it).
  return (Fraction(float(x)) - Fraction(float(o))) / Fraction(float(r))


def _ref_floor(x, o, r):
  return math.floor(_ref_quotient(x, o, r))


@given(coords, coords, resolutions, st.integers(-200000, 200000), st.sampled_from([-1, 0, 1, None]))
def test_floor_matches_exact_quotient_on_and_near_cell_boundaries(o, x, r, k, nudge):
  # Points placed on a boundary o + k*r (rounded to float32), one ulp either side, or anywhere.
  if nudge is not None:
    x = np.float32(float(o) + k * float(r))
    if nudge:
      x = np.nextafter(x, np.float32(np.inf) if nudge > 0 else np.float32(-np.inf))
  x, o, r = np.float32(x), np.float32(o), np.float32(r)
  if abs(x) < np.finfo(np.float32).tiny:
    x = np.float32(0.0)  # XLA flushes subnormals to zero (documented in geometry.py)
  ref = _ref_floor(x, o, r)
  if abs(ref) >= 2 ** 22:
    return
  assert int(_floor(x, o, r)) == ref
  assert int(_trunc(x, o, r)) == int(_ref_quotient(x, o, r))   # int() of a Fraction truncates


@given(coords, coords, coords, coords, resolutions, st.integers(1, 4000), st.integers(1, 4000))
def test_world_to_cell_matches_nav2_reference(x, y, ox, oy, r, w, h):
  mx, my, valid = geometry.world_to_cell(jnp.float32(x), jnp.float32(y), jnp.array([ox, oy], jnp.float32),
                                         jnp.float32(r), w, h)
  ref = reference.world_to_map(np.float32(x), np.float32(y), np.float32(ox), np.float32(oy), np.float32(r), w, h)
  assert bool(valid) == (ref is not None)
  if ref is not None:
    assert (int(mx), int(my)) == ref


def test_float32_division_alone_would_be_wrong():
  # The spec's example, on float32 values: 0.3 / 0.1 is 2.9999999 in float64 maths on
  # some inputs; float32 division rounds such quotients up. Count how often over a scan.
  o = np.float32(-10.0)
  r = np.float32(0.05)
  xs = (np.arange(-4000, 4000) * 0.05).astype(np.float32)
  ref = np.floor((xs.astype(np.float64) - float(o)) / float(r))
  naive = np.floor((xs - o) / r)
  exact = np.asarray(jax.vmap(lambda x: geometry.floor_div_exact([x, -o], r))(xs))
  assert np.any(naive != ref), "the scan should contain float32 rounding traps"
  np.testing.assert_array_equal(exact, ref)


def test_spec_world_to_map_examples():
  # costmap_filter_test: 3x3 mask, res 1, origin (3, 3).
  origin = jnp.array([3.0, 3.0])
  cases = {(4, 5): (1, 2), (3, 3): (0, 0), (5.9, 5.9): (2, 2), (2.9, 2.9): None, (6, 6): None}
  for (x, y), want in cases.items():
    mx, my, valid = geometry.world_to_cell(jnp.float32(x), jnp.float32(y), origin, jnp.float32(1.0), 3, 3)
    assert bool(valid) == (want is not None)
    if want:
      assert (int(mx), int(my)) == want


def test_nan_pose_is_invalid_not_an_error():
  mx, my, valid = geometry.world_to_cell(jnp.float32(np.nan), jnp.float32(1.0), jnp.zeros(2), jnp.float32(0.05), 10, 10)
  assert not bool(valid)
  assert 0 <= int(mx) < 10 and 0 <= int(my) < 10


@given(st.lists(st.floats(-1e6, 1e6, width=32, allow_subnormal=False).filter(lambda t: t == 0 or abs(t) > 1e-20), min_size=1, max_size=8))
def test_expansion_sign_is_exact(terms):
  from fractions import Fraction
  exact = sum(Fraction(float(np.float32(t))) for t in terms)
  got = int(geometry.expansion_sign([jnp.float32(t) for t in terms]))
  assert got == (exact > 0) - (exact < 0)
