"""Shared world data: the global costmap, navigation field, stations and zone tables.

`build_world(scenario, config)` does the once-per-scenario work:

1. global costmap = static layer -> keepout filter -> inflation, all with
   jaxfilters. The keepout is applied *before* inflation (as Nav2 users do who
   list the keepout filter under `plugins:`), so keepout zones are inflated and
   no global route passes next to one;
2. a coarser navigation grid (`navigation.pool_costmap`) keeps every
   keepout, obstacle, inscribed and unknown cell blocked;
3. goal stations (far from obstacles, in the largest connected free region,
   spread by farthest-point sampling) and spawn points (free cells, `spawn_spacing` apart);
4. the navigation field of every station (`navigation.distance_field`);
5. a speed-zone table: zone 0 is "no limit" (mask value 0, off-mask or
   unknown), zones 1..Z-1 are the distinct limits of the speed mask;
6. with keepout escape (`FleetConfig.keepout_escape`): the local keepout
   config (`keepout_config`), the exit field (`navigation.exit_field`, the
   shortest way out of every zone, crossing zones but not walls) and, for
   `robots_in_keepout`, spawn points whose footprint is on a lethal keepout
   cell (`zone_spawns`).

The device part, `WorldParams`, is one pytree shared (not batched) by every
world and robot; nothing in it is per robot, so its size does not grow with B.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from jaxfilters.asymmetric_inflation import AsymmetricInflationConfig
from jaxfilters.footprint import band_clearance, footprint_in_zone_one, window_cells
from jaxfilters.inflation import InflationConfig, inflate
from jaxfilters.keepout import KeepoutConfig, KeepoutState, keepout_filter
from jaxfilters.static_layer import StaticLayerConfig, static_layer
from jaxfilters.types import Costmap, FilterInfo, FilterMask, pytree_dataclass
from sims.fleet import local_costmap, navigation
from sims.fleet.config import FleetConfig
from sims.fleet.scenario import Scenario, speed_limit_host

STATIC_LAYER = StaticLayerConfig(track_unknown_space=True)
SPAWN_SPACING = 0.8  # m, robots start at least this far apart (2 * 0.22 m radius + margin) ...
SPAWN_GAP = 0.1      # m, ... or, for a larger robot, two radii and this gap apart (`spawn_spacing`)
MAX_SPAWNS = 4096    # spawn points kept per map (robots sample without replacement)


@pytree_dataclass
class WorldParams:
  """Device data every world shares (closed over by the env, passed to jit as an argument).

  Attributes:
    static_cost: uint8 [H + 2P, W + 2P], the static layer padded by P cells of
      NO_INFORMATION, so a rolling window is a plain dynamic slice.
    map_origin: float32 [2], origin of the unpadded static map.
    map_resolution: float32 [], static map (and local costmap) resolution.
    keepout: FilterMask (M = 1), Nav2 type 0.
    speed: FilterMask (M = 1), type 1 or 2.
    zone_table: int32 [256], zone id by speed-mask byte (int8 value read as uint8).
    zone_speed: float32 [Z], speed limit of each zone in m/s (+inf: no limit).
    speed_cap: float32 [Hs, Ws], on the speed mask's grid: the strictest
      speed-mask limit (m/s; +inf none or unknown) of each cell and its 8
      neighbours. The per-cell limit is what `jaxfilters.speed.speed_limit_at_one`
      returns at the cell (Nav2's rule, converted to m/s once); the one-cell
      dilation makes the planner's sampled lookahead conservative, so a rollout
      sampled every half cell cannot clip a zone corner between two samples.
    nav: NavField with S stations (and the exit field as dist[S] with keepout escape).
    spawns: float32 [P, 2], spawn points.
    zone_spawns: float32 [Q, 2], spawn points whose footprint (a disc of the
      robot radius) covers a lethal keepout cell, clear of the walls'
      inscribed band, with a way out (Q = 0 unless robots_in_keepout > 0).
    direction: FilterMask (M = 1) of type 5, the one-way lanes
      (`jaxfilters.direction`), or None (Scenario.direction None: no lanes).
    honour_lanes: bool [] (FleetConfig.honour_lanes) with a direction mask,
      else None: data, not a static option, so the honoured run and its
      measured baseline run one compiled program.
  """
  static_cost: jax.Array
  map_origin: jax.Array
  map_resolution: jax.Array
  keepout: FilterMask
  speed: FilterMask
  zone_table: jax.Array
  zone_speed: jax.Array
  speed_cap: jax.Array
  nav: navigation.NavField
  spawns: jax.Array
  zone_spawns: jax.Array
  direction: FilterMask | None = None
  honour_lanes: jax.Array | None = None


@dataclasses.dataclass(frozen=True, eq=False)
class World:
  """Host view of a built world (what reports and plots need) plus its WorldParams.

  Attributes:
    scenario, config: what it was built from.
    params: the device pytree.
    global_cost: uint8 [H, W], static + keepout + inflation.
    inflation: InflationConfig of both costmaps.
    window_cells: N, the local costmap is N x N cells at the map resolution.
    pad: P, padding of params.static_cost.
    nav_factor: map cells per navigation cell.
    zone_labels: one label per zone ("none", "50%", "0.3 m/s").
    zone_limits: raw limit per zone (percent or m/s; 0.0 for zone 0).
    zone_speed: m/s per zone (inf for zone 0).
    stations: float [S, 2]; spawns: float [P, 2].
    keepout_config: the local costmaps' KeepoutConfig with keepout escape
      (None: the filter after inflation, as Nav2 places filters).
    zone_spawns: float [Q, 2] (see WorldParams).
    local_layers: the local costmaps' inflation layers from the scenario's params
      (`local_layers`); empty: `(inflation,)`.
    plan_points: P, the points of each robot's plan (`navigation.trace_plan`,
      one per navigation cell) when an AsymmetricInflationLayer is configured; 0 otherwise.
    keepout_grid: the keepout mask on the map's grid (`local_costmap.keepout_grid`): the local
      costmaps read its cells as integers (`local_costmap.grid_keepout`); None: `keepout_filter`.
  """
  scenario: Scenario
  config: FleetConfig
  params: WorldParams
  global_cost: np.ndarray
  inflation: InflationConfig
  window_cells: int
  pad: int
  nav_factor: int
  zone_labels: tuple[str, ...]
  zone_limits: tuple[float, ...]
  zone_speed: tuple[float, ...]
  stations: np.ndarray
  spawns: np.ndarray
  keepout_config: KeepoutConfig | None = None
  zone_spawns: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 2), np.float32))
  local_layers: tuple[InflationConfig | AsymmetricInflationConfig, ...] = ()
  plan_points: int = 0
  keepout_grid: local_costmap.KeepoutGrid | None = None

  @property
  def local_inflation_layers(self) -> tuple[InflationConfig | AsymmetricInflationConfig, ...]:
    """The inflation layers the local costmaps run, in order: `local_layers`, else `(inflation,)`."""
    return self.local_layers or (self.inflation,)

  @property
  def plans_needed(self) -> bool:
    """Whether the local costmaps run an AsymmetricInflationLayer (each robot's plan is then traced)."""
    return any(isinstance(x, AsymmetricInflationConfig) for x in self.local_layers)

  @property
  def plan_step(self) -> float:
    """Metres between the points of a robot's plan: one navigation cell."""
    return self.nav_factor * float(self.scenario.map.resolution)

  @property
  def num_zones(self) -> int:
    """Z, speed zones including zone 0 (no limit)."""
    return len(self.zone_labels)


def spawn_spacing(config: FleetConfig) -> float:
  """Metres between spawn points: SPAWN_SPACING, or 2 * radius + SPAWN_GAP for a robot too large for it."""
  return max(SPAWN_SPACING, 2 * config.robot.radius + SPAWN_GAP)


def keepout_inscribed_radius(resolution: float, config: FleetConfig) -> float:
  """The inscribed radius (m) at which a robot centre outside 253 cells keeps its footprint off zones.

  The planner checks the cell under each rollout point (every max_speed * rollout_dt / 2
  metres), so a point on a cell below 253 is farther than inscribed - resolution / sqrt 2
  from every lethal cell centre, and the path between two points within a quarter of the
  spacing more; 1 cm more covers tracking. Then the footprint disc (the robot radius)
  covers no lethal cell centre: no footprint entry.
  """
  p, r = config.planner, config.robot
  return r.radius + resolution * math.sqrt(0.5) + r.max_speed * p.rollout_dt / 4 + 0.01


def inflation_config(resolution: float, config: FleetConfig) -> InflationConfig:
  """The InflationConfig of both costmaps: the robot's footprint and the fleet's inflation settings.

  With keepout escape the inscribed radius is at least `keepout_inscribed_radius` (as Nav2's
  `custom_inscribed_radius` would set it), so keepout zones run as a layer keep the
  footprint, not just the centre, out.

  Args:
    resolution: metres per costmap cell.
    config: the fleet config (robot radius and footprint padding, inflation radius, cost scaling).

  Returns:
    An InflationConfig for `jaxfilters.inflation.inflate`.
  """
  infl = InflationConfig.from_footprint(
      resolution=resolution, robot_radius=config.robot.radius,
      footprint_padding=config.robot.footprint_padding, inflation_radius=config.inflation_radius,
      cost_scaling_factor=config.cost_scaling_factor)
  if config.keepout_escape == "off":
    return infl
  return dataclasses.replace(infl, inscribed_radius=max(infl.inscribed_radius,
                                                        keepout_inscribed_radius(resolution, config)))


def local_layers(scenario: Scenario, resolution: float, config: FleetConfig
                 ) -> tuple[InflationConfig | AsymmetricInflationConfig, ...]:
  """The local costmaps' inflation layers from the scenario's params (`Scenario.layers`), in order.

  Each layer's config as the params file gives it (its parameters, the footprint's
  inscribed radius), at the map's resolution: the local costmap is a window of the
  static map.

  Args:
    scenario: the maps, with the params' local costmap layers (empty: none).
    resolution: the static map's metres per cell.
    config: the fleet config.

  Returns:
    The configs, empty when the scenario has no layers.

  Raises:
    ValueError: a layer whose resolution (the params' local costmap `resolution`,
      Nav2's default 0.1 when unset) is not the map's, or layers with keepout
      escape (which sets the local inflation's inscribed radius itself).
  """
  if not scenario.layers:
    return ()
  if config.keepout_escape != "off":
    raise ValueError("keepout escape (FleetConfig.keepout_escape) raises the local inflation's inscribed radius "
                     "itself; it does not run with a params file's local costmap inflation layers "
                     f"({', '.join(x.name for x in scenario.layers)})")
  out = []
  for layer in scenario.layers:
    if np.float32(layer.config.resolution) != np.float32(resolution):
      raise ValueError(f"the local costmap's layer '{layer.name}' is at resolution {layer.config.resolution} m "
                       f"(the params' local_costmap resolution; Nav2's default 0.1 when unset) but the fleet's "
                       f"local costmap is a window of the map at {resolution} m: set local_costmap "
                       f"resolution: {resolution}")
    out.append(dataclasses.replace(layer.config, resolution=resolution))
  return tuple(out)


def local_keepout_config(resolution: float, config: FleetConfig, infl: InflationConfig) -> KeepoutConfig | None:
  """The local costmaps' KeepoutConfig for `config.keepout_escape` (None for 'off').

  'center' is Nav2's escape mode (`override_lethal_cost`, lethal_override_cost 252);
  'footprint' adds the footprint test with the robot's disc and `band_clearance`, so escape
  ends only once the robot's centre cell is outside the zone's inscribed band.
  """
  if config.keepout_escape == "off":
    return None
  if config.keepout_escape == "center":
    return KeepoutConfig(override_lethal_cost=True)
  r = config.robot.radius
  return KeepoutConfig(override_lethal_cost=True, robot_in_zone="footprint", robot_radius=r,
                       min_mask_resolution=resolution,
                       escape_clearance=band_clearance(inscribed_radius=infl.inscribed_radius,
                                                       resolution=resolution, robot_radius=r))


@functools.partial(jax.jit, static_argnames=("infl", "with_keepout"))
def _global_costmap(data, origin, resolution, keepout: FilterMask, *, infl: InflationConfig,
                    with_keepout: bool = True):
  static = static_layer(data[None], config=STATIC_LAYER)
  cm = Costmap(static, origin[None], resolution[None])
  if with_keepout:
    cm, _ = keepout_filter(cm, keepout, jnp.zeros((1, 3), jnp.float32), KeepoutState.create(1))
  return inflate(cm.cost, config=infl)[0]


def global_costmap(scenario: Scenario, keepout: FilterMask, infl: InflationConfig, *,
                   with_keepout: bool = True) -> np.ndarray:
  """Static layer, then the keepout filter as a plugin, then inflation.

  Args:
    scenario: the maps (the static map's grid is the costmap's).
    keepout: FilterMask (M = 1) of the keepout filter.
    infl: InflationConfig at the map resolution.
    with_keepout: False leaves the keepout filter out (walls only: where a
      robot may stand inside a zone).

  Returns:
    uint8 [H, W] global costmap (Nav2 cost values).
  """
  grid = scenario.map
  return np.asarray(_global_costmap(jnp.asarray(grid.data), jnp.asarray(np.float32(grid.origin[:2])),
                                    jnp.asarray(np.float32(grid.resolution)), keepout, infl=infl,
                                    with_keepout=with_keepout))


@functools.partial(jax.jit, static_argnames=("radius", "window"))
def _footprint_on_zone(data, origin, res, xy, origin_lo, *, radius: float, window: int):
  one = lambda q: footprint_in_zone_one(data, origin, res, jnp.stack([q[0], q[1], jnp.float32(0.0)]),
                                        radius=radius, window=window, mask_origin_lo=origin_lo)
  return jax.lax.map(one, xy, batch_size=4096)


def zone_tables(scenario: Scenario, max_speed: float):
  """Zones of the speed mask: (table [256], labels, raw limits, m/s)."""
  values = np.unique(scenario.speed.data.astype(np.int32))
  limits = {}
  for d in values:
    lim, valid = speed_limit_host(int(d), scenario.speed_type, scenario.speed_base,
                                  scenario.speed_multiplier)
    limits[int(d)] = lim if valid else 0.0
  distinct = sorted({v for v in limits.values() if v != 0.0}, reverse=True)
  percent = scenario.speed_type == constants.SPEED_FILTER_PERCENT
  table = np.zeros(256, np.int32)
  for d, lim in limits.items():
    table[d & 0xFF] = 0 if lim == 0.0 else 1 + distinct.index(lim)
  labels = ("none",) + tuple(f"{v:g}%" if percent else f"{v:g} m/s" for v in distinct)
  speeds = (np.inf,) + tuple(max_speed * v / 100.0 if percent else v for v in distinct)
  return table, labels, (0.0,) + tuple(distinct), speeds


def dilate_min(a: np.ndarray) -> np.ndarray:
  """Minimum over each cell's 3 x 3 neighbourhood (edges replicate), host NumPy.

  Args:
    a: [H, W] array (e.g. float32 m/s caps).

  Returns:
    [H, W] array of a's dtype.
  """
  p = np.pad(a, 1, mode="edge")
  h, w = a.shape
  return np.min([p[i:i + h, j:j + w] for i in range(3) for j in range(3)], axis=0)


def spaced_points(pts: np.ndarray, chosen: np.ndarray, spacing: float = SPAWN_SPACING,
                  limit: int = MAX_SPAWNS) -> np.ndarray:
  """Greedy spacing: `chosen` followed by each point of `pts` (in order) at least `spacing` from all kept.

  A point is kept when its squared distance to every kept point is >= spacing ** 2 (float64),
  until `limit` points are kept. Each kept point strikes out the later candidates closer than
  `spacing` to it at once (one vectorised pass per kept point, not one per candidate), so the
  next kept point is the first candidate not struck out: the same points as the greedy loop.

  Args:
    pts: float64 [N, 2] candidates in the order they are tried.
    chosen: float64 [K, 2] points already kept (K may be 0).
    spacing: metres.
    limit: most points returned.

  Returns:
    float64 [K + k, 2]: `chosen`, then the k kept candidates in order.
  """
  pts = np.asarray(pts, np.float64).reshape(-1, 2)
  chosen = np.asarray(chosen, np.float64).reshape(-1, 2)
  s2 = spacing ** 2
  x, y = np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1])
  alive = np.ones(len(pts), bool)
  for qx, qy in chosen:
    alive &= (x - qx) ** 2 + (y - qy) ** 2 >= s2
  kept = [chosen]
  count, i = len(chosen), 0
  while count < limit:
    rest = np.flatnonzero(alive[i:])
    if len(rest) == 0:
      break
    i += int(rest[0])
    p = pts[i]
    kept.append(p[None])
    count += 1
    i += 1
    alive[i:] &= (x[i:] - p[0]) ** 2 + (y[i:] - p[1]) ** 2 >= s2
  return np.concatenate(kept)


