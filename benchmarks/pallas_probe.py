"""GPU probe of the Pallas keepout kernel (issue 9 item 3): one device call, one JSON dict.

    PYTHONPATH=$PWD python3 benchmarks/pallas_probe.py [--quick] [--budget-s 420] [--out FILE]

On the device, for the benchmark's aligned keepout (B = 16384 costmaps of 200 x 200
uint8, one 2000 x 2000 mask, 3 bytes per cell: read cost, read mask, write cost) and
one odd shape (W odd, so no wide vector is aligned), it

1. builds fresh random inputs on the device (every cost byte, mask values incl.
   unknown and out-of-range bytes, windows partly off the mask);
2. checks `keepout_filter` with `KeepoutConfig(kernel="pallas")` bit-equal to the
   XLA path (escape mode off and on, full and random update windows, a fleet with
   robots off the slice path), each result computed after poisoning the allocator
   with a buffer of 0xA5 bytes the size of the output;
3. times the XLA path and each Pallas tuning (compile time apart; warm-up, then the
   median of >= 20 runs with block_until_ready; in-place tunings with the costmap
   donated, each run's output the next run's input), the kernels alone on the same
   prepared table and windows, and a device-to-device copy of the same bytes
   (uint32 x + 1, read + write, and the donated in-place form) measured in the
   same call as the ceiling;
4. records the PTX Triton produced for each kernel and counts its global loads and
   stores by width (ld.global.v4.b32 = 16-byte vector), when jaxlib compiles
   Pallas kernels through `jax._src.lib.triton.compile` (jaxlib > 0.10.2).

Every step runs in its own try block: a failure (a Pallas compile error included)
is reported with its message and the probe goes on; the exit status is 0. The time
budget (--budget-s) skips whatever is left once it is spent, saying so.
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import functools
import json
import platform
import re
import sys
import time
import traceback

import jax
import jax.numpy as jnp
import numpy as np

import jaxfilters as jf
from jaxfilters import keepout as ko
from jaxfilters import keepout_pallas as kp
from jaxfilters.grid import OccupancyGrid
from jaxfilters.keepout_pallas import PallasTuning

RES = 0.05
REPEATS = 20
# The tunings tried: the default (16-byte flat runs, 16 cells per thread), bigger
# programs with more warps, the 2-D block layout, and the in-place kernel (donated).
TUNINGS = {
    "flat2048_w4": PallasTuning(),
    "flat4096_w8": PallasTuning(block_cells=4096, num_warps=8),
    "rows2048_w4": PallasTuning(layout="rows", block_cells=2048, num_warps=4),
    "flat2048_w4_in_place": PallasTuning(in_place=True),
}

_PTX: list[str] = []


def _log(msg):
  print(f"[probe {time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def _error(e: BaseException) -> dict:
  return dict(error=f"{type(e).__name__}: {str(e)[:2000]}", trace=traceback.format_exc(limit=6)[-4000:])


def _record_ptx():
  """Wraps jaxlib's Triton compile so each Pallas kernel's PTX is kept (where that path exists)."""
  try:
    from jax._src.lib import triton  # noqa: PLC0415
    original = triton.compile
  except Exception as e:  # noqa: BLE001
    return f"unavailable: {type(e).__name__}: {e}"

  def compile_and_keep(*args, **kwargs):
    result = original(*args, **kwargs)
    asm = getattr(result, "asm", None)
    if isinstance(asm, bytes):
      asm = asm.decode(errors="replace")
    if isinstance(asm, str):
      _PTX.append(asm)
    return result

  triton.compile = compile_and_keep
  return "wrapped jax._src.lib.triton.compile"


def _ptx_summary(asm: str) -> dict:
  """Global loads/stores in the PTX by form (e.g. ld.global.v4.b32 = 16-byte vector load)."""
  counts = collections.Counter(m.group(0) for m in re.finditer(r"\b(?:ld|st)\.global(?:\.[a-z0-9]+)+", asm))
  entry = re.search(r"\.entry\s+([A-Za-z0-9_$]+)", asm)
  return dict(kernel=entry.group(1) if entry else None, memory_ops=dict(sorted(counts.items())),
              ptx_lines=asm.count("\n"))


# ----------------------------------------------------------------------------- inputs


def make_fleet(seed, b, h, w, hm, wm, *, other_res_every=0):
  """Fresh random same-frame inputs: costs on the device, a blocky mask with odd bytes."""
  rng = np.random.default_rng(seed)
  values = np.asarray([-1, 0, 0, 0, 0, 0, 30, 60, 99, 100, 100], np.int8)
  coarse = rng.choice(values, (hm // 8 + 1, wm // 8 + 1))
  data = np.repeat(np.repeat(coarse, 8, 0), 8, 1)[:hm, :wm].copy()
  odd = rng.random((hm, wm)) < 0.01                 # bytes map_server never writes: unknown to both paths
  data[odd] = rng.choice(np.concatenate([np.arange(101, 128), np.arange(-128, -1)]).astype(np.int8), odd.sum())
  grid = OccupancyGrid.create(np.clip(data, -1, 100), RES, (0.0, 0.0))
  mask = jf.FilterMask.create(grid, jf.FilterInfo.create(0)).with_data(data)
  # Rolling windows over the mask, a few partly off it (as benchmarks/run.py's keepout_aligned).
  kx = rng.integers(-w // 4, wm - 3 * w // 4, b)
  ky = rng.integers(-h // 4, hm - 3 * h // 4, b)
  origin = (np.stack([kx, ky], 1) * RES).astype(np.float32)
  resolution = np.full(b, RES, np.float32)
  if other_res_every:
    resolution[::other_res_every] = np.float32(2 * RES)   # off the slice path: gathered
  shell = jf.Costmap.create(np.zeros((b, 1, 1), np.uint8), origin, resolution)
  cost = jax.random.bits(jax.random.key(seed), (b, h, w), jnp.uint8)
  cost = jnp.where(jax.random.bernoulli(jax.random.key(seed + 1), 0.05, (b, h, w)), jnp.uint8(255), cost)
  state = jf.KeepoutState.create(b)
  lethal = jnp.asarray(rng.random(b) < 0.5)
  x0, y0 = rng.integers(-3, w // 2, b), rng.integers(-3, h // 2, b)
  window = np.stack([x0, y0, x0 + rng.integers(1, w + 4, b), y0 + rng.integers(1, h + 4, b)], 1).astype(np.int32)
  return dict(cost=cost, shell=shell, mask=mask, state=state, lethal=lethal, window=jnp.asarray(window))


def filter_fn(config, with_window):
  def fn(cost, shell, mask, state, window):
    cm = dataclasses.replace(shell, cost=cost)
    poses = jnp.zeros((cost.shape[0], 3), jnp.float32)
    out, _ = jf.keepout_filter(cm, mask, poses, state, window=window if with_window else None, config=config)
    return out.cost
  return fn


def _poison(shape):
  junk = jnp.full(shape, 0xA5, jnp.uint8)
  junk.block_until_ready()
  del junk


def _time(compiled, args, *, donate: bool, repeats: int) -> dict:
  """Median seconds over `repeats` runs after 3 warm-ups; donated: each output is the next input."""
  args = list(args)
  if donate:
    args[0] = args[0] + jnp.uint8(0)          # a private copy to consume
  for _ in range(3):
    out = jax.block_until_ready(compiled(*args))
    if donate:
      args[0] = out
  times = []
  for _ in range(repeats):
    t = time.perf_counter()
    out = jax.block_until_ready(compiled(*args))
    times.append(time.perf_counter() - t)
    if donate:
      args[0] = out
  return dict(steady_s=float(np.median(times)), min_s=float(np.min(times)), runs=len(times))


def _compile(fn, args, donate):
  jitted = jax.jit(fn, donate_argnums=(0,) if donate else ())
  t = time.perf_counter()
  compiled = jitted.lower(*args).compile()
  return compiled, time.perf_counter() - t


def _hlo_summary(compiled) -> dict:
  """What the compiled program runs at its top level: copies of whole buffers, kernels, loops."""
  try:
    text = compiled.as_text()
  except Exception as e:  # noqa: BLE001
    return dict(unavailable=f"{type(e).__name__}: {e}")
  big_copies = [ln.strip()[:160] for ln in text.splitlines()
                if re.search(r"= u8\[\d{3,},[^]]*\][^=]*\bcopy\(", ln)]
  return dict(uint8_batch_copies=big_copies, custom_calls=len(re.findall(r"custom-call\(", text)),
              conditionals=len(re.findall(r"\bconditional\(", text)), whiles=len(re.findall(r"\bwhile\(", text)))


def _cells_fig(timing, cells, copy_bps):
  out = dict(timing)
  out["cells_per_s"] = cells / timing["steady_s"]
  if copy_bps:
    out["pct_of_copy_at_3_bytes_per_cell"] = round(100.0 * out["cells_per_s"] * 3 / copy_bps, 1)
  return out


# ----------------------------------------------------------------------------- sections


def copy_ceiling(nbytes, repeats):
  """uint32 x + 1 over the same bytes (read + write), plain and donated (in place)."""
  res = {}
  x = jnp.zeros((nbytes // 4,), jnp.uint32)
  for donate in (False, True):
    compiled, c = _compile(lambda x: x + jnp.uint32(1), (x,), donate)
    t = _time(compiled, (x,), donate=donate, repeats=repeats)
    res["donated" if donate else "plain"] = dict(t, compile_s=c, bytes_per_s=2 * nbytes / t["steady_s"])
  del x
  res["bytes"] = nbytes
  res["ceiling_bytes_per_s"] = max(v["bytes_per_s"] for k, v in res.items() if isinstance(v, dict))
  return res


def check_and_time(fleet, tunings, repeats, deadline, *, checks=True, timing=True):
  """The XLA path and each tuning through keepout_filter: bit-equality, compile, steady state."""
  b, h, w = fleet["cost"].shape
  cells = b * h * w
  args = (fleet["cost"], fleet["shell"], fleet["mask"], fleet["state"], fleet["window"])
  escape_state = dataclasses.replace(fleet["state"], is_pose_lethal=fleet["lethal"])
  xla = ko.KeepoutConfig()
  out = dict(B=b, H=h, W=w, mask=list(fleet["mask"].data.shape[1:]))
  try:
    out["paths_first_64"] = ko._path_report(jax.tree.map(lambda x: x[:64], dataclasses.replace(
        fleet["shell"], cost=fleet["cost"])), fleet["mask"])
  except Exception as e:  # noqa: BLE001
    out["paths_first_64"] = _error(e)

  refs = {}
  if checks:
    # References from the XLA path: Nav2's rule on full windows, escape mode on random windows.
    for escape, with_window in ((False, False), (True, True)):
      cfg = dataclasses.replace(xla, override_lethal_cost=escape, lethal_override_cost=120)
      a = list(args)
      if escape:
        a[3] = escape_state
      ref = jax.block_until_ready(jax.jit(filter_fn(cfg, with_window))(*a))
      refs[(escape, with_window)] = (cfg, a, ref, int(jnp.sum(ref != fleet["cost"])))

  if timing:
    try:
      compiled, c = _compile(filter_fn(xla, False), args, False)
      out["xla"] = dict(compile_s=c, hlo=_hlo_summary(compiled), **_time(compiled, args, donate=False,
                                                                          repeats=repeats))
      del compiled
      compiled, c = _compile(filter_fn(xla, False), args, True)
      out["xla_donated"] = dict(compile_s=c, **_time(compiled, args, donate=True, repeats=repeats))
      del compiled
    except Exception as e:  # noqa: BLE001
      out["xla"] = _error(e)

  out["pallas"] = {}
  for name, tuning in tunings.items():
    if time.perf_counter() > deadline:
      out["pallas"][name] = dict(skipped="time budget spent")
      continue
    _log(f"{b}x{h}x{w} pallas {name}")
    r = dict(tuning=dataclasses.asdict(tuning), geometry=kp.cells_per_program(h, w, tuning))
    n_ptx = len(_PTX)
    try:
      if timing:
        cfg = dataclasses.replace(xla, kernel="pallas", pallas=tuning)
        compiled, c = _compile(filter_fn(cfg, False), args, tuning.in_place)
        r["compile_s"] = c
        r["hlo"] = _hlo_summary(compiled)
        if len(_PTX) > n_ptx:
          r["ptx"] = [_ptx_summary(a) for a in _PTX[n_ptx:]]
        r.update(_time(compiled, args, donate=tuning.in_place, repeats=repeats))
        del compiled
      if checks:
        eq = {}
        for (escape, with_window), (xcfg, a, ref, changed) in refs.items():
          pcfg = dataclasses.replace(xcfg, kernel="pallas", pallas=tuning)
          fn = jax.jit(filter_fn(pcfg, with_window), donate_argnums=(0,) if tuning.in_place else ())
          a = list(a)
          if tuning.in_place:
            a[0] = a[0] + jnp.uint8(0)     # donated: a private copy
          _poison((b, h, w))
          got = jax.block_until_ready(fn(*a))
          key = f"escape={escape},window={'random' if with_window else 'full'}"
          eq[key] = dict(equal=bool(jnp.array_equal(got, ref)), cells_changed_by_filter=changed)
          if not eq[key]["equal"]:
            diff = got != ref
            eq[key]["mismatched_cells"] = int(jnp.sum(diff))
            eq[key]["mismatched_robots"] = int(jnp.sum(jnp.any(diff, axis=(1, 2))))
          del got
        r["bit_equal_to_xla"] = eq
    except Exception as e:  # noqa: BLE001 - a compile failure is a result, not a reason to stop
      r.update(_error(e))
    out["pallas"][name] = r
  out["cells"] = cells
  return out


def kernels_alone(fleet, tunings, repeats, deadline):
  """The write kernels on one prepared table and windows: Pallas vs the XLA aligned kernel."""
  cost = fleet["cost"]
  b, h, w = cost.shape
  data = fleet["mask"].data
  m, hm, wm = data.shape
  rng = np.random.default_rng(5)
  idx = jnp.zeros((b,), jnp.int32)
  sx = jnp.asarray(rng.integers(0, wm + w + 1, b), jnp.int32)
  sy = jnp.asarray(rng.integers(0, hm + h + 1, b), jnp.int32)
  col_ok, row_ok = jnp.ones((b, w), bool), jnp.ones((b, h), bool)
  state = fleet["state"]
  config = ko.KeepoutConfig()
  table = jax.block_until_ready(jax.jit(ko._cost_plus_one_table, static_argnums=(1, 2))(data, h, w))
  out = dict(note="full windows, random window starts over the whole padded table; the table is prepared "
                  "once (not timed); XLA: the GPU's packed (uint32 SWAR) kernel when W % 4 == 0, else bytes")
  if w % 4 == 0:
    words = jax.block_until_ready(jax.jit(ko._shifted_words)(table))
    xla_one = lambda c, t, i, x, y, co, ro, st: ko._aligned_packed_one(c, t, i, x, y, co, ro, st, config=config)
  else:
    words = table
    xla_one = lambda c, t, i, x, y, co, ro, st: ko._aligned_one(c, t, i, x, y, co, ro, st, config=config)
  # Every array is an argument (a closed-over array would be baked into the program).
  xla_fn = lambda c, t, i, x, y, co, ro, st: jax.vmap(xla_one, in_axes=(0, None, 0, 0, 0, 0, 0, 0))(
      c, t, i, x, y, co, ro, st)
  xla_args = (cost, words, idx, sx, sy, col_ok, row_ok, state)
  try:
    compiled, c = _compile(xla_fn, xla_args, False)
    ref = jax.block_until_ready(compiled(*xla_args))
    out["xla"] = dict(compile_s=c, **_time(compiled, xla_args, donate=False, repeats=repeats))
    del compiled
  except Exception as e:  # noqa: BLE001
    out["xla"] = _error(e)
    return out
  params = kp.slice_params(idx, sx, sy, col_ok, row_ok, jnp.ones((b,), bool), state.is_pose_lethal)
  out["pallas"] = {}
  for name, tuning in tunings.items():
    if time.perf_counter() > deadline:
      out["pallas"][name] = dict(skipped="time budget spent")
      continue
    try:
      fn = functools.partial(kp.aligned_write, escape=False, lethal_cost=0, tuning=tuning)
      compiled, c = _compile(fn, (cost, table, params), tuning.in_place)
      arg = cost + jnp.uint8(0) if tuning.in_place else cost
      _poison((b, h, w))
      got = jax.block_until_ready(compiled(arg, table, params))
      r = dict(compile_s=c, bit_equal_to_xla_kernel=bool(jnp.array_equal(got, ref)))
      del got
      r.update(_time(compiled, (cost, table, params), donate=tuning.in_place, repeats=repeats))
      r["cells_per_s"] = b * h * w / r["steady_s"]
      out["pallas"][name] = r
    except Exception as e:  # noqa: BLE001
      out["pallas"][name] = _error(e)
  if "steady_s" in out["xla"]:
    out["xla"]["cells_per_s"] = b * h * w / out["xla"]["steady_s"]
  return out


def main(argv=None) -> int:
  ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  ap.add_argument("--quick", action="store_true", help="small sizes (a smoke run of the probe itself)")
  ap.add_argument("--interpret", action="store_true",
                  help="run the Pallas kernels in the Pallas interpreter (with --quick: a CPU smoke run)")
  ap.add_argument("--budget-s", type=float, default=420.0, help="stop starting new steps after this many seconds")
  ap.add_argument("--out", default=None, help="also write the JSON dict to FILE")
  args = ap.parse_args(argv)
  t0 = time.perf_counter()
  deadline = t0 + args.budget_s
  dev = jax.devices()[0]
  report = dict(device=dict(platform=dev.platform, device_kind=dev.device_kind, jax=jax.__version__,
                            jaxlib=_jaxlib_version(),
                            python=platform.python_version()),
                ptx_capture=_record_ptx(), targets=dict(cells_per_s=1e12, pct_of_copy=70))
  big = (24, 40, 48, 150, 170) if args.quick else (16384, 200, 200, 2000, 2000)
  odd = (8, 13, 37, 61, 59) if args.quick else (4096, 211, 197, 1999, 2003)
  mixed = (16, 40, 48, 150, 170) if args.quick else (512, 200, 200, 2000, 2000)
  repeats = 5 if args.quick else REPEATS
  tunings = {k: dataclasses.replace(t, interpret=args.interpret) for k, t in TUNINGS.items()}
  report.update(repeats=repeats, interpret=args.interpret)

  def section(name, fn):
    if time.perf_counter() > deadline:
      report[name] = dict(skipped="time budget spent")
      return
    _log(f"{name} ...")
    try:
      report[name] = fn()
    except Exception as e:  # noqa: BLE001
      report[name] = _error(e)
    report[name + "_wall_s"] = round(time.perf_counter() - t0, 1)
    if args.out:
      with open(args.out, "w") as f:
        json.dump(report, f, default=str)

  fleet = {}
  section("inputs", lambda: fleet.update(main=make_fleet(0, *big)) or dict(main=list(big)))
  if "main" in fleet:
    nbytes = int(np.prod(fleet["main"]["cost"].shape))
    section("copy", lambda: copy_ceiling(nbytes, repeats))
    section("aligned", lambda: check_and_time(fleet["main"], tunings, repeats, deadline))
    section("kernels_alone", lambda: kernels_alone(fleet["main"], tunings, repeats, deadline))
    fleet.pop("main")
  # Every 8th robot at twice the resolution: those take the XLA gather (bit-equality only).
  section("mixed_check", lambda: check_and_time(
      make_fleet(1, *mixed, other_res_every=8), {k: tunings[k] for k in ("flat2048_w4", "flat2048_w4_in_place")},
      repeats, deadline, timing=False))
  section("odd_shape", lambda: check_and_time(make_fleet(2, *odd), {k: tunings[k] for k in ("flat2048_w4",
                                                                                            "rows2048_w4")},
                                              repeats, deadline))

  copy_bps = (report.get("copy") or {}).get("ceiling_bytes_per_s")
  for key in ("aligned", "odd_shape"):
    sec = report.get(key) or {}
    cells = sec.get("cells")
    if not cells:
      continue
    for name in ("xla", "xla_donated"):
      if "steady_s" in sec.get(name, {}):
        sec[name] = _cells_fig(sec[name], cells, copy_bps)
    for r in sec.get("pallas", {}).values():
      if "steady_s" in r:
        r.update(_cells_fig({k: r[k] for k in ("steady_s", "min_s", "runs")}, cells, copy_bps))
  summary = {}
  sec = report.get("aligned") or {}
  for name, r in [("xla", sec.get("xla", {})), ("xla_donated", sec.get("xla_donated", {}))] + \
      [(f"pallas:{k}", v) for k, v in sec.get("pallas", {}).items()]:
    if "cells_per_s" in r:
      checks = r.get("bit_equal_to_xla", {})
      summary[name] = dict(Gcell_per_s=round(r["cells_per_s"] / 1e9, 1),
                           pct_of_copy=r.get("pct_of_copy_at_3_bytes_per_cell"),
                           bit_equal=all(v["equal"] for v in checks.values()) if checks else None)
    elif "error" in r:
      summary[name] = r["error"][:200]
  report["summary_aligned"] = summary
  report["copy_ceiling_bytes_per_s"] = copy_bps
  report["total_wall_s"] = round(time.perf_counter() - t0, 1)
  text = json.dumps(report, default=str)
  if args.out:
    with open(args.out, "w") as f:
      f.write(text + "\n")
  print(text)
  return 0


def _jaxlib_version():
  try:
    import jaxlib  # noqa: PLC0415
    return jaxlib.__version__
  except Exception:  # noqa: BLE001
    return None


if __name__ == "__main__":
  sys.exit(main())
