"""Internal: world -> cell lookups (Nav2 `worldToMap`) and cell centres, decided exactly.

Part of `jaxfilters.geometry`; import it from there.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxfilters.geometry.exact import as_terms, exact_product, expansion_sign, floor_div_exact

_F32 = jnp.float32


def transform_points(transform: jax.Array, x: jax.Array, y: jax.Array) -> tuple[jax.Array, jax.Array]:
  """Applies an SE2 transform (tx, ty, yaw) to points (float32): R(yaw) p + t."""
  c, s = jnp.cos(transform[2]), jnp.sin(transform[2])
  return c * x - s * y + transform[0], s * x + c * y + transform[1]


def origin_terms(origin: jax.Array, origin_lo: jax.Array | None) -> list[jax.Array]:
  """Float32 terms [2]-shaped whose exact sum is the host origin (x, y).

  Args:
    origin: float32 [2], the float32 rounding of the origin (the `hi` part).
    origin_lo: None (the origin is exactly float32) or float32 [2, 2], the
      (mid, lo) parts from `validate.split_float64`.
  """
  terms = [jnp.asarray(origin, _F32)]
  if origin_lo is not None:
    terms += [jnp.asarray(origin_lo, _F32)[:, 0], jnp.asarray(origin_lo, _F32)[:, 1]]
  return terms


def resolution_terms(resolution: jax.Array, resolution_lo: jax.Array | None) -> list[jax.Array]:
  """Float32 parts whose exact sum is the host resolution (see `origin_terms`)."""
  terms = [jnp.asarray(resolution, _F32)]
  if resolution_lo is not None:
    lo = jnp.asarray(resolution_lo, _F32)
    terms += [lo[..., 0], lo[..., 1]]
  return terms


def world_to_cell(wx: jax.Array, wy: jax.Array, origin, resolution: jax.Array,
                  width: int, height: int, origin_lo: jax.Array | None = None
                  ) -> tuple[jax.Array, jax.Array, jax.Array]:
  """Nav2 `worldToMap` (docs/nav2_semantics.md §2.2): bounded, half-open [o, o + size*res).

  Args:
    wx, wy: float32 world coordinates (any matching shape).
    origin: float32 [2], lower-left corner of cell (0, 0), or a list of [2]
      float32 parts whose exact sum is the origin.
    resolution: float32 scalar, metres per cell.
    width, height: grid size in cells (static).
    origin_lo: optional float32 [2, 2] extra parts of a float64 origin
      (`validate.split_float64`); the comparison and the floor then use the double.

  Returns:
    (mx, my, valid): int32 cells (clipped into the grid so they can index it)
    and a bool that is False off the grid or for a non-finite point.
  """
  wx = jnp.asarray(wx, _F32)
  wy = jnp.asarray(wy, _F32)
  wx, wy = jnp.broadcast_arrays(wx, wy)
  parts = as_terms(origin)
  if origin_lo is not None:
    parts += origin_terms(parts[0], origin_lo)[1:]
  o_terms = [-jnp.stack([jnp.broadcast_to(t[0], wx.shape), jnp.broadcast_to(t[1], wx.shape)])
             for t in parts]
  terms = [jnp.stack([wx, wy]), *o_terms]
  mx, my = floor_div_exact(terms, resolution)
  if len(parts) == 1:
    inside_lo = (wx >= parts[0][0]) & (wy >= parts[0][1])
  else:
    nonneg = expansion_sign(terms) >= 0
    inside_lo = nonneg[0] & nonneg[1]
  valid = inside_lo & (mx < width) & (my < height) & jnp.isfinite(wx) & jnp.isfinite(wy)
  return (jnp.clip(mx, 0, width - 1), jnp.clip(my, 0, height - 1), valid)


def cell_centre_terms(index: jax.Array, origin, resolution) -> list[jax.Array]:
  """Float32 terms summing exactly to the world centre origin + (index + 0.5) * res.

  `origin` and `resolution` are float32 arrays or lists of parts (host doubles).
  """
  half_steps = 2.0 * jnp.asarray(index, _F32) + 1.0      # exact for index < 2**23
  terms = list(as_terms(origin))
  for r in as_terms(resolution):
    terms += exact_product(half_steps, 0.5 * r)
  return terms


def centres_to_cells_2d(shape: tuple[int, int], origin, resolution,
                        target_origin, target_resolution: jax.Array,
                        target_shape: tuple[int, int], *, sign_fn=expansion_sign):
  """Maps the cell centres of a grid's columns and rows onto another grid's cells.

  For same-frame grids the x and y mappings are separable, so the 2-D lookup is
  a gather with two 1-D index vectors computed exactly once per robot; both
  axes run as one stacked exact division.

  Args:
    shape: (H, W) of the source grid; origin [2] (or a list of [2] parts),
      resolution [] (or a list of [] parts) its geometry.
    target_origin [2] (or parts), target_resolution [], target_shape (Ht, Wt):
      the target grid.
    sign_fn: as `floor_div_exact` (same integers either way).

  Returns:
    ((mx int32 [W], vx bool [W]), (my int32 [H], vy bool [H])).
  """
  h, w = shape
  ht, wt = target_shape
  n = max(h, w)
  i = jnp.arange(n, dtype=_F32)
  idx = jnp.stack([i, i])
  per_axis = lambda o: jnp.stack([jnp.full((n,), o[0], _F32), jnp.full((n,), o[1], _F32)])
  o = [per_axis(t) for t in as_terms(origin)]
  res = [jnp.broadcast_to(r, idx.shape) for r in as_terms(resolution)]
  terms = cell_centre_terms(idx, o, res) + [-per_axis(t) for t in as_terms(target_origin)]
  cells = floor_div_exact(terms, target_resolution, sign_fn=sign_fn)
  nonneg = sign_fn(terms) >= 0
  size = jnp.asarray([[wt], [ht]], jnp.int32)
  valid = nonneg & (cells < size)
  cells = jnp.clip(cells, 0, size - 1)
  return (cells[0, :w], valid[0, :w]), (cells[1, :h], valid[1, :h])
