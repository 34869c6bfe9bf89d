"""A Pallas (Triton) kernel for the aligned same-frame keepout write (`KeepoutConfig.kernel`).

The aligned path of `keepout_filter` reads each robot's mask cells as one
[H, W] window of the masks' (cost + 1) table (`mask_cost_plus_one_table`,
padded by H rows and W columns of 0 = unknown) at a start (sx, sy), and applies
Nav2's rule `mask != 255 and (mask > old or (old == 255 and mask >= 253))` (or,
with `KeepoutConfig.unknown_overwrite="any"`, `... or old == 255`), which on (x + 1)
bytes is `m1 > c1` (see `same_frame.aligned_one`, `common.old_plus_one_u8`). XLA runs it as one fused loop; this
module runs it as one Triton kernel over the fleet: each costmap byte is read and
written once (or, with `PallasTuning(in_place=True)`, updated in place where the
caller donates the costmap), and the mask window is read from the table, a few
MB that stay in L2.

Two layouts of a program's work (`PallasTuning.layout`); both read the uint8
costmap as it is (an XLA bitcast to uint32 words would be a copy pass on GPU:
XLA expands bitcast-converts between widths into arithmetic):

* "flat": a program takes `rows = block_cells // W` whole rows of one robot as one
  contiguous run of `rows * W` bytes (padded to a power of two, the tail masked):
  with H * W and rows * W multiples of 16 every costmap access is a 16-byte vector;
  the row and column of each cell come from a division by the static W.
* "rows": a program takes a [R, C] block (R rows, C = next power of two >= W
  columns, masked): no division, but a row starts at a multiple of
  gcd(W, 16) bytes, so the vectors are that wide.

Cells outside a robot's window [x0, x1) x [y0, y1) (Nav2's clipped update
window), and every cell of a robot the caller does not hand to the kernel, read
no mask byte and keep their value: written back unchanged by default; with
`in_place` not touched at all where a whole row (rows layout) or robot (both)
lies outside. The result is the same integers as the XLA aligned path
(tests/jaxfilters/test_keepout_pallas.py runs the kernel in the Pallas interpreter against
it and against a float64 reference).

Pallas's Triton backend computes addresses in 32-bit signed arithmetic for an
array below 4 GiB, so a costmap batch of 2 GiB or more is run in chunks of robots
(a copy of each chunk in and out: slower, still exact) and a table of 2 GiB or
more is refused.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

KERNELS = ("auto", "xla", "pallas")
LAYOUTS = ("flat", "rows")
NUM_PARAMS = 8            # per-robot int32 scalars: i, sx, sy, x0, x1, y0, y1, lethal
# Largest arrays whose 32-bit signed offsets stay exact (the table is refused beyond, the
# costmap batch split into chunks of robots).
_MAX_TABLE_BYTES = (1 << 31) - 1
_MAX_COST_BYTES = (1 << 31) - 1


@dataclasses.dataclass(frozen=True)
class PallasTuning:
  """Static settings of the Pallas keepout kernel (they change the compiled program).

  Attributes:
    layout: "flat" (whole rows as one contiguous run, 16-byte vectors when the
      row run is a multiple of 16 bytes) or "rows" (a [R, next_pow2(W)] block, the
      default, the faster of the two on the GPUs measured).
    block_cells: cells per program, a power of two in [16, 65536]: "flat" takes
      max(1, block_cells // W) rows, "rows" max(1, block_cells // next_pow2(W)).
    num_warps: warps per program (1, 2, 4, 8, 16 or 32).
    num_stages: Triton software-pipelining stages (1..8; the kernel has no loop,
      so this rarely matters).
    in_place: update the costmap in place (`input_output_aliases`): cells outside
      a robot's window, and robots the kernel does not take, are neither read
      nor written. Only a caller that donates the costmap gains (no second
      buffer); without donation XLA first copies the costmap, a whole extra
      pass. False (default) writes a new costmap: every cell read and written
      once, whatever the caller donates.
    interpret: run the kernel in the Pallas interpreter (XLA on any backend,
      slow; for tests on CPU). `KeepoutConfig(kernel="pallas")` on a backend
      other than GPU raises unless this is True.
    frame_block_cells, frame_num_warps: the other-frame kernel's
      (`other_frame_write`) cells and warps per program (a power of two in
      [16, 65536]; 1..32 warps). The defaults, 512 cells and 1 warp, were the
      fastest of eleven settings from 128 to 4096 cells and 1 to 8 warps on an
      H200 (docs/benchmarks_history.md).
  """
  layout: str = "rows"
  block_cells: int = 2048
  num_warps: int = 4
  num_stages: int = 1
  in_place: bool = False
  interpret: bool = False
  frame_block_cells: int = 512
  frame_num_warps: int = 1

  def __post_init__(self):
    if self.layout not in LAYOUTS:
      raise ValueError(f"PallasTuning.layout must be one of {LAYOUTS}; got {self.layout!r}")
    cells = (lambda v: 16 <= v <= 65536 and v & (v - 1) == 0, "a power of two in [16, 65536]")
    warps = (lambda v: v in (1, 2, 4, 8, 16, 32), "one of 1, 2, 4, 8, 16, 32")
    for name, (ok, want) in (("block_cells", cells), ("frame_block_cells", cells), ("num_warps", warps),
                             ("frame_num_warps", warps), ("num_stages", (lambda v: 1 <= v <= 8, "an int in [1, 8]"))):
      v = getattr(self, name)
      if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or not ok(int(v)):
        raise ValueError(f"PallasTuning.{name} must be {want}; got {v!r}")
      object.__setattr__(self, name, int(v))
    for name in ("in_place", "interpret"):
      v = getattr(self, name)
      if not isinstance(v, (bool, np.bool_)):
        raise ValueError(f"PallasTuning.{name} must be a bool; got {v!r}")
      object.__setattr__(self, name, bool(v))


def check_kernel(kernel) -> str:
  """`kernel` if it is one of KERNELS, else ValueError naming the expected values."""
  if not isinstance(kernel, str) or kernel not in KERNELS:
    raise ValueError(f"kernel must be one of {KERNELS}; got {kernel!r}")
  return kernel


def use_pallas(kernel: str, tuning: PallasTuning, *, table_bytes: int = 0, backend: str | None = None,
               field: str = "kernel") -> bool:
  """Whether a keepout kernel runs in Pallas (decided at trace time).

  Args:
    kernel: "xla" (never), "pallas" (always; raises where it cannot run) or
      "auto" (on a GPU backend, when the table fits; XLA otherwise).
    tuning: the PallasTuning (its `interpret` lets "pallas" run off GPU).
    table_bytes: size of the mask table the kernel would read.
    backend: the backend to decide for; default `jax.default_backend()`.
    field: the KeepoutConfig field that chose `kernel` ("kernel" or "frame_kernel"), for messages.

  Raises:
    ValueError: kernel="pallas" on a backend other than GPU without
      `interpret=True` (no silent slow path), a table of 2 GiB or more, or the
      other-frame kernel in the interpreter on a GPU backend (wrong cells there).
  """
  check_kernel(kernel)
  if kernel == "xla":
    return False
  backend = jax.default_backend() if backend is None else backend
  fits = table_bytes <= _MAX_TABLE_BYTES
  if field == "frame_kernel" and backend == "gpu" and tuning.interpret and (kernel == "pallas" or fits):
    # Measured on an H200: the interpreter of the other-frame kernel on a GPU backend gives other
    # integers than the compiled kernel, the XLA loop and the exact path (which agree).
    raise ValueError(
        "PallasTuning(interpret=True) with the other-frame Pallas kernel on a GPU backend gives wrong "
        "cells (the Pallas interpreter there differs from the compiled kernel); use interpret=False "
        "(the compiled kernel) or KeepoutConfig(frame_kernel='xla')")
  if kernel == "auto":
    return backend == "gpu" and fits
  if backend != "gpu" and not tuning.interpret:
    raise ValueError(
        f"KeepoutConfig({field}='pallas') needs a GPU backend (the kernel lowers through Triton); "
        f"the default backend is {backend!r}. Use {field}='xla' or 'auto', or "
        f"PallasTuning(interpret=True) to run the kernel in the (slow) Pallas interpreter")
  if not fits:
    raise ValueError(f"the Pallas keepout kernel reads the mask table with 32-bit offsets: it must be "
                     f"< 2 GiB; got {table_bytes} bytes. Use {field}='xla'")
  return True


def slice_params(idx, sx, sy, col_ok, row_ok, take, lethal) -> jax.Array:
  """Per-robot kernel scalars from the aligned path's prologue: int32 [B, NUM_PARAMS].

  Args:
    idx: int32 [B] mask index. sx, sy: int32 [B] window start in the table.
    col_ok: bool [B, W], row_ok: bool [B, H]: the half-open update window as
      flags (`common.window_flags`: each a contiguous run; row_ok all False
      for a robot that does not run).
    take: bool [B], robots the kernel writes (others keep their cost).
    lethal: bool [B], `state.is_pose_lethal` (used in escape mode only).

  Returns:
    int32 [B, 8] rows (i, sx, sy, x0, x1, y0, y1, lethal); y0 == y1 == 0 for a
    robot with nothing to write.
  """
  def bounds(ok):
    n = jnp.sum(ok.astype(jnp.int32), axis=1)
    lo = jnp.where(n > 0, jnp.argmax(ok, axis=1).astype(jnp.int32), 0)
    return lo, lo + n

  x0, x1 = bounds(col_ok)
  y0, y1 = bounds(row_ok)
  return slice_params_from_bounds(idx, sx, sy, x0, x1, y0, y1, take, lethal, shape=(row_ok.shape[1], col_ok.shape[1]))


def slice_params_from_bounds(idx, sx, sy, x0, x1, y0, y1, take, lethal, *, shape) -> jax.Array:
  """Per-robot kernel scalars from per-robot scalars (no [B, W] flags): int32 [B, NUM_PARAMS].

  Args:
    idx: int32 [B] mask index. sx, sy: int32 [B] window start in the table.
    x0, x1, y0, y1: int32 [B], the half-open update window [x0, x1) x [y0, y1) in
      costmap cells (clipped here into the costmap; x1 <= x0 or y1 <= y0: empty).
    take: bool [B], robots the kernel writes (others keep their cost).
    lethal: bool [B], `state.is_pose_lethal` (used in escape mode only).
    shape: static (H, W) of the costmaps.

  Returns:
    int32 [B, 8] rows (i, sx, sy, x0, x1, y0, y1, lethal) as `slice_params`'s: the
    same rows for the same window; y0 == y1 == 0 for a robot with nothing to write.
  """
  h, w = shape
  i32 = lambda v: jnp.asarray(v).astype(jnp.int32)
  x0, x1 = jnp.clip(i32(x0), 0, w), jnp.clip(i32(x1), 0, w)
  y0, y1 = jnp.clip(i32(y0), 0, h), jnp.clip(i32(y1), 0, h)
  empty = (x1 <= x0) | (y1 <= y0) | ~jnp.asarray(take, bool)
  # slice_params' flag form: an empty column run is (0, 0); an empty row run zeroes y.
  x0, x1 = jnp.where(x1 <= x0, 0, x0), jnp.where(x1 <= x0, 0, x1)
  y0, y1 = jnp.where(empty, 0, y0), jnp.where(empty, 0, y1)
  cols = (idx, sx, sy, x0, x1, y0, y1, lethal)
  return jnp.stack([i32(c) for c in cols], axis=1)


UNKNOWN_OVERWRITES = ("inscribed", "any")   # KeepoutConfig.unknown_overwrite (config imports this module)


def check_unknown_overwrite(unknown_overwrite) -> str:
  """`unknown_overwrite` if it is one of UNKNOWN_OVERWRITES, else ValueError naming them."""
  if not isinstance(unknown_overwrite, str) or unknown_overwrite not in UNKNOWN_OVERWRITES:
    raise ValueError(f"unknown_overwrite must be one of {UNKNOWN_OVERWRITES}; got {unknown_overwrite!r}")
  return unknown_overwrite


def _rule(c, m1, lethal, *, escape: bool, lethal_cost: int, unknown_overwrite: str):
  """Nav2's write rule on uint8 cells c and mask (cost + 1) bytes m1 (0 = do not write).

  `common.m1_rule_u8`: with unknown_overwrite "inscribed" an unknown c (c1 = 0) compares
  as c1 = 253, so only a mask cost >= 253 overwrites it.
  """
  c1 = c + jnp.uint8(1)
  if unknown_overwrite == "inscribed":
    c1 = jnp.where(c1 == jnp.uint8(0), jnp.uint8(253), c1)
    value = m1 - jnp.uint8(1)
    if escape:
      value = jnp.where(lethal != 0, jnp.uint8(lethal_cost), value)
    return jnp.where(m1 > c1, value, c)
  if escape:
    value = jnp.where(lethal != 0, jnp.uint8(lethal_cost), m1 - jnp.uint8(1))
    return jnp.where(m1 > c1, value, c)
  return jnp.maximum(c1, m1) - jnp.uint8(1)


def _pallas():
  """(pallas, pallas.triton), imported on first use: `import jaxfilters` does not load Pallas."""
  from jax.experimental import pallas as pl  # noqa: PLC0415
  from jax.experimental.pallas import triton as plgpu  # noqa: PLC0415
  return pl, plgpu


def _params(p_ref, r):
  return [p_ref[r, k] for k in range(NUM_PARAMS)]


def _in_range(v, lo, hi):
  """lo <= v < hi for int32 v and lo <= hi, as one unsigned compare."""
  return (v - lo).astype(jnp.uint32) < (hi - lo).astype(jnp.uint32)


def _flat_kernel(p_ref, cost_ref, tab_ref, out_ref, *, h, w, plane, pitch, rows, span, nblk, escape, lethal_cost,
                 in_place, unknown_overwrite):
  pl, plgpu = _pallas()
  pid = pl.program_id(0)
  r, row0 = jax.lax.div(pid, nblk), jax.lax.rem(pid, nblk) * rows
  i, sx, sy, x0, x1, y0, y1, lethal = _params(p_ref, r)
  e = jnp.arange(span, dtype=jnp.int32)
  start = row0 * w
  # Bounds on the contiguous index only (and a per-robot scalar), so Triton can keep
  # the costmap access vectorised; the window is applied on the mask read.
  live = (e < rows * w) & (start + e < h * w)
  if in_place:
    live = live & (y1 > y0)
  q = jax.lax.div(e.astype(jnp.uint32), jnp.uint32(w)).astype(jnp.int32)   # row within the run
  col = e - q * w
  c = plgpu.load(cost_ref.at[r, pl.ds(start, span)], mask=live, other=jnp.uint8(0))
  visit = live & _in_range(row0 + q, y0, y1) & _in_range(col, x0, x1)
  # The table as one flat run: cell (sy + row0 + q, sx + col) of mask i.
  base = i * plane + (sy + row0) * pitch + sx
  m1 = plgpu.load(tab_ref.at[base + e + q * (pitch - w)], mask=visit, other=jnp.uint8(0))
  plgpu.store(out_ref.at[r, pl.ds(start, span)], _rule(c, m1, lethal, escape=escape, lethal_cost=lethal_cost, unknown_overwrite=unknown_overwrite),
              mask=live)


def _rows_kernel(p_ref, cost_ref, tab_ref, out_ref, *, h, rows, span, nblk, w, escape, lethal_cost, in_place,
                 unknown_overwrite):
  pl, plgpu = _pallas()
  pid = pl.program_id(0)
  r, row0 = jax.lax.div(pid, nblk), jax.lax.rem(pid, nblk) * rows
  i, sx, sy, x0, x1, y0, y1, lethal = _params(p_ref, r)
  j = row0 + jnp.arange(rows, dtype=jnp.int32)
  k = jnp.arange(span, dtype=jnp.int32)
  # y1 <= H, so the row window also masks the rows past the costmap's last.
  in_window = _in_range(j, y0, y1)[:, None] & (k < w)[None, :]
  live = in_window if in_place else (j < h)[:, None] & (k < w)[None, :]
  c = plgpu.load(cost_ref.at[r, pl.ds(row0, rows), pl.ds(0, span)], mask=live, other=jnp.uint8(0))
  visit = in_window & _in_range(k, x0, x1)[None, :]
  m1 = plgpu.load(tab_ref.at[i, pl.ds(sy + row0, rows), pl.ds(sx, span)], mask=visit, other=jnp.uint8(0))
  plgpu.store(out_ref.at[r, pl.ds(row0, rows), pl.ds(0, span)],
              _rule(c, m1, lethal, escape=escape, lethal_cost=lethal_cost, unknown_overwrite=unknown_overwrite), mask=live)


def _next_pow2(n: int) -> int:
  return 1 << max(0, (int(n) - 1).bit_length())


def block_shape(h: int, w: int, tuning: PallasTuning) -> tuple[int, int, int]:
  """(rows per program, padded lanes per row or per run, programs per robot) for H x W."""
  if tuning.layout == "flat":
    rows = max(1, min(h, tuning.block_cells // w))
    return rows, _next_pow2(rows * w), -(-h // rows)
  span = _next_pow2(w)
  rows = min(_next_pow2(h), max(1, tuning.block_cells // span))
  return rows, span, -(-h // rows)


def _robots_per_call(h: int, w: int) -> int:
  """Robots of H x W costmaps one kernel call takes so that its costmap offsets stay 32-bit exact."""
  return max(1, _MAX_COST_BYTES // (h * w))


def _in_chunks(fn, batched: tuple, chunk: int) -> jax.Array:
  """fn over consecutive chunks of `chunk` robots of the `batched` arrays, concatenated (a copy of
  each chunk in and out: slower, still exact; see the module docstring)."""
  b = batched[0].shape[0]
  parts = [fn(*jax.tree.map(lambda a: a[s:s + chunk], batched)) for s in range(0, b, chunk)]
  return jnp.concatenate(parts, axis=0)


def aligned_write(cost, table, params, *, escape: bool, lethal_cost: int, tuning: PallasTuning,
                  unknown_overwrite: str = "inscribed") -> jax.Array:
  """The aligned keepout write for a fleet in one Pallas kernel: new cost uint8 [B, H, W].

  Same integers as `jax.vmap(same_frame.aligned_one)` on the robots with a
  non-empty window in `params`; the others keep their cost. With
  `tuning.in_place` the result aliases `cost` (in place when the caller
  donates it under `jit`, else XLA copies it first); otherwise it is a new
  buffer with every cell written.

  Args:
    cost: uint8 [B, H, W] costmaps.
    table: uint8 [M, Hm + 2H, Wm + 2W] the masks' (cost + 1) bytes padded with 0
      (`common.cost_plus_one_table`); a robot's window starts at (sx, sy),
      0 <= sx <= Wm + W, 0 <= sy <= Hm + H.
    params: int32 [B, 8] from `slice_params`.
    escape: static, Nav2's override_lethal_cost (write `lethal_cost` where the
      robot's `lethal` flag is set).
    lethal_cost: static int in [0, 255].
    tuning: static PallasTuning.
    unknown_overwrite: static, `KeepoutConfig.unknown_overwrite` ("inscribed":
      an unknown old cell is overwritten only by a mask cost >= 253; "any": by any).

  Returns:
    uint8 [B, H, W].

  Raises:
    ValueError: wrong dtypes or shapes (static), a table of 2 GiB or more, an
      unknown_overwrite that is not one of UNKNOWN_OVERWRITES.
  """
  check_unknown_overwrite(unknown_overwrite)
  if cost.dtype != jnp.uint8 or cost.ndim != 3:
    raise ValueError(f"cost must be uint8 [B, H, W]; got {cost.dtype}{tuple(cost.shape)}")
  b, h, w = cost.shape
  if table.dtype != jnp.uint8 or table.ndim != 3 or table.shape[1] < 2 * h or table.shape[2] < 2 * w:
    raise ValueError(f"table must be uint8 [M, Hm + 2H, Wm + 2W] with H = {h}, W = {w}; "
                     f"got {table.dtype}{tuple(table.shape)}")
  if params.dtype != jnp.int32 or params.shape != (b, NUM_PARAMS):
    raise ValueError(f"params must be int32 [{b}, {NUM_PARAMS}]; got {params.dtype}{tuple(params.shape)}")
  if not 0 <= int(lethal_cost) <= 255:
    raise ValueError(f"lethal_cost must be a cost in [0, 255]; got {lethal_cost!r}")
  if table.size > _MAX_TABLE_BYTES:
    raise ValueError(f"the mask table must be < 2 GiB for the kernel's 32-bit offsets; got {table.size} bytes")
  if b == 0:
    return cost
  if b > _robots_per_call(h, w):
    return _in_chunks(lambda c, p: aligned_write(c, table, p, escape=escape, lethal_cost=lethal_cost, tuning=tuning,
                                                 unknown_overwrite=unknown_overwrite),
                      (cost, params), _robots_per_call(h, w))
  pl, plgpu = _pallas()
  rows, span, nblk = block_shape(h, w, tuning)
  statics = dict(h=h, w=w, rows=rows, span=span, nblk=nblk, escape=bool(escape), lethal_cost=int(lethal_cost),
                 in_place=tuning.in_place, unknown_overwrite=unknown_overwrite)
  if tuning.layout == "flat":
    statics.update(plane=table.shape[1] * table.shape[2], pitch=table.shape[2])
    kernel = lambda *refs: _flat_kernel(*refs, **statics)
    operand = cost.reshape(b, h * w)
    table = table.reshape(-1)
  else:
    kernel = lambda *refs: _rows_kernel(*refs, **statics)
    operand = cost
  call = pl.pallas_call(
      kernel,
      out_shape=jax.ShapeDtypeStruct(operand.shape, jnp.uint8),
      grid=(b * nblk,),
      input_output_aliases={1: 0} if tuning.in_place else {},
      interpret=tuning.interpret,
      compiler_params=plgpu.CompilerParams(num_warps=tuning.num_warps, num_stages=tuning.num_stages),
      name=f"keepout_aligned_{tuning.layout}",
  )
  return call(params, operand, table).reshape(b, h, w)


# ----------------------------------------------------------------------------- other frame (SE2)

FRAME_INT_PARAMS = 6      # per-robot int32: i, x0, x1, y0, y1, lethal
FRAME_FLOAT_PARAMS = 5    # per-robot float32: tx, ty, mask origin x, y (leading parts), 1 / mask resolution


def _frame_kernel(p_ref, f_ref, xc_ref, xs_ref, yc_ref, ys_ref, cost_ref, tx_ref, ty_ref, src_ref, out_ref, *,
                  h, w, hm, wm, rows, shift, nblk, escape, lethal_cost, unknown_overwrite):
  """One program: `rows` rows of one robot as a flat run of rows * 2**shift lanes (the columns padded)."""
  pl, plgpu = _pallas()
  pid = pl.program_id(0)
  r, row0 = jax.lax.div(pid, nblk), jax.lax.rem(pid, nblk) * rows
  i, x0, x1, y0, y1, lethal = [p_ref[r, k] for k in range(FRAME_INT_PARAMS)]
  t0, t1, mox, moy, inv = [f_ref[r, k] for k in range(FRAME_FLOAT_PARAMS)]
  e = jnp.arange(rows << shift, dtype=jnp.int32)
  row = row0 + (e >> shift)
  col = e & ((1 << shift) - 1)
  live = (row < h) & (col < w)
  c = plgpu.load(cost_ref.at[r, row * w + col], mask=live, other=jnp.uint8(0))
  xc = plgpu.load(xc_ref.at[r, col], mask=live, other=0.0)
  xs = plgpu.load(xs_ref.at[r, col], mask=live, other=0.0)
  yc = plgpu.load(yc_ref.at[r, row], mask=live, other=0.0)
  ys = plgpu.load(ys_ref.at[r, row], mask=live, other=0.0)
  px = (xc - ys) + t0                   # `reference.se2_grid`'s sums, in the same order
  py = (xs + yc) + t1

  def floor_by_edges(x, origin, table_ref, offset, size):   # `geometry.floor_by_edges`, one table read
    est = jnp.floor((x - origin) * inv - 0.5)
    n0 = jnp.where(x == x, jnp.clip(est, -1.0, float(size)), -1.0).astype(jnp.int32)
    edge = plgpu.load(table_ref.at[offset + n0 + 2], mask=live, other=jnp.inf)
    return n0 + (x >= edge).astype(jnp.int32)

  nx = floor_by_edges(px, mox, tx_ref, i * (wm + 3), wm)
  ny = floor_by_edges(py, moy, ty_ref, i * (hm + 3), hm)
  # The window as `common.window_flags` tests it (plain comparisons: any x0, x1).
  visit = (live & (nx >= 0) & (nx < wm) & (ny >= 0) & (ny < hm) & (col >= x0) & (col < x1)
           & (row >= y0) & (row < y1))
  m1 = plgpu.load(src_ref.at[i * (hm * wm) + ny * wm + nx], mask=visit, other=jnp.uint8(0))
  plgpu.store(out_ref.at[r, row * w + col], _rule(c, m1, lethal, escape=escape, lethal_cost=lethal_cost, unknown_overwrite=unknown_overwrite),
              mask=live)


def other_frame_write(cost, axes, tables, source, ints, floats, *, mshape, escape: bool, lethal_cost: int,
                      tuning: PallasTuning, unknown_overwrite: str = "inscribed") -> jax.Array:
  """The other-frame (SE2) keepout write of a fleet in one Pallas kernel: new cost uint8 [B, H, W].

  Each cell's centre is rotated with the robot's `reference.se2_axes_one` vectors
  (the same float32 sums as `reference.se2_grid`), its mask cell decided exactly by
  the edge tables (`geometry.floor_by_edges`, whose proof holds with or without a
  fused multiply-add) and Nav2's write rule applied: the integers of
  `other_frame._edges_one` for robots whose tables are trusted, every cell read
  and written once, the mask bytes read where a cell is visited.

  Args:
    cost: uint8 [B, H, W].
    axes: (xc, xs float32 [B, W], yc, ys float32 [B, H]) of `reference.se2_axes_one`.
    tables: (tx float32 [M * (Wm + 3)], ty float32 [M * (Hm + 3)]) from `other_frame.edge_tables`.
    source: uint8 [M * Hm * Wm] the masks' (cost + 1) bytes (`common.m1_table`), flat.
    ints: int32 [B, 6] (mask i, x0, x1, y0, y1 of the update window, rows empty for a robot
      that does not run; lethal) per robot.
    floats: float32 [B, 5] (tx, ty, the mask origin's leading parts, 1 / resolution as
      `geometry.edge_reciprocal`) per robot.
    mshape: static (Hm, Wm). escape, lethal_cost, unknown_overwrite: as `aligned_write`. tuning: static PallasTuning
      (its frame_block_cells, frame_num_warps, num_stages and interpret; a program takes
      whole rows of one robot as a flat run, the columns padded to a power of two).

  Returns:
    uint8 [B, H, W]. A batch of 2 GiB or more runs in chunks of robots, as `aligned_write`'s.
  """
  check_unknown_overwrite(unknown_overwrite)
  b, h, w = cost.shape
  hm, wm = mshape
  for name, a, dt in (("source", source, jnp.uint8), ("ints", ints, jnp.int32), ("floats", floats, jnp.float32)):
    if a.dtype != dt:
      raise ValueError(f"{name} must be {jnp.dtype(dt).name}; got {a.dtype}")
  if ints.shape != (b, FRAME_INT_PARAMS) or floats.shape != (b, FRAME_FLOAT_PARAMS):
    raise ValueError(f"ints must be [{b}, {FRAME_INT_PARAMS}] and floats [{b}, {FRAME_FLOAT_PARAMS}]; "
                     f"got {tuple(ints.shape)}, {tuple(floats.shape)}")
  if source.size > _MAX_TABLE_BYTES:
    raise ValueError(f"the other-frame kernel reads the masks with 32-bit offsets: they must be < 2 GiB; "
                     f"got {source.size} bytes. Use frame_kernel='xla'")
  if b == 0:
    return cost
  if b > _robots_per_call(h, w):
    return _in_chunks(lambda c, xc, xs, yc, ys, i, f: other_frame_write(
        c, (xc, xs, yc, ys), tables, source, i, f, mshape=mshape, escape=escape, lethal_cost=lethal_cost,
        tuning=tuning, unknown_overwrite=unknown_overwrite), (cost, *axes, ints, floats), _robots_per_call(h, w))
  pl, plgpu = _pallas()
  span = _next_pow2(w)
  rows = min(_next_pow2(h), max(1, tuning.frame_block_cells // span))
  nblk = -(-h // rows)
  statics = dict(h=h, w=w, hm=hm, wm=wm, rows=rows, shift=span.bit_length() - 1, nblk=nblk,
                 escape=bool(escape), lethal_cost=int(lethal_cost), unknown_overwrite=unknown_overwrite)
  xc, xs, yc, ys = axes
  call = pl.pallas_call(
      lambda *refs: _frame_kernel(*refs, **statics),
      out_shape=jax.ShapeDtypeStruct((b, h * w), jnp.uint8),
      grid=(b * nblk,),
      interpret=tuning.interpret,
      compiler_params=plgpu.CompilerParams(num_warps=tuning.frame_num_warps, num_stages=tuning.num_stages),
      name="keepout_other_frame",
  )
  return call(ints, floats, xc, xs, yc, ys, cost.reshape(b, h * w), tables[0], tables[1], source).reshape(b, h, w)
