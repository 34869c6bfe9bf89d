"""sims/fleet/navigation.py: the distance field against Dijkstra, a navigation function, values and descent directions.
"""

from __future__ import annotations

import heapq
import math

import jax.numpy as jnp
import numpy as np
import pytest

from sims.fleet import navigation


def _dijkstra(weight: np.ndarray, goal: tuple[int, int]) -> np.ndarray:
  """Reference: 8-connected Dijkstra with edge cost = step length x mean weight (float64)."""
  h, w = weight.shape
  dist = np.full((h, w), np.inf)
  dist[goal] = 0.0
  queue = [(0.0, goal)]
  while queue:
    d, (r, c) = heapq.heappop(queue)
    if d > dist[r, c]:
      continue
    for dr in (-1, 0, 1):
      for dc in (-1, 0, 1):
        rr, cc = r + dr, c + dc
        if (dr or dc) and 0 <= rr < h and 0 <= cc < w and np.isfinite(weight[rr, cc]):
          nd = d + math.hypot(dr, dc) * 0.5 * (weight[r, c] + weight[rr, cc])
          if nd < dist[rr, cc]:
            dist[rr, cc] = nd
            heapq.heappush(queue, (nd, (rr, cc)))
  return dist


def test_distance_field_matches_dijkstra():
  rng = np.random.default_rng(3)
  weight = (0.1 * (1.0 + rng.uniform(0, 2, (30, 40)))).astype(np.float32)
  weight[5:25, 12] = np.inf                     # a wall with a gap at the bottom
  weight[25:, 25] = np.inf                      # and one with a gap at the top
  weight[10:12, 30:38] = np.inf
  goals = [(2, 2), (28, 38), (15, 20)]
  out = np.asarray(navigation.distance_field(jnp.asarray(weight), jnp.asarray([g[0] for g in goals], jnp.int32),
                                             jnp.asarray([g[1] for g in goals], jnp.int32)))
  for s, g in enumerate(goals):
    ref = _dijkstra(weight, g)
    assert np.array_equal(np.isfinite(out[s]), np.isfinite(ref))
    np.testing.assert_allclose(out[s][np.isfinite(ref)], ref[np.isfinite(ref)], rtol=1e-5)


def test_distance_field_is_a_navigation_function():
  """Every reachable non-goal cell has a neighbour strictly closer to the goal."""
  weight = np.full((20, 20), 0.1, np.float32)
  weight[3:17, 10] = np.inf
  d = np.asarray(navigation.distance_field(jnp.asarray(weight), jnp.asarray([10], jnp.int32),
                                           jnp.asarray([2], jnp.int32)))[0]
  padded = np.pad(d, 1, constant_values=np.inf)
  best = np.min([padded[1 + dr:21 + dr, 1 + dc:21 + dc] for dr in (-1, 0, 1) for dc in (-1, 0, 1)
                 if dr or dc], axis=0)
  reach = np.isfinite(d)
  reach[10, 2] = False
  assert np.all(best[reach] < d[reach])


def test_nav_value_and_descent_direction():
  weight = jnp.full((20, 20), 0.1, jnp.float32)
  dist = navigation.distance_field(weight, jnp.asarray([10], jnp.int32), jnp.asarray([10], jnp.int32))
  field = navigation.NavField(dist=dist, origin=jnp.zeros(2), resolution=jnp.asarray(0.1, jnp.float32),
                              stations=jnp.asarray([[1.05, 1.05]]))
  goal = jnp.asarray(0)
  assert float(navigation.nav_value(field, goal, jnp.asarray([1.05, 1.05]))) == pytest.approx(0.0, abs=1e-6)
  assert float(navigation.nav_value(field, goal, jnp.asarray([1.55, 1.05]))) == pytest.approx(0.5, rel=1e-5)
  direction = np.asarray(navigation.descent_direction(field, goal, jnp.asarray([1.55, 1.07])))
  assert direction[0] < -0.95 and np.linalg.norm(direction) == pytest.approx(1.0, abs=1e-5)
  far = navigation.nav_value(field, goal, jnp.asarray([50.0, 50.0]))
  assert float(far) == navigation.UNREACHABLE

