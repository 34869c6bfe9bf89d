"""Per-robot rolling-window local costmaps, built with jaxfilters at the costmap rate.

For each robot of a world (Nav2's local costmap, `rolling_window: true`):

1. the window origin is snapped to the static map's grid, with the robot at
   the window centre;
2. static layer: the window is a slice of the (padded) static layer;
3. other robots of the world are obstacles: cells whose centre is within a
   robot radius of another robot's centre become LETHAL (what a sensor would
   mark);
4. inflation (`jaxfilters.inflation.inflate`), or the inflation layers of a
   params file's local costmap in their `plugins:` order (`layers`): an
   InflationLayer runs `inflate`, an AsymmetricInflationLayer
   `jaxfilters.asymmetric_inflate` with each robot's own plan (`paths`, world
   metres: the window's frame is the map's, its origin a map cell corner) and
   position;
5. the keepout filter (`jaxfilters.keepout.keepout_filter`) on the combined
   map *after* inflation, Nav2's filter order, so keepout cells are lethal but
   not inflated.

With a `keepout_config` (keepout escape, FleetConfig.keepout_escape) the
keepout filter runs instead as a layer before inflation (Nav2 users list it
under `plugins:` for that, docs PR #972): its updateBounds runs the escape
mode's robot-in-zone test at each robot's pose, its process() writes the zones
(`lethal_override_cost` while escaping, which inflation does not spread), and
inflation then gives the zones an inscribed band.

With a direction mask (one-way lanes, Scenario.direction) the direction filter
(`jaxfilters.direction.direction_filter`) runs last, after inflation like
Nav2's filters: every lane cell the robot's heading is not allowed on becomes
lethal in that robot's costmap, except the cell under the robot itself (it is
there already; left lethal, a robot that turned against a lane could not even
turn back, as a robot in a keepout zone could not leave without Nav2's escape
mode).

The work per robot is O(N^2 (R + K)) for an N x N window, independent of the
map size, so a GPU can run tens of thousands of robots.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from jaxfilters import constants
from jaxfilters.asymmetric_inflation import AsymmetricInflationConfig, asymmetric_inflate
from jaxfilters.direction import direction_filter
from jaxfilters.inflation import InflationConfig, inflate
from jaxfilters.keepout import KeepoutConfig, KeepoutState, keepout_filter, keepout_update_bounds
from jaxfilters.types import Costmap

_F32 = jnp.float32
# The fleet builds these costmaps per world under `jax.vmap`, where keepout_filter's run-time
# choice of its aligned slice path (a `lax.cond` on the robots' geometry) is batched and becomes
# a select that runs the slice, mixed and gather loops for every world. Its gather path alone
# gives the same integers (jaxfilters/keepout/other_resolution.py) in less time.
_KEEPOUT = KeepoutConfig(aligned_fast_path=False)


def window_index(xy: jax.Array, map_origin: jax.Array, res: jax.Array, n: int) -> jax.Array:
  """int32 [K, 2] (col, row) of each window's lower-left cell in static-map cells.

  Nav2's rolling window puts the robot at the centre and moves the origin by
  whole cells, so the window stays aligned with the static map's grid.

  Args:
    xy: float32 [K, 2] robot positions (m).
    map_origin: float32 [2] static map origin (m).
    res: float32 [] metres per cell.
    n: cells per window side (static).

  Returns:
    int32 [K, 2] (col, row), possibly negative or past the map (the static
    layer is padded).
  """
  return jnp.floor((xy - map_origin[None, :] - 0.5 * n * res) / res).astype(jnp.int32)


def local_costmaps(static_cost: jax.Array, map_origin: jax.Array, res: jax.Array, pad: int,
                   keepout, poses: jax.Array, keepout_state: KeepoutState, *, n: int,
                   robot_radius: float, inflation: InflationConfig,
                   keepout_config: KeepoutConfig | None = None,
                   layers: tuple[InflationConfig | AsymmetricInflationConfig, ...] | None = None,
                   paths: jax.Array | None = None,
                   path_lengths: jax.Array | None = None, direction=None,
                   honour_lanes=None) -> tuple[Costmap, KeepoutState]:
  """Builds the K local costmaps of one world.

  Args:
    static_cost: uint8 [H + 2P, W + 2P] static layer padded with NO_INFORMATION.
    map_origin: float32 [2] origin of the unpadded map; res float32 [].
    pad: P (static).
    keepout: FilterMask of the keepout filter.
    poses: float32 [K, 3] robot poses.
    keepout_state: KeepoutState [K].
    n: window side in cells (static).
    robot_radius: m, radius of the other robots' footprints.
    inflation: static InflationConfig at resolution res.
    keepout_config: static KeepoutConfig with escape mode: keepout as a layer
      before inflation (see above); None: Nav2's filter after inflation.
    layers: static inflation layers run in order instead of `inflation` (None:
      `(inflation,)`), each at resolution res.
    paths: float32 [K, P, 2], each robot's plan in world metres, and
    path_lengths: int32 [K] its points in use: needed (only) by an
      AsymmetricInflationConfig in `layers`.
    direction: FilterMask of type 5 (one-way lanes) or None (static: no
      direction work at all).
    honour_lanes: bool [] with a direction mask: False leaves the costmaps
      as they are (FleetConfig.honour_lanes; None means True).

  Returns:
    (Costmap with cost uint8 [K, n, n], origin [K, 2], resolution [K]; new KeepoutState).
  """
  layers = (inflation,) if layers is None else tuple(layers)
  if any(isinstance(x, AsymmetricInflationConfig) for x in layers) and (paths is None or path_lengths is None):
    raise ValueError("local_costmaps: an AsymmetricInflationConfig in layers reads each robot's plan; pass "
                     "paths float32 [K, P, 2] and path_lengths int32 [K]")
  k = poses.shape[0]
  hp, wp = static_cost.shape
  idx = window_index(poses[:, :2], map_origin, res, n)
  col = jnp.clip(idx[:, 0], -pad, wp - pad - n)
  row = jnp.clip(idx[:, 1], -pad, hp - pad - n)
  static = jax.vmap(lambda r, c: jax.lax.dynamic_slice(static_cost, (r + pad, c + pad), (n, n)))(row, col)
  origin = map_origin[None, :] + jnp.stack([col, row], axis=1).astype(_F32) * res
  centres = (jnp.arange(n, dtype=_F32) + 0.5) * res                     # [n]
  cx = origin[:, 0][:, None] + centres[None, :]                          # [K, n]
  cy = origin[:, 1][:, None] + centres[None, :]
  dx = cx[:, None, None, :] - poses[None, :, 0][:, :, None, None]        # [K, K, 1, n]
  dy = cy[:, None, :, None] - poses[None, :, 1][:, :, None, None]        # [K, K, n, 1]
  other = ~jnp.eye(k, dtype=bool)[:, :, None, None]
  occupied = jnp.any(other & (dx * dx + dy * dy <= robot_radius * robot_radius), axis=1)
  cost = jnp.where(occupied, jnp.uint8(constants.LETHAL_OBSTACLE), static)

  def inflate_all(c):
    for layer in layers:
      if isinstance(layer, AsymmetricInflationConfig):
        c = asymmetric_inflate(Costmap(c, origin, jnp.full((k,), res, _F32)), paths=paths,
                               path_lengths=path_lengths, robot_xy=poses[:, :2], config=layer).cost
      else:
        c = inflate(c, config=layer)
    return c

  if keepout_config is None:
    cost = inflate_all(cost)
    costmap = Costmap(cost, origin, jnp.full((k,), res, _F32))
    costmap, kstate = keepout_filter(costmap, keepout, poses, keepout_state, config=_KEEPOUT)
    return _lanes(costmap, direction, poses, honour_lanes), kstate
  keepout_config = dataclasses.replace(keepout_config, aligned_fast_path=False)   # as _KEEPOUT
  primary = Costmap(cost, origin, jnp.full((k,), res, _F32))
  bounds = jnp.concatenate([origin, origin + n * res], axis=1)     # the rolling window redraws it all
  kstate, _ = keepout_update_bounds(primary, keepout, poses, keepout_state, bounds, config=keepout_config)
  primary, kstate2 = keepout_filter(primary, keepout, poses, kstate, config=keepout_config)
  kstate2 = dataclasses.replace(kstate2, error=kstate2.error | kstate.error)
  primary = dataclasses.replace(primary, cost=inflate_all(primary.cost))
  return _lanes(primary, direction, poses, honour_lanes), kstate2


def _lanes(costmap: Costmap, direction, poses: jax.Array, honour) -> Costmap:
  """The direction filter on the K costmaps at the robots' headings, the robot's own cell kept (see above)."""
  if direction is None:
    return costmap
  out, _ = direction_filter(costmap, direction, poses, enabled=None if honour is None else honour)
  k, n, _ = costmap.cost.shape
  cell = jnp.floor((poses[:, :2] - costmap.origin) / costmap.resolution[:, None]).astype(jnp.int32)
  inside = jnp.all((cell >= 0) & (cell < n), axis=1)
  col, row = jnp.clip(cell[:, 0], 0, n - 1), jnp.clip(cell[:, 1], 0, n - 1)
  robots = jnp.arange(k)
  own = jnp.where(inside, costmap.cost[robots, row, col], out.cost[robots, row, col])
  return dataclasses.replace(out, cost=out.cost.at[robots, row, col].set(own))
