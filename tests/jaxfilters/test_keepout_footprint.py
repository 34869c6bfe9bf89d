"""The footprint-aware keepout escape (jaxfilters/footprint.py) against the float64 reference.

The rule is decided in float32 on the device; the reference (reference/nav2.py)
computes it in float64 over every mask cell. Random cases compare with an
undecided band of EPS metres around the footprint boundary (the device cannot
do better in float32); the dyadic cases (0.25 m grid, yaw 0), where every
float32 step is exact, compare exactly, with cell centres on the footprint
boundary and poses on cell edges.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfilters as jf
from jaxfilters import footprint as fp
from reference import nav2 as reference
from tests.compile_count import count_compiles

EPS = 2e-5            # m: undecided band of the random cases (float32 on coordinates up to ~10 m)
KEEPOUT = jf.FilterInfo.create(0)
FOOTPRINTS = {
    "disc": dict(robot_radius=0.3),
    "rect": dict(footprint=((0.35, 0.2), (-0.25, 0.2), (-0.25, -0.2), (0.35, -0.2))),
    # Non-convex (an L): the even-odd interior and the notch matter.
    "ell": dict(footprint=((0.3, 0.3), (-0.2, 0.3), (-0.2, -0.3), (0.05, -0.3), (0.05, 0.05), (0.3, 0.05))),
}
HM, WM = 12, 15


def _config(name, *, clearance=0.0, min_res=0.05, cost=200):
  return jf.KeepoutConfig(override_lethal_cost=True, lethal_override_cost=cost, robot_in_zone="footprint",
                          min_mask_resolution=min_res, escape_clearance=clearance, **FOOTPRINTS[name])


def _shape(cfg):
  return dict(polygon=cfg.footprint, radius=cfg.robot_radius)


def _ref(case, cfg, margin):
  return reference.footprint_in_zone(case["data"], case["origin"], case["res"], case["pose"], margin=margin,
                                     eps=case.get("eps", EPS), **_shape(cfg))


def _random_cases(seed, count):
  """Masks with lethal, graded, free and unknown cells; poses on, near and off the mask, any yaw."""
  rng = np.random.default_rng(seed)
  cases = []
  for _ in range(count):
    res = np.float32(rng.choice([0.05, 0.1]))
    data = rng.choice([-1, 0, 0, 40, 99, 100, 100], (HM, WM)).astype(np.int8)
    if rng.random() < 0.3:                     # a sparse mask: single lethal cells decide
      data = np.where(rng.random((HM, WM)) < 0.05, 100, 0).astype(np.int8)
    origin = np.float32(rng.uniform(-4, 4, 2))
    x = origin[0] + rng.uniform(-0.6, WM * res + 0.6)
    y = origin[1] + rng.uniform(-0.6, HM * res + 0.6)
    pose = np.float32([x, y, rng.uniform(-np.pi, np.pi)])
    cases.append(dict(data=data, origin=origin, res=res, pose=pose))
  return cases


def _stack(cases):
  return (jnp.asarray(np.stack([c["data"] for c in cases])), jnp.asarray(np.stack([c["origin"] for c in cases])),
          jnp.asarray(np.stack([c["res"] for c in cases])), jnp.asarray(np.stack([c["pose"] for c in cases])))


def _kernel(cfg):
  """The per-robot kernel with the config's static footprint, margin traced."""
  def one(data, origin, res, pose, margin):
    return fp.footprint_in_zone_one(data, origin, res, pose, window=cfg.footprint_window, margin=margin,
                                    **_shape(cfg))
  return one


def _check(got, want):
  """got bool within the reference's (surely, possibly); returns how many were undecided."""
  surely, possibly = want
  assert (got or not surely) and (possibly or not got), (got, want)
  return int(surely != possibly)


# ----------------------------------------------------------------------------- the rule, four ways


