"""Speed, binary and zone filters: reference sequences, spec examples, real Nav2 masks."""

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfilters as jf
from jaxfilters import speed as sp
from reference import nav2 as reference


def _mask(data, res, origin, ftype, base=0.0, mult=1.0):
  return jf.FilterMask.create(jf.OccupancyGrid.create(np.asarray(data, np.int8), res, origin),
                              jf.FilterInfo.create(ftype, base, mult))


def _random_mask(rng, ftype, base, mult, shape=(12, 16)):
  data = rng.choice([-1, 0, 0, 10, 20, 37, 50, 65, 99, 100], shape).astype(np.int8)
  res = np.float32(rng.choice([0.05, 0.1, 0.5]))
  origin = np.float32(rng.uniform(-5, 5, 2))
  return data, res, origin, _mask(data, float(res), tuple(origin), ftype, base, mult)


def _walk(rng, origin, res, shape, b, t):
  lo = origin - 2 * res
  hi = origin + (np.array(shape[::-1]) + 2) * res
  return np.float32(rng.uniform(lo, hi, (t, b, 2)))


_speed = jax.jit(sp.speed_filter)


@pytest.mark.parametrize("ftype,base,mult", [(1, 100.0, -1.0), (1, 0.0, 1.0), (2, 0.0, 0.01),
                                             (1, 120.0, -1.23), (2, -0.2, 0.01)])
def test_speed_sequences_match_reference(ftype, base, mult):
  rng = np.random.default_rng(ftype * 10 + int(base))
  data, res, origin, mask = _random_mask(rng, ftype, base, mult)
  b, t = 16, 12
  xy = _walk(rng, origin, res, data.shape, b, t)
  enabled = rng.random((t, b)) < 0.9
  state = sp.SpeedState.create(b)
  refs = [reference.SpeedRef() for _ in range(b)]
  b32, m32 = np.float32(base), np.float32(mult)
  for k in range(t):
    poses = np.concatenate([xy[k], np.zeros((b, 1), np.float32)], axis=1)
    state, out = _speed(mask, poses, state, enabled=enabled[k])
    for r in range(b):
      lim, valid = reference.speed_limit_at(data, origin, res, ftype, b32, m32, xy[k, r, 0], xy[k, r, 1])
      want, changed = refs[r].process(lim, valid, enabled[k, r])
      assert bool(out.changed[r]) == changed
      np.testing.assert_allclose(float(out.speed_limit[r]), want, rtol=1e-6, atol=1e-6)
      assert bool(out.percentage[r]) == (ftype == 1)
  assert _speed._cache_size() <= 2  # one compile per enabled-dtype signature, none per step


def test_speed_vmap_of_kernel_equals_python_loop():
  rng = np.random.default_rng(3)
  data, res, origin, mask = _random_mask(rng, 1, 100.0, -1.0)
  poses = np.concatenate([_walk(rng, origin, res, data.shape, 20, 1)[0], np.zeros((20, 1), np.float32)], 1)
  state = sp.SpeedState.create(20)
  _, out = sp.speed_filter(mask, poses, state)
  info = jax.tree.map(lambda x: x[0], mask.info)
  for r in range(20):
    lim, valid = sp.speed_limit_at_one(mask.data[0], mask.origin[0], mask.resolution[0], info, jnp.asarray(poses[r, :2]))
    assert bool(valid) == bool(out.valid[r])
    if bool(valid):
      assert float(lim) == float(out.speed_limit[r])


def test_speed_rules_no_limit_start_and_sticky_limit():
  mask = _mask([[0, 40, -1]], 1.0, (0, 0), 1, 100.0, -1.0)
  state = sp.SpeedState.create(1)
  seq = [(0.5, 0.0, False), (1.5, 60.0, True), (2.5, 60.0, False), (5.0, 60.0, False), (1.5, 60.0, False),
         (0.5, 0.0, True)]
  for x, limit, changed in seq:
    state, out = sp.speed_filter(mask, np.array([[x, 0.5, 0]], np.float32), state)
    assert (float(out.speed_limit[0]), bool(out.changed[0])) == (limit, changed), x


def test_speed_percent_range_and_absolute_rules():
  # d=100 with 100 - d -> 0 % = no limit; 120 - 1.23 d out of range for d <= 16 -> 0.
  mask = _mask([[100, 16, 17]], 1.0, (0, 0), 1, 120.0, -1.23)
  lims = [float(sp.speed_filter(mask, np.array([[x, 0.5, 0]], np.float32), sp.SpeedState.create(1))[1].speed_limit[0])
          for x in (0.5, 1.5, 2.5)]
  assert lims[0] == 0.0 and lims[1] == 0.0
  np.testing.assert_allclose(lims[2], 120 - 17 * float(np.float32(1.23)), rtol=1e-6)
  absm = _mask([[5, 50]], 1.0, (0, 0), 2, -0.2, 0.01)
  lims = [float(sp.speed_filter(absm, np.array([[x, 0.5, 0]], np.float32), sp.SpeedState.create(1))[1].speed_limit[0])
          for x in (0.5, 1.5)]
  assert lims[0] == 0.0
  np.testing.assert_allclose(lims[1], 0.3, rtol=1e-5)