def _farthest_points(xy: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
  """Indices of k points of xy [N, 2] spread by farthest-point sampling."""
  chosen = [int(rng.integers(len(xy)))]
  d = np.linalg.norm(xy - xy[chosen[0]], axis=1)
  for _ in range(1, k):
    i = int(np.argmax(d))
    chosen.append(i)
    d = np.minimum(d, np.linalg.norm(xy - xy[i], axis=1))
  return np.asarray(chosen)


def build_world(scenario: Scenario, config: FleetConfig, *, seed: int = 0) -> World:
  """Builds the shared world data for a scenario and fleet config.

  Args:
    scenario: the maps.
    config: the fleet config (robot size, inflation, navigation grid, stations).
    seed: host seed for station and spawn selection (deterministic).

  Returns:
    World with its WorldParams.

  Raises:
    ValueError: masks whose resolution differs from the map's, too little free
      space for the stations, or fewer spawn points than robots per world.
  """
  grid = scenario.map
  res = float(grid.resolution)
  for name, mask in (("keepout", scenario.keepout), ("speed", scenario.speed)):
    if not np.isclose(mask.resolution, res):
      raise ValueError(f"the {name} mask resolution ({mask.resolution}) must equal the map "
                       f"resolution ({res}): the planner samples masks at half-cell spacing")
  infl = inflation_config(res, config)
  layers = local_layers(scenario, res, config)
  keepout = FilterMask.create(scenario.keepout, FilterInfo.create(constants.KEEPOUT_FILTER))
  speed = FilterMask.create(scenario.speed, FilterInfo.create(
      scenario.speed_type, scenario.speed_base, scenario.speed_multiplier))
  cost = global_costmap(scenario, keepout, infl)

  # Navigation grid.
  factor = max(1, int(round(config.nav_resolution / res)))
  blocked, weight = navigation.pool_costmap(cost, factor)
  nav_res = factor * res
  weight_m = np.where(blocked, np.inf, weight * np.float32(nav_res)).astype(np.float32)
  ox, oy = float(grid.origin[0]), float(grid.origin[1])
  # Station and spawn candidates: coarse cells whose fine cells are all cost 0 (clear of
  # the inflation radius around obstacles and keepout zones).
  # A map whose free space runs to its edge (Nav2's warehouse) has no wall there, but a robot
  # cannot leave the map: cells closer to the edge than the inflation radius host no station or
  # spawn point.
  hn, wn = blocked.shape
  cx = (np.arange(wn) + 0.5) * nav_res
  cy = (np.arange(hn) + 0.5) * nav_res
  width, height = grid.data.shape[1] * res, grid.data.shape[0] * res
  inside = (np.minimum(cy, height - cy)[:, None] >= config.inflation_radius) & \
      (np.minimum(cx, width - cx)[None, :] >= config.inflation_radius)
  clear = (~blocked) & (weight == 1.0) & inside
  cr, cc = np.nonzero(clear)
  if len(cr) < config.num_stations:
    raise ValueError(f"the map has {len(cr)} clear navigation cells; need at least "
                     f"num_stations = {config.num_stations}")
  rng = np.random.default_rng(seed)
  # Largest connected region: the seed that reaches the most clear cells (num_stations
  # seeds, so this and the final field share one compiled shape).
  seeds = rng.choice(len(cr), size=config.num_stations, replace=False)
  reach = np.isfinite(np.asarray(navigation.distance_field(
      jnp.asarray(weight_m), jnp.asarray(cr[seeds], jnp.int32), jnp.asarray(cc[seeds], jnp.int32))))
  best = int(np.argmax([reach[i][cr, cc].sum() for i in range(len(seeds))]))
  ok = reach[best][cr, cc]
  cr, cc = cr[ok], cc[ok]
  centres = np.stack([ox + (cc + 0.5) * nav_res, oy + (cr + 0.5) * nav_res], axis=1)
  if len(cr) < config.num_stations:
    raise ValueError(f"the largest free region has {len(cr)} clear cells; need num_stations = "
                     f"{config.num_stations}")
  pick = _farthest_points(centres, config.num_stations, rng)
  stations = centres[pick].astype(np.float32)
  dist = navigation.distance_field(jnp.asarray(weight_m), jnp.asarray(cr[pick], jnp.int32),
                                   jnp.asarray(cc[pick], jnp.int32))
  # Spawn points: reachable navigation cells, at least SPAWN_SPACING apart, picked greedily in a
  # seeded random order from the cells clear of the whole inflation radius (cost 0) first; only
  # when those cannot host robots_per_world robots are other free cells (cost below inscribed,
  # so a robot there is clear of obstacles and keepout) added. Nav2's small tb3_sandbox has
  # free space but little of it clear of the whole inflation radius.
  reachable = np.isfinite(reach[best])
  spacing = spawn_spacing(config)

  def spaced(pts, chosen):
    return spaced_points(pts[rng.permutation(len(pts))], chosen, spacing)

  def pick(cells, chosen):
    r, c = np.nonzero(cells)
    return spaced(np.stack([ox + (c + 0.5) * nav_res, oy + (r + 0.5) * nav_res], axis=1), chosen)

  keepout_cfg = local_keepout_config(res, config, infl)
  zone_spawns = np.zeros((0, 2), np.float32)
  if keepout_cfg is not None:
    # Exit field: through zones (walls only block), to the nearest cell of the main free region that
    # is outside every zone and its inscribed band.
    walls = global_costmap(scenario, keepout, infl, with_keepout=False)
    wall_blocked, wall_weight = navigation.pool_costmap(walls, factor)
    exit_weight = np.where(wall_blocked, np.inf, wall_weight * np.float32(nav_res)).astype(np.float32)
    exit_dist = navigation.exit_field(jnp.asarray(exit_weight), jnp.asarray(~blocked & reachable))
    dist = jnp.concatenate([dist, exit_dist])
    if config.robots_in_keepout:
      zone_spawns = _zone_spawns(grid, keepout, walls, np.asarray(exit_dist[0]), factor, config, spaced)
      if len(zone_spawns) < config.robots_in_keepout:
        raise ValueError(f"the keepout zones have room for {len(zone_spawns)} robots started in them (footprint "
                         f"on a lethal cell, clear of walls, a way out, {spacing:g} m apart); need "
                         f"robots_in_keepout = {config.robots_in_keepout}")
  chosen = pick(clear & reachable, zone_spawns.astype(np.float64))
  if len(chosen) - len(zone_spawns) < config.robots_per_world:
    chosen = pick(~blocked & ~clear & reachable & inside, chosen)
  spawns = chosen[len(zone_spawns):].astype(np.float32)       # >= spacing from every zone spawn
  if len(spawns) < config.robots_per_world:
    raise ValueError(f"the map has room for {len(spawns)} robots per world (free cells clear of "
                     f"obstacles and keepout, {spacing:g} m apart); need robots_per_world = "
                     f"{config.robots_per_world}: use fewer robots per world")

  n = int(round(config.local_costmap_size / res))
  pad = n
  static = np.asarray(static_layer(jnp.asarray(grid.data), config=STATIC_LAYER))
  padded = np.pad(static, pad, constant_values=constants.NO_INFORMATION)
  table, labels, raw_limits, speeds = zone_tables(scenario, config.robot.max_speed)
  cell_speed = np.asarray(speeds, np.float32)[table[scenario.speed.data.astype(np.uint8)]]
  params = WorldParams(
      static_cost=jnp.asarray(padded),
      map_origin=jnp.asarray(np.float32([ox, oy])),
      map_resolution=jnp.asarray(np.float32(res)),
      keepout=keepout, speed=speed,
      zone_table=jnp.asarray(table),
      zone_speed=jnp.asarray(np.asarray(speeds, np.float32)),
      speed_cap=jnp.asarray(dilate_min(cell_speed)),
      nav=navigation.NavField(dist=dist, origin=jnp.asarray(np.float32([ox, oy])),
                              resolution=jnp.asarray(np.float32(nav_res)),
                              stations=jnp.asarray(stations)),
      spawns=jnp.asarray(spawns), zone_spawns=jnp.asarray(zone_spawns, jnp.float32).reshape(-1, 2),
      direction=None if scenario.direction is None else FilterMask.create(
          scenario.direction, FilterInfo.create(constants.DIRECTION_FILTER, scenario.direction_base,
                                                scenario.direction_multiplier)),
      honour_lanes=None if scenario.direction is None else jnp.asarray(config.honour_lanes))
  return World(scenario=scenario, config=config, params=params, global_cost=cost, inflation=infl,
               window_cells=n, pad=pad, nav_factor=factor, zone_labels=labels,
               zone_limits=raw_limits, zone_speed=speeds, stations=stations, spawns=spawns,
               keepout_config=keepout_cfg, zone_spawns=np.asarray(zone_spawns, np.float32).reshape(-1, 2),
               local_layers=layers, plan_points=_plan_points(layers, config, nav_res),
               keepout_grid=local_costmap.keepout_grid(params.map_origin, params.map_resolution, keepout,
                                                       (-pad, padded.shape[1] - 2 * pad), (-pad, padded.shape[0] - 2 * pad)))


def _plan_points(layers, config: FleetConfig, step: float) -> int:
  """P: plan points covering the window's corner plus the widest asymmetric layer's radius, one per
  navigation cell (0 without an asymmetric layer). Nav2 culls the segments farther from the window
  than the radius; a plan that leaves that reach and comes back is cut (`navigation.trace_plan`)."""
  radii = [x.inflation_radius for x in layers if isinstance(x, AsymmetricInflationConfig)]
  if not radii:
    return 0
  reach = config.local_costmap_size * math.sqrt(0.5) + max(radii)
  return math.ceil(reach / step) + 2


def _zone_spawns(grid, keepout: FilterMask, walls: np.ndarray, exit_dist: np.ndarray, factor: int,
                 config: FleetConfig, spaced) -> np.ndarray:
  """Map cell centres where a robot's footprint covers a lethal keepout cell, spaced apart.

  Candidates are clear of the walls' inscribed band (walls-only global cost < 253, so the
  robot is not trapped by a wall) and have a finite exit field (a way out); the footprint
  is the robot's disc, with the keepout footprint test (jaxfilters.footprint).
  """
  ox, oy = float(grid.origin[0]), float(grid.origin[1])
  res = float(grid.resolution)
  rows, cols = np.nonzero(walls < constants.INSCRIBED_INFLATED_OBSTACLE)
  ok = np.isfinite(exit_dist[rows // factor, cols // factor])
  rows, cols = rows[ok], cols[ok]
  xy = np.stack([ox + (cols + 0.5) * res, oy + (rows + 0.5) * res], axis=1).astype(np.float32)
  r = config.robot.radius
  mres = float(keepout.resolution[0])
  lo = None if keepout.origin_lo is None else keepout.origin_lo[0]
  on = np.asarray(_footprint_on_zone(keepout.data[0], keepout.origin[0], keepout.resolution[0], jnp.asarray(xy),
                                     lo, radius=r, window=window_cells(None, r, 0.0, mres)))
  return spaced(xy[on].astype(np.float64), np.empty((0, 2))).astype(np.float32)
