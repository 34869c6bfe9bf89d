"""asymmetric_inflate_zones: the AsymmetricInflationLayer scoped to the zones of a mask.

Inside the zones every cell equals the global layer's (`asymmetric_inflate`), outside the
plain `inflate` with `config.symmetric`, cell for cell. Which costmap cells are inside is
computed here independently, with exact rational arithmetic on the host doubles (the cell
centre `origin + (i + 0.5) * resolution`, floored onto the mask's grid), on a mask whose
resolution and origin differ from the costmap's so that some centres lie within rounding of
mask cell edges (0.05 + 0.1 * 2 = 0.25). Every test runs two robots on 40 x 40 maps, so the
layers compile once for the module.
"""

from fractions import Fraction

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfilters as jf
from jaxfilters.types import Costmap, FilterMask
from tests.compile_count import count_compiles

RES = 0.1
N = 40                                  # 40 x 40 cells of 0.1 m at the origin
P = 8
CONFIG = jf.AsymmetricInflationConfig(inflation_radius=0.55, cost_scaling_factor_left=1.0,
                                      cost_scaling_factor_right=10.0, inscribed_radius=0.0, resolution=RES)
STRAIGHT = [(0.5, 2.0), (1.5, 2.0), (2.5, 2.0), (3.5, 2.0)]       # left (north) is disfavoured
MASK_RES, MASK_ORIGIN = 0.25, (-0.5, -0.5)                          # mask edges at -0.5 + 0.25 k


def _costs(b=1):
  c = np.zeros((b, N, N), np.uint8)
  c[:, 24, 5:36:3] = 254                # obstacles 0.4 m north of the path, along it
  c[:, 16, 8:30:4] = 254                # and south of it
  return c


def _zones(rows_cols, value=100, shape=(18, 18)):
  data = np.zeros(shape, np.int8)
  for r, c in rows_cols:
    data[r, c] = value
  return data


def _mask(*datas):
  grids = [jf.OccupancyGrid.create(d, MASK_RES, MASK_ORIGIN) for d in datas]
  info = jf.FilterInfo.create(0)
  masks = [FilterMask.create(g, info) for g in grids]
  if len(masks) == 1:
    return masks[0]
  return jax.tree.map(lambda *xs: None if xs[0] is None else jnp.concatenate(xs), *masks,
                      is_leaf=lambda x: x is None)


