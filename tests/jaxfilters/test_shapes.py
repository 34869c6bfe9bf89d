"""Shapes rasterised on the device against Nav2's Vector Object server rule, cell by cell.

Two independent references, both plain Python loops over cells and shapes:
`_vo_reference` is the C++ (`isPointInsidePolygon`, the circle test and
`processVal`) in float64, as Nav2 runs it; `_exact_reference` evaluates the
same predicates with `fractions.Fraction`, the real-number rule the rasteriser
implements, which decides cell centres that lie exactly on an edge.
"""

import dataclasses
from fractions import Fraction

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, strategies as st

from tests.compile_count import count_compiles
from jaxfilters import constants, geometry
from jaxfilters import shapes as S
from jaxfilters.grid import OccupancyGrid
from jaxfilters.keepout import KeepoutState, keepout_filter
from jaxfilters.speed import SpeedState, speed_filter
from jaxfilters.types import Costmap, FilterInfo, FilterMask

H, W = 24, 30          # one grid shape and one slot layout: one compile per overlay type
SLOTS = dict(max_polygons=4, max_vertices=8, max_circles=4)


# ----------------------------------------------------------------------------- references


def _vo_inside_polygon(px, py, pts):
  """nav2_util::geometry_utils::isPointInsidePolygon, in float64."""
  res = False
  i = len(pts) - 1
  for j in range(len(pts)):
    xi, yi, xj, yj = float(pts[i][0]), float(pts[i][1]), float(pts[j][0]), float(pts[j][1])
    if (py <= yi) == (py > yj):
      x_inter = xi + (py - yi) * (xj - xi) / (yj - yi)
      if x_inter > px:
        res = not res
    i = j
  return res


def _process_val(m, v, overlay):
  """nav2_map_server processVal."""
  if overlay == S.OVERLAY_SEQ:
    return v
  if overlay == S.OVERLAY_MAX:
    return v if v > m else m
  if (m == -1 or v < m) and v != -1:
    return v
  return m


def _reference(shapes, origin, res, h, w, *, overlay=S.OVERLAY_SEQ, default=-1, exact=False):
  """The Vector Object server's putVectorObjectsOnMap on a given grid (float32 inputs)."""
  num = Fraction if exact else float
  ox, oy, r = (num(float(np.float32(v))) for v in (origin[0], origin[1], res))
  out = np.full((h, w), default, np.int64)
  for s in shapes:
    if isinstance(s, S.Polygon):
      pts = [(num(float(x)), num(float(y))) for x, y in np.float32(s.points)]
    else:
      cx, cy = (num(float(v)) for v in np.float32(s.center))
      rad = num(float(np.float32(s.radius)))
    for my in range(h):
      for mx in range(w):
        wx, wy = ox + (mx + num(0.5)) * r, oy + (my + num(0.5)) * r
        if isinstance(s, S.Polygon):
          inside = _vo_inside_polygon(wx, wy, pts) if not exact else _exact_inside_polygon(wx, wy, pts)
        else:
          inside = (wx - cx) * (wx - cx) + (wy - cy) * (wy - cy) <= rad * rad
        if inside:
          out[my, mx] = _process_val(out[my, mx], s.value, overlay)
  return out


def _exact_inside_polygon(px, py, pts):
  res = False
  i = len(pts) - 1
  for j in range(len(pts)):
    (xi, yi), (xj, yj) = pts[i], pts[j]
    if (py <= yi) == (py > yj) and xi + (py - yi) * (xj - xi) / (yj - yi) > px:
      res = not res
    i = j
  return res


# ----------------------------------------------------------------------------- random cases


def _polygon(rng, kind, centre, size):
  n = int(rng.integers(3, SLOTS["max_vertices"] + 1))
  if kind == "convex":
    ang = np.sort(rng.uniform(0, 2 * np.pi, n))
    rad = np.full(n, size)
  elif kind == "star":                    # non-convex, simple
    ang = np.sort(rng.uniform(0, 2 * np.pi, n))
    rad = size * rng.uniform(0.2, 1.0, n)
  else:                                   # self-intersecting: even-odd decides
    ang = rng.uniform(0, 2 * np.pi, n)
    rad = size * rng.uniform(0.3, 1.0, n)
  return np.stack([centre[0] + rad * np.cos(ang), centre[1] + rad * np.sin(ang)], 1)


