"""Device data model: pytrees for filter info, masks and batched costmaps.

Every field is a traced leaf (STYLE.md habit 2), so a fleet whose robots use
different resolutions, origins, bases or multipliers compiles once, and
replacing a mask's contents with one of the same shape never recompiles.
Factories (`create`) validate on the host and raise `ValueError` naming what
was expected and what was given (habit 3); the dataclass constructors stay
dumb records because JAX rebuilds them under `jit`/`vmap`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from jaxfilters.grid import OccupancyGrid


def _dataclass(cls):
  cls = dataclasses.dataclass(frozen=True)(cls)
  names = [f.name for f in dataclasses.fields(cls)]
  return jax.tree_util.register_dataclass(cls, data_fields=names, meta_fields=[])


def _f32(x) -> np.ndarray:
  return np.asarray(x, dtype=np.float32)


@_dataclass
class FilterInfo:
  """nav2_msgs/CostmapFilterInfo without the topic: `value = data * multiplier + base`.

  Leaves share one leading shape: [] for one mask, [M] for a stack of masks.

  Attributes:
    type: int32, Nav2's type code (0 keepout, 1 speed %, 2 speed m/s,
      3 binary, 4 zone parameter).
    base: float32 (the message field is float32; 0.1 arrives as 0.10000000149).
    multiplier: float32.
  """
  type: jax.Array
  base: jax.Array
  multiplier: jax.Array

  @classmethod
  def create(cls, type: int, base: float = constants.BASE_DEFAULT,
             multiplier: float = constants.MULTIPLIER_DEFAULT) -> "FilterInfo":
    """Builds a scalar FilterInfo; base and multiplier are rounded to float32 like the message.

    Raises:
      ValueError: unknown type code, or a non-finite base or multiplier.
    """
    if int(type) not in constants.FILTER_TYPES or int(type) != type:
      raise ValueError(f"FilterInfo type must be one of {constants.FILTER_TYPES} "
                       f"(0 keepout, 1 speed %, 2 speed m/s, 3 binary, 4 zone); got {type!r}")
    for name, v in (("base", base), ("multiplier", multiplier)):
      if not np.isfinite(float(v)):
        raise ValueError(f"FilterInfo {name} must be finite; got {v!r}")
    return cls(jnp.asarray(int(type), jnp.int32), jnp.asarray(_f32(base)),
               jnp.asarray(_f32(multiplier)))


@_dataclass
class FilterMask:
  """A stack of M filter masks of one shape, each with its own geometry and info.

  A fleet sharing one mask has M = 1; a fleet with one mask per robot (or per
  group) passes `mask_index` [B] to the filters to pick each robot's mask.

  Attributes:
    data: int8 [M, H, W], OccupancyGrid values; row 0 is the lowest y.
    origin: float32 [M, 2], world (x, y) of the lower-left corner of cell (0, 0).
    resolution: float32 [M], metres per cell (float32, as nav_msgs stores it).
    info: FilterInfo with leaves [M].
  """
  data: jax.Array
  origin: jax.Array
  resolution: jax.Array
  info: FilterInfo

  @property
  def num_masks(self) -> int:
    return self.data.shape[0]

  @property
  def shape(self) -> tuple[int, int]:
    return tuple(self.data.shape[1:])

  @classmethod
  def create(cls, grids: OccupancyGrid | Sequence[OccupancyGrid],
             infos: FilterInfo | Sequence[FilterInfo]) -> "FilterMask":
    """Stacks one or more OccupancyGrids with their FilterInfo into a device mask.

    Args:
      grids: one grid, or a sequence of grids of the same [H, W].
      infos: one FilterInfo for all grids, or one per grid.

    Raises:
      ValueError: empty input, grids of different shapes, or a count mismatch.
      TypeError: a grid that is not an OccupancyGrid.
    """
    if isinstance(grids, OccupancyGrid):
      grids = [grids]
    grids = list(grids)
    if not grids:
      raise ValueError("FilterMask.create needs at least one OccupancyGrid; got none")
    for g in grids:
      if not isinstance(g, OccupancyGrid):
        raise TypeError(f"FilterMask.create expects OccupancyGrid objects (see jaxfilters.load_map); "
                        f"got {type(g).__name__}")
    shapes = {g.data.shape for g in grids}
    if len(shapes) != 1:
      raise ValueError(f"all masks in one FilterMask must share one [H, W]; got shapes {sorted(shapes)}")
    if isinstance(infos, FilterInfo):
      infos = [infos] * len(grids)
    infos = list(infos)
    if len(infos) != len(grids):
      raise ValueError(f"need one FilterInfo or one per grid ({len(grids)}); got {len(infos)}")
    info = FilterInfo(
        type=jnp.asarray(np.array([int(i.type) for i in infos], np.int32)),
        base=jnp.asarray(_f32([float(i.base) for i in infos])),
        multiplier=jnp.asarray(_f32([float(i.multiplier) for i in infos])))
    return cls(
        data=jnp.asarray(np.stack([g.data for g in grids]).astype(np.int8)),
        origin=jnp.asarray(_f32([g.origin[:2] for g in grids])),
        resolution=jnp.asarray(_f32([g.resolution for g in grids])),
        info=info)

  def with_data(self, data) -> "FilterMask":
    """Returns this mask with new cell contents of the same shape (no recompile).

    Raises:
      ValueError: data of another shape, or values outside int8.
    """
    arr = np.asarray(data)
    if arr.ndim == 2:
      arr = arr[None]
    if arr.shape != tuple(self.data.shape):
      raise ValueError(f"new mask data must have shape {tuple(self.data.shape)} (or [H, W] "
                       f"for M = 1); got {arr.shape}")
    if arr.size and (arr.min() < -128 or arr.max() > 127):
      raise ValueError("new mask data must fit int8 (OccupancyGrid values -1..100)")
    return dataclasses.replace(self, data=jnp.asarray(arr.astype(np.int8)))


def resolve_mask_index(mask: FilterMask, mask_index: jax.Array | None,
                       num_robots: int) -> jax.Array:
  """Returns int32 [B]: which mask of the stack each robot uses.

  A shared mask (mask_index None) must have M == 1. The [M, H, W] data stack
  is never copied per robot: kernels receive the stack and this index.

  Raises:
    ValueError: a stack of several masks without mask_index, or a mask_index
      that is not an integer [B] array.
  """
  if mask_index is None:
    if mask.num_masks != 1:
      raise ValueError(f"a FilterMask stack of {mask.num_masks} masks needs mask_index [B] "
                       "to say which mask each robot uses; got mask_index=None")
    idx = jnp.zeros((num_robots,), jnp.int32)
  else:
    idx = jnp.asarray(mask_index)
    if idx.shape != (num_robots,) or not jnp.issubdtype(idx.dtype, jnp.integer):
      raise ValueError(f"mask_index must be an integer array of shape ({num_robots},); "
                       f"got {idx.dtype}{tuple(idx.shape)}")
    idx = idx.astype(jnp.int32)
  return idx


@_dataclass
class Costmap:
  """A batch of B costmaps of one [H, W]: rolling-window local maps or full global maps.

  Attributes:
    cost: uint8 [B, H, W], Nav2 cost values (0..252, 253, 254, 255).
    origin: float32 [B, 2], world (x, y) of the lower-left corner of cell (0, 0),
      per robot (a rolling window moves it; a global map repeats it).
    resolution: float32 [B], metres per cell.
  """
  cost: jax.Array
  origin: jax.Array
  resolution: jax.Array

  @property
  def num_robots(self) -> int:
    return self.cost.shape[0]

  @classmethod
  def create(cls, cost, origin, resolution) -> "Costmap":
    """Validates and builds a batch of costmaps.

    Args:
      cost: uint8 [B, H, W] (or [H, W] for B = 1).
      origin: [B, 2] or [2] (broadcast to every robot).
      resolution: [B] or scalar (broadcast).

    Raises:
      ValueError: wrong rank or dtype, batch mismatch, resolution not > 0.
    """
    c = np.asarray(cost)
    if c.ndim == 2:
      c = c[None]
    if c.ndim != 3:
      raise ValueError(f"cost must be uint8 [B, H, W]; got shape {c.shape}")
    if c.dtype != np.uint8:
      raise ValueError(f"cost must have dtype uint8 (Nav2 costs 0..255); got {c.dtype}")
    b = c.shape[0]
    o = _f32(origin)
    if o.shape == (2,):
      o = np.broadcast_to(o, (b, 2))
    if o.shape != (b, 2):
      raise ValueError(f"origin must be [B, 2] = ({b}, 2) or [2]; got {o.shape}")
    r = _f32(resolution)
    if r.ndim == 0:
      r = np.broadcast_to(r, (b,))
    if r.shape != (b,):
      raise ValueError(f"resolution must be [B] = ({b},) or a scalar; got {r.shape}")
    if not np.all(np.isfinite(r)) or np.any(r <= 0):
      raise ValueError(f"resolution must be finite and > 0; got {r}")
    if not np.all(np.isfinite(o)):
      raise ValueError("origin must be finite")
    return cls(jnp.asarray(c), jnp.asarray(np.ascontiguousarray(o)),
               jnp.asarray(np.ascontiguousarray(r)))

  @classmethod
  def from_grid(cls, grid: OccupancyGrid, cost, num_robots: int) -> "Costmap":
    """A global costmap with `grid`'s geometry, repeated for `num_robots` robots."""
    c = np.broadcast_to(np.asarray(cost, np.uint8), (num_robots, *np.shape(cost)[-2:]))
    return cls.create(np.ascontiguousarray(c), grid.origin[:2], grid.resolution)