@pytest.mark.parametrize("name", sorted(FOOTPRINTS))
def test_random_cases_match_reference_jit_and_vmap(name):
  cfg = _config(name, clearance=0.1)
  cases = _random_cases(sorted(FOOTPRINTS).index(name), 160)
  margins = np.float32(np.random.default_rng(1).choice([0.0, 0.1], len(cases)))
  batched = jax.jit(jax.vmap(_kernel(cfg)))(*_stack(cases), jnp.asarray(margins))
  undecided = 0
  hits = 0
  for c, m, got in zip(cases, margins, np.asarray(batched)):
    undecided += _check(bool(got), _ref(c, cfg, float(m)))
    hits += bool(got)
  assert undecided <= 2, undecided               # the band is thin: nearly every case is decided
  assert 20 < hits < len(cases) - 20, hits      # both answers are exercised
  # vmap == a loop of jitted single calls == eager calls (a few: eager dispatch is slow).
  jitted = jax.jit(_kernel(cfg))
  for i in range(0, len(cases), 16):
    args = [jnp.asarray(cases[i][k]) for k in ("data", "origin", "res", "pose")]
    assert bool(jitted(*args, margins[i])) == bool(batched[i])
  for i in range(3):
    args = [jnp.asarray(cases[i][k]) for k in ("data", "origin", "res", "pose")]
    assert bool(_kernel(cfg)(*args, margins[i])) == bool(batched[i])


def _dyadic(data_cells, pose, **extra):
  """A 0.25 m grid at origin (-1, -0.5) where float32 is exact; lethal cells at (col, row) pairs."""
  data = np.zeros((HM, WM), np.int8)
  for col, row in data_cells:
    data[row, col] = 100
  return dict(data=data, origin=np.float32([-1.0, -0.5]), res=np.float32(0.25), pose=np.float32(pose), eps=0.0,
              **extra)


# Lethal cell (4, 4) has its centre at (0.125, 0.625); the disc has radius 0.3 or 0.5, the square is +-0.25.
_C = (0.125, 0.625)
DYADIC = [
    # (footprint, case, expected): centres exactly on the boundary are covered (closed footprint).
    ("r05", _dyadic([(4, 4)], [_C[0] + 0.5, _C[1], 0.0]), True),               # on the circle, +x
    ("r05", _dyadic([(4, 4)], [_C[0], _C[1] - 0.5, 0.0]), True),               # on the circle, -y
    ("r05", _dyadic([(4, 4)], [_C[0] + 0.25, _C[1] + 0.25, 0.0]), True),       # |d| = 0.354, inside
    ("r05", _dyadic([(4, 4)], [_C[0] + 0.5 + 2 ** -12, _C[1], 0.0]), False),  # just outside
    ("r05", _dyadic([(4, 4)], [0.0, 0.5, 0.0]), True),                         # pose on a cell corner
    ("r05", _dyadic([(4, 4)], [0.75, 0.5, 0.0]), False),                       # on a cell edge, |d| > 0.5
    ("sq", _dyadic([(4, 4)], [_C[0] + 0.25, _C[1] + 0.125, 0.0]), True),       # on the left edge
    ("sq", _dyadic([(4, 4)], [_C[0] - 0.25, _C[1] - 0.25, 0.0]), True),        # on a vertex
    ("sq", _dyadic([(4, 4)], [_C[0] + 0.25 + 2 ** -12, _C[1], 0.0]), False),
    ("sq", _dyadic([(4, 4)], [_C[0], _C[1] + 0.25 + 2 ** -12, 0.0]), False),
    # Partly off the mask: the robot's centre left of the mask, the footprint over column 0.
    ("r05", _dyadic([(0, 2)], [-1.25, 0.125, 0.0]), True),
    ("r05", _dyadic([(0, 2)], [-1.5, 0.125, 0.0]), False),                     # centre (-0.875) 0.625 away
    ("sq", _dyadic([(14, 11)], [2.625 + 0.25, 2.375 + 0.25, 0.0]), True),      # vertex, robot past the corner
    ("sq", _dyadic([], [0.5, 0.5, 0.0]), False),                               # no lethal cell at all
    ("r05", dict(_dyadic([(4, 4)], [_C[0], _C[1], 0.0]), pose=np.float32([np.nan, 0.5, 0.0])), False),
]
DYADIC_SHAPES = {"r05": dict(robot_radius=0.5), "sq": dict(footprint=((0.25, 0.25), (-0.25, 0.25),
                                                                       (-0.25, -0.25), (0.25, -0.25)))}


