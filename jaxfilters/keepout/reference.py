"""The exact per-cell keepout path: the reference that every fast path equals.

Same frame, each master cell's mask cell comes from the exact division of
`geometry.centres_to_cells_2d`, on the host doubles of the costmap's origin and
resolution and the mask's origin (carried as float32 parts), and Nav2's overlap clip
(docs/nav2_semantics.md §4.3) from the exact `same_frame_window`. With a frame
transform each master cell centre is rotated in float32 (`se2_axes_one`: every product
formed by `geometry.rounded_product`, so the point does not depend on how XLA fuses
the program), then mapped with the exact floor; Nav2 rotates in float64, so a centre
that lands within ~1e-6 m of a mask cell boundary may pick the neighbouring mask cell.

`keepout_filter` runs this path for masks too large for the fast paths' float32
index arithmetic and for the robots a fast path could not decide.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxfilters import constants
from jaxfilters import geometry
from jaxfilters.keepout.common import processed, robot_geometry, with_error
from jaxfilters.mask_lookup import mask_origin_terms
from jaxfilters.keepout.config import KeepoutConfig, occ_to_cost

_F32 = jnp.float32
GENERAL_CHUNK_CELLS = 1 << 24
"""Cells per `lax.map` chunk of `general_batch` with a transform (read when a program is traced)."""


def same_frame_window(shape_m, mask_origin, mask_res, origin, res, window):
  """Nav2's same-frame overlap clip with the mask's half cell (docs/nav2_semantics.md §4.3).

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
                               sign_fn=geometry.fixed_point_sign)
  g0, g1 = (g[0], g[1]), (g[2], g[3])
  overlap = ~((g0[0] >= max_i) | (g0[1] >= max_j)) & ~((g1[0] <= min_i) | (g1[1] <= min_j))
  x0, y0 = jnp.maximum(min_i, g0[0]), jnp.maximum(min_j, g0[1])
  x1, y1 = jnp.minimum(max_i, g1[0]), jnp.minimum(max_j, g1[1])
  return overlap, (x0, y0, x1, y1)


