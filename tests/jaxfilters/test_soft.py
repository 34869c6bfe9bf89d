"""Soft zones: signed distance against a float64 loop, gradients against central differences,
and the soft keepout cost / speed limit against the hard Nav2 filters as the width -> 0."""

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfilters import constants, shapes as S, soft
from jaxfilters.grid import OccupancyGrid
from jaxfilters.keepout import KeepoutState, keepout_filter
from jaxfilters.speed import SpeedState, speed_filter
from jaxfilters.types import Costmap, FilterInfo, FilterMask

SLOTS = dict(max_polygons=4, max_vertices=8, max_circles=4)   # as tests/jaxfilters/test_shapes.py: shared compiles
N = 64                    # points per call: one compile per function


def _items(seed):
  rng = np.random.default_rng(seed)
  items = []
  for k in range(3):
    n = int(rng.integers(3, SLOTS["max_vertices"] + 1))
    ang = np.sort(rng.uniform(0, 2 * np.pi, n))
    rad = rng.uniform(0.5, 1.5, n) if k else np.full(n, 1.2)          # one convex, others star-shaped
    c = rng.uniform(1.0, 5.0, 2)
    items.append(S.Polygon(np.float32(np.stack([c[0] + rad * np.cos(ang), c[1] + rad * np.sin(ang)], 1)),
                           int(rng.choice([20, 50, 100]))))
  for _ in range(2):
    items.append(S.Circle(np.float32(rng.uniform(1.0, 5.0, 2)), float(rng.uniform(0.3, 1.0)),
                          int(rng.choice([30, 60, 100]))))
  order = rng.permutation(len(items))
  return [items[i] for i in order]


def _closest(p, a, b):
  ab, ap = b - a, p - a
  den = float(ab @ ab)
  t = 0.0 if den == 0 else min(1.0, max(0.0, float(ap @ ab) / den))
  return a + t * ab


def _seg_dist(p, a, b):
  return float(np.hypot(*(p - _closest(p, a, b))))


def _ref_sd(point, item):
  """Float64 loop: distance to the boundary, negative inside (Nav2's even-odd test)."""
  p = np.float64(point)
  if isinstance(item, S.Circle):
    return float(np.hypot(*(p - np.float64(np.float32(item.center))))) - float(np.float32(item.radius))
  pts = np.float64(np.float32(item.points))
  n = len(pts)
  d = min(_seg_dist(p, pts[i], pts[(i + 1) % n]) for i in range(n))
  inside, j = False, n - 1
  for i in range(n):
    (xi, yi), (xj, yj) = pts[j], pts[i]
    if (p[1] <= yi) == (p[1] > yj) and xi + (p[1] - yi) * (xj - xi) / (yj - yi) > p[0]:
      inside = not inside
    j = i
  return -d if inside else d


def _slot_items(items):
  """Items by slot (polygon slots, then circle slots; None for an unused slot)."""
  polys = [i for i in items if isinstance(i, S.Polygon)]
  circles = [i for i in items if isinstance(i, S.Circle)]
  return (polys + [None] * (SLOTS["max_polygons"] - len(polys))
          + circles + [None] * (SLOTS["max_circles"] - len(circles)))


@pytest.mark.parametrize("seed", range(3))
def test_signed_distance_matches_float64_loop(seed):
  items = _items(seed)
  sh = S.Shapes.create(items, **SLOTS)
  pts = np.float32(np.random.default_rng(seed + 50).uniform(0, 6, (N, 2)))
  got = np.asarray(soft.signed_distance(sh, pts))
  want = np.array([[np.inf if it is None else _ref_sd(p, it) for it in _slot_items(items)] for p in pts])
  np.testing.assert_allclose(got, want, atol=2e-5, rtol=1e-5)
  # One point at a time, un-jitted, equals the batched call.
  for k in range(0, N, 16):
    np.testing.assert_allclose(np.asarray(soft.signed_distance_one(sh, jnp.asarray(pts[k]))), got[k], rtol=1e-6)


