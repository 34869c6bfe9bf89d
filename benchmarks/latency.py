"""Latency per call at small and large batches, beside the lean C++ loop, and cold compile times.

    python -m benchmarks.latency                 # B = 1, 8, 64, 1024, 16384, every row
    python -m benchmarks.latency --quick         # B = 1, 8, 64 (a 2-core CPU in a minute or two)
    python -m benchmarks.latency --sizes 1,64 --no-compile

The floor row times one add over the same costmaps (eager and jitted): what any call costs
on the device. For each keepout path (aligned: the mask at the costmap's resolution; other_res: a mask at
twice it; other_frame: a frame transform; aligned_escape: aligned with
`override_lethal_cost` and every robot in a zone) and for the speed filter, the median
microseconds per call over rotated input sets of 60 x 60 windows on a 2000 x 2000 mask:

* eager: the public function called from Python, as in a notebook cell (a result blocked on);
* jitted: the public function inside the caller's `jax.jit`, every input an argument;
* jitted first call: the seconds of the jitted function's first call (trace, compile with the
  exact reruns in the program, one run; persistent compilation cache off), before any eager call;
* lean C++: benchmarks/lean_keepout_peer.cpp (built by benchmarks/nav2_peer.py, g++ -O2,
  one core), on the same robots in the same process, timed between blocks of the JAX runs,
  its integers checked against the JAX output first (nav2_peer.check).

`--compile` (default on) adds the cold seconds of each public entry point's first eager
call at the README's B = 4096 and of a second call at a new B (4000), each entry point in a
fresh interpreter with JAX's persistent compilation cache off. Runs on any backend: the
device is JAX's default one.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import time

import numpy as np

import jaxfilters  # noqa: F401  (first: importing it sets the XLA:CPU flags, jaxfilters/xla_flags.py)

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import jaxfilters as jf  # noqa: E402
from benchmarks import nav2_peer  # noqa: E402
from benchmarks.run import RES, keepout_inputs, point_mask, random_poses  # noqa: E402
from jaxfilters.cli import ArgumentParser  # noqa: E402

HW = 60
MASK = 2000
SIZES = (1, 8, 64, 1024, 16384)
QUICK_SIZES = (1, 8, 64)
KEEPOUT_PATHS = ("aligned", "other_res", "other_frame", "aligned_escape")
_PATH_MASK_RES = {"aligned": RES, "other_res": 2 * RES, "other_frame": RES, "aligned_escape": RES}


def _block(x):
  return jax.block_until_ready(x)


def time_calls(fn, sets, *, min_s=0.3, min_n=7, max_n=300, between=None):
  """Median seconds of fn(*set) over rotated sets (results blocked on), after two warm-ups per set.

  `between(n)`, if given, runs after each half of the timed calls (the C++ peer, so both
  see the same machine load).
  """
  for s in sets:
    _block(fn(*s))
    _block(fn(*s))
  times = []
  t_end = time.perf_counter() + min_s
  half = False
  while len(times) < max_n and (len(times) < min_n or time.perf_counter() < t_end):
    s = sets[len(times) % len(sets)]
    t = time.perf_counter()
    _block(fn(*s))
    times.append(time.perf_counter() - t)
    if between is not None and not half and len(times) >= min_n // 2:
      between(len(times))
      half = True
  if between is not None:
    between(len(times))
  return float(np.median(times)), len(times)


class Lean:
  """The lean C++ loop on one input set's robots, in place on preallocated buffers."""

  def __init__(self, sets):
    self.fn, self.desc = nav2_peer.build(nav2_peer.LEAN_SOURCE)
    self.times = []
    if self.fn is not None:
      self.inputs = [nav2_peer.host_inputs(cm, mask, transform=tf) for cm, mask, tf in sets]
      self.buffers = [inp["cost"].copy() for inp in self.inputs]

  def check(self, costs):
    if self.fn is None:
      return self.desc
    return [nav2_peer.check(self.fn, inp, np.asarray(c), "JAX") for inp, c in zip(self.inputs, costs)][0]

  def block(self, n):
    if self.fn is None:
      return
    for k in range(max(1, n)):
      inp, buf = self.inputs[k % len(self.inputs)], self.buffers[k % len(self.inputs)]
      np.copyto(buf, inp["cost"])
      self.times.append(nav2_peer.run(self.fn, inp, buf)[1])

  def median(self):
    return float(np.median(self.times)) if self.times else float("nan")


