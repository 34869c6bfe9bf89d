"""AsymmetricInflationLayer (jaxfilters.asymmetric_inflation) against Nav2's tests and a float64 reference.

The scenarios of Nav2's `test/integration/asymmetric_inflation_tests.cpp` and
`test/unit/asymmetric_inflation_layer_test.cpp` (main at a3a97043) are transcribed with
their fixture (40 x 40 cells of 0.1 m at the origin, inflation radius 0.55 m, inscribed
radius 0, the robot at (0, 0), the path y = 2.0 through x = 0.5 .. 3.5) and checked
two ways: Nav2's own expectations, and bit-equality with reference/asymmetric_inflation.py
(transcribed from the C++ loop by loop). Random maps then put ties on purpose: paths
through cell centres, obstacles exactly one radius from the path, robots exactly at the
goal threshold; every fleet runs batched under `jit` with a different path per robot.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfilters as jf
from jaxfilters.types import Costmap
from reference import asymmetric_inflation as ref
from tests.compile_count import count_compiles

RES = 0.1
N = 40
STRAIGHT = [(0.5, 2.0), (1.5, 2.0), (2.5, 2.0), (3.5, 2.0)]
P = 8


def _fixture_config(left=10.0, right=10.0, threshold=1.5):
  return jf.AsymmetricInflationConfig(inflation_radius=0.55, cost_scaling_factor_left=left,
                                      cost_scaling_factor_right=right, goal_distance_threshold=threshold,
                                      inscribed_radius=0.0, resolution=RES)


def _run(costs, paths, config, *, robots=None, origin=(0.0, 0.0), npts=P):
  """The fleet of `costs` [B, H, W] with `paths` (lists of points), batched; and the reference's, robot by robot."""
  costs = np.asarray(costs, np.uint8)
  b = costs.shape[0]
  pts = np.zeros((b, npts, 2), np.float32)
  n = np.zeros(b, np.int32)
  for k, p in enumerate(paths):
    if len(p):
      pts[k, :len(p)] = p
    n[k] = len(p)
  xy = np.zeros((b, 2), np.float32) if robots is None else np.asarray(robots, np.float32)
  cm = Costmap.create(costs, np.broadcast_to(np.asarray(origin, np.float64), (b, 2)), config.resolution)
  got = np.asarray(jf.asymmetric_inflate(cm, paths=pts, path_lengths=n, robot_xy=xy, config=config).cost)
  for k in range(b):
    want = ref.asymmetric_inflate(
        costs[k], pts[k, :n[k]], xy[k], origin=origin, resolution=config.resolution,
        inflation_radius=config.inflation_radius, cost_scaling_factor_left=config.cost_scaling_factor_left,
        cost_scaling_factor_right=config.cost_scaling_factor_right,
        goal_distance_threshold=config.goal_distance_threshold, inscribed_radius=config.inscribed_radius,
        inflate_unknown=config.inflate_unknown, inflate_around_unknown=config.inflate_around_unknown,
        enabled=config.enabled)
    np.testing.assert_array_equal(got[k], want, err_msg=f"robot {k}")
  return got


def _lethal(*cells):
  c = np.zeros((N, N), np.uint8)
  for mx, my in cells:
    c[my, mx] = 254
  return c


def test_nav2_symmetric_fallbacks():
  """no_path_produces_symmetric_output, equal_sides_produce_symmetric_output (factors 10, 10)."""
  out = _run([_lethal((20, 20)), _lethal((20, 20), (20, 30))], [[], STRAIGHT], _fixture_config())
  assert out[0][20, 15] == out[0][20, 25] > 0
  for dy in range(-5, 6):
    assert out[1][20 + dy, 15] == out[1][20 + dy, 25]


