"""KeepoutFilter against the float64 reference, the worked examples of docs/nav2_semantics.md, run four ways."""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfilters import keepout as ko
from jaxfilters.grid import OccupancyGrid
from jaxfilters.types import Costmap, FilterInfo, FilterMask
from reference import nav2 as reference
from tests.compile_count import count_compiles

KEEPOUT = FilterInfo.create(0)


def _mask(data, res, origin):
  return FilterMask.create(OccupancyGrid.create(np.asarray(data), res, origin), KEEPOUT)


def _case(seed, *, coarse=False, fine=False, transform=False):
  """A random keepout case: master costs, mask, window, geometry (float32 values)."""
  rng = np.random.default_rng(seed)
  h, w = 18, 22      # fixed shapes: one compile serves the whole table
  hm, wm = 14, 10
  res = np.float32(rng.choice([0.05, 0.1, 0.03, 1.0]))
  mres = np.float32(res * (2 if coarse else 0.5 if fine else 1))
  origin = np.float32(rng.uniform(-50, 50, 2))
  shift = rng.integers(-6, 6, 2) * res + (rng.uniform(0, 1, 2) * res if rng.random() < 0.5 else 0)
  morigin = np.float32(origin + shift)
  cost = rng.choice([0, 0, 10, 100, 200, 252, 253, 254, 255], (h, w)).astype(np.uint8)
  data = rng.choice([-1, 0, 0, 1, 25, 50, 75, 99, 100, 100], (hm, wm)).astype(np.int8)
  x0, y0 = rng.integers(-2, w // 2), rng.integers(-2, h // 2)
  window = np.array([x0, y0, rng.integers(x0 + 1, w + 3), rng.integers(y0 + 1, h + 3)], np.int32)
  tf = np.float32([rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-np.pi, np.pi)]) if transform else None
  return dict(cost=cost, origin=origin, res=res, data=data, morigin=morigin, mres=mres, window=window, tf=tf)


def _ref(c, **kw):
  win = np.clip(c["window"], 0, [c["cost"].shape[1], c["cost"].shape[0]] * 2)
  return reference.keepout_process(c["cost"], c["origin"], c["res"], c["data"], c["morigin"], c["mres"], win,
                                   transform=c["tf"], **kw)[0]


def _kernel(*args, tf, config):
  return ko.keepout_one(*args, tf, config=config)


_jitted = jax.jit(_kernel, static_argnames="config")


def _run_one(c, jit=False, config=ko.KeepoutConfig(), lethal=False):
  state = jax.tree.map(lambda x: x[0], ko.KeepoutState.create(1))
  state = ko.KeepoutState(jnp.asarray(lethal), state.last_pose_lethal, state.acc_box)
  win = np.clip(c["window"], 0, [c["cost"].shape[1], c["cost"].shape[0]] * 2).astype(np.int32)
  tf = None if c["tf"] is None else jnp.asarray(c["tf"])
  f = functools.partial(_jitted if jit else _kernel, tf=tf, config=config)
  cost, _ = f(jnp.asarray(c["cost"]), jnp.asarray(c["origin"]), jnp.float32(c["res"]), jnp.asarray(c["data"]),
              jnp.asarray(c["morigin"]), jnp.float32(c["mres"]), state, jnp.asarray(win), jnp.asarray(True))
  return np.asarray(cost)


SAME_FRAME_CASES = ([dict(seed=s) for s in range(12)] + [dict(seed=s, coarse=True) for s in range(12, 20)]
                    + [dict(seed=s, fine=True) for s in range(20, 28)])


@pytest.mark.parametrize("kw", SAME_FRAME_CASES)
def test_same_frame_matches_reference_under_jit(kw):
  c = _case(**kw)
  np.testing.assert_array_equal(_run_one(c, jit=True), _ref(c))


@pytest.mark.parametrize("kw", SAME_FRAME_CASES[::8])
def test_same_frame_matches_reference_eager(kw):
  c = _case(**kw)
  np.testing.assert_array_equal(_run_one(c, jit=False), _ref(c))


