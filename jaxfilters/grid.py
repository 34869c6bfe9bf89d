"""Host-side occupancy grid: what map_server loads and filter masks are built from."""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True, eq=False)
class OccupancyGrid:
  """A nav_msgs/OccupancyGrid held on the host.

  Attributes:
    data: int8 [H, W], values -1 (unknown) and 0..100. Row 0 is the lowest y
      (the bottom row of the image), as in nav_msgs/OccupancyGrid.
    resolution: metres per cell (nav_msgs stores it as float32).
    origin: (x, y, yaw) of the lower-left corner of cell (0, 0). Nav2 ignores
      the yaw everywhere (spec §2.1); it is kept for saving.
    frame_id: the frame the grid lives in ("map" as map_server loads it).
  """
  data: np.ndarray
  resolution: float
  origin: tuple[float, float, float]
  frame_id: str = "map"

  @property
  def width(self) -> int:
    return int(self.data.shape[1])

  @property
  def height(self) -> int:
    return int(self.data.shape[0])

  @classmethod
  def create(cls, data, resolution: float, origin=(0.0, 0.0, 0.0),
             frame_id: str = "map") -> "OccupancyGrid":
    """Validates and builds a grid.

    Raises:
      ValueError: data not 2-D, values outside -1..100, resolution not > 0,
        origin not 2 or 3 numbers.
    """
    arr = np.asarray(data)
    if arr.ndim != 2 or arr.shape[0] == 0 or arr.shape[1] == 0:
      raise ValueError(f"OccupancyGrid data must be a non-empty 2-D [H, W] array; got shape {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.integer) or arr.dtype == bool):
      raise ValueError(f"OccupancyGrid data must be integers -1..100; got dtype {arr.dtype}")
    if arr.size and (arr.min() < -1 or arr.max() > 100):
      raise ValueError(f"OccupancyGrid data must lie in -1..100; got min {arr.min()} max {arr.max()}")
    res = float(resolution)
    if not np.isfinite(res) or res <= 0:
      raise ValueError(f"resolution must be a finite number > 0; got {resolution!r}")
    org = tuple(float(v) for v in origin)
    if len(org) == 2:
      org = (*org, 0.0)
    if len(org) != 3 or not all(np.isfinite(org)):
      raise ValueError(f"origin must be (x, y) or (x, y, yaw) finite numbers; got {origin!r}")
    return cls(np.ascontiguousarray(arr, dtype=np.int8), res, org, frame_id)
