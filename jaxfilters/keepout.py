"""KeepoutFilter (spec §4): write no-go zones from a mask into each robot's costmap.

Nav2's filter runs in two phases per costmap cycle, and so does this module:

* `keepout_update_bounds` is `KeepoutFilter::updateBounds` (§4.2): it grows the
  update window when a new mask arrives (with Nav2's quirk of using the master
  grid's origin and resolution with the mask's cell counts) and runs the
  robot-in-zone test of the escape mode (`override_lethal_cost`), growing an
  accumulated box while the robot is inside a zone and one cycle after.
* `keepout_filter` is `KeepoutFilter::process` (§4.3-§4.4): for each visited
  master cell, sample the mask at the cell centre and raise the cost
  (`data > old or old == 255`), skipping unknown mask cells; in escape mode the
  written value is `lethal_override_cost`.

Both are written for one robot (`*_one`) and vmapped once at the public edge.
Lanes (seed design: "covered by KeepoutFilter") are keepout masks with graded
values 1..99, which give intermediate costs round(2.54 * d).

Float policy: same-frame cell mapping is exact (jaxfilters.geometry), on the
host doubles of the costmap's origin and resolution and the mask's origin
(carried as float32 parts). With a frame transform (`transform` given) each
master cell centre is rotated in float32, then mapped exactly; Nav2 rotates in
float64, so a centre that lands within ~1e-6 m of a mask cell boundary may
pick the neighbouring mask cell.

Both public functions are jitted at the edge (STYLE.md habit 14): an eager
call compiles once per shape and config, and inside a caller's `jit` they
inline. A robot whose traced `mask_index` is outside [0, M) is left untouched
and gets `KeepoutState.error` True (an eager call raises instead).
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from jaxfilters import geometry
from jaxfilters.types import Costmap, FilterMask, _dataclass, check_costmap, robot_inputs

_F32 = jnp.float32
_EMPTY_BOX = (np.inf, np.inf, -np.inf, -np.inf)
_GENERAL_CHUNK_CELLS = 1 << 24  # cells per lax.map chunk of the general (per-cell) path


def occ_to_cost(data: jax.Array) -> jax.Array:
  """Mask value -> cost (spec §1.4): round-half-away(2.54 * d), -1 -> 255.

  Values outside -1..100 (never produced by map_server; undefined behaviour in
  Nav2) are treated as unknown (255), as the spec recommends. Uses integer
  arithmetic: floor((254 d + 50) / 100) == floor(2.54 d + 0.5) exactly.

  Args:
    data: int8 (or any integer) array of OccupancyGrid values.

  Returns:
    uint8 array of the same shape.
  """
  d = jnp.asarray(data).astype(jnp.int32)
  cost = (d * 254 + 50) // 100
  return jnp.where((d >= 0) & (d <= 100), cost, constants.NO_INFORMATION).astype(jnp.uint8)


@dataclasses.dataclass(frozen=True)
class KeepoutConfig:
  """Static keepout options (Nav2 parameters `<filter>.override_lethal_cost` etc.).

  Attributes:
    override_lethal_cost: escape mode; while the robot's centre is in a lethal
      keepout cell, every cell the filter writes gets `lethal_override_cost`.
    lethal_override_cost: clamped to [0, 252] like Nav2 (MAX_NON_OBSTACLE).
    aligned_fast_path: let `keepout_filter` take the slice path (same integers,
      see `_aligned_batch`) when, at run time, every robot's costmap cells map
      one to one onto consecutive mask cells (`_aligned_offsets`: equal
      resolutions, or nearly equal ones with no cell edge between) and no
      `transform` is given.
      The choice is one batch-wide `lax.cond`, so both paths are compiled.
  """
  override_lethal_cost: bool = False
  lethal_override_cost: int = constants.MAX_NON_OBSTACLE
  aligned_fast_path: bool = True

  def __post_init__(self):
    if not isinstance(self.aligned_fast_path, (bool, np.bool_)):
      raise ValueError(f"aligned_fast_path must be a bool; got {self.aligned_fast_path!r}")
    object.__setattr__(self, "aligned_fast_path", bool(self.aligned_fast_path))
    if not isinstance(self.override_lethal_cost, (bool, np.bool_)):
      raise ValueError(f"override_lethal_cost must be a bool; got {self.override_lethal_cost!r}")
    if int(self.lethal_override_cost) != self.lethal_override_cost:
      raise ValueError(f"lethal_override_cost must be an integer cost; got {self.lethal_override_cost!r}")
    # Nav2 clamps rather than rejects.
    object.__setattr__(self, "lethal_override_cost",
                       int(min(max(int(self.lethal_override_cost), 0), constants.MAX_NON_OBSTACLE)))


@_dataclass
class KeepoutState:
  """Per-robot state KeepoutFilter carries between cycles.

  Attributes:
    is_pose_lethal: bool [B], robot centre in a lethal keepout cell (escape mode).
    last_pose_lethal: bool [B], the value at the end of the last process().
    acc_box: float32 [B, 4] world (min_x, min_y, max_x, max_y) accumulated while
      the robot is in a zone; (+inf, +inf, -inf, -inf) when empty.
    error: bool [B], the last call could not run for this robot because its
      traced `mask_index` was outside [0, M): nothing was written and the
      rest of its state was kept. None in a hand-built state.
  """
  is_pose_lethal: jax.Array
  last_pose_lethal: jax.Array
  acc_box: jax.Array
  error: jax.Array | None = None

  @classmethod
  def create(cls, num_robots: int) -> "KeepoutState":
    """The state before the first cycle: not in a zone, empty box, no error."""
    return cls(jnp.zeros((num_robots,), bool), jnp.zeros((num_robots,), bool),
               jnp.tile(jnp.asarray(_EMPTY_BOX, _F32), (num_robots, 1)),
               jnp.zeros((num_robots,), bool))


def pose_in_lethal_zone_one(data, mask_origin, mask_res, xy, mask_origin_lo=None):
  """Nav2's robot-in-keepout test (spec §4.2): the point's mask cell costs 253 or 254.

  Unknown mask cells (cost 255, data -1) are not lethal: a robot standing on
  one does not switch escape mode on.

  Args:
    data: int8 [Hm, Wm]; mask_origin float32 [2]; mask_res float32 [].
    xy: float32 [2] point in the mask frame.
    mask_origin_lo: optional float32 [2, 2] parts of a float64 mask origin.

  Returns:
    bool []: False off the mask.
  """
  h, w = data.shape
  mx, my, valid = geometry.world_to_cell(xy[0], xy[1], mask_origin, mask_res, w, h, mask_origin_lo)
  cost = occ_to_cost(data[my, mx])
  return valid & (cost >= constants.INSCRIBED_INFLATED_OBSTACLE) & (cost <= constants.LETHAL_OBSTACLE)


def keepout_update_bounds_one(state, data, mask_origin, mask_res, pose, bounds,
                              master_origin, master_res, new_mask, enabled, transform,
                              *, override_lethal_cost: bool, mask_origin_lo=None, index_ok=True):
  """KeepoutFilter::updateBounds for one robot (spec §4.2).

  Args:
    state: KeepoutState of one robot (scalar leaves, acc_box [4]).
    data: int8 [Hm, Wm] this robot's mask.
    mask_origin, mask_res: float32 [2], [].
    pose: float32 [3], robot (x, y, yaw) in the costmap's global frame.
    bounds: float32 [4] world (min_x, min_y, max_x, max_y) so far this cycle.
    master_origin, master_res: the costmap's geometry ([2], []).
    new_mask: bool [], a new mask arrived since the last cycle.
    enabled: bool [].
    transform: float32 [3] T_mask_from_global or None (same frame).
    override_lethal_cost: static, escape mode.
    mask_origin_lo: optional float32 [2, 2] parts of a float64 mask origin.
    index_ok: bool [], this robot's mask_index is in range (else nothing runs
      and `error` is set).

  Returns:
    (new state, new bounds).
  """
  hm, wm = data.shape
  # New mask: grow to the master-grid centres of (0, 0) and (Wm, Hm) (Nav2 quirk) and return.
  lo = master_origin + 0.5 * master_res
  hi = master_origin + (jnp.asarray([wm, hm], _F32) + 0.5) * master_res
  grown = jnp.concatenate([jnp.minimum(bounds[:2], lo), jnp.maximum(bounds[2:], hi)])

  xy = pose[:2]
  if transform is not None:
    xy = jnp.stack(geometry.transform_points(transform, xy[0], xy[1]))
  lethal = jnp.asarray(False)
  if override_lethal_cost:
    lethal = pose_in_lethal_zone_one(data, mask_origin, mask_res, xy, mask_origin_lo)
  keep_box = override_lethal_cost & (lethal | state.last_pose_lethal)
  union = jnp.concatenate([jnp.minimum(state.acc_box[:2], bounds[:2]),
                           jnp.maximum(state.acc_box[2:], bounds[2:])])
  acc = jnp.where(keep_box, union, jnp.asarray(_EMPTY_BOX, _F32))
  normal_state = dataclasses.replace(state, is_pose_lethal=lethal, acc_box=acc)
  normal_bounds = jnp.where(keep_box, union, bounds)

  pick = lambda a, b: jax.tree.map(lambda x, y: jnp.where(new_mask, x, y), a, b)
  out_state = pick(state, normal_state)
  out_bounds = jnp.where(new_mask, grown, normal_bounds)
  run = enabled & index_ok
  out_state = jax.tree.map(lambda x, y: jnp.where(run, x, y), out_state, state)
  out_state = _with_error(out_state, ~index_ok)
  return out_state, jnp.where(run, out_bounds, bounds)


def _with_error(state, error):
  return dataclasses.replace(state, error=jnp.asarray(error, bool))


def _same_frame_window(shape_m, mask_origin, mask_res, origin, res, window):
  """Nav2's same-frame overlap clip with the mask's half cell (spec §4.3).

  The four worldToMapNoBounds calls run as one stacked exact division.
  `mask_origin`, `origin` and `res` are float32 arrays or lists of float32
  parts (host doubles); `mask_res` is float32 (nav_msgs).
  """
  hm, wm = shape_m
  half = 0.5 * mask_res
  min_i, min_j, max_i, max_j = window[0], window[1], window[2], window[3]
  four = lambda o: jnp.stack([o[0], o[1], o[0], o[1]])
  mo = [four(t) for t in geometry._as_terms(mask_origin)]
  o = [-four(t) for t in geometry._as_terms(origin)]
  extent = jnp.asarray([0.0, 0.0, wm, hm], _F32)       # corners (0, 0) and (Wm, Hm)
  g = geometry.trunc_div_exact([*mo, *geometry.exact_product(extent, mask_res), half, *o], res)
  g0, g1 = (g[0], g[1]), (g[2], g[3])
  overlap = ~((g0[0] >= max_i) | (g0[1] >= max_j)) & ~((g1[0] <= min_i) | (g1[1] <= min_j))
  x0, y0 = jnp.maximum(min_i, g0[0]), jnp.maximum(min_j, g0[1])
  x1, y1 = jnp.minimum(max_i, g1[0]), jnp.minimum(max_j, g1[1])
  return overlap, (x0, y0, x1, y1)


def keepout_one(cost, origin, res, data, mask_origin, mask_res, state, window, enabled,
                transform, *, config: KeepoutConfig):
  return _keepout_stack_one(cost, origin, res, data[None], jnp.int32(0), mask_origin, mask_res, state,
                            window, enabled, transform, config=config)


def _keepout_stack_one(cost, origin, res, stack, i, mask_origin, mask_res, state, window, enabled,
                       transform, *, config: KeepoutConfig, index_ok=True):
  """KeepoutFilter::process for one robot's costmap (spec §4.3-§4.4).

  Args:
    cost: uint8 [H, W] the combined costmap.
    origin, res: float32 [2], [] its geometry (or lists of float32 parts
      whose exact sums are the host doubles).
    data: int8 [Hm, Wm] this robot's mask (`keepout_one`); the private
      `_keepout_stack_one` takes the [M, Hm, Wm] stack and the index i instead.
    mask_origin, mask_res: float32 [2] (or a list of [2] parts), [].
    state: KeepoutState for this robot (scalar leaves).
    window: int32 [4] (min_i, min_j, max_i, max_j), half-open update window.
    enabled: bool [].
    transform: float32 [3] T_mask_from_global (x, y, yaw), or None for the same frame.
    config: static KeepoutConfig.

  Returns:
    (new cost uint8 [H, W], new state).
  """
  h, w = cost.shape
  hm, wm = stack.shape[1:]
  # Gather from the flat [M * Hm * Wm] stack: one scalar index per cell, no per-robot
  # copy of the mask (a 2-D index gather was 10x slower on XLA:CPU, benchmarks/NOTES.md).
  flat = stack.reshape(-1)
  base = i * (hm * wm)
  min_i, min_j, max_i, max_j = window[0], window[1], window[2], window[3]
  cols = jnp.arange(w, dtype=jnp.int32)
  rows = jnp.arange(h, dtype=jnp.int32)
  if transform is None:
    overlap, (x0, y0, x1, y1) = _same_frame_window((hm, wm), mask_origin, mask_res, origin, res, window)
    (mx, vx), (my, vy) = geometry.centres_to_cells_2d((h, w), origin, res, mask_origin, mask_res, (hm, wm))
    visit = (((cols >= x0) & (cols < x1) & vx)[None, :] & ((rows >= y0) & (rows < y1) & vy)[:, None])
    mask_val = flat[base + my[:, None] * wm + mx[None, :]]
  else:
    overlap = jnp.asarray(True)
    o = sum(geometry._as_terms(origin)[1:], geometry._as_terms(origin)[0])
    r = sum(geometry._as_terms(res)[1:], geometry._as_terms(res)[0])
    cx = o[0] + (cols.astype(_F32) + 0.5) * r
    cy = o[1] + (rows.astype(_F32) + 0.5) * r
    px, py = geometry.transform_points(transform, cx[None, :], cy[:, None])
    mx, my, inside = geometry.world_to_cell(px, py, mask_origin, mask_res, wm, hm)
    in_window = (((cols >= min_i) & (cols < max_i))[None, :] & ((rows >= min_j) & (rows < max_j))[:, None])
    visit = inside & in_window
    mask_val = flat[base + my * wm + mx]
  mask_cost = occ_to_cost(mask_val)
  write = (visit & (mask_cost != constants.NO_INFORMATION)
           & ((mask_cost > cost) | (cost == constants.NO_INFORMATION)))
  if config.override_lethal_cost:
    value = jnp.where(state.is_pose_lethal, jnp.uint8(config.lethal_override_cost), mask_cost)
  else:
    value = mask_cost
  run = enabled & overlap & index_ok
  new_cost = jnp.where(run & write, value, cost)
  return new_cost, _with_error(_processed(state, run), ~jnp.asarray(index_ok))


keepout_one.__doc__ = ("KeepoutFilter::process for one robot and one mask `data` [Hm, Wm] (the per-robot "
                       "kernel; see `_keepout_stack_one` for the arguments).\n\n" + _keepout_stack_one.__doc__)


def mask_cost_plus_one_table() -> np.ndarray:
  """uint8 [256]: entry v is (occ_to_cost(int8 v) + 1) mod 256, so unknown (255) -> 0."""
  d = np.arange(256, dtype=np.uint8).view(np.int8).astype(np.int32)
  cost = np.where((d >= 0) & (d <= 100), (d * 254 + 50) // 100, constants.NO_INFORMATION)
  return ((cost + 1) % 256).astype(np.uint8)


_COST1 = mask_cost_plus_one_table()


def _processed(state, run):
  """State after process(): last_pose_lethal follows is_pose_lethal unless it returned early."""
  return dataclasses.replace(
      state, last_pose_lethal=jnp.where(run, state.is_pose_lethal, state.last_pose_lethal))


def _aligned_offsets(shape, origin, res, mask_origin, mask_res):
  """Mask cells of the first and last master cell centres, per axis, decided exactly.

  Nav2 maps master cell k to mask cell floor((o + (k + 1/2) r - mo) / mr). The
  offset floor(...) - k is monotone in k (its slope r / mr - 1 has one sign),
  so it is the same for every k iff it is the same at k = 0 and k = size - 1:
  then the mask cells under the costmap are the plain window starting at k0.
  That holds whenever r == mr, and also for a double costmap resolution such
  as 0.05 beside the float32 mask resolution 0.0500000007 unless a cell edge
  falls between the two ends.

  Returns:
    (k0 int32 [2] (x, y) mask cell of master cell (0, 0), unit bool []).
  """
  h, w = shape
  ends = jnp.asarray([[0.0, w - 1.0], [0.0, h - 1.0]], _F32)                     # [axis, end]
  o = [t[:, None] for t in geometry._as_terms(origin)]
  mo = [-t[:, None] for t in geometry._as_terms(mask_origin)]
  k = geometry.floor_div_exact(geometry.cell_centre_terms(ends, o, res) + mo, mask_res)
  unit = jnp.all((k[:, 1] - k[:, 0]) == jnp.asarray([w - 1, h - 1], jnp.int32))
  return k[:, 0], unit


def _aligned_slice(shape, padded_shape, origin, res, mask_origin, mask_res, window, enabled):
  """Where a costmap's window starts in the padded mask table, and what it visits.

  Only valid when `_aligned_offsets` says `unit` (the caller checks it).

  Args:
    shape: (H, W) of the costmap; padded_shape: (Hm + 2H, Wm + 2W) of the table.
    origin, res, mask_origin, mask_res, window, enabled: as keepout_one.

  Returns:
    (sx, sy) int32 start of the [H, W] window in the table, col_ok bool [W],
    row_ok bool [H] (False everywhere when the filter does not run), and run bool [].
  """
  h, w = shape
  hm, wm = padded_shape[0] - 2 * h, padded_shape[1] - 2 * w
  overlap, (x0, y0, x1, y1) = _same_frame_window((hm, wm), mask_origin, mask_res, origin, res, window)
  k0, _ = _aligned_offsets(shape, origin, res, mask_origin, mask_res)
  sx = jnp.clip(k0[0], -w, wm) + w
  sy = jnp.clip(k0[1], -h, hm) + h
  run = enabled & overlap
  cols = jnp.arange(w, dtype=jnp.int32)
  rows = jnp.arange(h, dtype=jnp.int32)
  return sx, sy, (cols >= x0) & (cols < x1), (rows >= y0) & (rows < y1) & run, run


def _aligned_one(cost, origin, res, table, i, mask_origin, mask_res, state, window, enabled,
                 *, config: KeepoutConfig, index_ok=True):
  """keepout_one for a costmap whose resolution equals the mask's (same frame).

  With res == mask_res (as float32 values) the real quotient for master cell k
  is (origin - mask_origin) / res + 0.5 + k, so its exact floor is k0 + k with
  k0 the exact floor for k = 0 (one scalar `floor_div_exact` per axis), and the
  cell is on the mask iff 0 <= k0 + k < size. The mask cells are then a plain
  [H, W] window: a `dynamic_slice` of `table`, the mask's (cost + 1) bytes
  padded by H rows and W columns of 0 (= unknown, never written), so windows
  partly or wholly off the mask read 0 there.

  In uint8 with wrap-around, c1 = cost + 1 and m1 = mask cost + 1 map 255 to 0,
  so Nav2's rule `mask != 255 and (mask > old or old == 255)` is `m1 > c1`,
  and the written value max(c1, m1) - 1.

  Args:
    cost: uint8 [H, W]; origin [2], res []: the costmap.
    table: uint8 [M, Hm + 2H, Wm + 2W] padded (cost + 1) masks; i: int32 [] the mask.
    mask_origin, mask_res, state, window, enabled, config: as keepout_one.

  Returns:
    (new cost uint8 [H, W], new state).
  """
  h, w = cost.shape
  sx, sy, col_ok, row_ok, run = _aligned_slice(cost.shape, table.shape[1:], origin, res, mask_origin,
                                               mask_res, window, enabled & index_ok)
  m1 = jax.lax.dynamic_slice(table, (i, sy, sx), (1, h, w))[0]
  m1 = jnp.where(col_ok[None, :] & row_ok[:, None], m1, jnp.uint8(0))
  c1 = cost + jnp.uint8(1)
  if config.override_lethal_cost:
    value = jnp.where(state.is_pose_lethal, jnp.uint8(config.lethal_override_cost), m1 - jnp.uint8(1))
    new_cost = jnp.where(m1 > c1, value, cost)
  else:
    new_cost = jnp.maximum(c1, m1) - jnp.uint8(1)
  return new_cost, _with_error(_processed(state, run), ~jnp.asarray(index_ok))


# SWAR helpers: four uint8 cells per uint32 word, per-byte arithmetic without carries
# between bytes (Hacker's Delight 2-18). XLA:GPU moves uint8 elementwise data at about
# a third of the HBM rate measured with 4-byte words (benchmarks/NOTES.md), so the GPU
# fast path packs the costmap and the mask into words.
_HI = 0x80808080
_LO = 0x7F7F7F7F
_ONES = 0x01010101


def _u32(v):
  return jnp.uint32(v)


def _bytes_plus_one(x):
  return ((x & _u32(_LO)) + _u32(_ONES)) ^ (x & _u32(_HI))


def _bytes_minus_one(x):
  return ((x | _u32(_HI)) - _u32(_ONES)) ^ (~x & _u32(_HI))


def _bytes_less_than(a, b):
  """0xFF in each byte where a < b (unsigned), else 0x00."""
  d = ((a | _u32(_HI)) - (b & _u32(_LO))) ^ ((a ^ ~b) & _u32(_HI))
  borrow = ((~a & b) | (~(a ^ b) & d)) & _u32(_HI)
  return (borrow >> _u32(7)) * _u32(0xFF)


def _pack(x):
  """uint8 [..., 4n] -> uint32 [..., n] (little-endian bytes)."""
  return jax.lax.bitcast_convert_type(x.reshape(*x.shape[:-1], x.shape[-1] // 4, 4), jnp.uint32)


def _unpack(x):
  """uint32 [..., n] -> uint8 [..., 4n]."""
  y = jax.lax.bitcast_convert_type(x, jnp.uint8)
  return y.reshape(*x.shape[:-1], x.shape[-1] * 4)


def _shifted_words(table):
  """uint8 [M, R, C] -> uint32 [4, M, R, Q]: entry [s, m, r, q] packs bytes 4q+s .. 4q+s+3.

  Any 4-aligned run of words starts a window at byte offset 4q + s.
  """
  m, r, c = table.shape
  q = -(-c // 4)
  table = jnp.pad(table, ((0, 0), (0, 0), (0, 4 * q + 4 - c)))
  return jnp.stack([_pack(table[:, :, s:s + 4 * q]) for s in range(4)])


def _aligned_packed_one(cost, origin, res, words, i, mask_origin, mask_res, state, window, enabled,
                        *, config: KeepoutConfig, padded_shape, index_ok=True):
  """`_aligned_one` on uint32 words: same slice arithmetic, SWAR write rule (W % 4 == 0)."""
  h, w = cost.shape
  sx, sy, col_ok, row_ok, run = _aligned_slice(cost.shape, padded_shape, origin, res, mask_origin,
                                               mask_res, window, enabled & index_ok)
  m1 = jax.lax.dynamic_slice(words, (sx % 4, i, sy, sx // 4), (1, 1, h, w // 4))[0, 0]
  col_bytes = jnp.where(col_ok, jnp.uint8(0xFF), jnp.uint8(0))
  m1 = jnp.where(row_ok[:, None], m1 & _pack(col_bytes)[None, :], _u32(0))
  c = _pack(cost)
  write = _bytes_less_than(_bytes_plus_one(c), m1)
  if config.override_lethal_cost:
    lethal = _u32(config.lethal_override_cost * _ONES)
    value = jnp.where(state.is_pose_lethal, lethal, _bytes_minus_one(m1))
  else:
    value = _bytes_minus_one(m1)
  new_cost = _unpack((c & ~write) | (value & write))
  return new_cost, _with_error(_processed(state, run), ~jnp.asarray(index_ok))


def _robot_geometry(costmap: Costmap, mask: FilterMask):
  """Per-robot geometry leaves for vmap: (origin parts, resolution parts) of the costmaps."""
  return (costmap.origin, costmap.origin_lo, costmap.resolution, costmap.resolution_lo)


def _mask_origin(mask: FilterMask, i):
  return geometry.origin_terms(mask.origin[i], None if mask.origin_lo is None else mask.origin_lo[i])


def _aligned_batch(costmap, mask, idx, idx_ok, state, window, enabled, *, config: KeepoutConfig,
                   loop: str = "auto", packed: bool | None = None):
  """The same-resolution keepout over a fleet (`_aligned_one` per robot).

  `loop` "map" runs the robots with `lax.map` (each window a contiguous slice:
  3.5x faster than the batched gather vmap makes of it on XLA:CPU), "vmap"
  vectorises them (the GPU choice); "auto" picks "map" on the CPU backend.
  `packed` processes four cells per uint32 word (needs W % 4 == 0); None picks
  it off the CPU backend, where LLVM already vectorises the uint8 loop.
  """
  h, w = costmap.cost.shape[1:]
  table = jnp.asarray(_COST1)[jax.lax.bitcast_convert_type(mask.data, jnp.uint8).astype(jnp.int32)]
  table = jnp.pad(table, ((0, 0), (h, h), (w, w)))
  on_cpu = jax.default_backend() == "cpu"
  if loop == "auto":
    loop = "map" if on_cpu else "vmap"
  if packed is None:
    packed = not on_cpu and w % 4 == 0
  if packed and w % 4:
    raise ValueError(f"the packed keepout path needs a costmap width divisible by 4; got W = {w}")

  if packed:
    words = _shifted_words(table)

    def one(cost, origin, origin_lo, res, res_lo, i, ok, st, win, en):
      return _aligned_packed_one(cost, geometry.origin_terms(origin, origin_lo),
                                 geometry.resolution_terms(res, res_lo), words, i,
                                 _mask_origin(mask, i), mask.resolution[i], st, win, en, config=config,
                                 padded_shape=table.shape[1:], index_ok=ok)
  else:
    def one(cost, origin, origin_lo, res, res_lo, i, ok, st, win, en):
      return _aligned_one(cost, geometry.origin_terms(origin, origin_lo),
                          geometry.resolution_terms(res, res_lo), table, i,
                          _mask_origin(mask, i), mask.resolution[i], st, win, en, config=config,
                          index_ok=ok)

  args = (costmap.cost, *_robot_geometry(costmap, mask), idx, idx_ok, state, window, enabled)
  if loop == "map":
    return jax.lax.map(lambda a: one(*a), args)
  if loop != "vmap":
    raise ValueError(f"loop must be 'auto', 'map' or 'vmap'; got {loop!r}")
  return jax.vmap(one)(*args)


def _batched_inputs(costmap, mask, poses, mask_index, enabled, window, transform, where):
  check_costmap(costmap, where)
  b = costmap.num_robots
  h, w = costmap.cost.shape[1:]
  idx, idx_ok, poses, enabled, transform = robot_inputs(mask, poses, b, mask_index, enabled, transform)
  if window is None:
    window = jnp.tile(jnp.asarray([0, 0, w, h], jnp.int32), (b, 1))
  else:
    window = jnp.asarray(window)
    if window.shape not in ((4,), (b, 4)) or not jnp.issubdtype(window.dtype, jnp.integer):
      raise ValueError(f"window must be integer (min_i, min_j, max_i, max_j) of shape (4,) or ({b}, 4); "
                       f"got {window.dtype}{tuple(window.shape)}")
    # Clip to the map like LayeredCostmap does.
    window = jnp.broadcast_to(window.astype(jnp.int32), (b, 4))
    window = jnp.stack([jnp.maximum(window[:, 0], 0), jnp.maximum(window[:, 1], 0),
                        jnp.minimum(window[:, 2], w), jnp.minimum(window[:, 3], h)], axis=1)
  return idx, idx_ok, poses, enabled, window, transform


def _fill_error(state: KeepoutState, b: int) -> KeepoutState:
  """A hand-built state without `error` gets an all-False one (same pytree every cycle)."""
  if state.error is None:
    state = dataclasses.replace(state, error=jnp.zeros((b,), bool))
  return state


def keepout_filter(costmap: Costmap, mask: FilterMask, poses, state: KeepoutState, *,
                   mask_index=None, enabled=None, window=None, transform=None,
                   config: KeepoutConfig = KeepoutConfig()) -> tuple[Costmap, KeepoutState]:
  """Nav2 KeepoutFilter::process over a fleet (spec §4.3-§4.4).

  Jitted at the edge (config static); inside a caller's `jit` it inlines.

  Args:
    costmap: Costmap with cost uint8 [B, H, W] (the combined map after layers).
    mask: FilterMask with M masks (M = 1 shared, or a stack with mask_index).
    poses: float [B, 3] robot (x, y, yaw) in the costmap frame (used by the
      escape mode through the state, which `keepout_update_bounds` sets).
    state: KeepoutState [B].
    mask_index: optional int [B], which mask each robot uses. Concrete values
      outside [0, M) raise; traced ones leave that robot's costmap and state
      untouched and set `state.error` (never another mask).
    enabled: optional bool [B] or scalar (Nav2 `enabled` / toggle_filter); a
      disabled robot's costmap and state pass through unchanged.
    window: optional int [B, 4] or [4] (min_i, min_j, max_i, max_j) half-open
      update window, clipped to the map; default the whole map.
    transform: optional float [B, 3] or [3] T_mask_from_global (x, y, yaw)
      when the mask frame differs from the costmap frame; None = same frame.
    config: static KeepoutConfig.

  Returns:
    (Costmap with the new cost, new KeepoutState).

  Raises:
    TypeError / ValueError: inputs of the wrong type, dtype or shape (e.g. a
      Costmap whose cost is not uint8), or a concrete mask_index out of range.
  """
  if not isinstance(config, KeepoutConfig):
    raise TypeError(f"config must be a KeepoutConfig; got {type(config).__name__}")
  idx, idx_ok, poses, enabled, window, transform = _batched_inputs(
      costmap, mask, poses, mask_index, enabled, window, transform, "keepout_filter")
  del poses
  state = _fill_error(state, costmap.num_robots)
  return _keepout_filter_jit(costmap, mask, idx, idx_ok, state, window, enabled, transform, config=config)


@functools.partial(jax.jit, static_argnames=("config",))
def _keepout_filter_jit(costmap, mask, idx, idx_ok, state, window, enabled, transform, *, config):
  with jax.named_scope("keepout_filter"):
    def one(cost, origin, origin_lo, res, res_lo, i, ok, st, win, en, tf):
      return _keepout_stack_one(cost, geometry.origin_terms(origin, origin_lo),
                                geometry.resolution_terms(res, res_lo), mask.data, i,
                                _mask_origin(mask, i), mask.resolution[i], st, win, en, tf,
                                config=config, index_ok=ok)

    tf_axis = None if transform is None else 0
    geo_axes = tuple(None if g is None else 0 for g in _robot_geometry(costmap, mask))

    def general(state):
      args = (costmap.cost, *_robot_geometry(costmap, mask), idx, idx_ok, state, window, enabled, transform)
      b, h, w = costmap.cost.shape
      # Only the SE2 path needs chunking: the same-frame gather fuses well and runs
      # 2.4x faster as one vmap (H200: 172 vs 72 Gcell/s at B=16384, 200x200).
      if transform is None or b * h * w <= _GENERAL_CHUNK_CELLS:
        return jax.vmap(one, in_axes=(0, *geo_axes, 0, 0, 0, 0, 0, tf_axis))(*args)
      # The per-cell exact arithmetic keeps ~40 float32 temporaries per cell alive at
      # once (an SE2 fleet of 655 M cells asked XLA:GPU for 107 GiB): run in chunks.
      return jax.lax.map(lambda a: one(*a), args, batch_size=max(1, _GENERAL_CHUNK_CELLS // (h * w)))

    if transform is None and config.aligned_fast_path:
      def unit_stride(origin, origin_lo, res, res_lo, i):
        return _aligned_offsets(costmap.cost.shape[1:], geometry.origin_terms(origin, origin_lo),
                                geometry.resolution_terms(res, res_lo), _mask_origin(mask, i),
                                mask.resolution[i])[1]
      aligned = jnp.all(jax.vmap(unit_stride, in_axes=(*geo_axes, 0))(*_robot_geometry(costmap, mask), idx))
      cost, new_state = jax.lax.cond(
          aligned, lambda st: _aligned_batch(costmap, mask, idx, idx_ok, st, window, enabled, config=config),
          general, state)
    else:
      cost, new_state = general(state)
    return dataclasses.replace(costmap, cost=cost), new_state


def keepout_update_bounds(costmap: Costmap, mask: FilterMask, poses, state: KeepoutState,
                          bounds, *, new_mask=None, mask_index=None, enabled=None,
                          transform=None, config: KeepoutConfig = KeepoutConfig()):
  """Nav2 KeepoutFilter::updateBounds over a fleet (spec §4.2).

  Jitted at the edge like `keepout_filter`.

  Args:
    costmap: the costmap whose geometry (origin, resolution) the bounds use.
    mask, poses, state, mask_index, enabled, transform, config: as keepout_filter.
    bounds: float [B, 4] world (min_x, min_y, max_x, max_y) grown by the layers
      this cycle (Nav2 starts from (+inf, +inf, -inf, -inf)).
    new_mask: optional bool [B] or scalar, a new mask arrived since last cycle.

  Returns:
    (new KeepoutState, new bounds float32 [B, 4]).
  """
  if not isinstance(config, KeepoutConfig):
    raise TypeError(f"config must be a KeepoutConfig; got {type(config).__name__}")
  b = costmap.num_robots
  idx, idx_ok, poses, enabled, _, transform = _batched_inputs(
      costmap, mask, poses, mask_index, enabled, None, transform, "keepout_update_bounds")
  bounds = jnp.asarray(bounds, _F32)
  if bounds.shape != (b, 4):
    raise ValueError(f"bounds must be float [B, 4] = ({b}, 4); got {tuple(bounds.shape)}")
  new_mask = jnp.asarray(False if new_mask is None else new_mask)
  if new_mask.dtype != jnp.bool_ or new_mask.shape not in ((), (b,)):
    raise ValueError(f"new_mask must be a bool scalar or bool [B] = ({b},); got "
                     f"{new_mask.dtype}{tuple(new_mask.shape)}")
  new_mask = jnp.broadcast_to(new_mask, (b,))
  state = _fill_error(state, b)
  return _update_bounds_jit(costmap, mask, idx, idx_ok, poses, state, bounds, new_mask, enabled, transform,
                            override_lethal_cost=config.override_lethal_cost)


@functools.partial(jax.jit, static_argnames=("override_lethal_cost",))
def _update_bounds_jit(costmap, mask, idx, idx_ok, poses, state, bounds, new_mask, enabled, transform, *,
                       override_lethal_cost):
  with jax.named_scope("keepout_update_bounds"):
    def one(st, i, ok, pose, bnd, origin, res, nm, en, tf):
      return keepout_update_bounds_one(
          st, mask.data[i], mask.origin[i], mask.resolution[i], pose, bnd, origin, res, nm, en, tf,
          override_lethal_cost=override_lethal_cost,
          mask_origin_lo=None if mask.origin_lo is None else mask.origin_lo[i], index_ok=ok)

    tf_axis = None if transform is None else 0
    return jax.vmap(one, in_axes=(0, 0, 0, 0, 0, 0, 0, 0, 0, tf_axis))(
        state, idx, idx_ok, poses, bounds, costmap.origin, costmap.resolution, new_mask, enabled, transform)
