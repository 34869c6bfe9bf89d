"""The fast keepout paths give the exact path's integers, on cell edges too.

`keepout_filter` decides same-frame cells through bracketed index vectors (a slice
where they are consecutive) and other-frame cells through `world_to_index_checked`,
falling back to the exact arithmetic where a bracket stays open. These tests compare
the fast paths (both batch loops, plain and escape mode) with the per-cell exact path
(`process.filter_batch(exact=True)`) on fleets built to put cell centres exactly on
mask-cell edges and one ulp either side, as well as at random; the exact path and the
other-frame semantics (float32 rotation with rounded products, then the exact floor)
against independent references (reference/nav2.py in float64, and a NumPy float32
rotation with Fractions); and the new geometry helpers against Fractions with
hypothesis.
"""

import dataclasses
import functools
import math
from fractions import Fraction

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, strategies as st

from jaxfilters import geometry
from jaxfilters import keepout as ko
from jaxfilters.keepout import common, other_frame, other_resolution, process, prologue, same_frame
from jaxfilters.keepout import reference as keepout_reference
from jaxfilters import mask_lookup
from jaxfilters import validate
from reference import nav2 as reference
from tests.keepout_fleets import B, H, HM, M, W, WM, fleet

PLAIN = ko.KeepoutConfig()
ESCAPE = ko.KeepoutConfig(override_lethal_cost=True, lethal_override_cost=200)
f32 = np.float32


# ----------------------------------------------------------------------------- helpers


def _run(cm, mask, state, window, mask_index, enabled, transform, config, **kw):
  idx, ok, _, en, win, tf = common.batched_inputs(cm, mask, jnp.zeros((B, 3)), mask_index, enabled, window,
                                               transform, "test")
  cost, st = process.filter_batch(cm, mask, idx, ok, common.fill_error(state, B), win, en, tf, config=config, **kw)
  return np.asarray(cost.cost), np.asarray(st.last_pose_lethal)


def _fast_equals_exact(case, transform=None, configs=(PLAIN, ESCAPE), loops=("map", "vmap")):
  for cfg in configs:
    want = _run(*case, transform, cfg, exact=True)
    for loop in (loops if cfg is PLAIN else ("map",)):
      got = _run(*case, transform, cfg, loop=loop)
      np.testing.assert_array_equal(got[0], want[0], err_msg=f"{cfg} {loop}")
      np.testing.assert_array_equal(got[1], want[1], err_msg=f"{cfg} {loop}")
  return want[0]


def _nudge(x, steps):
  """x moved by `steps` float32 ulps (negative: down)."""
  x = np.float32(x)
  for _ in range(abs(steps)):
    x = np.nextafter(x, np.float32(np.inf if steps > 0 else -np.inf))
  return x


# ----------------------------------------------------------------------------- helpers of geometry


def test_mask_cost_u8_is_occ_to_cost_for_every_byte():
  d = np.arange(256, dtype=np.uint8).view(np.int8)
  known, cost = common.mask_cost_u8(jnp.asarray(d))
  want = np.asarray(ko.occ_to_cost(jnp.asarray(d)))
  assert np.array_equal(np.asarray(known), want != 255)
  assert np.array_equal(np.asarray(cost)[np.asarray(known)], want[want != 255])
  assert [reference.mask_cost(v) for v in range(101)] == np.asarray(cost)[:101].tolist()


finite32 = st.floats(-1e4, 1e4, width=32, allow_nan=False).filter(lambda v: v == 0 or abs(v) >= 1e-30)


_signs = jax.jit(lambda t: (geometry.fixed_point_sign(list(t)), geometry.expansion_sign(list(t))))


@given(st.lists(finite32, min_size=2, max_size=9), st.integers(0, 8))
def test_fixed_point_sign_equals_expansion_sign(values, cancel):
  # Cancelling pairs and exact sums of 0 make the sign hinge on the smallest parts.
  terms = list(np.float32(values)) + [-np.float32(v) for v in values[:cancel]]
  padded = np.zeros(18, np.float32)
  padded[:len(terms)] = terms
  got, want = (int(v) for v in _signs(jnp.asarray(padded)))
  exact = sum(Fraction(float(t)) for t in terms)
  assert got == want == (exact > 0) - (exact < 0)


any_finite32 = st.floats(width=32, allow_nan=False, allow_infinity=False, allow_subnormal=True)


@given(st.lists(any_finite32, min_size=1, max_size=24), st.integers(0, 24))
def test_fixed_point_sign_over_the_whole_float32_range(values, cancel):
  # Subnormals (2**-149, the fixed point's unit), float32's largest values (its top limbs) and
  # exact cancellation between them.
  terms = [np.float32(v) for v in values] + [-np.float32(v) for v in values[:cancel]]
  got = int(_fixed_sign(jnp.asarray(np.asarray(terms, np.float32))))
  exact = sum(Fraction(float(t)) for t in terms)
  assert got == (exact > 0) - (exact < 0)


