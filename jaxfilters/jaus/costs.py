"""Occupancy <-> Nav2 cost <-> run-length level: the cell-value mappings of the JAUS codec.

`mapping` (docs/jaus.md §11 (11)):
  "nav2" (default)  occupancy d -> cost round_half_up(2.54 d) (Nav2's mask
                    cost, 0..254), -1 -> 255; back: round_half_up(c / 2.54),
                    an exact inverse on every cost the forward map makes.
  "fkie"            the fkie ROS/IOP bridge: cost = 2 d (0..200), -1 -> 255;
                    back: c // 2, 255 -> -1 (a cost 201..254 is refused).
Run-length levels keep 3 bits of cost with the class-keeping map of
docs/jaus.md §4 (free stays free, lethal stays lethal).
"""

from __future__ import annotations

import numpy as np

from jaxfilters import constants
from jaxfilters.jaus.messages import RLE_LEVEL_COST, apply_lut, check_choice
from jaxfilters.validate import int_values

# Occupancy -> cost mappings.
MAPPINGS = ("nav2", "fkie")
# cost -> occupancy tables (index = cost 0..255): round_half_up(c * 100 / 254) and c // 2,
# 255 -> -1; _REFUSED marks the costs 201..254 the fkie mapping cannot turn into occupancy.
_REFUSED = -2
_NAV2_OCC = np.array([(c * 200 + 254) // 508 for c in range(255)] + [-1], np.int8)
_FKIE_OCC = np.array([c // 2 if c <= 200 else _REFUSED for c in range(255)] + [-1], np.int8)


def occupancy_to_cost(occupancy, *, mapping: str = "nav2") -> np.ndarray:
  """OccupancyGrid values -> Nav2 costs (see `jaxfilters.jaus.costs` for `mapping`).

  Args:
    occupancy: integer array of values -1..100.
    mapping: "nav2" (round_half_up(2.54 d)) or "fkie" (2 d).

  Returns:
    uint8 array of the same shape: 0..254 ("nav2") or 0..200 ("fkie"), 255 unknown.

  Raises:
    ValueError: non-integer values or values outside -1..100; unknown mapping.
  """
  check_choice("mapping", mapping, MAPPINGS)
  d = int_values(occupancy, "occupancy", lo=-1, hi=100).astype(np.int32)
  cost = (d * 254 + 50) // 100 if mapping == "nav2" else 2 * d
  return np.where(d < 0, constants.NO_INFORMATION, cost).astype(np.uint8)


def cost_to_occupancy(cost, *, mapping: str = "nav2") -> np.ndarray:
  """Nav2 costs -> OccupancyGrid values (inverse of `occupancy_to_cost`).

  "nav2": round_half_up(c * 100 / 254), which gives back d for every cost
  `occupancy_to_cost` makes and the nearest occupancy for the others
  (253 -> 100); "fkie": c // 2. 255 -> -1 in both.

  Args:
    cost: integer array of costs 0..255.
    mapping: "nav2" or "fkie".

  Returns:
    int8 array of the same shape, values -1..100.

  Raises:
    ValueError: values outside 0..255, or ("fkie") a cost 201..254, which the
      fkie client would turn into an occupancy above 100.
  """
  check_choice("mapping", mapping, MAPPINGS)
  c = int_values(cost, "cost", lo=0, hi=255)
  occ = apply_lut(_NAV2_OCC if mapping == "nav2" else _FKIE_OCC, c)
  if mapping == "fkie":
    bad = occ == _REFUSED
    if bad.any():
      raise ValueError(f"the fkie mapping covers costs 0..200 (occupancy * 2) and 255; got cost "
                       f"{int(c[bad].flat[0])} ({int(bad.sum())} cells); use mapping='nav2'")
  return occ


def cost_to_rle_level(cost) -> np.ndarray:
  """Nav2 cost 0..254 -> the 3-bit run-length cost level 0..7, keeping each class.

  0 -> 0 (free), 254 -> 7 (non-traversable), 1..253 -> 1 + (c - 1) * 6 // 253
  (1..6), so no cost in between becomes free or lethal. Unknown (255) is
  carried by the certainty bit, not by a level.

  Raises:
    ValueError: values outside 0..254.
  """
  c = int_values(cost, "cost", lo=0, hi=254).astype(np.int32)
  level = np.where(c == 0, 0, np.where(c >= constants.LETHAL_OBSTACLE, 7, 1 + (c - 1) * 6 // 253))
  return level.astype(np.uint8)


def rle_level_to_cost(level) -> np.ndarray:
  """3-bit run-length level 0..7 -> Nav2 cost round(level * 254 / 7): 0, 36, ..., 218, 254.

  Raises:
    ValueError: values outside 0..7.
  """
  return RLE_LEVEL_COST[int_values(level, "rle level", lo=0, hi=7)]