@pytest.mark.parametrize("seed", range(6))
def test_override_mode_writes_override_cost(seed):
  c = _case(seed)
  cfg = ko.KeepoutConfig(override_lethal_cost=True, lethal_override_cost=200)
  got = _run_one(c, jit=True, config=cfg, lethal=True)
  np.testing.assert_array_equal(got, _ref(c, is_pose_lethal=True, override=True, override_cost=200))


def test_vmap_of_kernel_equals_python_loop_and_public_batch():
  cases = [_case(s) for s in range(100, 108)]
  # One geometry per robot but a shared mask shape: use a stack of masks with an index.
  hm, wm = 14, 10
  rng = np.random.default_rng(7)
  for c in cases:
    c["data"] = rng.choice([-1, 0, 50, 100], (hm, wm)).astype(np.int8)
    c["window"] = np.array([0, 0, 22, 18], np.int32)
  grids = [OccupancyGrid.create(c["data"], float(c["mres"]), tuple(c["morigin"])) for c in cases]
  mask = FilterMask.create(grids, KEEPOUT)
  cm = Costmap.create(np.stack([c["cost"] for c in cases]), np.stack([c["origin"] for c in cases]),
                      np.array([c["res"] for c in cases]))
  out, _ = ko.keepout_filter(cm, mask, np.zeros((8, 3), np.float32), ko.KeepoutState.create(8),
                             mask_index=np.arange(8))
  loop = np.stack([_run_one(c, jit=True) for c in cases])
  refs = np.stack([_ref(c) for c in cases])
  np.testing.assert_array_equal(np.asarray(out.cost), loop)
  np.testing.assert_array_equal(loop, refs)


@pytest.mark.parametrize("seed", range(8))
def test_different_frames_match_reference_away_from_float_ties(seed):
  c = _case(seed, transform=True)
  got = _run_one(c, jit=True)
  want = _ref(c)
  # Nav2 rotates cell centres in float64, we in float32 (documented): exclude master
  # cells whose rotated centre lies within 1e-4 m of a mask cell edge in float64.
  h, w = c["cost"].shape
  tx, ty, yaw = (float(v) for v in c["tf"])
  near = np.zeros((h, w), bool)
  for j in range(h):
    for i in range(w):
      x = float(c["origin"][0]) + (i + 0.5) * float(c["res"])
      y = float(c["origin"][1]) + (j + 0.5) * float(c["res"])
      px = math.cos(yaw) * x - math.sin(yaw) * y + tx - float(c["morigin"][0])
      py = math.sin(yaw) * x + math.cos(yaw) * y + ty - float(c["morigin"][1])
      fx, fy = px / float(c["mres"]), py / float(c["mres"])
      near[j, i] = min(abs(fx - round(fx)), abs(fy - round(fy))) * float(c["mres"]) < 1e-4
  assert near.mean() < 0.05
  np.testing.assert_array_equal(got[~near], want[~near])


def test_spec_worked_example_windows():
  mask = _mask(np.full((3, 3), 100), 1.0, (3, 3))
  cm = Costmap.create(np.zeros((1, 10, 10), np.uint8), (0, 0), 1.0)
  table = {(2, 2, 5, 5): {(3, 3), (3, 4), (4, 3), (4, 4)}, (3, 6, 5, 7): set(), (6, 3, 7, 5): set(),
           (5, 5, 6, 6): {(5, 5)}, (0, 0, 2, 2): set(), (0, 7, 2, 9): set(), (7, 0, 9, 2): set(),
           (7, 7, 9, 9): set()}
  for win, cells in table.items():
    out, _ = ko.keepout_filter(cm, mask, np.zeros((1, 3)), ko.KeepoutState.create(1), window=np.array([win]))
    got = {(int(i), int(j)) for j, i in np.argwhere(np.asarray(out.cost[0]) == 254)}
    assert got == cells, win


