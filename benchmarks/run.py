"""One benchmark harness: compile time apart from steady state, device named, baselines in the same run.

    python -m benchmarks --json [--quick] [--only keepout_aligned,speed] [--robots N] [--out FILE]

Every figure is a dict with its parameters (B, H, W, mask size, dtype),
`compile_s` (lower + compile), `steady_s` (median of `repeats` runs after
`block_until_ready`, inputs rotated among >= 2 sets so caches do not flatter),
`throughput` and `unit`. `--json` prints one JSON object on stdout; a table
goes to stderr either way.

Every keepout figure also times the Nav2-style C++ peer (benchmarks/nav2_keepout_peer.cpp,
built here with g++ -O2, one core) and the lean C++ loop (benchmarks/lean_keepout_peer.cpp)
on the same inputs after checking their integers, interleaved with the JAX runs, and
reports `speedup_vs_cpp` and `speedup_vs_lean` (ratios of medians of >= 5 runs each);
without a compiler `cpp_peer` / `cpp_lean_peer` say why they were skipped.
"""

from __future__ import annotations

import inspect
import json
import math
import platform
import sys
import time
import traceback

import jax
import jax.numpy as jnp
import numpy as np

import jaxfilters as jf
from jaxfilters.grid import OccupancyGrid

from benchmarks import nav2_peer
from jaxfilters.cli import ArgumentParser  # one-line errors, exit code 2

RES = 0.05
# The keepout figures of `bench_keepout` / `bench_keepout_pallas` and their masks' resolution.
KEEPOUT_MASK_RES = {"keepout_aligned": RES, "keepout_aligned_pallas": RES, "keepout_other_res": 2 * RES,
                    "keepout_transform": RES, "keepout_transform_xla": RES}
KEEPOUT_FIGURES = tuple(KEEPOUT_MASK_RES)
NAMES = ("bandwidth", *KEEPOUT_FIGURES, "speed", "binary", "zone", "inflation", "pipeline", "baseline_keepout",
         "baseline_speed", "fleet")


def sizes(platform_name: str, quick: bool) -> dict:
  if quick:
    return dict(keepout_b=32, hw=100, mask=500, filter_b=256, infl_b=16, pipe_b=16, copy_mb=32,
                base_keepout_b=4, base_speed_b=64, fleet_robots=8, fleet_steps=5, repeats=5, cpp_keepout_b=32)
  # cpp_keepout_b: robots the C++ peer runs (the first ones of the same inputs); all of them on
  # the CPU, a 256-robot prefix beside a GPU fleet (one core would take minutes for 16384).
  if platform_name == "cpu":
    return dict(keepout_b=256, hw=200, mask=2000, filter_b=4096, infl_b=64, pipe_b=64, copy_mb=256,
                base_keepout_b=16, base_speed_b=512, fleet_robots=1024, fleet_steps=100, repeats=5,
                cpp_keepout_b=256)
  return dict(keepout_b=16384, hw=200, mask=2000, filter_b=65536, infl_b=16384, pipe_b=4096,
              copy_mb=2048, base_keepout_b=16, base_speed_b=512, fleet_robots=65536, fleet_steps=100,
              repeats=7, cpp_keepout_b=256)


# ----------------------------------------------------------------------------- timing