def test_nav2_left_disfavoured_scenarios():
  """Factors (1, 10): unequal_sides_raise_costs_from_standalone_layer, short_path_falls_back_to_symmetric,
  map_edge_obstacle_is_inflated, max_cost_not_overwritten_by_inflation, and the seedDistanceMap cases
  (interior obstacles skipped, an obstacle far from the path untouched)."""
  preset = _lethal((20, 24))
  preset[28, 20] = 200
  block = _lethal(*[(20 + dx, 20 + dy) for dx in (-1, 0, 1) for dy in (-1, 0, 1)])
  costs = [_lethal((20, 24), (20, 16)), _lethal((20, 20)), _lethal((0, 20)), preset, block, _lethal((0, 0))]
  paths = [STRAIGHT, [(2.0, 2.0)], STRAIGHT, STRAIGHT, STRAIGHT, STRAIGHT]
  out = _run(costs, paths, _fixture_config(1.0, 10.0))
  assert out[0][28, 20] > out[0][12, 20]
  assert out[1][20, 15] == out[1][20, 25] > 0
  assert out[2][20, 4] > 100
  assert out[3][28, 20] == 200
  assert out[5][0, 0] == 254
  # Pass 2 raised the disfavoured (north) side above the symmetric pass and left the cells farther
  # than the radius (6 cells) from the north obstacle alone.
  sym = ref.symmetric_pass(costs[0], r_cells=6, lut=ref.cost_lut(6, RES, 0.0, 10.0), inflate_unknown=False,
                           inflate_around_unknown=False)
  assert (out[0][25:, :] >= sym[25:, :]).all() and (out[0][25:, :] > sym[25:, :]).any()
  np.testing.assert_array_equal(out[0][:18], sym[:18])


def test_nav2_right_disfavoured_and_near_goal():
  """right_side_disfavored_raises_right_costs (10, 1); near_goal_disables_asymmetry (1, 10, threshold 5)."""
  out = _run([_lethal((20, 16), (20, 24))], [STRAIGHT], _fixture_config(10.0, 1.0))
  assert out[0][12, 20] > out[0][28, 20]
  out = _run([_lethal((20, 24), (20, 16))], [STRAIGHT], _fixture_config(1.0, 10.0, threshold=5.0))
  assert out[0][28, 20] == out[0][12, 20]


def test_nav2_cost_at_known_distance():
  """cost_at_known_distance_matches_formula: factors (3, 10), 5 cells from a disfavoured obstacle:
  floor(252 exp(-1.5)) = 56 (Nav2 allows +-2 for the LUT; the LUT gives it exactly)."""
  out = _run([_lethal((20, 24))], [STRAIGHT], _fixture_config(3.0, 10.0))
  assert out[0][29, 20] == 56


@pytest.mark.parametrize("case", [
    # (path, point, radius, want): ObstacleSideTest, resolution 0.1, radius 1.0 unless given.
    (STRAIGHT, (2.05, 2.55), 1.0, 1), (STRAIGHT, (2.05, 1.55), 1.0, -1), (STRAIGHT, (2.05, 3.55), 1.0, 0),
    ([(0.5, 2.0), (1.0, 2.0), (1.5, 2.0), (2.0, 2.0), (2.0, 1.5), (2.0, 1.0), (2.0, 0.5)], (2.35, 1.75), 1.0, 1),
    ([(2.0, 2.0), (2.0, 2.0)], (2.0, 2.0), 1.0, 0),
    ([(3.0, 3.0), (3.5, 3.0)], (1.5, 2.0), 0.3, 0),
    ([(0.0, 0.0), (2.0, 0.0)], (3.0, 1.0), 1.0, 0),
    ([(0.5, 2.0), (3.5, 2.0)], (1.5, 2.0), 1.0, 0),
], ids=["north_left", "south_right", "beyond_radius", "corner_nearest_leg", "zero_length", "aabb_rejected",
        "aabb_corner", "on_segment"])
def test_reference_obstacle_side_matches_nav2_unit_tests(case):
  path, (x, y), r, want = case
  segs = [(path[i - 1], path[i]) for i in range(1, len(path))]
  assert ref.obstacle_side(x, y, list(range(len(segs))), segs, r) == want


def test_reference_side_rules_nav2_unit_tests_gaps_and_nearest():
  """does_not_bridge_filtered_path_gaps and closest_segment_wins."""
  gaps = [((0.5, 2.0), (1.0, 2.0)), ((3.0, 2.0), (3.5, 2.0))]
  assert ref.obstacle_side(2.05, 2.55, [0, 1], gaps, 1.0) == 0
  two = [((0.5, 1.8), (3.5, 1.8)), ((0.5, 3.5), (3.5, 3.5))]
  assert ref.obstacle_side(2.0, 2.0, [0, 1], two, 2.0) == 1


