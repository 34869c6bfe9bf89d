"""Soft zones at far, infinite and NaN points: outside, NaN in gives NaN out, finite gradients.
"""


import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfilters as jf

SHAPES = jf.Shapes.create([jf.Polygon([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], 100),
                           jf.Circle([5.0, 5.0], 1.0, 60)])


@pytest.mark.parametrize("x", [2e19, 1e30, 3e38, np.inf, -np.inf])
def test_soft_zones_far_and_infinite_points_are_outside(x):
  pts = np.float32([[x, 0.5], [0.5, x]])
  cost = np.asarray(jf.soft_keepout_cost(SHAPES, pts, width=0.1))
  np.testing.assert_array_equal(cost, [0.0, 0.0])
  lim = np.asarray(jf.soft_speed_limit(SHAPES, jf.FilterInfo.create(1, 0.0, 0.5), pts, width=0.1, no_limit=100.0))
  np.testing.assert_array_equal(lim, [100.0, 100.0])
  sd = np.asarray(jf.signed_distance(SHAPES, pts))
  assert (sd > 0).all()
  if np.isfinite(x) and abs(x) < 1e38:
    np.testing.assert_allclose(sd, abs(x), rtol=1e-6)
  elif not np.isfinite(x):
    assert np.isinf(sd).all()


def test_soft_zones_nan_points_give_nan():
  pts = np.float32([[np.nan, 0.5], [0.5, 0.5]])
  cost = np.asarray(jf.soft_keepout_cost(SHAPES, pts, width=0.1))
  assert np.isnan(cost[0]) and cost[1] > 250
  lim = np.asarray(jf.soft_speed_limit(SHAPES, jf.FilterInfo.create(1, 0.0, 0.5), pts, width=0.1, no_limit=100.0))
  assert np.isnan(lim[0]) and np.isfinite(lim[1])
  assert np.isnan(np.asarray(jf.signed_distance(SHAPES, pts))[0]).all()


def test_soft_zones_far_point_gradients_are_finite():
  g = jax.grad(lambda p: jf.soft_keepout_cost(SHAPES, p[None], width=0.1)[0])(jnp.float32([2e19, 0.5]))
  assert np.isfinite(np.asarray(g)).all()

