"""The C++ keepout peers: build, call, check.

Two peers with one C signature: the Nav2-style line-by-line copy of
KeepoutFilter::process (benchmarks/nav2_keepout_peer.cpp, `SOURCE`) and a lean cell
loop without its per-call window arithmetic (benchmarks/lean_keepout_peer.cpp,
`LEAN_SOURCE`). The harness compiles a peer at benchmark time with `g++ -O2` (or
`$CXX`), loads it with ctypes and times it on the same inputs as the JAX paths, on one
core like Nav2's costmap thread. Where no compiler exists the peer is skipped with the
reason.

Before a peer figure is timed its integers are checked: equal to `reference/nav2.py`
(float64, the same arithmetic) on the first robot, and equal to the JAX output on every
robot it runs, cell for cell in the same frame; with a frame transform (SE2) except at
cells whose float64 mask coordinate lies within `SE2_EDGE_BAND_M` of a mask-cell edge
(JAX rotates cell centres in float32, as jaxfilters/keepout/reference.py documents). A failed
check raises, so no ratio is reported against a peer that computes something else.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import pathlib
import shutil
import subprocess
import tempfile
import time

import numpy as np

from reference import nav2 as nav2_reference

SOURCE = pathlib.Path(__file__).with_name("nav2_keepout_peer.cpp")
LEAN_SOURCE = pathlib.Path(__file__).with_name("lean_keepout_peer.cpp")
_SYMBOLS = {SOURCE.name: "nav2_keepout_batch", LEAN_SOURCE.name: "lean_keepout_batch"}
FLAGS = ("-O2", "-ffp-contract=off", "-shared", "-fPIC")
SE2_EDGE_BAND_M = 1e-4       # float32 vs float64 rotation of centres up to ~100 m: ~1e-5 m

_LIBS: dict = {}


def build(source: pathlib.Path = SOURCE):
  """Compiles and loads a peer (`SOURCE` or `LEAN_SOURCE`) once per process.

  Returns:
    (ctypes function or None, description): the description names the compiler and
    flags, or says why the peer was skipped.
  """
  if source not in _LIBS:
    _LIBS[source] = _build(source)
  return _LIBS[source]


def _build(source: pathlib.Path):
  cxx = os.environ.get("CXX") or shutil.which("g++")
  if not cxx:
    return None, "no C++ compiler (g++ not on PATH and CXX unset)"
  if not source.exists():
    return None, f"peer source {source} not found"
  # One build per source, compiler and flags, kept in the temp folder between runs.
  key = hashlib.sha256(source.read_bytes() + " ".join([cxx, *FLAGS]).encode()).hexdigest()[:16]
  out = pathlib.Path(tempfile.gettempdir()) / f"jaxfilters_{source.stem}_{key}.so"
  part = out.with_suffix(f".{os.getpid()}.so")
  cmd = [cxx, *FLAGS, "-o", str(part), str(source)]
  if not out.exists():
    try:
      proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.TimeoutExpired) as e:
      return None, f"{' '.join(cmd)} failed: {type(e).__name__}: {e}"
    if proc.returncode != 0:
      return None, f"{' '.join(cmd)} exited {proc.returncode}: {proc.stderr.strip()[:300]}"
    os.replace(part, out)                       # atomic: a concurrent run never loads half a file
  lib = ctypes.CDLL(str(out))
  fn = getattr(lib, _SYMBOLS[source.name])
  fn.restype = ctypes.c_int
  p = ctypes.c_void_p
  fn.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int, p, p, p, p, ctypes.c_int, ctypes.c_int, p, p, p,
                 p, p, p, ctypes.c_int, ctypes.c_int, p]
  version = subprocess.run([cxx, "--version"], capture_output=True, text=True).stdout.splitlines()[:1]
  return fn, f"{source.name}, {' '.join(version) or cxx} {' '.join(FLAGS[:2])}, ctypes, 1 thread"


def host_inputs(cm, mask, window=None, transform=None, num_robots=None):
  """The float64 values Nav2 holds, from jaxfilters' device pytrees (exact sums of the parts).

  Args:
    cm: jaxfilters.Costmap [B]; mask: jaxfilters.FilterMask; window: int [B, 4] or None
      (whole map); transform: float [B, 3] or None; num_robots: use the first robots only.

  Returns:
    dict of contiguous NumPy arrays for `run`.
  """
  b = cm.num_robots if num_robots is None else num_robots
  parts = lambda hi, lo: (np.asarray(hi, np.float64) if lo is None
                          else np.asarray(hi, np.float64) + np.asarray(lo, np.float64).sum(-1))
  h, w = cm.cost.shape[1:]
  win = np.tile(np.int32([0, 0, w, h]), (b, 1)) if window is None else np.asarray(window, np.int32)[:b]
  return dict(
      cost=np.ascontiguousarray(np.asarray(cm.cost)[:b]),
      origin=np.ascontiguousarray(parts(cm.origin, cm.origin_lo)[:b]),
      res=np.ascontiguousarray(parts(cm.resolution, cm.resolution_lo)[:b]),
      masks=np.ascontiguousarray(np.asarray(mask.data)),
      mask_index=np.zeros((b,), np.int32),
      mask_origin=np.ascontiguousarray(parts(mask.origin, mask.origin_lo)),
      mask_res=np.ascontiguousarray(np.asarray(mask.resolution, np.float64)),
      window=np.ascontiguousarray(win),
      transform=None if transform is None else np.ascontiguousarray(np.asarray(transform, np.float64)[:b]))


def run(fn, inp, cost=None):
  """Runs the peer in place on `cost` (default a copy of inp['cost']); returns (cost, seconds)."""
  cost = inp["cost"].copy() if cost is None else cost
  b, h, w = cost.shape
  hm, wm = inp["masks"].shape[1:]
  ptr = lambda a: None if a is None else a.ctypes.data
  t = time.perf_counter()
  fn(b, h, w, ptr(cost), ptr(inp["origin"]), ptr(inp["res"]), ptr(inp["masks"]), hm, wm, ptr(inp["mask_index"]),
     ptr(inp["mask_origin"]), ptr(inp["mask_res"]), ptr(inp["window"]), ptr(inp["transform"]), None, 0, 0, None)
  return cost, time.perf_counter() - t


def near_mask_edge(inp, band_m=SE2_EDGE_BAND_M):
  """bool [B, H, W]: the float64 SE2 image of each cell centre lies within band_m of a mask-cell edge."""
  b, h, w = inp["cost"].shape
  o, r = inp["origin"], inp["res"]
  x = o[:, 0, None, None] + (np.arange(w)[None, None, :] + 0.5) * r[:, None, None]
  y = o[:, 1, None, None] + (np.arange(h)[None, :, None] + 0.5) * r[:, None, None]
  tf = inp["transform"]
  c, s = np.cos(tf[:, 2])[:, None, None], np.sin(tf[:, 2])[:, None, None]
  px = c * x - s * y + tf[:, 0, None, None]
  py = s * x + c * y + tf[:, 1, None, None]
  m = inp["mask_index"]
  mres = inp["mask_res"][m][:, None, None]
  fx = (px - inp["mask_origin"][m, 0][:, None, None]) / mres
  fy = (py - inp["mask_origin"][m, 1][:, None, None]) / mres
  dist = np.minimum(np.abs(fx - np.round(fx)), np.abs(fy - np.round(fy))) * mres
  return dist < band_m


def check(fn, inp, jax_cost, label="JAX"):
  """Checks the peer's integers against the JAX output and the float64 reference.

  Args:
    fn: the loaded peer; inp: `host_inputs`; jax_cost: uint8 [b, H, W] the result to match
      on the same robots (JAX's, or the NumPy baseline's: `label` names it).

  Returns:
    A one-line description of what was checked.

  Raises:
    AssertionError: the peer disagrees (outside the documented float32-rotation band).
  """
  got, _ = run(fn, inp)
  jax_cost = np.asarray(jax_cost)
  b = got.shape[0]
  if inp["transform"] is None:
    bad = int(np.count_nonzero(got != jax_cost))
    if bad:
      raise AssertionError(f"C++ peer and {label} differ at {bad} cells of {got.size} (same frame)")
    return f"equal to {label} on all {b} robots ({got.size} cells)" + _reference_check(got, inp)
  differ = got != jax_cost
  outside = differ & ~near_mask_edge(inp)
  if outside.any():
    raise AssertionError(f"C++ peer and {label} differ at {int(outside.sum())} cells away from mask-cell edges (SE2)")
  note = (f"equal to {label} on all {b} robots ({got.size} cells) except {int(differ.sum())} within "
          f"{SE2_EDGE_BAND_M:g} m of a mask-cell edge (float32 vs float64 rotation)")
  return note + _reference_check(got, inp)


def _reference_check(got, inp):
  """Robot 0 of the peer against reference/nav2.py (float64 loops, shares no code)."""
  tf = None if inp["transform"] is None else inp["transform"][0]
  h, w = got.shape[1:]
  win = np.clip(inp["window"][0], 0, [w, h, w, h])
  want, _ = nav2_reference.keepout_process(inp["cost"][0], inp["origin"][0], inp["res"][0],
                                           inp["masks"][inp["mask_index"][0]], inp["mask_origin"][inp["mask_index"][0]],
                                           inp["mask_res"][inp["mask_index"][0]], win, transform=tf)
  if not np.array_equal(got[0], want):
    raise AssertionError(f"C++ peer and reference/nav2.py differ at {int((got[0] != want).sum())} cells")
  return "; equal to reference/nav2.py (float64) on robot 0"