def _case(seed, *, snapped=False):
  """Random grid and shapes (values include -1); `snapped` puts vertices and centres on cell centres."""
  rng = np.random.default_rng(seed)
  res = np.float32(0.25 if snapped else rng.choice([0.05, 0.1, 0.03, 0.25, 1.0]))
  origin = (np.float32(rng.integers(-8, 8, 2) * res) if snapped
            else np.float32(rng.uniform(-20, 20, 2)))
  extent = np.float32([W, H]) * res
  items = []
  for k in range(int(rng.integers(3, 7))):
    centre = origin + extent * rng.uniform(0.05, 0.95, 2)
    size = float(extent.min() * rng.uniform(0.1, 0.5))
    value = int(rng.choice([-1, 0, 1, 30, 50, 99, 100]))
    if rng.random() < 0.6 and sum(isinstance(i, S.Polygon) for i in items) < SLOTS["max_polygons"]:
      pts = _polygon(rng, ["convex", "star", "tangled"][k % 3], centre, size)
      if snapped:    # vertices on cell centres: centre-on-edge ties everywhere
        pts = origin + (np.round((pts - origin) / res - 0.5) + 0.5) * res
      items.append(S.Polygon(np.float32(pts), value))
    elif sum(isinstance(i, S.Circle) for i in items) < SLOTS["max_circles"]:
      if snapped:
        centre = origin + (np.round((centre - origin) / res - 0.5) + 0.5) * res
        size = float(res * rng.integers(1, 5))
      items.append(S.Circle(np.float32(centre), size, value))
  return items, origin, res


def _run(items, origin, res, **kw):
  out = S.rasterize(S.Shapes.create(items, **SLOTS), origin, res, shape=(H, W), **kw)
  assert bool(out.valid)
  return np.asarray(out.data)


@pytest.mark.parametrize("overlay", S.OVERLAY_TYPES)
@pytest.mark.parametrize("seed", range(6))
def test_matches_vector_object_server_float64(seed, overlay):
  items, origin, res = _case(seed)
  default = [-1, 0, 50][seed % 3]
  got = _run(items, origin, res, default_value=default, overlay_type=overlay)
  np.testing.assert_array_equal(got, _reference(items, origin, res, H, W, overlay=overlay, default=default))


@pytest.mark.parametrize("seed", range(100, 104))
def test_centres_on_edges_follow_the_exact_rule(seed):
  items, origin, res = _case(seed, snapped=True)
  np.testing.assert_array_equal(_run(items, origin, res),
                                _reference(items, origin, res, H, W, exact=True))


def test_edge_rule_of_an_axis_aligned_rectangle():
  """Centres on the left and top edges are in; on the right and bottom edges out (hand-worked)."""
  # res 1, origin 0: centres at k + 0.5. The rectangle's edges run through centres 1.5 and 4.5.
  rect = S.Polygon([(1.5, 1.5), (4.5, 1.5), (4.5, 4.5), (1.5, 4.5)], 100)
  got = _run([rect], np.float32([0, 0]), np.float32(1.0))
  want = np.full((H, W), -1)
  want[2:5, 1:4] = 100           # rows y = 2.5, 3.5, 4.5 (top edge in); columns x = 1.5 .. 3.5
  np.testing.assert_array_equal(got, want)
  # A circle of radius 2 about a centre: the four centres at distance exactly 2 are in.
  got = _run([S.Circle((2.5, 2.5), 2.0, 7)], np.float32([0, 0]), np.float32(1.0))
  yy, xx = np.mgrid[0:H, 0:W] + 0.5
  np.testing.assert_array_equal(got == 7, (xx - 2.5) ** 2 + (yy - 2.5) ** 2 <= 4.0)
  assert got[2, 4] == 7 and got[0, 2] == 7       # (4.5, 2.5) and (2.5, 0.5): on the circle


def test_nav2_vector_object_server_unit_test_map():
  """nav2_map_server/test/unit/test_vector_object_server.cpp `verifyMap(true)`.

  Polygon (-1,-1)..(1,1) value 100, circle centre (3, 0) radius 1 value 50,
  resolution 0.1. The server sizes its map to the shapes: origin (-1, -1),
  width int(5 / 0.1) + 1 = 51, height int(2 / 0.1) + 1 = 21 (double division).
  """
  items = [S.Polygon([(1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)], 100), S.Circle((3.0, 0.0), 1.0, 50)]
  got = np.asarray(S.rasterize(S.Shapes.create(items), np.float32([-1, -1]), np.float32(0.1), shape=(21, 51)).data)
  for my in range(21):
    for mx in range(51):
      if mx <= 19 and my <= 19:
        want = 100
      elif np.hypot(39.5 - mx, 9.5 - my) <= 10.0:
        want = 50
      else:
        want = -1
      assert got[my, mx] == want, (mx, my)


