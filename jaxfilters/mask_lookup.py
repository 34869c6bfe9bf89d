"""Internal: the one cell rule every reader of a FilterMask uses (filters, point queries, sims).

A mask's origin is the host float64 value carried exactly as float32 parts
(`FilterMask.origin` plus `FilterMask.origin_lo`, see `validate.split_float64`),
and a point's cell is the exact floor Nav2's `worldToMap` computes from those
doubles (`geometry.world_to_cell`). Reading the cell with the leading part alone
would move points near a cell edge into the neighbouring cell (a mask at
origin x = -15.1 with 1 m cells puts x = float32(-12.1) in cell 2; the float32
origin alone gives cell 3), so every reader goes through `mask_leaves` and
`mask_cell`, and a filter and a point query at the same pose read the same cell.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp

from jaxfilters import geometry
from jaxfilters.types import FilterMask


def mask_origin_terms(mask: FilterMask, i) -> list[jax.Array]:
  """Float32 parts [2] each whose exact sum is mask i's host origin (x, y)."""
  return geometry.origin_terms(mask.origin[i], None if mask.origin_lo is None else mask.origin_lo[i])


@functools.partial(jax.tree_util.register_dataclass, data_fields=["stack", "index"], meta_fields=[])
@dataclasses.dataclass(frozen=True)
class MaskView:
  """Mask `index` of an int8 [M, Hm, Wm] stack, read in place: `view[my, mx]` is `stack[index, my, mx]`.

  Per-point readers run under `vmap` with a per-point index; `stack[index]` there is a gather of a
  whole [Hm, Wm] slice per point, and where the stack is a constant of the caller's program (an
  env that closes over its masks) XLA constant-folds those copies at compile time (81 x 240 kB
  for the RL env's 9 x 9 observation crop on 400 x 600 masks). Indexing through the view reads
  only the cells asked for, with the same values.
  """
  stack: jax.Array
  index: jax.Array

  @property
  def shape(self) -> tuple[int, int]:
    return tuple(self.stack.shape[1:])

  def __getitem__(self, cells):
    if not isinstance(cells, tuple) or len(cells) != 2:
      raise TypeError(f"MaskView takes two index arrays [my, mx]; got {cells!r}")
    return self.stack[self.index, cells[0], cells[1]]


def mask_leaves(mask: FilterMask, i):
  """(data MaskView [Hm, Wm], origin parts, resolution float32 [], FilterInfo with scalar leaves) of mask i.

  `i` is an int32 [] index into the stack (a kernel's gather; the caller checks its range).
  `data[my, mx]` reads the cells; `data.shape` is (Hm, Wm).
  """
  return (MaskView(mask.data, i), mask_origin_terms(mask, i), mask.resolution[i],
          jax.tree.map(lambda x: x[i], mask.info))


def mask_cell(data: jax.Array | MaskView, origin, resolution: jax.Array, xy: jax.Array) -> tuple[jax.Array, jax.Array]:
  """The mask value under one point and whether the point is on the mask.

  Args:
    data: int8 [Hm, Wm] one mask, or its `MaskView`. origin: float32 [2] or a list of [2] parts
      (exact sum: the host origin; `mask_leaves` gives them). resolution: float32 [].
    xy: float32 [2] point in the mask frame (m).

  Returns:
    (d int32 [], the raw OccupancyGrid value of the cell (clipped read off the
    mask: meaningless there), inside bool [], False off the mask or for a
    non-finite point).
  """
  hm, wm = data.shape
  mx, my, inside = geometry.world_to_cell(xy[0], xy[1], origin, resolution, wm, hm)
  return data[my, mx].astype(jnp.int32), inside


def transform_point(transform: jax.Array, xy: jax.Array) -> jax.Array:
  """T_mask_from_global (x, y, yaw) float32 [3] applied to one point float32 [2]."""
  return jnp.stack(geometry.transform_points(transform, xy[0], xy[1]))