@pytest.mark.parametrize("shape", sorted(DYADIC_SHAPES))
def test_dyadic_boundary_cases_exact(shape):
  cfg = jf.KeepoutConfig(override_lethal_cost=True, robot_in_zone="footprint", min_mask_resolution=0.25,
                         **DYADIC_SHAPES[shape])
  cases = [(c, want) for s, c, want in DYADIC if s == shape]
  for c, want in cases:
    assert reference.footprint_in_zone(c["data"], c["origin"], c["res"], c["pose"], **_shape(cfg)) == (want, want)
  batched = np.asarray(jax.vmap(_kernel(cfg))(*_stack([c for c, _ in cases]), jnp.zeros(len(cases))))
  assert batched.tolist() == [w for _, w in cases]
  one = jax.jit(_kernel(cfg))
  for (c, want), b in zip(cases, batched):
    assert bool(one(*[jnp.asarray(c[k]) for k in ("data", "origin", "res", "pose")], 0.0)) == want


def test_dyadic_rotated_square_covers_by_its_rotated_corner():
  """Yaw pi/4 (not exact in float32): a centre 0.01 m inside the rotated corner is covered, 0.01 m out is not."""
  cfg = jf.KeepoutConfig(override_lethal_cost=True, robot_in_zone="footprint", min_mask_resolution=0.25,
                         **DYADIC_SHAPES["sq"])
  corner = 0.25 * math.sqrt(2.0)
  out = []
  for d in (corner - 0.01, corner + 0.01):
    c = _dyadic([(4, 4)], [_C[0] - d, _C[1], math.pi / 4])
    out.append(bool(jax.jit(_kernel(cfg))(*[jnp.asarray(c[k]) for k in ("data", "origin", "res", "pose")], 0.0)))
    assert reference.footprint_in_zone(c["data"], c["origin"], c["res"], c["pose"], eps=EPS,
                                       **_shape(cfg)) == (out[-1], out[-1])
  assert out == [True, False]


# ----------------------------------------------------------------------------- through the public filter
#
# Every call below uses B = 8 costmaps of 24 x 24 cells and a stack of 8 masks of 12 x 15 (one
# compile of each jitted function serves them all; process() ignores the footprint options, so
# the filter compiles once per override cost).

B = 8
ORIGIN = np.float32([-0.4, 0.3])       # every mask's origin; 0.05 m cells


def _fleet(seed, *, res=0.05, datas=None):
  """B robots, one random mask each (a stack), poses on, near and off their masks."""
  rng = np.random.default_rng(seed)
  if datas is None:
    datas = []
    for _ in range(B):
      data = np.zeros((HM, WM), np.int8)
      r0, c0 = rng.integers(0, HM - 4), rng.integers(0, WM - 5)
      data[r0:r0 + rng.integers(2, 5), c0:c0 + rng.integers(2, 6)] = 100
      data[rng.random((HM, WM)) < 0.08] = -1
      data[rng.random((HM, WM)) < 0.08] = 50
      datas.append(data)
  mask = jf.FilterMask.create([jf.OccupancyGrid.create(d, res, tuple(ORIGIN)) for d in datas], KEEPOUT)
  poses = np.float32(np.stack([rng.uniform(-0.7, -0.4 + WM * res + 0.3, B),
                               rng.uniform(0.0, 0.3 + HM * res + 0.3, B), rng.uniform(-np.pi, np.pi, B)], 1))
  return mask, poses, np.stack(datas)