def keepout_rows(path, b):
  """Eager, jitted and lean C++ microseconds per call for one keepout path at batch b."""
  sets = [keepout_inputs(s, b, HW, MASK, _PATH_MASK_RES[path], path == "other_frame") for s in range(2)]
  escape = path == "aligned_escape"
  config = jf.KeepoutConfig(override_lethal_cost=escape)
  state = jf.KeepoutState.create(b)
  if escape:
    state = jf.KeepoutState(jnp.ones((b,), bool), jnp.ones((b,), bool), state.acc_box, state.error)
  poses = jnp.zeros((b, 3), jnp.float32)

  def eager(cm, mask, tf):
    return jf.keepout_filter(cm, mask, poses, state, transform=tf, config=config)[0].cost

  jitted_fn = jax.jit(lambda cm, mask, tf, poses, state: jf.keepout_filter(cm, mask, poses, state, transform=tf,
                                                                             config=config)[0].cost)
  jitted = lambda cm, mask, tf: jitted_fn(cm, mask, tf, poses, state)
  # The caller's jit compiles the whole filter, its exact reruns in it, at its first call: timed
  # before any eager call, so no trace of the filter's parts is cached yet.
  t = time.perf_counter()
  _block(jitted(*sets[0]))
  jit_first_s = time.perf_counter() - t
  outs = [np.asarray(eager(*s)) for s in sets]
  for s, o in zip(sets, outs):
    if not np.array_equal(np.asarray(jitted(*s)), o):
      raise AssertionError(f"keepout {path} B={b}: eager and jitted results differ")
  lean = Lean(sets) if not escape else None
  check = lean.check(outs) if lean else "escape mode: no C++ peer (the lean loop has no override)"
  row = dict(filter=f"keepout_{path}", B=b, jit_first_call_s=jit_first_s)
  row["eager_us"], row["eager_n"] = [v if k else v * 1e6 for k, v in enumerate(time_calls(eager, sets))]
  between = lean.block if lean else None
  row["jit_us"], row["jit_n"] = [v if k else v * 1e6 for k, v in enumerate(time_calls(jitted, sets,
                                                                                         between=between))]
  if lean and lean.times:
    row["lean_cpp_us"] = lean.median() * 1e6
    row["jit_vs_cpp"] = row["lean_cpp_us"] / row["jit_us"]
    row["eager_vs_cpp"] = row["lean_cpp_us"] / row["eager_us"]
  row["check"] = check
  return row


def floor_rows(b):
  """The dispatch floor: one add over the same B x 60 x 60 costmaps, eager and jitted (issue 31's
  'trivial jitted op on the same host'); a filter call cannot be faster than this on the device."""
  sets = [(keepout_inputs(s, b, HW, MASK, RES, False)[0].cost,) for s in range(2)]
  eager = lambda c: c + 1
  jitted = jax.jit(lambda c: c + 1)
  row = dict(filter="floor", B=b)
  row["eager_us"], row["eager_n"] = [v if k else v * 1e6 for k, v in enumerate(time_calls(eager, sets))]
  row["jit_us"], row["jit_n"] = [v if k else v * 1e6 for k, v in enumerate(time_calls(jitted, sets))]
  return row


