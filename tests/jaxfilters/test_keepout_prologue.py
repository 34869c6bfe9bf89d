"""The same-frame keepout prologue on per-robot scalars gives the exact path's integers.

`prologue.slice_test_one` decides whether a robot's window reads its mask cells as one slice from
the exact floors at the window's two end columns and rows (bracketed, or exact), instead
of building and scanning the [W] / [H] index vectors. These tests check it against the
index vectors computed with Fractions from the host doubles' float32 parts (soundness: a
sliced robot reads exactly the cells the vectors name; completeness: an exactly
consecutive window is sliced), the bracketed answer against the exact one, and the whole
filter (both batch loops, the packed XLA kernel and the Pallas kernel in interpret mode)
bit for bit against the per-cell exact path on adversarial fleets: centres exactly on
mask-cell edges and one ulp off, a double 0.05 against the float32 0.05, origins with
float32 parts, windows partly off the mask, huge coordinates. Also: no loop runs in the
compiled aligned path outside a branch taken only when some robot needs the exact
arithmetic.
"""

import math
import re
from fractions import Fraction

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfilters import geometry
from jaxfilters import keepout as ko
from jaxfilters.keepout import PallasTuning, common, process, prologue, same_frame
from jaxfilters.keepout import pallas as kp
from jaxfilters import mask_lookup
from benchmarks.keepout_paths import path_report
from tests import keepout_fleets
from tests.keepout_fleets import H, HM, W, WM

B = 8
PLAIN = ko.KeepoutConfig()
PALLAS = ko.KeepoutConfig(kernel="pallas", pallas=PallasTuning(interpret=True))


def _nudge(x, steps):
  """float32 x moved by `steps` ulps (negative: down)."""
  x = np.float32(x)
  for _ in range(abs(steps)):
    x = np.nextafter(x, np.float32(np.inf if steps > 0 else -np.inf))
  return x


def _fleet(rng, res, mres, origins, mask_origins, *, windows=None):
  """`keepout_fleets.fleet_with_lower_parts` of B robots."""
  return keepout_fleets.fleet_with_lower_parts(rng, res, mres, origins, mask_origins, windows=windows, b=B)


def _cases():
  """Adversarial same-frame fleets (name, fleet)."""
  rng = np.random.default_rng(90)
  mo = [(9.0, 9.5), (9.15, 9.05)]                       # decimal: float32 parts
  cases = []
  # A double 0.05 against the float32 0.05, origins on the mask grid (in doubles), some
  # windows partly or wholly off the mask.
  k = rng.integers(-W - 3, WM + 3, (B, 2))
  cases.append(("double_0.05", _fleet(rng, 0.05, 0.05, 9.0 + k * 0.05, mo)))
  # Equal binary resolutions, master centres exactly on mask-cell edges, and one ulp off.
  k = rng.integers(-W - 3, WM + 3, (B, 2))
  origins = (k + 0.5) * 0.25
  for r in range(1, B, 2):
    origins[r] = _nudge(origins[r, 0], (-1) ** r), _nudge(origins[r, 1], 1)
  origins[B - 1] = (0.1, 0.3)   # a double origin (float32 parts), so every fleet has the same pytree layout
  cases.append(("edges", _fleet(rng, 0.25, 0.25, origins, [(0.0, 0.0), (0.1, 0.3)])))
  # Centres on the mask's cell centres (the usual aligned case) with double origins.
  k = rng.integers(-4, 8, (B, 2))
  cases.append(("centres", _fleet(rng, 0.1, 0.1, 0.3 + k * 0.1, [(0.3, 0.3), (0.1, 0.2)])))
  # Huge coordinates: both grids near 3e5 m (an ulp is 3 cm), and some costmaps far away.
  k = rng.integers(-W, WM, (B, 2))
  origins = 3e5 + k * 0.05
  origins[B - 1] = (1e12, -1e12)
  origins[B - 2] = (-3e7, 3e5)
  cases.append(("huge", _fleet(rng, 0.05, 0.05, origins, [(3e5, 3e5), (3e5 + 0.05, 3e5 - 0.1)])))
  # Other resolutions: finer (every centre on an edge) and coarser masks; only robots off
  # the mask or with empty windows may slice.
  k = rng.integers(-W - 3, WM + 3, (B, 2))
  cases.append(("finer", _fleet(rng, 0.5, 0.25, k * 0.5, [(0.0, 0.0), (-1.0, 0.5)])))
  cases.append(("coarser", _fleet(rng, 0.05, 0.1, rng.uniform(-1, 1, (B, 2)), [(-0.5, -0.3), (0.1, -0.7)])))
  # Narrow windows (one column, one row) at random places over a random geometry.
  x0, y0 = rng.integers(0, W, B), rng.integers(0, H, B)
  windows = np.stack([x0, y0, x0 + 1, y0 + rng.integers(0, 3, B)], 1)
  cases.append(("narrow", _fleet(rng, 0.05, 0.05, rng.uniform(-1, 0.5, (B, 2)), [(-0.5, -0.3), (0.1, -0.7)],
                                 windows=windows)))
  return cases