def test_sequential_overlay_follows_arrival_order_not_slots():
  big = S.Polygon([(0, 0), (3, 0), (3, 3), (0, 3)], 10)
  small = S.Circle((1.5, 1.5), 0.6, 90)
  grid = dict(origin=np.float32([0, 0]), resolution=np.float32(0.5), shape=(H, W))
  ras = lambda sh: np.asarray(S.rasterize(sh, **grid).data)
  a = ras(S.Shapes.create([big, small], **SLOTS))
  b = ras(S.Shapes.create([small, big], **SLOTS))
  assert (a == 90).sum() == 4 and not (b == 90).any()
  # Modifying a shape keeps its place; adding one into a free slot puts it last.
  sh = S.Shapes.create([small, big], **SLOTS)
  assert not (ras(sh.set_circle(0, S.Circle((1.5, 1.5), 0.6, 90))) == 90).any()
  assert (ras(sh.remove_circle(0).set_circle(0, small)) == 90).sum() == 4
  assert (ras(sh.remove_circle(0).set_circle(2, small)) == 90).sum() == 4


# ----------------------------------------------------------------------------- four ways


def test_batched_masks_match_one_by_one():
  """[M] grids: vmap of the kernel (one program for per-grid and shared shapes) vs one by one."""
  cases = [_case(s) for s in (7, 8, 9)]
  sets = [S.Shapes.create(items, **SLOTS) for items, _, _ in cases]
  stacked = jax.tree.map(lambda *x: jnp.stack(x), *sets)
  origins = np.stack([c[1] for c in cases])
  res = np.stack([c[2] for c in cases])
  out = S.rasterize(stacked, origins, res, shape=(H, W), overlay_type=S.OVERLAY_MAX)
  assert out.data.shape == (3, H, W) and np.asarray(out.valid).all()
  shared = S.rasterize(sets[0], origins, res, shape=(H, W), overlay_type=S.OVERLAY_MAX)
  for k, (items, origin, r) in enumerate(cases):
    want = _reference(items, origin, r, H, W, overlay=S.OVERLAY_MAX)
    np.testing.assert_array_equal(np.asarray(out.data[k]), want)
    np.testing.assert_array_equal(np.asarray(out.data[k]), _run(items, origin, r, overlay_type=S.OVERLAY_MAX))
    np.testing.assert_array_equal(np.asarray(shared.data[k]),
                                  _reference(cases[0][0], origins[k], res[k], H, W, overlay=S.OVERLAY_MAX))


def test_moving_adding_removing_shapes_compiles_nothing():
  items, origin, res = _case(3)
  sh = S.Shapes.create(items[:2], **SLOTS)
  S.rasterize(sh, origin, res, shape=(H, W)).data.block_until_ready()
  moved = dataclasses.replace(sh, vertices=sh.vertices + 0.37, center=sh.center - 0.21)
  added = sh.set_circle(SLOTS["max_circles"] - 1, S.Circle(origin + 1.0, 0.8, 42))
  removed = added.remove_polygon(0) if bool(added.polygon_active[0]) else added.remove_circle(0)
  with count_compiles() as compiles:
    for s, o, r, kw in ((moved, origin, res, {}), (added, origin + 0.5, res * 2, dict(default_value=0)),
                        (removed, origin, res, dict(overlay_type=S.OVERLAY_MIN))):
      S.rasterize(s, o, r, shape=(H, W), **kw).data.block_until_ready()
  assert compiles() == 0
  got = np.asarray(S.rasterize(added, origin, res, shape=(H, W)).data)
  want_items = [i for i in items[:2]] + [S.Circle(origin + 1.0, 0.8, 42)]
  np.testing.assert_array_equal(got, _reference(want_items, origin, res, H, W))


# ----------------------------------------------------------------------------- errors and flags


