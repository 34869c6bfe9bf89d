"""GPU probe of the same-frame keepout prologue (issue 9): one device call, one JSON line.

    PYTHONPATH=$PWD python3 benchmarks/prologue_probe.py [--quick] [--budget-s 100] [--out FILE]

At B = 16384 costmaps of 200 x 200 uint8 and one 2000 x 2000 mask (--quick: 256
costmaps of 40 x 40, a 200 x 200 mask: a CPU smoke run), it times

- the prologue alone: "old" (the index vectors [B, W] and [B, H], bracketed, the exact
  reruns through `keepout._rerun`'s data-dependent loop, the window clip with its rerun,
  `_consecutive` and the window flags: the code before issue 9's change, rebuilt from
  the helpers keepout.py keeps) against "new" (`keepout._same_frame_prologue`: per-robot
  scalars, exact branches only under a batch-level `lax.cond`), on the aligned fleet
  (costmap 0.05 as a double, mask float32 0.05) and the other-resolution one (costmap
  0.05 double, mask 0.1);
- the whole `keepout_filter` on both fleets with the XLA path and `kernel="pallas"`.

Each figure: compile seconds, the median of the timed runs after warm-ups (with
block_until_ready), cells per second, and what the compiled program runs at its top level
(fusions, while loops, conditionals, custom calls). The new prologue's answers are checked
against the old one's (same sliced robots, same starts where sliced, same windows). Each
variant runs in its own try block: a failure is reported with its message and the probe
goes on; the exit status is 0. The budget skips what is left once spent, saying so.
"""

from __future__ import annotations

import argparse
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
from jaxfilters import geometry
from jaxfilters import keepout as ko
from jaxfilters.grid import OccupancyGrid
from jaxfilters.keepout_pallas import PallasTuning

REPEATS = 20


