"""The fast other-frame (SE2) keepout path: the exact path's integers with a frame transform.

Each master cell's centre is rotated in float32 (`reference.se2_axes_one`, the points
the exact path maps too), then mapped to its mask cell with a floor decided without
the exact division:

* on the CPU backend (`loop` "map"), `geometry.world_to_index_checked` decides each
  floor in ~45 float32 operations and proves it, leaving undecided only centres within
  ~1e-13 relative of a mask-cell edge (in practice: exactly on one); the cells' codes
  are written out robot by robot (XLA:CPU runs the arithmetic several times slower
  when it is fused into the gather), then gathered, and a robot with an undecided cell
  settles it with the exact arithmetic (`_fix_one`). XLA:CPU does not vectorise a loop
  that reads a table, so the edge tables below would be slower there.
* vectorised over the fleet (`loop` "vmap"), `geometry.floor_by_edges` decides each
  floor exactly from a per-mask table of edge thresholds (the smallest float32 at or
  above each mask-cell edge): an estimate good to one cell, two table reads and two
  float32 comparisons per axis, so no undecided cells, no reduction and no second
  pass; four cells per uint32 word when W % 4 == 0 in XLA, or (`KeepoutConfig.frame_kernel`,
  by default on a GPU) one Triton kernel (`pallas.other_frame_write`) that reads the
  tables and the mask bytes per cell and writes nothing but the costmap.
  Robots whose mask geometry the
  tables do not cover (`geometry.edge_thresholds`' `trusted`, never for a map file's
  values) run the exact per-cell path.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxfilters import geometry
from jaxfilters.keepout import pallas
from jaxfilters.keepout.common import (divisor_at_most, m1_rule_u8, m1_table, processed, rerun,
                                       robot_geometry, window_flags, with_error, write_u8)
from jaxfilters.mask_lookup import mask_origin_terms
from jaxfilters.keepout.config import KeepoutConfig
from jaxfilters.keepout.packed import pack, unpack, word, write_rule
from jaxfilters.keepout.reference import keepout_stack_one, se2_axes_one, se2_grid
from jaxfilters.types import FilterMask

_FIX_CELLS = 64   # undecided cells of one robot settled one by one before the whole window is redone


def codes_one(axes, i, mask_origin, mask_res, mshape, window, run):
  """What the CPU other-frame kernel decided per cell: int32 [H, W].

  The flat index (into the [M * Hm * Wm] mask stack) of the cell's mask cell where it
  is visited and proven on the mask, -1 where it is not visited or proven off the
  mask, -2 where `geometry.world_to_index_checked` left it undecided.

  Args:
    axes: the robot's `reference.se2_axes_one`. i: int32 [] the mask.
    mask_origin, mask_res: the mask's origin parts and resolution. mshape: (Hm, Wm).
    window: int32 [4] the update window. run: bool [], the robot runs.
  """
  xc, ys = axes[0], axes[3]
  h, w = ys.shape[0], xc.shape[0]
  hm, wm = mshape
  px, py = se2_grid(axes)
  index, inside, certain = geometry.world_to_index_checked(px, py, mask_origin, mask_res, wm, hm)
  col_ok, row_ok = window_flags(w, h, window[0], window[1], window[2], window[3], run)
  visit = col_ok[None, :] & row_ok[:, None]
  code = jnp.where(certain, jnp.where(inside, i * (hm * wm) + index, -1), -2)
  return jnp.where(visit, code, -1)


def _write_one(cost, code, flat, state, *, config: KeepoutConfig):
  """The write rule on `codes_one`'s cells: new cost uint8 [H, W]."""
  d = flat[jnp.maximum(code, 0)]
  return write_u8(cost, d, code >= 0, state, config)