def _bounds():
  return np.tile(np.float32([-2, -2, 2, 2]), (B, 1))


def _costmaps(poses, rng):
  cost = rng.choice([0, 0, 0, 30, 120, 253, 254, 255], (B, 24, 24)).astype(np.uint8)
  return jf.Costmap.create(cost, poses[:, :2] - 0.6, 0.05)


def _cycle(cm, mask, poses, state, cfg):
  state, _ = jf.keepout_update_bounds(cm, mask, poses, state, _bounds(), mask_index=np.arange(B), config=cfg)
  return jf.keepout_filter(cm, mask, poses, state, mask_index=np.arange(B), config=cfg)


@pytest.mark.parametrize("name", ["disc", "ell"])
def test_update_bounds_and_escape_write_match_reference(name):
  cfg = _config(name, clearance=0.08)
  rng = np.random.default_rng(3)
  decided = lethal_count = 0
  for rnd in range(5):
    mask, poses, datas = _fleet(10 * rnd + len(name))
    prev = rng.random(B) < 0.5                     # escape on last cycle: the grown footprint decides
    state = dataclasses.replace(jf.KeepoutState.create(B), is_pose_lethal=jnp.asarray(prev))
    cm = _costmaps(poses, rng)
    new_cm, state = _cycle(cm, mask, poses, state, cfg)
    lethal = np.asarray(state.is_pose_lethal)
    lethal_count += int(lethal.sum())
    assert not np.asarray(state.error).any()
    for i in range(B):
      case = dict(data=datas[i], origin=ORIGIN, res=np.float32(0.05), pose=poses[i])
      centre = reference.centre_in_zone(datas[i], ORIGIN, 0.05, poses[i, 0], poses[i, 1])
      surely, possibly = _ref(case, cfg, cfg.escape_clearance if prev[i] else 0.0)
      _check(bool(lethal[i]), (centre or surely, centre or possibly))
      if (centre or surely) == (centre or possibly):
        decided += 1
        want, _ = reference.keepout_process(np.asarray(cm.cost[i]), np.asarray(cm.origin[i]), 0.05, datas[i],
                                            ORIGIN, 0.05, (0, 0, 24, 24), is_pose_lethal=bool(lethal[i]),
                                            override=True, override_cost=cfg.lethal_override_cost)
        np.testing.assert_array_equal(np.asarray(new_cm.cost[i]), want)
  assert decided >= 5 * B - 1
  assert 5 < lethal_count < 5 * B - 5


def test_footprint_catches_what_the_centre_test_misses_and_keeps_nav2_default():
  """A robot whose centre is beside a zone and whose footprint is in it: Nav2 says out, footprint says in."""
  data = np.zeros((HM, WM), np.int8)
  data[:, 8:] = 100                                  # zone: x >= 0.0
  mask, _, _ = _fleet(0, datas=[data] * B)
  y = ORIGIN[1] + 6.5 * 0.05                         # on a row of cell centres
  poses = np.float32([[-0.1, y, 0.0], [-0.25, y, 0.0], [0.1, y, 1.0]] + [[-0.25, y, 0.0]] * (B - 3))
  cm = jf.Costmap.create(np.zeros((B, 24, 24), np.uint8), np.tile(np.float32([-0.6, 0.0]), (B, 1)), 0.05)
  nav2 = jf.KeepoutConfig(override_lethal_cost=True, lethal_override_cost=200)
  foot = _config("disc")
  foot = dataclasses.replace(foot, robot_radius=0.22)
  got = {}
  for label, cfg in (("nav2", nav2), ("foot", foot)):
    out, st = _cycle(cm, mask, poses, jf.KeepoutState.create(B), cfg)
    got[label] = (np.asarray(st.is_pose_lethal)[:3].tolist(), np.asarray(out.cost)[:3, 12, 18].tolist())
  # Robot 0: centre 0.1 m from the zone (r 0.22): only the footprint test sees it; robot 1: 0.25 m, out;
  # robot 2: centre inside, both. The zone (cell (18, 12) = (0.325, 0.625)) is written 200 (escape) or 254.
  assert got["nav2"] == ([False, False, True], [254, 254, 200])
  assert got["foot"] == ([True, False, True], [200, 254, 200])
  assert jf.KeepoutConfig() == jf.KeepoutConfig(robot_in_zone="center") and jf.KeepoutConfig().footprint_window == 0


