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

Beyond Nav2 (an option; Nav2's centre-cell test stays the default):
`KeepoutConfig(robot_in_zone="footprint")` decides escape mode over the robot's
footprint, with hysteresis (issue #6505, PR #6526; the rule is in
jaxfilters/footprint.py). Only updateBounds changes: process() writes as Nav2.

Both are written for one robot (`*_one`) and vmapped once at the public edge.
Lanes (seed design: "covered by KeepoutFilter") are keepout masks with graded
values 1..99, which give intermediate costs round(2.54 * d).

Float policy: same-frame cell mapping is exact (jaxfilters.geometry), on the
host doubles of the costmap's origin and resolution and the mask's origin
(carried as float32 parts). With a frame transform (`transform` given) each
master cell centre is rotated in float32 (every product formed by
`geometry.rounded_product`, so the point does not depend on how XLA fuses the
program; see `_se2_axes_one`), then mapped exactly; Nav2 rotates in float64, so
a centre that lands within ~1e-6 m of a mask cell boundary may pick the
neighbouring mask cell.

Fast paths (same integers as the per-cell exact arithmetic, which the tests run
beside them; benchmarks/NOTES.md has the measurements): same frame, two exact
index vectors per robot decide every cell, bracketed in float32 and computed
exactly only where a bracket stays open, and the mask cells are one slice of
the mask when they are consecutive; with a transform, each cell's floor is
decided in ~30 float32 operations with a proof (`geometry.world_to_index_checked`)
and a robot with a cell left undecided (a centre exactly on a mask-cell edge)
settles it with the exact arithmetic.

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
from jaxfilters import footprint as footprint_lib
from jaxfilters import geometry
from jaxfilters import keepout_pallas
from jaxfilters.keepout_pallas import PallasTuning
from jaxfilters.types import Costmap, FilterMask, pytree_dataclass, check_costmap, per_robot_bool, robot_inputs

_F32 = jnp.float32
_EMPTY_BOX = (np.inf, np.inf, -np.inf, -np.inf)
_GENERAL_CHUNK_CELLS = 1 << 24  # cells per lax.map chunk of the general (per-cell) path
_PASS_CHUNK_CELLS_CPU = 1 << 22  # cells per chunk of the fast SE2 path's first pass, CPU
_PASS_CHUNK_CELLS = 1 << 26      # ... other backends


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
    override_lethal_cost: escape mode; while the robot's centre (or, with
      robot_in_zone "footprint", its footprint) is in a lethal keepout cell,
      every cell the filter writes gets `lethal_override_cost`.
    lethal_override_cost: clamped to [0, 252] like Nav2 (MAX_NON_OBSTACLE).
    aligned_fast_path: let `keepout_filter` read a robot's mask cells as one
      slice (same integers, see `_consecutive`) when, at run time, its exact
      per-column and per-row mask indices are consecutive (same frame, equal
      resolutions up to the float32 rounding of the mask's); False always
      gathers them through the two index vectors. The choice is made at run
      time (`lax.cond`), so both are compiled.
    kernel: what runs the aligned path's cells: "xla" (one fused XLA loop, every
      backend), "pallas" (the Triton kernel of `jaxfilters.keepout_pallas`, same
      integers; needs a GPU backend, or `pallas.interpret=True`, else
      `keepout_filter` raises) or "auto" (Pallas on a GPU backend, XLA
      elsewhere). The gather and other-frame paths are XLA either way.
    pallas: static `keepout_pallas.PallasTuning` of the kernel (layout, block,
      warps, interpreter).
    robot_in_zone: the escape mode's robot-in-zone test: "center" (Nav2: the
      robot centre's mask cell) or "footprint" (beyond Nav2, issue #6505 / PR
      #6526: any lethal mask cell whose centre the footprint covers, or the
      centre test; exact rule and hysteresis in jaxfilters/footprint.py). Needs
      override_lethal_cost.
    footprint: "footprint" mode: polygon ((x, y), ...) in the robot frame
      (metres, >= 3 vertices, float32 values), or None.
    robot_radius: "footprint" mode: disc radius (m) instead of a polygon.
    min_mask_resolution: "footprint" mode: the finest mask resolution (m) it
      meets; sizes the static window of mask cells the test reads (a finer
      mask raises eagerly and sets `KeepoutState.error` under jit).
    escape_clearance: "footprint" mode, m >= 0: escape, once on, stays on until
      the footprint grown by this distance is clear of lethal cells
      (`footprint.band_clearance` gives the value that leaves the robot's
      centre cell outside the zone's inscribed band).
  """
  override_lethal_cost: bool = False
  lethal_override_cost: int = constants.MAX_NON_OBSTACLE
  aligned_fast_path: bool = True
  kernel: str = "xla"
  pallas: PallasTuning = PallasTuning()
  robot_in_zone: str = "center"
  footprint: tuple | None = None
  robot_radius: float | None = None
  min_mask_resolution: float | None = None
  escape_clearance: float = 0.0

  @property
  def footprint_window(self) -> int:
    """n: the footprint test reads (2n + 1) x (2n + 1) mask cells per robot (0 in "center" mode)."""
    if self.robot_in_zone != "footprint":
      return 0
    return footprint_lib.window_cells(self.footprint, self.robot_radius, self.escape_clearance,
                                      self.min_mask_resolution)

  def __post_init__(self):
    keepout_pallas.check_kernel(self.kernel)
    if not isinstance(self.pallas, PallasTuning):
      raise ValueError(f"pallas must be a keepout_pallas.PallasTuning; got {type(self.pallas).__name__}")
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
    opts = footprint_lib.check_options(self.robot_in_zone, self.footprint, self.robot_radius,
                                       self.min_mask_resolution, self.escape_clearance,
                                       self.override_lethal_cost)
    for name, value in opts.items():
      object.__setattr__(self, name, value)


@pytree_dataclass
class KeepoutState:
  """Per-robot state KeepoutFilter carries between cycles.

  Attributes:
    is_pose_lethal: bool [B], robot centre in a lethal keepout cell (escape mode).
    last_pose_lethal: bool [B], the value at the end of the last process().
    acc_box: float32 [B, 4] world (min_x, min_y, max_x, max_y) accumulated while
      the robot is in a zone; (+inf, +inf, -inf, -inf) when empty.
    error: bool [B], the last call could not run for this robot because its
      traced `mask_index` was outside [0, M): nothing was written and the
      rest of its state was kept. After `keepout_update_bounds` with a
      "footprint" KeepoutConfig it is also True where the mask is finer than
      `min_mask_resolution` (the footprint test saw only its window).
      None in a hand-built state.
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
                              *, override_lethal_cost: bool, mask_origin_lo=None, index_ok=True,
                              config: KeepoutConfig | None = None):
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
    config: static KeepoutConfig whose `robot_in_zone` "footprint" (with
      override_lethal_cost) replaces the centre test by the footprint test of
      jaxfilters/footprint.py: the centre test OR a covered lethal cell, the
      footprint grown by `escape_clearance` while `state.is_pose_lethal` was
      True. `error` is then also set where the mask is finer than
      `min_mask_resolution` (the window read is still tested). None: Nav2's test.

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
  window_bad = jnp.asarray(False)
  if override_lethal_cost:
    lethal = pose_in_lethal_zone_one(data, mask_origin, mask_res, xy, mask_origin_lo)
    if config is not None and config.robot_in_zone == "footprint":
      yaw = pose[2] if transform is None else pose[2] + transform[2]
      margin = jnp.where(state.is_pose_lethal, jnp.float32(config.escape_clearance), jnp.float32(0.0))
      lethal = lethal | footprint_lib.footprint_in_zone_one(
          data, mask_origin, mask_res, jnp.stack([xy[0], xy[1], yaw]), polygon=config.footprint,
          radius=config.robot_radius, window=config.footprint_window, margin=margin,
          mask_origin_lo=mask_origin_lo)
      window_bad = ~footprint_lib.window_fits(mask_res, config.min_mask_resolution)
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
  out_state = _with_error(out_state, ~index_ok | (run & ~new_mask & window_bad))
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
  mo = [four(t) for t in geometry.as_terms(mask_origin)]
  o = [-four(t) for t in geometry.as_terms(origin)]
  extent = jnp.asarray([0.0, 0.0, wm, hm], _F32)       # corners (0, 0) and (Wm, Hm)
  g = geometry.trunc_div_exact([*mo, *geometry.exact_product(extent, mask_res), half, *o], res,
                               sign_fn=geometry.expansion_sign_rolled)
  g0, g1 = (g[0], g[1]), (g[2], g[3])
  overlap = ~((g0[0] >= max_i) | (g0[1] >= max_j)) & ~((g1[0] <= min_i) | (g1[1] <= min_j))
  x0, y0 = jnp.maximum(min_i, g0[0]), jnp.maximum(min_j, g0[1])
  x1, y1 = jnp.minimum(max_i, g1[0]), jnp.minimum(max_j, g1[1])
  return overlap, (x0, y0, x1, y1)


def _se2_axes_one(origin, res, transform, h, w):
  """The rotated master cell centres of one robot as per-column and per-row float32 vectors.

  The float32 rotation has one defined result: the centre cx = o + (k + 0.5) r with o,
  r the float32 sums of the host parts, then R(yaw) (cx, cy) + t summed in
  `geometry.transform_points`' order, every product a `geometry.rounded_product` (XLA
  would otherwise fuse a product and the next sum into an FMA in some programs and not
  in others: one jitted program gave the same centre two values an ulp apart). The
  exact and the fast paths share these vectors, so they decide about the same points.

  Args:
    origin, res: float32 [2], [] (or lists of float32 parts). transform: float32 [3].
    h, w: static costmap size.

  Returns:
    (xc, xs float32 [W]: c cx and s cx; yc, ys float32 [H]: c cy and s cy; t float32 [2]),
    with c, s the float32 cos and sin of the yaw.
  """
  to, tr = geometry.as_terms(origin), geometry.as_terms(res)
  o = sum(to[1:], to[0])
  r = sum(tr[1:], tr[0])
  cx = o[0] + geometry.rounded_product(jnp.arange(w, dtype=jnp.int32).astype(_F32) + 0.5, r)
  cy = o[1] + geometry.rounded_product(jnp.arange(h, dtype=jnp.int32).astype(_F32) + 0.5, r)
  c, s = jnp.cos(transform[2]), jnp.sin(transform[2])
  mul = geometry.rounded_product
  return mul(c, cx), mul(s, cx), mul(c, cy), mul(s, cy), transform[:2]