def measure(fn, input_sets, repeats, outputs=None, between=None, after_warmup=None):
  """(compile_s, steady_s median, all steady times) for jitted fn over rotated input sets.

  `outputs`, a list, receives each input set's result from the warm-up runs;
  `between(n)`, if given, runs (untimed here) after the first half of the timed
  runs and after the rest, n being the runs just timed: a baseline timed in two
  blocks between them sees the same machine load (the VM is shared) without
  evicting the caches between two JAX runs. `after_warmup(outputs)` runs once after
  the warm-up (then every set is run once more, untimed, so the allocator is back in
  its steady state: a fresh 10 MB output costs 2,500 page faults, ~3 ms here).
  """
  jitted = jax.jit(fn)
  t = time.perf_counter()
  compiled = jitted.lower(*input_sets[0]).compile()
  compile_s = time.perf_counter() - t
  for args in input_sets:                       # warm every set once (allocations, first touch)
    out = jax.block_until_ready(compiled(*args))
    if outputs is not None:
      outputs.append(out)
  if after_warmup is not None:
    after_warmup(outputs)
    for args in input_sets:
      jax.block_until_ready(compiled(*args))
  times = []
  n = max(repeats, 5)
  for k in range(n):
    args = input_sets[k % len(input_sets)]
    t = time.perf_counter()
    jax.block_until_ready(compiled(*args))
    times.append(time.perf_counter() - t)
    if between is not None and k + 1 in (n // 2, n):
      between(k + 1 - (0 if k + 1 == n // 2 else n // 2))
  return compile_s, float(np.median(times)), times


def figure(name, params, compile_s, steady_s, work, unit, **extra):
  return dict(name=name, params=params, compile_s=round(compile_s, 4), steady_s=steady_s,
              throughput=work / steady_s if steady_s > 0 else float("nan"), unit=unit, **extra)


# ----------------------------------------------------------------------------- inputs


def _mask_data(rng, n, values):
  # Blocky zones (8x8-cell blobs) like a drawn mask, not white noise.
  coarse = rng.choice(np.asarray(values, np.int8), (n // 8 + 1, n // 8 + 1))
  return np.repeat(np.repeat(coarse, 8, 0), 8, 1)[:n, :n]


def keepout_inputs(seed, b, hw, n, mask_res, transform):
  rng = np.random.default_rng(seed)
  data = _mask_data(rng, n, [-1, 0, 0, 0, 0, 0, 30, 60, 100, 100])
  mask = jf.FilterMask.create(OccupancyGrid.create(data, mask_res, (0.0, 0.0)), jf.FilterInfo.create(0))
  span = n * mask_res
  # Rolling windows at random places over the mask, a few partly off it.
  k = rng.integers(-hw // 4, int(span / RES) - 3 * hw // 4, (b, 2))
  origin = (k * RES).astype(np.float32)
  cost = rng.choice(np.asarray([0, 0, 0, 0, 10, 100, 253, 254, 255], np.uint8), (b, hw, hw))
  cm = jf.Costmap.create(cost, origin, RES)
  tf = None
  if transform:
    # T_mask_from_global turns each window about its centre by any yaw and shifts it by up to
    # 1 m, so the rotated window still lies over the mask (a turn about the world origin, as
    # before 2026-11-23, put 3/4 of the cells off the mask, where a per-cell loop stops early).
    tf = turned_windows(rng, origin, hw)
  return cm, mask, tf


def turned_windows(rng, origin, hw):
  """float32 [B, 3] T_mask_from_global turning each hw x hw window (lower-left corner `origin`
  [B, 2], cells of RES) about its centre by a random yaw and shifting it by up to 1 m."""
  b = origin.shape[0]
  yaw = rng.uniform(-np.pi, np.pi, b)
  centre = origin.astype(np.float64) + 0.5 * hw * RES
  c, s = np.cos(yaw), np.sin(yaw)
  turned = np.stack([c * centre[:, 0] - s * centre[:, 1], s * centre[:, 0] + c * centre[:, 1]], 1)
  shift = centre + rng.uniform(-1, 1, (b, 2)) - turned
  return jnp.asarray(np.concatenate([shift, yaw[:, None]], 1).astype(np.float32))


def point_mask(seed, n, ftype, values):
  rng = np.random.default_rng(seed)
  data = _mask_data(rng, n, values)
  info = jf.FilterInfo.create(ftype, base=0.0, multiplier=1.0) if ftype in (1, 3) else jf.FilterInfo.create(ftype)
  return jf.FilterMask.create(OccupancyGrid.create(data, RES, (0.0, 0.0)), info)


def random_poses(seed, b, span):
  rng = np.random.default_rng(seed + 1000)
  return jnp.asarray(np.stack([rng.uniform(-1, span + 1, b), rng.uniform(-1, span + 1, b),
                               rng.uniform(-np.pi, np.pi, b)], 1).astype(np.float32))


# ----------------------------------------------------------------------------- benches


def bench_keepout(kind, sz, b, config=None):
  hw, n = sz["hw"], sz["mask"]
  mask_res = KEEPOUT_MASK_RES[kind]
  transform = kind.startswith("keepout_transform")
  sets = [keepout_inputs(s, b, hw, n, mask_res, transform) for s in range(2)]
  state = jf.KeepoutState.create(b)
  poses = jnp.zeros((b, 3), jnp.float32)
  config = jf.KeepoutConfig() if config is None else config

  def fn(cm, mask, tf):
    out, st = jf.keepout_filter(cm, mask, poses, state, transform=tf, config=config)
    return out.cost, st

  outs = []
  peer = PeerTimer(sets, min(b, sz["cpp_keepout_b"]))
  lean = PeerTimer(sets, min(b, sz["cpp_keepout_b"]), source=nav2_peer.LEAN_SOURCE)

  def between(n):
    peer.block(n)
    lean.block(n)

  def prepare(o):
    peer.prepare([x[0] for x in o])
    lean.prepare([x[0] for x in o])

  c, s, _ = measure(fn, sets, sz["repeats"], outputs=outs, between=between, after_warmup=prepare)
  cells = b * hw * hw
  fig = figure(kind, dict(B=b, H=hw, W=hw, mask=[n, n], mask_res=mask_res, costmap_res=RES,
                          dtype="uint8 cost, int8 mask", transform=transform, kernel=config.kernel,
                          frame_kernel=config.frame_kernel),
               c, s, cells, "cells/s", bytes_per_cell=3)
  fig["cpp_peer"] = peer.result()
  fig["cpp_lean_peer"] = lean.result()
  try:   # which fast-path branches these inputs take (counts over the first 64 robots)
    from benchmarks.keepout_paths import path_report  # noqa: PLC0415
    cm, mask, tf = sets[0]
    sub = min(b, 64)
    fig["paths"] = path_report(jax.tree.map(lambda x: x[:sub], cm), mask, None if tf is None else tf[:sub])
  except Exception as e:  # noqa: BLE001 - a report, never a reason to lose the figure
    fig["paths"] = f"unavailable: {type(e).__name__}: {e}"
  return fig


def bench_keepout_pallas(sz, b):
  """keepout_aligned through the Pallas kernel (`KeepoutConfig(kernel="pallas")`, default tuning)."""
  backend = jax.default_backend()
  if backend != "gpu":
    return dict(name="keepout_aligned_pallas", skipped=f"needs a GPU backend (the Pallas kernel lowers through "
                                                       f"Triton); this run's backend is {backend!r}")
  return bench_keepout("keepout_aligned_pallas", sz, b, config=jf.KeepoutConfig(kernel="pallas"))


class PeerTimer:
  """The C++ peer on the first b robots of each (costmap, mask, transform) set.

  `prepare(costs)` checks the peer against `costs` (the result to match, per set)
  and warms it; `block(n)` times n peer runs, rotating the sets, on preallocated
  buffers (no allocation that would disturb the JAX runs' allocator state); the
  callers time blocks between blocks of their own runs. `result()` is the figure's
  `cpp_peer` entry.
  """

  def __init__(self, sets, b, label="JAX", source=nav2_peer.SOURCE):
    self.fn, self.desc = nav2_peer.build(source)
    self.b, self.label, self.times, self.checks = b, label, [], []
    if self.fn is not None:
      self.inputs = [nav2_peer.host_inputs(cm, mask, transform=tf, num_robots=b) for cm, mask, tf in sets]

  def prepare(self, costs):
    if self.fn is None:
      return
    self.checks = [nav2_peer.check(self.fn, inp, np.asarray(c[:self.b]), self.label)
                   for inp, c in zip(self.inputs, costs)]
    self.buffers = [inp["cost"].copy() for inp in self.inputs]
    for inp, buf in zip(self.inputs, self.buffers):     # warm (first touch), untimed
      nav2_peer.run(self.fn, inp, buf)

  def block(self, n):
    if self.fn is None:
      return
    for k in range(n):
      inp, buf = self.inputs[k % len(self.inputs)], self.buffers[k % len(self.inputs)]
      np.copyto(buf, inp["cost"])
      self.times.append(nav2_peer.run(self.fn, inp, buf)[1])

  def result(self):
    if self.fn is None:
      return dict(skipped=self.desc)
    steady = float(np.median(self.times))
    h, w = self.inputs[0]["cost"].shape[1:]
    return dict(impl=self.desc, B=self.b, steady_s=steady, throughput=self.b * h * w / steady, unit="cells/s",
                timed="in two blocks between two blocks of the runs it is compared with", check=self.checks[0] +
                f" (and {len(self.checks) - 1} more input set(s) checked the same way)")


def bench_point_filter(kind, sz, b):
  n = sz["mask"]
  span = n * RES
  if kind == "speed":
    sets = [(point_mask(s, n, 1, [0, 10, 30, 50, 100, -1]), random_poses(s, b, span)) for s in range(2)]
    state = jf.SpeedState.create(b)
    fn = lambda m, p: jf.speed_filter(m, p, state)
  elif kind == "binary":
    sets = [(point_mask(s, n, 3, [0, 0, 100, -1]), random_poses(s, b, span)) for s in range(2)]
    state = jf.BinaryState.create(b) if hasattr(jf.BinaryState, "create") else jf.BinaryState(jnp.zeros((b,), bool))
    fn = lambda m, p: jf.binary_filter(m, p, state)
  else:
    table = jf.ZoneTable.create(["max_vel", "inflation"], {"max_vel": 1.0, "inflation": 0.5},
                                {1: {"max_vel": 0.3}, 2: {"inflation": 0.2}, 3: {"max_vel": 0.5, "inflation": 0.1}})
    sets = [(point_mask(s, n, 4, [0, 1, 2, 3, -1]), random_poses(s, b, span)) for s in range(2)]
    state = jf.ZoneState.create(table, b)
    fn = lambda m, p: jf.zone_filter(m, p, state, table)
  c, s, _ = measure(fn, sets, sz["repeats"])
  return figure(kind, dict(B=b, mask=[n, n], dtype="int8 mask, float32 poses"), c, s, b, "robots/s")


def _inflation_config():
  return jf.InflationConfig(inflation_radius=0.7, cost_scaling_factor=10.0, inscribed_radius=0.22,
                            resolution=RES)


def bench_inflation(sz, b):
  hw = sz["hw"]
  cfg = _inflation_config()
  sets = []
  for s in range(2):
    rng = np.random.default_rng(s)
    sets.append((jnp.asarray(rng.choice(np.asarray([0, 0, 0, 0, 0, 0, 0, 254, 255], np.uint8), (b, hw, hw))),))
  c, st, _ = measure(lambda cost: jf.inflate(cost, config=cfg), sets, sz["repeats"])
  return figure("inflation", dict(B=b, H=hw, W=hw, R=cfg.cell_radius, res=RES, dtype="uint8"), c, st,
                b * hw * hw, "cells/s")


def bench_pipeline(sz, b):
  hw, n = sz["hw"], sz["mask"]
  cfg = jf.LayersConfig(inflation=_inflation_config())
  sets = []
  for s in range(2):
    cm, kmask, _ = keepout_inputs(s, b, hw, n, RES, False)
    rng = np.random.default_rng(s + 7)
    static = jnp.asarray(rng.choice(np.asarray([0, 0, 0, 0, 0, 0, 100, -1], np.int8), (b, hw, hw)))
    smask = point_mask(s, n, 1, [0, 10, 30, 50, 100, -1])
    poses = random_poses(s, b, n * RES)
    sets.append((static, cm.origin, cm.resolution, poses, kmask, smask))
  kst, sst = jf.KeepoutState.create(b), jf.SpeedState.create(b)

  def fn(static, origin, res, poses, kmask, smask):
    out = jf.costmap_pipeline(static, origin, res, poses, config=cfg, keepout_mask=kmask, keepout_state=kst,
                              speed_mask=smask, speed_state=sst)
    return out.combined.cost, out.speed

  c, st, _ = measure(fn, sets, sz["repeats"])
  return figure("pipeline", dict(B=b, H=hw, W=hw, mask=[n, n], R=_inflation_config().cell_radius,
                                 stages="static+inflation+keepout+speed", dtype="int8 in, uint8 out"),
                c, st, b * hw * hw, "cells/s")


def bench_bandwidth(sz):
  """Memory roofline: x + 1 over a large uint32 array (4-byte words, as a copy kernel moves
  them), bytes read + written. The same op on uint8 is reported beside it: XLA's byte-wise
  elementwise loop runs well below this on GPU, which is why keepout packs bytes into words."""
  n = sz["copy_mb"] << 20
  sets = [(jnp.full((n // 4,), s, jnp.uint32),) for s in range(2)]
  c, st, _ = measure(lambda x: x + jnp.uint32(1), sets, sz["repeats"])
  fig = figure("bandwidth", dict(bytes=n, dtype="uint32", op="x + 1 (read + write)"), c, st, 2 * n, "bytes/s")
  sets8 = [(jnp.full((n,), s, jnp.uint8),) for s in range(2)]
  c8, st8, _ = measure(lambda x: x + jnp.uint8(1), sets8, sz["repeats"])
  fig["uint8_same_op_bytes_per_s"] = 2 * n / st8
  del sets, sets8
  torch_bw = _torch_copy_bandwidth(n, sz["repeats"])
  if torch_bw:
    fig["torch_copy_bytes_per_s"] = torch_bw
  # The roofline is the best copy rate measured in this call (a JAX elementwise loop
  # does not reach the card's copy rate; the device's own copy engine path does).
  fig["roofline_bytes_per_s"] = max(fig["throughput"], torch_bw or 0.0)
  fig["roofline_label"] = roofline_label(fig)
  return fig


def roofline_label(fig: dict) -> str:
  """Which copy set a bandwidth figure's roofline: PyTorch's device-to-device copy or JAX's `x + 1`."""
  torch_bw = fig.get("torch_copy_bytes_per_s")
  return "PyTorch D2D copy" if torch_bw and torch_bw >= fig["throughput"] else "JAX x + 1 copy"


def _torch_copy_bandwidth(n: int, repeats: int) -> float | None:
  """Device-to-device copy through PyTorch (bytes read + written per second), if torch+CUDA exist."""
  try:
    import torch  # noqa: PLC0415 - optional: only on machines that have it
  except ImportError:
    return None
  if not torch.cuda.is_available():
    return None
  a = torch.empty(n, dtype=torch.uint8, device="cuda").random_(0, 255)
  b = torch.empty_like(a)
  b.copy_(a)
  torch.cuda.synchronize()
  times = []
  for _ in range(max(5, repeats)):
    start, end = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
    start.record()
    b.copy_(a)
    end.record()
    torch.cuda.synchronize()
    times.append(start.elapsed_time(end) / 1e3)
  del a, b
  torch.cuda.empty_cache()
  return 2 * n / float(np.median(times))


# NumPy baselines: what a Python user writes today (vectorised per robot, a loop over robots).


def numpy_keepout_one(cost, origin, res, data, mask_origin, mask_res):
  h, w = cost.shape
  hm, wm = data.shape
  x = origin[0] + (np.arange(w) + 0.5) * res
  y = origin[1] + (np.arange(h) + 0.5) * res
  mx = np.floor((x - mask_origin[0]) / mask_res).astype(np.int64)
  my = np.floor((y - mask_origin[1]) / mask_res).astype(np.int64)
  vx = (x >= mask_origin[0]) & (mx < wm)
  vy = (y >= mask_origin[1]) & (my < hm)
  d = data[np.clip(my, 0, hm - 1)[:, None], np.clip(mx, 0, wm - 1)[None, :]].astype(np.int64)
  mc = np.where((d >= 0) & (d <= 100), np.floor(d * 2.54 + 0.5), 255)
  write = vy[:, None] & vx[None, :] & (mc != 255) & ((mc > cost) | (cost == 255))
  return np.where(write, mc, cost).astype(np.uint8)


def bench_baseline_keepout(sz, b):
  hw, n = sz["hw"], sz["mask"]
  sets, cpu_sets = [], []
  for s in range(2):
    cm, mask, _ = keepout_inputs(s, b, hw, n, RES, False)
    cpu_sets.append((cm, mask, None))
    sets.append((np.asarray(cm.cost), np.asarray(cm.origin, np.float64), float(cm.resolution[0]),
                 np.asarray(mask.data[0]), np.asarray(mask.origin[0], np.float64), float(mask.resolution[0])))
  # The peer on the same inputs, timed in turn with the NumPy loop; its integers checked
  # against the NumPy loop's (aligned geometry: no cell centre near a mask-cell edge, so
  # float64 NumPy is exact here).
  numpy_out = [np.stack([numpy_keepout_one(c[r], o[r], rs, d, mo, mr) for r in range(b)])
               for c, o, rs, d, mo, mr in sets]
  peer = PeerTimer(cpu_sets, b, label="the NumPy loop")
  peer.prepare(numpy_out)
  times = []
  runs = max(sz["repeats"], 5)
  for k in range(runs):
    cost, origin, res, data, mo, mres = sets[k % 2]
    t = time.perf_counter()
    for r in range(b):
      numpy_keepout_one(cost[r], origin[r], res, data, mo, mres)
    times.append(time.perf_counter() - t)
    if k + 1 in (runs // 2, runs):
      peer.block(runs // 2 if k + 1 == runs // 2 else runs - runs // 2)
  st = float(np.median(times))
  fig = figure("baseline_keepout", dict(B=b, H=hw, W=hw, mask=[n, n], impl="numpy per-robot loop, float64",
                                        dtype="uint8 cost, int8 mask"), 0.0, st, b * hw * hw, "cells/s")
  fig["cpp_peer"] = peer.result()
  return fig


def bench_baseline_speed(sz, b):
  n = sz["mask"]
  sets = []
  for s in range(2):
    m = point_mask(s, n, 1, [0, 10, 30, 50, 100, -1])
    sets.append((np.asarray(m.data[0]), np.asarray(random_poses(s, b, n * RES), np.float64)))
  times = []
  for k in range(max(sz["repeats"], 5)):
    data, poses = sets[k % 2]
    hm, wm = data.shape
    prev = np.zeros(b)
    t = time.perf_counter()
    for r in range(b):
      x, y = poses[r, 0], poses[r, 1]
      mx, my = int(math.floor(x / RES)), int(math.floor(y / RES))
      if x < 0 or y < 0 or mx >= wm or my >= hm:
        continue
      d = int(data[my, mx])
      if d == -1:
        continue
      limit = 0.0 if d == 0 else d * 1.0 + 0.0
      if limit < 0.0 or limit > 100.0:
        limit = 0.0
      prev[r] = limit
    times.append(time.perf_counter() - t)
  st = float(np.median(times))
  return figure("baseline_speed", dict(B=b, mask=[n, n], impl="python per-robot loop"), 0.0, st, b, "robots/s")


def bench_fleet(sz, b):
  try:
    from sims.scale import bench as sims_bench
    fn = sims_bench.fleet_throughput
  except Exception as e:  # noqa: BLE001 - reported, not raised
    return dict(name="fleet", error=f"sims.scale.bench.fleet_throughput unavailable: {type(e).__name__}: {e}")
  out = dict(name="fleet", signature=str(inspect.signature(fn)),
             params=dict(num_robots=b, num_steps=sz["fleet_steps"], impl="jax"))
  for key, filters in (("filters_on", True), ("bare_mjx", False)):
    try:
      r = fn(b, sz["fleet_steps"], filters=filters, impl="jax")
      out[key] = r if isinstance(r, (dict, int, float, str)) else repr(r)
    except Exception as e:  # noqa: BLE001
      out[key] = dict(error=f"{type(e).__name__}: {e}", trace=traceback.format_exc(limit=3))
  return out


# ----------------------------------------------------------------------------- driver


def device_info() -> dict:
  d = jax.devices()[0]
  return dict(platform=d.platform, device_kind=d.device_kind, num_devices=jax.device_count(),
              jax=jax.__version__, python=platform.python_version(), host=platform.node())


def _fmt(x, unit):
  if not isinstance(x, (int, float)) or not math.isfinite(x):
    return str(x)
  for p, s in ((1e12, "T"), (1e9, "G"), (1e6, "M"), (1e3, "k")):
    if abs(x) >= p:
      return f"{x / p:.3g} {s}{unit}"
  return f"{x:.3g} {unit}"


def table(report) -> str:
  lines = [f"device: {report['device']['device_kind']} ({report['device']['platform']}), jax {report['device']['jax']}",
           f"{'name':22s} {'B':>7s} {'compile_s':>10s} {'steady_s':>10s} {'throughput':>18s}  note"]
  for name, r in report["results"].items():
    if "error" in r:
      lines.append(f"{name:22s} ERROR {r['error'][:90]}")
      continue
    if "skipped" in r:
      lines.append(f"{name:22s} skipped: {r['skipped'][:100]}")
      continue
    if name == "fleet":
      lines.append(f"{name:22s} {json.dumps({k: v for k, v in r.items() if k in ('filters_on', 'bare_mjx')})[:150]}")
      continue
    b = r["params"].get("B", "")
    note = ""
    if "roofline_pct" in r:
      note = f"{r['roofline_pct']:.1f}% of copy bandwidth at 3 B/cell"
    if "speedup_vs_numpy" in r:
      note += f"  x{r['speedup_vs_numpy']:.2g} vs numpy"
    peer = r.get("cpp_peer")
    if peer and "throughput" in peer:
      note += f"  x{r['speedup_vs_cpp']:.3g} vs C++ peer ({_fmt(peer['throughput'], 'cells/s')}, 1 core)"
    elif peer:
      note += f"  C++ peer skipped: {peer.get('skipped', '')}"
    lean = r.get("cpp_lean_peer")
    if lean and "throughput" in lean:
      note += f"  x{r['speedup_vs_lean']:.3g} vs lean C++ loop ({_fmt(lean['throughput'], 'cells/s')})"
    lines.append(f"{name:22s} {b!s:>7s} {r['compile_s']:10.3f} {r['steady_s']:10.5f} "
                 f"{_fmt(r['throughput'], r['unit']):>18s}  {note}")
  return "\n".join(lines)


def main(argv=None) -> int:
  ap = ArgumentParser(prog="python -m benchmarks", description=__doc__.splitlines()[0])
  ap.add_argument("--json", action="store_true", help="print one JSON object on stdout")
  ap.add_argument("--quick", action="store_true", help="small sizes (CPU smoke run)")
  ap.add_argument("--only", default="", help=f"comma-separated subset of {','.join(NAMES)}")
  ap.add_argument("--robots", type=int, default=None, help="B for every figure (overrides defaults)")
  ap.add_argument("--repeats", type=int, default=None, help="timed runs per figure (>= 5)")
  ap.add_argument("--out", default=None, help="also write the JSON object to FILE")
  args = ap.parse_args(argv)

  dev = device_info()
  sz = sizes(dev["platform"], args.quick)
  if args.repeats:
    sz["repeats"] = max(5, args.repeats)
  only = [n for n in args.only.split(",") if n] or list(NAMES)
  unknown = sorted(set(only) - set(NAMES))
  if unknown:
    ap.error(f"unknown --only names {unknown}; choose from {NAMES}")
  rb = lambda default: args.robots or default

  runners = {
      "bandwidth": lambda: bench_bandwidth(sz),
      "keepout_aligned": lambda: bench_keepout("keepout_aligned", sz, rb(sz["keepout_b"])),
      "keepout_aligned_pallas": lambda: bench_keepout_pallas(sz, rb(sz["keepout_b"])),
      "keepout_other_res": lambda: bench_keepout("keepout_other_res", sz, rb(sz["keepout_b"])),
      "keepout_transform": lambda: bench_keepout("keepout_transform", sz, rb(sz["keepout_b"])),
      # The other frame's XLA edge-table loop, beside the default (the Triton kernel on a GPU).
      "keepout_transform_xla": lambda: bench_keepout("keepout_transform_xla", sz, rb(sz["keepout_b"]),
                                                     config=jf.KeepoutConfig(frame_kernel="xla")),
      "speed": lambda: bench_point_filter("speed", sz, rb(sz["filter_b"])),
      "binary": lambda: bench_point_filter("binary", sz, rb(sz["filter_b"])),
      "zone": lambda: bench_point_filter("zone", sz, rb(sz["filter_b"])),
      "inflation": lambda: bench_inflation(sz, rb(sz["infl_b"])),
      "pipeline": lambda: bench_pipeline(sz, rb(sz["pipe_b"])),
      "baseline_keepout": lambda: bench_baseline_keepout(sz, sz["base_keepout_b"]),
      "baseline_speed": lambda: bench_baseline_speed(sz, sz["base_speed_b"]),
      "fleet": lambda: bench_fleet(sz, rb(sz["fleet_robots"])),
  }
  results = {}
  t0 = time.perf_counter()
  for name in NAMES:
    if name not in only:
      continue
    t = time.perf_counter()
    try:
      results[name] = runners[name]()
    except Exception as e:  # noqa: BLE001 - one failing figure must not hide the others
      results[name] = dict(name=name, error=f"{type(e).__name__}: {e}", trace=traceback.format_exc(limit=4))
    results[name]["wall_s"] = round(time.perf_counter() - t, 2)
    print(f"[bench] {name} done in {results[name]['wall_s']} s", file=sys.stderr, flush=True)
    if args.out:   # partial results survive a timeout
      with open(args.out, "w") as f:
        json.dump(dict(device=dev, partial=True, sizes=sz, results=results), f, default=str)

  bw_fig = results.get("bandwidth", {})
  bw = bw_fig.get("roofline_bytes_per_s", bw_fig.get("throughput"))
  base = results.get("baseline_keepout", {}).get("throughput")
  for name in KEEPOUT_FIGURES:
    r = results.get(name)
    if r and "throughput" in r and bw:
      r["roofline_pct"] = 100.0 * r["throughput"] * 3 / bw
    if r and "throughput" in r and base:
      r["speedup_vs_numpy"] = r["throughput"] / base
  for name in (*KEEPOUT_FIGURES, "baseline_keepout"):
    r = results.get(name)
    peer = (r or {}).get("cpp_peer", {})
    if "throughput" in (r or {}) and "throughput" in peer:
      r["speedup_vs_cpp"] = r["throughput"] / peer["throughput"]
    lean = (r or {}).get("cpp_lean_peer", {})
    if "throughput" in (r or {}) and "throughput" in lean:
      r["speedup_vs_lean"] = r["throughput"] / lean["throughput"]
  base = results.get("baseline_speed", {}).get("throughput")
  if base and "throughput" in results.get("speed", {}):
    results["speed"]["speedup_vs_numpy"] = results["speed"]["throughput"] / base

  report = dict(device=dev, quick=args.quick, sizes=sz, total_wall_s=round(time.perf_counter() - t0, 2),
                targets=dict(cpu_keepout_cells_per_s=5e9, gpu_keepout_cells_per_s=1e12, gpu_roofline_pct=70),
                results=results)
  text = json.dumps(report, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o))
  if args.out:
    with open(args.out, "w") as f:
      f.write(text + "\n")
  print(table(report), file=sys.stderr)
  if args.json:
    print(text)
  return 0