def speed_rows(b):
  sets = [(point_mask(s, MASK, 1, [0, 10, 30, 50, 100, -1]), random_poses(s, b, MASK * RES)) for s in range(2)]
  state = jf.SpeedState.create(b)
  eager = lambda m, p: jf.speed_filter(m, p, state)[1].speed_limit
  jitted_fn = jax.jit(lambda m, p, st: jf.speed_filter(m, p, st)[1].speed_limit)
  jitted = lambda m, p: jitted_fn(m, p, state)
  row = dict(filter="speed", B=b)
  row["eager_us"], row["eager_n"] = [v if k else v * 1e6 for k, v in enumerate(time_calls(eager, sets))]
  row["jit_us"], row["jit_n"] = [v if k else v * 1e6 for k, v in enumerate(time_calls(jitted, sets))]
  return row


# The README's first cell, one entry point per fresh interpreter (persistent cache off).
_COLD = textwrap.dedent("""
    import os, sys, time, json
    t0 = time.perf_counter()
    import jaxfilters  # noqa: F401  (first: importing it sets the XLA:CPU flags, jaxfilters/xla_flags.py)
    import jax
    jax.config.update("jax_enable_compilation_cache", False)
    import numpy as np, jax.numpy as jnp
    import jaxfilters as jf
    from jaxfilters.grid import OccupancyGrid
    entry = sys.argv[1]
    rng = np.random.default_rng(0)
    data = np.zeros((400, 560), np.int8); data[100:200, 100:300] = 100; data[250:260] = -1
    def masks(ftype):
      info = jf.FilterInfo.create(ftype, base=100.0, multiplier=-1.0) if ftype == 1 else jf.FilterInfo.create(ftype)
      return jf.FilterMask.create(OccupancyGrid.create(data, 0.05, (-14.0, -10.0)), info)
    def call(b):
      poses = rng.uniform([-14, -9, -3], [14, 9, 3], (b, 3)).astype(np.float32)
      if entry == "speed_filter":
        out = jf.speed_filter(masks(1), poses, jf.SpeedState.create(b))
      elif entry == "binary_filter":
        out = jf.binary_filter(masks(3), poses, jf.BinaryState.create(b))
      elif entry.startswith("keepout"):
        cm = jf.Costmap.create(np.zeros((b, 60, 60), np.uint8), poses[:, :2] - 1.5, 0.05)
        st = jf.KeepoutState.create(b)
        if entry == "keepout_update_bounds":
          out = jf.keepout_update_bounds(cm, masks(0), poses, st, np.tile([np.inf, np.inf, -np.inf, -np.inf], (b, 1)))
        else:
          tf = None if entry == "keepout_filter" else np.asarray([0.3, -0.2, 0.4], np.float32)
          out = jf.keepout_filter(cm, masks(0), poses, st, transform=tf)
      jax.block_until_ready(out)
    t1 = time.perf_counter(); call(4096); t2 = time.perf_counter(); call(4000); t3 = time.perf_counter()
    print(json.dumps(dict(import_s=t1 - t0, first_call_s=t2 - t1, new_batch_s=t3 - t2)))
""")
COLD_ENTRIES = ("keepout_filter", "keepout_filter_transform", "keepout_update_bounds", "speed_filter",
                "binary_filter")


def cold_compile(entry):
  env = dict(os.environ, JAX_ENABLE_COMPILATION_CACHE="false")
  env.pop("JAX_COMPILATION_CACHE_DIR", None)
  proc = subprocess.run([sys.executable, "-c", _COLD, entry], capture_output=True, text=True, env=env,
                        timeout=900)
  if proc.returncode:
    return dict(entry=entry, error=proc.stderr.strip().splitlines()[-1:])
  return dict(entry=entry, **json.loads(proc.stdout.strip().splitlines()[-1]))