def check_poses(poses: Any, num_robots: int) -> jax.Array:
  """Validates poses float [B, 3] (x, y, yaw) and returns them as float32.

  Raises:
    ValueError: wrong shape or a non-float dtype.
  """
  p = jnp.asarray(poses)
  if p.shape != (num_robots, 3):
    raise ValueError(f"poses must be [B, 3] = ({num_robots}, 3) (x, y, yaw); got {tuple(p.shape)}")
  if not jnp.issubdtype(p.dtype, jnp.floating):
    raise ValueError(f"poses must be floating point; got {p.dtype}")
  return p.astype(jnp.float32)


def robot_inputs(mask: FilterMask, poses: Any, num_robots: int, mask_index=None, enabled=None,
                 transform=None):
  """Validates and broadcasts the per-robot inputs every filter takes.

  Args:
    mask: the FilterMask stack.
    poses: float [B, 3].
    num_robots: B.
    mask_index: None (shared mask, M == 1) or int [B].
    enabled: None (all enabled), a bool scalar, or bool [B].
    transform: None (mask in the costmap frame), or T_mask_from_global
      (x, y, yaw) as [3] or [B, 3].

  Returns:
    (mask index int32 [B], poses float32 [B, 3], enabled bool [B],
     transform float32 [B, 3] or None).

  Raises:
    ValueError: any of them with the wrong shape or dtype.
  """
  b = num_robots
  idx = resolve_mask_index(mask, mask_index, b)
  poses = check_poses(poses, b)
  en = jnp.asarray(True if enabled is None else enabled)
  if en.dtype != jnp.bool_ or en.shape not in ((), (b,)):
    raise ValueError(f"enabled must be a bool scalar or bool [B] = ({b},); got {en.dtype}{tuple(en.shape)}")
  en = jnp.broadcast_to(en, (b,))
  if transform is not None:
    transform = jnp.asarray(transform, jnp.float32)
    if transform.shape not in ((3,), (b, 3)):
      raise ValueError(f"transform must be T_mask_from_global (x, y, yaw) of shape (3,) or ({b}, 3); "
                       f"got {tuple(transform.shape)}")
    transform = jnp.broadcast_to(transform, (b, 3))
  return idx, poses, en, transform