def se2_axes_one(origin, res, transform, h, w):
  """The rotated master cell centres of one robot as per-column and per-row float32 vectors.

  The float32 rotation has one defined result: the centre cx = o + (k + 0.5) r with o,
  r the float32 sums of the host parts, then R(yaw) (cx, cy) + t summed in
  `geometry.transform_points`' order, every product a `geometry.rounded_product` (XLA
  would otherwise fuse a product and the next sum into an FMA in some programs and not
  in others, so one centre could take two values an ulp apart). The
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


def se2_grid(axes):
  """float32 [H, W] (px, py) from `se2_axes_one`: (c cx - s cy) + tx, (s cx + c cy) + ty (sums only)."""
  xc, xs, yc, ys, t = axes
  return (xc[None, :] - ys[:, None]) + t[0], (xs[None, :] + yc[:, None]) + t[1]


def keepout_one(cost, origin, res, data, mask_origin, mask_res, state, window, enabled,
                transform, *, config: KeepoutConfig):
  """KeepoutFilter::process for one robot and one mask `data` int8 [Hm, Wm] (the per-robot kernel).

  The arguments are `keepout_stack_one`'s, with the mask itself in place of the stack
  and its index.

  Returns:
    (new cost uint8 [H, W], new state).
  """
  return keepout_stack_one(cost, origin, res, data[None], jnp.int32(0), mask_origin, mask_res, state,
                           window, enabled, transform, config=config)


def keepout_stack_one(cost, origin, res, stack, i, mask_origin, mask_res, state, window, enabled,
                      transform, *, config: KeepoutConfig, index_ok=True, axes=None):
  """KeepoutFilter::process for one robot's costmap (docs/nav2_semantics.md §4.3-§4.4).

  Args:
    cost: uint8 [H, W] the combined costmap.
    origin, res: float32 [2], [] its geometry (or lists of float32 parts
      whose exact sums are the host doubles).
    stack: int8 [M, Hm, Wm] the masks; i: int32 [] this robot's mask.
    mask_origin, mask_res: float32 [2] (or a list of [2] parts), [].
    state: KeepoutState for this robot (scalar leaves).
    window: int32 [4] (min_i, min_j, max_i, max_j), half-open update window.
    enabled: bool [].
    transform: float32 [3] T_mask_from_global (x, y, yaw), or None for the same frame.
    config: static KeepoutConfig.
    axes: this robot's `se2_axes_one`, when the caller already formed them.

  Returns:
    (new cost uint8 [H, W], new state).
  """
  h, w = cost.shape
  hm, wm = stack.shape[1:]
  # Gather from the flat [M * Hm * Wm] stack: one scalar index per cell, no per-robot
  # copy of the mask (XLA:CPU runs a 2-D index gather several times slower).
  flat = stack.reshape(-1)
  base = i * (hm * wm)
  min_i, min_j, max_i, max_j = window[0], window[1], window[2], window[3]
  cols = jnp.arange(w, dtype=jnp.int32)
  rows = jnp.arange(h, dtype=jnp.int32)
  if transform is None and axes is None:
    overlap, (x0, y0, x1, y1) = same_frame_window((hm, wm), mask_origin, mask_res, origin, res, window)
    (mx, vx), (my, vy) = geometry.centres_to_cells_2d((h, w), origin, res, mask_origin, mask_res, (hm, wm),
                                                        sign_fn=geometry.fixed_point_sign)
    visit = (((cols >= x0) & (cols < x1) & vx)[None, :] & ((rows >= y0) & (rows < y1) & vy)[:, None])
    mask_val = flat[base + my[:, None] * wm + mx[None, :]]
  else:
    overlap = jnp.asarray(True)
    px, py = se2_grid(se2_axes_one(origin, res, transform, h, w) if axes is None else axes)
    mx, my, inside = geometry.world_to_cell(px, py, mask_origin, mask_res, wm, hm)
    in_window = (((cols >= min_i) & (cols < max_i))[None, :] & ((rows >= min_j) & (rows < max_j))[:, None])
    visit = inside & in_window
    mask_val = flat[base + my * wm + mx]
  mask_cost = occ_to_cost(mask_val)
  unknown_old = cost == constants.NO_INFORMATION
  if config.unknown_overwrite == "inscribed":   # Nav2 main (PR #6329)
    unknown_old = unknown_old & (mask_cost >= constants.INSCRIBED_INFLATED_OBSTACLE)
  write = visit & (mask_cost != constants.NO_INFORMATION) & ((mask_cost > cost) | unknown_old)
  if config.override_lethal_cost:
    value = jnp.where(state.is_pose_lethal, jnp.uint8(config.lethal_override_cost), mask_cost)
  else:
    value = mask_cost
  run = enabled & overlap & index_ok
  new_cost = jnp.where(run & write, value, cost)
  return new_cost, with_error(processed(state, run), ~jnp.asarray(index_ok))


def general_batch(costmap, mask, idx, idx_ok, state, window, enabled, transform, *, config: KeepoutConfig):
  """The exact per-cell path (`keepout_stack_one`) over a fleet: the reference the fast paths equal."""
  def one(cost, origin, origin_lo, res, res_lo, i, ok, st, win, en, tf):
    return keepout_stack_one(cost, geometry.origin_terms(origin, origin_lo),
                             geometry.resolution_terms(res, res_lo), mask.data, i,
                             mask_origin_terms(mask, i), mask.resolution[i], st, win, en, tf,
                             config=config, index_ok=ok)

  tf_axis = None if transform is None else 0
  geo_axes = tuple(None if g is None else 0 for g in robot_geometry(costmap, mask))
  args = (costmap.cost, *robot_geometry(costmap, mask), idx, idx_ok, state, window, enabled, transform)
  b, h, w = costmap.cost.shape
  # Only the SE2 path needs chunking: the same-frame gather fuses well and runs
  # faster as one vmap.
  if transform is None or b * h * w <= GENERAL_CHUNK_CELLS:
    return jax.vmap(one, in_axes=(0, *geo_axes, 0, 0, 0, 0, 0, tf_axis))(*args)
  # The per-cell exact arithmetic keeps ~40 float32 temporaries per cell alive at
  # once (tens of GiB for a large SE2 fleet): run in chunks.
  return jax.lax.map(lambda a: one(*a), args, batch_size=max(1, GENERAL_CHUNK_CELLS // (h * w)))
