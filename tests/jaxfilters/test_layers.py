"""StaticLayer (docs/nav2_semantics.md §1.5) and InflationLayer (§9.3) against plain float64 NumPy references.

Every kernel runs four ways on one case table: the reference, eager JAX,
`jax.jit`, and `jax.vmap` of the per-robot kernel against a Python loop, with
exact integer equality. The references loop over cells, find the nearest
obstacle by brute force and repeat Nav2's arithmetic (float64 computeCost,
float32 distance and LUT index) without sharing code with the package.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import zlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxfilters.inflation import (InflationConfig, squared_distance, cost_tables, compute_cost,
                                  footprint_radii, inflate, inflate_one)
from jaxfilters.static_layer import StaticLayerConfig, static_layer, static_layer_table
from jaxfilters.types import Costmap


@pytest.fixture(autouse=True)
def _strict_promotion():
  with jax.numpy_rank_promotion("raise"), jax.numpy_dtype_promotion("strict"):
    yield


# ----------------------------------------------------------------------------
# References.


def ref_interpret(v: int, c: StaticLayerConfig) -> int:
  """StaticLayer::interpretValue on one uint8 value, in Nav2's order and double maths."""
  t = max(min(c.lethal_cost_threshold, 100), 0)
  if v == c.unknown_cost_value:
    return 255 if c.track_unknown_space else 0
  if v == c.inscribed_obstacle_cost_value:
    return 253
  if v >= t:
    return 254
  if c.trinary_costmap:
    return 0
  return int(np.trunc(np.float64(v) / np.float64(t) * np.float64(254.0)))


def ref_static(data: np.ndarray, c: StaticLayerConfig) -> np.ndarray:
  raw = data.view(np.uint8)
  out = np.empty(raw.shape, np.uint8)
  for idx in np.ndindex(raw.shape):
    out[idx] = ref_interpret(int(raw[idx]), c)
  return out


def ref_compute_cost(d: float, res: float, inscribed: float, csf: float) -> int:
  if d == 0.0:
    return 254
  if d * res <= inscribed:
    return 253
  return int(np.trunc(252.0 * np.exp(-1.0 * csf * (d * res - inscribed))))


def ref_inflate(cost: np.ndarray, *, inflation_radius: float, cost_scaling_factor: float,
                inscribed_radius: float, resolution: float, inflate_unknown: bool = False,
                inflate_around_unknown: bool = False, enabled: bool = True) -> np.ndarray:
  """Nav2 InflationLayer::updateCosts over the whole map, cell by cell."""
  r = max(0.0, math.ceil(inflation_radius / resolution))
  if not enabled or r == 0:
    return cost.copy()
  lut = [ref_compute_cost(k / 100.0, resolution, inscribed_radius, cost_scaling_factor)
         for k in range(int(r) * 100 + 2)]
  src = (cost == 254) | (inflate_around_unknown & (cost == 255))
  sy, sx = np.nonzero(src)
  out = cost.copy()
  if sy.size == 0:
    return out
  h, w = cost.shape
  for y in range(h):
    for x in range(w):
      sq = int(np.min((sy - y) ** 2 + (sx - x) ** 2))   # brute-force nearest source
      dist = np.sqrt(np.float32(sq))                     # Eigen cwiseSqrt, float32
      if dist > np.float32(r):
        continue
      k = int(np.float32(np.float32(dist * np.float32(100)) + np.float32(0.5)))
      c = lut[min(len(lut) - 1, k)]
      old = int(cost[y, x])
      if old == 255 and (c > 0 if inflate_unknown else c >= 253):
        out[y, x] = c
      else:
        out[y, x] = max(old, c)
  return out


def ref_inflate_cfg(cost: np.ndarray, cfg: InflationConfig) -> np.ndarray:
  return ref_inflate(cost, **dataclasses.asdict(cfg))