def _se2_grid(axes):
  """float32 [H, W] (px, py) from `_se2_axes_one`: (c cx - s cy) + tx, (s cx + c cy) + ty (sums only)."""
  xc, xs, yc, ys, t = axes
  return (xc[None, :] - ys[:, None]) + t[0], (xs[None, :] + yc[:, None]) + t[1]


def keepout_one(cost, origin, res, data, mask_origin, mask_res, state, window, enabled,
                transform, *, config: KeepoutConfig):
  return _keepout_stack_one(cost, origin, res, data[None], jnp.int32(0), mask_origin, mask_res, state,
                            window, enabled, transform, config=config)


def _keepout_stack_one(cost, origin, res, stack, i, mask_origin, mask_res, state, window, enabled,
                       transform, *, config: KeepoutConfig, index_ok=True, axes=None):
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
    axes: (private) this robot's `_se2_axes_one`, when the caller already formed them.

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
  if transform is None and axes is None:
    overlap, (x0, y0, x1, y1) = _same_frame_window((hm, wm), mask_origin, mask_res, origin, res, window)
    (mx, vx), (my, vy) = geometry.centres_to_cells_2d((h, w), origin, res, mask_origin, mask_res, (hm, wm))
    visit = (((cols >= x0) & (cols < x1) & vx)[None, :] & ((rows >= y0) & (rows < y1) & vy)[:, None])
    mask_val = flat[base + my[:, None] * wm + mx[None, :]]
  else:
    overlap = jnp.asarray(True)
    px, py = _se2_grid(_se2_axes_one(origin, res, transform, h, w) if axes is None else axes)
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
                       "kernel; see `_keepout_stack_one` for the arguments).\n\n" + (_keepout_stack_one.__doc__ or ""))


def _window_flags(w, h, x0, y0, x1, y1, run):
  """col_ok bool [W], row_ok bool [H] of a half-open window; rows all False when not run."""
  cols = jnp.arange(w, dtype=jnp.int32)
  rows = jnp.arange(h, dtype=jnp.int32)
  return (cols >= x0) & (cols < x1), (rows >= y0) & (rows < y1) & run


def _mask_cost_u8(d):
  """int8 mask values -> (known bool, cost uint8) in integer arithmetic (no table).

  Known are 0..100 (a byte <= 100 once read as uint8); their cost round(2.54 d) is
  2 d + ((553 d + 511) >> 10), checked for every d in 0..100 by
  tests/test_keepout_paths.py against `occ_to_cost`. Unknown bytes give garbage costs
  that `known` masks.
  """
  u = jax.lax.bitcast_convert_type(d, jnp.uint8)
  known = u <= jnp.uint8(100)
  d16 = u.astype(jnp.uint16)
  cost = (d16 * jnp.uint16(2) + ((d16 * jnp.uint16(553) + jnp.uint16(511)) >> jnp.uint16(10))).astype(jnp.uint8)
  return known, cost


def _write_u8(cost, d, visit, state, config):
  """Nav2's per-cell rule (spec §4.4) on int8 mask values d where `visit`, in uint8 arithmetic.

  With c1 = cost + 1 and m1 = mask cost + 1 (0 where unknown or not visited), both
  wrapping 255 to 0, `mask != 255 and (mask > old or old == 255)` is `m1 > c1` and
  the written value max(c1, m1) - 1 (see `_aligned_one`).
  """
  known, mc = _mask_cost_u8(d)
  m1 = jnp.where(visit & known, mc + jnp.uint8(1), jnp.uint8(0))
  c1 = cost + jnp.uint8(1)
  if config.override_lethal_cost:
    value = jnp.where(state.is_pose_lethal, jnp.uint8(config.lethal_override_cost), m1 - jnp.uint8(1))
    return jnp.where(m1 > c1, value, cost)
  return jnp.maximum(c1, m1) - jnp.uint8(1)


# ----------------------------------------------------------------------------- same frame, fast
#
# Same frame, the mask column of master column i depends on i alone (and the row on j):
# two exact index vectors per robot, [W] and [H], decide every cell. Their exact division
# costs a few hundred float32 operations per entry, so the fast path brackets each entry
# with `geometry.centre_floor_bracket` (a dozen operations) and uses the exact division
# only for a robot with an entry the bracket leaves open. When both vectors are
# consecutive (k0 + i: same resolution in practice, a float32 mask resolution against
# the costmap's double, or equal) the mask cells are one [H, W] slice of the mask padded
# with unknown cells; otherwise they are gathered through the two vectors.


def _axis_cells(shape, origin, res, mask_origin, mask_res, mshape):
  """The per-column and per-row mask cells, bracketed: (((mx, vx), (my, vy)), all_known).

  Entries are exact where `all_known` (bool []) is True; the caller falls back to
  `geometry.centres_to_cells_2d` (same integers) where it is False.
  """
  h, w = shape
  hm, wm = mshape
  n = max(h, w)
  i = jnp.arange(n, dtype=_F32)
  per_axis = lambda o: jnp.stack([jnp.full((n,), o[0], _F32), jnp.full((n,), o[1], _F32)])
  lo, hi = geometry.centre_floor_bracket(jnp.stack([i, i]), [per_axis(t) for t in geometry.as_terms(origin)],
                                         geometry.as_terms(res),
                                         [per_axis(t) for t in geometry.as_terms(mask_origin)], mask_res)
  size = jnp.asarray([[wm], [hm]], _F32)
  known = (lo == hi) | (hi < 0) | (lo >= size)          # an exact floor, or surely off the mask
  cells = jnp.clip(jnp.where(known, lo, 0.0), 0, size - 1).astype(jnp.int32)
  valid = (lo >= 0) & (lo < size)
  all_known = jnp.all(known[0, :w]) & jnp.all(known[1, :h])
  return ((cells[0, :w], valid[0, :w]), (cells[1, :h], valid[1, :h])), all_known


def _exact_axis_cells(shape, origin, res, mask_origin, mask_res, mshape):
  """`geometry.centres_to_cells_2d` (rolled expansions: a fallback, so compile time counts more)."""
  return geometry.centres_to_cells_2d(shape, origin, res, mask_origin, mask_res, mshape,
                                      sign_fn=geometry.expansion_sign_rolled)


def _consecutive(cells, valid, size):
  """(k0 int32, ok bool): ok when entry i's mask cell is k0 + i wherever that lies on the mask.

  Then `valid` is exactly 0 <= k0 + i < size, so a slice starting at k0 of the mask
  padded with unknown cells reads the same cells as the gather.
  """
  n = cells.shape[0]
  i = jnp.arange(n, dtype=jnp.int32)
  first = jnp.argmax(valid)
  k0 = jnp.where(jnp.any(valid), cells[first] - first, -n)
  k = k0 + i
  ok = jnp.all(valid == ((k >= 0) & (k < size))) & jnp.all(~valid | (cells == k))
  return k0, ok


def _slice_start(k0, n, size):
  """Start of a window of n entries in an axis padded by n on each side (clipped: all padding)."""
  return jnp.clip(k0, -n, size) + n


def _same_frame_window_fast(shape_m, mask_origin, mask_res, origin, res, window):
  """`_same_frame_window` from float32 estimates: (overlap, (x0, y0, x1, y1), known bool []).

  Each of the four worldToMapNoBounds quotients (w - o) / res, w = mask origin +
  (0 or size) mask_res + half a mask cell, is bracketed (`geometry.quotient_bracket`;
  the costmap resolution's lower parts enter the error as a relative term). The
  result equals `_same_frame_window`'s where `known`: where the bracket's ends give
  the same overlap and clipped window.
  """
  hm, wm = shape_m
  four = lambda o: jnp.stack([o[0], o[1], o[0], o[1]])
  mo = [four(t) for t in geometry.as_terms(mask_origin)]
  o = [four(t) for t in geometry.as_terms(origin)]
  r = geometry.as_terms(res)
  u = 2.0 ** -24
  e = jnp.asarray([0.0, 0.0, wm, hm], _F32) * mask_res
  c1 = mo[0] + e
  c2 = c1 + 0.5 * mask_res
  c = c2 - o[0]
  err = u * (jnp.abs(e) + jnp.abs(c1) + jnp.abs(c2) + jnp.abs(c))
  for t in mo[1:] + o[1:]:
    err = err + jnp.abs(t)
  rel = sum((jnp.abs(t) for t in r[1:]), jnp.zeros((), _F32)) / r[0]
  err = err + 2.0 * rel * (jnp.abs(c) + err)
  lo, hi = geometry.quotient_bracket(c, err, r[0])
  ok = jnp.all(jnp.isfinite(lo) & jnp.isfinite(hi) & (jnp.abs(lo) < 2.0 ** 30) & (jnp.abs(hi) < 2.0 ** 30))
  ok = ok & (rel < 2.0 ** -8)
  glo = jnp.where(ok, jnp.trunc(lo), 0.0).astype(jnp.int32)
  ghi = jnp.where(ok, jnp.trunc(hi), 0.0).astype(jnp.int32)
  min_i, min_j, max_i, max_j = window[0], window[1], window[2], window[3]

  def clip(g0, g1):
    overlap = ~((g0[0] >= max_i) | (g0[1] >= max_j)) & ~((g1[2] <= min_i) | (g1[3] <= min_j))
    return overlap, (jnp.maximum(min_i, g0[0]), jnp.maximum(min_j, g0[1]),
                     jnp.minimum(max_i, g1[2]), jnp.minimum(max_j, g1[3]))

  # Every result is monotone in each quotient (the overlap falls with the lower corner
  # and rises with the upper one, the clipped bounds rise with theirs), so it is known
  # where the bracket's two ends give the same value, even if a quotient is not: a
  # window that lies inside the mask does not need the mask's corners exactly.
  overlap_lo, box_lo = clip(ghi, glo)
  overlap_hi, box_hi = clip(glo, ghi)
  same_box = jnp.all(jnp.stack(box_lo) == jnp.stack(box_hi))
  known = ok & (overlap_lo == overlap_hi) & (~overlap_hi | same_box)
  return overlap_hi, box_hi, known