def table(rows):
  lines = ["| filter | B | eager us | jitted us | lean C++ us | C++/jitted | C++/eager | jitted first call s |",
           "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
  f = lambda v, d=1: "" if v is None else (f"{v:.{d}f}" if v < 100 else f"{v:,.0f}")
  for r in rows:
    lines.append(f"| {r['filter']} | {r['B']:,} | {f(r['eager_us'])} | {f(r['jit_us'])} | {f(r.get('lean_cpp_us'))} "
                 f"| {f(r.get('jit_vs_cpp'), 2)} | {f(r.get('eager_vs_cpp'), 2)} | {f(r.get('jit_first_call_s'), 2)} |")
  return "\n".join(lines)


def main(argv=None):
  p = ArgumentParser(prog="python -m benchmarks.latency", description=__doc__.split("\n")[0])
  p.add_argument("--sizes", help="comma-separated batch sizes (default 1,8,64,1024,16384; --quick 1,8,64)")
  p.add_argument("--quick", action="store_true", help="B = 1, 8, 64 only (a CPU in a minute or two)")
  p.add_argument("--paths", default="floor," + ",".join(KEEPOUT_PATHS) + ",speed",
                 help=f"rows to run, comma-separated from floor, {', '.join(KEEPOUT_PATHS)}, speed")
  p.add_argument("--no-compile", dest="compile", action="store_false", help="skip the cold compile rows")
  p.add_argument("--entries", default=",".join(COLD_ENTRIES),
                 help=f"cold compile rows, comma-separated from {', '.join(COLD_ENTRIES)}")
  p.add_argument("--json", help="also write the rows to this JSON file")
  args = p.parse_args(argv)
  try:
    sizes = [int(s) for s in args.sizes.split(",")] if args.sizes else list(QUICK_SIZES if args.quick else SIZES)
  except ValueError:
    p.error(f"--sizes must be comma-separated integers; got {args.sizes!r}")
  if any(b < 1 for b in sizes):
    p.error(f"--sizes must be >= 1; got {args.sizes!r}")
  paths = [s for s in args.paths.split(",") if s]
  unknown = [s for s in paths if s not in ("floor", *KEEPOUT_PATHS, "speed")]
  if unknown:
    p.error(f"--paths: unknown {unknown}; choose from floor, {', '.join(KEEPOUT_PATHS)}, speed")
  entries = [e for e in args.entries.split(",") if e]
  if any(e not in COLD_ENTRIES for e in entries):
    p.error(f"--entries: choose from {', '.join(COLD_ENTRIES)}; got {args.entries!r}")
  # Every compile is a cold one: a persistent cache folder in the environment would turn the
  # jitted first calls into cache reads.
  jax.config.update("jax_enable_compilation_cache", False)
  dev = jax.devices()[0]
  print(f"# {jax.default_backend()} {dev.device_kind}, jax {jax.__version__}, {os.cpu_count()} host cores, "
        f"{HW}x{HW} windows, {MASK}x{MASK} mask", flush=True)
  rows = []
  for path in paths:
    for b in sizes:
      rows.append(speed_rows(b) if path == "speed" else floor_rows(b) if path == "floor" else keepout_rows(path, b))
      r = rows[-1]
      print(f"{r['filter']:24s} B={b:6d} eager {r['eager_us']:10.1f} us  jit {r['jit_us']:10.1f} us"
            + (f"  lean C++ {r['lean_cpp_us']:10.1f} us" if "lean_cpp_us" in r else ""), flush=True)
  print()
  print(table(rows))
  cold = []
  if args.compile:
    print("\n| entry point (cold, no cache) | import s | first call B=4096 s | new B=4000 s |\n| --- | ---: | ---: | ---: |")
    for e in entries:
      c = cold_compile(e)
      cold.append(c)
      if "error" in c:
        print(f"| {e} | failed: {c['error']} | | |", flush=True)
      else:
        print(f"| {e} | {c['import_s']:.2f} | {c['first_call_s']:.2f} | {c['new_batch_s']:.2f} |", flush=True)
  if args.json:
    with open(args.json, "w") as f:
      json.dump(dict(backend=jax.default_backend(), device=dev.device_kind, rows=rows, cold=cold), f, indent=1)
  return 0


if __name__ == "__main__":
  sys.exit(main())