def random_costmap(rng: np.random.Generator, shape, *, p_lethal=0.02, p_unknown=0.02,
                   p_inscribed=0.01, p_other=0.3) -> np.ndarray:
  """Never all zeros: obstacles, unknown, 253 written by others and arbitrary costs."""
  u = rng.random(shape)
  cost = np.zeros(shape, np.uint8)
  edges = np.cumsum([p_lethal, p_unknown, p_inscribed, p_other])
  cost[u < edges[0]] = 254
  cost[(u >= edges[0]) & (u < edges[1])] = 255
  cost[(u >= edges[1]) & (u < edges[2])] = 253
  other = (u >= edges[2]) & (u < edges[3])
  cost[other] = rng.integers(1, 253, size=int(other.sum()))
  flat = cost.reshape(-1, *shape[-2:])
  for m in flat:                                   # at least one obstacle per map
    m[rng.integers(m.shape[0]), rng.integers(m.shape[1])] = 254
  return cost


# ----------------------------------------------------------------------------
# Static layer.

STATIC_CONFIGS = [
    StaticLayerConfig(),
    StaticLayerConfig(track_unknown_space=True),
    StaticLayerConfig(trinary_costmap=False),
    StaticLayerConfig(trinary_costmap=False, track_unknown_space=True, lethal_cost_threshold=65),
    StaticLayerConfig(trinary_costmap=False, lethal_cost_threshold=1),
    StaticLayerConfig(trinary_costmap=False, lethal_cost_threshold=0),
    StaticLayerConfig(trinary_costmap=False, lethal_cost_threshold=-7),      # clamped to 0
    StaticLayerConfig(trinary_costmap=False, lethal_cost_threshold=250),     # clamped to 100
    StaticLayerConfig(trinary_costmap=False, inscribed_obstacle_cost_value=120,
                      unknown_cost_value=0, track_unknown_space=True),
    StaticLayerConfig(inscribed_obstacle_cost_value=255, unknown_cost_value=255),
]
ALL_INT8 = np.arange(-128, 128, dtype=np.int8)


@pytest.mark.parametrize("cfg", STATIC_CONFIGS, ids=str)
def test_static_full_table_four_ways(cfg):
  want = ref_static(ALL_INT8, cfg)
  np.testing.assert_array_equal(static_layer_table(cfg)[ALL_INT8.view(np.uint8)], want)
  np.testing.assert_array_equal(np.asarray(static_layer(ALL_INT8, config=cfg)), want)
  jitted = jax.jit(functools.partial(static_layer, config=cfg))
  np.testing.assert_array_equal(np.asarray(jitted(ALL_INT8)), want)
  grid = ALL_INT8.reshape(16, 16)
  batch = np.stack([grid, grid.T, grid[::-1]])
  got = jax.vmap(functools.partial(static_layer, config=cfg))(batch)
  loop = np.stack([np.asarray(static_layer(b, config=cfg)) for b in batch])
  np.testing.assert_array_equal(np.asarray(got), loop)
  np.testing.assert_array_equal(loop, ref_static(batch, cfg))
  # The raw uint8 bytes give the same result.
  np.testing.assert_array_equal(np.asarray(static_layer(ALL_INT8.view(np.uint8), config=cfg)),
                                want)


def test_static_named_values():
  conv = lambda v, **kw: int(static_layer(np.int8(v), config=StaticLayerConfig(**kw)))
  assert [conv(v) for v in (-1, 0, 50, 98, 99, 100, 127, -2, -128)] == \
      [0, 0, 0, 0, 253, 254, 254, 254, 254]
  assert conv(-1, track_unknown_space=True) == 255
  assert conv(50, trinary_costmap=False) == 127
  assert conv(1, trinary_costmap=False) == 2
  assert conv(99, trinary_costmap=False) == 253          # inscribed wins over scaling
  assert conv(0, trinary_costmap=False, lethal_cost_threshold=0) == 254
  assert conv(-1, trinary_costmap=False, lethal_cost_threshold=0) == 0