_fixed_sign = jax.jit(lambda t: geometry.fixed_point_sign(list(t)))


def _exact_signs(terms):
  """The exact sign of each column's sum (float32 [n, L]), in Python integers (units of 2**-149)."""
  out = []
  for col in terms.T:
    total = 0
    for v in col.tolist():
      num, den = float(v).as_integer_ratio()
      total += num * ((1 << 149) // den)
    out.append((total > 0) - (total < 0))
  return np.asarray(out)


def test_fixed_point_sign_on_random_bit_patterns_and_near_ties():
  # 20,000 lanes of 1-40 terms: random bit patterns (every exponent), sums that cancel to 0 exactly
  # or to one subnormal unit, a huge term against many small ones, and many terms of one limb (carries).
  rng = np.random.default_rng(7)
  lanes = 2000
  for n in (1, 2, 5, 13, 24, 40):
    bits = rng.integers(0, 2 ** 32, (n, lanes), dtype=np.uint64).astype(np.uint32)
    t = bits.view(np.float32).copy()
    t[~np.isfinite(t)] = 0.0
    kind = rng.integers(0, 5, lanes)
    half = n // 2
    if half:
      t[half:2 * half, kind == 1] = -t[:half, kind == 1]                   # cancels to 0 (odd n: one left)
      tiny = np.float32(2.0 ** -149) * rng.choice([-1, 1], lanes).astype(np.float32)
      t[half:2 * half, kind == 2] = -t[:half, kind == 2]
      t[-1, kind == 2] = tiny[kind == 2]                                    # cancels to +-2**-149 (or near)
    t[:, kind == 3] = (rng.integers(2 ** 23, 2 ** 24, (n, lanes)) * rng.choice([-1, 1], (n, lanes))
                       ).astype(np.float32)[:, kind == 3]                   # full 24-bit mantissas, one scale
    t[0, kind == 4] = np.float32(3.0e38)
    t[1:, kind == 4] = -np.float32(1.0e37)
    got = np.asarray(_fixed_sign(jnp.asarray(t)))
    np.testing.assert_array_equal(got, _exact_signs(t), err_msg=f"{n} terms")


def _exact_floor(x, origin_parts, res):
  return math.floor((Fraction(float(x)) - sum(Fraction(float(p)) for p in origin_parts)) / Fraction(float(res)))


_checked = jax.jit(lambda x, o, r, size: geometry.floor_div_checked(x, [o[0], o[1], o[2]], r, size),
                   static_argnames="size")
_checked_big = jax.jit(lambda x, o, r: geometry.floor_div_checked(x, [o[0], o[1], o[2]], r, 60000))

resolutions = st.sampled_from([0.05, 0.1, 0.025, 0.03, 1.0, 0.25]) | st.floats(0.004, 3.0)
coords = lambda m: st.floats(-m, m).filter(lambda v: v == 0 or abs(v) >= 1e-20)   # host doubles


@given(coords(300.0), resolutions, st.integers(-30, 4100), st.sampled_from([-2, -1, 0, 1, 2, None]),
       st.floats(0.0, 1.0), st.booleans())
def test_floor_div_checked_is_exact_where_certain(origin, res, k, nudge, frac, big):
  # Points on a cell edge o + k r (rounded to float32), a few ulps either side, or inside a cell.
  o = validate.split_float64(origin)
  r = f32(res)
  edge = float(origin) + k * float(r)
  x = f32(edge + frac * float(r)) if nudge is None else _nudge(f32(edge), nudge)
  size = 4000
  run = _checked_big if big else (lambda x, o, r: _checked(x, o, r, size=size))
  cell, inside, certain = (np.asarray(v) for v in run(jnp.float32(x), jnp.asarray(o), jnp.float32(r)))
  want = _exact_floor(x, o, r)
  limit = 60000 if big else size
  if certain:
    assert bool(inside) == (0 <= want < limit)
    if inside:
      assert int(cell) == want
  if nudge is None and 0.01 < frac < 0.99:
    assert certain                        # far from an edge the fast decision always stands


def test_floor_div_checked_is_undecided_only_on_the_edge():
  o = validate.split_float64(-15.1)
  r = f32(0.05)
  xs = np.float32([-15.1 + 100 * 0.05 * (1 + 2 ** -40), -15.0, 0.0, 123.4567, np.nan, np.inf])
  edges = np.float32(o[0]) + np.arange(0, 500, dtype=np.float32) * r    # float32 sums: near, rarely on, edges
  x = jnp.asarray(np.concatenate([xs, edges]))
  cell, inside, certain = (np.asarray(v) for v in _checked(x, jnp.asarray(o), r, size=4000))
  for xv, c, i, ok in zip(np.asarray(x), cell, inside, certain):
    if not ok:
      continue
    if not np.isfinite(xv):
      assert not i
      continue
    want = _exact_floor(xv, o, r)
    assert bool(i) == (0 <= want < 4000) and (not i or int(c) == want)
  assert certain[:4].all() and not certain[4:6].any()      # NaN and inf stay undecided
  # A point exactly on an edge: the residual is exactly 0 and the helper says so.
  on_edge = np.float32(0.25) * 3
  assert not bool(_checked(jnp.float32(on_edge), jnp.zeros((3,), jnp.float32), jnp.float32(0.25), size=4000)[2])


def test_world_to_cell_is_off_the_grid_beyond_float32_quotients():
  # x / res overflows float32 (3e37 / 0.05): the exact floor used to restart from 0 and
  # report cell 1 as valid; both the exact and the checked helpers say off the grid.
  x = jnp.asarray([3e37, 1e38, -1e38, 3.4e38], jnp.float32)
  y = jnp.ones((4,), jnp.float32)
  _, _, valid = geometry.world_to_cell(x, y, jnp.zeros((2,), jnp.float32), jnp.float32(0.05), 100, 100)
  assert not np.asarray(valid).any()
  _, inside, certain = geometry.world_to_index_checked(x, y, jnp.zeros((2,), jnp.float32), jnp.float32(0.05), 100, 100)
  assert not np.asarray(inside & certain).any()


@given(st.integers(0, 4000), coords(200.0), st.sampled_from([0.05, 0.1, 0.03, 0.5]), coords(200.0), resolutions)
def test_centre_floor_bracket_contains_the_exact_floor(i, o, res, t, tres):
  op, rp, tp = validate.split_float64(o), validate.split_float64(res), validate.split_float64(t)
  lo, hi = geometry.centre_floor_bracket(jnp.float32(i), list(jnp.asarray(op)), list(jnp.asarray(rp)),
                                         list(jnp.asarray(tp)), jnp.float32(tres))
  centre = sum(Fraction(float(p)) for p in op) + (i + Fraction(1, 2)) * sum(Fraction(float(p)) for p in rp)
  want = math.floor((centre - sum(Fraction(float(p)) for p in tp)) / Fraction(float(f32(tres))))
  assert float(lo) <= want <= float(hi)


def _split12(x):
  x = np.asarray(x, np.float32)
  hi = (x.view(np.uint32) & np.uint32(0xFFFFF000)).view(np.float32)
  return hi, np.float32(x - hi)


def _rounded_product_np(a, b):
  ah, al = _split12(a)
  bh, bl = _split12(b)
  return np.float32(ah * bh) + ((np.float32(ah * bl) + np.float32(al * bh)) + np.float32(al * bl))


normal32 = lambda lo, hi: st.floats(-hi, hi, width=32).filter(lambda v: v == 0 or abs(v) >= lo)


@given(st.lists(normal32(1e-6, 1e6), min_size=1, max_size=16), normal32(1e-6, 1e3))
def test_rounded_product_is_the_defined_sum_and_near_the_product(a, b):
  a = np.float32(a)
  got = np.asarray(jax.jit(geometry.rounded_product)(jnp.asarray(a), jnp.float32(b)))
  want = _rounded_product_np(a, np.float32(b))
  assert np.array_equal(got, want)
  for g, x in zip(got, a):
    exact = Fraction(float(x)) * Fraction(float(np.float32(b)))
    ulp = Fraction(float(np.spacing(np.float32(abs(float(exact)))))) if exact else Fraction(0)
    assert abs(Fraction(float(g)) - exact) <= ulp * (Fraction(1, 2) + Fraction(1, 2048))


# ----------------------------------------------------------------------------- same frame


def _same_frame_cases():
  rng = np.random.default_rng(7)
  cases = []
  # The practical "aligned" case: a double costmap resolution against the float32 mask one.
  origins = np.round(rng.uniform(8.6, 9.8, (B, 2)) / 0.05) * 0.05
  cases.append(fleet(rng, 0.05, 0.05, origins, [(9.0, 9.5), (9.15, 9.0)]))
  # Binary-exact equal resolutions, origins on the mask grid and one ulp off it.
  origins = np.round(rng.uniform(-3, 3, (B, 2)) * 4) / 4
  origins[1] = _nudge(origins[1, 0], 1), _nudge(origins[1, 1], -1)
  cases.append(fleet(rng, 0.25, 0.25, origins, [(0.0, -1.0), (-0.5, 0.25)]))
  # A finer mask (res / 2): every master centre lies exactly on a mask-cell edge.
  origins = np.round(rng.uniform(-2, 2, (B, 2)) * 4) / 4
  origins[2] = _nudge(origins[2, 0], -1), _nudge(origins[2, 1], 1)
  cases.append(fleet(rng, 0.5, 0.25, origins, [(0.0, 0.0), (-1.0, 0.5)]))
  # A coarser mask, decimal resolutions: the window clip's quotients sit near integers.
  origins = np.round(rng.uniform(-1, 1, (B, 2)) / 0.05) * 0.05
  cases.append(fleet(rng, 0.05, 0.1, origins, [(-0.5, -0.3), (0.1, -0.7)]))
  # Anything: random resolutions and origins.
  cases.append(fleet(rng, 0.03, 0.07, rng.uniform(-1, 1, (B, 2)), rng.uniform(-1, 0, (M, 2))))
  return cases


@pytest.mark.parametrize("n", range(5))
def test_same_frame_fast_paths_equal_the_exact_path(n):
  case = _same_frame_cases()[n]
  out = _fast_equals_exact(case)
  assert (out != np.asarray(case[0].cost)).any()          # the filter wrote something


def test_same_frame_fast_path_matches_float64_reference():
  cm, mask, state, window, mask_index, enabled = _same_frame_cases()[0]
  got, _ = _run(cm, mask, state, window, mask_index, jnp.ones((B,), bool), None, PLAIN)
  for b in range(B):
    i = int(mask_index[b])
    win = np.clip(window[b], 0, [W, H, W, H])
    origin = np.asarray(cm.origin[b], np.float64) + np.asarray(cm.origin_lo[b], np.float64).sum(-1)
    res = float(cm.resolution[b]) + float(np.asarray(cm.resolution_lo[b], np.float64).sum())
    morigin = np.asarray(mask.origin[i], np.float64) + np.asarray(mask.origin_lo[i], np.float64).sum(-1)
    want, _ = reference.keepout_process(np.asarray(cm.cost[b]), origin, res, np.asarray(mask.data[i]), morigin,
                                        np.asarray(mask.resolution[i]), win)
    np.testing.assert_array_equal(got[b], want)


# ----------------------------------------------------------------------------- other frame


def _se2_cases():
  rng = np.random.default_rng(11)
  cases = []
  # Binary-exact grids, yaw 0 and translations on the mask grid: every centre on an edge
  # (whole windows undecided), one ulp off it, and small windows (a few undecided cells).
  origins = np.round(rng.uniform(-2, 2, (B, 2)) * 4) / 4
  case = fleet(rng, 0.5, 0.25, origins, [(0.0, 0.0), (-0.75, 0.5)])
  tf = np.zeros((B, 3), np.float32)
  tf[:, :2] = np.round(rng.uniform(-1, 1, (B, 2)) * 4) / 4
  tf[1, 0], tf[2, 1] = _nudge(tf[1, 0], 1), _nudge(tf[2, 1], -1)
  windows = case[3].copy()
  windows[3:] = [(2, 2, 5, 4), (0, 0, 2, 3), (5, 1, 8, 3)]
  cases.append((case[:3] + (windows,) + case[4:], tf))
  # Quarter turns (float32 pi/2: cos is -4.4e-8, not 0) and the same binary grids.
  case = fleet(rng, 0.5, 0.25, origins, [(-4.0, -4.0), (-3.5, -4.25)])
  tf = np.zeros((B, 3), np.float32)
  tf[:, 2] = np.float32(np.pi / 2) * rng.integers(-2, 3, B)
  tf[:, :2] = np.round(rng.uniform(-1, 1, (B, 2)) * 4) / 4
  cases.append((case, tf))
  # Random transforms, decimal grids.
  case = fleet(rng, 0.05, 0.05, rng.uniform(-0.3, 0.3, (B, 2)), [(-0.5, -0.5), (-0.4, -0.6)])
  tf = np.stack([rng.uniform(-0.2, 0.2, B), rng.uniform(-0.2, 0.2, B), rng.uniform(-np.pi, np.pi, B)], 1)
  cases.append((case, tf.astype(np.float32)))
  return cases


@pytest.mark.parametrize("n", range(3))
def test_other_frame_fast_path_equals_the_exact_path(n):
  case, tf = _se2_cases()[n]
  out = _fast_equals_exact(case, transform=jnp.asarray(tf))
  assert (out != np.asarray(case[0].cost)).any()


def test_edge_fleet_really_has_undecided_cells():
  """The edge case above exercises the fallback: cells the fast arithmetic leaves open."""
  (cm, mask, *_), tf = _se2_cases()[0]
  lo = lambda a: None if a is None else a[0]          # None: the geometry is exactly float32
  axes = keepout_reference.se2_axes_one(geometry.origin_terms(cm.origin[0], lo(cm.origin_lo)),
                          geometry.resolution_terms(cm.resolution[0], lo(cm.resolution_lo)), jnp.asarray(tf[0]), H, W)
  px, py = keepout_reference.se2_grid(axes)
  _, _, certain = geometry.world_to_index_checked(px, py, mask_lookup.mask_origin_terms(mask, 0), mask.resolution[0], WM, HM)
  assert not bool(jnp.all(certain))


def _se2_numpy(cm, mask, b, i, tf):
  """The other-frame semantics in NumPy: float32 rotation with rounded products, exact floor."""
  o = np.asarray(cm.origin[b], np.float32)
  for p in (np.zeros((2, 0), np.float32) if cm.origin_lo is None else np.asarray(cm.origin_lo[b], np.float32)).T:
    o = o + p
  r = np.float32(cm.resolution[b])
  for p in (() if cm.resolution_lo is None else np.asarray(cm.resolution_lo[b], np.float32)):
    r = np.float32(r + p)
  cx = o[0] + _rounded_product_np(np.arange(W, dtype=np.float32) + np.float32(0.5), r)
  cy = o[1] + _rounded_product_np(np.arange(H, dtype=np.float32) + np.float32(0.5), r)
  c, s = np.float32(jnp.cos(jnp.float32(tf[2]))), np.float32(jnp.sin(jnp.float32(tf[2])))
  px = (_rounded_product_np(c, cx)[None, :] - _rounded_product_np(s, cy)[:, None]) + np.float32(tf[0])
  py = (_rounded_product_np(s, cx)[None, :] + _rounded_product_np(c, cy)[:, None]) + np.float32(tf[1])
  mo = [sum(Fraction(float(p)) for p in np.asarray(mask.origin_lo[i], np.float64)[a]) + Fraction(float(mask.origin[i, a]))
        for a in range(2)]
  mres = Fraction(float(mask.resolution[i]))
  mx = np.vectorize(lambda v: math.floor((Fraction(float(v)) - mo[0]) / mres))(px)
  my = np.vectorize(lambda v: math.floor((Fraction(float(v)) - mo[1]) / mres))(py)
  return px, py, mx, my


def test_other_frame_semantics_against_numpy_and_float64_reference():
  (cm, mask, state, window, mask_index, enabled), tf = _se2_cases()[2]
  got, _ = _run(cm, mask, state, window, mask_index, jnp.ones((B,), bool), jnp.asarray(tf), PLAIN)
  for b in range(B):
    i = int(mask_index[b])
    win = np.clip(window[b], 0, [W, H, W, H])
    px, py, mx, my = _se2_numpy(cm, mask, b, i, tf[b])
    data = np.asarray(mask.data[i])
    want = np.asarray(cm.cost[b]).copy()
    for j in range(win[1], win[3]):
      for k in range(win[0], win[2]):
        if 0 <= mx[j, k] < WM and 0 <= my[j, k] < HM:
          d = reference.mask_cost(data[my[j, k], mx[j, k]])
          if d != 255 and (d > want[j, k] or (want[j, k] == 255 and d >= 253)):   # Nav2 main (PR #6329)
            want[j, k] = d
    np.testing.assert_array_equal(got[b], want)
    # And Nav2's float64 reference wherever the float64 centre is not within 1e-4 m of an edge.
    origin = np.asarray(cm.origin[b], np.float64) + np.asarray(cm.origin_lo[b], np.float64).sum(-1)
    res = float(cm.resolution[b]) + float(np.asarray(cm.resolution_lo[b], np.float64).sum())
    morigin = np.asarray(mask.origin[i], np.float64) + np.asarray(mask.origin_lo[i], np.float64).sum(-1)
    ref, _ = reference.keepout_process(np.asarray(cm.cost[b]), origin, res, data, morigin,
                                       np.asarray(mask.resolution[i]), win, transform=tf[b])
    near = np.zeros((H, W), bool)
    cs, sn = math.cos(float(tf[b, 2])), math.sin(float(tf[b, 2]))
    for j in range(H):
      for k in range(W):
        x, y = origin[0] + (k + 0.5) * res, origin[1] + (j + 0.5) * res
        fx = (cs * x - sn * y + float(tf[b, 0]) - morigin[0]) / float(mask.resolution[i])
        fy = (sn * x + cs * y + float(tf[b, 1]) - morigin[1]) / float(mask.resolution[i])
        near[j, k] = min(abs(fx - round(fx)), abs(fy - round(fy))) * float(mask.resolution[i]) < 1e-4
    np.testing.assert_array_equal(got[b][~near], ref[~near])


# ----------------------------------------------------------------------------- edge tables
#
# `geometry.edge_thresholds` / `floor_by_edges` decide each other-frame cell with float32
# comparisons against exact per-mask thresholds; the kernels selected by `_se2_batch(impl=)`
# and `_same_frame_batch(gather_impl=)` must give the exact path's integers.

EDGE_SIZE = 64
_edges = jax.jit(lambda parts, r: geometry.edge_thresholds([parts[0], parts[1], parts[2]], r, EDGE_SIZE))
_floor_edges = jax.jit(lambda x, o, inv, table: geometry.floor_by_edges(x, o, inv, table, jnp.int32(0), EDGE_SIZE))


def _edge(parts, r, n):
  return sum(Fraction(float(p)) for p in parts) + n * Fraction(float(r))


def _ceil32(e):
  """The smallest float32 >= the Fraction e (by bisection on float32 neighbours)."""
  t = np.float32(float(e))
  while Fraction(float(t)) < e:
    t = np.nextafter(t, np.float32(np.inf))
  while Fraction(float(np.nextafter(t, np.float32(-np.inf)))) >= e:
    t = np.nextafter(t, np.float32(-np.inf))
  return t


grid_origins = st.one_of(coords(500.0), st.integers(-400, 400).map(lambda k: k * 0.05),
                         st.integers(-400, 400).map(lambda k: k * float(f32(0.05))))
grid_resolutions = st.sampled_from([0.05, 0.1, 0.025, 0.03, 1.0, 0.25, 0.07]) | st.floats(0.001, 5.0)


@given(grid_origins, grid_resolutions)
def test_edge_thresholds_are_the_smallest_float32_at_or_above_each_edge(origin, res):
  # Origins on the float32 grid of the resolution make edges exactly 0 or float32 values.
  parts, r = validate.split_float64(origin), f32(res)
  table, trusted = (np.asarray(v) for v in _edges(jnp.asarray(parts), jnp.float32(r)))
  assert bool(trusted)                         # any map file's geometry is covered
  assert table[0] == -np.inf and table[-1] == np.inf and table.shape == (EDGE_SIZE + 3,)
  for n in range(EDGE_SIZE + 1):
    e = _edge(parts, r, n)
    assert table[n + 1] == (0.0 if e == 0 else _ceil32(e)), n


def test_edge_thresholds_refuse_geometry_they_do_not_cover():
  ok = lambda origin, res: bool(_edges(jnp.asarray(validate.split_float64(origin)), jnp.float32(res))[1])
  assert ok(-15.1, 0.05) and ok(0.0, 2.0 ** -40)
  assert not ok(0.0, 2.0 ** -41)               # resolution below 2**-40
  assert not ok(0.1, 1e-9)                     # origin's lower parts beyond res / 4
  inv, good = geometry.edge_reciprocal(jnp.asarray([0.05, 0.1, 3.0, 2.0 ** -40], jnp.float32))
  assert np.asarray(good).all() and np.isfinite(np.asarray(inv)).all()


@given(grid_origins, grid_resolutions, st.integers(-80, 150), st.sampled_from([-2, -1, 0, 1, 2, None]),
       st.floats(0.0, 1.0))
def test_floor_by_edges_is_the_exact_floor(origin, res, k, nudge, frac):
  # Points on an edge (rounded to float32), a few ulps either side, inside cells, and far off.
  parts, r = validate.split_float64(origin), f32(res)
  table, trusted = _edges(jnp.asarray(parts), jnp.float32(r))
  inv, inv_ok = geometry.edge_reciprocal(jnp.float32(r))
  assert bool(trusted) and bool(inv_ok)
  edge = float(_edge(parts, r, k))
  x = f32(edge + frac * float(r)) if nudge is None else _nudge(f32(edge), nudge)
  if 0 < abs(x) < np.finfo(np.float32).tiny:
    x = f32(0.0)        # XLA reads a subnormal as 0 (the exact path too); the points are never one
  xs = np.asarray([x, f32(edge * 1e6 + 1e7), f32(-edge * 1e6 - 1e7), np.nan, np.inf, -np.inf], np.float32)
  got = np.asarray(_floor_edges(jnp.asarray(xs), jnp.float32(parts[0]), inv, table))
  for xv, g in zip(xs, got):
    if np.isnan(xv):
      want = -1
    elif np.isinf(xv):
      want = EDGE_SIZE + 1 if xv > 0 else -1
    else:
      q = (Fraction(float(xv)) - sum(Fraction(float(p)) for p in parts)) / Fraction(float(r))
      want = min(max(math.floor(q), -1), EDGE_SIZE)
    assert int(g) == want, (xv, int(g), want)


_other_frame = jax.jit(other_frame.other_frame_batch, static_argnames=("config", "loop"))


def _impl_inputs(case, transform, *, lower_parts=False):
  """The `_keepout_filter_jit` arguments; `lower_parts` gives exactly-float32 geometry zero
  lower parts, so fleets of both kinds share one pytree structure (one compile)."""
  cm, mask, state, window, mask_index, enabled = case
  if lower_parts:
    zeros = lambda x, shape: jnp.zeros(shape, jnp.float32) if x is None else x
    cm = dataclasses.replace(cm, origin_lo=zeros(cm.origin_lo, (B, 2, 2)),
                             resolution_lo=zeros(cm.resolution_lo, (B, 2)))
    mask = dataclasses.replace(mask, origin_lo=zeros(mask.origin_lo, (M, 2, 2)))
  idx, ok, _, en, win, tf = common.batched_inputs(cm, mask, jnp.zeros((B, 3)), mask_index, enabled, window, transform,
                                               "test")
  return cm, mask, idx, ok, common.fill_error(state, B), win, en, tf


@pytest.mark.parametrize("n", range(3))
def test_other_frame_kernels_equal_the_exact_path(n):
  # Centres on mask-cell edges and one ulp off (cases 0 and 1), random transforms (case 2);
  # both kernels: "map" (checked floors, the CPU's) and "vmap" (edge tables, four cells a word).
  case, tf = _se2_cases()[n]
  args = _impl_inputs(case, jnp.asarray(tf), lower_parts=True)
  for cfg in (PLAIN, ESCAPE):
    want = process.filter_batch(*args, config=cfg, exact=True)
    for loop in ("map", "vmap"):
      cost, st = _other_frame(*args, config=cfg, loop=loop)
      np.testing.assert_array_equal(np.asarray(cost), np.asarray(want[0].cost), err_msg=f"{loop} {cfg}")
      np.testing.assert_array_equal(np.asarray(st.last_pose_lethal), np.asarray(want[1].last_pose_lethal))
  assert (np.asarray(want[0].cost) != np.asarray(case[0].cost)).any()


@pytest.mark.parametrize("n", range(3))
def test_other_frame_pallas_kernel_equals_the_exact_path(n):
  """`pallas.other_frame_write` (in the Pallas interpreter here; tuned small so a robot spans
  several programs) on the same edge, one-ulp and random cases, plain and in escape mode."""
  case, tf = _se2_cases()[n]
  args = _impl_inputs(case, jnp.asarray(tf), lower_parts=True)
  tuning = ko.PallasTuning(interpret=True, frame_block_cells=64)
  for cfg in (PLAIN, ESCAPE):
    want = process.filter_batch(*args, config=cfg, exact=True)
    cost, st = _other_frame(*args, config=dataclasses.replace(cfg, frame_kernel="pallas", pallas=tuning),
                            loop="vmap")
    np.testing.assert_array_equal(np.asarray(cost), np.asarray(want[0].cost), err_msg=f"{cfg}")
    np.testing.assert_array_equal(np.asarray(st.last_pose_lethal), np.asarray(want[1].last_pose_lethal))


def test_other_frame_pallas_kernel_runs_large_batches_in_chunks(monkeypatch):
  """A fleet whose costmaps pass the kernel's 32-bit offsets runs in chunks of robots (here: pretend
  two robots reach it), with the exact path's integers; before, the default kernel raised there."""
  from jaxfilters.keepout import pallas as kp
  case, tf = _se2_cases()[2]
  args = _impl_inputs(case, jnp.asarray(tf), lower_parts=True)
  monkeypatch.setattr(kp, "_MAX_COST_BYTES", 2 * H * W + 1)
  cfg = dataclasses.replace(PLAIN, frame_kernel="pallas", pallas=ko.PallasTuning(interpret=True))
  run = functools.partial(other_frame.other_frame_batch, config=cfg, loop="vmap")
  assert str(jax.make_jaxpr(run)(*args)).count("pallas_call") == -(-B // 2)
  want = process.filter_batch(*args, config=PLAIN, exact=True)[0].cost
  np.testing.assert_array_equal(np.asarray(run(*args)[0]), np.asarray(want))


def test_frame_kernel_pallas_off_gpu_raises_or_runs_in_the_interpreter():
  """`frame_kernel="pallas"` never falls back silently: off a GPU it raises naming the field; with the
  interpreter it runs under the CPU's default loop and gives the exact path's integers."""
  case, tf = _se2_cases()[2]
  cm, mask, state, window, mask_index, enabled = case
  poses = jnp.zeros((B, 3), jnp.float32)
  run = lambda cfg: ko.keepout_filter(cm, mask, poses, state, mask_index=mask_index, enabled=enabled, window=window,
                                      transform=jnp.asarray(tf), config=cfg)[0].cost
  if jax.default_backend() != "gpu":
    with pytest.raises(ValueError, match=r"KeepoutConfig\(frame_kernel='pallas'\) needs a GPU backend.*"
                                         r"Use frame_kernel='xla' or 'auto'"):
      run(ko.KeepoutConfig(frame_kernel="pallas"))
  got = run(ko.KeepoutConfig(frame_kernel="pallas", pallas=ko.PallasTuning(interpret=True)))
  want = _run(*case, jnp.asarray(tf), PLAIN, exact=True)[0]
  np.testing.assert_array_equal(np.asarray(got), want)


def test_other_frame_kernels_run_the_exact_path_where_edge_tables_are_untrusted():
  # A 2**-41 m mask (below the tables' range): the robots on it must run the exact path.
  rng = np.random.default_rng(3)
  mres, res = 2.0 ** -41, 2.0 ** -42
  case = fleet(rng, res, mres, np.round(rng.uniform(0, 4, (B, 2))) * res, [(0.0, 0.0), (2 * mres, -mres)])
  tf = np.zeros((B, 3), np.float32)
  tf[:, 2] = rng.uniform(-np.pi, np.pi, B)
  tf[:, :2] = rng.uniform(2, 8, (B, 2)) * mres
  args = _impl_inputs(case, jnp.asarray(tf), lower_parts=True)
  assert not np.asarray(other_frame.edge_tables(args[1])[-1]).any()
  want = np.asarray(process.filter_batch(*args, config=PLAIN, exact=True)[0].cost)
  assert (want != np.asarray(case[0].cost)).any()
  np.testing.assert_array_equal(np.asarray(_other_frame(*args, config=PLAIN, loop="vmap")[0]), want)
  pallas_cfg = ko.KeepoutConfig(frame_kernel="pallas", pallas=ko.PallasTuning(interpret=True))
  np.testing.assert_array_equal(np.asarray(_other_frame(*args, config=pallas_cfg, loop="vmap")[0]), want)


def _exact_vectors(cm, mask, idx, ok, win, en):
  """Per-robot exact index vectors and window flags (the exact arithmetic, no brackets)."""
  h, w = cm.cost.shape[1:]
  hm, wm = mask.data.shape[1:]

  def one(origin, origin_lo, res, res_lo, i, ok, win, en):
    o, r = geometry.origin_terms(origin, origin_lo), geometry.resolution_terms(res, res_lo)
    mo, mr = mask_lookup.mask_origin_terms(mask, i), mask.resolution[i]
    cells = prologue.exact_axis_cells((h, w), o, r, mo, mr, (hm, wm))
    overlap, box, _ = prologue.box_one((hm, wm), o, r, mo, mr, win, exact=True)
    return cells, common.window_flags(w, h, *box, en & overlap & ok)
  return jax.vmap(one)(cm.origin, cm.origin_lo, cm.resolution, cm.resolution_lo, idx, ok, win, en)


_other_res = jax.jit(other_resolution.other_resolution_batch, static_argnames=("config",))


@pytest.mark.parametrize("n", [2, 3, 4])
def test_other_resolution_kernels_equal_the_exact_path(n):
  # A finer mask (every centre on an edge) and coarser masks: the vectorised kernel (four cells
  # a word) and the CPU's byte gather, robot by robot.
  case = _same_frame_cases()[n]
  cm, mask, idx, ok, state, win, en, _ = _impl_inputs(case, None)
  ((mx, vx), (my, vy)), (col_ok, row_ok) = _exact_vectors(cm, mask, idx, ok, win, en)
  cells = (cm.cost, idx, mx, vx, my, vy, col_ok, row_ok, state)
  flat = mask.data.reshape(-1)
  for cfg in (PLAIN, ESCAPE):
    want = np.asarray(process.filter_batch(cm, mask, idx, ok, state, win, en, None, config=cfg, exact=True)[0].cost)
    np.testing.assert_array_equal(np.asarray(_other_res(cells, mask, config=cfg)), want)
    one = lambda c, i, mx, vx, my, vy, co, ro, st: other_resolution.gather_write_one(
        c, flat, i, (HM, WM), mx, vx, my, vy, co, ro, st, config=cfg)
    np.testing.assert_array_equal(np.asarray(jax.vmap(one)(*cells)), want)
  assert (want != np.asarray(cm.cost)).any()


def test_vectorised_same_frame_batch_gathers_other_resolutions():
  args = _impl_inputs(_same_frame_cases()[3], None)
  want = process.filter_batch(*args, config=ESCAPE, exact=True)
  same_frame_batch = jax.jit(same_frame.same_frame_batch, static_argnames=("config", "loop"))
  cost, st = same_frame_batch(*args[:-1], config=ESCAPE, loop="vmap")
  np.testing.assert_array_equal(np.asarray(cost), np.asarray(want[0].cost))
  np.testing.assert_array_equal(np.asarray(st.last_pose_lethal), np.asarray(want[1].last_pose_lethal))
  with pytest.raises(ValueError, match="loop must be"):
    same_frame_batch(*args[:-1], config=ESCAPE, loop="nope")
  with pytest.raises(ValueError, match="loop must be"):
    _other_frame(*_impl_inputs(_se2_cases()[2][0], jnp.zeros((B, 3))), config=PLAIN, loop="nope")
