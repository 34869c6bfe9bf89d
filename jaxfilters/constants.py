"""Nav2 cost values, occupancy values, filter type codes and the costmap publisher's value table
(docs/nav2_semantics.md §1)."""

import numpy as np

# Costmap cell values (nav2_costmap_2d/cost_values.hpp), uint8.
FREE_SPACE = 0
MAX_NON_OBSTACLE = 252
INSCRIBED_INFLATED_OBSTACLE = 253
LETHAL_OBSTACLE = 254
NO_INFORMATION = 255

# nav_msgs/OccupancyGrid values, int8.
OCC_GRID_UNKNOWN = -1
OCC_GRID_FREE = 0
OCC_GRID_OCCUPIED = 100

# CostmapFilterInfo.type codes (nav2_util filter_values.hpp).
KEEPOUT_FILTER = 0
SPEED_FILTER_PERCENT = 1
SPEED_FILTER_ABSOLUTE = 2
BINARY_FILTER = 3
ZONE_PARAMETER_FILTER = 4
# Not a Nav2 type: this project's direction (one-way lane) filter takes the next free code
# (docs/nav2_semantics.md §13, jaxfilters/direction.py).
DIRECTION_FILTER = 5
FILTER_TYPES = (KEEPOUT_FILTER, SPEED_FILTER_PERCENT, SPEED_FILTER_ABSOLUTE,
                BINARY_FILTER, ZONE_PARAMETER_FILTER, DIRECTION_FILTER)

BASE_DEFAULT = 0.0
MULTIPLIER_DEFAULT = 1.0
SPEED_MASK_UNKNOWN = -1
SPEED_MASK_NO_LIMIT = 0
NO_SPEED_LIMIT = 0.0


def costmap_to_occupancy(cost) -> np.ndarray:
  """Costmap costs -> the values Nav2's costmap publisher puts in an OccupancyGrid.

  The publisher's `cost_translation_table_` (docs/nav2_semantics.md §1.6):
  0 -> 0, 1..252 -> 1 + (97 * (c - 1)) // 251, 253 -> 99, 254 -> 100, 255 -> -1.

  Args:
    cost: uint8 (or integer) array of costs 0..255.

  Returns:
    int8 array of the same shape, values -1..100.

  Raises:
    ValueError: a non-integer array or values outside 0..255.
  """
  c = np.asarray(cost)
  if c.dtype == bool or not np.issubdtype(c.dtype, np.integer):
    raise ValueError(f"costs must be an integer array; got dtype {c.dtype}")
  if c.size and (c.min() < 0 or c.max() > 255):
    raise ValueError(f"costs must be 0..255; got {int(c.min())}..{int(c.max())}")
  return _COST_TRANSLATION[c.astype(np.intp)]


def _translation_table() -> np.ndarray:
  table = np.empty(256, np.int8)
  table[0] = 0
  table[1:253] = 1 + (97 * (np.arange(1, 253) - 1)) // 251
  table[253], table[254], table[255] = 99, 100, -1
  return table


_COST_TRANSLATION = _translation_table()