def test_factory_rejects_bad_shapes_with_expected_vs_got():
  with pytest.raises(ValueError, match="at least 3 vertices"):
    S.Shapes.create([S.Polygon([(0, 0), (1, 1)])])
  with pytest.raises(ValueError, match="max_vertices = 3"):
    S.Shapes.create([S.Polygon([(0, 0), (1, 0), (1, 1), (0, 1)])], max_vertices=3)
  with pytest.raises(ValueError, match=r"-1\.\.100"):
    S.Shapes.create([S.Circle((0, 0), 1.0, 101)])
  with pytest.raises(ValueError, match="integer OccupancyGrid value"):
    S.Shapes.create([S.Circle((0, 0), 1.0, 50.5)])
  with pytest.raises(ValueError, match="radius must be >= 0"):
    S.Shapes.create([S.Circle((0, 0), -0.1)])
  with pytest.raises(ValueError, match="finite"):
    S.Shapes.create([S.Polygon([(0, 0), (np.nan, 0), (1, 1)])])
  with pytest.raises(ValueError, match="inf"):
    S.Shapes.create([S.Circle((1e39, 0), 1.0)])
  with pytest.raises(ValueError, match=r"2\*\*-32"):
    S.Shapes.create([S.Circle((1e-20, 0), 1.0)])
  with pytest.raises(ValueError, match="max_circles = 1"):
    S.Shapes.create([S.Circle((0, 0), 1.0), S.Circle((1, 0), 1.0)], max_circles=1)
  with pytest.raises(ValueError, match="Polygon or Circle"):
    S.Shapes.create([((0, 0), 1.0)])
  with pytest.raises(ValueError, match=r"\[N, 2\]"):
    S.Shapes.create([S.Polygon([0, 1, 2, 3, 4, 5])])
  sh = S.Shapes.create([S.Circle((0, 0), 1.0)], max_polygons=1)
  with pytest.raises(ValueError, match=r"slot must be an integer in \[0, 1\)"):
    sh.set_circle(1, S.Circle((0, 0), 1.0))
  with pytest.raises(ValueError, match="overlay_type must be one of"):
    S.rasterize(sh, np.float32([0, 0]), np.float32(0.1), shape=(4, 4), overlay_type=3)
  with pytest.raises(ValueError, match=r"default_value: value must lie in -1\.\.100"):
    S.rasterize(sh, np.float32([0, 0]), np.float32(0.1), shape=(4, 4), default_value=-2)
  with pytest.raises(ValueError, match=r"shape must be a tuple \(H, W\)"):
    S.rasterize(sh, np.float32([0, 0]), np.float32(0.1), shape=(0, 4))
  with pytest.raises(ValueError, match=r"\[M, 2\] and \[M\]"):
    S.rasterize(sh, np.float32([[0, 0]]), np.float32(0.1), shape=(4, 4))


def test_out_of_domain_values_under_jit_are_flagged_not_drawn():
  inside = S.Circle((1.0, 1.0), 0.5, 100)
  sh = S.Shapes.create([S.Polygon([(0, 0), (2, 0), (2, 2)], 60), inside], **SLOTS)
  grid = dict(origin=np.float32([0, 0]), resolution=np.float32(0.25), shape=(H, W))
  base = S.rasterize(sh, **grid)
  assert bool(base.valid)
  far = dataclasses.replace(sh, vertices=sh.vertices.at[0, 1, 0].set(1e12))
  out = S.rasterize(far, **grid)
  assert not bool(out.valid)
  # The bad polygon is not drawn; the circle still is.
  np.testing.assert_array_equal(np.asarray(out.data),
                                _reference([inside], grid["origin"], grid["resolution"], H, W))
  nan = dataclasses.replace(sh, radius=sh.radius.at[0].set(np.nan))
  assert not bool(S.rasterize(nan, **grid).valid)
  few = dataclasses.replace(sh, num_vertices=sh.num_vertices.at[0].set(2))
  assert not bool(S.rasterize(few, **grid).valid)
  loud = dataclasses.replace(sh, circle_value=sh.circle_value.at[0].set(120))
  assert not bool(S.rasterize(loud, **grid).valid)
  assert not bool(S.rasterize(sh, grid["origin"], np.float32(0.0), shape=(H, W)).valid)
  # Overlay settings out of range that reach the device (traced, so the host check cannot
  # see them; the per-grid kernel is jitted with them as arguments): all unknown, flagged.
  for d, o in ((-5, 0), (0, 3)):
    bad = jax.jit(lambda d, o: S.rasterize_one(sh, grid["origin"], grid["resolution"], d, o, shape=(H, W)))(d, o)
    assert not bool(bad.valid) and (np.asarray(bad.data) == -1).all()
  # Removed (inactive) shapes are not checked: an inactive NaN slot is fine.
  assert bool(S.rasterize(nan.remove_circle(0), **grid).valid)