def test_static_double_equals_integer_formula():
  for t in range(1, 101):
    cfg = StaticLayerConfig(trinary_costmap=False, lethal_cost_threshold=t,
                            inscribed_obstacle_cost_value=0, unknown_cost_value=255)
    table = static_layer_table(cfg)
    for v in range(1, t):
      assert int(table[v]) == (v * 254) // t == int(np.float64(v) / t * 254), (v, t)


def test_static_shapes_and_dtype():
  rng = np.random.default_rng(1)
  data = rng.integers(-1, 101, size=(3, 7, 5)).astype(np.int8)
  out = static_layer(data)
  assert out.dtype == jnp.uint8 and out.shape == (3, 7, 5)
  np.testing.assert_array_equal(np.asarray(out), ref_static(data, StaticLayerConfig()))
  with pytest.raises(ValueError, match="int8"):
    static_layer(data.astype(np.int32))


@pytest.mark.parametrize("kwargs, match", [
    (dict(unknown_cost_value=256), "unknown_cost_value"),
    (dict(unknown_cost_value=-1), "unknown_cost_value"),
    (dict(inscribed_obstacle_cost_value=300), "inscribed_obstacle_cost_value"),
    (dict(lethal_cost_threshold=50.5), "lethal_cost_threshold"),
    (dict(lethal_cost_threshold=True), "lethal_cost_threshold"),
    (dict(trinary_costmap=1), "trinary_costmap"),
    (dict(track_unknown_space="yes"), "track_unknown_space"),
])
def test_static_config_validation(kwargs, match):
  with pytest.raises(ValueError, match=match):
    StaticLayerConfig(**kwargs)


def test_static_config_clamps_and_hashes():
  assert StaticLayerConfig(lethal_cost_threshold=500).lethal_threshold == 100
  assert StaticLayerConfig(lethal_cost_threshold=-3).lethal_threshold == 0
  assert hash(StaticLayerConfig(unknown_cost_value=np.int64(255))) == hash(StaticLayerConfig())
  with pytest.raises(dataclasses.FrozenInstanceError):
    StaticLayerConfig().trinary_costmap = False


# ----------------------------------------------------------------------------
# Radii and computeCost.


def test_footprint_radii_robot_radius():
  inscribed, circumscribed = footprint_radii(robot_radius=0.22)
  assert inscribed == pytest.approx(0.22550, abs=5e-6)
  assert circumscribed == pytest.approx(0.23414, abs=5e-6)
  # No padding: the 16-gon's apothem and its radius.
  inscribed0, circumscribed0 = footprint_radii(robot_radius=0.22, footprint_padding=0.0)
  assert inscribed0 == pytest.approx(0.22 * math.cos(math.pi / 16), rel=1e-12)
  assert circumscribed0 == pytest.approx(0.22, rel=1e-12)


def test_footprint_radii_polygon():
  rect = [(1.75, 1.0), (-1.75, 1.0), (-1.75, -1.0), (1.75, -1.0)]
  assert footprint_radii(footprint=rect, footprint_padding=0.0) == (1.0, math.hypot(1.75, 1.0))
  inscribed, circumscribed = footprint_radii(footprint=rect, footprint_padding=0.01)
  assert inscribed == pytest.approx(1.01, abs=1e-12)
  assert circumscribed == pytest.approx(math.hypot(1.76, 1.01), abs=1e-12)
  # A triangle whose nearest edge point is interior to the edge.
  tri = [(1.0, -1.0), (1.0, 1.0), (-2.0, 0.0)]
  assert footprint_radii(footprint=tri, footprint_padding=0.0)[0] == pytest.approx(
      min(1.0, 2.0 / math.sqrt(10.0)))


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.floats(-3, 3), st.floats(-3, 3)), min_size=3, max_size=8),
       st.floats(0, 0.1))