def test_obstacle_side_scenarios_through_the_layer():
  """The ObstacleSideTest geometries as obstacles in a map (radius 1.0, factors (2, 8), inscribed 0.3):
  each robot's layer output equals the reference's, so the device classifies them as Nav2 does."""
  cfg = jf.AsymmetricInflationConfig(inflation_radius=1.0, cost_scaling_factor_left=2.0,
                                     cost_scaling_factor_right=8.0, goal_distance_threshold=1.5,
                                     inscribed_radius=0.3, resolution=RES)
  l_path = [(0.5, 2.0), (1.0, 2.0), (1.5, 2.0), (2.0, 2.0), (2.0, 1.5), (2.0, 1.0), (2.0, 0.5)]
  costs = [_lethal((20, 25), (20, 15), (20, 35)), _lethal((23, 17)), _lethal((20, 25)), _lethal((20, 25))]
  paths = [STRAIGHT, l_path, [(0.5, 2.0), (1.0, 2.0), (3.0, 2.0), (3.5, 2.0)], [(2.0, 2.0), (2.0, 2.0), (3.9, 3.9)]]
  robots = [(0.0, 0.0), (3.9, 0.0), (0.0, 0.0), (0.0, 0.0)]
  _run(costs, paths, cfg, robots=robots)


def test_config_defaults_and_nav2_validation():
  cfg = jf.AsymmetricInflationConfig(inscribed_radius=0.2, resolution=0.05)
  assert (cfg.inflation_radius, cfg.cost_scaling_factor_left, cfg.cost_scaling_factor_right,
          cfg.goal_distance_threshold, cfg.inflate_unknown, cfg.inflate_around_unknown, cfg.enabled) == (
              2.0, 4.0, 4.0, 1.5, False, False, True)
  assert hash(cfg) == hash(dataclasses.replace(cfg))
  with pytest.raises(TypeError):
    jf.AsymmetricInflationConfig(0.5, inscribed_radius=0.2, resolution=0.05)   # keyword-only
  for name in ("inflation_radius", "cost_scaling_factor_left", "cost_scaling_factor_right",
               "goal_distance_threshold"):
    with pytest.raises(ValueError, match=f"{name} must be >= 0"):
      jf.AsymmetricInflationConfig(**{name: -0.1}, inscribed_radius=0.2, resolution=0.05)
  for bad in (dict(resolution=0.0), dict(inflation_radius=float("nan")), dict(enabled=1)):
    with pytest.raises(ValueError, match="AsymmetricInflationConfig"):
      jf.AsymmetricInflationConfig(**{"inscribed_radius": 0.2, "resolution": 0.05, **bad})


def test_bad_inputs_raise():
  cfg = _fixture_config(1.0, 10.0)
  cm = Costmap.create(np.zeros((2, N, N), np.uint8), (0.0, 0.0), RES)
  good = dict(paths=np.zeros((2, P, 2), np.float32), path_lengths=np.zeros(2, np.int32),
              robot_xy=np.zeros((2, 2), np.float32))
  for key, value, match in (("paths", np.zeros((3, P, 2), np.float32), "paths must be float32"),
                            ("paths", np.zeros((2, P, 2), np.float64), "paths must be float32"),
                            ("path_lengths", np.full(2, P + 1, np.int32), r"in \[0, P\]"),
                            ("robot_xy", np.full((2, 2), np.nan, np.float32), "robot_xy must be finite")):
    with pytest.raises(ValueError, match=match):
      jf.asymmetric_inflate(cm, **{**good, key: value}, config=cfg)
  nan_path = np.zeros((2, P, 2), np.float32)
  nan_path[0, 1] = np.nan
  with pytest.raises(ValueError, match="finite"):
    jf.asymmetric_inflate(cm, **{**good, "paths": nan_path, "path_lengths": np.full(2, 2, np.int32)}, config=cfg)
  with pytest.raises(ValueError, match="resolution"):
    jf.asymmetric_inflate(cm, **good, config=dataclasses.replace(cfg, resolution=0.05))
  with pytest.raises(TypeError):
    jf.asymmetric_inflate(cm, **good, config=jf.InflationConfig(inscribed_radius=0.0, resolution=RES))