@given(st.integers(0, 2 ** 31 - 1))
def test_exact_sign_matches_fractions(seed):
  """Sums built to cancel (a, b, -a, -b plus small parts) and exact zeros, as in the predicates."""
  rng = np.random.default_rng(seed)
  n, lanes = 24, 16
  big = np.float32(rng.standard_normal((n // 2, lanes)) * 2.0 ** rng.integers(-20, 20, (n // 2, lanes)))
  small = np.float32(rng.standard_normal((n // 2, lanes)) * 2.0 ** rng.integers(-60, -20, (n // 2, lanes)))
  small[:, rng.random(lanes) < 0.4] = 0.0
  terms = np.concatenate([big, -big + small])[rng.permutation(n)]
  sign, resolved = jax.jit(geometry.exact_sign)(jnp.asarray(terms))
  assert np.asarray(resolved).all()
  for lane in range(lanes):
    exact = sum(Fraction(float(v)) for v in terms[:, lane])
    assert int(sign[lane]) == (exact > 0) - (exact < 0)


# ----------------------------------------------------------------------------- driving filters


def test_rasterised_mask_drives_keepout_and_speed_filters_and_follows_a_moving_zone():
  grid = OccupancyGrid.create(np.full((H, W), -1, np.int8), 0.1, (0.0, 0.0))
  keepout = FilterMask.create(grid, FilterInfo.create(constants.KEEPOUT_FILTER))
  speed = FilterMask.create(grid, FilterInfo.create(constants.SPEED_FILTER_PERCENT, 100.0, -1.0))
  zone = S.Polygon([(0.5, 0.5), (1.0, 0.5), (1.0, 1.0), (0.5, 1.0)], 100)
  slow = S.Circle((1.5, 1.5), 0.3, 60)             # 100 - 60 = 40 %
  sh = S.Shapes.create([zone, slow], **SLOTS)
  costmap = Costmap.create(np.zeros((1, H, W), np.uint8), (0.0, 0.0), 0.1)
  poses = np.float32([[0.75, 0.75, 0.0]])

  def run(shapes, at):
    km, kv = S.rasterize_mask(shapes, keepout)
    sm, sv = S.rasterize_mask(shapes, speed, default_value=0)
    assert bool(kv[0]) and bool(sv[0])
    cost, _ = keepout_filter(costmap, km, poses, KeepoutState.create(1))
    _, out = speed_filter(sm, np.float32([[at[0], at[1], 0.0]]), SpeedState.create(1))
    return np.asarray(cost.cost[0]), np.asarray(km.data[0]), float(out.speed_limit[0])

  cost, data, limit = run(sh, (1.5, 1.5))
  np.testing.assert_array_equal(data, _reference([zone, slow], (0, 0), 0.1, H, W))
  # Keepout writes round(2.54 d) where the mask is known (unknown cells are skipped).
  d = data.astype(np.int64)
  want = np.where(d >= 0, np.floor(d * 254 / 100 + 0.5), 0).astype(np.uint8)
  np.testing.assert_array_equal(cost, want)
  assert cost[7, 7] == 254 and cost[15, 15] == 152
  assert limit == pytest.approx(40.0)
  moved = dataclasses.replace(sh, vertices=sh.vertices + np.float32(0.8), center=sh.center - np.float32(1.0))
  cost2, data2, limit2 = run(moved, (0.5, 0.5))
  assert cost2[7, 7] == 0 and cost2[15, 15] == 254   # the keepout followed the zone
  assert limit2 == pytest.approx(40.0)               # the slow zone moved to (0.5, 0.5)
  assert run(moved, (1.5, 1.5))[2] == 0.0            # old place: now keepout d = 100 -> 0 % = no limit
  np.testing.assert_array_equal(data2, _reference(
      [S.Polygon(np.float32(zone.points) + np.float32(0.8), 100), S.Circle(np.float32(slow.center) - 1, 0.3, 60)],
      (0, 0), 0.1, H, W))
