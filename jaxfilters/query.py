"""Point queries: what each Nav2 filter's mask says at given points (rewards, planners, tools).

The filters (`speed_filter`, `keepout_filter`, ...) run Nav2's per-cycle
process with carried state over a fleet [B]. A reward or a planner often only
needs "what does the mask say here": these functions answer that for points of
any leading shape, a single point [2] included, with no state and no fake
batch of one:

    limit, percentage, valid = speed_limit_at(mask, [1.2, 3.4])     # shapes []
    cost = keepout_cost_at(mask, xy)                                 # xy [T, B, 2] -> uint8 [T, B]

Every answer is one mask cell, read through the filters' own cell rule
(`mask_lookup.mask_cell`: Nav2's `worldToMap` as an exact floor on the host
float64 origin) and decoded by the filters' own rules (`speed.speed_limit_value`,
`keepout.occ_to_cost`, `binary.binary_cell`, `zone.zone_cell`), so a query and a
filter at the same pose read the same cell and give the same answer. No frame
transform is applied (points are in the mask frame).

Fill values (value problems are masked, never raised under `jit`, so one bad
point cannot stop a batch):

| query | off the mask, non-finite point, unknown cell (-1), bad mask_index, unusable mask geometry |
| --- | --- |
| `speed_limit_at` | limit 0.0, valid False |
| `keepout_cost_at` | 255 (NO_INFORMATION) |
| `zone_at` | -1 |
| `binary_at` | state = default_state, valid False |

`mask_index` picks one mask of a stack per point (int of the points' leading
shape). With concrete values (eager calls) an index outside [0, M) raises
`ValueError` naming it; under an outer `jit` the values are unknown, so such a
point gets the fill value above (never another mask's answer). A mask whose
traced geometry is unusable (`types.mask_geometry_ok`: a resolution that is not
a normal float32 > 0, a non-finite origin) likewise gives the fill value.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from jaxfilters.binary import binary_cell
from jaxfilters.keepout import occ_to_cost
from jaxfilters.mask_lookup import mask_cell, mask_leaves
from jaxfilters.speed import speed_limit_at_one
from jaxfilters.types import FilterMask, check_mask, mask_geometry_ok
from jaxfilters.zone import zone_cell
from jaxfilters.validate import F32_TINY, float32_values, short_repr

_F32 = jnp.float32
NO_ZONE = -1


def _is_traced(x) -> bool:
  return isinstance(x, jax.core.Tracer)


def _points(fn: str, points) -> jax.Array:
  """Validates points float [..., 2] and returns them as float32.

  Host arrays are checked in float32 terms: a finite value that becomes inf, or
  a non-zero value that becomes 0 or subnormal, would silently move the point
  (ValueError). NaN and inf stay allowed: they are value problems and come back
  invalid.
  """
  if _is_traced(points) or isinstance(points, jax.Array):
    p = points
    dtype = p.dtype
  else:
    try:
      p = np.asarray(points)
    except Exception as e:  # noqa: BLE001
      raise TypeError(f"{fn}: points must be a float array [..., 2]; got {short_repr(points)} "
                      f"({type(e).__name__})") from None
    dtype = p.dtype
  if dtype == bool or not (jnp.issubdtype(dtype, jnp.floating) or jnp.issubdtype(dtype, jnp.integer)):
    raise TypeError(f"{fn}: points must be real numbers (float [..., 2]); got dtype {dtype}")
  if p.ndim < 1 or p.shape[-1] != 2:
    raise ValueError(f"{fn}: points must have shape [..., 2] (x, y in the mask frame, m); "
                     f"got shape {tuple(p.shape)}")
  if isinstance(p, np.ndarray):
    p64 = p.astype(np.float64)
    with np.errstate(over="ignore", under="ignore"):
      p32 = p64.astype(np.float32)
    overflow = np.isfinite(p64) & ~np.isfinite(p32)
    tiny = (p64 != 0) & (np.abs(p64) < F32_TINY)
    if np.any(overflow | tiny):
      bad = p64[overflow | tiny]
      raise ValueError(f"{fn}: points must be 0 or between {F32_TINY:.4g} and 3.4e38 in magnitude "
                       f"(float32, the device's precision); got {short_repr(bad.tolist())}")
    return jnp.asarray(p32)
  return p.astype(_F32)


def _mask_index(fn: str, mask: FilterMask, mask_index, lead: tuple[int, ...]) -> jax.Array:
  """int32 of the leading shape; concrete values are range-checked (see module docstring)."""
  check_mask(mask, fn)
  m = mask.num_masks
  if mask_index is None:
    if m != 1:
      raise ValueError(f"{fn}: a FilterMask stack of {m} masks needs mask_index (int of the points' "
                       f"leading shape {lead}) to say which mask each point uses; got None")
    return jnp.zeros(lead, jnp.int32)
  traced = _is_traced(mask_index)
  idx = mask_index if traced or isinstance(mask_index, jax.Array) else np.asarray(mask_index)
  if idx.dtype == bool or not jnp.issubdtype(idx.dtype, jnp.integer):
    raise TypeError(f"{fn}: mask_index must be integers; got dtype {idx.dtype}")
  if tuple(idx.shape) != lead:
    raise ValueError(f"{fn}: mask_index must have the points' leading shape {lead}; "
                     f"got {tuple(idx.shape)}")
  if not traced:
    host = np.asarray(idx)
    bad = (host < 0) | (host >= m)
    if np.any(bad):
      where = [tuple(int(v) for v in w) for w in np.argwhere(bad)[:5]]
      raise ValueError(f"{fn}: mask_index must lie in [0, {m}) (the stack has {m} masks); got "
                       f"{short_repr(host[bad][:5].tolist())} at positions {where}"
                       f"{' ...' if int(bad.sum()) > 5 else ''}")
  return jnp.asarray(idx).astype(jnp.int32)


def _prepare(fn, mask, points, mask_index):
  pts = _points(fn, points)
  lead = tuple(pts.shape[:-1])
  idx = _mask_index(fn, mask, mask_index, lead)
  return pts.reshape(-1, 2), idx.reshape(-1), lead


def _mask_at(mask: FilterMask, i):
  """(mask i's leaves as `mask_lookup.mask_leaves`, usable bool []): i outside [0, M) or bad geometry -> False."""
  m = mask.num_masks
  ok = (i >= 0) & (i < m)
  j = jnp.clip(i, 0, m - 1)
  return mask_leaves(mask, j), ok & mask_geometry_ok(mask)[j]


def _cell(mask: FilterMask, i, xy):
  """(raw value int32, on a usable mask bool, info) of mask i at one point (the filters' cell rule)."""
  (data, origin, res, info), ok = _mask_at(mask, i)
  d, inside = mask_cell(data, origin, res, xy)
  return d, inside & ok, info


@jax.jit
def _speed(mask: FilterMask, pts, idx):
  def one(xy, i):
    (data, origin, res, info), ok = _mask_at(mask, i)
    limit, valid = speed_limit_at_one(data, origin, res, info, xy)
    valid = valid & ok
    return (jnp.where(valid, limit, 0.0).astype(_F32),
            info.type == constants.SPEED_FILTER_PERCENT, valid)
  return jax.vmap(one)(pts, idx)


def speed_limit_at(mask: FilterMask, points, *, mask_index=None):
  """The SpeedFilter limit at points (Nav2 getSpeedLimitAtPose, docs/nav2_semantics.md §5.3).

  Args:
    mask: FilterMask of type 1 (percent) or 2 (m/s), M masks.
    points: float [..., 2] (x, y) in the mask frame (m); a single point is [2].
    mask_index: None for a single-mask FilterMask (M = 1), else int [...] (the
      points' leading shape) picking each point's mask.

  Returns:
    (limit float32 [...], percentage bool [...], valid bool [...]). limit is
    Nav2's value: 0.0 means "no limit" (mask value 0, or a computed limit out
    of range), otherwise percent of max speed or m/s per `percentage`. valid is
    False (limit 0.0) off the mask, for a non-finite point, on an unknown (-1)
    cell, for a mask whose type is neither 1 nor 2, for an out-of-range
    mask_index under jit and on a mask whose traced geometry is unusable.

  Raises:
    ValueError / TypeError: points not float [..., 2], a host value that does
      not survive float32, mask_index missing for a stack, of the wrong shape
      or dtype, or (concrete values) outside [0, M).
  """
  with jax.named_scope("speed_limit_at"):
    pts, idx, lead = _prepare("speed_limit_at", mask, points, mask_index)
    limit, pct, valid = _speed(mask, pts, idx)
    return limit.reshape(lead), pct.reshape(lead), valid.reshape(lead)


@jax.jit
def _keepout(mask: FilterMask, pts, idx):
  def one(xy, i):
    d, inside, _ = _cell(mask, i, xy)
    return jnp.where(inside, occ_to_cost(d), jnp.uint8(constants.NO_INFORMATION))
  return jax.vmap(one)(pts, idx)


def keepout_cost_at(mask: FilterMask, points, *, mask_index=None) -> jax.Array:
  """The cost the KeepoutFilter would write from the mask cell at points (docs/nav2_semantics.md §1.4, §4.4).

  Args:
    mask: FilterMask (type 0; like Nav2, base and multiplier are not used).
    points: float [..., 2] (x, y) in the mask frame (m).
    mask_index: as `speed_limit_at`.

  Returns:
    uint8 [...]: `occ_to_cost` of the cell (0..254; 254 for mask value 100,
    the lethal keepout), 255 off the mask, for a non-finite point, on an
    unknown cell, for an out-of-range mask_index under jit and on a mask
    whose traced geometry is unusable.

  Raises:
    ValueError / TypeError: as `speed_limit_at`.
  """
  with jax.named_scope("keepout_cost_at"):
    pts, idx, lead = _prepare("keepout_cost_at", mask, points, mask_index)
    return _keepout(mask, pts, idx).reshape(lead)


@jax.jit
def _zone(mask: FilterMask, pts, idx):
  def one(xy, i):
    d, inside, _ = _cell(mask, i, xy)
    zid, known = zone_cell(d)
    return jnp.where(inside & known, zid, NO_ZONE).astype(jnp.int32)
  return jax.vmap(one)(pts, idx)


def zone_at(mask: FilterMask, points, *, mask_index=None) -> jax.Array:
  """The ZoneParameterFilter state id at points (docs/nav2_semantics.md §7: id = mask value 0..127).

  Args:
    mask: FilterMask (type 4; base and multiplier are ignored, as in Nav2).
    points: float [..., 2] (x, y) in the mask frame (m).
    mask_index: as `speed_limit_at`.

  Returns:
    int32 [...]: the zone id (0 = nominal), -1 off the mask, for a
    non-finite point, on a negative (unknown) cell, for an out-of-range
    mask_index under jit and on a mask whose traced geometry is unusable.

  Raises:
    ValueError / TypeError: as `speed_limit_at`.
  """
  with jax.named_scope("zone_at"):
    pts, idx, lead = _prepare("zone_at", mask, points, mask_index)
    return _zone(mask, pts, idx).reshape(lead)


@jax.jit
def _binary(mask: FilterMask, pts, idx, default_state, flip_threshold):
  def one(xy, i):
    d, inside, info = _cell(mask, i, xy)
    target, known = binary_cell(d, info, default_state, flip_threshold)
    valid = inside & (info.type == constants.BINARY_FILTER) & known
    return jnp.where(valid, target, default_state), valid
  return jax.vmap(one)(pts, idx)


def binary_at(mask: FilterMask, points, *, mask_index=None, default_state: bool = False,
              flip_threshold: float = 50.0):
  """The BinaryFilter state at points (docs/nav2_semantics.md §6): base + d * multiplier > flip_threshold flips it.

  Args:
    mask: FilterMask of type 3.
    points: float [..., 2] (x, y) in the mask frame (m).
    mask_index: as `speed_limit_at`.
    default_state: Nav2 `default_state` (bool scalar).
    flip_threshold: Nav2 `flip_threshold` (float scalar, compared exactly as float32).

  Returns:
    (state bool [...], valid bool [...]): state is `not default_state` where
    the cell's value is above the threshold, else `default_state`. valid is
    False (state = default_state) off the mask, for a non-finite point, on an
    unknown cell, for a mask whose type is not 3, for an out-of-range
    mask_index under jit and on a mask whose traced geometry is unusable.

  Raises:
    ValueError / TypeError: as `speed_limit_at`, or a non-bool default_state,
      or a flip_threshold that is not a finite float32 scalar.
  """
  with jax.named_scope("binary_at"):
    pts, idx, lead = _prepare("binary_at", mask, points, mask_index)
    if not isinstance(default_state, (bool, np.bool_)) and not (
        _is_traced(default_state) and default_state.dtype == bool and default_state.shape == ()):
      raise TypeError(f"binary_at: default_state must be a bool scalar; got {short_repr(default_state)}")
    if not _is_traced(flip_threshold):
      thr = float32_values(flip_threshold, "flip_threshold", owner="binary_at")
      if thr.shape != ():
        raise ValueError(f"binary_at: flip_threshold must be a scalar; got shape {thr.shape}")
      flip_threshold = thr
    state, valid = _binary(mask, pts, idx, jnp.asarray(default_state, bool),
                           jnp.asarray(flip_threshold, _F32))
    return state.reshape(lead), valid.reshape(lead)


__all__ = ["NO_ZONE", "binary_at", "keepout_cost_at", "speed_limit_at", "zone_at"]