def test_removed_and_malformed_slots_are_infinitely_far_with_zero_gradient():
  items = _items(0)
  sh = S.Shapes.create(items, **SLOTS).remove_polygon(1).remove_circle(0)
  sh = dataclasses.replace(sh, num_vertices=sh.num_vertices.at[2].set(2))
  sd = np.asarray(soft.signed_distance(sh, np.float32([[1.0, 1.0]] * N)))
  # Slots: polygons 0..3 (1 removed, 2 malformed, 3 never used), circles 4..7 (4 removed, 5 live).
  assert np.isinf(sd[:, [1, 2, 3, 4, 6, 7]]).all() and np.isfinite(sd[:, [0, 5]]).all()
  g = jax.grad(lambda v: soft.soft_keepout_cost(dataclasses.replace(sh, vertices=v),
                                                np.float32([[1.0, 1.0]] * N), width=0.3).sum())(sh.vertices)
  assert np.isfinite(np.asarray(g)).all() and (np.asarray(g)[1:] == 0).all()


def _central(f, x, eps):
  x = np.float64(x)
  g = np.zeros_like(x)
  for i in np.ndindex(x.shape):
    up, dn = x.copy(), x.copy()
    up[i] += eps
    dn[i] -= eps
    g[i] = (f(np.float32(up)) - f(np.float32(dn))) / (2 * eps)
  return g


def _smooth_points(items, rng, n, eps):
  """Points away from the kinks of the distance (medial axes, boundaries), so FD is meaningful."""
  out = []
  while len(out) < n:
    p = rng.uniform(0, 6, 2)
    ds = []
    for it in items:
      if isinstance(it, S.Circle):
        ds.append(abs(_ref_sd(p, it)))
        if np.hypot(*(p - np.float32(it.center))) < 50 * eps:
          ds.append(0.0)
      else:
        # A kink: two different closest points (not two edges meeting at one vertex) at
        # nearly the same distance.
        pts = np.float64(np.float32(it.points))
        near = [_closest(p, pts[i], pts[(i + 1) % len(pts)]) for i in range(len(pts))]
        dist = [float(np.hypot(*(p - q))) for q in near]
        k = int(np.argmin(dist))
        others = [d for q, d in zip(near, dist) if np.hypot(*(q - near[k])) > 1e-9]
        if others and min(others) - dist[k] < 50 * eps:
          ds.append(0.0)
        ds.append(dist[k])
    if min(ds) > 50 * eps:
      out.append(p)
  return np.float32(out)


def test_gradients_match_central_differences():
  eps = 1e-3
  items = _items(4)
  sh = S.Shapes.create(items, **SLOTS)
  rng = np.random.default_rng(9)
  pts = _smooth_points(items, rng, N, eps)

  # d(sum of signed distances)/d(points, vertices, centres, radii).
  def total(points, verts, cen, rad):
    s = dataclasses.replace(sh, vertices=verts, center=cen, radius=rad)
    sd = soft.signed_distance(s, points)
    return jnp.sum(jnp.where(jnp.isfinite(sd), sd, 0.0))

  args = [jnp.asarray(pts), sh.vertices, sh.center, sh.radius]
  grads = jax.grad(total, argnums=(0, 1, 2, 3))(*args)
  for k in range(4):
    f = lambda x, k=k: float(total(*[jnp.asarray(x) if i == k else a for i, a in enumerate(args)]))
    num = _central(f, np.asarray(args[k]), eps)
    np.testing.assert_allclose(np.asarray(grads[k]), num, atol=3e-2, rtol=2e-2)

  # Soft keepout cost (with a margin) and soft speed limit (w.r.t. the zone limits).
  info = FilterInfo.create(constants.SPEED_FILTER_ABSOLUTE, 0.0, 0.01)
  cost = lambda p: soft.soft_keepout_cost(sh, p, width=0.2, margin=0.1).sum() / 254.0
  g = jax.grad(cost)(jnp.asarray(pts))
  np.testing.assert_allclose(np.asarray(g), _central(lambda x: float(cost(jnp.asarray(x))), pts, eps),
                             atol=2e-2, rtol=2e-2)
  lim0 = np.float32(soft.zone_speed_limits(sh, info, 1.0))
  speed = lambda lim: soft.soft_speed_limit(sh, info, pts, width=0.2, no_limit=1.0, limits=lim).sum()
  g = jax.grad(speed)(jnp.asarray(lim0))
  np.testing.assert_allclose(np.asarray(g), _central(lambda x: float(speed(jnp.asarray(x))), lim0, eps),
                             atol=2e-2, rtol=2e-2)
  assert np.abs(np.asarray(g)).sum() > 1.0     # the limits matter at these points


