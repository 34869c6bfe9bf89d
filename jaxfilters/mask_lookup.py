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

import jax
import jax.numpy as jnp

from jaxfilters import geometry
from jaxfilters.types import FilterMask


def mask_origin_terms(mask: FilterMask, i) -> list[jax.Array]:
  """Float32 parts [2] each whose exact sum is mask i's host origin (x, y)."""
  return geometry.origin_terms(mask.origin[i], None if mask.origin_lo is None else mask.origin_lo[i])


def mask_leaves(mask: FilterMask, i):
  """(data int8 [Hm, Wm], origin parts, resolution float32 [], FilterInfo with scalar leaves) of mask i.

  `i` is an int32 [] index into the stack (a kernel's gather; the caller checks its range).
  """
  return (mask.data[i], mask_origin_terms(mask, i), mask.resolution[i],
          jax.tree.map(lambda x: x[i], mask.info))


def mask_cell(data: jax.Array, origin, resolution: jax.Array, xy: jax.Array) -> tuple[jax.Array, jax.Array]:
  """The mask value under one point and whether the point is on the mask.

  Args:
    data: int8 [Hm, Wm] one mask. origin: float32 [2] or a list of [2] parts
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
