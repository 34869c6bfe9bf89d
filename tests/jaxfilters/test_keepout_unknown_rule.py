"""The keepout write rule for unknown master cells (docs/nav2_semantics.md §4.4, Nav2 PR #6329).

`KeepoutConfig.unknown_overwrite="inscribed"` (default, Nav2 main): a known mask cost
`data` over a master cell `old` is written when
`data > old || (old == NO_INFORMATION && data >= 253)`; "any" (Nav2 before #6329):
`data > old || old == NO_INFORMATION`. One table costmap holds every old cost (rows
0..255) under every mask value (columns -1..100 and two out-of-range bytes); every
keepout path (exact per-cell, the same-frame slice and gather, both batch loops and
the packed words, a finer mask, the other-frame loop, the Pallas kernels in the
interpreter) must give the closed-form integers and the float64 reference's, for both
rules, in plain and escape mode.

Each fast path runs as an eager call runs it: the program of its `plan.make_plan` plan, which
has no exact reruns in it and reports the robots it leaves open (none here: the table's cell
centres are mid-cell). The program a caller's `jit` compiles (the same kernels, with the exact
reruns of open robots inside) runs for both rules on the two loops; its composition is held to
the exact path on random fleets by test_keepout_paths*.py. The reruns made the file's 34
programs take ~80 s to compile on a 2-core CPU; the plan programs take ~0.5 s each.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfilters import keepout as ko
from jaxfilters.grid import OccupancyGrid
from jaxfilters.keepout import common, packed, plan, process
from jaxfilters.types import Costmap, FilterInfo, FilterMask
from reference import nav2 as reference

KEEPOUT = FilterInfo.create(0)
RES = 0.05
VALUES = np.concatenate([np.arange(-1, 101), [101, -128]]).astype(np.int8)   # 104 columns: packed words
H, W = 256, VALUES.size
OVERRIDE_COST = 77
RULES = ("inscribed", "any")


def _closed_form(old, d, rule, lethal_value):
  """Nav2's rule cell by cell, from the PR's text: int64 arrays."""
  known = (d >= 0) & (d <= 100)
  mc = np.floor(np.clip(d, 0, 100) * 2.54 + 0.5).astype(np.int64)
  unknown_old = old == 255
  if rule == "inscribed":
    unknown_old = unknown_old & (mc >= 253)
  write = known & ((mc > old) | unknown_old)
  return np.where(write, mc if lethal_value is None else lethal_value, old)


def _table(mask_scale=1):
  """Two robots over the table costmap; the mask `mask_scale` (odd) times finer, the table's value
  in the mask cell around each costmap cell centre (mid-cell: no ties) and random values elsewhere."""
  old = np.repeat(np.arange(256, dtype=np.uint8)[:, None], W, axis=1)
  cm = Costmap.create(np.stack([old, old]), np.zeros((2, 2)), RES)
  rng = np.random.default_rng(0)
  data = rng.choice(VALUES, (H * mask_scale, W * mask_scale)).astype(np.int8)
  off = mask_scale // 2
  data[off::mask_scale, off::mask_scale] = np.broadcast_to(VALUES, (H, W))
  grid = OccupancyGrid.create(np.clip(data, -1, 100), RES / mask_scale, (0.0, 0.0))
  mask = FilterMask.create([grid], KEEPOUT).with_data(data[None])
  state = dataclasses.replace(ko.KeepoutState.create(2), is_pose_lethal=jnp.asarray([False, True]))
  return cm, mask, common.fill_error(state, 2), data


def _run(cm, mask, state, config, *, exact=False, loop="auto", transform=None, eager=False):
  """The batch's cost as int64. `eager`: the program an eager call runs (its plan, no exact reruns
  inside), which must leave no robot open on the table."""
  idx, ok, _, en, win, tf = common.batched_inputs(cm, mask, jnp.zeros((2, 3)), None, None, None, transform,
                                                  "test")
  run_plan = None
  if eager:
    assert loop in ("map", "vmap"), "an eager path names the loop its plan is made for"
    run_plan = plan.make_plan(cm, mask, state, None, None, None, transform, aligned=config.aligned_fast_path,
                              loop=loop)
  res = process.filter_batch(cm, mask, idx, ok, state, win, en, tf, config=config, exact=exact, loop=loop,
                             plan=run_plan)
  if eager:
    assert not np.asarray(res[2]).any(), "the table left a robot open: its cells would be redone exactly"
  return np.asarray(res[0].cost).astype(np.int64)


# Off a GPU the kernels run in the Pallas interpreter; on a GPU compiled (the interpreter of the
# other-frame kernel gives wrong cells there and is refused: test_keepout_pallas.py).
INTERP = ko.PallasTuning(interpret=jax.default_backend() != "gpu", block_cells=4096, frame_block_cells=4096)
PATHS = {
    "exact": dict(exact=True),
    "slice_map": dict(loop="map"),
    "slice_vmap_packed": dict(loop="vmap"),
    "gather_map": dict(loop="map", cfg=dict(aligned_fast_path=False)),
    "gather_vmap": dict(loop="vmap", cfg=dict(aligned_fast_path=False)),
    # The vectorised loop (a GPU's): its plan sends an all-sliced fleet to the Pallas kernel; the CPU's
    # loop ("map") plans the gather kernel for it (process.py), which would not test the kernel.
    "pallas_aligned": dict(loop="vmap", cfg=dict(kernel="pallas", pallas=INTERP)),
    "finer_mask_vmap": dict(loop="vmap", scale=3),
    "finer_mask_map": dict(loop="map", scale=3),
    "other_frame_map": dict(loop="map", transform=True, cfg=dict(frame_kernel="xla")),
    "other_frame_vmap": dict(loop="vmap", transform=True, cfg=dict(frame_kernel="xla")),
    "other_frame_pallas": dict(loop="vmap", transform=True, cfg=dict(frame_kernel="pallas", pallas=INTERP)),
}


ESCAPE_PATHS = ("exact", "slice_vmap_packed", "pallas_aligned", "finer_mask_vmap", "other_frame_pallas")
CASES = [(p, False) for p in PATHS] + [(p, True) for p in ESCAPE_PATHS]


def _check_path(path, rule, escape, *, eager):
  spec = PATHS[path]
  cm, mask, state, _ = _table(spec.get("scale", 1))
  config = ko.KeepoutConfig(unknown_overwrite=rule, override_lethal_cost=escape,
                            lethal_override_cost=OVERRIDE_COST, **spec.get("cfg", {}))
  transform = jnp.zeros((2, 3), jnp.float32) if spec.get("transform") else None
  exact = spec.get("exact", False)
  got = _run(cm, mask, state, config, exact=exact, loop=spec.get("loop", "auto"), transform=transform,
             eager=eager and not exact)
  old = np.asarray(cm.cost[0]).astype(np.int64)
  d = np.broadcast_to(VALUES.astype(np.int64), (H, W))
  np.testing.assert_array_equal(got[0], _closed_form(old, d, rule, None))
  np.testing.assert_array_equal(got[1], _closed_form(old, d, rule, OVERRIDE_COST if escape else None))


@pytest.mark.parametrize("rule", RULES)
@pytest.mark.parametrize("path,escape", CASES, ids=[p + ("_escape" if e else "") for p, e in CASES])
def test_every_path_applies_the_chosen_rule(path, rule, escape):
  _check_path(path, rule, escape, eager=True)


def test_the_vectorised_plan_takes_the_kernel_each_path_names():
  """The plans of the vectorised loop's paths pick the kernel the path is named for (slice, or the Pallas
  kernel, for an all-sliced fleet; gather)."""
  for path, sliced in (("slice_vmap_packed", True), ("gather_vmap", False), ("finer_mask_vmap", False),
                       ("pallas_aligned", True)):
    spec = PATHS[path]
    cm, mask, state, _ = _table(spec.get("scale", 1))
    aligned = ko.KeepoutConfig(**spec.get("cfg", {})).aligned_fast_path
    assert plan.make_plan(cm, mask, state, None, None, None, None, aligned=aligned, loop="vmap").all_sliced == sliced


@pytest.mark.parametrize("rule", RULES)
@pytest.mark.parametrize("path", ["slice_map", "slice_vmap_packed"])
def test_the_jitted_program_applies_the_chosen_rule(path, rule):
  """What a caller's `jit` compiles: the fast path with the exact reruns inside (escape mode: robot 0
  plain, robot 1 in a zone)."""
  _check_path(path, rule, True, eager=False)


@pytest.mark.parametrize("rule", RULES)
def test_float64_reference_applies_the_chosen_rule(rule):
  cm, mask, _, data = _table()
  old = np.asarray(cm.cost[0])
  for escape in (False, True):
    want, ran = reference.keepout_process(old, (0.0, 0.0), RES, data, (0.0, 0.0), RES, (0, 0, W, H),
                                          is_pose_lethal=True, override=escape, override_cost=OVERRIDE_COST,
                                          unknown_overwrite=rule)
    assert ran
    d = np.broadcast_to(VALUES.astype(np.int64), (H, W))
    np.testing.assert_array_equal(want, _closed_form(old.astype(np.int64), d, rule,
                                                      OVERRIDE_COST if escape else None))


def test_rules_differ_only_on_unknown_master_cells_under_low_mask_costs():
  """The two rules give different integers exactly where old == 255 and 0 <= data cost < 253."""
  cm, mask, state, _ = _table()
  new = _run(cm, mask, state, ko.KeepoutConfig(), exact=True)[0]
  legacy = _run(cm, mask, state, ko.KeepoutConfig(unknown_overwrite="any"), exact=True)[0]
  differ = new != legacy
  mc = np.floor(np.clip(VALUES, 0, 100) * 2.54 + 0.5)
  want_cols = (VALUES >= 0) & (VALUES <= 100) & (mc < 253)
  assert np.array_equal(differ[255], want_cols) and not differ[:255].any()
  assert (new[255][want_cols] == 255).all()


@pytest.mark.parametrize("rule", RULES)
@pytest.mark.parametrize("escape", [False, True])
def test_packed_words_equal_the_byte_rule_on_every_pair(rule, escape):
  """`packed.write_rule` (four cells per uint32) against `common.m1_rule_u8` on all 256 x 256 (old, m1)."""
  c = np.repeat(np.arange(256, dtype=np.uint8), 256)
  m1 = np.tile(np.arange(256, dtype=np.uint8), 256)
  config = ko.KeepoutConfig(unknown_overwrite=rule, override_lethal_cost=escape, lethal_override_cost=OVERRIDE_COST)
  state = dataclasses.replace(ko.KeepoutState.create(1), is_pose_lethal=jnp.asarray(True))
  byte = np.asarray(common.m1_rule_u8(jnp.asarray(c), jnp.asarray(m1), state, config))
  word = np.asarray(packed.unpack(packed.write_rule(packed.pack(jnp.asarray(c)), packed.pack(jnp.asarray(m1)),
                                                    state, config)))
  np.testing.assert_array_equal(word, byte)
  mc = m1.astype(np.int64) - 1        # -1: unknown or not visited
  write = (mc >= 0) & ((mc > c) | ((c == 255) & ((rule == "any") | (mc >= 253))))
  np.testing.assert_array_equal(byte, np.where(write, OVERRIDE_COST if escape else mc, c))


def test_default_follows_nav2_main_and_bad_values_raise():
  assert ko.KeepoutConfig().unknown_overwrite == "inscribed"
  for bad in ("legacy", None, 1, "Inscribed"):
    with pytest.raises(ValueError, match="unknown_overwrite must be one of"):
      ko.KeepoutConfig(unknown_overwrite=bad)
  with pytest.raises(ValueError, match="unknown_overwrite"):
    reference.keepout_process(np.zeros((2, 2), np.uint8), (0, 0), 1.0, np.zeros((2, 2)), (0, 0), 1.0, (0, 0, 2, 2),
                              unknown_overwrite="legacy")