def _same_frame_prologue_one(shape, origin, res, mask_origin, mask_res, mshape, window, enabled, index_ok,
                             *, part="both", exact=False):
  """One robot's per-axis work: the index vectors and the window flags (`part` picks one or both).

  Bracketed (`exact` False: every integer proven where its `known` flag is True) or
  exact (the exact arithmetic throughout).

  Returns:
    cells ((mx, vx) int32/bool [W], (my, vy) [H]) and cells_known bool [], then flags
    (col_ok [W], row_ok [H], run []) and flags_known bool [], as `part` asks.
  """
  h, w = shape
  out = ()
  if part in ("both", "cells"):
    if exact:
      out += (_exact_axis_cells((h, w), origin, res, mask_origin, mask_res, mshape), jnp.asarray(True))
    else:
      out += _axis_cells((h, w), origin, res, mask_origin, mask_res, mshape)
  if part in ("both", "flags"):
    overlap, box, known = _same_frame_box_one(mshape, origin, res, mask_origin, mask_res, window, exact=exact)
    run = enabled & overlap & index_ok
    out += (_window_flags(w, h, *box, run) + (run,), known)
  return out


def _same_frame_box_one(mshape, origin, res, mask_origin, mask_res, window, *, exact=False):
  """The window clip, bracketed or exact: (overlap bool [], (x0, y0, x1, y1) int32 [], known bool [])."""
  if exact:
    overlap, box = _same_frame_window(mshape, mask_origin, mask_res, origin, res, window)
    return overlap, box, jnp.asarray(True)
  return _same_frame_window_fast(mshape, mask_origin, mask_res, origin, res, window)


# The slice test in O(1) per robot. The exact mask column of master column i is
# floor(q(i)), q(i) = (o + (i + 0.5) r - mo) / mr: affine in i with slope r / mr > 0. So
# g(i) = q(i) - i is affine too, and if floor(q(a)) = k + a and floor(q(b)) = k + b, both
# g(a) and g(b) lie in [k, k + 1), hence every g(i) between does, i.e. floor(q(i)) = k + i
# for every i in [a, b]: the two end floors decide the whole run (and the converse is
# trivial). Columns outside the update window [x0, x1) are never written, so the ends are
# the window's first and last columns; and if the last one's q is < 0 (or the first one's
# >= the mask's size) every column between is off the mask on that side, so the window
# reads only padding. Same for rows.


def _slice_ends(shape, box):
  """Window end indices: (ends int32 [2 axes, 2] = [[a_x, b_x], [a_y, b_y]], empty bool [])."""
  h, w = shape
  x0, y0, x1, y1 = box
  a = jnp.stack([jnp.maximum(x0, 0), jnp.maximum(y0, 0)])
  b = jnp.stack([jnp.minimum(x1, w), jnp.minimum(y1, h)]) - 1
  return jnp.stack([a, b], axis=1), jnp.any(b < a)


def _slice_decision(ends, empty, lo, hi, known, size, n):
  """(start k0 int32 [2], sliced bool [], decided bool []) from end floors lo <= floor <= hi ([2, 2])."""
  off = (hi[:, 1] < 0) | (lo[:, 0] >= size)                   # whole run off the mask, one side
  both = known[:, 0] & known[:, 1]
  span = (ends[:, 1] - ends[:, 0]).astype(lo.dtype)
  consecutive = both & (lo[:, 1] - lo[:, 0] == span)
  axis_slice = off | consecutive
  axis_gather = both & ~off & ~consecutive
  axis_decided = axis_slice | axis_gather
  k0 = jnp.where(consecutive & ~off, lo[:, 0].astype(jnp.int32) - ends[:, 0], -n)
  sliced = empty | jnp.all(axis_slice)
  decided = empty | jnp.all(axis_decided) | jnp.any(axis_gather)
  return jnp.where(empty, -n, k0), sliced, decided


def _slice_test_one(shape, origin, res, mask_origin, mask_res, mshape, box, *, exact=False):
  """Whether one robot's window reads its mask cells as one slice: (sx, sy, sliced, decided).

  `box` (x0, y0, x1, y1) int32 [] is the clipped update window (x1 <= x0 or y1 <= y0:
  nothing to write). The end floors are bracketed (`geometry.centre_floor_bracket`,
  decided where both ends of each axis are known or one axis is surely not
  consecutive) or `exact` (`geometry.floor_div_exact`, always decided).

  Returns:
    sx, sy int32 []: the window's start in the padded table (`_slice_start`; any
      all-padding start for a window that reads no mask cell); sliced bool []: the
      window's mask cells are that slice (same integers as the index vectors); decided
      bool []: `sliced` is proven (False: rerun exactly).
  """
  h, w = shape
  hm, wm = mshape
  n = jnp.asarray([w, h], jnp.int32)
  size = jnp.asarray([wm, hm], jnp.int32)
  ends, empty = _slice_ends(shape, box)
  col = lambda t: jnp.asarray(t, _F32)[:, None]
  o = [col(t) for t in geometry.as_terms(origin)]
  mo = [col(t) for t in geometry.as_terms(mask_origin)]
  idx = ends.astype(_F32)
  if exact:
    terms = geometry.cell_centre_terms(idx, o, res) + [-t for t in mo]
    cells = geometry.floor_div_exact(terms, mask_res, sign_fn=geometry.expansion_sign_rolled)
    negative = geometry.expansion_sign_rolled(terms) < 0
    # An exact floor is the floor for |quotient| < 2**22; beyond, its sign and side are still right.
    lo = jnp.where(negative, jnp.minimum(cells, -1), cells)
    k0, sliced, _ = _slice_decision(ends, empty, lo, lo, jnp.ones_like(negative), size, n)
    decided = jnp.asarray(True)
  else:
    lo, hi = geometry.centre_floor_bracket(idx, o, res, mo, mask_res)
    known = (lo == hi) & (jnp.abs(lo) < 2.0 ** 22)
    k0, sliced, decided = _slice_decision(ends, empty, lo, hi, known, size.astype(_F32), n)
  sx, sy = _slice_start(k0[0], w, wm), _slice_start(k0[1], h, hm)
  return sx, sy, sliced, decided


def _gather_write_one(cost, flat, i, mshape, mx, vx, my, vy, col_ok, row_ok, state, *, config: KeepoutConfig):
  """The write rule on mask cells gathered through the two index vectors (uint8 [H, W])."""
  hm, wm = mshape
  d = flat[i * (hm * wm) + my[:, None] * wm + mx[None, :]]
  return _write_u8(cost, d, (col_ok & vx)[None, :] & (row_ok & vy)[:, None], state, config)


def _slice_write_one(cost, padded, i, sx, sy, col_ok, row_ok, state, *, config: KeepoutConfig):
  """The write rule on one [H, W] slice of the masks padded with unknown (-1) cells (uint8 [H, W])."""
  h, w = cost.shape
  d = jax.lax.dynamic_slice(padded, (i, sy, sx), (1, h, w))[0]
  return _write_u8(cost, d, col_ok[None, :] & row_ok[:, None], state, config)


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


def _aligned_one(cost, table, i, sx, sy, col_ok, row_ok, state, *, config: KeepoutConfig):
  """The slice kernel on a (cost + 1) table (the GPU choice when W % 4 != 0).

  With the mask cell of master cell (j, k) at (k0y + j, k0x + k) (`_consecutive`), the
  mask cells are a plain [H, W] window: a `dynamic_slice` of `table`, the mask's
  (cost + 1) bytes padded by H rows and W columns of 0 (= unknown, never written), so
  windows partly or wholly off the mask read 0 there.

  In uint8 with wrap-around, c1 = cost + 1 and m1 = mask cost + 1 map 255 to 0,
  so Nav2's rule `mask != 255 and (mask > old or old == 255)` is `m1 > c1`,
  and the written value max(c1, m1) - 1.

  Args:
    cost: uint8 [H, W]. table: uint8 [M, Hm + 2H, Wm + 2W] padded (cost + 1) masks;
    i: int32 [] the mask; (sx, sy): the window's start in the table; col_ok [W], row_ok [H].
    state, config: as keepout_one.

  Returns:
    new cost uint8 [H, W].
  """
  h, w = cost.shape
  m1 = jax.lax.dynamic_slice(table, (i, sy, sx), (1, h, w))[0]
  m1 = jnp.where(col_ok[None, :] & row_ok[:, None], m1, jnp.uint8(0))
  c1 = cost + jnp.uint8(1)
  if config.override_lethal_cost:
    value = jnp.where(state.is_pose_lethal, jnp.uint8(config.lethal_override_cost), m1 - jnp.uint8(1))
    return jnp.where(m1 > c1, value, cost)
  return jnp.maximum(c1, m1) - jnp.uint8(1)


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


def _aligned_packed_one(cost, words, i, sx, sy, col_ok, row_ok, state, *, config: KeepoutConfig):
  """`_aligned_one` on uint32 words: same slice, SWAR write rule (W % 4 == 0)."""
  h, w = cost.shape
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
  return _unpack((c & ~write) | (value & write))


def _robot_geometry(costmap: Costmap, mask: FilterMask):
  """Per-robot geometry leaves for vmap: (origin parts, resolution parts) of the costmaps."""
  return (costmap.origin, costmap.origin_lo, costmap.resolution, costmap.resolution_lo)


def _mask_origin(mask: FilterMask, i):
  return geometry.origin_terms(mask.origin[i], None if mask.origin_lo is None else mask.origin_lo[i])


