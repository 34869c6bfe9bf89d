"""keepout/host_exact.py: the exact same-frame path in integer arithmetic on the host equals the device's.

An eager call on a CPU redoes the few robots its fast path leaves open with `host_exact.redo` (no
compile) instead of the device's exact path. Here both run on the adversarial fleets of
test_keepout_prologue.py (centres exactly on mask-cell edges and one ulp off, a double 0.05 against
the float32 0.05, float32 parts, windows partly off the mask, finer and coarser masks, narrow
windows), in plain and escape mode under both unknown-cell rules, with disabled robots, unusable
geometry and out-of-range mask indices; the costs and every state leaf must be equal. Then an eager
call with open robots takes the host redo and gives the jitted call's integers.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfilters as jf
from jaxfilters import keepout as ko
from jaxfilters.keepout import common, host_exact, process
from tests.jaxfilters.test_keepout_prologue import B, CASES
from tests.keepout_fleets import fleet_with_lower_parts

CONFIGS = {"plain": ko.KeepoutConfig(),
           "escape_any": ko.KeepoutConfig(override_lethal_cost=True, lethal_override_cost=77, unknown_overwrite="any"),
           "escape": ko.KeepoutConfig(override_lethal_cost=True, lethal_override_cost=77)}


def _take(tree, rows):
  return jax.tree.map(lambda x: np.asarray(x)[rows], tree)


def _batched(name):
  cm, mask, state, window, mask_index, enabled = dict(CASES)[name]
  idx, ok, _, en, win, tf = common.batched_inputs(cm, mask, jnp.zeros((B, 3)), mask_index, enabled, window, None, "t")
  return cm, mask, common.fill_error(state, B), idx, ok, win, en


def _assert_equal(got, want, msg):
  (g_cm, g_st), (w_cm, w_st) = got, want
  np.testing.assert_array_equal(np.asarray(g_cm.cost), np.asarray(w_cm.cost), err_msg=msg)
  for field in ("is_pose_lethal", "last_pose_lethal", "acc_box", "error"):
    np.testing.assert_array_equal(np.asarray(getattr(g_st, field)), np.asarray(getattr(w_st, field)),
                                  err_msg=f"{msg}: {field}")


@pytest.mark.parametrize("config", CONFIGS, ids=list(CONFIGS))
@pytest.mark.parametrize("name", [c[0] for c in CASES])
def test_host_redo_equals_the_device_exact_path(name, config):
  cfg = CONFIGS[config]
  cm, mask, state, idx, ok, win, en = _batched(name)
  rows = np.arange(B)
  if name == "huge":
    rows[B - 2:] = (0, 1)         # robots B-2, B-1 sit at 3e7 and 1e12 m (past the exact floors' 2^22
                                  # cells): robots 0 and 1 again, so that every fleet compiles one program
  sub = _take((cm, idx, ok, state, win, en), rows)
  want = process.filter_batch(*sub[:1], mask, *sub[1:3], sub[3], sub[4], sub[5], None, config=cfg, exact=True)
  got = host_exact.redo(*sub, None, mask=mask, config=cfg)
  assert got is not None
  _assert_equal(got, want, f"{name} {config}")
  assert (np.asarray(got[0].cost) != np.asarray(sub[0].cost)).any() or name == "huge"


def test_centres_exactly_on_the_mask_origin_and_one_ulp_below():
  """Column and row centres exactly on the mask's origin (a zero numerator: worldToMap's wx >= origin)
  and one ulp below it."""
  rng = np.random.default_rng(7)
  origins = np.full((B, 2), -0.125)
  origins[1::2] = np.nextafter(np.float32(-0.125), np.float32(-1)), -0.125
  fleet = fleet_with_lower_parts(rng, 0.25, 0.25, origins, [(0.0, 0.0), (0.0, 0.0)], b=B,
                                 windows=np.tile([0, 0, 16, 12], (B, 1)))
  cm, mask, state, window, mask_index, enabled = fleet
  idx, ok, _, en, win, _ = common.batched_inputs(cm, mask, jnp.zeros((B, 3)), mask_index, enabled, window, None, "t")
  sub = _take((cm, idx, ok, common.fill_error(state, B), win, en), np.arange(B))
  want = process.filter_batch(sub[0], mask, *sub[1:6], None, config=ko.KeepoutConfig(), exact=True)
  _assert_equal(host_exact.redo(*sub, None, mask=mask, config=ko.KeepoutConfig()), want, "origin edge")


def test_the_device_scatter_equals_the_numpy_one():
  x = jnp.arange(60, dtype=jnp.int32).reshape(15, 4)
  rows = np.asarray([2, 11, 3])
  sel = np.concatenate([rows, np.full(5, rows[0])])
  v = np.arange(12, dtype=np.int32).reshape(3, 4) + 100
  host, device = process.put_rows(x, v, rows, sel, True), process.put_rows(x, v, rows, sel, False)
  np.testing.assert_array_equal(np.asarray(host), np.asarray(device))
  assert (np.asarray(device)[rows] == v).all() and (np.asarray(device)[[0, 1, 4]] == np.asarray(x)[[0, 1, 4]]).all()


def test_robots_past_the_exact_floors_range_go_back_to_the_device():
  cm, mask, state, idx, ok, win, en = _batched("huge")
  assert host_exact.redo(*_take((cm, idx, ok, state, win, en), [B - 1]), None, mask=mask,
                         config=ko.KeepoutConfig()) is None
  assert host_exact.redo(cm, idx, ok, state, win, en, jnp.zeros((B, 3)), mask=mask, config=ko.KeepoutConfig()) is None


def test_unusable_geometry_and_bad_indices_are_left_untouched_and_flagged():
  """As the device path (common.usable_geometry): NaN, zero and subnormal resolutions, a non-finite
  origin part, an index flagged out of range; robots beside them are processed."""
  cm, mask, state, idx, ok, win, en = _batched("double_0.05")
  res = np.asarray(cm.resolution).copy()
  res[1], res[2], res[3] = np.nan, 0.0, 1e-40
  origin_lo = np.asarray(cm.origin_lo).copy()
  origin_lo[4, 0, 1] = np.inf
  cm = dataclasses.replace(cm, resolution=jnp.asarray(res, jnp.float32), origin_lo=jnp.asarray(origin_lo))
  ok = np.asarray(ok).copy()
  ok[5] = False
  en = np.ones(B, bool)
  sub = _take((cm, idx, ok, state, win, en), np.arange(B))
  want = process.filter_batch(sub[0], mask, *sub[1:6], None, config=ko.KeepoutConfig(), exact=True)
  got = host_exact.redo(*sub, None, mask=mask, config=ko.KeepoutConfig())
  _assert_equal(got, want, "unusable")
  assert np.asarray(got[1].error).tolist() == [False, True, True, True, True, True, False, False]


@pytest.mark.parametrize("host_memory", [True, False], ids=["cpu_rows", "device_rows"])
def test_an_eager_call_redoes_its_open_robots_on_the_host_with_the_jitted_integers(host_memory, monkeypatch):
  """64 robots, some with centres on mask-cell edges (open brackets): the eager call's host redo
  runs (the device's exact program is not called) and gives the jitted call's costs and state, with
  the rows moved through NumPy (a CPU) or gathered and scattered on the device (other backends)."""
  monkeypatch.setattr(process, "_cpu_backend", lambda: host_memory)
  rng = np.random.default_rng(4)
  data = rng.choice([-1, 0, 30, 60, 100, 100], (80, 90)).astype(np.int8)
  mask = jf.FilterMask.create(jf.OccupancyGrid.create(data, 0.25, (0.0, 0.0)), jf.FilterInfo.create(0))
  b = 64
  k = rng.integers(-10, 80, (b, 2))
  origin = (k + rng.uniform(0.1, 0.9, (b, 2))) * 0.25
  origin[:6] = (k[:6] + 0.5) * 0.25                 # cell centres exactly on mask-cell edges
  cm = jf.Costmap.create(rng.choice([0, 10, 200, 254, 255], (b, 12, 16)).astype(np.uint8), origin, 0.25)
  poses = np.concatenate([origin + 1.0, np.zeros((b, 1))], 1).astype(np.float32)
  state = jf.KeepoutState.create(b)
  calls = []
  monkeypatch.setattr(process, "exact_redo", lambda *a, **k: calls.append(1))
  redo = host_exact.redo
  monkeypatch.setattr(host_exact, "redo", lambda *a, **k: calls.append("host") or redo(*a, **k))
  got = jf.keepout_filter(cm, mask, poses, state)
  assert calls == ["host"]
  want = jax.jit(jf.keepout_filter)(cm, mask, poses, state)
  np.testing.assert_array_equal(np.asarray(got[0].cost), np.asarray(want[0].cost))
  np.testing.assert_array_equal(np.asarray(got[1].last_pose_lethal), np.asarray(want[1].last_pose_lethal))
  np.testing.assert_array_equal(np.asarray(got[1].error), np.asarray(want[1].error))