def test_footprint_radii_properties(pts, pad):
  inscribed, circumscribed = footprint_radii(footprint=pts, footprint_padding=pad)
  padded = [(x + np.sign(x) * pad, y + np.sign(y) * pad) for x, y in pts]
  norms = [math.hypot(x, y) for x, y in padded]
  assert 0.0 <= inscribed <= min(norms) + 1e-12
  assert circumscribed == pytest.approx(max(norms), rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("kwargs", [
    dict(), dict(robot_radius=0.2, footprint=[(0, 1), (1, 0), (0, 0)]),
    dict(footprint=[(0, 1), (1, 0)]), dict(footprint=[(0, 1, 2), (1, 0), (0, 0)]),
    dict(robot_radius=-0.1), dict(robot_radius=float("nan")),
    dict(robot_radius=0.2, footprint_padding=float("inf")),
])
def test_footprint_radii_errors(kwargs):
  with pytest.raises(ValueError):
    footprint_radii(**kwargs)


def test_cell_radius_and_lut():
  cfg = InflationConfig(inflation_radius=0.7, inscribed_radius=0.22, resolution=0.05)
  assert 0.7 / 0.05 == 13.999999999999998 and cfg.cell_radius == 14
  assert InflationConfig(inscribed_radius=0.22, resolution=0.05).cell_radius == 11
  assert InflationConfig(inflation_radius=0.0, inscribed_radius=0.2, resolution=0.05).cell_radius == 0
  assert cfg.cost_lut.shape == (14 * 100 + 2,) and cfg.cost_lut.dtype == np.uint8
  want = [ref_compute_cost(k / 100, 0.05, 0.22, 10.0) for k in range(1402)]
  np.testing.assert_array_equal(cfg.cost_lut, want)


def test_compute_cost_boundary():
  cfg = InflationConfig(inscribed_radius=0.22, resolution=0.05)
  assert 4.4 * 0.05 == 0.22000000000000003
  assert compute_cost(4.4, config=cfg) == ref_compute_cost(4.4, 0.05, 0.22, 10.0) == 251
  assert compute_cost(4.39, config=cfg) == 253
  assert compute_cost(0.0, config=cfg) == 254
  assert compute_cost(0.01, config=cfg) == 253
  # The 0.01-cell LUT reads d = 4.4 at index 440 too.
  assert cfg.cost_lut[440] == 251 and cfg.cost_lut[439] == 253


@pytest.mark.parametrize("kwargs, match", [
    (dict(resolution=0.0), "resolution"),
    (dict(resolution=-0.05), "resolution"),
    (dict(resolution=float("nan")), "resolution"),
    (dict(inflation_radius=-0.1), "inflation_radius"),
    (dict(inflation_radius=float("inf")), "inflation_radius"),
    (dict(cost_scaling_factor=float("nan")), "cost_scaling_factor"),
    (dict(cost_scaling_factor=-1.0), "cost_scaling_factor"),
    (dict(inscribed_radius=-0.2), "inscribed_radius"),
    (dict(inscribed_radius="big"), "inscribed_radius"),
    (dict(inflate_unknown=1), "inflate_unknown"),
    (dict(enabled=None), "enabled"),
    (dict(inflation_radius=100.0, resolution=0.05), "1024"),
])
def test_inflation_config_validation(kwargs, match):
  base = dict(inscribed_radius=0.22, resolution=0.05)
  with pytest.raises(ValueError, match=match):
    InflationConfig(**{**base, **kwargs})


def test_inflation_config_required_and_hashable():
  with pytest.raises(TypeError):
    InflationConfig(resolution=0.05)                      # inscribed_radius is required
  a = InflationConfig(inscribed_radius=np.float64(0.22), resolution=0.05)
  b = InflationConfig(inscribed_radius=0.22, resolution=np.float32(0.05).item())
  assert hash(a) == hash(InflationConfig(inscribed_radius=0.22, resolution=0.05))
  assert a != b                                            # float32(0.05) is another resolution
  c = InflationConfig.from_footprint(resolution=0.05, robot_radius=0.22, cost_scaling_factor=3.0)
  assert c.inscribed_radius == footprint_radii(robot_radius=0.22)[0]
  assert c.cost_scaling_factor == 3.0


# ----------------------------------------------------------------------------
# Exact distances.


@pytest.mark.parametrize("r", [1, 3, 14])
def test_squared_distance_exact(r):
  rng = np.random.default_rng(r)
  for density in (0.002, 0.03, 0.3):
    src = rng.random((37, 29)) < density
    src[rng.integers(37), rng.integers(29)] = True
    sy, sx = np.nonzero(src)
    yy, xx = np.mgrid[:37, :29]
    true = np.min((yy[..., None] - sy) ** 2 + (xx[..., None] - sx) ** 2, axis=-1)
    want = np.minimum(true, (r + 1) ** 2)
    for dtype in (jnp.int16, jnp.int32):
      got = jax.jit(squared_distance, static_argnums=(1, 2))(jnp.asarray(src), r, dtype)
      np.testing.assert_array_equal(np.asarray(got), want)


def test_sq_table_matches_float32_distance():
  cfg = InflationConfig(inflation_radius=0.7, inscribed_radius=0.22, resolution=0.05,
                        cost_scaling_factor=3.0)
  lut, by_sq, max_sq = cost_tables(cfg)
  assert max_sq == 14 ** 2
  for s in range(max_sq + 1):
    d = np.sqrt(np.float32(s))
    k = int(np.float32(np.float32(d * np.float32(100)) + np.float32(0.5)))
    assert by_sq[s] == lut[min(len(lut) - 1, k)]


# ----------------------------------------------------------------------------
# Inflation: worked example and realistic profile.


def test_worked_example_testinflation3():
  inscribed, circumscribed = footprint_radii(
      footprint=[(1.75, 1.0), (-1.75, 1.0), (-1.75, -1.0), (1.75, -1.0)], footprint_padding=0.0)
  assert inscribed == 1.0 and circumscribed == pytest.approx(2.016, abs=1e-3)
  cfg = InflationConfig(inflation_radius=3.0, cost_scaling_factor=1.0, inscribed_radius=inscribed,
                        resolution=1.0)
  assert cfg.cell_radius == 3
  cost = np.zeros((10, 10), np.uint8)
  cost[5, 5] = 254                                         # (x, y) = (5, 5)
  out = np.asarray(inflate_one(cost, config=cfg))
  want_top_row_highest_y = np.array([
      [0, 0, 0, 34, 0, 0, 0],
      [0, 40, 72, 92, 72, 40, 0],
      [0, 72, 167, 253, 167, 72, 0],
      [34, 92, 253, 254, 253, 92, 34],
      [0, 72, 167, 253, 167, 72, 0],
      [0, 40, 72, 92, 72, 40, 0],
      [0, 0, 0, 34, 0, 0, 0]], np.uint8)
  np.testing.assert_array_equal(out[2:9, 2:9][::-1], want_top_row_highest_y)
  assert np.count_nonzero(out) == 29
  assert np.count_nonzero(out == 254) == 1 and np.count_nonzero(out == 253) == 4
  yy, xx = np.mgrid[:10, :10]
  np.testing.assert_array_equal(out > 0, (yy - 5) ** 2 + (xx - 5) ** 2 <= 9)
  np.testing.assert_array_equal(out, ref_inflate_cfg(cost, cfg))
  # The LUT's 0.01-cell quantisation: exact d = sqrt(2) would give 166, d = sqrt(5) 73.
  assert ref_compute_cost(math.sqrt(2), 1, 1, 1) == 166 and out[6, 6] == 167
  assert ref_compute_cost(math.sqrt(5), 1, 1, 1) == 73 and out[6, 7] == 72


def test_realistic_profile():
  cfg = InflationConfig(inflation_radius=0.55, cost_scaling_factor=3.0, inscribed_radius=0.22,
                        resolution=0.05)
  assert cfg.cell_radius == 11
  profile = [254, 253, 253, 253, 253, 230, 198, 170, 146, 126, 108, 93]
  cost = np.zeros((40, 40), np.uint8)
  cost[20, 20] = 254
  out = np.asarray(inflate_one(cost, config=cfg))
  for line in (out[20, 20:], out[20, 20::-1], out[20:, 20], out[20::-1, 20]):
    assert list(line[:12]) == profile
    assert not line[12:].any()                              # d >= 12: untouched
  # On a map that is not blank, cells beyond R keep their old value.
  base = np.full((40, 40), 7, np.uint8)
  base[20, 20] = 254
  out = np.asarray(inflate_one(base, config=cfg))
  assert list(out[20, 20:33]) == profile + [7]
  np.testing.assert_array_equal(out, ref_inflate_cfg(base, cfg))


# ----------------------------------------------------------------------------
# Inflation: unknown cells, sources and borders.


def _cfg(**kw):
  base = dict(inflation_radius=3.0, cost_scaling_factor=1.0, inscribed_radius=1.0, resolution=1.0)
  return InflationConfig(**{**base, **kw})


def test_unknown_cells_default_rule():
  cost = np.zeros((9, 9), np.uint8)
  cost[4, 4] = 254
  cost[4, 5] = 255        # d = 1: 253 >= 253 overwrites unknown
  cost[4, 6] = 255        # d = 2: 92 < 253, stays unknown
  cost[0, 0] = 255        # out of range, stays unknown
  cost[5, 5] = 253        # written by another layer: not a source
  out = np.asarray(inflate_one(cost, config=_cfg()))
  assert out[4, 5] == 253 and out[4, 6] == 255 and out[0, 0] == 255
  assert out[5, 5] == 253 and out[6, 6] == 40               # d = sqrt(8) from (4, 4) only
  np.testing.assert_array_equal(out, ref_inflate_cfg(cost, _cfg()))


def test_unknown_cells_inflate_unknown():
  cfg = _cfg(inflate_unknown=True)
  cost = np.zeros((9, 9), np.uint8)
  cost[4, 4] = 254
  cost[4, 6] = 255        # d = 2: takes 92
  cost[4, 7] = 255        # d = 3: takes 34
  cost[0, 0] = 255        # d > 3: untouched
  out = np.asarray(inflate_one(cost, config=cfg))
  assert out[4, 6] == 92 and out[4, 7] == 34 and out[0, 0] == 255
  np.testing.assert_array_equal(out, ref_inflate_cfg(cost, cfg))
  # A LUT cost of 0 inside R (steep decay) leaves unknown alone even then.
  steep = _cfg(inflate_unknown=True, cost_scaling_factor=20.0)
  assert compute_cost(3.0, config=steep) == 0
  out = np.asarray(inflate_one(cost, config=steep))
  assert out[4, 7] == 255
  np.testing.assert_array_equal(out, ref_inflate_cfg(cost, steep))


def test_unknown_cells_inflate_around_unknown():
  cfg = _cfg(inflate_around_unknown=True)
  cost = np.zeros((9, 9), np.uint8)
  cost[2, 2] = 255
  cost[6, 7] = 255
  out = np.asarray(inflate_one(cost, config=cfg))
  assert out[2, 2] == 254 and out[6, 7] == 254              # unknown becomes 254
  assert out[2, 3] == 253 and out[2, 4] == 92               # and is a source
  np.testing.assert_array_equal(out, ref_inflate_cfg(cost, cfg))
  # Without the flag unknown is neither a source nor overwritten.
  out = np.asarray(inflate_one(cost, config=_cfg()))
  np.testing.assert_array_equal(out, cost)


def test_border_sees_only_in_map_obstacles():
  cfg = _cfg()
  cost = np.zeros((5, 6), np.uint8)
  cost[0, 0] = 254
  out = np.asarray(inflate_one(cost, config=cfg))
  assert out[0, 0] == 254 and out[0, 3] == 34 and out[0, 4] == 0 and out[3, 0] == 34
  np.testing.assert_array_equal(out, ref_inflate_cfg(cost, cfg))


def test_disabled_and_zero_radius_are_identity():
  rng = np.random.default_rng(5)
  cost = random_costmap(rng, (3, 12, 12))
  for cfg in (_cfg(enabled=False), _cfg(inflation_radius=0.0)):
    np.testing.assert_array_equal(np.asarray(inflate(cost, config=cfg)), cost)
    np.testing.assert_array_equal(ref_inflate_cfg(cost[0], cfg), cost[0])


def test_no_sources_untouched():
  cost = np.full((6, 7), 100, np.uint8)
  cost[2, 3] = 255
  np.testing.assert_array_equal(np.asarray(inflate_one(cost, config=_cfg())), cost)


# ----------------------------------------------------------------------------
# Inflation: the case table, four ways.

INFLATION_CASES = [
    # name, (B, H, W), config, costmap densities
    ("unit_res", (3, 16, 16), _cfg(), {}),
    ("realistic", (2, 31, 27),
     InflationConfig(inflation_radius=0.55, cost_scaling_factor=3.0, inscribed_radius=0.22,
                     resolution=0.05), dict(p_lethal=0.005)),
    ("bringup_local", (2, 33, 30),
     InflationConfig.from_footprint(resolution=0.05, robot_radius=0.22, inflation_radius=0.7,
                                    cost_scaling_factor=3.0), dict(p_lethal=0.003)),
    ("inflate_unknown", (2, 20, 18), _cfg(inflate_unknown=True, cost_scaling_factor=0.7),
     dict(p_unknown=0.1)),
    ("around_unknown", (2, 20, 18), _cfg(inflate_around_unknown=True, inflation_radius=4.0),
     dict(p_lethal=0.005, p_unknown=0.01)),
    ("both_unknown", (2, 19, 21),
     _cfg(inflate_unknown=True, inflate_around_unknown=True, inflation_radius=2.5,
          resolution=0.5, inscribed_radius=0.3), dict(p_unknown=0.05)),
    ("dense", (2, 14, 15), _cfg(inflation_radius=5.0, resolution=1.0, inscribed_radius=1.2),
     dict(p_lethal=0.2, p_other=0.5)),
    ("radius_beyond_map", (2, 6, 9),
     InflationConfig(inflation_radius=1.0, cost_scaling_factor=2.0, inscribed_radius=0.18,
                     resolution=0.1), {}),
    ("thin_map", (2, 1, 25), _cfg(inflation_radius=4.0), dict(p_lethal=0.1)),
]


@pytest.mark.parametrize("name, shape, cfg, dens", INFLATION_CASES,
                         ids=[c[0] for c in INFLATION_CASES])
def test_inflation_case_table_four_ways(name, shape, cfg, dens):
  rng = np.random.default_rng(zlib.crc32(name.encode()))
  cost = random_costmap(rng, shape, **dens)
  want = np.stack([ref_inflate_cfg(c, cfg) for c in cost])
  assert (want != cost).any()                                  # the case does something
  one = functools.partial(inflate_one, config=cfg)
  eager = np.stack([np.asarray(one(c)) for c in cost])         # eager, Python loop
  np.testing.assert_array_equal(eager, want)
  jitted = jax.jit(one)
  np.testing.assert_array_equal(np.stack([np.asarray(jitted(c)) for c in cost]), want)
  np.testing.assert_array_equal(np.asarray(jax.vmap(one)(cost)), eager)
  batched = jax.jit(functools.partial(inflate, config=cfg))(jnp.asarray(cost))
  assert batched.dtype == jnp.uint8 and batched.shape == shape
  np.testing.assert_array_equal(np.asarray(batched), want)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1),
       case=st.sampled_from([(1.0, 2.0, 0.5, 1.0), (0.05, 0.3, 3.0, 0.12),
                             (0.1, 0.55, 10.0, 0.17), (0.25, 1.0, 1.5, 0.0)]),
       flags=st.tuples(st.booleans(), st.booleans()),
       dens=st.sampled_from([0.005, 0.05, 0.3]))
