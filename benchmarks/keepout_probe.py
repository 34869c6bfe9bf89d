"""Where the other-resolution and other-frame (SE2) keepout paths spend their time, on one device.

    PYTHONPATH=$PWD python3 -m benchmarks.keepout_probe --out $OUT/keepout_probe.json
        [--robots 16384] [--hw 200] [--mask 2000] [--repeats 7] [--budget-s 170]
        [--only other_res,se2] [--no-edges] [--list]

Prints one compact JSON object on stdout (a few KB, so it survives a log tail) and, with
--out, writes the full one (per-run times, per-fleet edge counts, tracebacks), rewritten
after every variant so a timeout keeps what was measured. Progress goes to stderr.

For each figure (`other_res`: costmap 0.05 m as Nav2's double against a 0.1 m float32
mask, same frame; `se2`: 0.05 m against 0.05 m with each window turned about its centre
by any yaw; B robots of H x W over one Hm x Hm mask, windows at random places, as in
benchmarks/run.py's keepout figures) it

1. runs the exact per-cell path (`_keepout_filter_jit(exact=True)`) once: the reference;
2. for every variant: compiles it (reported apart), runs it on the first input set and
   counts the cells (and escape flags) that differ from the reference, then times it
   (median of `repeats` runs alternating two input sets, after `block_until_ready`).
   A variant that should be exact ("current", "candidate") and differs gets `valid:
   false` (its time is reported but `summary` never picks it); ablations and ceilings
   change the work on purpose, so their counts are for information;
3. checks the current path and every candidate, plain and escape mode, against the exact
   path on small "edge" fleets whose cell centres lie exactly on mask-cell edges and one
   ulp off them (`edge_check`, `edge_valid`): the device's FMA contraction, division and
   flush-to-zero are what could move a cell there.

The phases run in that order over both figures (current and candidates first, then the
ablations, then the edge checks), each variant caught on its own: an error is reported in
its entry and the rest go on; a variant that would start after --budget-s seconds is
reported as skipped. With the defaults the whole call should take about 2-3 minutes on an
H100 (compiling ~30 programs is most of it).

`summary` in each figure names the fastest candidate that is bit-equal on the timed inputs
and on the edge fleets, beside the current path. To make it the default, set in
jaxfilters/keepout.py `_GATHER_IMPL` (other resolution: "gather" | "packed" | "rows" |
"window") or `_SE2_IMPL` (other frame, non-CPU backends: "codes" | "fused" | "thresholds"
| "thresholds_packed"; `_SE2_IMPL_CPU` for the CPU backend).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import sys
import time
import traceback

import jax
import jax.numpy as jnp
import numpy as np

import jaxfilters as jf
from jaxfilters import geometry
from jaxfilters import keepout as ko
from jaxfilters.grid import OccupancyGrid

from benchmarks.run import RES as BENCH_RES, turned_windows

RES = BENCH_RES            # the benchmark harness's costmap resolution (turned_windows uses it)
PLAIN = ko.KeepoutConfig()
ESCAPE = ko.KeepoutConfig(override_lethal_cost=True, lethal_override_cost=200)


def log(*a):
  print("[probe]", *a, file=sys.stderr, flush=True)


# ----------------------------------------------------------------------------- inputs


def _mask_data(rng, n, values):
  # Blocky zones (8x8-cell blobs) like a drawn mask (benchmarks/run.py's).
  coarse = rng.choice(np.asarray(values, np.int8), (n // 8 + 1, n // 8 + 1))
  return np.repeat(np.repeat(coarse, 8, 0), 8, 1)[:n, :n]


def fleet(seed, b, hw, n, mask_res, transform):
  """benchmarks/run.py's keepout inputs, the costs drawn on the device (16384 x 200 x 200 in ms).

  Returns the argument tuple of `_keepout_filter_jit`: (costmap, mask, idx, idx_ok, state,
  window, enabled, transform).
  """
  rng = np.random.default_rng(seed)
  data = _mask_data(rng, n, [-1, 0, 0, 0, 0, 0, 30, 60, 100, 100])
  mask = jf.FilterMask.create(OccupancyGrid.create(data, mask_res, (0.0, 0.0)), jf.FilterInfo.create(0))
  span = n * mask_res
  k = rng.integers(-hw // 4, int(span / RES) - 3 * hw // 4, (b, 2))
  origin = (k * RES).astype(np.float32)
  geo = jf.Costmap.create(np.zeros((b, 1, 1), np.uint8), origin, RES)     # the double 0.05 as parts
  table = jnp.asarray([0, 0, 0, 0, 10, 100, 253, 254, 255], jnp.uint8)
  cost = table[jax.random.randint(jax.random.PRNGKey(seed), (b, hw, hw), 0, 9)]
  cm = dataclasses.replace(geo, cost=cost)
  tf = None
  if transform:
    tf = turned_windows(rng, origin, hw)
  state = ko._fill_error(jf.KeepoutState.create(b), b)
  idx, ok, _, en, win, tf = ko._batched_inputs(cm, mask, jnp.zeros((b, 3)), None, None, None, tf, "probe")
  return cm, mask, idx, ok, state, win, en, tf


def edge_fleets(kind):
  """Small fleets whose cell centres lie on mask-cell edges and one ulp off them (binary-exact grids).

  Yields (label, argument tuple). W = 64 (a multiple of 4, so the packed kernels run packed).
  """
  b, h, w, hm, wm = 64, 48, 64, 160, 144
  rng = np.random.default_rng(5)
  data = rng.choice(np.asarray([-1, 0, 0, 1, 25, 50, 75, 99, 100, 100, 101, -128], np.int8), (2, hm, wm))
  nudge = lambda x, k: np.float32(x) if k == 0 else (np.nextafter(np.float32(x), np.float32(np.inf * k)))

  def build(res, mres, origins, morigins, tf=None):
    grids = [OccupancyGrid.create(np.clip(d, -1, 100), float(mres), tuple(o)) for d, o in zip(data, morigins)]
    mask = jf.FilterMask.create(grids, jf.FilterInfo.create(0)).with_data(data)
    cost = rng.choice(np.asarray([0, 0, 10, 100, 200, 252, 253, 254, 255], np.uint8), (b, h, w))
    cm = jf.Costmap.create(cost, np.asarray(origins, np.float64), res)
    x0, y0 = rng.integers(-2, w // 2, b), rng.integers(-2, h // 2, b)
    win = np.stack([x0, y0, x0 + rng.integers(1, w + 3, b), y0 + rng.integers(1, h + 3, b)], 1).astype(np.int32)
    win[: b // 2] = (0, 0, w, h)
    state = dataclasses.replace(jf.KeepoutState.create(b), is_pose_lethal=jnp.asarray(rng.random(b) < 0.5))
    mi = rng.integers(0, 2, b).astype(np.int32)
    en = jnp.asarray(rng.random(b) < 0.9)
    # One pytree structure for every fleet (zero lower parts where the value is float32): one compile.
    zeros = lambda x, shape: jnp.zeros(shape, jnp.float32) if x is None else x
    cm = dataclasses.replace(cm, origin_lo=zeros(cm.origin_lo, (b, 2, 2)),
                             resolution_lo=zeros(cm.resolution_lo, (b, 2)))
    mask = dataclasses.replace(mask, origin_lo=zeros(mask.origin_lo, (2, 2, 2)))
    idx, ok, _, en, win, tf = ko._batched_inputs(cm, mask, jnp.zeros((b, 3)), mi, en, win,
                                                 None if tf is None else jnp.asarray(tf), "probe")
    return cm, mask, idx, ok, ko._fill_error(state, b), win, en, tf

  origins = np.round(rng.uniform(-4, 4, (b, 2)) * 4) / 4
  for r in range(0, b, 8):           # every 8th robot one ulp off the grid, in turn up and down
    origins[r] = nudge(origins[r, 0], 1 if r % 16 else -1), nudge(origins[r, 1], -1 if r % 16 else 1)
  if kind == "other_res":
    # Finer mask (every centre on an edge), coarser mask (centres on every other edge), decimal grids.
    yield "finer_on_edges", build(0.5, 0.25, origins, [(-8.0, -8.0), (-7.5, -8.25)])
    yield "coarser_on_edges", build(0.25, 0.5, origins - 0.125, [(-8.0, -8.0), (-8.5, -7.5)])
    dec = np.round(rng.uniform(-1, 1, (b, 2)) / 0.05) * 0.05
    yield "decimal_0.05_vs_0.1", build(0.05, 0.1, dec, [(-2.5, -3.0), (-2.0, -2.7)])
    return
  tf = np.zeros((b, 3), np.float32)
  tf[:, :2] = np.round(rng.uniform(-1, 1, (b, 2)) * 4) / 4
  tf[1::8, 0] = [nudge(v, 1) for v in tf[1::8, 0]]
  tf[2::8, 1] = [nudge(v, -1) for v in tf[2::8, 1]]
  yield "yaw0_on_edges", build(0.5, 0.25, origins, [(-10.0, -10.0), (-9.75, -9.5)], tf)
  tq = tf.copy()
  tq[:, 2] = np.float32(np.pi / 2) * rng.integers(-2, 3, b)      # float32 pi/2: cos is -4.4e-8, not 0
  yield "quarter_turns", build(0.5, 0.25, origins, [(-12.0, -12.0), (-11.5, -12.25)], tq)
  tr = np.stack([rng.uniform(-0.2, 0.2, b), rng.uniform(-0.2, 0.2, b), rng.uniform(-np.pi, np.pi, b)], 1)
  dec = np.round(rng.uniform(-1, 1, (b, 2)) / 0.05) * 0.05
  yield "random_yaw_decimal", build(0.05, 0.05, dec, [(-2.5, -2.5), (-2.4, -2.6)], tr.astype(np.float32))


# ----------------------------------------------------------------------------- pieces for ablations
#
# These rebuild parts of jaxfilters/keepout.py's batch functions from its private kernels,
# so each part can be timed alone. They are for measurement only.


def _geometry_axes(costmap, mask):
  return tuple(None if g is None else 0 for g in ko._robot_geometry(costmap, mask))


def same_frame_prologue(cm, mask, idx, ok, state, win, en, *, reruns=True):
  """`_same_frame_batch`'s per-robot vector work: ((mx, vx), (my, vy)), (col_ok, row_ok, run)."""
  b, h, w = cm.cost.shape
  _, hm, wm = mask.data.shape
  in_axes = (*_geometry_axes(cm, mask), 0, 0, 0, 0)
  args = (*ko._robot_geometry(cm, mask), idx, ok, win, en)

  def prologue(origin, origin_lo, res, res_lo, i, ok, win, en, *, part="both", exact=False):
    return ko._same_frame_prologue_one((h, w), geometry.origin_terms(origin, origin_lo),
                                       geometry.resolution_terms(res, res_lo), ko._mask_origin(mask, i),
                                       mask.resolution[i], (hm, wm), win, en, ok, part=part, exact=exact)

  def exact(part):
    return lambda a: jax.vmap(lambda *x: prologue(*x, part=part, exact=True), in_axes=in_axes)(*a)[0]

  cells, cells_known, flags, flags_known = jax.vmap(prologue, in_axes=in_axes)(*args)
  if reruns:
    cells = ko._rerun(~cells_known, cells, exact("cells"), args, ko._rerun_capacity(b))
    flags = ko._rerun(~flags_known, flags, exact("flags"), args, max(8, b // 16))
  return cells, flags


def se2_axes(cm, mask, tf):
  h, w = cm.cost.shape[1:]

  def axes_of(origin, origin_lo, res, res_lo, t):
    return ko._se2_axes_one(geometry.origin_terms(origin, origin_lo), geometry.resolution_terms(res, res_lo), t, h, w)
  return jax.vmap(axes_of, in_axes=(*_geometry_axes(cm, mask), 0))(*ko._robot_geometry(cm, mask), tf)


def se2_codes(cm, mask, idx, win, run, axes):
  """`_se2_batch`'s first pass (vmap loop): int32 codes [B, H, W] in lax.map chunks."""
  b, h, w = cm.cost.shape
  _, hm, wm = mask.data.shape

  def codes_one(a):
    ax, i, wn, rn = a
    return ko._se2_codes_one(ax, i, ko._mask_origin(mask, i), mask.resolution[i], (hm, wm), wn, rn)
  return jax.lax.map(codes_one, (axes, idx, win, run),
                     batch_size=ko._divisor_at_most(b, ko._PASS_CHUNK_CELLS // (h * w)))


def plain_floor_one(cost, axes, mask, i, win, run, state, *, packed):
  """Not exact: the float32 floor((p - origin) / res) of each rotated centre, gather and write rule."""
  xc, xs, yc, ys, t = axes
  h, w = cost.shape
  _, hm, wm = mask.data.shape
  col_ok, row_ok = ko._window_flags(w, h, win[0], win[1], win[2], win[3], run)
  mo, r = mask.origin[i], mask.resolution[i]

  def cells(xc, xs, col_ok):
    px = (xc[None, :] - ys[:, None]) + t[0]
    py = (xs[None, :] + yc[:, None]) + t[1]
    nx = jnp.floor((px - mo[0]) / r).astype(jnp.int32)
    ny = jnp.floor((py - mo[1]) / r).astype(jnp.int32)
    visit = (nx >= 0) & (nx < wm) & (ny >= 0) & (ny < hm) & col_ok[None, :] & row_ok[:, None]
    return jnp.where(visit, i * (hm * wm) + ny * wm + nx, 0), visit

  if not packed:
    index, visit = cells(xc, xs, col_ok)
    return ko._write_u8(cost, mask.data.reshape(-1)[index], visit, state, PLAIN)
  table = ko._m1_table(mask.data).reshape(-1)
  planes = []
  for s in range(4):
    index, visit = cells(xc[s::4], xs[s::4], col_ok[s::4])
    planes.append(jnp.where(visit, table[index], jnp.uint8(0)))
  return ko._unpack(ko._packed_rule(ko._pack(cost), ko._word(planes), state, PLAIN))


def edges_decide_one(cost, axes, tables, mask, i, win, run):
  """The edge-table decision of every cell with no mask read: a byte of the index, stored."""
  tx, ty, mo, inv = tables
  xc, xs, yc, ys, t = axes
  h, w = cost.shape
  _, hm, wm = mask.data.shape
  col_ok, row_ok = ko._window_flags(w, h, win[0], win[1], win[2], win[3], run)
  px = (xc[None, :] - ys[:, None]) + t[0]
  py = (xs[None, :] + yc[:, None]) + t[1]
  nx = geometry.floor_by_edges(px, mo[i, 0], inv[i], tx, i * (wm + 3), wm)
  ny = geometry.floor_by_edges(py, mo[i, 1], inv[i], ty, i * (hm + 3), hm)
  visit = (nx >= 0) & (nx < wm) & (ny >= 0) & (ny < hm) & col_ok[None, :] & row_ok[:, None]
  return jnp.where(visit, (ny * wm + nx).astype(jnp.uint8), cost)


# ----------------------------------------------------------------------------- variants
#
# Each variant maps the argument tuple of `_keepout_filter_jit` (cm, mask, idx, ok, state,
# win, en, tf) to (cost uint8 [B, H, W] or another array, last_pose_lethal bool [B] or None).
# kind: "current" (what keepout_filter runs today), "candidate" (must be bit-equal),
# "ablation" (part of the work, or the work changed), "ceiling" (not exact: a bound).


def _filter(a, config=PLAIN):
  cm, st = ko._keepout_filter_jit(*a, config=config)
  return cm.cost, st.last_pose_lethal


def _same_frame(impl):
  def fn(a, config=PLAIN):
    cm, mask, idx, ok, state, win, en, _ = a
    cost, st = ko._same_frame_batch(cm, mask, idx, ok, state, win, en, config=config, loop="vmap",
                                    gather_impl=impl)
    return cost, st.last_pose_lethal
  return fn


def _se2(impl):
  def fn(a, config=PLAIN):
    cm, mask, idx, ok, state, win, en, tf = a
    cost, st = ko._se2_batch(cm, mask, idx, ok, state, win, en, tf, config=config, loop="vmap", impl=impl)
    return cost, st.last_pose_lethal
  return fn


def _gather_given_vectors(kernel):
  """The other-res cell pass alone, on index vectors computed beforehand (an input)."""
  def fn(a, vectors):
    cm, mask, idx, ok, state, win, en, _ = a
    ((mx, vx), (my, vy)), (col_ok, row_ok, _) = vectors
    _, hm, wm = mask.data.shape
    if kernel == "gather":
      flat = mask.data.reshape(-1)
      one = lambda c, i, mx, vx, my, vy, co, ro, st: ko._gather_write_one(c, flat, i, (hm, wm), mx, vx, my, vy, co,
                                                                          ro, st, config=PLAIN)
      return jax.vmap(one)(cm.cost, idx, mx, vx, my, vy, col_ok, row_ok, state), None
    if kernel == "packed":
      table = ko._m1_table(mask.data).reshape(-1)
      one = lambda c, i, mx, cv, my, rv, st: ko._gather_packed_one(c, table, i, (hm, wm), mx, cv, my, rv, st,
                                                                   config=PLAIN)
      return jax.vmap(one)(cm.cost, idx, mx, col_ok & vx, my, row_ok & vy, state), None
    # "write": the write rule with a mask byte made from the indices, no mask read.
    def one(c, mx, vx, my, vy, co, ro, st):
      d = ((my[:, None] * 7 + mx[None, :]) % 101).astype(jnp.int8)
      return ko._write_u8(c, d, (co & vx)[None, :] & (ro & vy)[:, None], st, PLAIN)
    return jax.vmap(one)(cm.cost, mx, vx, my, vy, col_ok, row_ok, state), None
  return fn


def _copy(words):
  def fn(a):
    c = a[0].cost
    if words:
      return ko._unpack(ko._pack(c) + jnp.uint32(0x01010101)), None
    return c + jnp.uint8(1), None
  return fn


def _prologue(reruns):
  def fn(a):
    return same_frame_prologue(*a[:-1], reruns=reruns), None
  return fn


def _se2_part(part):
  def fn(a, pre=None):
    cm, mask, idx, ok, state, win, en, tf = a
    run = en & ok
    axes = se2_axes(cm, mask, tf)
    flat = mask.data.reshape(-1)
    if part == "tables":
      return ko._se2_edge_tables(mask), None
    if part == "codes_pass":
      return se2_codes(cm, mask, idx, win, run, axes), None
    if part == "write_from_codes":       # pre: the codes, computed beforehand (an input)
      return jax.vmap(lambda c, k, st: ko._se2_write_one(c, k, flat, st, config=PLAIN))(cm.cost, pre, state), None
    if part == "codes_no_rerun":
      codes = se2_codes(cm, mask, idx, win, run, axes)
      return jax.vmap(lambda c, k, st: ko._se2_write_one(c, k, flat, st, config=PLAIN))(cm.cost, codes, state), None
    if part in ("plain_floor", "plain_floor_packed"):
      one = lambda c, ax, i, wn, rn, st: plain_floor_one(c, ax, mask, i, wn, rn, st, packed=part.endswith("packed"))
      return jax.vmap(one)(cm.cost, axes, idx, win, run, state), None
    if part == "edges_decide_only":
      tx, ty, inv, _ = ko._se2_edge_tables(mask)
      one = lambda c, ax, i, wn, rn: edges_decide_one(c, ax, (tx, ty, mask.origin, inv), mask, i, wn, rn)
      return jax.vmap(one)(cm.cost, axes, idx, win, run), None
    raise ValueError(part)
  return fn


VARIANTS = {
    "other_res": [
        ("current: keepout_filter (gather)", "current", _filter, "exact"),
        ("gather_impl=packed", "candidate", _same_frame("packed"), "exact"),
        ("gather_impl=rows", "candidate", _same_frame("rows"), "exact"),
        ("gather_impl=window", "candidate", _same_frame("window"), "exact"),
        ("prologue: index vectors + window clip, with exact reruns", "ablation", _prologue(True), None),
        ("prologue: bracketed only, no reruns", "ablation", _prologue(False), None),
        ("cells only: gather + write rule (vectors given)", "ablation", _gather_given_vectors("gather"), "vectors"),
        ("cells only: packed gather + SWAR rule (vectors given)", "ablation", _gather_given_vectors("packed"),
         "vectors"),
        ("cells only: write rule, no mask read (vectors given)", "ablation", _gather_given_vectors("write"),
         "vectors_compare"),
        ("ceiling: cost + 1, uint8 elementwise", "ceiling", _copy(False), None),
        ("ceiling: cost + 1, uint32 words", "ceiling", _copy(True), None),
    ],
    "se2": [
        ("current: keepout_filter (codes)", "current", _filter, "exact"),
        ("impl=fused", "candidate", _se2("fused"), "exact"),
        ("impl=thresholds", "candidate", _se2("thresholds"), "exact"),
        ("impl=thresholds_packed", "candidate", _se2("thresholds_packed"), "exact"),
        ("codes + write, rerun disabled", "ablation", _se2_part("codes_no_rerun"), "compare"),
        ("codes pass only (int32 [B, H, W] out)", "ablation", _se2_part("codes_pass"), None),
        ("gather + write only (codes given)", "ablation", _se2_part("write_from_codes"), "codes"),
        ("edge tables only", "ablation", _se2_part("tables"), None),
        ("edge-table decision only, no mask read", "ablation", _se2_part("edges_decide_only"), None),
        ("ceiling: plain float32 floor + gather (not exact)", "ceiling", _se2_part("plain_floor"), "compare"),
        ("ceiling: plain float32 floor + gather, packed words (not exact)", "ceiling",
         _se2_part("plain_floor_packed"), "compare"),
    ],
}


# ----------------------------------------------------------------------------- running


def _block(x):
  return jax.block_until_ready(x)


def _diff(out, ref):
  cost, flags = out
  d = int(jnp.sum(cost != ref[0]))
  if flags is not None:
    d_flags = int(jnp.sum(flags != ref[1]))
    return d, d_flags
  return d, None


def _hlo_kernels(compiled) -> int | None:
  """How many kernels (fusions, custom calls, loops) the entry computation launches, roughly."""
  try:
    text = compiled.as_text()
  except Exception:  # noqa: BLE001 - diagnostics only
    return None
  entry = text[text.find("ENTRY"):]
  entry = entry[:entry.find("\n}")]
  ops = (" fusion(", " custom-call(", " while(", " conditional(", " gather(", " scatter(", " copy(")
  return sum(line.count(op) for line in entry.splitlines() for op in ops)


def time_variant(fn, arg_sets, repeats, extra_sets=None):
  """(compile_s, median steady_s, output on set 0, kernels); fn(args[, extra]) jitted."""
  jitted = jax.jit(fn)
  call_args = [(a,) if extra_sets is None else (a, e) for a, e in zip(arg_sets, extra_sets or arg_sets)]
  t = time.perf_counter()
  compiled = jitted.lower(*call_args[0]).compile()
  compile_s = time.perf_counter() - t
  out0 = _block(compiled(*call_args[0]))
  for ca in call_args[1:]:
    _block(compiled(*ca))
  times = []
  for k in range(max(repeats, 3)):
    ca = call_args[k % len(call_args)]
    t = time.perf_counter()
    _block(compiled(*ca))
    times.append(time.perf_counter() - t)
  return compile_s, float(np.median(times)), out0, _hlo_kernels(compiled), times


@jax.jit
def _edge_exact(a):
  out = {}
  for name, cfg in (("plain", PLAIN), ("escape", ESCAPE)):
    cm, st = ko._keepout_filter_jit(*a, config=cfg, exact=True)
    out[name] = (cm.cost, st.last_pose_lethal)
  return out


def edge_check(fn, kind):
  """Cells (and escape flags) that differ from the exact path on the edge fleets: {fleet/config: count}.

  The fleets share one shape and pytree structure, so the variant compiles once per config.
  """
  out = {}
  runs = {name: jax.jit(lambda a, cfg=cfg: fn(a, config=cfg)) for name, cfg in (("plain", PLAIN), ("escape", ESCAPE))}
  for label, a in edge_fleets(kind):
    want = _edge_exact(a)
    for name, run in runs.items():
      got = run(a)
      out[f"{label}/{name}"] = int(jnp.sum(got[0] != want[name][0])) + int(jnp.sum(got[1] != want[name][1]))
  return out


def _filter_exact(a):
  cm, st = ko._keepout_filter_jit(*a, config=PLAIN, exact=True)
  return cm.cost, st.last_pose_lethal


def setup_figure(name, args):
  """Inputs (two sets) and the exact path's result on the first: (figure dict, sets, reference)."""
  b, hw, n = args.robots, args.hw, args.mask
  mask_res = 2 * RES if name == "other_res" else RES
  t = time.perf_counter()
  sets = [fleet(s, b, hw, n, mask_res, name == "se2") for s in range(2)]
  _block(sets[1][0].cost)
  fig = dict(params=dict(B=b, H=hw, W=hw, mask=[n, n], costmap_res=f"{RES} (double)", mask_res=mask_res,
                         transform=name == "se2", repeats=args.repeats,
                         timing="median of the timed runs, alternating 2 input sets, after block_until_ready"),
             inputs_s=round(time.perf_counter() - t, 2), variants=[])
  ref = None
  try:
    t = time.perf_counter()
    ref = _block(jax.jit(_filter_exact)(sets[0]))
    fig["exact_reference"] = dict(wall_s=round(time.perf_counter() - t, 2), note="compile + one run")
    if name == "se2":
      sub = min(b, 1024)
      fig["paths_first_robots"] = ko._path_report(jax.tree.map(lambda x: x[:sub], sets[0][0]), sets[0][1],
                                                  sets[0][7][:sub])
  except Exception as e:  # noqa: BLE001
    fig["exact_reference"] = dict(error=f"{type(e).__name__}: {e}"[:600], trace=traceback.format_exc(limit=4))
  return fig, sets, ref


def time_one(name, fig, sets, ref, variant, args, pre):
  """Times one variant into a new entry of fig["variants"] (errors caught and reported there)."""
  label, kind, fn, check = variant
  entry = dict(name=label, kind=kind)
  fig["variants"].append(entry)
  b, hw = args.robots, args.hw
  t = time.perf_counter()
  try:
    extra = None
    if check in ("vectors", "vectors_compare"):
      if "vectors" not in pre:
        pre["vectors"] = [_block(jax.jit(lambda a: same_frame_prologue(*a[:-1]))(s)) for s in sets]
      extra = pre["vectors"]
    elif check == "codes":
      if "codes" not in pre:
        pre["codes"] = [_block(jax.jit(_se2_part("codes_pass"))(s)[0]) for s in sets]
      extra = pre["codes"]
    compile_s, steady, out0, kernels, times = time_variant(fn, sets, args.repeats, extra)
    entry.update(compile_s=round(compile_s, 3), steady_s=steady, gcells_per_s=round(b * hw * hw / steady / 1e9, 2),
                 runs_s=[round(x, 6) for x in times], hlo_kernels=kernels)
    if check in ("exact", "compare", "vectors", "vectors_compare") and ref is not None:
      d, df = _diff(out0, ref)
      entry.update(diff_cells=d, diff_escape_flags=df)
      if check in ("exact", "vectors"):      # the others change the work on purpose
        entry["valid"] = d == 0 and not df
    del out0
  except Exception as e:  # noqa: BLE001 - one variant's failure must not lose the rest
    entry["error"] = f"{type(e).__name__}: {e}"[:600]
    entry["trace"] = traceback.format_exc(limit=6)[-2000:]
  entry["wall_s"] = round(time.perf_counter() - t, 2)
  log(name, label, {k: entry.get(k) for k in ("compile_s", "steady_s", "gcells_per_s", "diff_cells", "valid",
                                              "error")})
  return entry


def summary(fig):
  """The current path's figure beside the fastest candidate that is bit-equal (timed inputs and edge fleets)."""
  vs = [v for v in fig["variants"] if "gcells_per_s" in v]
  cur = next((v for v in vs if v["kind"] == "current"), None)
  ok = [v for v in vs if v["kind"] == "candidate" and v.get("valid") and v.get("edge_valid") is not False]
  best = max(ok, key=lambda v: v["gcells_per_s"], default=None)
  out = dict(current=cur and dict(name=cur["name"], gcells_per_s=cur["gcells_per_s"], valid=cur.get("valid")),
             best_valid_candidate=best and dict(name=best["name"], gcells_per_s=best["gcells_per_s"],
                                                edge_checked=best.get("edge_valid") is True))
  if cur and best:
    out["speedup"] = round(best["gcells_per_s"] / cur["gcells_per_s"], 3)
  return out


def _write(path, obj):
  with open(path, "w") as f:
    json.dump(obj, f, default=str)


def main(argv=None) -> int:
  ap = argparse.ArgumentParser(prog="python -m benchmarks.keepout_probe", description=__doc__.splitlines()[0])
  ap.add_argument("--robots", type=int, default=None, help="B (default 16384 on a GPU, 64 on the CPU)")
  ap.add_argument("--hw", type=int, default=200, help="costmap H = W (default 200)")
  ap.add_argument("--mask", type=int, default=None, help="mask Hm = Wm (default 2000; 500 on the CPU)")
  ap.add_argument("--repeats", type=int, default=7, help="timed runs per variant (>= 3)")
  ap.add_argument("--budget-s", type=float, default=170.0, help="start no variant after this many seconds")
  ap.add_argument("--only", default="", help="comma-separated figures: other_res,se2")
  ap.add_argument("--no-edges", action="store_true", help="skip the edge-fleet exactness checks")
  ap.add_argument("--list", action="store_true", help="print the variants and exit")
  ap.add_argument("--out", default=None, help="also write the JSON object (and partial results) to FILE")
  args = ap.parse_args(argv)
  if args.list:
    for fig, vs in VARIANTS.items():
      for label, kind, _, _ in vs:
        print(f"{fig:10s} {kind:10s} {label}")
    return 0
  if args.repeats < 3:
    ap.error(f"--repeats must be >= 3; got {args.repeats}")
  only = [x for x in args.only.split(",") if x] or list(VARIANTS)
  unknown = sorted(set(only) - set(VARIANTS))
  if unknown:
    ap.error(f"unknown --only figures {unknown}; choose from {sorted(VARIANTS)}")
  cpu = jax.default_backend() == "cpu"
  args.robots = (64 if cpu else 16384) if args.robots is None else args.robots
  args.mask = (500 if cpu else 2000) if args.mask is None else args.mask
  if args.robots < 1 or args.hw < 4 or args.hw % 4 or args.mask < 8:
    ap.error(f"need --robots >= 1, --hw >= 4 and a multiple of 4, --mask >= 8; got {args.robots}, {args.hw}, "
             f"{args.mask}")
  t0 = time.perf_counter()
  d = jax.devices()[0]
  report = dict(probe="keepout_probe", device=dict(platform=d.platform, device_kind=d.device_kind, jax=jax.__version__,
                                                   python=platform.python_version()),
                defaults=dict(SE2_IMPL=ko._SE2_IMPL, SE2_IMPL_CPU=ko._SE2_IMPL_CPU, GATHER_IMPL=ko._GATHER_IMPL),
                budget_s=args.budget_s, figures={})
  state = {}
  for name in only:
    try:
      fig, sets, ref = setup_figure(name, args)
      state[name] = (sets, ref, {})
    except Exception as e:  # noqa: BLE001
      fig = dict(error=f"{type(e).__name__}: {e}"[:600], trace=traceback.format_exc(limit=6), variants=[])
    report["figures"][name] = fig
  # Three phases, the most telling first, so a spent budget loses the least: the current
  # path and the candidates of every figure; the ablations and ceilings; the edge checks.
  phases = [("time", ("current", "candidate")), ("time", ("ablation", "ceiling")), ("edges", ("current", "candidate"))]
  for what, kinds in phases:
    for name in state:
      sets, ref, pre = state[name]
      fig = report["figures"][name]
      for variant in VARIANTS[name]:
        if variant[1] not in kinds:
          continue
        if what == "time":
          if time.perf_counter() - t0 > args.budget_s:
            fig["variants"].append(dict(name=variant[0], kind=variant[1], skipped=f"time budget ({args.budget_s} s)"))
            continue
          time_one(name, fig, sets, ref, variant, args, pre)
        elif not args.no_edges:
          entry = next((v for v in fig["variants"] if v["name"] == variant[0]), None)
          if entry is None or "gcells_per_s" not in entry:
            continue
          if time.perf_counter() - t0 > args.budget_s:
            entry["edge_check"] = f"skipped: time budget ({args.budget_s} s)"
            continue
          t = time.perf_counter()
          try:
            entry["edge_check"] = edge_check(variant[2], name)
            entry["edge_valid"] = all(v == 0 for v in entry["edge_check"].values())
          except Exception as e:  # noqa: BLE001
            entry["edge_check"] = f"error: {type(e).__name__}: {e}"[:600]
            entry["edge_valid"] = False
          entry["edge_check_s"] = round(time.perf_counter() - t, 2)
          log(name, variant[0], "edge_valid", entry.get("edge_valid"))
        if args.out:
          _write(args.out, dict(report, partial=True))
    if what == "time" and "ablation" in kinds:
      for name in state:      # free the device copies before the edge checks
        state[name] = (None, None, {})
  for name, fig in report["figures"].items():
    if "variants" in fig:
      fig["summary"] = summary(fig)
  report["total_s"] = round(time.perf_counter() - t0, 1)
  if args.out:
    with open(args.out, "w") as f:
      f.write(json.dumps(report, default=str) + "\n")
  print(json.dumps(compact(report), default=str, separators=(",", ":")))
  return 0


def compact(report):
  """The report without per-run times, traces and per-fleet counts (a few KB: it fits a log tail)."""
  keep = ("name", "kind", "compile_s", "gcells_per_s", "diff_cells", "diff_escape_flags", "valid", "edge_valid",
          "hlo_kernels", "skipped", "error")
  out = dict(report, figures={})
  for name, fig in report["figures"].items():
    small = {k: v for k, v in fig.items() if k not in ("variants", "trace")}
    rows = []
    for v in fig.get("variants", []):
      row = {k: v[k] for k in keep if k in v}
      if "steady_s" in v:
        row["steady_ms"] = round(1e3 * v["steady_s"], 4)
      if isinstance(v.get("edge_check"), str):
        row["edge_check"] = v["edge_check"]
      if "error" in row:
        row["error"] = row["error"][:200]
      rows.append(row)
    small["variants"] = rows
    out["figures"][name] = small
  return out


if __name__ == "__main__":
  sys.exit(main())