def _tree_where(pick, a, b):
  """Per-robot choice between two batched pytrees (pick bool [B])."""
  return jax.tree.map(lambda x, y: jnp.where(pick.reshape(pick.shape + (1,) * (x.ndim - 1)), x, y), a, b)


def _rerun_if_any(need, fast, exact_fn, args, capacity):
  """`_rerun` inside one batch-level `lax.cond`: when no robot needs the exact arithmetic
  (`need` bool [B] all False) nothing runs, not even a loop test (on a GPU each turn of a
  loop whose trip count is data dependent waits for the host)."""
  return jax.lax.cond(jnp.any(need), lambda f: _rerun(need, f, exact_fn, args, capacity), lambda f: f, fast)


def _same_frame_prologue(costmap, mask, idx, idx_ok, window, enabled):
  """The same-frame fast path's per-robot scalars, for the whole fleet.

  The window clip is bracketed (`_same_frame_window_fast`) and the slice test too
  (`_slice_test_one`); the robots whose bracket is open redo that part exactly
  (`_rerun`, inside one batch-level `lax.cond` taken only when there are any), so a
  fleet without such robots runs a few fused elementwise passes over [B] scalars and
  no loop.

  Args:
    costmap, mask: as keepout_filter; idx int32 [B], idx_ok bool [B] (mask index in range),
    window int32 [B, 4] (clipped to the costmap), enabled bool [B].

  Returns:
    box (x0, y0, x1, y1) int32 [B] each: the clipped update window, empty ((0, 0, 0, 0))
    where a robot does not run; run bool [B]; sx, sy int32 [B]: the window's start in
    the padded table; sliced bool [B]: the robot's mask cells are that slice.
  """
  b, h, w = costmap.cost.shape
  hm, wm = mask.data.shape[1:]
  geo = _robot_geometry(costmap, mask)
  geo_axes = tuple(None if g is None else 0 for g in geo)

  def batched(fn):
    def one(origin, origin_lo, res, res_lo, i, extra):
      o, r = geometry.origin_terms(origin, origin_lo), geometry.resolution_terms(res, res_lo)
      return fn(o, r, _mask_origin(mask, i), mask.resolution[i], extra)
    return lambda args: jax.vmap(one, in_axes=(*geo_axes, 0, 0))(*args)

  box_of = lambda exact: batched(lambda o, r, mo, mr, win: _same_frame_box_one((hm, wm), o, r, mo, mr, win,
                                                                               exact=exact))
  slice_of = lambda exact: batched(lambda o, r, mo, mr, bx: _slice_test_one((h, w), o, r, mo, mr, (hm, wm), bx,
                                                                             exact=exact))
  # Robots left open redo that part exactly, `capacity` at a time (few in practice: centres
  # exactly on mask-cell edges, grids whose edges line up).
  capacity = _rerun_capacity(b)
  args = (*geo, idx, window)
  overlap, box, box_known = box_of(False)(args)
  overlap, box = _rerun_if_any(~box_known, (overlap, box), lambda a: box_of(True)(a)[:2], args, capacity)
  run = enabled & overlap & idx_ok
  box = tuple(jnp.where(run, c, 0) for c in box)      # a robot that does not run: an empty window
  args = (*geo, idx, box)
  sx, sy, sliced, decided = slice_of(False)(args)
  sx, sy, sliced = _rerun_if_any(~decided, (sx, sy, sliced), lambda a: slice_of(True)(a)[:3], args, capacity)
  return box, run, sx, sy, sliced


def _same_frame_batch(costmap, mask, idx, idx_ok, state, window, enabled, *, config: KeepoutConfig,
                      loop: str, packed: bool | None = None, gather_impl: str | None = None):
  """The fast same-frame keepout over a fleet: same integers as the exact path.

  The prologue works on per-robot scalars (`_same_frame_prologue`): the window clip,
  then the slice test at the window's two end columns and rows (`_slice_test_one`),
  both bracketed, with exact reruns only for robots left open. Only when some robot is not sliced are the [B, W] / [B, H] index
  vectors built (bracketed, exact reruns for robots left open), inside that branch.
  Then `loop` "map" runs the cells one robot after another with `lax.map` (each robot's
  slice-or-gather choice a real branch, each slice contiguous: the CPU choice), "vmap"
  vectorises them too (the GPU choice) and makes the choice once for the batch.
  `packed` (vmap) runs the slice on four cells per uint32 word (needs W % 4 == 0);
  None picks it off the CPU backend. `gather_impl` (vmap) picks the kernel of a fleet
  that is not sliced throughout (`_other_res_batch`); None reads `_GATHER_IMPL`.
  """
  b, h, w = costmap.cost.shape
  m, hm, wm = mask.data.shape
  mshape = (hm, wm)
  flat = mask.data.reshape(-1)
  geo_axes = tuple(None if g is None else 0 for g in _robot_geometry(costmap, mask))
  geo = _robot_geometry(costmap, mask)

  def terms(origin, origin_lo, res, res_lo, i):
    return (geometry.origin_terms(origin, origin_lo), geometry.resolution_terms(res, res_lo), _mask_origin(mask, i),
            mask.resolution[i])

  def per_robot(fn, *extra_axes):
    return jax.vmap(fn, in_axes=(*geo_axes, 0, *extra_axes))

  box, run, sx, sy, sliced = _same_frame_prologue(costmap, mask, idx, idx_ok, window, enabled)
  new_state = _with_error(jax.vmap(_processed)(state, run), ~idx_ok)
  if not config.aligned_fast_path:
    sliced = jnp.zeros((b,), bool)
  flags = lambda bx: _window_flags(w, h, *bx, True)

  def vectors():
    """Index vectors ((mx, vx), (my, vy)) [B, W] / [B, H]: bracketed, exact reruns where open."""
    def one(origin, origin_lo, res, res_lo, i, exact=False):
      o, r, mo, mr = terms(origin, origin_lo, res, res_lo, i)
      if exact:
        return _exact_axis_cells((h, w), o, r, mo, mr, mshape), jnp.asarray(True)
      return _axis_cells((h, w), o, r, mo, mr, mshape)
    cells, known = per_robot(one)(*geo, idx)
    exact = lambda a: per_robot(functools.partial(one, exact=True))(*a)[0]
    return _rerun_if_any(~known, cells, exact, (*geo, idx), _rerun_capacity(b))

  def gather(c, i, mx, vx, my, vy, bx, st):
    return _gather_write_one(c, flat, i, mshape, mx, vx, my, vy, *flags(bx), st, config=config)

  def gather_all(cost):
    """The vmap (GPU) choice for robots not sliced: `_other_res_batch` by kernel `gather_impl`."""
    (mx, vx), (my, vy) = vectors()
    col_ok, row_ok = jax.vmap(flags)(box)
    return _other_res_batch((cost, idx, mx, vx, my, vy, col_ok, row_ok, state), mask, config=config,
                            impl=gather_impl)

  table_bytes = m * (hm + 2 * h) * (wm + 2 * w)
  if keepout_pallas.use_pallas(config.kernel, config.pallas, table_bytes=table_bytes):
    return _pallas_batch(costmap.cost, mask.data, sliced, idx, sx, sy, box, state, gather_all,
                         config=config), new_state
  if loop == "map":
    def all_sliced():
      padded = jnp.pad(mask.data, ((0, 0), (h, h), (w, w)), constant_values=-1)
      return jax.lax.map(lambda a: _slice_write_one(a[0], padded, a[1], a[2], a[3], *flags(a[4]), a[5],
                                                    config=config),
                         (costmap.cost, idx, sx, sy, box, state))

    def mixed():
      padded = jnp.pad(mask.data, ((0, 0), (h, h), (w, w)), constant_values=-1)
      (mx, vx), (my, vy) = vectors()

      def body(a):
        c, i, mx, vx, my, vy, bx, st, x, y, sl = a
        return jax.lax.cond(sl, lambda: _slice_write_one(c, padded, i, x, y, *flags(bx), st, config=config),
                            lambda: gather(c, i, mx, vx, my, vy, bx, st))
      return jax.lax.map(body, (costmap.cost, idx, mx, vx, my, vy, box, state, sx, sy, sliced))

    # A branch inside the loop costs a copy of every robot's result (2x for the slice on
    # XLA:CPU), so a fleet that is sliced, or gathered, throughout runs a loop without one.
    def map_gather():
      (mx, vx), (my, vy) = vectors()
      return jax.lax.map(lambda a: gather(*a), (costmap.cost, idx, mx, vx, my, vy, box, state))
    return jax.lax.cond(jnp.all(sliced), all_sliced,
                        lambda: jax.lax.cond(jnp.any(sliced), mixed, map_gather)), new_state
  if loop != "vmap":
    raise ValueError(f"loop must be 'auto', 'map' or 'vmap'; got {loop!r}")
  if packed is None:
    packed = jax.default_backend() != "cpu" and w % 4 == 0
  if packed and w % 4:
    raise ValueError(f"the packed keepout path needs a costmap width divisible by 4; got W = {w}")

  def by_slice():
    table = _cost_plus_one_table(mask.data, h, w)
    if packed:
      words = _shifted_words(table)
      one = lambda c, i, x, y, bx, st: _aligned_packed_one(c, words, i, x, y, *flags(bx), st, config=config)
    else:
      one = lambda c, i, x, y, bx, st: _aligned_one(c, table, i, x, y, *flags(bx), st, config=config)
    return jax.vmap(one)(costmap.cost, idx, sx, sy, box, state)

  return jax.lax.cond(jnp.all(sliced), by_slice, lambda: gather_all(costmap.cost)), new_state


def _cost_plus_one_table(data, h, w):
  """uint8 [M, Hm + 2H, Wm + 2W]: the masks' (cost + 1) bytes (`_COST1`) padded with 0 (unknown)."""
  table = jnp.asarray(_COST1)[jax.lax.bitcast_convert_type(data, jnp.uint8).astype(jnp.int32)]
  return jnp.pad(table, ((0, 0), (h, h), (w, w)))