def test_inflation_random_maps(seed, case, flags, dens):
  res, radius, csf, inscribed = case
  cfg = InflationConfig(inflation_radius=radius, cost_scaling_factor=csf,
                        inscribed_radius=inscribed, resolution=res,
                        inflate_unknown=flags[0], inflate_around_unknown=flags[1])
  cost = random_costmap(np.random.default_rng(seed), (13, 11), p_lethal=dens, p_unknown=dens / 2)
  got = _jitted_inflate_one(cfg)(cost)
  np.testing.assert_array_equal(np.asarray(got), ref_inflate_cfg(cost, cfg))


@functools.lru_cache(maxsize=None)
def _jitted_inflate_one(cfg):
  return jax.jit(functools.partial(inflate_one, config=cfg))


# ----------------------------------------------------------------------------
# API conventions and recompilation.


def test_inflate_costmap_pytree():
  cfg = InflationConfig(inflation_radius=0.55, cost_scaling_factor=3.0, inscribed_radius=0.22,
                        resolution=0.05)
  rng = np.random.default_rng(11)
  cost = random_costmap(rng, (3, 24, 20))
  cm = Costmap.create(cost, origin=[[0.0, 0.0], [1.0, -2.0], [3.5, 0.25]], resolution=0.05)
  out = inflate(cm, config=cfg)
  assert isinstance(out, Costmap)
  np.testing.assert_array_equal(np.asarray(out.origin), np.asarray(cm.origin))
  np.testing.assert_array_equal(np.asarray(out.resolution), np.asarray(cm.resolution))
  np.testing.assert_array_equal(np.asarray(out.cost), np.stack([ref_inflate_cfg(c, cfg)
                                                                for c in cost]))
  out_jit = jax.jit(functools.partial(inflate, config=cfg))(cm)
  np.testing.assert_array_equal(np.asarray(out_jit.cost), np.asarray(out.cost))
  with pytest.raises(ValueError, match="resolution"):
    inflate(cm, config=dataclasses.replace(cfg, resolution=0.1))