def _fix_one(new_cost, code, cost, axes, stack, i, mask_origin, mask_res, state, window, run, *,
             config: KeepoutConfig):
  """Settles one robot's undecided cells (code -2) exactly: its final cost, uint8 [H, W].

  Up to `_FIX_CELLS` of them are mapped with `geometry.world_to_cell` (the exact path's
  arithmetic, on the same float32 points; padding slots redo cell 0, whose exact result
  is right either way); a robot with more reruns its window with `keepout_stack_one`.
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
    col_ok, row_ok = window_flags(w, h, window[0], window[1], window[2], window[3], run)
    visit = inside & col_ok[col] & row_ok[row]
    d = stack.reshape(-1)[i * (hm * wm) + my * wm + mx]
    value = write_u8(cost.reshape(-1)[sel], d, visit, state, config)
    return new_cost.reshape(-1).at[sel].set(value).reshape(h, w)

  def whole():
    return keepout_stack_one(cost, None, None, stack, i, mask_origin, mask_res, state, window, run, None,
                             config=config, axes=axes)[0]

  return jax.lax.cond(jnp.sum(undecided.astype(jnp.int32)) <= _FIX_CELLS, few, whole)


def other_frame_batch(costmap, mask, idx, idx_ok, state, window, enabled, transform, *, config: KeepoutConfig,
                      loop: str, plan=None):
  """The fast other-frame keepout over a fleet: same integers as the exact path.

  `loop` "map" runs the CPU kernel (checked floors, codes, exact fixes), "vmap" the
  edge-table kernel (see the module docstring); a Pallas `config.frame_kernel`
  ("pallas", or "auto" on a GPU) runs the edge tables in Triton whatever the loop.
  With a `plan` (static: an eager call) the robots that need the exact arithmetic (an
  undecided cell; a mask outside the edge tables' cover) are not redone here: the
  batch also returns them, needs bool [B] (process.py redoes them with the exact path).
  Without one a loop of data-dependent trip count (no conditional) redoes them.

  Returns:
    (new cost uint8 [B, H, W], new state).
  """
  if loop not in ("map", "vmap"):
    raise ValueError(f"loop must be 'auto', 'map' or 'vmap'; got {loop!r}")
  b, h, w = costmap.cost.shape
  _, hm, wm = mask.data.shape
  flat = mask.data.reshape(-1)
  geo_axes = tuple(None if g is None else 0 for g in robot_geometry(costmap, mask))

  def axes_of(origin, origin_lo, res, res_lo, tf):
    return se2_axes_one(geometry.origin_terms(origin, origin_lo), geometry.resolution_terms(res, res_lo), tf, h, w)

  axes = jax.vmap(axes_of, in_axes=(*geo_axes, 0))(*robot_geometry(costmap, mask), transform)
  run = enabled & idx_ok
  new_state = with_error(jax.vmap(processed)(state, run), ~idx_ok)
  frame_pallas = pallas.use_pallas(config.frame_kernel, config.pallas, table_bytes=mask.data.size,
                                   field="frame_kernel")
  if loop == "vmap" or frame_pallas:
    return _edges_batch(costmap.cost, mask, axes, idx, state, window, run, config=config,
                        packed=w % 4 == 0, use_pallas=frame_pallas, new_state=new_state, report=plan is not None)

  def codes(a):
    ax, i, win, rn = a
    return codes_one(ax, i, mask_origin_terms(mask, i), mask.resolution[i], (hm, wm), win, rn)

  # Chunks of robots, each: codes robot by robot (an inner loop, so XLA writes them out),
  # then gather and write. Every buffer stays a few MB: XLA:CPU maps fresh pages for
  # buffers beyond glibc's 32 MB mmap threshold on every call, a page fault per page.
  cb = divisor_at_most(b, max(2, (1 << 21) // (h * w)))
  split = lambda x: x.reshape(b // cb, cb, *x.shape[1:])

  def chunk(a):
    pr, c, st = a
    k = jax.lax.map(codes, pr)
    new = jax.vmap(lambda c, k, st: _write_one(c, k, flat, st, config=config))(c, k, st)
    return new, jnp.any(k == -2, axis=(1, 2))

  per_robot = (axes, idx, window, run)
  cost, need = jax.lax.map(chunk, jax.tree.map(split, (per_robot, costmap.cost, state)))
  cost, need = cost.reshape(b, h, w), need.reshape(b)
  if plan is not None:
    return cost, new_state, need

  def settle(new, old, ax, i, st, win, rn):
    return _fix_one(new, codes((ax, i, win, rn)), old, ax, mask.data, i, mask_origin_terms(mask, i),
                    mask.resolution[i], st, win, rn, config=config)
  args = (cost, costmap.cost, axes, idx, state, window, run)
  return rerun(need, cost, lambda a: jax.vmap(settle)(*a), args, 1), new_state


def edge_tables(mask: FilterMask):
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


def _edges_one(cost, axes, tables, source, i, mshape, window, run, state, *, config: KeepoutConfig, packed: bool):
  """One robot's other-frame cells decided by the edge tables: new cost uint8 [H, W].

  The points are `reference.se2_grid`'s (the same float32 sums), so the integers are
  the exact path's wherever the robot's mask tables are trusted.

  Args:
    cost: uint8 [H, W]. axes: `reference.se2_axes_one`. tables: (tx, ty, mask origin
      float32 [M, 2] (leading parts), inv [M]) from `edge_tables`.
    source: the masks' (cost + 1) bytes (`common.m1_table`), flat.
    i: int32 [] the mask. mshape: (Hm, Wm). window int32 [4], run bool [], state, config.
    packed: four cells per uint32 word (W % 4 == 0).
  """
  tx, ty, mo, inv = tables
  xc, xs, yc, ys, t = axes
  h, w = cost.shape
  hm, wm = mshape
  col_ok, row_ok = window_flags(w, h, window[0], window[1], window[2], window[3], run)

  def cells(xc, xs, col_ok):
    px = (xc[None, :] - ys[:, None]) + t[0]            # `reference.se2_grid`'s sums
    py = (xs[None, :] + yc[:, None]) + t[1]
    nx = geometry.floor_by_edges(px, mo[i, 0], inv[i], tx, i * (wm + 3), wm)
    ny = geometry.floor_by_edges(py, mo[i, 1], inv[i], ty, i * (hm + 3), hm)
    visit = (nx >= 0) & (nx < wm) & (ny >= 0) & (ny < hm) & col_ok[None, :] & row_ok[:, None]
    return jnp.where(visit, i * (hm * wm) + ny * wm + nx, 0), visit

  if not packed:
    index, visit = cells(xc, xs, col_ok)
    return m1_rule_u8(cost, jnp.where(visit, source[index], jnp.uint8(0)), state, config)
  planes = []
  for s in range(4):
    index, visit = cells(xc[s::4], xs[s::4], col_ok[s::4])
    planes.append(jnp.where(visit, source[index], jnp.uint8(0)))
  return unpack(write_rule(pack(cost), word(planes), state, config))


def _edges_batch(cost, mask, axes, idx, state, window, run, *, config: KeepoutConfig, packed: bool,
                 use_pallas: bool, new_state, report=False):
  """The edge-table kernel over a fleet (in Pallas with `use_pallas`: `pallas.other_frame_write`),
  then the exact path for robots of untrusted masks (with `report`, those robots are
  returned instead: (cost, new_state, needs)); (cost, new_state)."""
  b = cost.shape[0]
  _, hm, wm = mask.data.shape
  tx, ty, inv, trusted = edge_tables(mask)
  tables = (tx, ty, mask.origin, inv)
  source = m1_table(mask.data).reshape(-1)
  if use_pallas:
    xc, xs, yc, ys, t = axes
    ints = jnp.stack([idx, window[:, 0], window[:, 2], window[:, 1], jnp.where(run, window[:, 3], window[:, 1]),
                      state.is_pose_lethal.astype(jnp.int32)], axis=1).astype(jnp.int32)
    floats = jnp.stack([t[:, 0], t[:, 1], mask.origin[idx, 0], mask.origin[idx, 1], inv[idx]], axis=1)
    new = pallas.other_frame_write(cost, (xc, xs, yc, ys), (tx, ty), source, ints, floats.astype(jnp.float32),
                                   mshape=(hm, wm), escape=config.override_lethal_cost,
                                   lethal_cost=config.lethal_override_cost, tuning=config.pallas,
                                   unknown_overwrite=config.unknown_overwrite)
  else:
    one = lambda c, ax, i, win, rn, st: _edges_one(c, ax, tables, source, i, (hm, wm), win, rn, st,
                                                   config=config, packed=packed)
    new = jax.vmap(one)(cost, axes, idx, window, run, state)

  def exact(a):
    c, ax, i, st, win, rn = a
    one = lambda c, ax, i, st, win, rn: keepout_stack_one(
        c, None, None, mask.data, i, mask_origin_terms(mask, i), mask.resolution[i], st, win, rn, None, config=config,
        axes=ax)[0]
    return jax.vmap(one)(c, ax, i, st, win, rn)

  if report:
    return new, new_state, run & ~trusted[idx]
  return rerun(run & ~trusted[idx], new, exact, (cost, axes, idx, state, window, run), min(b, 8)), new_state