def _tie_fleet(seed, thr, res=0.125, h=24, w=28, b=4):
  """Maps on a dyadic grid so that cell centres, radii and thresholds are exact: ties happen."""
  rng = np.random.default_rng(seed)
  costs = np.zeros((b, h, w), np.uint8)
  costs[rng.random((b, h, w)) < 0.06] = 254
  costs[rng.random((b, h, w)) < 0.03] = 255
  costs[rng.random((b, h, w)) < 0.05] = 253
  other = (rng.random((b, h, w)) < 0.1) & (costs == 0)
  costs[other] = rng.integers(1, 253, int(other.sum()))
  paths, robots = [], []
  for k in range(b):
    n = int(rng.integers(2, P + 1))
    # Points at cell centres (i + 0.5) * res, some off the map, some repeated (zero-length segments).
    ij = rng.integers(-3, max(h, w) + 3, (n, 2))
    pts = (ij + 0.5) * res
    if k % 2:
      pts[1] = pts[0]
    paths.append([tuple(p) for p in pts])
    # The robot exactly at the goal threshold `thr` (1.0: (0, -1); 1.25: (0.75, 1), 3-4-5), one
    # float32 step beyond it, inside it, or far.
    exact = (0.0, -1.0) if thr == 1.0 else (0.75, 1.0)
    beyond = (0.0, -float(np.nextafter(np.float32(thr), np.float32(2))))
    robots.append(pts[-1] + [exact, beyond, (0.0, 0.5), (3.0, 4.0)][k % 4])
  return costs, paths, robots


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("flags", [(False, False), (True, True)], ids=["plain", "unknown"])
def test_random_maps_with_ties_equal_the_reference(seed, flags):
  """Radius 0.5 m = 4 cells of 0.125: obstacles exactly one radius from a segment count (dist^2 == r^2);
  goal threshold 1.0 or 1.25 against robots at exactly that distance; paths through cell centres."""
  inflate_unknown, around = flags
  cfg = jf.AsymmetricInflationConfig(inflation_radius=0.5, cost_scaling_factor_left=3.0 + seed,
                                     cost_scaling_factor_right=1.5, goal_distance_threshold=1.0 + 0.25 * (seed % 2),
                                     inscribed_radius=0.125, resolution=0.125, inflate_unknown=inflate_unknown,
                                     inflate_around_unknown=around)
  costs, paths, robots = _tie_fleet(seed, cfg.goal_distance_threshold)
  _run(costs, paths, cfg, robots=robots, origin=(-0.5, -0.25))


