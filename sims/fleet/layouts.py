"""Random zone layouts of a scenario, and the bank of them the RL env draws from per episode.

A layout keeps the scenario's static map (walls and shelves) and replaces its
two filter masks: keepout zones and speed zones become axis-aligned rectangles
at random places, of random sizes, the speed zones with random limits. Each
layout is an ordinary `Scenario` (`random_layout`), so everything downstream
(Nav2's filters, `build_world`'s navigation field around the keepout zones,
goal stations, spawn points) treats it like a map loaded from disk.

`layout_bank` builds L layouts once on the host and stacks what the RL env
reads per step: the keepout and speed masks as `FilterMask` stacks of L masks
(the filters pick one with `mask_index`), the L navigation fields and their
stations as one `NavField` of L x S stations (station id = layout * S + s), and
each layout's spawn points. An env carries only its layout index, so a batch
of thousands of envs shares one copy of the bank.

Speed zones are written with Nav2 bringup's percent convention (type 1,
base 100, multiplier -1: limit = 100 - value %), whatever the scenario's own
convention; Nav2 reads a mask value of 0 as "no limit" for any base and
multiplier (docs/nav2_semantics.md §5.3).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from jaxfilters.types import FilterMask, pytree_dataclass
from sims.fleet import navigation
from sims.fleet.config import FleetConfig
from sims.fleet.scenario import Scenario
from sims.fleet.world import World, build_world

_KEEPOUT_VALUE = 100     # occupancy of a keepout cell (lethal in a Nav2 type-0 mask)


@dataclasses.dataclass(frozen=True)
class LayoutConfig:
  """How random layouts are drawn.

  Attributes:
    keepout_zones: (min, max) number of keepout rectangles per layout, inclusive.
    speed_zones: (min, max) number of speed rectangles per layout, inclusive.
    zone_size: (min, max) side length of a rectangle in metres.
    speed_limits: the limits (percent of max speed, in (0, 100)) a speed zone draws from.
    include_scenario: layout 0 of a bank is the scenario's own zones.
  """
  keepout_zones: tuple[int, int] = (1, 4)
  speed_zones: tuple[int, int] = (1, 3)
  zone_size: tuple[float, float] = (1.0, 3.5)
  speed_limits: tuple[float, ...] = (30.0, 40.0, 50.0, 60.0, 70.0)
  include_scenario: bool = True

  def __post_init__(self):
    for name in ("keepout_zones", "speed_zones"):
      lo, hi = getattr(self, name)
      if not (isinstance(lo, int) and isinstance(hi, int)) or not 0 <= lo <= hi <= 32:
        raise ValueError(f"LayoutConfig.{name} must be integers 0 <= min <= max <= 32; got {(lo, hi)!r}")
    lo, hi = self.zone_size
    if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo <= hi):
      raise ValueError(f"LayoutConfig.zone_size must be finite metres 0 < min <= max; got {(lo, hi)!r}")
    lim = np.asarray(self.speed_limits, np.float64)
    if lim.ndim != 1 or lim.size == 0 or not np.all(np.isfinite(lim)) or np.any(lim <= 0) or np.any(lim >= 100) \
        or np.any(lim != np.round(lim)):
      raise ValueError("LayoutConfig.speed_limits must be whole percentages in (0, 100) (a mask value is an "
                       f"integer 100 - limit); got {self.speed_limits!r}")


def _rectangles(rng: np.random.Generator, grid, free: np.ndarray, count: int, size: tuple[float, float]):
  """`count` (row0, row1, col0, col1) cell boxes centred on random free cells of `grid`."""
  rows, cols = np.nonzero(free)
  res = float(grid.resolution)
  h, w = grid.data.shape
  out = []
  for _ in range(count):
    i = int(rng.integers(len(rows)))
    sx, sy = rng.uniform(size[0], size[1], 2)
    hx, hy = max(1, int(round(sx / res / 2))), max(1, int(round(sy / res / 2)))
    r, c = int(rows[i]), int(cols[i])
    out.append((max(0, r - hy), min(h, r + hy), max(0, c - hx), min(w, c + hx)))
  return out


def random_layout(scenario: Scenario, rng: np.random.Generator, config: LayoutConfig = LayoutConfig(), *,
                  name: str | None = None) -> Scenario:
  """The scenario with random keepout and speed zones (see the module docstring).

  Args:
    scenario: the static map and the mask grids (the new masks use the same grids).
    rng: NumPy generator (the layout is a function of its state).
    config: LayoutConfig.
    name: label of the new scenario (default: the scenario's name + "/random").

  Returns:
    A Scenario with the same map and new keepout (trinary, 100 inside zones) and
    speed masks (percent convention: value 100 - limit inside zones, 0 = no limit).
  """
  free = scenario.map.data == 0
  if not np.any(free):
    raise ValueError(f"scenario {scenario.name!r}: the static map has no free cell to place zones on")
  keep = np.zeros_like(scenario.keepout.data, dtype=np.int8)
  n_keep = int(rng.integers(config.keepout_zones[0], config.keepout_zones[1] + 1))
  for r0, r1, c0, c1 in _rectangles(rng, scenario.keepout, _on_grid(free, scenario.map, scenario.keepout),
                                    n_keep, config.zone_size):
    keep[r0:r1, c0:c1] = _KEEPOUT_VALUE
  speed = np.zeros_like(scenario.speed.data, dtype=np.int8)
  n_speed = int(rng.integers(config.speed_zones[0], config.speed_zones[1] + 1))
  for r0, r1, c0, c1 in _rectangles(rng, scenario.speed, _on_grid(free, scenario.map, scenario.speed),
                                    n_speed, config.zone_size):
    limit = float(rng.choice(np.asarray(config.speed_limits)))
    speed[r0:r1, c0:c1] = np.int8(100 - int(limit))
  return dataclasses.replace(
      scenario, name=name or f"{scenario.name}/random",
      keepout=dataclasses.replace(scenario.keepout, data=keep),
      speed=dataclasses.replace(scenario.speed, data=speed),
      speed_type=constants.SPEED_FILTER_PERCENT, speed_base=100.0, speed_multiplier=-1.0)


def _on_grid(free: np.ndarray, src, dst) -> np.ndarray:
  """Free cells of grid `src` resampled onto grid `dst` (nearest cell centre; False off `src`)."""
  h, w = dst.data.shape
  res = float(dst.resolution)
  x = float(dst.origin[0]) + (np.arange(w) + 0.5) * res
  y = float(dst.origin[1]) + (np.arange(h) + 0.5) * res
  c = np.floor((x - float(src.origin[0])) / float(src.resolution)).astype(np.int64)
  r = np.floor((y - float(src.origin[1])) / float(src.resolution)).astype(np.int64)
  okc = (c >= 0) & (c < free.shape[1])
  okr = (r >= 0) & (r < free.shape[0])
  out = free[np.clip(r, 0, free.shape[0] - 1)][:, np.clip(c, 0, free.shape[1] - 1)]
  return out & okr[:, None] & okc[None, :]


@pytree_dataclass
class LayoutBank:
  """L layouts of one map, stacked for per-env indexing (all leaves traced).

  Attributes:
    keepout: FilterMask of L masks (Nav2 type 0).
    speed: FilterMask of L masks.
    nav: NavField of L x S stations: dist float32 [L * S, Hn, Wn], stations float32 [L * S, 2];
      station id = layout * S + s.
    spawns: float32 [L, P, 2], each layout's spawn points (the first spawn_count[l] are valid).
    spawn_count: int32 [L].
  """
  keepout: FilterMask
  speed: FilterMask
  nav: navigation.NavField
  spawns: jax.Array
  spawn_count: jax.Array

  @property
  def num_layouts(self) -> int:
    """L."""
    return int(self.spawn_count.shape[0])

  @property
  def stations_per_layout(self) -> int:
    """S."""
    return int(self.nav.stations.shape[0]) // self.num_layouts


def bank_from_worlds(worlds: list[World]) -> LayoutBank:
  """Stacks the masks, navigation fields and spawns of worlds built on one map.

  Raises:
    ValueError: worlds of different map grids or station counts.
  """
  first = worlds[0].params
  s = first.nav.stations.shape[0]
  for w in worlds[1:]:
    p = w.params
    if p.nav.dist.shape[1:] != first.nav.dist.shape[1:] or p.nav.stations.shape[0] != s \
        or p.keepout.data.shape != first.keepout.data.shape or p.speed.data.shape != first.speed.data.shape:
      raise ValueError("layout_bank: every layout must share the map, mask grids and station count")
  cat = lambda xs: jnp.concatenate(xs, axis=0)
  keepout = jax.tree.map(lambda *xs: cat(xs), *[w.params.keepout for w in worlds])
  speed = jax.tree.map(lambda *xs: cat(xs), *[w.params.speed for w in worlds])
  nav = navigation.NavField(dist=cat([w.params.nav.dist[:s] for w in worlds]), origin=first.nav.origin,
                            resolution=first.nav.resolution,
                            stations=cat([w.params.nav.stations for w in worlds]))
  p_max = max(int(w.params.spawns.shape[0]) for w in worlds)
  spawns = np.zeros((len(worlds), p_max, 2), np.float32)
  counts = np.zeros((len(worlds),), np.int32)
  for i, w in enumerate(worlds):
    sp = np.asarray(w.params.spawns)
    spawns[i, :len(sp)] = sp
    spawns[i, len(sp):] = sp[0]
    counts[i] = len(sp)
  return LayoutBank(keepout=keepout, speed=speed, nav=nav, spawns=jnp.asarray(spawns),
                    spawn_count=jnp.asarray(counts))


def layout_scenarios(scenario: Scenario, count: int, seed: int,
                     config: LayoutConfig = LayoutConfig()) -> list[Scenario]:
  """`count` layouts of the scenario: the scenario itself first (if config.include_scenario), then random ones.

  Raises:
    ValueError: count < 1.
  """
  if isinstance(count, bool) or int(count) != count or count < 1:
    raise ValueError(f"the number of layouts must be an integer >= 1; got {count!r}")
  rng = np.random.default_rng(np.random.SeedSequence([int(seed) & 0xFFFFFFFF, 0x1A7]))
  out = [scenario] if config.include_scenario else []
  while len(out) < count:
    out.append(random_layout(scenario, rng, config, name=f"{scenario.name}/layout{len(out)}"))
  return out


def layout_worlds(scenario: Scenario, fleet_config: FleetConfig, count: int, seed: int,
                  config: LayoutConfig = LayoutConfig()) -> list[World]:
  """Builds the `count` layouts of `layout_scenarios` as Worlds (`build_world`, seed + i for layout i).

  Raises:
    ValueError: count < 1, or a layout whose free space cannot hold the stations or a robot
      (`build_world`'s errors, naming the layout).
  """
  worlds = []
  for i, sc in enumerate(layout_scenarios(scenario, count, seed, config)):
    try:
      worlds.append(build_world(sc, fleet_config, seed=int(seed) + i))
    except ValueError as e:
      raise ValueError(f"layout {i} of {scenario.name!r} (seed {seed}): {e}") from None
  return worlds


def layout_bank(scenario: Scenario, fleet_config: FleetConfig, count: int, seed: int,
                config: LayoutConfig = LayoutConfig()) -> tuple[LayoutBank, list[World]]:
  """Builds `count` layouts (`layout_worlds`) and their stacked bank.

  Args:
    scenario: the map.
    fleet_config: robot size, inflation and navigation grid (as `build_world`).
    count: L >= 1.
    seed: host seed of the layouts (and of each layout's station and spawn choice).
    config: LayoutConfig.

  Returns:
    (LayoutBank, the L Worlds: their scenarios hold the masks, for pictures and reports).

  Raises:
    ValueError: as `layout_worlds`.
  """
  worlds = layout_worlds(scenario, fleet_config, count, seed, config)
  return bank_from_worlds(worlds), worlds


__all__ = ["LayoutBank", "LayoutConfig", "bank_from_worlds", "layout_bank", "layout_scenarios", "layout_worlds", "random_layout"]