CASES = _cases()


def _frac(parts):
  return sum((Fraction(float(p)) for p in parts), Fraction(0))


def _geometry(cm, mask, r, i):
  """Float32 parts of robot r's and mask i's geometry, as the batch sees them."""
  lo = lambda a: None if a is None else a[r]
  o = geometry.origin_terms(cm.origin[r], lo(cm.origin_lo))
  res = geometry.resolution_terms(cm.resolution[r], lo(cm.resolution_lo))
  return o, res, mask_lookup.mask_origin_terms(mask, i), mask.resolution[i]


def _reference_cells(o, res, mo, mres, axis, n):
  """Exact mask cells of the n centres along `axis`, from the float32 parts (Fractions)."""
  origin = _frac([np.asarray(t)[axis] for t in o])
  r = _frac([np.asarray(t) for t in res])
  morigin = _frac([np.asarray(t)[axis] for t in mo])
  mr = Fraction(float(mres))
  return [math.floor((origin + (j + Fraction(1, 2)) * r - morigin) / mr) for j in range(n)]


@jax.jit
def _slice_tests(o, res, mo, mres, box):
  fast = prologue.slice_test_one((H, W), o, res, mo, mres, (HM, WM), box)
  exact = prologue.slice_test_one((H, W), o, res, mo, mres, (HM, WM), box, exact=True)
  return fast, exact


def _boxes(rng):
  """Windows: full, random (partly off the costmap), single cells and empty ones."""
  boxes = [(0, 0, W, H), (3, 2, 4, 3), (5, 5, 5, 9), (0, 0, 0, 0)]
  for _ in range(4):
    x0, y0 = rng.integers(0, W), rng.integers(0, H)
    boxes.append((x0, y0, rng.integers(x0, W + 1), rng.integers(y0, H + 1)))
  return boxes


@pytest.mark.parametrize("name", [c[0] for c in CASES])
def test_slice_test_agrees_with_fraction_index_vectors(name):
  cm, mask, _, _, mask_index, _ = dict(CASES)[name]
  rng = np.random.default_rng(len(name))
  decided_fast = sliced_seen = 0
  for r in range(B):
    i = int(mask_index[r])
    o, res, mo, mres = _geometry(cm, mask, r, i)
    cols = _reference_cells(o, res, mo, mres, 0, W)
    rows = _reference_cells(o, res, mo, mres, 1, H)
    for box in _boxes(rng):
      (fx, fy, fs, fd), (ex, ey, es, ed) = _slice_tests(o, res, mo, mres, jnp.asarray(box, jnp.int32))
      assert bool(ed)
      x0, y0, x1, y1 = box
      spans = [(cols, range(x0, x1), int(ex), W, WM), (rows, range(y0, y1), int(ey), H, HM)]
      empty = x1 <= x0 or y1 <= y0
      # Completeness: an exactly consecutive window (or an empty one) is sliced.
      consecutive = all(all(c[j] - c[s[0]] == j - s[0] for j in s) for c, s, *_ in spans)
      if empty or consecutive:
        assert bool(es), (name, r, box)
      if bool(es) and not empty:
        sliced_seen += 1
        # Soundness: the table column start + j - n is the mask cell where that is on the
        # mask, and off the mask (padding) exactly where the cell is.
        for c, s, start, n, size in spans:
          for j in s:
            t = start + j - n
            on = 0 <= c[j] < size
            assert (0 <= t < size) == on and (not on or t == c[j]), (name, r, box, j)
      # The bracket, where it decides, gives the exact answer (and its start when sliced).
      if bool(fd):
        decided_fast += 1
        assert bool(fs) == bool(es)
        if bool(es) and not empty:
          assert (int(fx), int(fy)) == (int(ex), int(ey))
  assert decided_fast > 0
  if name not in ("finer", "coarser"):
    assert sliced_seen > 0


