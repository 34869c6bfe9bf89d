"""The speed-zone tuning example: gradient vs central differences, tuning, and the hard re-run."""

import math

import jax.numpy as jnp
import numpy as np
import pytest

from sims.tuning import corner_speed as T

SCENARIO = T.CornerScenario()


@pytest.mark.parametrize("limit", [0.5, 0.95])
def test_gradient_through_the_rollout_matches_central_differences(limit):
  """0.5 m/s: progress dominates; 0.95 m/s: the soft keepout penalty dominates."""
  (_, (progress, exposure)), grad = T.objective_and_grad(SCENARIO, jnp.float32(limit))
  fd = T.finite_difference(SCENARIO, limit, eps=3e-3)
  assert float(grad) == pytest.approx(fd, rel=0.02)
  assert (float(exposure) < 1e-3) if limit == 0.5 else (float(exposure) > 0.05)


def test_tuning_raises_progress_and_the_hard_rerun_keeps_the_margin():
  hist = T.tune(SCENARIO, init=0.3, iterations=20)
  k = len(hist.limit)
  assert all(len(getattr(hist, f)) == k for f in ("objective", "gradient", "progress", "exposure"))
  assert hist.limit[0] == 0.3 and hist.objective.max() > hist.objective[0] + 2.0
  best = hist.best_limit
  assert 0.6 < best < 1.0
  start, tuned, fast = (T.hard_check(SCENARIO, v) for v in (0.3, best, 1.5))
  # The tuned zone, carried by a Nav2 speed mask (rounded down) and the hard filters.
  assert tuned.mask_value == math.floor(best / T.SPEED_MULTIPLIER + 1e-9)
  assert tuned.hard_limit <= best
  assert tuned.margin_held and tuned.cells_entered == 0 and tuned.clearance > 0
  assert tuned.keepout_cells > 1000
  assert tuned.progress > start.progress + 2.0          # more goals per hour
  # The check can fail: at the robots' top speed they swing into the keepout.
  assert not fast.margin_held and fast.cells_entered > 0
  # Soft and hard rollouts agree on the progress at the tuned limit (within the quantisation).
  assert tuned.progress == pytest.approx(hist.progress[int(np.argmax(hist.objective))], abs=0.2)


def test_footprint_clearance_hand_worked():
  cells = np.array([[0.0, 0.0]])                # the square [-0.5, 0.5]^2
  traj = np.array([[2.0, 0.0], [1.0, 1.0], [0.2, 0.0]])
  got = T.footprint_clearance(traj, cells, 1.0, 0.5)
  np.testing.assert_allclose(got, [1.0, math.sqrt(0.5) - 0.5, -0.3 - 0.5])


def test_rounded_route_pieces():
  path = SCENARIO.path
  assert [k for k, _ in path] == ["line", "arc", "line"]
  r = SCENARIO.corner_radius
  assert SCENARIO.route_length == pytest.approx(7 - r + math.pi / 2 * r + 8 - r)
  s = np.linspace(0.0, SCENARIO.route_length, 57)
  pts = np.asarray([T.route_point(path, jnp.float32(u)) for u in s])
  back = np.asarray([T.route_progress(path, jnp.asarray(p)) for p in pts])
  np.testing.assert_allclose(back, s, atol=1e-4)
  assert np.all(np.linalg.norm(np.diff(pts, axis=0), axis=1) < s[1] - s[0] + 1e-4)   # no jumps


def test_invalid_settings_raise_with_expected_vs_got():
  with pytest.raises(ValueError, match="dt must be finite and > 0"):
    T.CornerScenario(dt=0.0)
  with pytest.raises(ValueError, match="corner_radius 5.0 m needs 5 m of each segment"):
    T.CornerScenario(corner_radius=5.0)
  with pytest.raises(ValueError, match=r"starts must be finite \(x, y, yaw\) rows"):
    T.CornerScenario(starts=((0.0, 0.0),))
  with pytest.raises(ValueError, match=r"mask value 1\.\.100 .* got 2\.5 m/s -> 125"):
    T.speed_mask_value(2.5)
  with pytest.raises(ValueError, match=r"init must lie in \[lo, hi\]"):
    T.tune(SCENARIO, init=3.0)