def test_speed_mask_of_wrong_type_publishes_nothing():
  mask = _mask([[40]], 1.0, (0, 0), 0)
  _, out = sp.speed_filter(mask, np.array([[0.5, 0.5, 0]], np.float32), sp.SpeedState.create(1))
  assert not bool(out.valid[0]) and not bool(out.changed[0])


def test_speed_path_lookahead_spec_example():
  data = np.zeros((10, 5), np.int8)
  for j, v in enumerate([0, 0, 0, 3, 3, 13, 13, 13, 20, 20]):
    data[j] = v
  mask = _mask(data, 0.5, (0, 0), 1, 0.0, 1.0)
  ys = np.array([5 * k / 11 for k in range(12)], np.float32)
  path = np.stack([np.full(12, 2.0, np.float32), ys], 1)[None]
  state, out = sp.speed_filter_lookahead(mask, np.array([[2.0, 0.0, 0.0]]), sp.SpeedState.create(1), path,
                                         np.array([12]), np.array([1.0]),
                                         config=sp.LookaheadConfig(max_decel=-0.2))
  assert float(out.speed_limit[0]) == 3.0 and bool(out.changed[0])
  assert float(state.held_lookahead[0]) == 2.5    # robot cell limit 0 != 3: distance held
  # Slower: d = clamp(0.01 / 0.4, 0.3, 5) = 0.3 -> but the held 2.5 still applies.
  state, out = sp.speed_filter_lookahead(mask, np.array([[2.0, 0.0, 0.0]]), state, path, np.array([12]),
                                         np.array([0.1]), config=sp.LookaheadConfig(max_decel=-0.2))
  assert float(out.speed_limit[0]) == 3.0 and not bool(out.changed[0])
  # Fresh state, slow robot: lookahead 0.3 m sees only y = 0 (d = 0) -> no limit, nothing published.
  _, out = sp.speed_filter_lookahead(mask, np.array([[2.0, 0.0, 0.0]]), sp.SpeedState.create(1), path,
                                     np.array([12]), np.array([0.1]), config=sp.LookaheadConfig(max_decel=-0.2))
  assert float(out.speed_limit[0]) == 0.0 and not bool(out.changed[0])


def test_warehouse_speed_mask_limits_are_100_minus_value(nav2_maps):
  grid = jf.load_map(nav2_maps / "warehouse_speed.yaml")
  mask = jf.FilterMask.create(grid, jf.FilterInfo.create(1, 100.0, -1.0))
  rng = np.random.default_rng(0)
  rows, cols = rng.integers(0, grid.height, 400), rng.integers(0, grid.width, 400)
  # Include cells of every value present.
  for v in np.unique(grid.data):
    j, i = np.argwhere(grid.data == v)[0]
    rows, cols = np.append(rows, j), np.append(cols, i)
  ox, oy = np.float32(grid.origin[0]), np.float32(grid.origin[1])
  res = np.float32(grid.resolution)
  xy = np.stack([ox + (cols + 0.5) * res, oy + (rows + 0.5) * res], 1).astype(np.float32)
  poses = np.concatenate([xy, np.zeros((len(xy), 1), np.float32)], 1)
  _, out = sp.speed_filter(mask, poses, sp.SpeedState.create(len(xy)))
  d = grid.data[rows, cols].astype(int)
  expected = np.where((d == 0) | (d == 100), 0.0, 100.0 - d)
  known = d != -1
  np.testing.assert_array_equal(np.asarray(out.valid), known)
  np.testing.assert_array_equal(np.asarray(out.speed_limit)[known], expected[known])
  assert set(np.unique(d)) >= {0, 20}


def test_mask_stack_with_index_and_swap_without_recompile():
  a = jf.OccupancyGrid.create(np.full((4, 4), 30, np.int8), 1.0, (0, 0))
  b = jf.OccupancyGrid.create(np.full((4, 4), 60, np.int8), 1.0, (0, 0))
  info = jf.FilterInfo.create(1, 100.0, -1.0)
  mask = jf.FilterMask.create([a, b], info)
  f = jax.jit(lambda m, p, i: sp.speed_filter(m, p, sp.SpeedState.create(3), mask_index=i)[1].speed_limit)
  p = np.full((3, 3), 1.5, np.float32)
  assert np.asarray(f(mask, p, jnp.array([0, 1, 1]))).tolist() == [70.0, 40.0, 40.0]
  mask2 = mask.with_data(np.stack([np.full((4, 4), 90), np.full((4, 4), 10)]).astype(np.int8))
  assert np.asarray(f(mask2, p, jnp.array([0, 1, 0]))).tolist() == [10.0, 90.0, 10.0]
  assert f._cache_size() == 1
  with pytest.raises(ValueError, match="shape"):
    mask.with_data(np.zeros((3, 3), np.int8))