def test_hysteresis_escape_lasts_until_grown_footprint_is_clear():
  """A robot driving out of a zone along +x: escape ends at r + clearance, not at r."""
  data = np.zeros((20, 40), np.int8)
  data[:, :10] = 100                                          # zone: x < 0.5
  mask = jf.FilterMask.create(jf.OccupancyGrid.create(data, 0.05, (0.0, 0.0)), KEEPOUT)
  cfg = jf.KeepoutConfig(override_lethal_cost=True, robot_in_zone="footprint", robot_radius=0.2,
                         min_mask_resolution=0.05, escape_clearance=0.1)
  xs = np.arange(0.3, 1.2, 0.01, dtype=np.float32)
  cm = jf.Costmap.create(np.zeros((1, 20, 40), np.uint8), np.zeros((1, 2)), 0.05)
  st = jf.KeepoutState.create(1)
  on = []
  for x in xs:            # y on a row of centres: the nearest zone centre is straight ahead
    st, _ = jf.keepout_update_bounds(cm, mask, np.float32([[x, 0.475, 0.3]]), st, np.float32([[-2, -2, 2, 2]]), config=cfg)
    on.append(bool(st.is_pose_lethal[0]))
  last_centre = 0.475                          # the last zone centre column: x = 0.475
  off = xs[np.argmin(on)]
  assert all(on[:int(np.argmin(on))]) and not any(on[int(np.argmin(on)):])
  assert last_centre + 0.3 < off <= last_centre + 0.3 + 0.0101     # r + clearance, to the 1 cm step
  # Driving back in from outside switches it on at r (not r + clearance).
  on_back = []
  for x in xs[::-1]:
    st, _ = jf.keepout_update_bounds(cm, mask, np.float32([[x, 0.475, 0.3]]), st, np.float32([[-2, -2, 2, 2]]), config=cfg)
    on_back.append(bool(st.is_pose_lethal[0]))
  first = xs[::-1][int(np.argmax(on_back))]
  assert last_centre + 0.2 - 0.0101 <= first <= last_centre + 0.2


def test_transform_rotates_the_footprint_into_the_mask_frame():
  """A rectangle 0.7 m long: whether its nose reaches a zone depends on the yaw in the mask frame."""
  data = np.zeros((20, 20), np.int8)
  data[:, 14:] = 100                                          # zone: x >= 0.7 in the mask frame
  mask = jf.FilterMask.create(jf.OccupancyGrid.create(data, 0.05, (0.0, 0.0)), KEEPOUT)
  cfg = jf.KeepoutConfig(override_lethal_cost=True, robot_in_zone="footprint", min_mask_resolution=0.05,
                         footprint=((0.4, 0.05), (-0.1, 0.05), (-0.1, -0.05), (0.4, -0.05)))
  cm = jf.Costmap.create(np.zeros((2, 20, 20), np.uint8), np.zeros((2, 2)), 0.05)
  # T_mask_from_global rotates by +pi/2: global (0.5, 0) heading -pi/2 is mask (0, 0.5) heading 0, its nose
  # at x = 0.4 (out); global (0.5, -0.35) is mask (0.35, 0.5), its nose at 0.75 over the zone's first centre.
  poses = np.float32([[0.5, 0.0, -np.pi / 2], [0.5, -0.35, -np.pi / 2]])
  tf = np.float32([0.0, 0.0, np.pi / 2])
  st, _ = jf.keepout_update_bounds(cm, mask, poses, jf.KeepoutState.create(2), _bounds()[:2], transform=tf, config=cfg)
  got = np.asarray(st.is_pose_lethal).tolist()
  for i, p in enumerate(poses):
    c, s = math.cos(float(tf[2])), math.sin(float(tf[2]))
    x, y = c * p[0] - s * p[1] + tf[0], s * p[0] + c * p[1] + tf[1]
    want = reference.footprint_in_zone(data, (0.0, 0.0), 0.05, (x, y, p[2] + tf[2]), eps=EPS, **_shape(cfg))
    assert want[0] == want[1] == got[i]
  assert got == [False, True]