def test_inflate_input_errors():
  cfg = _cfg()
  with pytest.raises(ValueError, match=r"uint8 \[B, H, W\]"):
    inflate(np.zeros((4, 4), np.uint8), config=cfg)
  with pytest.raises(ValueError, match=r"uint8 \[B, H, W\]"):
    inflate(np.zeros((1, 4, 4), np.int32), config=cfg)
  with pytest.raises(ValueError, match=r"uint8 \[H, W\]"):
    inflate_one(np.zeros((1, 4, 4), np.uint8), config=cfg)
  with pytest.raises(TypeError, match="InflationConfig"):
    inflate(np.zeros((1, 4, 4), np.uint8), config=StaticLayerConfig())


def test_second_call_compiles_nothing():
  cfg = InflationConfig(inflation_radius=0.7, cost_scaling_factor=3.0, inscribed_radius=0.22,
                        resolution=0.05)
  rng = np.random.default_rng(3)
  inflate_jit = jax.jit(functools.partial(inflate, config=cfg))
  cm1 = Costmap.create(random_costmap(rng, (4, 30, 30)), [0.0, 0.0], 0.05)
  cm2 = Costmap.create(random_costmap(rng, (4, 30, 30)), [[1.0, 2.0]] * 4, 0.05)
  out1 = inflate_jit(cm1)
  out2 = inflate_jit(cm2)
  assert inflate_jit._cache_size() == 1
  assert not np.array_equal(np.asarray(out1.cost), np.asarray(out2.cost))
  np.testing.assert_array_equal(np.asarray(out2.cost[1]), ref_inflate_cfg(np.asarray(cm2.cost[1]),
                                                                          cfg))
  static_jit = jax.jit(static_layer)
  static_jit(rng.integers(-1, 101, (2, 8, 8)).astype(np.int8))
  static_jit(rng.integers(-1, 101, (2, 8, 8)).astype(np.int8))
  assert static_jit._cache_size() == 1
  # An equal (but distinct) config object hits the same cache entry.
  same = jax.jit(inflate, static_argnames="config")
  same(cm1.cost, config=cfg)
  same(cm2.cost, config=dataclasses.replace(cfg))
  assert same._cache_size() == 1