def test_spec_different_frames_example():
  mask = _mask(np.full((3, 3), 100), 1.0, (3, 3))
  cm = Costmap.create(np.zeros((1, 10, 10), np.uint8), (0, 0), 1.0)
  out, _ = ko.keepout_filter(cm, mask, np.zeros((1, 3)), ko.KeepoutState.create(1),
                             window=np.array([2, 2, 5, 5]), transform=np.array([1.0, 1.0, 0.0]))
  got = {(int(i), int(j)) for j, i in np.argwhere(np.asarray(out.cost[0]) == 254)}
  assert got == {(i, j) for i in range(2, 5) for j in range(2, 5)}


def test_coarse_mask_loses_first_column_and_row():
  # The quirk of docs/nav2_semantics.md §4.3 with binary-exact sizes: master 1/16 m at (0,0), mask 1/8 m at (1,1),
  # 10x10. gx0 = int((1 + 1/16) / (1/16)) = 17, but master cell 16 (centre 1.03125) lies in
  # the mask and is never visited. (With the documented decimal 0.05/0.1 the float32 values
  # give gx0 = 20 where Nav2's float64 0.05 gives 21: the float32 policy, jaxfilters/geometry/.)
  mask = _mask(np.full((10, 10), 100), 0.125, (1, 1))
  cm = Costmap.create(np.zeros((1, 48, 48), np.uint8), (0, 0), 0.0625)
  out, _ = ko.keepout_filter(cm, mask, np.zeros((1, 3)), ko.KeepoutState.create(1))
  cols = np.nonzero(np.asarray(out.cost[0]).max(axis=0) == 254)[0]
  rows = np.nonzero(np.asarray(out.cost[0]).max(axis=1) == 254)[0]
  assert cols.tolist() == list(range(17, 36)) and rows.tolist() == list(range(17, 36))
  ref, _ = reference.keepout_process(np.zeros((48, 48), np.uint8), (0, 0), 0.0625, np.full((10, 10), 100),
                                     (1, 1), 0.125, (0, 0, 48, 48))
  np.testing.assert_array_equal(np.asarray(out.cost[0]), ref)


def test_occ_to_cost_table_and_rounding_ties():
  d = np.arange(-3, 128, dtype=np.int64)
  got = np.asarray(ko.occ_to_cost(jnp.asarray(d.astype(np.int8))))
  want = np.array([reference.mask_cost(v) for v in d])
  np.testing.assert_array_equal(got, want)
  assert got[d == 25][0] == 64 and got[d == 75][0] == 191 and 253 not in got


@pytest.mark.parametrize("rule, want", [("inscribed", [255, 255, 255, 100]), ("any", [127, 255, 0, 100])])
def test_write_rule_unknown_master_and_unknown_mask(rule, want):
  # Nav2 main (#6329, the default "inscribed"): an unknown master cell takes only a mask cost >= 253,
  # so mask 50 (cost 127) and mask 0 leave it unknown. Before #6329 ("any", Nav2's old
  # testUnknownMasterNonLethalKeepout): master 255, mask 50 -> 127 and mask 0 over unknown -> 0.
  # Both: an unknown mask cell never writes; a lower mask cost never lowers a cell.
  mask = _mask(np.array([[50, -1, 0, 10]]), 1.0, (0, 0))
  cm = Costmap.create(np.array([[[255, 255, 255, 100]]], np.uint8), (0, 0), 1.0)
  out, _ = ko.keepout_filter(cm, mask, np.zeros((1, 3)), ko.KeepoutState.create(1),
                             config=ko.KeepoutConfig(unknown_overwrite=rule))
  assert np.asarray(out.cost[0, 0]).tolist() == want


def test_lanes_give_graded_costs():
  # A lane mask: graded values 1..99 across the lane give round(2.54 d) costs on free space.
  values = np.array([[0, 10, 30, 60, 90, 99, 30, 0]], np.int8)
  mask = _mask(np.repeat(values, 4, axis=0), 0.1, (0, 0))
  cm = Costmap.create(np.zeros((1, 4, 8), np.uint8), (0, 0), 0.1)
  out, _ = ko.keepout_filter(cm, mask, np.zeros((1, 3)), ko.KeepoutState.create(1))
  assert np.asarray(out.cost[0, 2]).tolist() == [0, 25, 76, 152, 229, 251, 76, 0]