# ----------------------------------------------------------------------------- jit, recompiles, errors


def test_moved_zones_compile_nothing():
  cfg = _config("rect")
  mask, poses, _ = _fleet(11)
  cm = _costmaps(poses, np.random.default_rng(0))
  jax.block_until_ready(_cycle(cm, mask, poses, jf.KeepoutState.create(B), cfg))
  moved = mask.with_data(np.roll(np.asarray(mask.data), 3, axis=2))      # every zone 3 cells to the right
  with count_compiles() as compiles:
    _, st2 = _cycle(cm, moved, poses, jf.KeepoutState.create(B), cfg)
  assert compiles() == 0
  datas = np.asarray(moved.data)
  for i in range(B):
    case = dict(data=datas[i], origin=ORIGIN, res=np.float32(0.05), pose=poses[i])
    centre = reference.centre_in_zone(datas[i], ORIGIN, 0.05, poses[i, 0], poses[i, 1])
    s, p = _ref(case, cfg, 0.0)
    _check(bool(st2.is_pose_lethal[i]), (centre or s, centre or p))


def test_mask_finer_than_min_resolution_raises_eagerly_and_flags_under_jit():
  cfg = _config("disc", min_res=0.1)
  mask, poses, _ = _fleet(2, res=0.05)
  ok_mask, _, _ = _fleet(2, res=0.1)
  cm = _costmaps(poses, np.random.default_rng(0))
  with pytest.raises(ValueError, match="finer than KeepoutConfig.min_mask_resolution = 0.1"):
    jf.keepout_update_bounds(cm, mask, poses, jf.KeepoutState.create(B), _bounds(), mask_index=np.arange(B),
                             config=cfg)
  # Under jit (a traced mask) the robots are flagged; the pipeline keeps updateBounds' flag past
  # process(), which sets its own (mask_index).
  lcfg = jf.LayersConfig(keepout=cfg, keepout_as_layer=True)

  @jax.jit
  def pipe(mask):
    return jf.costmap_pipeline(np.zeros((B, 24, 24), np.int8), poses[:, :2] - 0.6, 0.05, poses, config=lcfg,
                               keepout_mask=mask, keepout_state=jf.KeepoutState.create(B),
                               mask_index=jnp.arange(B)).keepout_state.error
  assert np.asarray(pipe(mask)).all() and not np.asarray(pipe(ok_mask)).any()