@pytest.mark.parametrize("default_state,thr,base,mult", [(False, 50.0, 0.0, 1.0), (True, 35.0, 100.0, -1.0),
                                                         (False, 20.0, 0.5, 0.3)])
def test_binary_sequences_match_reference(default_state, thr, base, mult):
  rng = np.random.default_rng(int(thr))
  data, res, origin, mask = _random_mask(rng, 3, base, mult)
  b, t = 12, 14
  xy = _walk(rng, origin, res, data.shape, b, t)
  state = jf.BinaryState.create(b)
  refs = [reference.BinaryRef(default_state, float(np.float32(thr))) for _ in range(b)]
  f = jax.jit(lambda p, s: jf.binary_filter(mask, p, s, default_state=default_state, flip_threshold=thr))
  for k in range(t):
    poses = np.concatenate([xy[k], np.zeros((b, 1), np.float32)], axis=1)
    state, out = f(poses, state)
    for r in range(b):
      pub = refs[r].process(data, origin, res, np.float32(base), np.float32(mult), xy[k, r, 0], xy[k, r, 1])
      assert bool(out.published[r]) == pub and bool(out.binary_state[r]) == refs[r].state


def test_binary_spec_example_scaled():
  # testBinaryStateScaled: base 100, mult -1, threshold 35: on when d < 65.
  mask = _mask([[0, 65]], 1.0, (0, 0), 3, 100.0, -1.0)
  s = jf.BinaryState.create(1)
  s, out = jf.binary_filter(mask, np.array([[0.5, 0.5, 0]]), s, flip_threshold=35.0)
  assert bool(out.binary_state[0]) and bool(out.published[0])
  s, out = jf.binary_filter(mask, np.array([[1.5, 0.5, 0]]), s, flip_threshold=35.0)
  assert not bool(out.binary_state[0]) and bool(out.published[0])
  # Outside the mask: default state published every cycle.
  for _ in range(2):
    s, out = jf.binary_filter(mask, np.array([[9.0, 0.5, 0]]), s, flip_threshold=35.0)
    assert bool(out.published[0]) and not bool(out.binary_state[0])


def test_zone_sequences_match_reference():
  nominal = {"max_vel": 1.0, "inflation": 0.55}
  states = {3: {"max_vel": 0.3}, 7: {"inflation": 0.9, "lamp": 1.0}, 9: {"max_vel": 0.1, "lamp": 2.0}}
  table = jf.ZoneTable.create(["max_vel", "inflation", "lamp"], nominal, states)
  rng = np.random.default_rng(5)
  data = rng.choice([-1, 0, 3, 7, 9, 11], (10, 10)).astype(np.int8)
  mask = _mask(data, 0.5, (0, 0), 4)
  b, t = 10, 16
  xy = _walk(rng, np.zeros(2, np.float32), np.float32(0.5), data.shape, b, t)
  state = jf.ZoneState.create(table, b)
  refs = [reference.ZoneRef(nominal, states) for _ in range(b)]
  for r in refs:
    r.params["lamp"] = 0.0
  f = jax.jit(lambda p, s: jf.zone_filter(mask, p, s, table))
  for k in range(t):
    poses = np.concatenate([xy[k], np.zeros((b, 1), np.float32)], axis=1)
    state, out = f(poses, state)
    for r in range(b):
      event, error = refs[r].process(data, (0, 0), 0.5, xy[k, r, 0], xy[k, r, 1])
      assert bool(out.event[r]) == event and bool(out.error[r]) == error
      assert int(out.zone[r]) == refs[r].current
      np.testing.assert_allclose(np.asarray(out.params[r]),
                                 [refs[r].params["max_vel"], refs[r].params["inflation"], refs[r].params["lamp"]],
                                 rtol=1e-6)


def test_zone_table_validation():
  with pytest.raises(ValueError, match="zone id"):
    jf.ZoneTable.create(["a"], {"a": 1.0}, {200: {"a": 2.0}})
  with pytest.raises(ValueError, match="not one of the parameters"):
    jf.ZoneTable.create(["a"], {"a": 1.0}, {2: {"b": 2.0}})


