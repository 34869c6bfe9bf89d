"""Host-side occupancy grid: what map_server loads and filter masks are built from."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from jaxfilters import validate
from jaxfilters.validate import short_repr


def geometry_values(resolution: Any, origin: Any, owner: str, res_name: str = "resolution",
                    origin_name: str = "origin") -> tuple[float, tuple[float, float, float]]:
  """Checks a grid's resolution and origin in the float32 terms the device sees.

  Args:
    resolution: metres per cell: one finite number > 0 that stays a normal
      float32 (1e-50 would become 0 on the device, 1e39 inf).
    origin: (x, y) or (x, y, yaw): finite numbers that are 0 or normal in
      float32 (metres, metres, radians); a missing yaw is 0.
    owner: who checks ("OccupancyGrid.create", a YAML path), for messages.
    res_name: the resolution's name in messages (e.g. "key 'resolution'").
    origin_name: the origin's name in messages.

  Returns:
    (resolution, (x, y, yaw)) as the given float64 values (not rounded).

  Raises:
    ValueError: a bool, array or non-number resolution, or one that is not
      finite, not > 0, or 0/subnormal/inf in float32; an origin that is not 2
      or 3 numbers or whose values are not finite or become inf/subnormal in
      float32. The message names owner and value (cut short).
  """
  if isinstance(resolution, (bool, np.bool_)):
    raise ValueError(f"{owner}: {res_name} must be a number; got {resolution!r}")
  if isinstance(resolution, (float, np.floating)) and \
      0 < abs(float(resolution)) < validate.F32_TINY:  # clearer than float32_values' wording
    raise ValueError(f"{owner}: {res_name} must be > 0 and at least {validate.F32_TINY:.4g} "
                     f"(smaller values become 0 or subnormal in float32 on the device); got "
                     f"{short_repr(resolution)}")
  res = validate.resolution_value(resolution, owner=owner, name=res_name)
  if res.shape != ():
    raise ValueError(f"{owner}: {res_name} must be one number; got shape {res.shape}")
  org = validate.float32_values(origin, origin_name, owner=owner)
  if org.ndim != 1 or org.shape[0] not in (2, 3):
    raise ValueError(f"{owner}: {origin_name} must be (x, y) or (x, y, yaw); got "
                     f"{short_repr(origin)}")
  org64 = tuple(float(v) for v in np.asarray(origin, dtype=np.float64))
  return float(np.asarray(resolution, dtype=np.float64)), (*org64, 0.0)[:3]


@dataclasses.dataclass(frozen=True, eq=False)
class OccupancyGrid:
  """A nav_msgs/OccupancyGrid held on the host.

  Attributes:
    data: int8 [H, W], values -1 (unknown) and 0..100. Row 0 is the lowest y
      (the bottom row of the image), as in nav_msgs/OccupancyGrid.
    resolution: metres per cell (nav_msgs stores it as float32).
    origin: (x, y, yaw) of the lower-left corner of cell (0, 0): metres,
      metres, radians. Nav2 ignores the yaw everywhere (docs/nav2_semantics.md §2.1); it is kept
      for saving.
    frame_id: the frame the grid lives in ("map" as map_server loads it).
  """
  data: np.ndarray
  resolution: float
  origin: tuple[float, float, float]
  frame_id: str = "map"

  @property
  def width(self) -> int:
    """W, cells along x."""
    """W, the number of columns (cells along +x)."""
    return int(self.data.shape[1])

  @property
  def height(self) -> int:
    """H, cells along y."""
    """H, the number of rows (cells along +y)."""
    return int(self.data.shape[0])

  @classmethod
  def create(cls, data, resolution: float, origin=(0.0, 0.0, 0.0),
             frame_id: str = "map") -> "OccupancyGrid":
    """Validates and builds a grid.

    Args:
      data: integer (or bool) [H, W] array, values -1..100, row 0 = lowest y.
      resolution: metres per cell; finite, > 0 and a normal float32 (the
        filters divide by it in float32 on the device).
      origin: (x, y) or (x, y, yaw) of the lower-left corner of cell (0, 0);
        finite, 0 or normal in float32.
      frame_id: non-empty frame name.

    Returns:
      The grid with int8 data and the given float64 resolution and origin.

    Raises:
      ValueError: data not a non-empty 2-D integer array, values outside
        -1..100, a resolution or origin that fails `geometry_values`, or an
        empty / non-string frame_id.
    """
    owner = "OccupancyGrid.create"
    arr = np.asarray(data)
    if arr.ndim != 2 or arr.shape[0] == 0 or arr.shape[1] == 0:
      raise ValueError(f"{owner}: data must be a non-empty 2-D [H, W] array; got shape "
                       f"{arr.shape}")
    if not (np.issubdtype(arr.dtype, np.integer) or arr.dtype == bool):
      raise ValueError(f"{owner}: data must be integers -1..100; got dtype {arr.dtype}")
    if arr.size and (arr.min() < -1 or arr.max() > 100):
      raise ValueError(f"{owner}: data must lie in -1..100; got min {arr.min()} max {arr.max()}")
    res, org = geometry_values(resolution, origin, owner)
    if not isinstance(frame_id, str) or not frame_id:
      raise ValueError(f"{owner}: frame_id must be a non-empty string; got {short_repr(frame_id)}")
    return cls(np.ascontiguousarray(arr, dtype=np.int8), res, org, frame_id)