def _inside(data):
  """bool [N, N]: the costmap cells whose centre's mask cell is non-zero (exact rationals)."""
  res, mres = Fraction(RES), Fraction(float(np.float32(MASK_RES)))
  ox, oy = (Fraction(float(np.float32(v))) for v in MASK_ORIGIN)
  hm, wm = data.shape

  def cell(k, o):
    return int(((Fraction(k) + Fraction(1, 2)) * res - o) // mres)

  out = np.zeros((N, N), bool)
  for j in range(N):
    for i in range(N):
      mx, my = cell(i, ox), cell(j, oy)
      out[j, i] = 0 <= mx < wm and 0 <= my < hm and data[my, mx] != 0
  return out


def _paths(*ps):
  pts = np.zeros((len(ps), P, 2), np.float32)
  n = np.zeros(len(ps), np.int32)
  for k, p in enumerate(ps):
    pts[k, :len(p)] = p
    n[k] = len(p)
  return pts, n


def _layers(costs, pts, n, xy):
  cm = Costmap.create(costs, np.zeros((costs.shape[0], 2)), RES)
  glob = np.asarray(jf.asymmetric_inflate(cm, paths=pts, path_lengths=n, robot_xy=xy, config=CONFIG).cost)
  plain = np.asarray(jf.inflate(cm, config=CONFIG.symmetric).cost)
  return cm, glob, plain


# A zone band x in [1.0, 2.5) (mask columns 6..11) over the whole map: its two edges cross the path.
BAND = _zones([(r, c) for r in range(18) for c in range(6, 12)])


@pytest.fixture(scope="module")
def fleet():
  """Two robots on the same map: the straight path, and the same path reversed (right disfavoured)."""
  pts, n = _paths(STRAIGHT, [(3.5, 2.0), (0.5, 2.0)])
  xy = np.zeros((2, 2), np.float32)
  return (pts, n, xy, *_layers(_costs(2), pts, n, xy))


def test_inside_is_the_global_layer_and_outside_the_plain_inflation_cell_for_cell(fleet):
  pts, n, xy, cm, glob, plain = fleet
  out, error = jf.asymmetric_inflate_zones(cm, _mask(BAND), paths=pts, path_lengths=n, robot_xy=xy, config=CONFIG)
  out = np.asarray(out.cost)
  inside = _inside(BAND)
  assert not np.any(np.asarray(error))
  for k in range(2):
    np.testing.assert_array_equal(out[k][inside], glob[k][inside])
    np.testing.assert_array_equal(out[k][~inside], plain[k][~inside])
    # Both sides of the scoping matter: the asymmetric pass raised cells in the band and out of it.
    assert np.any(glob[k][inside] != plain[k][inside]) and np.any(glob[k][~inside] != plain[k][~inside])


def test_a_zone_edge_crossing_the_path(fleet):
  """Along the row between the path and its north obstacles, the cost steps at the band's edge x = 1.0."""
  pts, n, xy, cm, glob, plain = fleet
  out, _ = jf.asymmetric_inflate_zones(cm, _mask(BAND), paths=pts, path_lengths=n, robot_xy=xy, config=CONFIG)
  row = np.asarray(out.cost)[0, 22]            # y = 2.25: between the path and the north obstacles
  # Column 9 (centre 0.95) is west of the edge, column 10 (centre 1.05) east of it.
  assert not _inside(BAND)[22, 9] and _inside(BAND)[22, 10]
  assert row[9] == plain[0, 22, 9] < glob[0, 22, 9]
  assert row[10] == glob[0, 22, 10] > plain[0, 22, 10]


@pytest.mark.parametrize("fill, expect", [(0, "plain"), (100, "global"), (-1, "global"), (37, "global")])
def test_empty_and_full_zone_masks(fleet, fill, expect):
  pts, n, xy, cm, glob, plain = fleet
  # The mask covers the whole costmap (x, y in [-0.5, 4.0) > [0, 4)).
  data = np.full((18, 18), fill, np.int8)
  out, _ = jf.asymmetric_inflate_zones(cm, _mask(data), paths=pts, path_lengths=n, robot_xy=xy, config=CONFIG)
  np.testing.assert_array_equal(np.asarray(out.cost), plain if expect == "plain" else glob)


def test_a_mask_that_does_not_cover_the_costmap_is_outside_beyond_its_edge(fleet):
  pts, n, xy, cm, glob, plain = fleet
  data = np.full((10, 10), 100, np.int8)             # x, y in [-0.5, 2.0): the rest of the map is off it
  out, _ = jf.asymmetric_inflate_zones(cm, _mask(data), paths=pts, path_lengths=n, robot_xy=xy, config=CONFIG)
  inside = _inside(data)
  assert inside[:20, :20].all() and not inside[20:].any() and not inside[:, 20:].any()
  for k in range(2):
    np.testing.assert_array_equal(np.asarray(out.cost)[k][inside], glob[k][inside])
    np.testing.assert_array_equal(np.asarray(out.cost)[k][~inside], plain[k][~inside])


def test_fleet_with_a_zone_per_robot_compiles_once_and_flags_a_bad_traced_index():
  costs = _costs(2)
  cm = Costmap.create(costs, np.zeros((2, 2)), RES)
  west = _zones([(r, c) for r in range(18) for c in range(9)])
  zones = _mask(BAND, west)
  step = jax.jit(lambda p, n, xy, z, zi: jf.asymmetric_inflate_zones(cm, z, paths=p, path_lengths=n, robot_xy=xy,
                                                                     config=CONFIG, zone_index=zi))
  rng = np.random.default_rng(5)

  def call(zone_index):
    p = rng.uniform(0.0, 4.0, (2, P, 2)).astype(np.float32)
    n = rng.integers(2, P + 1, 2).astype(np.int32)
    xy = rng.uniform(0.0, 4.0, (2, 2)).astype(np.float32)
    return (p, n, xy), step(p, n, xy, zones, jnp.asarray(zone_index, jnp.int32))

  call([0, 1])
  with count_compiles() as compiles:
    runs = [call(zi) for zi in ([1, 0], [0, 0], [7, 1])]
  assert compiles() == 0
  for zi, ((p, n, xy), (out, error)) in zip(([1, 0], [0, 0], [7, 1]), runs):
    _, glob, plain = _layers(costs, p, n, xy)
    for k in range(2):
      if zi[k] == 7:                   # outside [0, 2): flagged, and the global layer everywhere
        assert bool(error[k])
        np.testing.assert_array_equal(np.asarray(out.cost[k]), glob[k])
        continue
      assert not bool(error[k])
      inside = _inside(BAND if zi[k] == 0 else west)
      want = np.where(inside, glob[k], plain[k])
      np.testing.assert_array_equal(np.asarray(out.cost[k]), want, err_msg=f"robot {k}, zone {zi[k]}")


def test_bare_cost_array_and_eager_equals_jit():
  costs = _costs(2)
  pts, n = _paths(STRAIGHT, [(0.5, 2.0), (0.5, 3.5)])
  xy = np.zeros((2, 2), np.float32)
  zones = _mask(BAND)
  out, err = jf.asymmetric_inflate_zones(costs, zones, paths=pts, path_lengths=n, robot_xy=xy, config=CONFIG)
  cm = Costmap.create(costs, np.zeros((2, 2)), RES)
  jit_out, jit_err = jax.jit(lambda p: jf.asymmetric_inflate_zones(cm, zones, paths=p, path_lengths=n, robot_xy=xy,
                                                                   config=CONFIG))(pts)
  np.testing.assert_array_equal(np.asarray(out), np.asarray(jit_out.cost))
  np.testing.assert_array_equal(np.asarray(err), np.asarray(jit_err))


def test_bad_zone_inputs_raise():
  costs = _costs(2)
  pts, n = _paths(STRAIGHT, STRAIGHT)
  xy = np.zeros((2, 2), np.float32)
  kw = {"paths": pts, "path_lengths": n, "robot_xy": xy, "config": CONFIG}
  stack = _mask(BAND, BAND)
  with pytest.raises(TypeError, match="zones: mask must be a FilterMask"):
    jf.asymmetric_inflate_zones(costs, BAND, **kw)
  with pytest.raises(ValueError, match="stack of 2 masks needs zone_index"):
    jf.asymmetric_inflate_zones(costs, stack, **kw)
  with pytest.raises(ValueError, match=r"zone_index must lie in \[0, 2\).*robots \[1\] have \[2\]"):
    jf.asymmetric_inflate_zones(costs, stack, zone_index=np.int32([0, 2]), **kw)
  with pytest.raises(ValueError, match="zone_index must be an integer array of shape"):
    jf.asymmetric_inflate_zones(costs, stack, zone_index=np.float32([0, 1]), **kw)
  bad = FilterMask(stack.data.astype(jnp.int16), stack.origin, stack.resolution, stack.info, stack.origin_lo)
  with pytest.raises(ValueError, match="mask.data must be int8"):
    jf.asymmetric_inflate_zones(costs, bad, zone_index=np.int32([0, 1]), **kw)
  with pytest.raises(TypeError, match="config must be an AsymmetricInflationConfig"):
    jf.asymmetric_inflate_zones(costs, _mask(BAND), paths=pts, path_lengths=n, robot_xy=xy,
                                config=CONFIG.symmetric)
