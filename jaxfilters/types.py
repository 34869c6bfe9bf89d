"""Device data model: pytrees for filter info, masks and batched costmaps.

Every field is a traced leaf, so a fleet whose robots use different
resolutions, origins, bases or multipliers compiles once, and replacing a
mask's contents with one of the same shape never recompiles. Factories
(`create`) validate on the host and raise `ValueError` naming what was expected
and what was given; the dataclass constructors stay dumb records because JAX
rebuilds them under `jit`/`vmap`. Under `jit` the static parts (shapes, dtypes)
are checked at trace time (`check_mask`, `check_costmap`) and traced geometry
values are judged by `mask_geometry_ok` / `costmap_geometry_ok`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from jaxfilters import validate
from jaxfilters.grid import OccupancyGrid
from jaxfilters.validate import short_repr


def pytree_dataclass(cls):
  cls = dataclasses.dataclass(frozen=True)(cls)
  names = [f.name for f in dataclasses.fields(cls)]
  return jax.tree_util.register_dataclass(cls, data_fields=names, meta_fields=[])


def _f32(x) -> np.ndarray:
  return np.asarray(x, dtype=np.float32)


@pytree_dataclass
class FilterInfo:
  """nav2_msgs/CostmapFilterInfo without the topic: `value = data * multiplier + base`.

  Leaves share one leading shape: [] for one mask, [M] for a stack of masks.

  Attributes:
    type: int32, Nav2's type code (0 keepout, 1 speed %, 2 speed m/s,
      3 binary, 4 zone parameter), or 5 direction (one-way lanes,
      `jaxfilters.direction`; not a Nav2 type).
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
      ValueError: unknown type code; a base or multiplier that is not finite in
        float32 (NaN, beyond 3.4e38, or a non-zero value below 1.18e-38 that
        the device would flush to 0); or a pair for which `d * multiplier +
        base` overflows float32 for some mask value d in -1..100 (the filter
        would report inf or NaN as a valid limit).
    """
    try:
      type_ok = int(type) == type and int(type) in constants.FILTER_TYPES
    except (TypeError, ValueError, OverflowError):
      type_ok = False
    if not type_ok:
      raise ValueError(f"FilterInfo type must be one of {constants.FILTER_TYPES} "
                       f"(0 keepout, 1 speed %, 2 speed m/s, 3 binary, 4 zone, 5 direction); got {short_repr(type)}")
    b32 = validate.float32_values(base, "base", owner="FilterInfo.create")
    m32 = validate.float32_values(multiplier, "multiplier", owner="FilterInfo.create")
    if b32.shape != () or m32.shape != ():
      raise ValueError(f"FilterInfo.create: base and multiplier must be scalars; got shapes "
                       f"{b32.shape} and {m32.shape}")
    with np.errstate(over="ignore", invalid="ignore"):
      extremes = np.array([-1.0, 100.0], np.float32) * m32 + b32
    if not np.all(np.isfinite(extremes)):
      raise ValueError(f"FilterInfo.create: d * multiplier + base must stay finite in float32 for "
                       f"mask values d in -1..100; got base {short_repr(base)}, multiplier "
                       f"{short_repr(multiplier)}")
    return cls(jnp.asarray(int(type), jnp.int32), jnp.asarray(b32), jnp.asarray(m32))


@pytree_dataclass
class FilterMask:
  """A stack of M filter masks of one shape, each with its own geometry and info.

  A fleet sharing one mask has M = 1; a fleet with one mask per robot (or per
  group) passes `mask_index` [B] to the filters to pick each robot's mask.

  Attributes:
    data: int8 [M, H, W], OccupancyGrid values; row 0 is the lowest y.
    origin: float32 [M, 2], world (x, y) of the lower-left corner of cell (0, 0)
      (the float32 rounding of the host double).
    resolution: float32 [M], metres per cell (float32, as nav_msgs stores it).
    info: FilterInfo with leaves [M].
    origin_lo: float32 [M, 2, 2] or None: the (mid, lo) float32 parts that,
      added to `origin`, give the host float64 origin exactly
      (`validate.split_float64`); None means the origin is exactly float32.
  """
  data: jax.Array
  origin: jax.Array
  resolution: jax.Array
  info: FilterInfo
  origin_lo: jax.Array | None = None

  @property
  def num_masks(self) -> int:
    """M, the number of masks in the stack."""
    return self.data.shape[0]

  @property
  def shape(self) -> tuple[int, int]:
    """(H, W) of every mask in the stack."""
    return tuple(self.data.shape[1:])

  @classmethod
  def create(cls, grids: OccupancyGrid | Sequence[OccupancyGrid],
             infos: FilterInfo | Sequence[FilterInfo]) -> "FilterMask":
    """Stacks one or more OccupancyGrids with their FilterInfo into a device mask.

    Every grid is re-validated here (a grid built without `OccupancyGrid.create`
    may hold anything): integer cell values that fit int8 (never wrapped),
    a non-empty [H, W], a resolution that is > 0 and a normal float32, and an
    origin whose float64 value is carried exactly.

    Args:
      grids: one grid, or a sequence of grids of the same [H, W].
      infos: one FilterInfo for all grids, or one per grid.

    Raises:
      ValueError: empty input, grids of different shapes, a count mismatch, or
        a bad value in a grid (named with the grid's position).
      TypeError: a grid that is not an OccupancyGrid or an info that is not a FilterInfo.
    """
    if isinstance(grids, OccupancyGrid):
      grids = [grids]
    grids = list(grids)
    if not grids:
      raise ValueError("FilterMask.create needs at least one OccupancyGrid; got none")
    datas, origins, resolutions = [], [], []
    for k, g in enumerate(grids):
      if not isinstance(g, OccupancyGrid):
        raise TypeError(f"FilterMask.create expects OccupancyGrid objects (see jaxfilters.load_map); "
                        f"got {type(g).__name__}")
      owner = f"FilterMask.create grid {k}"
      arr = np.asarray(g.data)
      if arr.ndim != 2 or arr.shape[0] == 0 or arr.shape[1] == 0:
        raise ValueError(f"{owner}: data must be a non-empty [H, W] array; got shape {arr.shape}")
      datas.append(validate.int_values(arr, "data", lo=-128, hi=127, owner=owner).astype(np.int8))
      resolutions.append(validate.resolution_value(g.resolution, owner=owner))
      try:
        org = np.asarray(g.origin, np.float64)
      except (TypeError, ValueError):
        org = np.zeros((0,))
      if org.ndim != 1 or org.shape[0] not in (2, 3):
        raise ValueError(f"{owner}: origin must be (x, y) or (x, y, yaw); got {short_repr(g.origin)}")
      validate.float32_values(org[:2], "origin", owner=owner)
      origins.append(org[:2])
    shapes = {d.shape for d in datas}
    if len(shapes) != 1:
      raise ValueError(f"all masks in one FilterMask must share one [H, W]; got shapes {sorted(shapes)}")
    if isinstance(infos, FilterInfo):
      infos = [infos] * len(grids)
    infos = list(infos)
    if len(infos) != len(grids):
      raise ValueError(f"need one FilterInfo or one per grid ({len(grids)}); got {len(infos)}")
    for i in infos:
      if not isinstance(i, FilterInfo):
        raise TypeError(f"FilterMask.create expects FilterInfo objects (FilterInfo.create); got "
                        f"{type(i).__name__}")
    info = FilterInfo(
        type=jnp.asarray(np.array([int(i.type) for i in infos], np.int32)),
        base=jnp.asarray(_f32([float(i.base) for i in infos])),
        multiplier=jnp.asarray(_f32([float(i.multiplier) for i in infos])))
    try:
      parts = validate.split_float64(np.stack(origins))
    except ValueError as e:
      raise ValueError(f"FilterMask.create: origin: {e}") from None
    return cls(
        data=jnp.asarray(np.stack(datas)),
        origin=jnp.asarray(np.ascontiguousarray(parts[..., 0])),
        resolution=jnp.asarray(np.stack(resolutions).astype(np.float32)),
        info=info,
        # None when the origins are exactly float32: fewer terms in the exact arithmetic.
        origin_lo=None if not np.any(parts[..., 1:]) else jnp.asarray(np.ascontiguousarray(parts[..., 1:])))

  def with_data(self, data) -> "FilterMask":
    """Returns this mask with new cell contents of the same shape (no recompile).

    Works eagerly and inside a caller's `jit`. Eager (a concrete array) every
    value is checked. Traced (inside `jit`), the values cannot be read, so only
    what is static is checked: the shape, and the dtype, which must be int8 (an
    int32 array would wrap silently when cast; cast it yourself, e.g. with
    `jnp.clip(x, -128, 127).astype(jnp.int8)`, where you know its range).

    Args:
      data: integer [M, H, W] (or [H, W] for M = 1) values that fit int8.

    Raises:
      ValueError: data of another shape, a non-integer dtype (floats such as
        99.9 or NaN are refused, never truncated), values outside int8 (eager),
        or a traced array that is not int8.
    """
    if isinstance(data, jax.core.Tracer):
      arr = data[None] if data.ndim == 2 else data
      if tuple(arr.shape) != tuple(self.data.shape):
        raise ValueError(f"new mask data must have shape {tuple(self.data.shape)} (or [H, W] "
                         f"for M = 1); got {tuple(data.shape)}")
      if arr.dtype != jnp.int8:
        raise ValueError(f"FilterMask.with_data: traced new mask data must be int8 (its values cannot be "
                         f"checked under jit, and a cast would wrap them); got {arr.dtype}")
      return dataclasses.replace(self, data=arr)
    arr = np.asarray(data)
    if arr.ndim == 2:
      arr = arr[None]
    if arr.shape != tuple(self.data.shape):
      raise ValueError(f"new mask data must have shape {tuple(self.data.shape)} (or [H, W] "
                       f"for M = 1); got {arr.shape}")
    arr = validate.int_values(arr, "new mask data", lo=-128, hi=127, owner="FilterMask.with_data")
    return dataclasses.replace(self, data=jnp.asarray(arr.astype(np.int8)))


def check_mask(mask: FilterMask, where: str) -> None:
  """Static checks of a FilterMask pytree that reaches a public function (works under jit).

  A mask built as a pytree (not through `FilterMask.create`) may have any leaves;
  the shapes and dtypes are static, so they are checked here, at trace time.
  Values (a NaN resolution, say) are not: see `mask_geometry_ok`.

  Raises:
    TypeError: not a FilterMask.
    ValueError: wrong dtypes or shapes of its leaves, naming the leaf and the
      shape expected (data int8 [M, H, W] with M, H, W >= 1; origin float [M, 2];
      resolution float [M]; info leaves [M]; origin_lo float [M, 2, 2] or None).
  """
  if not isinstance(mask, FilterMask):
    raise TypeError(f"{where}: mask must be a FilterMask (FilterMask.create); got {type(mask).__name__}")
  if not isinstance(mask.info, FilterInfo):
    raise TypeError(f"{where}: mask.info must be a FilterInfo; got {type(mask.info).__name__}")
  d = mask.data
  if getattr(d, "ndim", None) != 3 or d.dtype != jnp.int8:
    raise ValueError(f"{where}: mask.data must be int8 [M, H, W]; got {getattr(d, 'dtype', None)}"
                     f"{tuple(getattr(d, 'shape', ()))}")
  if 0 in d.shape:
    raise ValueError(f"{where}: mask.data must be int8 [M, H, W] with M, H and W >= 1 (at least one "
                     f"mask of at least one cell); got shape {tuple(d.shape)}")
  m = d.shape[0]
  expect = {"origin": ((m, 2), "floating"), "resolution": ((m,), "floating"),
            "info.type": ((m,), "integer"), "info.base": ((m,), "floating"),
            "info.multiplier": ((m,), "floating")}
  leaves = {"origin": mask.origin, "resolution": mask.resolution, "info.type": mask.info.type,
            "info.base": mask.info.base, "info.multiplier": mask.info.multiplier}
  if mask.origin_lo is not None:
    expect["origin_lo"] = ((m, 2, 2), "floating")
    leaves["origin_lo"] = mask.origin_lo
  for name, (shape, kind) in expect.items():
    v = leaves[name]
    dt = getattr(v, "dtype", None)
    ok_kind = dt is not None and jnp.issubdtype(dt, jnp.floating if kind == "floating" else jnp.integer)
    if tuple(getattr(v, "shape", ())) != shape or not ok_kind:
      raise ValueError(f"{where}: mask.{name} must be {kind} {shape} (M = {m} masks, from mask.data "
                       f"{tuple(d.shape)}); got {dt}{tuple(getattr(v, 'shape', ()))}")


def mask_geometry_ok(mask: FilterMask, *, xp=jnp) -> jax.Array:
  """Whether each mask's geometry can be used, as a traced value: bool [M].

  `FilterMask.create` refuses bad geometry on the host; a mask whose leaves are
  replaced under `jit` (or built as a pytree) can still carry anything. A mask is
  usable when its resolution is finite and at least the smallest normal float32
  (1.18e-38; so 0, negative, NaN, inf and subnormal resolutions are not) and its
  origin parts (`origin`, and `origin_lo` when present) are finite. Every filter
  and point query treats a robot or point on an unusable mask as it treats a bad
  mask index: `valid` False and `error` True (filters), the fill value (queries).
  `xp=numpy` runs the same test on host arrays (no device op, nothing to compile).
  """
  r = mask.resolution
  ok = xp.isfinite(r) & (r >= validate.F32_TINY)
  ok = ok & xp.all(xp.isfinite(mask.origin), axis=-1)
  if mask.origin_lo is not None:
    ok = ok & xp.all(xp.isfinite(mask.origin_lo), axis=(-2, -1))
  return ok


def check_mask_index_host(host: np.ndarray, m: int, num_robots: int) -> None:
  """A concrete mask_index (NumPy) is an integer [B] array in [0, M) (`resolve_mask_index`'s host checks)."""
  if host.shape != (num_robots,) or not (np.issubdtype(host.dtype, np.integer)):
    raise ValueError(f"mask_index must be an integer array of shape ({num_robots},); "
                     f"got {host.dtype}{tuple(host.shape)}")
  bad = np.nonzero((host < 0) | (host >= m))[0]
  if bad.size:
    raise ValueError(f"mask_index must lie in [0, {m}) (the FilterMask holds {m} masks); robots "
                     f"{bad[:8].tolist()}{' ...' if bad.size > 8 else ''} have "
                     f"{host[bad[:8]].tolist()}")


def resolve_mask_index(mask: FilterMask, mask_index: jax.Array | None,
                       num_robots: int) -> tuple[jax.Array, jax.Array]:
  """Which mask of the stack each robot uses, and whether that index is in range.

  A shared mask (mask_index None) must have M == 1. The [M, H, W] data stack
  is never copied per robot: kernels receive the stack and this index.

  Concrete indices (numpy, Python or concrete jax values: an eager call) are
  checked here and an out-of-range one raises. Traced indices (inside a
  caller's `jit`) cannot be checked on the host: a robot whose index is
  outside [0, M) gets index 0 *for memory safety only* and `ok` False, and
  every filter then leaves that robot untouched (no write, `valid` False) and
  sets its `error` flag. An index is never clamped onto another mask.

  Returns:
    (index int32 [B] safe to gather with, ok bool [B]).

  Raises:
    ValueError: a stack of several masks without mask_index, a mask_index that
      is not an integer [B] array, or (eager) one outside [0, M).
  """
  m = mask.num_masks
  if mask_index is None:
    if m != 1:
      raise ValueError(f"a FilterMask stack of {m} masks needs mask_index [B] "
                       "to say which mask each robot uses; got mask_index=None")
    return jnp.zeros((num_robots,), jnp.int32), jnp.ones((num_robots,), bool)
  if not isinstance(mask_index, jax.core.Tracer):
    check_mask_index_host(np.asarray(mask_index), m, num_robots)
  idx = jnp.asarray(mask_index)
  if idx.shape != (num_robots,) or not jnp.issubdtype(idx.dtype, jnp.integer):
    raise ValueError(f"mask_index must be an integer array of shape ({num_robots},); "
                     f"got {idx.dtype}{tuple(idx.shape)}")
  ok = (idx >= 0) & (idx < m)
  return jnp.where(ok, idx, 0).astype(jnp.int32), ok


@pytree_dataclass
class Costmap:
  """A batch of B costmaps of one [H, W]: rolling-window local maps or full global maps.

  Attributes:
    cost: uint8 [B, H, W], Nav2 cost values (0..252, 253, 254, 255).
    origin: float32 [B, 2], world (x, y) of the lower-left corner of cell (0, 0),
      per robot (a rolling window moves it; a global map repeats it); the
      float32 rounding of the host value.
    resolution: float32 [B], metres per cell (float32 rounding).
    origin_lo: float32 [B, 2, 2] or None: the (mid, lo) parts that make the
      host float64 origin exact (`validate.split_float64`); None = exactly float32
      (`create` leaves it None then; a value that is not float32 compiles the
      longer exact arithmetic, once).
    resolution_lo: float32 [B, 2] or None: the same for the resolution (Nav2's
      costmap resolution is a double parameter such as 0.05).
  """
  cost: jax.Array
  origin: jax.Array
  resolution: jax.Array
  origin_lo: jax.Array | None = None
  resolution_lo: jax.Array | None = None

  @property
  def num_robots(self) -> int:
    """B, the number of costmaps in the batch."""
    return self.cost.shape[0]

  @classmethod
  def create(cls, cost, origin, resolution) -> "Costmap":
    """Validates and builds a batch of costmaps, keeping float64 geometry exact.

    Works eagerly and inside a caller's `jit`. A concrete argument is checked
    in full (values included) and a float64 origin or resolution is carried
    exactly (`validate.split_float64`). A traced argument (inside `jit`) is
    checked for what is static only, its shape and dtype: traced `cost` must be
    uint8, a traced origin or resolution must be floating point and is used as
    its float32 value (float64 does not exist inside `jit` by default). Traced
    geometry values are not checked here: `costmap_geometry_ok` says, as a
    traced value, whether they are usable.

    Args:
      cost: uint8 [B, H, W] (or [H, W] for B = 1).
      origin: [B, 2] or [2] (broadcast to every robot), metres; a float64
        value (Nav2's costmap origin is a double) is carried exactly.
      resolution: [B] or scalar (broadcast), metres per cell; float64 kept exactly.

    Raises:
      ValueError: wrong rank or dtype, batch mismatch, an empty grid, and (for
        concrete values) a resolution not > 0 or not a normal float32, a
        non-finite origin.
    """
    traced = lambda x: isinstance(x, jax.core.Tracer)
    if traced(cost):
      c = cost[None] if cost.ndim == 2 else cost
      if c.ndim != 3 or 0 in c.shape:
        raise ValueError(f"cost must be a non-empty uint8 [B, H, W]; got shape {tuple(c.shape)}")
      if c.dtype != jnp.uint8:
        raise ValueError(f"cost must have dtype uint8 (Nav2 costs 0..255); got {c.dtype}")
    else:
      c = np.asarray(cost)
      if c.ndim == 2:
        c = c[None]
      if c.ndim != 3 or 0 in c.shape:
        raise ValueError(f"cost must be a non-empty uint8 [B, H, W]; got shape {c.shape}")
      if c.dtype != np.uint8:
        raise ValueError(f"cost must have dtype uint8 (Nav2 costs 0..255); got {c.dtype}")
    b = c.shape[0]
    arr = lambda x: jnp.asarray(np.ascontiguousarray(x))
    lo = lambda x: None if not np.any(x) else arr(x)    # exactly float32: fewer exact terms
    if traced(origin):
      o_hi, o_lo = _traced_float(origin, "origin", (2,), (b, 2)), None
    else:
      o = np.asarray(validate.float32_values(origin, "origin", owner="Costmap.create").shape)
      o64 = np.asarray(origin, np.float64)
      if o64.shape == (2,):
        o64 = np.broadcast_to(o64, (b, 2))
      if o64.shape != (b, 2):
        raise ValueError(f"Costmap.create: origin must be [B, 2] = ({b}, 2) or [2]; got {tuple(o)}")
      try:
        op = validate.split_float64(o64)
      except ValueError as e:
        raise ValueError(f"Costmap.create: {e}") from None
      o_hi, o_lo = arr(op[..., 0]), lo(op[..., 1:])
    if traced(resolution):
      r_hi, r_lo = _traced_float(resolution, "resolution", (), (b,)), None
    else:
      validate.resolution_value(resolution, owner="Costmap.create")
      r64 = np.asarray(resolution, np.float64)
      if r64.ndim == 0:
        r64 = np.broadcast_to(r64, (b,))
      if r64.shape != (b,):
        raise ValueError(f"Costmap.create: resolution must be [B] = ({b},) or a scalar; got {r64.shape}")
      try:
        rp = validate.split_float64(r64)
      except ValueError as e:
        raise ValueError(f"Costmap.create: {e}") from None
      r_hi, r_lo = arr(rp[..., 0]), lo(rp[..., 1:])
    return cls(jnp.asarray(c), o_hi, r_hi, o_lo, r_lo)

  @classmethod
  def from_grid(cls, grid: OccupancyGrid, cost, num_robots: int) -> "Costmap":
    """A global costmap with `grid`'s geometry, repeated for `num_robots` robots."""
    c = np.broadcast_to(np.asarray(cost, np.uint8), (num_robots, *np.shape(cost)[-2:]))
    return cls.create(np.ascontiguousarray(c), grid.origin[:2], grid.resolution)


def _traced_float(x, name: str, one: tuple[int, ...], full: tuple[int, ...]) -> jax.Array:
  """A traced float argument of `Costmap.create` as float32 `full`, broadcast from `one` (static checks only)."""
  if not jnp.issubdtype(x.dtype, jnp.floating):
    raise ValueError(f"Costmap.create: {name} must be floating point; got {x.dtype}")
  if tuple(x.shape) not in (one, full):
    raise ValueError(f"Costmap.create: {name} must be {list(full)} or {list(one)}; got {tuple(x.shape)}")
  return jnp.broadcast_to(x.astype(jnp.float32), full)


def costmap_geometry_ok(costmap: Costmap, *, xp=jnp) -> jax.Array:
  """Whether each costmap's geometry can be used, as a traced value: bool [B].

  As `mask_geometry_ok` (`xp` too): a resolution that is finite and at least the smallest
  normal float32, finite origin parts (and finite `*_lo` parts when present).
  """
  r = costmap.resolution
  ok = xp.isfinite(r) & (r >= validate.F32_TINY) & xp.all(xp.isfinite(costmap.origin), axis=-1)
  if costmap.origin_lo is not None:
    ok = ok & xp.all(xp.isfinite(costmap.origin_lo), axis=(-2, -1))
  if costmap.resolution_lo is not None:
    ok = ok & xp.all(xp.isfinite(costmap.resolution_lo), axis=-1)
  return ok


def check_costmap(costmap: Costmap, where: str) -> None:
  """Static checks of a Costmap pytree that reaches a public function (works under jit).

  Raises:
    TypeError: not a Costmap.
    ValueError: cost not uint8 [B, H, W] (int32 or float "costs" would give
      values outside 0..255), or geometry leaves of the wrong shape or dtype.
  """
  if not isinstance(costmap, Costmap):
    raise TypeError(f"{where}: costmap must be a Costmap (Costmap.create); got {type(costmap).__name__}")
  c = costmap.cost
  if getattr(c, "ndim", None) != 3 or c.dtype != jnp.uint8:
    raise ValueError(f"{where}: costmap.cost must be uint8 [B, H, W] (Nav2 costs 0..255); got "
                     f"{getattr(c, 'dtype', None)}{tuple(getattr(c, 'shape', ()))}")
  if 0 in c.shape:
    raise ValueError(f"{where}: costmap.cost must be uint8 [B, H, W] with B, H and W >= 1; got shape "
                     f"{tuple(c.shape)}")
  b = c.shape[0]
  for name, v, shape in (("origin", costmap.origin, (b, 2)), ("resolution", costmap.resolution, (b,)),
                         ("origin_lo", costmap.origin_lo, (b, 2, 2)),
                         ("resolution_lo", costmap.resolution_lo, (b, 2))):
    if v is None and name.endswith("_lo"):
      continue
    dt = getattr(v, "dtype", None)
    if tuple(getattr(v, "shape", ())) != shape or dt is None or not jnp.issubdtype(dt, jnp.floating):
      raise ValueError(f"{where}: costmap.{name} must be float {shape}; got {dt}{tuple(getattr(v, 'shape', ()))}")


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


def per_robot_bool(name: str, value: Any, num_robots: int, *, default: bool) -> jax.Array:
  """A per-robot flag: None (-> `default`), a bool scalar or bool [B]; returns bool [B].

  Raises:
    ValueError: another dtype or shape (a float or int flag is not silently cast).
  """
  b = num_robots
  v = jnp.asarray(default if value is None else value)
  if v.dtype != jnp.bool_ or v.shape not in ((), (b,)):
    raise ValueError(f"{name} must be a bool scalar or bool [B] = ({b},); got {v.dtype}{tuple(v.shape)}")
  return jnp.broadcast_to(v, (b,))


def check_state_batch(state: Any, num_robots: int, source: str) -> None:
  """Static check that every leaf of a per-robot state (a pytree dataclass) leads with B robots.

  A mismatch would otherwise surface as JAX's internal "vmap got inconsistent sizes".

  Args:
    state: the state (KeepoutState, SpeedState, ...); None leaves are skipped.
    num_robots: B.
    source: what says B, for the message (e.g. "costmaps have 4 (cost [4, 6, 6])").

  Raises:
    ValueError: a leaf whose leading size is not B, naming the leaf, its shape and `source`.
  """
  for f in dataclasses.fields(state):
    leaf = getattr(state, f.name)
    if leaf is None:
      continue
    shape = tuple(int(n) for n in getattr(leaf, "shape", ()))
    if not shape or shape[0] != num_robots:
      n = shape[0] if shape else "no"
      raise ValueError(f"{type(state).__name__} has {n} robots ({f.name} {list(shape)}) but {source}; "
                       f"build it with {type(state).__name__}.create for the same B")


def host_view(x):
  """x with .shape and .dtype and no device work: a JAX or NumPy array as it is, else NumPy."""
  if isinstance(x, (jax.Array, np.ndarray, jax.core.Tracer)):
    return x
  return np.asarray(x)


def check_robot_inputs(mask: FilterMask, poses: Any, num_robots: int, mask_index=None, enabled=None,
                       transform=None, *, state: Any = None):
  """`robot_inputs`' checks at an eager call's edge, with no device work.

  A public function runs this in Python and `robot_inputs` inside its jitted body:
  the conversions (dtype casts, broadcasts, index flags) then run in the compiled
  program instead of as one eager device operation each, and a concrete mask_index
  is still checked on the host. The messages are `robot_inputs`'.

  Returns:
    (poses, mask_index, enabled, transform): arrays (NumPy for Python values) or None.

  Raises:
    ValueError: the inputs `robot_inputs` refuses, with its messages.
  """
  b = num_robots
  poses = host_view(poses)
  if state is not None:
    first = dataclasses.fields(state)[0].name
    lead = f"{type(state).__name__} has {b} robots ({first} {list(getattr(state, first).shape)})"
    if poses.ndim == 2 and poses.shape[0] != b:
      raise ValueError(f"{lead} but poses have {poses.shape[0]} (poses {list(poses.shape)})")
    check_state_batch(state, b, f"{first} has {b}")
  check_mask(mask, "filter input")
  if mask_index is None:
    if mask.num_masks != 1:
      resolve_mask_index(mask, None, b)       # raises
  else:
    mask_index = host_view(mask_index)
    if not isinstance(mask_index, jax.core.Tracer):
      check_mask_index_host(np.asarray(mask_index), mask.num_masks, b)
  if tuple(poses.shape) != (b, 3):
    raise ValueError(f"poses must be [B, 3] = ({b}, 3) (x, y, yaw); got {tuple(poses.shape)}")
  if not jnp.issubdtype(poses.dtype, jnp.floating):
    raise ValueError(f"poses must be floating point; got {poses.dtype}")
  if enabled is not None:
    enabled = host_view(enabled)
    if enabled.dtype != np.bool_ or tuple(enabled.shape) not in ((), (b,)):
      raise ValueError(f"enabled must be a bool scalar or bool [B] = ({b},); got {enabled.dtype}"
                       f"{tuple(enabled.shape)}")
  if transform is not None:
    transform = host_view(transform)
    if tuple(transform.shape) not in ((3,), (b, 3)):
      raise ValueError(f"transform must be T_mask_from_global (x, y, yaw) of shape (3,) or ({b}, 3); "
                       f"got {tuple(transform.shape)}")
  return poses, mask_index, enabled, transform


def robot_inputs(mask: FilterMask, poses: Any, num_robots: int, mask_index=None, enabled=None,
                 transform=None, *, state: Any = None):
  """Validates and broadcasts the per-robot inputs every filter takes.

  Args:
    mask: the FilterMask stack.
    poses: float [B, 3].
    num_robots: B.
    mask_index: None (shared mask, M == 1) or int [B].
    enabled: None (all enabled), a bool scalar, or bool [B].
    transform: None (mask in the costmap frame), or T_mask_from_global
      (x, y, yaw) as [3] or [B, 3].
    state: optional per-robot state whose first leaf gave B; its leaves and
      the poses are checked against it (`check_state_batch`).

  Returns:
    (mask index int32 [B], index in range bool [B] (see resolve_mask_index),
    poses float32 [B, 3], enabled bool [B], transform float32 [B, 3] or None).

  Raises:
    ValueError: any of them with the wrong shape or dtype, a state or poses
      whose batch is not B (naming both sizes), or (eager) a mask_index
      outside [0, M).
    TypeError: mask is not a FilterMask.
  """
  b = num_robots
  if state is not None:
    first = dataclasses.fields(state)[0].name
    lead = f"{type(state).__name__} has {b} robots ({first} {list(getattr(state, first).shape)})"
    p_shape = tuple(int(n) for n in jnp.shape(poses))
    if len(p_shape) == 2 and p_shape[0] != b:
      raise ValueError(f"{lead} but poses have {p_shape[0]} (poses {list(p_shape)})")
    check_state_batch(state, b, f"{first} has {b}")
  check_mask(mask, "filter input")
  idx, idx_ok = resolve_mask_index(mask, mask_index, b)
  poses = check_poses(poses, b)
  en = per_robot_bool("enabled", enabled, b, default=True)
  if transform is not None:
    transform = jnp.asarray(transform, jnp.float32)
    if transform.shape not in ((3,), (b, 3)):
      raise ValueError(f"transform must be T_mask_from_global (x, y, yaw) of shape (3,) or ({b}, 3); "
                       f"got {tuple(transform.shape)}")
    transform = jnp.broadcast_to(transform, (b, 3))
  return idx, idx_ok, poses, en, transform
