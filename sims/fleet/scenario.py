"""Scenarios: a static map plus keepout and speed masks, loaded as Nav2's map_server would.

`Scenario.default()` is the built-in warehouse shipped in sims/assets (written
by sims/make_default_scenario.py); `Scenario.load(...)` takes any three Nav2
map YAMLs, e.g. Nav2's own warehouse:

    Scenario.load("warehouse.yaml", "warehouse_keepout.yaml", "warehouse_speed.yaml")

Filter info follows Nav2's bringup (`nav2_params.yaml`): keepout type 0 with
base 0 and multiplier 1; speed type 1 (percent) with base 100 and multiplier
-1, so a mask value d limits speed to 100 - d percent.

A Scenario built from a Nav2 params file (`jaxfilters fleet --params`) also
carries the inflation layers its local costmap lists under `plugins:`
(`Scenario.layers`); the fleet's local costmaps then run them
(sims/fleet/world.py `local_layers`).
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np

from jaxfilters import constants
from jaxfilters.grid import OccupancyGrid
from jaxfilters.map_io import load_map
from jaxfilters.nav2 import Nav2InflationLayer

ASSETS = Path(__file__).resolve().parents[1] / "assets"
DEFAULT_FILES = tuple(ASSETS / f"default_{n}.yaml" for n in ("map", "keepout", "speed"))


@dataclasses.dataclass(frozen=True, eq=False)
class Scenario:
  """Host-side maps of one warehouse.

  Attributes:
    name: a label for reports.
    map: the static map (OccupancyGrid, int8 [H, W]).
    keepout: the keepout mask (Nav2 type 0).
    speed: the speed mask.
    speed_type: 1 (percent of max speed) or 2 (absolute m/s).
    speed_base, speed_multiplier: limit = d * multiplier + base (float32 in Nav2).
    layers: the local costmap's inflation layers from a params file, in its
      `plugins:` order (`Nav2Costmap.layers`); empty: the fleet's own inflation
      (FleetConfig.inflation_radius, cost_scaling_factor, the robot's footprint).
    direction: optional one-way-lane mask (`jaxfilters.direction`, FilterInfo
      type 5; load it with `jaxfilters.map_io.load_map`, mode raw); None (the
      default): no lanes, and the fleet does no direction work at all.
    direction_base, direction_multiplier: lane direction in degrees = d *
      multiplier + base (defaults: d = 1 east, 19 north, 37 west, 55 south).
  """
  name: str
  map: OccupancyGrid
  keepout: OccupancyGrid
  speed: OccupancyGrid
  speed_type: int = constants.SPEED_FILTER_PERCENT
  speed_base: float = 100.0
  speed_multiplier: float = -1.0
  layers: tuple[Nav2InflationLayer, ...] = ()
  direction: OccupancyGrid | None = None
  direction_base: float = -5.0
  direction_multiplier: float = 5.0

  def __post_init__(self):
    if not isinstance(self.layers, tuple) or not all(isinstance(x, Nav2InflationLayer) for x in self.layers):
      raise ValueError("Scenario.layers must be a tuple of Nav2InflationLayer (Nav2Costmap.layers); got "
                       f"{type(self.layers).__name__}")
    for field in ("map", "keepout", "speed"):
      if not isinstance(getattr(self, field), OccupancyGrid):
        raise ValueError(f"Scenario.{field} must be an OccupancyGrid; got {type(getattr(self, field)).__name__}")
    if self.speed_type not in (constants.SPEED_FILTER_PERCENT, constants.SPEED_FILTER_ABSOLUTE):
      raise ValueError(f"Scenario.speed_type must be 1 (percent) or 2 (absolute m/s); got {self.speed_type!r}")
    if self.direction is not None and not isinstance(self.direction, OccupancyGrid):
      raise ValueError(f"Scenario.direction must be an OccupancyGrid or None; got {type(self.direction).__name__}")
    for name in ("speed_base", "speed_multiplier", "direction_base", "direction_multiplier"):
      if not np.isfinite(float(getattr(self, name))):
        raise ValueError(f"Scenario.{name} must be finite; got {getattr(self, name)!r}")

  @classmethod
  def load(cls, map_yaml: str | os.PathLike, keepout_yaml: str | os.PathLike,
           speed_yaml: str | os.PathLike, *, speed_type: int = constants.SPEED_FILTER_PERCENT,
           speed_base: float = 100.0, speed_multiplier: float = -1.0,
           name: str | None = None, layers: tuple[Nav2InflationLayer, ...] = (),
           direction_yaml: str | os.PathLike | None = None,
           direction_base: float = -5.0, direction_multiplier: float = 5.0) -> "Scenario":
    """Loads three Nav2 map YAMLs with `jaxfilters.map_io.load_map`.

    Args:
      map_yaml, keepout_yaml, speed_yaml: map_server YAML files of the static
        map, the keepout mask (Nav2 type 0) and the speed mask.
      speed_type: 1 (percent of max speed) or 2 (m/s).
      speed_base, speed_multiplier: limit = d * multiplier + base (Nav2's
        CostmapFilterInfo; the defaults are Nav2 bringup's).
      name: label for reports (default: the map YAML's stem).
      layers: the local costmap's inflation layers (see the class).
      direction_yaml: optional map_server YAML of a one-way-lane mask
        (`jaxfilters.direction`; `mode: raw`, so a pixel byte is the cell value).
      direction_base, direction_multiplier: lane direction in degrees =
        d * multiplier + base (see the class).

    Returns:
      The Scenario.

    Raises:
      FileNotFoundError: a missing YAML or image.
      ValueError: a malformed map (see load_map) or bad speed info.
    """
    return cls(name=name or Path(map_yaml).stem, map=load_map(map_yaml), keepout=load_map(keepout_yaml),
               speed=load_map(speed_yaml), speed_type=int(speed_type), speed_base=float(speed_base),
               speed_multiplier=float(speed_multiplier), layers=tuple(layers),
               direction=None if direction_yaml is None else load_map(direction_yaml),
               direction_base=float(direction_base), direction_multiplier=float(direction_multiplier))

  @classmethod
  def default(cls) -> "Scenario":
    """The built-in 30 m x 20 m warehouse (sims/assets/default_*.yaml)."""
    return cls.load(*DEFAULT_FILES, name="default_warehouse")


def speed_limit_host(d: int, speed_type: int, base: float, multiplier: float) -> tuple[float, bool]:
  """Nav2 getSpeedLimitAtPose for one raw mask value, in float64 (docs/nav2_semantics.md §5.3).

  Base and multiplier are rounded to float32 first, as CostmapFilterInfo carries them.

  Args:
    d: raw mask value (-1..100).
    speed_type: 1 (percent) or 2 (m/s).
    base, multiplier: the filter info's base and multiplier.

  Returns:
    (limit, valid): 0.0 means no limit; invalid for d == -1.
  """
  if d == constants.SPEED_MASK_UNKNOWN:
    return 0.0, False
  if d == constants.SPEED_MASK_NO_LIMIT:
    return 0.0, True
  limit = d * float(np.float32(multiplier)) + float(np.float32(base))
  if limit < 0 or (speed_type == constants.SPEED_FILTER_PERCENT and limit > 100):
    limit = 0.0
  return float(np.float32(limit)), True