@pytest.mark.parametrize("kwargs, match", [
    (dict(robot_in_zone="polygon"), r"robot_in_zone must be one of \('center', 'footprint'\); got 'polygon'"),
    (dict(robot_radius=0.2), "only apply with robot_in_zone='footprint'"),
    (dict(escape_clearance=0.1), "only apply with robot_in_zone='footprint'"),
    (dict(robot_in_zone="footprint", override_lethal_cost=False, robot_radius=0.2, min_mask_resolution=0.05),
     "set override_lethal_cost=True"),
    (dict(robot_in_zone="footprint", min_mask_resolution=0.05), "exactly one of footprint"),
    (dict(robot_in_zone="footprint", robot_radius=0.2, footprint=((0, 0), (1, 0), (0, 1)),
          min_mask_resolution=0.05), "exactly one of footprint"),
    (dict(robot_in_zone="footprint", robot_radius=0.2), "needs min_mask_resolution"),
    (dict(robot_in_zone="footprint", robot_radius=0.0, min_mask_resolution=0.05), "robot_radius must be > 0"),
    (dict(robot_in_zone="footprint", robot_radius=float("nan"), min_mask_resolution=0.05), "must be finite"),
    (dict(robot_in_zone="footprint", robot_radius=1e39, min_mask_resolution=0.05), "must fit float32"),
    (dict(robot_in_zone="footprint", robot_radius=0.2, min_mask_resolution=1e-45), "at least 1.175e-38"),
    (dict(robot_in_zone="footprint", robot_radius=0.2, min_mask_resolution=0.05, escape_clearance=-0.1),
     "escape_clearance must be >= 0"),
    (dict(robot_in_zone="footprint", footprint=((0, 0), (1, 0)), min_mask_resolution=0.05), "at least 3 vertices"),
    (dict(robot_in_zone="footprint", footprint=((0, 0), (1, 1), (2, 2)), min_mask_resolution=0.05),
     "must enclose an area"),
    (dict(robot_in_zone="footprint", footprint=((0, 0, 0), (1, 0, 0), (0, 1, 0)), min_mask_resolution=0.05),
     r"sequence of \(x, y\) vertices"),
    (dict(robot_in_zone="footprint", footprint=((0, 0), (1, float("inf")), (0, 1)), min_mask_resolution=0.05),
     "must be finite"),
    (dict(robot_in_zone="footprint", robot_radius=5.0, min_mask_resolution=0.05), "at most 64"),
])
def test_config_validation(kwargs, match):
  kwargs = {"override_lethal_cost": True, **kwargs}
  with pytest.raises(ValueError, match=match):
    jf.KeepoutConfig(**kwargs)


def test_config_normalises_and_hashes():
  a = jf.KeepoutConfig(override_lethal_cost=True, robot_in_zone="footprint", min_mask_resolution=0.05,
                       footprint=[[0.3, 0.2], [-0.3, 0.2], [-0.3, -0.2], [0.3, -0.2]])
  b = jf.KeepoutConfig(override_lethal_cost=True, robot_in_zone="footprint", min_mask_resolution=0.05,
                       footprint=np.array([[0.3, 0.2], [-0.3, 0.2], [-0.3, -0.2], [0.3, -0.2]]))
  assert a == b and hash(a) == hash(b) and isinstance(a.footprint, tuple)
  assert a.footprint[0] == (float(np.float32(0.3)), float(np.float32(0.2)))       # float32 values, as used
  assert a.footprint_window == math.ceil(math.hypot(0.3, 0.2) / 0.05) + 2


# ----------------------------------------------------------------------------- as a layer before inflation


def _layer_case(pose_x):
  """A 2 m x 1 m local map (0.05 m cells), zone x >= 1.0; one robot at (pose_x, 0.5)."""
  occ = np.zeros((1, 20, 40), np.int8)
  data = np.zeros((20, 40), np.int8)
  data[:, 20:] = 100
  mask = jf.FilterMask.create(jf.OccupancyGrid.create(data, 0.05, (0.0, 0.0)), KEEPOUT)
  return occ, mask, np.float32([[pose_x, 0.5, 0.0]])