def test_dense_paths_take_windows_and_equal_the_reference():
  """Paths as Nav2's planners give them, a pose about a cell apart, on maps larger than the window
  (2R + 1 + WINDOW_SLACK cells): the short segments update a window each, the few long jumps the
  whole map, and ties between a short and a long segment (equal dist^2) go to the lower index."""
  from jaxfilters.asymmetric_inflation import WINDOW_SLACK
  cfg = jf.AsymmetricInflationConfig(inflation_radius=0.5, cost_scaling_factor_left=1.5, cost_scaling_factor_right=6.0,
                                     goal_distance_threshold=0.25, inscribed_radius=0.125, resolution=0.125)
  h, w, b, p = 36, 44, 4, 40
  assert 2 * cfg.cell_radius + 1 + WINDOW_SLACK < min(h, w)
  rng = np.random.default_rng(11)
  costs = np.zeros((b, h, w), np.uint8)
  costs[rng.random((b, h, w)) < 0.08] = 254
  costs[rng.random((b, h, w)) < 0.02] = 255
  paths = []
  for k in range(b):
    ij = np.empty((p, 2), np.int64)
    ij[0] = rng.integers(0, (w, h))
    for i in range(1, p):
      ij[i] = ij[i - 1] + rng.integers(-1, 3, 2)
    if k % 2:   # a long jump (the whole-map pass), then the walk doubles back over itself (ties)
      ij[p // 2:] = ij[p // 2:] + (-12, 9)
      ij[3 * p // 4:] = ij[p // 4:p // 2][::-1][:p - 3 * p // 4]
    if k == 3:  # off the map at the start
      ij[:4] -= (6, 6)
    paths.append([tuple(q) for q in (ij + 0.5) * 0.125])
  got = _run(costs, paths, cfg, robots=[(-5.0, -5.0)] * b, origin=(0.0, 0.0), npts=p)
  plain = np.asarray(jf.inflate(costs, config=cfg.symmetric))
  assert np.any(got != plain)   # the second pass raised cells


def test_random_maps_decimal_resolution():
  """A decimal resolution (0.05, carried as float64) and origin, left disfavoured, default radius."""
  rng = np.random.default_rng(7)
  cfg = jf.AsymmetricInflationConfig(inflation_radius=0.6, cost_scaling_factor_left=2.0, cost_scaling_factor_right=9.0,
                                     goal_distance_threshold=0.3, inscribed_radius=0.15, resolution=0.05)
  costs = np.where(rng.random((3, 30, 36)) < 0.05, 254, 0).astype(np.uint8)
  origin = (0.3, -1.1)
  paths = [[tuple(p) for p in origin + rng.uniform(-0.5, 2.0, (int(rng.integers(2, P + 1)), 2))] for _ in range(3)]
  _run(costs, paths, cfg, robots=[(0.3, -1.1)] * 3, origin=origin)


def test_one_compile_for_any_paths_under_jit():
  cfg = _fixture_config(1.0, 10.0)
  cm = Costmap.create(np.stack([_lethal((20, 24), (20, 16))] * 3), (0.0, 0.0), RES)
  step = jax.jit(lambda c, p, n, xy: jf.asymmetric_inflate(c, paths=p, path_lengths=n, robot_xy=xy, config=cfg).cost)
  rng = np.random.default_rng(3)

  def call():
    p = rng.uniform(0.0, 4.0, (3, P, 2)).astype(np.float32)
    return step(cm, jnp.asarray(p), jnp.asarray(rng.integers(0, P + 1, 3), jnp.int32),
                jnp.asarray(rng.uniform(0, 4, (3, 2)), jnp.float32))

  call()
  with count_compiles() as compiles:
    outs = [np.asarray(call()) for _ in range(3)]
  assert compiles() == 0
  assert any(not np.array_equal(outs[0], o) for o in outs[1:])   # the paths changed the result


def test_obstacles_exactly_one_radius_from_the_path_are_seeds():
  """A wall exactly r = 0.5 m (4 cells of 0.125) left of a horizontal and of a vertical path through
  cell centres: dist^2 == r^2 is not beyond the radius and the centre on the padded box's edge is inside
  it (Nav2: `min_dist_sq > r^2` is neutral, the box test is `cx < min_x || cx > max_x`), so the wall
  seeds pass 2."""
  res, r = 0.125, 0.5
  cfg = jf.AsymmetricInflationConfig(inflation_radius=r, cost_scaling_factor_left=1.0, cost_scaling_factor_right=6.0,
                                     goal_distance_threshold=0.0, inscribed_radius=0.0, resolution=res)
  c = lambda i: (i + 0.5) * res
  costs = np.zeros((2, 24, 24), np.uint8)
  costs[0, 14, 8:13] = 254                     # 4 rows above the path's row 10
  costs[1, 8:13, 6] = 254                      # 4 columns left (west) of the northbound path's column 10
  paths = [[(c(4), c(10)), (c(18), c(10))], [(c(10), c(3)), (c(10), c(20))]]
  out = _run(costs, paths, cfg, robots=[(0.0, 0.0)] * 2)
  for k in range(2):
    sym = ref.symmetric_pass(costs[k], r_cells=4, lut=ref.cost_lut(4, res, 0.0, 6.0), inflate_unknown=False,
                             inflate_around_unknown=False)
    assert (out[k] > sym).any(), f"robot {k}: the wall one radius away did not seed pass 2"


def test_pass_one_is_nav2_inflation_layer_on_inflation_tests_cpp():
  """inflation_tests.cpp testInflation3 (docs/nav2_semantics.md §9.5): 10 x 10 cells of 1 m, inscribed
  radius 1.0, scaling 1.0, radius 3, one obstacle at (5, 5). With equal factors the asymmetric layer is
  that InflationLayer whatever the path; with unequal ones and the obstacle beyond every segment's
  reach, pass 1 alone runs with max(left, right)."""
  want = np.array([[0, 0, 0, 34, 0, 0, 0],
                   [0, 40, 72, 92, 72, 40, 0],
                   [0, 72, 167, 253, 167, 72, 0],
                   [34, 92, 253, 254, 253, 92, 34],
                   [0, 72, 167, 253, 167, 72, 0],
                   [0, 40, 72, 92, 72, 40, 0],
                   [0, 0, 0, 34, 0, 0, 0]], np.uint8)[::-1]        # row 0 = lowest y
  cost = np.zeros((10, 10), np.uint8)
  cost[5, 5] = 254
  far = [(0.5, 9.5), (1.5, 9.5)]                                  # > 3 m from (5.5, 5.5)
  for left, right, path in ((1.0, 1.0, [(0.5, 5.5), (9.5, 5.5)]), (1.0, 0.5, far)):
    cfg = jf.AsymmetricInflationConfig(inflation_radius=3.0, cost_scaling_factor_left=left,
                                       cost_scaling_factor_right=right, goal_distance_threshold=0.0,
                                       inscribed_radius=1.0, resolution=1.0)
    out = _run(cost[None], [path], cfg, robots=[(0.0, 0.0)])[0]
    np.testing.assert_array_equal(out[2:9, 2:9], want)
    assert np.count_nonzero(out) == 29