@pytest.mark.parametrize("name", [c[0] for c in CASES])
def test_filter_equals_exact_path_on_adversarial_fleets(name):
  cm, mask, state, window, mask_index, enabled = dict(CASES)[name]
  idx, ok, _, en, win, tf = common.batched_inputs(cm, mask, jnp.zeros((B, 3)), mask_index, enabled, window, None, "t")
  state = common.fill_error(state, B)
  # Each batch loop and kernel once (one compile each: every fleet has one pytree layout). The
  # prologue does not depend on escape mode, which tests/jaxfilters/test_keepout_paths_random.py covers.
  runs = [(PLAIN, dict(loop="map")), (PLAIN, dict(loop="vmap")), (PALLAS, dict(loop="vmap"))]
  want = {}
  for cfg, kw in runs:
    exact_cfg = PLAIN
    if exact_cfg not in want:
      want[exact_cfg] = process.filter_batch(cm, mask, idx, ok, state, win, en, tf, config=exact_cfg, exact=True)
    want_cm, want_st = want[exact_cfg]
    got, st = _same_frame(cm, mask, idx, ok, state, win, en, config=cfg, **kw)
    np.testing.assert_array_equal(np.asarray(got), np.asarray(want_cm.cost), err_msg=f"{name} {cfg} {kw}")
    np.testing.assert_array_equal(np.asarray(st.last_pose_lethal), np.asarray(want_st.last_pose_lethal))
  want_cm = want[PLAIN][0]
  assert (np.asarray(want_cm.cost) != np.asarray(cm.cost)).any() or name in ("huge",)


_same_frame = jax.jit(same_frame.same_frame_batch, static_argnames=("config", "loop"))


def test_edge_fleet_needs_the_exact_prologue():
  """The edge fleet exercises the exact branches: brackets left open at the window ends."""
  cm, mask, *_ = dict(CASES)["edges"]
  report = path_report(cm, mask, mask_index=dict(CASES)["edges"][4])
  assert report["exact_slice_test"] > 0 and report["sliced"] > 0, report


def test_slice_params_from_bounds_equal_slice_params_from_flags():
  rng = np.random.default_rng(3)
  b, h, w = 64, 7, 9
  x0, y0 = rng.integers(-2, w + 2, b), rng.integers(-2, h + 2, b)
  x1, y1 = x0 + rng.integers(-2, w, b), y0 + rng.integers(-2, h, b)
  take, lethal = rng.random(b) < 0.7, rng.random(b) < 0.5
  idx, sx, sy = rng.integers(0, 3, b), rng.integers(0, 30, b), rng.integers(0, 30, b)
  cols, rows = np.arange(w), np.arange(h)
  col_ok = (cols >= x0[:, None]) & (cols < x1[:, None])
  row_ok = (rows >= y0[:, None]) & (rows < y1[:, None]) & take[:, None]
  want = kp.slice_params(*map(jnp.asarray, (idx, sx, sy, col_ok, row_ok, take, lethal)))
  got = kp.slice_params_from_bounds(*map(jnp.asarray, (idx, sx, sy, x0, x1, y0, y1, take, lethal)), shape=(h, w))
  np.testing.assert_array_equal(np.asarray(got), np.asarray(want))


def _entry_ops(hlo: str, op: str) -> int:
  """How many `op` instructions the ENTRY computation of an HLO module runs directly."""
  entry = hlo[hlo.index("ENTRY"):]
  entry = entry[:entry.index("\n}")]
  return len(re.findall(rf"[\s)]{op}\(", entry))


def test_aligned_path_runs_no_loop_unless_some_robot_needs_the_exact_arithmetic():
  """Every loop of the compiled vmap path sits in a conditional branch (none at the top level)."""
  cm, mask, state, window, mask_index, enabled = dict(CASES)["double_0.05"]
  idx, ok, _, en, win, _ = common.batched_inputs(cm, mask, jnp.zeros((B, 3)), mask_index, enabled, window, None, "t")
  for cfg in (PLAIN, PALLAS):
    hlo = _same_frame.lower(cm, mask, idx, ok, common.fill_error(state, B), win, en, config=cfg,
                            loop="vmap").compile().as_text()
    assert _entry_ops(hlo, "while") == 0
    assert _entry_ops(hlo, "conditional") >= 3          # window rerun, slice-test rerun, slice or gather