def _pallas_batch(cost, data, sliced, idx, sx, sy, box, state, gather_all, *, config: KeepoutConfig):
  """The same-frame cells with the Pallas kernel on the sliced robots (`KeepoutConfig.kernel`).

  The kernel takes per-robot scalars (`keepout_pallas.slice_params_from_bounds`: the
  window bounds, no [B, W] flags); it writes the sliced robots and passes the others
  through; those are then gathered from its result (their cells are still the old
  ones), only when there are any (`gather_all(cost)` gathers every robot). Without
  `in_place` a fleet not sliced throughout is gathered at once; `in_place`'s kernel must not
  sit in a `lax.cond` branch (XLA would copy the costmap into the branch to update it
  there).
  """
  h, w = cost.shape[1:]
  x0, y0, x1, y1 = box

  def kernel_then_gather():
    params = keepout_pallas.slice_params_from_bounds(idx, sx, sy, x0, x1, y0, y1, sliced, state.is_pose_lethal,
                                                     shape=(h, w))
    out = keepout_pallas.aligned_write(cost, _cost_plus_one_table(data, h, w), params,
                                       escape=config.override_lethal_cost,
                                       lethal_cost=config.lethal_override_cost, tuning=config.pallas)

    def rest(out):
      return _tree_where(sliced, out, gather_all(out))
    return jax.lax.cond(jnp.all(sliced), lambda o: o, rest, out)

  if config.pallas.in_place:
    return kernel_then_gather()
  # A fleet not sliced throughout is gathered whole (exact for every robot), as on the XLA
  # vmap path: the kernel plus a gather of the rest measured 187 against 445 Gcell/s for
  # the gather alone (H100, other-resolution fleet with 24 of 16384 robots sliced).
  return jax.lax.cond(jnp.all(sliced), kernel_then_gather, lambda: gather_all(cost))


# ----------------------------------------------------------------------------- other frame, fast
#
# With a transform each master cell's centre is rotated in float32 and mapped with an
# exact floor. `geometry.world_to_cell_checked` decides that floor for every cell in
# ~45 float32 operations (instead of several hundred) and proves it, leaving undecided
# only centres within ~1e-13 relative of a mask-cell edge (in practice: exactly on one);
# a robot with such a cell in its window runs the exact per-cell path.


def _se2_codes_one(axes, i, mask_origin, mask_res, mshape, window, run):
  """What the fast other-frame path decided per cell: int32 [H, W].

  The flat index (into the [M * Hm * Wm] mask stack) of the cell's mask cell where it
  is visited and proven on the mask, -1 where it is not visited or proven off the
  mask, -2 where `geometry.world_to_cell_checked` left it undecided.
  """
  xc, ys = axes[0], axes[3]
  h, w = ys.shape[0], xc.shape[0]
  hm, wm = mshape
  px, py = _se2_grid(axes)
  index, inside, certain = geometry.world_to_index_checked(px, py, mask_origin, mask_res, wm, hm)
  col_ok, row_ok = _window_flags(w, h, window[0], window[1], window[2], window[3], run)
  visit = col_ok[None, :] & row_ok[:, None]
  code = jnp.where(certain, jnp.where(inside, i * (hm * wm) + index, -1), -2)
  return jnp.where(visit, code, -1)


def _se2_write_one(cost, code, flat, state, *, config: KeepoutConfig):
  """The write rule on `_se2_codes_one`'s cells: new cost uint8 [H, W]."""
  d = flat[jnp.maximum(code, 0)]
  return _write_u8(cost, d, code >= 0, state, config)