def test_disabled_robot_passes_through_and_toggle_needs_no_recompile():
  mask = _mask(np.full((3, 3), 100), 1.0, (3, 3))
  cm = Costmap.create(np.zeros((2, 10, 10), np.uint8), (0, 0), 1.0)
  f = jax.jit(lambda cm, en: ko.keepout_filter(cm, mask, jnp.zeros((2, 3)), ko.KeepoutState.create(2), enabled=en))
  out, _ = f(cm, jnp.array([True, False]))
  assert int(out.cost[0].max()) == 254 and int(out.cost[1].max()) == 0
  with count_compiles() as compiles:
    out, _ = f(cm, jnp.array([False, True]))
  assert int(out.cost[0].max()) == 0 and int(out.cost[1].max()) == 254
  assert compiles() == 0


# One robot's keepout inside a caller's jit (shared by the two tests below: one compile).
_one_robot = jax.jit(lambda cm, m: ko.keepout_filter(cm, m, jnp.zeros((1, 3)), ko.KeepoutState.create(1))[0].cost)


def test_new_mask_contents_compile_nothing():
  mask = _mask(np.full((3, 3), 100), 1.0, (3, 3))
  cm = Costmap.create(np.zeros((1, 10, 10), np.uint8), (0, 0), 1.0)
  f = _one_robot
  a = f(cm, mask)
  mask2 = mask.with_data(np.full((3, 3), 50, np.int8))
  b = f(cm, mask2)
  assert int(a.max()) == 254 and int(b.max()) == 127
  mask3 = mask.with_data(np.full((3, 3), 25, np.int8))
  with count_compiles() as compiles:
    c = f(cm, mask3)
  assert int(c.max()) == 64
  assert compiles() == 0


def test_one_robot_runs_no_exact_path_outside_the_rerun_loop():
  """Inside a caller's jit the robots a fast path leaves open are redone exactly in a loop of as many
  turns as there are such robots (common.rerun): none open, no turn. With one robot, XLA hoisted the
  exact path out of that loop (its inputs, sliced to the whole batch of one, looked loop-invariant),
  so every call ran the exact path's own loops (~90 turns): 400 against 185 us per call on the 2-core
  CPU (BENCHMARKS.md, latency). No loop of the rerun loop's body may sit in the program's entry."""
  mask = _mask(np.full((3, 3), 100), 1.0, (3, 3))
  cm = Costmap.create(np.zeros((1, 10, 10), np.uint8), (0, 0), 1.0)
  text = _one_robot.lower(cm, mask).compile().as_text()
  entry = text[text.index("\nENTRY"):]
  entry = entry[:entry.index("\n}\n")]
  loops = [line for line in entry.splitlines() if " while(" in line]
  hoisted = [line.split(" = ")[0].strip() for line in loops if "/while/body/" in line]
  assert loops and not hoisted, f"{len(hoisted)} loops of the rerun loop's body run at every call: {hoisted}"