@pytest.mark.parametrize("overlay", [S.OVERLAY_SEQ, S.OVERLAY_MAX])
def test_soft_tends_to_the_hard_filters_away_from_edges(overlay):
  """width -> 0: soft cost and limit at cell centres equal keepout_filter / speed_filter there."""
  items = _items(7)
  sh = S.Shapes.create(items, **SLOTS)
  h, w, res = 24, 30, 0.25              # the grid of tests/jaxfilters/test_shapes.py
  grid = OccupancyGrid.create(np.zeros((h, w), np.int8), res, (0.0, 0.0))
  keep = FilterMask.create(grid, FilterInfo.create(constants.KEEPOUT_FILTER))
  info = FilterInfo.create(constants.SPEED_FILTER_PERCENT, 100.0, -1.0)
  speed = FilterMask.create(grid, info)
  km, kv = S.rasterize_mask(sh, keep, overlay_type=overlay)
  sm, sv = S.rasterize_mask(sh, speed, default_value=0)
  assert bool(kv[0]) and bool(sv[0])
  cost, _ = keepout_filter(Costmap.create(np.zeros((1, h, w), np.uint8), (0.0, 0.0), res), km,
                           np.zeros((1, 3), np.float32), KeepoutState.create(1))
  cy, cx = np.mgrid[0:h, 0:w]
  centres = np.float32(np.stack([(cx.ravel() + 0.5) * res, (cy.ravel() + 0.5) * res], 1))
  width = 1e-3
  sd = np.asarray(soft.signed_distance(sh, centres))
  far = np.min(np.abs(sd), axis=1) > 20 * width
  assert far.sum() > 0.9 * len(centres)
  got = np.asarray(soft.soft_keepout_cost(sh, centres, width=width, overlay_type=overlay))
  np.testing.assert_allclose(got[far], np.asarray(cost.cost[0]).ravel()[far].astype(np.float32), atol=1e-3)
  assert len(np.unique(got[far])) >= 3 and (got[far] == 0).any()   # several zone costs compared

  if overlay == S.OVERLAY_SEQ:
    poses = np.concatenate([centres, np.zeros((len(centres), 1), np.float32)], 1)
    _, out = speed_filter(sm, poses, SpeedState.create(len(centres)))
    hard = np.asarray(out.speed_limit)
    hard = np.where(hard == 0.0, 100.0, hard)              # Nav2 0.0 = no limit
    soft_lim = np.asarray(soft.soft_speed_limit(sh, info, centres, width=width, no_limit=100.0))
    assert np.asarray(out.valid).all()
    np.testing.assert_allclose(soft_lim[far], hard[far], atol=1e-3)
    assert len(np.unique(np.round(hard[far]))) >= 3      # several zone limits were compared


def test_soft_errors_and_traced_width():
  sh = S.Shapes.create(_items(1), **SLOTS)
  pts = np.zeros((N, 2), np.float32)
  info = FilterInfo.create(constants.SPEED_FILTER_PERCENT, 100.0, -1.0)
  with pytest.raises(ValueError, match="width must be > 0"):
    soft.soft_keepout_cost(sh, pts, width=0.0)
  with pytest.raises(ValueError, match="OVERLAY_MIN has no smooth counterpart"):
    soft.soft_keepout_cost(sh, pts, width=0.1, overlay_type=S.OVERLAY_MIN)
  with pytest.raises(ValueError, match=r"points must be float \[N, 2\]"):
    soft.signed_distance(sh, np.zeros((N, 3), np.float32))
  with pytest.raises(ValueError, match=r"limits must be float \[P \+ C\] = \(8,\)"):
    soft.soft_speed_limit(sh, info, pts, width=0.1, no_limit=100.0, limits=np.zeros(5, np.float32))
  with pytest.raises(ValueError, match="info.type must be 1"):
    soft.soft_speed_limit(sh, FilterInfo.create(0), pts, width=0.1, no_limit=100.0)
  with pytest.raises(ValueError, match="no_limit must be > 0"):
    soft.soft_speed_limit(sh, info, pts, width=0.1, no_limit=0.0)
  traced = jax.jit(lambda wd: soft.soft_keepout_cost(sh, pts, width=wd))(jnp.float32(-1.0))
  assert np.isnan(np.asarray(traced)).all()
  assert not math.isnan(float(jax.jit(lambda wd: soft.soft_keepout_cost(sh, pts, width=wd))(0.5)[0]))