def test_as_layer_escape_has_no_band_and_band_clearance_releases_outside_it():
  infl = jf.InflationConfig.from_footprint(resolution=0.05, robot_radius=0.22, footprint_padding=0.01,
                                           inflation_radius=0.55, cost_scaling_factor=3.0)
  clear = fp.band_clearance(inscribed_radius=infl.inscribed_radius, resolution=0.05, robot_radius=0.22)
  centre = jf.KeepoutConfig(override_lethal_cost=True)
  foot = jf.KeepoutConfig(override_lethal_cost=True, robot_in_zone="footprint", robot_radius=0.22,
                          min_mask_resolution=0.05, escape_clearance=clear)

  def cycle(x, cfg, state):
    occ, mask, poses = _layer_case(x)
    out = jf.costmap_pipeline(occ, np.zeros((1, 2)), 0.05, poses, config=jf.LayersConfig(
        inflation=infl, keepout=cfg, keepout_as_layer=True), keepout_mask=mask, keepout_state=state)
    col = int(x / 0.05)
    return out.keepout_state, np.asarray(out.combined.cost[0]), int(out.combined.cost[0, 10, col])

  # Escaping (centre inside): the zone is 252 and is not inflated, whatever the test.
  for cfg in (centre, foot):
    st, cost, _ = cycle(1.3, cfg, jf.KeepoutState.create(1))
    assert bool(st.is_pose_lethal[0]) and (cost[:, 20:] == 252).all() and cost[:, :20].max() == 0
  # Driving out along -x in 3 cm steps (a cycle per step), as a controller would while the robot's
  # centre cell is below 253. Nav2's centre test ends escape as the centre leaves the zone: its cell is
  # then in the inscribed band (the trap of #6505). The footprint test with band_clearance never does.
  for cfg, trapped in ((centre, True), (foot, False)):
    st = jf.KeepoutState.create(1)
    stuck_at = None
    for x in np.arange(1.3, 0.3, -0.03, dtype=np.float32):
      st, cost, here = cycle(float(x), cfg, st)
      if here >= 253:
        stuck_at = float(x)
        break
    assert (stuck_at is not None) == trapped, (cfg.robot_in_zone, stuck_at)
    if trapped:
      assert 0.95 <= stuck_at < 1.0                              # just out of the zone, in its band
  # Once released, the zone is lethal and inflated again.
  assert not bool(st.is_pose_lethal[0]) and (cost[:, 20:] == 254).all() and cost[10, 19] == 253


def test_band_clearance_leaves_the_centre_cell_out_of_the_band():
  """Random disc and polygon robots released by the grown-footprint test: their cell is below 253."""
  rng = np.random.default_rng(5)
  for radius, poly in ((0.22, None), (None, ((0.3, 0.2), (-0.2, 0.2), (-0.2, -0.2), (0.3, -0.2)))):
    infl = jf.InflationConfig.from_footprint(resolution=0.05, robot_radius=radius, footprint=poly,
                                             footprint_padding=0.01, inflation_radius=0.55, cost_scaling_factor=3.0)
    clear = fp.band_clearance(inscribed_radius=infl.inscribed_radius, resolution=0.05, robot_radius=radius,
                              footprint=poly)
    data = np.zeros((40, 40), np.int8)
    data[15:25, 15:25] = 100
    cost = np.asarray(jf.inflate(jnp.asarray(np.where(data == 100, 254, 0).astype(np.uint8))[None], config=infl))[0]
    released = 0
    for _ in range(400):
      pose = np.float32([rng.uniform(0, 2), rng.uniform(0, 2), rng.uniform(-np.pi, np.pi)])
      s, p = reference.footprint_in_zone(data, (0.0, 0.0), 0.05, pose, polygon=poly, radius=radius, margin=clear)
      if not p:
        released += 1
        assert cost[int(pose[1] / 0.05), int(pose[0] / 0.05)] < 253, pose
    assert released > 100


def test_band_clearance_needs_the_origin_inside_the_footprint():
  with pytest.raises(ValueError, match="must contain the robot origin"):
    fp.band_clearance(inscribed_radius=0.3, resolution=0.05, footprint=((0.1, 0.1), (0.5, 0.1), (0.5, 0.4)))
  with pytest.raises(ValueError, match="must contain the robot origin"):       # the origin on an edge
    fp.band_clearance(inscribed_radius=0.3, resolution=0.05, footprint=((0.0, -0.2), (0.4, -0.2), (0.4, 0.2),
                                                                          (0.0, 0.2)))
  got = fp.band_clearance(inscribed_radius=0.3, resolution=0.05, footprint=((0.3, 0.2), (-0.2, 0.2), (-0.2, -0.2),
                                                                              (0.3, -0.2)))
  assert got == pytest.approx(0.3 - 0.2 + 0.05 * math.sqrt(0.5) + 1e-3)