def test_update_bounds_escape_mode_sequence():
  """docs/nav2_semantics.md §4.2/§4.6: new-mask cycle skips the check; inside a zone the box grows;
  one more cycle after."""
  mask = _mask(np.pad(np.full((4, 4), 100), 3), 1.0, (0, 0))    # zone cells 3..6
  cm = Costmap.create(np.zeros((1, 10, 10), np.uint8), (0, 0), 1.0)
  cfg = ko.KeepoutConfig(override_lethal_cost=True, lethal_override_cost=200)
  state = ko.KeepoutState.create(1)
  inf = np.float32(np.inf)
  empty = np.array([[inf, inf, -inf, -inf]], np.float32)
  inside = np.array([[4.5, 4.5, 0.0]], np.float32)
  outside = np.array([[1.5, 1.5, 0.0]], np.float32)
  small = np.array([[4.0, 4.0, 5.0, 5.0]], np.float32)

  # 1) new mask: bounds grow to the master centres of (0,0) and (Wm, Hm); check skipped.
  state, b = ko.keepout_update_bounds(cm, mask, inside, state, empty, new_mask=True, config=cfg)
  np.testing.assert_allclose(np.asarray(b), [[0.5, 0.5, 10.5, 10.5]])
  assert not bool(state.is_pose_lethal[0])
  # 2) inside: lethal, box = union(acc, bounds); process writes the override cost.
  state, b = ko.keepout_update_bounds(cm, mask, inside, state, small, config=cfg)
  assert bool(state.is_pose_lethal[0])
  np.testing.assert_allclose(np.asarray(b), small)
  out, state = ko.keepout_filter(cm, mask, inside, state, config=cfg)
  assert int(out.cost[0, 4, 4]) == 200 and bool(state.last_pose_lethal[0])
  # 3) still inside with other bounds: the box grows monotonically.
  state, b = ko.keepout_update_bounds(cm, mask, inside, state, np.array([[6, 6, 8, 8]], np.float32), config=cfg)
  np.testing.assert_allclose(np.asarray(b), [[4, 4, 8, 8]])
  out, state = ko.keepout_filter(cm, mask, inside, state, config=cfg)
  # 4) left the zone: one more cycle with the accumulated box, then reset.
  state, b = ko.keepout_update_bounds(cm, mask, outside, state, np.array([[1, 1, 2, 2]], np.float32), config=cfg)
  assert not bool(state.is_pose_lethal[0])
  np.testing.assert_allclose(np.asarray(b), [[1, 1, 8, 8]])
  out, state = ko.keepout_filter(cm, mask, outside, state, config=cfg)
  assert int(out.cost[0, 4, 4]) == 254
  state, b = ko.keepout_update_bounds(cm, mask, outside, state, np.array([[1, 1, 2, 2]], np.float32), config=cfg)
  np.testing.assert_allclose(np.asarray(b), [[1, 1, 2, 2]])
  assert np.isinf(np.asarray(state.acc_box)).all()


def test_override_cost_is_clamped_and_config_validated():
  assert ko.KeepoutConfig(lethal_override_cost=300).lethal_override_cost == 252
  assert ko.KeepoutConfig(lethal_override_cost=-5).lethal_override_cost == 0
  with pytest.raises(ValueError, match="override_lethal_cost"):
    ko.KeepoutConfig(override_lethal_cost="yes")


def test_bad_inputs_raise_clear_errors():
  mask = _mask(np.full((3, 3), 100), 1.0, (3, 3))
  cm = Costmap.create(np.zeros((2, 10, 10), np.uint8), (0, 0), 1.0)
  st = ko.KeepoutState.create(2)
  with pytest.raises(ValueError, match="poses must be"):
    ko.keepout_filter(cm, mask, np.zeros((3, 3)), st)
  with pytest.raises(ValueError, match="window"):
    ko.keepout_filter(cm, mask, np.zeros((2, 3)), st, window=np.zeros((2, 3), np.int32))
  with pytest.raises(ValueError, match="mask_index"):
    ko.keepout_filter(cm, mask, np.zeros((2, 3)), st, mask_index=np.zeros((3,), np.int32))
  stack = FilterMask.create([OccupancyGrid.create(np.zeros((3, 3), np.int8), 1.0)] * 2, KEEPOUT)
  with pytest.raises(ValueError, match="needs mask_index"):
    ko.keepout_filter(cm, stack, np.zeros((2, 3)), st)
  with pytest.raises(ValueError, match="uint8"):
    Costmap.create(np.zeros((2, 10, 10), np.int32), (0, 0), 1.0)
  with pytest.raises(ValueError, match="resolution"):
    Costmap.create(np.zeros((2, 10, 10), np.uint8), (0, 0), 0.0)