def test_filter_info_and_mask_validation():
  with pytest.raises(ValueError, match="type must be one of"):
    jf.FilterInfo.create(7)
  assert float(jf.FilterInfo.create(1, 1.23, 0.1).base) == float(np.float32(1.23))
  with pytest.raises(ValueError, match="share one"):
    jf.FilterMask.create([jf.OccupancyGrid.create(np.zeros((2, 2), np.int8), 1.0),
                          jf.OccupancyGrid.create(np.zeros((3, 2), np.int8), 1.0)], jf.FilterInfo.create(0))
  with pytest.raises(TypeError, match="OccupancyGrid"):
    jf.FilterMask.create([np.zeros((2, 2))], jf.FilterInfo.create(0))
  with pytest.raises(ValueError, match="-1..100"):
    jf.OccupancyGrid.create(np.full((2, 2), 101), 1.0)


@pytest.mark.parametrize("call", ["speed", "binary", "zone"])
def test_bad_per_robot_inputs_raise_clear_errors(call):
  mask = _mask([[0, 40]], 1.0, (0, 0), 1, 100.0, -1.0)
  table = jf.ZoneTable.create(["a"], {"a": 1.0}, {})
  run = {"speed": lambda **kw: jf.speed_filter(mask, np.zeros((2, 3)), jf.SpeedState.create(2), **kw),
         "binary": lambda **kw: jf.binary_filter(mask, np.zeros((2, 3)), jf.BinaryState.create(2), **kw),
         "zone": lambda **kw: jf.zone_filter(mask, np.zeros((2, 3)), jf.ZoneState.create(table, 2), table, **kw)}[call]
  with pytest.raises(ValueError, match="enabled must be"):
    run(enabled=np.ones((3,), bool))
  with pytest.raises(ValueError, match="transform must be"):
    run(transform=np.zeros((2, 2)))
  with pytest.raises(ValueError, match="mask_index"):
    run(mask_index=np.zeros((5,), np.int32))


class KernelJitVariantsTest(chex.TestCase):
  """The per-robot kernels against the NumPy reference, eager and under jit (`chex.variants`).

  The public filters are jitted at the edge, so only the `*_one` kernels run op by op when
  called eagerly; both variants must give the reference's sequence exactly.
  """

  @chex.variants(with_jit=True, without_jit=True)
  def test_speed_filter_one_sequence_matches_reference(self):
    rng = np.random.default_rng(21)
    data, res, origin, mask = _random_mask(rng, 1, 120.0, -1.23)
    info = jax.tree.map(lambda x: x[0], mask.info)

    @self.variant
    def step(state, pose, enabled):
      return sp.speed_filter_one(state, mask.data[0], mask.origin[0], mask.resolution[0], info, pose, enabled,
                                 None)

    t = 30
    xy = _walk(rng, origin, res, data.shape, 1, t)[:, 0]
    enabled = rng.random(t) < 0.85
    state = jax.tree.map(lambda x: x[0], sp.SpeedState.create(1))
    ref = reference.SpeedRef()
    seen = set()
    for k in range(t):
      state, out = step(state, jnp.asarray([xy[k, 0], xy[k, 1], 0.0], jnp.float32), jnp.asarray(enabled[k]))
      lim, valid = reference.speed_limit_at(data, origin, res, 1, np.float32(120.0), np.float32(-1.23), *xy[k])
      want, changed = ref.process(lim, valid, enabled[k])
      seen.add((valid, changed))
      self.assertEqual(bool(out.changed), changed)
      np.testing.assert_allclose(float(out.speed_limit), want, rtol=1e-6, atol=1e-6)
    self.assertGreaterEqual(len(seen), 3)      # valid and invalid cycles, changes and repeats

  @chex.variants(with_jit=True, without_jit=True)
  def test_binary_filter_one_sequence_matches_reference(self):
    rng = np.random.default_rng(22)
    data, res, origin, mask = _random_mask(rng, 3, 100.0, -1.0)
    info = jax.tree.map(lambda x: x[0], mask.info)
    thr = np.float32(35.0)

    @self.variant
    def step(state, pose):
      return jf.binary.binary_filter_one(state, mask.data[0], mask.origin[0], mask.resolution[0], info, pose,
                                         jnp.asarray(True), jnp.asarray(thr), jnp.asarray(True), None)

    t = 30
    xy = _walk(rng, origin, res, data.shape, 1, t)[:, 0]
    state = jax.tree.map(lambda x: x[0], jf.BinaryState.create(1))
    ref = reference.BinaryRef(True, float(thr))
    flips = 0
    for k in range(t):
      state, out = step(state, jnp.asarray([xy[k, 0], xy[k, 1], 0.0], jnp.float32))
      pub = ref.process(data, origin, res, np.float32(100.0), np.float32(-1.0), xy[k, 0], xy[k, 1])
      self.assertEqual(bool(out.published), pub)
      self.assertEqual(bool(out.binary_state), ref.state)
      flips += pub
    self.assertGreater(flips, 1)
