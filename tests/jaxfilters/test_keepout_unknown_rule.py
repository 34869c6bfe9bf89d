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
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfilters import keepout as ko
from jaxfilters.grid import OccupancyGrid
from jaxfilters.keepout import common, packed, process
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


def _run(cm, mask, state, config, *, exact=False, loop="auto", transform=None):
  idx, ok, _, en, win, tf = common.batched_inputs(cm, mask, jnp.zeros((2, 3)), None, None, None, transform,
                                                  "test")
  out, _ = process.filter_batch(cm, mask, idx, ok, state, win, en, tf, config=config, exact=exact, loop=loop)
  return np.asarray(out.cost).astype(np.int64)


# Off a GPU the kernels run in the Pallas interpreter; on a GPU compiled (the interpreter of the
# other-frame kernel gives wrong cells there and is refused: test_keepout_pallas.py).
INTERP = ko.PallasTuning(interpret=jax.default_backend() != "gpu", block_cells=4096, frame_block_cells=4096)
PATHS = {
    "exact": dict(exact=True),
    "slice_map": dict(loop="map"),
    "slice_vmap_packed": dict(loop="vmap"),
    "gather_map": dict(loop="map", cfg=dict(aligned_fast_path=False)),
    "gather_vmap": dict(loop="vmap", cfg=dict(aligned_fast_path=False)),
    "pallas_aligned": dict(cfg=dict(kernel="pallas", pallas=INTERP)),
    "finer_mask_vmap": dict(loop="vmap", scale=3),
    "finer_mask_map": dict(loop="map", scale=3),
    "other_frame_map": dict(loop="map", transform=True, cfg=dict(frame_kernel="xla")),
    "other_frame_vmap": dict(loop="vmap", transform=True, cfg=dict(frame_kernel="xla")),
    "other_frame_pallas": dict(loop="vmap", transform=True, cfg=dict(frame_kernel="pallas", pallas=INTERP)),
}


ESCAPE_PATHS = ("exact", "slice_vmap_packed", "pallas_aligned", "finer_mask_vmap", "other_frame_pallas")
CASES = [(p, False) for p in PATHS] + [(p, True) for p in ESCAPE_PATHS]


@pytest.mark.parametrize("rule", RULES)
@pytest.mark.parametrize("path,escape", CASES, ids=[p + ("_escape" if e else "") for p, e in CASES])
def test_every_path_applies_the_chosen_rule(path, rule, escape):
  spec = PATHS[path]
  cm, mask, state, _ = _table(spec.get("scale", 1))
  config = ko.KeepoutConfig(unknown_overwrite=rule, override_lethal_cost=escape,
                            lethal_override_cost=OVERRIDE_COST, **spec.get("cfg", {}))
  transform = jnp.zeros((2, 3), jnp.float32) if spec.get("transform") else None
  got = _run(cm, mask, state, config, exact=spec.get("exact", False), loop=spec.get("loop", "auto"),
             transform=transform)
  old = np.asarray(cm.cost[0]).astype(np.int64)
  d = np.broadcast_to(VALUES.astype(np.int64), (H, W))
  np.testing.assert_array_equal(got[0], _closed_form(old, d, rule, None))
  np.testing.assert_array_equal(got[1], _closed_form(old, d, rule, OVERRIDE_COST if escape else None))


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