def _rerun(need, fast, exact_fn, args, capacity):
  """`fast` (a batched pytree) with the robots where `need` replaced by `exact_fn`'s results.

  exact_fn maps batched args to batched results (one compiled copy). The robots that
  need it are gathered `capacity` at a time, in a loop of as many turns as that takes
  (none when no robot needs it); the last turn's spare slots redo robot 0 (or another
  already redone), whose exact result is right either way.
  """
  b = need.shape[0]
  count = jnp.sum(need.astype(jnp.int32))
  order = jnp.nonzero(need, size=b + capacity, fill_value=0)[0]

  def body(k, out):
    if capacity == 1:   # in-place slices: a scatter would copy the whole batch each turn
      r = order[k]
      res = exact_fn(jax.tree.map(lambda a: jax.lax.dynamic_slice_in_dim(a, r, 1), args))
      return jax.tree.map(lambda o, x: jax.lax.dynamic_update_slice_in_dim(o, x, r, 0), out, res)
    sel = jax.lax.dynamic_slice(order, (k * capacity,), (capacity,))
    res = exact_fn(jax.tree.map(lambda a: a[sel], args))
    return jax.tree.map(lambda o, r: o.at[sel].set(r), out, res)

  return jax.lax.fori_loop(0, (count + capacity - 1) // capacity, body, fast)


def _rerun_capacity(b):
  return min(b, max(8, b // 32))


def _divisor_at_most(b, limit):
  """The largest divisor of b that is <= max(limit, 1): lax.map chunks without a remainder
  (a remainder chunk runs outside the loop, where XLA fuses it into the next pass)."""
  return max(d for d in range(1, min(b, max(limit, 1)) + 1) if b % d == 0)


_FIX_CELLS = 64   # undecided cells of one robot settled one by one before the whole window is redone


def _se2_fix_one(new_cost, code, cost, axes, stack, i, mask_origin, mask_res, state, window, run, *,
                 config: KeepoutConfig, mode: str = "auto"):
  """Settles one robot's undecided cells (code -2) exactly: its final cost, uint8 [H, W].

  `mode` "few" maps up to `_FIX_CELLS` of them with `geometry.world_to_cell` (the
  exact path's arithmetic, on the same float32 points; padding slots redo cell 0,
  whose exact result is right either way); "whole" reruns the robot's window with
  `_keepout_stack_one`; "auto" picks "few" when it covers them all (a real branch on
  the CPU loop; under vmap the batch code calls the modes apart).
  """
  h, w = cost.shape
  hm, wm = stack.shape[1:]
  undecided = (code == -2).reshape(-1)

  def few():
    sel = jnp.nonzero(undecided, size=_FIX_CELLS, fill_value=0)[0]
    row, col = sel // w, sel % w
    xc, xs, yc, ys, t = axes
    px, py = (xc[col] - ys[row]) + t[0], (xs[col] + yc[row]) + t[1]
    mx, my, inside = geometry.world_to_cell(px, py, mask_origin, mask_res, wm, hm)
    col_ok, row_ok = _window_flags(w, h, window[0], window[1], window[2], window[3], run)
    visit = inside & col_ok[col] & row_ok[row]
    d = stack.reshape(-1)[i * (hm * wm) + my * wm + mx]
    value = _write_u8(cost.reshape(-1)[sel], d, visit, state, config)
    return new_cost.reshape(-1).at[sel].set(value).reshape(h, w)

  def whole():
    return _keepout_stack_one(cost, None, None, stack, i, mask_origin, mask_res, state, window, run, None,
                              config=config, axes=axes)[0]

  if mode == "few":
    return few()
  if mode == "whole":
    return whole()
  return jax.lax.cond(jnp.sum(undecided.astype(jnp.int32)) <= _FIX_CELLS, few, whole)


def _se2_batch(costmap, mask, idx, idx_ok, state, window, enabled, transform, *, config: KeepoutConfig,
               loop: str, impl: str | None = None):
  """The fast other-frame keepout over a fleet: same integers as the exact path.

  `impl` (one of `_SE2_IMPLS`; None reads `_SE2_IMPL_CPU` on the CPU backend and
  `_SE2_IMPL` on the others) picks the kernel:

  * "codes": two passes, the cells' codes (`_se2_codes_one`, written out so that XLA
    does not fuse the arithmetic into the gather, which runs it several times slower on
    XLA:CPU), then the gather and the write rule. Robots with undecided cells are then
    settled by `_se2_fix_one` (`_rerun`): one after another in a loop of as many turns
    as there are such robots ("map"), or gathered and settled together ("vmap").
  * "fused": the same codes computed inside the gather's pass (no [B, H, W] int32
    array), and once more in a reduction that finds the robots to settle.
  * "thresholds", "thresholds_packed": every cell decided exactly in one pass by the
    masks' edge tables (`_se2_edges_one`): no undecided cells, no second pass; robots
    whose mask geometry the tables do not cover (`geometry.edge_thresholds`' `trusted`,
    never for a map file's values) run the exact per-cell path. "_packed" works on
    four cells per uint32 word (W % 4 != 0 runs "thresholds").
  """
  if impl is None:
    impl = _SE2_IMPL_CPU if jax.default_backend() == "cpu" else _SE2_IMPL
  if impl not in _SE2_IMPLS:
    raise ValueError(f"impl must be one of {_SE2_IMPLS}; got {impl!r}")
  if loop not in ("map", "vmap"):
    raise ValueError(f"loop must be 'auto', 'map' or 'vmap'; got {loop!r}")
  b, h, w = costmap.cost.shape
  m, hm, wm = mask.data.shape
  flat = mask.data.reshape(-1)
  geo_axes = tuple(None if g is None else 0 for g in _robot_geometry(costmap, mask))

  def axes_of(origin, origin_lo, res, res_lo, tf):
    return _se2_axes_one(geometry.origin_terms(origin, origin_lo), geometry.resolution_terms(res, res_lo), tf,
                         h, w)

  axes = jax.vmap(axes_of, in_axes=(*geo_axes, 0))(*_robot_geometry(costmap, mask), transform)
  run = enabled & idx_ok
  new_state = _with_error(jax.vmap(_processed)(state, run), ~idx_ok)
  if impl.startswith("thresholds"):
    packed = impl == "thresholds_packed" and w % 4 == 0
    return _se2_edges_batch(costmap.cost, mask, axes, idx, state, window, run, config=config, loop=loop,
                            packed=packed), new_state

  def codes_one(a):
    ax, i, win, rn = a
    return _se2_codes_one(ax, i, _mask_origin(mask, i), mask.resolution[i], (hm, wm), win, rn)

  def write(c, k, st):
    return jax.vmap(lambda c, k, st: _se2_write_one(c, k, flat, st, config=config))(c, k, st)

  def fix(new, code, old, ax, i, st, win, rn, mode="auto"):
    return _se2_fix_one(new, code, old, ax, mask.data, i, _mask_origin(mask, i), mask.resolution[i], st, win, rn,
                        config=config, mode=mode)

  def fused(pr, c, st):
    """(new cost, undecided cells per robot) of a group of robots, codes never written out."""
    new = jax.vmap(lambda a, c, st: _se2_write_one(c, codes_one(a), flat, st, config=config))(pr, c, st)
    return new, jax.vmap(lambda a: jnp.sum((codes_one(a) == -2).astype(jnp.int32)))(pr)

  per_robot = (axes, idx, window, run)
  if loop == "map":
    # Chunks of robots, each: codes robot by robot (an inner loop, so XLA writes them out),
    # then gather and write. Every buffer stays a few MB: XLA:CPU maps fresh pages for
    # buffers beyond glibc's 32 MB mmap threshold on every call (a 40 MB int32 code array
    # cost 10,000 page faults, ~10 ms, per call).
    cb = _divisor_at_most(b, max(2, (1 << 21) // (h * w)))
    split = lambda x: x.reshape(b // cb, cb, *x.shape[1:])

    def chunk(a):
      pr, c, st = a
      if impl == "fused":
        new, undecided = fused(pr, c, st)
        return new, undecided > 0
      k = jax.lax.map(codes_one, pr)
      return write(c, k, st), jnp.any(k == -2, axis=(1, 2))

    cost, need = jax.lax.map(chunk, jax.tree.map(split, (per_robot, costmap.cost, state)))
    cost, need = cost.reshape(b, h, w), need.reshape(b)

    def settle(new, old, ax, i, st, win, rn):
      return fix(new, codes_one((ax, i, win, rn)), old, ax, i, st, win, rn)
    args = (cost, costmap.cost, axes, idx, state, window, run)
    return _rerun(need, cost, lambda a: jax.vmap(settle)(*a), args, 1), new_state
  if impl == "fused":
    cost, undecided = fused(per_robot, costmap.cost, state)
    # The fixes recompute a robot's codes (it has none written out).
    fix_codes = lambda new, old, ax, i, st, win, rn, mode: fix(new, codes_one((ax, i, win, rn)), old, ax, i, st, win,
                                                                rn, mode=mode)
    args = (cost, costmap.cost, axes, idx, state, window, run)
  else:
    chunk_cells = _PASS_CHUNK_CELLS_CPU if jax.default_backend() == "cpu" else _PASS_CHUNK_CELLS
    codes = jax.lax.map(codes_one, per_robot, batch_size=_divisor_at_most(b, chunk_cells // (h * w)))
    cost = write(costmap.cost, codes, state)
    undecided = jnp.sum((codes == -2).astype(jnp.int32), axis=(1, 2))
    fix_codes = lambda new, code, old, ax, i, st, win, rn, mode: fix(new, code, old, ax, i, st, win, rn, mode=mode)
    args = (cost, codes, costmap.cost, axes, idx, state, window, run)
  many = undecided > _FIX_CELLS
  # Under vmap a branch runs both sides, so the few-cells and whole-window fixes are
  # separate passes, each over the robots that need it.
  few = functools.partial(fix_codes, mode="few")
  cost = _rerun((undecided > 0) & ~many, cost, lambda a: jax.vmap(few)(*a), args, _rerun_capacity(b))
  args = (cost,) + args[1:]
  whole = functools.partial(fix_codes, mode="whole")
  return _rerun(many, cost, lambda a: jax.vmap(whole)(*a), args, min(b, 8)), new_state


# ----------------------------------------------------------------------------- other frame, edge tables
#
# `geometry.floor_by_edges` decides each cell's floor exactly from a per-mask table of edge
# thresholds (the smallest float32 at or above each mask-cell edge): an estimate good to one
# cell, two table reads and two float32 comparisons per axis, no rounding that could matter.
# So the other-frame path needs no undecided-cell flag, no reduction and no second pass.

_SE2_IMPLS = ("codes", "fused", "thresholds", "thresholds_packed")
# The kernel `keepout_filter` runs with a transform (see `_se2_batch`), off the CPU and on
# it. benchmarks/keepout_probe.py times them all on a GPU; flip `_SE2_IMPL` to its winner.
# On XLA:CPU (2-core VM, B = 256, 200x200, 2000x2000 mask, CPU time, min of 7) "codes" ran
# 38-39 ms, "thresholds" 42-44 ms (it compiles in 3 s instead of 4-6 s): XLA:CPU does not
# vectorise a loop that reads a table, so the CPU keeps "codes" unless the lead decides
# the compile time is worth more. On an H100 (benchmarks/keepout_probe.py, B = 16384, 200x200,
# 2000x2000 mask, 2026-11-22): codes 63.1, fused 82.3, thresholds 99.9, thresholds_packed
# 101.9 Gcell/s, all bit-equal to the exact path incl. the edge fleets; the plain (inexact)
# float32 floor + gather ceiling 207 Gcell/s.
_SE2_IMPL = "thresholds_packed"
_SE2_IMPL_CPU = "codes"


def _se2_edge_tables(mask: FilterMask):
  """Each mask's edge tables: (tx float32 [M * (Wm + 3)], ty float32 [M * (Hm + 3)], inv float32 [M],
  trusted bool [M]) (`geometry.edge_thresholds`, `geometry.edge_reciprocal`)."""
  _, hm, wm = mask.data.shape
  lo = mask.origin_lo

  def axis(a, size):
    parts = [mask.origin[:, a]] + ([] if lo is None else [lo[:, a, 0], lo[:, a, 1]])
    return geometry.edge_thresholds(parts, mask.resolution, size)

  tx, okx = axis(0, wm)
  ty, oky = axis(1, hm)
  inv, okr = geometry.edge_reciprocal(mask.resolution)
  return tx.reshape(-1), ty.reshape(-1), inv, okx & oky & okr


def _se2_edges_one(cost, axes, tables, source, i, mshape, window, run, state, *, config: KeepoutConfig,
                   packed: bool):
  """One robot's other-frame cells decided by the edge tables: new cost uint8 [H, W].

  The points are `_se2_grid`'s (the same float32 sums), so the integers are the exact
  path's wherever the robot's mask tables are trusted.

  Args:
    cost: uint8 [H, W]. axes: `_se2_axes_one`. tables: (tx, ty, mask origin float32
      [M, 2] (leading parts), inv [M]) from `_se2_edge_tables`.
    source: the masks' (cost + 1) bytes (`_m1_table`), flat.
    i: int32 [] the mask. mshape: (Hm, Wm). window int32 [4], run bool [], state, config.
    packed: four cells per uint32 word (W % 4 == 0).
  """
  tx, ty, mo, inv = tables
  xc, xs, yc, ys, t = axes
  h, w = cost.shape
  hm, wm = mshape
  col_ok, row_ok = _window_flags(w, h, window[0], window[1], window[2], window[3], run)

  def cells(xc, xs, col_ok):
    px = (xc[None, :] - ys[:, None]) + t[0]            # `_se2_grid`'s sums
    py = (xs[None, :] + yc[:, None]) + t[1]
    nx = geometry.floor_by_edges(px, mo[i, 0], inv[i], tx, i * (wm + 3), wm)
    ny = geometry.floor_by_edges(py, mo[i, 1], inv[i], ty, i * (hm + 3), hm)
    visit = (nx >= 0) & (nx < wm) & (ny >= 0) & (ny < hm) & col_ok[None, :] & row_ok[:, None]
    return jnp.where(visit, i * (hm * wm) + ny * wm + nx, 0), visit

  if not packed:
    index, visit = cells(xc, xs, col_ok)
    return _m1_rule_u8(cost, jnp.where(visit, source[index], jnp.uint8(0)), state, config)
  planes = []
  for s in range(4):
    index, visit = cells(xc[s::4], xs[s::4], col_ok[s::4])
    planes.append(jnp.where(visit, source[index], jnp.uint8(0)))
  return _unpack(_packed_rule(_pack(cost), _word(planes), state, config))


def _se2_edges_batch(cost, mask, axes, idx, state, window, run, *, config: KeepoutConfig, loop: str, packed: bool):
  """The edge-table kernel over a fleet, then the exact path for robots of untrusted masks."""
  b, h, w = cost.shape
  _, hm, wm = mask.data.shape
  tx, ty, inv, trusted = _se2_edge_tables(mask)
  tables = (tx, ty, mask.origin, inv)
  source = _m1_table(mask.data).reshape(-1)

  def group(a):
    c, ax, i, win, rn, st = a
    one = lambda c, ax, i, win, rn, st: _se2_edges_one(c, ax, tables, source, i, (hm, wm), win, rn, st,
                                                       config=config, packed=packed)
    return jax.vmap(one)(c, ax, i, win, rn, st)

  per_robot = (cost, axes, idx, window, run, state)
  if loop == "map":   # chunks of a few MB (see `_se2_batch`)
    cb = _divisor_at_most(b, max(2, (1 << 21) // (h * w)))
    new = jax.lax.map(group, jax.tree.map(lambda x: x.reshape(b // cb, cb, *x.shape[1:]), per_robot))
    new = new.reshape(b, h, w)
  else:
    new = group(per_robot)

  def exact(a):
    c, ax, i, st, win, rn = a
    one = lambda c, ax, i, st, win, rn: _keepout_stack_one(
        c, None, None, mask.data, i, _mask_origin(mask, i), mask.resolution[i], st, win, rn, None, config=config,
        axes=ax)[0]
    return jax.vmap(one)(c, ax, i, st, win, rn)

  return _rerun(run & ~trusted[idx], new, exact, (cost, axes, idx, state, window, run), min(b, 8))


# ----------------------------------------------------------------------------- same frame, other resolution
#
# A fleet whose mask cells are not one slice (another mask resolution) reads them through
# the two exact index vectors. The kernels below read the same cells in different orders;
# benchmarks/keepout_probe.py times them side by side on a GPU, and `_GATHER_IMPL` picks
# the one `keepout_filter` runs (flip it there once the probe has picked a winner):
#
#   "gather"  one byte gather per cell through both vectors, uint8 write rule (the default);
#   "packed"  four cells per uint32 word: four byte gathers from the (cost + 1) table, the
#             write rule in SWAR word arithmetic, whole-word loads and stores of the costs
#             (XLA:GPU moves bytes one at a time in an elementwise loop); W % 4 != 0 runs
#             "gather";
#   "rows"    two steps: the mask row each costmap row reads, W columns from the first
#             mask column the robot reads (a [H, W] slab of contiguous row slices), then
#             the columns inside the slab;
#   "window"  the box of mask cells the robot reads, one [H, W] dynamic slice, then a
#             gather inside it.
#
# "rows" and "window" need the cells a robot reads to span at most W columns and H rows
# (a mask as coarse as the costmap or coarser); a fleet with a robot beyond that runs
# "gather" (one batch-wide branch). Every kernel gives "gather"'s integers
# (tests/test_keepout_paths.py).

_GATHER_IMPLS = ("gather", "packed", "rows", "window")
# On an H100 (benchmarks/keepout_probe.py, B = 16384, 200x200, mask 0.1 m 2000x2000 under a
# 0.05 m costmap, 2026-11-22): gather 248, packed 409, rows 127, window 321 Gcell/s, all
# bit-equal incl. the edge fleets. XLA:CPU never runs this function by default (its loop is
# "map"), and vectorises "packed" badly (69 ms against 11 ms for "gather" at B = 256).
_GATHER_IMPL = "packed"


def _m1_table(data):
  """uint8 [M, Hm, Wm]: each mask cell's cost + 1, 0 where unknown (`mask_cost_plus_one_table`)."""
  return jnp.asarray(_COST1)[jax.lax.bitcast_convert_type(data, jnp.uint8).astype(jnp.int32)]


def _m1_rule_u8(cost, m1, state, config: KeepoutConfig):
  """Nav2's write rule on (mask cost + 1) bytes m1 (0: unknown or not visited), uint8 [H, W]."""
  c1 = cost + jnp.uint8(1)
  if config.override_lethal_cost:
    value = jnp.where(state.is_pose_lethal, jnp.uint8(config.lethal_override_cost), m1 - jnp.uint8(1))
    return jnp.where(m1 > c1, value, cost)
  return jnp.maximum(c1, m1) - jnp.uint8(1)


def _packed_rule(c, m1, state, config: KeepoutConfig):
  """`_m1_rule_u8` on uint32 words of four cells (SWAR, see `_aligned_packed_one`)."""
  write = _bytes_less_than(_bytes_plus_one(c), m1)
  if config.override_lethal_cost:
    value = jnp.where(state.is_pose_lethal, _u32(config.lethal_override_cost * _ONES), _bytes_minus_one(m1))
  else:
    value = _bytes_minus_one(m1)
  return (c & ~write) | (value & write)


def _word(byte_planes):
  """uint32 word from four uint8 arrays (byte s of the word from plane s), by shifts."""
  word = byte_planes[0].astype(jnp.uint32)
  for s in range(1, 4):
    word = word | (byte_planes[s].astype(jnp.uint32) << _u32(8 * s))
  return word


def _gather_packed_one(cost, m1flat, i, mshape, mx, colv, my, rowv, state, *, config: KeepoutConfig):
  """"packed": the gather kernel on four cells per uint32 word (W % 4 == 0), uint8 [H, W].

  colv [W] / rowv [H]: the column / row is in the window and its mask cell on the mask.
  """
  h, w = cost.shape
  hm, wm = mshape
  base = i * (hm * wm) + my * wm
  mx4, cv4 = mx.reshape(w // 4, 4), colv.reshape(w // 4, 4)
  planes = [jnp.where(cv4[None, :, s] & rowv[:, None], m1flat[base[:, None] + mx4[None, :, s]], jnp.uint8(0))
            for s in range(4)]
  return _unpack(_packed_rule(_pack(cost), _word(planes), state, config))


def _span(cells, valid):
  """(first, count): the smallest valid entry and how many cells from it to the largest."""
  lo = jnp.min(jnp.where(valid, cells, jnp.iinfo(jnp.int32).max))
  hi = jnp.max(jnp.where(valid, cells, -1))
  some = jnp.any(valid)
  return jnp.where(some, lo, 0), jnp.where(some, hi - lo + 1, 0)


def _rows_one(cost, padded, i, x0, mx, colv, my, rowv, state, *, config: KeepoutConfig):
  """"rows": a [H, W] slab of the mask rows the robot reads (W columns from x0), then the columns.

  padded: uint8 [M, Hm + 2H, Wm + 2W] (cost + 1) table padded by H rows and W columns of
  0, so no slice is clipped (dynamic_slice would move a clipped start).
  """
  h, w = cost.shape
  rows = jnp.where(rowv, my, 0) + h
  slab = jax.vmap(lambda y: jax.lax.dynamic_slice(padded, (i, y, x0 + w), (1, 1, w))[0, 0])(rows)
  m1 = slab[:, jnp.where(colv, mx - x0, 0)]
  return _m1_rule_u8(cost, jnp.where(colv[None, :] & rowv[:, None], m1, jnp.uint8(0)), state, config)


def _window_one(cost, padded, i, x0, y0, mx, colv, my, rowv, state, *, config: KeepoutConfig):
  """"window": the robot's [H, W] box of mask cells from (y0, x0), then a gather inside it."""
  h, w = cost.shape
  box = jax.lax.dynamic_slice(padded, (i, y0 + h, x0 + w), (1, h, w))[0]
  m1 = box[jnp.where(rowv, my - y0, 0)[:, None], jnp.where(colv, mx - x0, 0)[None, :]]
  return _m1_rule_u8(cost, jnp.where(colv[None, :] & rowv[:, None], m1, jnp.uint8(0)), state, config)


def _other_res_batch(cells, mask, *, config: KeepoutConfig, impl: str | None = None):
  """The same-frame cells of a fleet through the exact index vectors, by kernel `impl`.

  Args:
    cells: (cost uint8 [B, H, W], mask index int32 [B], mx int32 [B, W], vx bool [B, W],
      my int32 [B, H], vy bool [B, H], col_ok bool [B, W], row_ok bool [B, H], state).
    mask: the FilterMask stack. config: static KeepoutConfig.
    impl: one of `_GATHER_IMPLS`; None reads `_GATHER_IMPL`.

  Returns:
    new cost uint8 [B, H, W], the same integers for every `impl`.
  """
  impl = _GATHER_IMPL if impl is None else impl
  if impl not in _GATHER_IMPLS:
    raise ValueError(f"gather_impl must be one of {_GATHER_IMPLS}; got {impl!r}")
  cost, idx, mx, vx, my, vy, col_ok, row_ok, state = cells
  b, h, w = cost.shape
  _, hm, wm = mask.data.shape
  flat = mask.data.reshape(-1)

  def plain():
    one = lambda c, i, mx, vx, my, vy, co, ro, st: _gather_write_one(c, flat, i, (hm, wm), mx, vx, my, vy, co, ro,
                                                                     st, config=config)
    return jax.vmap(one)(*cells)

  if impl == "gather" or (impl == "packed" and w % 4):
    return plain()
  colv, rowv = col_ok & vx, row_ok & vy
  table = _m1_table(mask.data)
  if impl == "packed":
    one = functools.partial(_gather_packed_one, mshape=(hm, wm), config=config)
    return jax.vmap(lambda c, i, mx, cv, my, rv, st: one(c, table.reshape(-1), i, mx=mx, colv=cv, my=my, rowv=rv,
                                                         state=st))(cost, idx, mx, colv, my, rowv, state)
  x0, xspan = jax.vmap(_span)(mx, colv)
  y0, yspan = jax.vmap(_span)(my, rowv)
  fits = jnp.all((xspan <= w) & (yspan <= h))
  padded = jnp.pad(table, ((0, 0), (h, h), (w, w)))
  if impl == "rows":
    boxed = lambda: jax.vmap(functools.partial(_rows_one, config=config), in_axes=(0, None, 0, 0, 0, 0, 0, 0, 0))(
        cost, padded, idx, x0, mx, colv, my, rowv, state)
  else:
    boxed = lambda: jax.vmap(functools.partial(_window_one, config=config),
                             in_axes=(0, None, 0, 0, 0, 0, 0, 0, 0, 0))(
        cost, padded, idx, x0, y0, mx, colv, my, rowv, state)
  return jax.lax.cond(fits, boxed, plain)


def _general_batch(costmap, mask, idx, idx_ok, state, window, enabled, transform, *, config: KeepoutConfig):
  """The exact per-cell path (`_keepout_stack_one`) over a fleet: the reference the fast paths equal."""
  def one(cost, origin, origin_lo, res, res_lo, i, ok, st, win, en, tf):
    return _keepout_stack_one(cost, geometry.origin_terms(origin, origin_lo),
                              geometry.resolution_terms(res, res_lo), mask.data, i,
                              _mask_origin(mask, i), mask.resolution[i], st, win, en, tf,
                              config=config, index_ok=ok)

  tf_axis = None if transform is None else 0
  geo_axes = tuple(None if g is None else 0 for g in _robot_geometry(costmap, mask))
  args = (costmap.cost, *_robot_geometry(costmap, mask), idx, idx_ok, state, window, enabled, transform)
  b, h, w = costmap.cost.shape
  # Only the SE2 path needs chunking: the same-frame gather fuses well and runs
  # 2.4x faster as one vmap (H200: 172 vs 72 Gcell/s at B=16384, 200x200).
  if transform is None or b * h * w <= _GENERAL_CHUNK_CELLS:
    return jax.vmap(one, in_axes=(0, *geo_axes, 0, 0, 0, 0, 0, tf_axis))(*args)
  # The per-cell exact arithmetic keeps ~40 float32 temporaries per cell alive at
  # once (an SE2 fleet of 655 M cells asked XLA:GPU for 107 GiB): run in chunks.
  return jax.lax.map(lambda a: one(*a), args, batch_size=max(1, _GENERAL_CHUNK_CELLS // (h * w)))


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
    ValueError: `config.kernel="pallas"` on a backend other than GPU without
      `PallasTuning(interpret=True)`.
  """
  if not isinstance(config, KeepoutConfig):
    raise TypeError(f"config must be a KeepoutConfig; got {type(config).__name__}")
  keepout_pallas.use_pallas(config.kernel, config.pallas)   # kernel="pallas" off GPU raises here
  idx, idx_ok, poses, enabled, window, transform = _batched_inputs(
      costmap, mask, poses, mask_index, enabled, window, transform, "keepout_filter")
  del poses
  _check_index_range(costmap, mask)
  state = _fill_error(state, costmap.num_robots)
  return _keepout_filter_jit(costmap, mask, idx, idx_ok, state, window, enabled, transform,
                             config=_process_config(config))


def _check_index_range(costmap: Costmap, mask: FilterMask) -> None:
  """The kernels address the mask stack, padded by a costmap on each side, with int32 flat indices.

  Raises:
    ValueError: M (Hm + 2H) (Wm + 2W) >= 2^31, where an index would wrap and read
      another cell (a static problem: the shapes alone decide it).
  """
  m, hm, wm = (int(n) for n in mask.data.shape)
  h, w = (int(n) for n in costmap.cost.shape[1:])
  cells = m * (hm + 2 * h) * (wm + 2 * w)
  if cells >= 2 ** 31:
    raise ValueError(f"keepout_filter: the mask stack [M, Hm, Wm] = [{m}, {hm}, {wm}] padded by the costmap "
                     f"[{h}, {w}] on each side has {cells} cells; the keepout kernels index it with int32 and "
                     f"take fewer than 2^31 (split the stack or crop the masks)")


def _process_config(config: KeepoutConfig) -> KeepoutConfig:
  """The options process() uses: the robot-in-zone test lives in updateBounds, so fleets with
  different footprints share one compiled filter."""
  if config.robot_in_zone == "center":
    return config
  # replace() keeps every other option (a new one included) as the caller set it.
  return dataclasses.replace(config, robot_in_zone="center", footprint=None, robot_radius=None,
                             min_mask_resolution=None, escape_clearance=0.0)


def _path_report(costmap: Costmap, mask: FilterMask, transform=None, mask_index=None) -> dict:
  """How many robots each fast-path branch takes on these inputs (for benchmarks/NOTES.md).

  Same frame: robots whose slice test (`_slice_test_one`) or window clip the bracket
  left open (the batch then runs that part exactly), and robots whose cells are read
  as one slice. Other frame: robots with an undecided cell (settled exactly).
  """
  b, h, w = costmap.cost.shape
  idx, ok, _, en, win, tf = _batched_inputs(costmap, mask, jnp.zeros((b, 3)), mask_index, None, None, transform,
                                            "_path_report")
  hm, wm = mask.data.shape[1:]
  geo_axes = tuple(None if g is None else 0 for g in _robot_geometry(costmap, mask))

  @jax.jit
  def same_frame(origin, origin_lo, res, res_lo, i, ok, win, en):
    def one(origin, origin_lo, res, res_lo, i, ok, win, en):
      o, r = geometry.origin_terms(origin, origin_lo), geometry.resolution_terms(res, res_lo)
      mo, mr = _mask_origin(mask, i), mask.resolution[i]
      overlap, box, wknown = _same_frame_box_one((hm, wm), o, r, mo, mr, win)
      exact_overlap, exact_box, _ = _same_frame_box_one((hm, wm), o, r, mo, mr, win, exact=True)
      overlap, box = jax.tree.map(lambda e, f: jnp.where(wknown, f, e), (exact_overlap, exact_box), (overlap, box))
      run = en & overlap & ok
      box = tuple(jnp.where(run, c, 0) for c in box)
      _, _, sliced, known = _slice_test_one((h, w), o, r, mo, mr, (hm, wm), box)
      exact_sliced = _slice_test_one((h, w), o, r, mo, mr, (hm, wm), box, exact=True)[2]
      return known, wknown, jnp.where(known, sliced, exact_sliced)
    return jax.vmap(one, in_axes=(*geo_axes, 0, 0, 0, 0))(origin, origin_lo, res, res_lo, i, ok, win, en)

  @jax.jit
  def other_frame(origin, origin_lo, res, res_lo, i, win, tf):
    def one(origin, origin_lo, res, res_lo, i, win, tf):
      axes = _se2_axes_one(geometry.origin_terms(origin, origin_lo), geometry.resolution_terms(res, res_lo), tf, h, w)
      code = _se2_codes_one(axes, i, _mask_origin(mask, i), mask.resolution[i], (hm, wm), win, True)
      return jnp.any(code == -2)
    return jax.vmap(one, in_axes=(*geo_axes, 0, 0, 0))(origin, origin_lo, res, res_lo, i, win, tf)

  if tf is None:
    known, wknown, sliced = same_frame(*_robot_geometry(costmap, mask), idx, ok, win, en)
    return dict(robots=b, exact_slice_test=int(jnp.sum(~known)), exact_window=int(jnp.sum(~wknown)),
                sliced=int(jnp.sum(sliced)))
  undecided = other_frame(*_robot_geometry(costmap, mask), idx, win, tf)
  return dict(robots=b, robots_with_undecided_cells=int(jnp.sum(undecided)))


@functools.partial(jax.jit, static_argnames=("config", "exact", "loop"))
def _keepout_filter_jit(costmap, mask, idx, idx_ok, state, window, enabled, transform, *, config,
                        exact=False, loop="auto"):
  """The batch behind `keepout_filter`. `exact` (tests) runs only the per-cell exact path;
  `loop` "auto" picks `lax.map` over robots on the CPU backend and `vmap` elsewhere."""
  with jax.named_scope("keepout_filter"):
    if loop == "auto":
      loop = "map" if jax.default_backend() == "cpu" else "vmap"
    hm, wm = mask.data.shape[1:]
    if exact or (transform is not None and (max(hm, wm) > 2 ** 17 or hm * wm >= 2 ** 24)):
      cost, new_state = _general_batch(costmap, mask, idx, idx_ok, state, window, enabled, transform,
                                       config=config)
    elif transform is None:
      cost, new_state = _same_frame_batch(costmap, mask, idx, idx_ok, state, window, enabled, config=config,
                                          loop=loop)
    else:
      cost, new_state = _se2_batch(costmap, mask, idx, idx_ok, state, window, enabled, transform,
                                   config=config, loop=loop)
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
    (new KeepoutState, new bounds float32 [B, 4]). With
    `config.robot_in_zone == "footprint"`, `is_pose_lethal` comes from the
    footprint test (jaxfilters/footprint.py) and `error` is also set for a
    robot whose mask is finer than `config.min_mask_resolution` (traced masks;
    a concrete one raises).

  Raises:
    TypeError / ValueError: as keepout_filter; a concrete mask finer than
      `config.min_mask_resolution` in "footprint" mode.
  """
  if not isinstance(config, KeepoutConfig):
    raise TypeError(f"config must be a KeepoutConfig; got {type(config).__name__}")
  b = costmap.num_robots
  idx, idx_ok, poses, enabled, _, transform = _batched_inputs(
      costmap, mask, poses, mask_index, enabled, None, transform, "keepout_update_bounds")
  bounds = jnp.asarray(bounds, _F32)
  if bounds.shape != (b, 4):
    raise ValueError(f"bounds must be float [B, 4] = ({b}, 4); got {tuple(bounds.shape)}")
  new_mask = per_robot_bool("new_mask", new_mask, b, default=False)
  state = _fill_error(state, b)
  _check_footprint_window(mask, config)
  footprint = config if config.robot_in_zone == "footprint" else None
  return _update_bounds_jit(costmap, mask, idx, idx_ok, poses, state, bounds, new_mask, enabled, transform,
                            override_lethal_cost=config.override_lethal_cost, footprint=footprint)


def _check_footprint_window(mask: FilterMask, config: KeepoutConfig) -> None:
  """Eagerly: a concrete mask finer than `min_mask_resolution` raises (under jit: `error`)."""
  if config.robot_in_zone != "footprint" or isinstance(mask.resolution, jax.core.Tracer):
    return
  res = np.asarray(mask.resolution, np.float32)
  if np.any(res < np.float32(config.min_mask_resolution)):
    raise ValueError(f"keepout_update_bounds: mask resolution {float(res.min()):g} m is finer than "
                     f"KeepoutConfig.min_mask_resolution = {config.min_mask_resolution:g} m, which sizes the "
                     "footprint test's window; build the config with min_mask_resolution <= the finest mask")


@functools.partial(jax.jit, static_argnames=("override_lethal_cost", "footprint"))
def _update_bounds_jit(costmap, mask, idx, idx_ok, poses, state, bounds, new_mask, enabled, transform, *,
                       override_lethal_cost, footprint=None):
  with jax.named_scope("keepout_update_bounds"):
    def one(st, i, ok, pose, bnd, origin, res, nm, en, tf):
      return keepout_update_bounds_one(
          st, mask.data[i], mask.origin[i], mask.resolution[i], pose, bnd, origin, res, nm, en, tf,
          override_lethal_cost=override_lethal_cost,
          mask_origin_lo=None if mask.origin_lo is None else mask.origin_lo[i], index_ok=ok, config=footprint)

    tf_axis = None if transform is None else 0
    return jax.vmap(one, in_axes=(0, 0, 0, 0, 0, 0, 0, 0, 0, tf_axis))(
        state, idx, idx_ok, poses, bounds, costmap.origin, costmap.resolution, new_mask, enabled, transform)