def _log(msg):
  print(f"[prologue_probe {time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def _error(e: BaseException) -> dict:
  return dict(error=f"{type(e).__name__}: {str(e)[:1500]}", trace=traceback.format_exc(limit=5)[-3000:])


def make_fleet(seed, b, h, w, hm, wm, *, mask_res):
  """Same-frame inputs: costmaps at 0.05 m (a double), windows rolling over the mask, some partly off."""
  rng = np.random.default_rng(seed)
  data = rng.choice(np.asarray([-1, 0, 0, 0, 30, 60, 99, 100], np.int8), (hm // 8 + 1, wm // 8 + 1))
  data = np.repeat(np.repeat(data, 8, 0), 8, 1)[:hm, :wm].copy()
  grid = OccupancyGrid.create(data, mask_res, (0.35, -0.2))
  mask = jf.FilterMask.create(grid, jf.FilterInfo.create(0))
  span = np.asarray([wm, hm]) * mask_res / 0.05
  k = rng.integers(-np.asarray([w, h]) // 4, (span - 3 * np.asarray([w, h]) // 4).astype(int), (b, 2))
  origin = np.asarray([0.35, -0.2]) + k * 0.05                         # float64: carried as float32 parts
  shell = jf.Costmap.create(np.zeros((b, 1, 1), np.uint8), origin, 0.05)
  cost = jax.random.bits(jax.random.key(seed), (b, h, w), jnp.uint8)
  x0, y0 = rng.integers(-3, w // 2, b), rng.integers(-3, h // 2, b)
  window = np.stack([x0, y0, x0 + rng.integers(1, w + 4, b), y0 + rng.integers(1, h + 4, b)], 1).astype(np.int32)
  return dict(cost=cost, shell=shell, mask=mask, state=jf.KeepoutState.create(b), window=jnp.asarray(window))


def _inputs(fleet):
  cm = dataclasses.replace(fleet["shell"], cost=fleet["cost"])
  b = cm.num_robots
  idx, ok, _, en, win, _ = ko._batched_inputs(cm, fleet["mask"], jnp.zeros((b, 3)), None, None, fleet["window"],
                                              None, "prologue_probe")
  return cm, idx, ok, en, win


def old_prologue(costmap, mask, idx, idx_ok, window, enabled):
  """The prologue before issue 9 (index vectors, `_rerun` loops, `_consecutive`), rebuilt from keepout's helpers."""
  b, h, w = costmap.cost.shape
  hm, wm = mask.data.shape[1:]
  geo = ko._robot_geometry(costmap, mask)
  in_axes = (*(None if g is None else 0 for g in geo), 0, 0, 0, 0)
  args = (*geo, idx, idx_ok, window, enabled)

  def prologue(origin, origin_lo, res, res_lo, i, ok, win, en, *, part="both", exact=False):
    return ko._same_frame_prologue_one((h, w), geometry.origin_terms(origin, origin_lo),
                                       geometry.resolution_terms(res, res_lo), ko._mask_origin(mask, i),
                                       mask.resolution[i], (hm, wm), win, en, ok, part=part, exact=exact)

  def exact(part):
    return lambda a: jax.vmap(functools.partial(prologue, part=part, exact=True), in_axes=in_axes)(*a)[0]

  cells, cells_known, flags, flags_known = jax.vmap(prologue, in_axes=in_axes)(*args)
  (mx, vx), (my, vy) = ko._rerun(~cells_known, cells, exact("cells"), args, ko._rerun_capacity(b))
  col_ok, row_ok, run = ko._rerun(~flags_known, flags, exact("flags"), args, max(8, b // 16))
  k0x, okx = jax.vmap(ko._consecutive, in_axes=(0, 0, None))(mx, vx, wm)
  k0y, oky = jax.vmap(ko._consecutive, in_axes=(0, 0, None))(my, vy, hm)
  return col_ok, row_ok, run, ko._slice_start(k0x, w, wm), ko._slice_start(k0y, h, hm), okx & oky


def _summary(compiled) -> dict:
  text = compiled.as_text()
  entry = text[text.index("ENTRY"):]
  entry = entry[:entry.index("\n}")]
  count = lambda s, op: len(re.findall(rf"[\s)]{op}\(", s))    # an instruction's opcode
  return dict(fusions=count(text, "fusion"), whiles=count(text, "while"), entry_whiles=count(entry, "while"),
              conditionals=count(text, "conditional"), custom_calls=count(text, "custom-call"),
              entry_kernels=count(entry, "fusion") + count(entry, "custom-call"))


def _timed(fn, args, repeats, cells=None) -> dict:
  jitted = jax.jit(fn)
  t = time.perf_counter()
  compiled = jitted.lower(*args).compile()
  out = dict(compile_s=round(time.perf_counter() - t, 3), hlo=_summary(compiled))
  for _ in range(3):
    jax.block_until_ready(compiled(*args))
  times = []
  for _ in range(repeats):
    t = time.perf_counter()
    jax.block_until_ready(compiled(*args))
    times.append(time.perf_counter() - t)
  out.update(steady_s=float(np.median(times)), min_s=float(np.min(times)), runs=repeats)
  if cells:
    out["gcells_per_s"] = round(cells / out["steady_s"] / 1e9, 1)
  return out


def _agree(fleet) -> dict:
  """The new prologue's answers against the old one's, robot by robot."""
  cm, idx, ok, en, win = _inputs(fleet)
  mask = fleet["mask"]
  col_ok, row_ok, run_o, sx_o, sy_o, sl_o = jax.jit(old_prologue)(cm, mask, idx, ok, win, en)
  box, run, sx, sy, sl = jax.jit(ko._same_frame_prologue)(cm, mask, idx, ok, win, en)
  h, w = cm.cost.shape[1:]
  flags = jax.vmap(lambda x0, y0, x1, y1: ko._window_flags(w, h, x0, y0, x1, y1, True))(*box)
  writes = jnp.any(col_ok, 1) & jnp.any(row_ok, 1)      # a robot that writes nothing has no window to compare
  new_writes = jnp.any(flags[0], 1) & jnp.any(flags[1], 1)
  same_window = ~writes | (jnp.all(flags[0] == col_ok, 1) & jnp.all(flags[1] == row_ok, 1))
  both = sl & sl_o & writes
  return dict(robots=int(cm.num_robots), sliced_old=int(jnp.sum(sl_o)), sliced_new=int(jnp.sum(sl)),
              sliced_old_not_new=int(jnp.sum(sl_o & ~sl & writes)),
              same_writers=bool(jnp.array_equal(writes, new_writes)), same_windows=bool(jnp.all(same_window)),
              same_run=bool(jnp.array_equal(run, run_o)),
              same_starts_where_both_slice_and_write=bool(jnp.all(~both | ((sx == sx_o) & (sy == sy_o)))))


def main(argv=None):
  p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  p.add_argument("--quick", action="store_true", help="small sizes (a CPU smoke run)")
  p.add_argument("--budget-s", type=float, default=100.0, help="skip what is left after this many seconds")
  p.add_argument("--repeats", type=int, default=REPEATS)
  p.add_argument("--out", help="also write the JSON line to this file")
  a = p.parse_args(argv)
  start = time.perf_counter()
  b, h, w, hm, wm = (256, 40, 40, 200, 200) if a.quick else (16384, 200, 200, 2000, 2000)
  dev = jax.devices()[0]
  result = dict(probe="prologue_probe", device=dict(platform=dev.platform, device_kind=dev.device_kind,
                                                    jax=jax.__version__, python=platform.python_version()),
                params=dict(B=b, H=h, W=w, mask=[hm, wm], costmap_res="0.05 (double)", repeats=a.repeats),
                figures={})
  pallas = jax.default_backend() == "gpu" or a.quick
  configs = {"xla": ko.KeepoutConfig()}
  if pallas:
    configs["pallas"] = ko.KeepoutConfig(kernel="pallas", pallas=PallasTuning(interpret=dev.platform != "gpu"))
  for fleet_name, mask_res in (("aligned", 0.05), ("other_res", 0.1)):
    fig = result["figures"][fleet_name] = dict(mask_res=mask_res)
    try:
      fleet = make_fleet(1, b, h, w, hm, wm, mask_res=mask_res)
      jax.block_until_ready(fleet["cost"])
      fig["agreement"] = _agree(fleet)
    except Exception as e:  # noqa: BLE001
      fig["inputs"] = _error(e)
      continue
    cm, idx, ok, en, win = _inputs(fleet)
    variants = {"prologue_old": (old_prologue, (cm, fleet["mask"], idx, ok, win, en), None),
                "prologue_new": (ko._same_frame_prologue, (cm, fleet["mask"], idx, ok, win, en), None)}
    for name, config in configs.items():
      fn = functools.partial(lambda c, cm, mask, st, win, config: jf.keepout_filter(
          dataclasses.replace(cm, cost=c), mask, jnp.zeros((c.shape[0], 3)), st, window=win, config=config)[0].cost,
          config=config)
      variants[f"filter_{name}"] = (fn, (fleet["cost"], fleet["shell"], fleet["mask"], fleet["state"],
                                         fleet["window"]), b * h * w)
    for name, (fn, args, cells) in variants.items():
      if time.perf_counter() - start > a.budget_s:
        fig[name] = dict(skipped="time budget spent")
        continue
      _log(f"{fleet_name} {name}")
      try:
        fig[name] = _timed(fn, args, 3 if (a.quick and "pallas" in name) else a.repeats, cells)
      except Exception as e:  # noqa: BLE001
        fig[name] = _error(e)
  result["wall_s"] = round(time.perf_counter() - start, 1)
  line = json.dumps(result)
  print(line)
  if a.out:
    with open(a.out, "w") as f:
      f.write(line + "\n")
  return 0


if __name__ == "__main__":
  sys.exit(main())
