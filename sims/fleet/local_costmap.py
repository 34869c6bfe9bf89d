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
   not inflated. A keepout mask on the map's own grid (the usual case: a mask
   drawn on the map; `KeepoutGrid`) is read as whole cells (`grid_keepout`),
   the same integers in a program about a quarter smaller to compile.

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
import numpy as np

from jaxfilters import constants
from jaxfilters.asymmetric_inflation import AsymmetricInflationConfig, asymmetric_inflate
from jaxfilters.direction import direction_filter
from jaxfilters.inflation import InflationConfig, inflate
from jaxfilters.keepout import KeepoutConfig, KeepoutState, keepout_filter, keepout_update_bounds
from jaxfilters.keepout.common import processed, write_u8
from jaxfilters.types import Costmap, FilterMask

_F32 = jnp.float32
# The fleet builds these costmaps per world under `jax.vmap`, where keepout_filter's run-time
# choice of its aligned slice path (a `lax.cond` on the robots' geometry) is batched and becomes
# a select that runs the slice, mixed and gather loops for every world. Its gather path alone
# gives the same integers (jaxfilters/keepout/other_resolution.py) in less time.
_KEEPOUT = KeepoutConfig(aligned_fast_path=False)
# How far (in cells) a window's float32 origin may stray from its grid line for `KeepoutGrid`:
# the exact sampling point is half a cell from the nearest mask-cell edge, so anything under 0.5
# gives the same cells; 0.25 leaves room for the bound's own rounding.
_GRID_SLACK = 0.25


@dataclasses.dataclass(frozen=True)
class KeepoutGrid:
  """A keepout mask on the static map's own grid: mask cell = map cell + `offset`, proven on the host.

  The rolling windows' origins are map-grid corners (`window_index`), so when the mask's
  resolution is the map's and its origin lies on the map's grid, Nav2's per-cell sampling
  (the cell centre's worldToMap on the mask, docs/nav2_semantics.md §4.3) reads mask cell
  (col + offset_x + i, row + offset_y + j) for window cell (i, j): the centre is half a cell
  from every mask-cell edge, so the float32 rounding of the window origin cannot move it
  across one. `keepout_grid` proves that bound for every window position of the map and
  records the float32 geometry it proved it for; `grid_keepout` then reads the cells as
  integers, the same integers as `keepout_filter` (tests/fleet/test_grid_keepout.py),
  in a program a fraction of the size (no exact-arithmetic fallback to compile).

  Attributes:
    offset: (dx, dy) mask column and row of map cell (0, 0).
    geometry: the float32 values proven: (map origin x, y, map resolution, mask origin x,
      y, the mask origin's lower parts (4), mask resolution), as Python floats. A traced
      WorldParams with any other value (`FleetEnv.with_params`) is not applied and flagged.
  """
  offset: tuple[int, int]
  geometry: tuple[float, ...]


def _geometry_values(map_origin, map_resolution, mask: FilterMask):
  lo = np.zeros((2, 2), np.float32) if mask.origin_lo is None else np.asarray(mask.origin_lo, np.float32)[0]
  return (np.asarray(map_origin, np.float32).reshape(2), np.float32(map_resolution),
          np.asarray(mask.origin, np.float32)[0], lo, np.float32(np.asarray(mask.resolution)[0]))


def keepout_grid(map_origin, map_resolution, mask: FilterMask, cols: tuple[int, int],
                 rows: tuple[int, int]) -> KeepoutGrid | None:
  """The `KeepoutGrid` of a one-mask FilterMask for windows whose lower-left map cell lies in
  [cols[0], cols[1]] x [rows[0], rows[1]], or None where it cannot be proven (another
  resolution, an origin off the map's grid, coordinates too large for float32's rounding):
  the local costmaps then run `keepout_filter`.
  """
  if mask.data.shape[0] != 1:
    return None
  o, r, mo_hi, mo_lo, mr = _geometry_values(map_origin, map_resolution, mask)
  if not (r == mr and np.isfinite(r) and r > 0 and np.all(np.isfinite(o)) and np.all(np.isfinite(mo_hi))):
    return None
  r = float(r)
  mo = mo_hi.astype(np.float64) + mo_lo.astype(np.float64).sum(axis=0)      # the mask's origin (double)
  shift = (o.astype(np.float64) - mo) / r
  offset = np.round(shift)
  if np.any(np.abs(offset) > 2 ** 22):      # keepout_filter's exact floors hold below 2^22 cells
    return None
  residual = np.abs(o.astype(np.float64) - mo - offset * r)                 # m, the grids' misfit
  # A window's origin is fl32(o + fl32(c r)): at most 2^-24 (|c r|) + 2^-24 (|o| + |c r|) (1 + 2^-24) from
  # o + c r; with the double's rounding of the residual, 2^-22 (|o| + |c| r) bounds it.
  c_max = np.asarray([max(abs(cols[0]), abs(cols[1])), max(abs(rows[0]), abs(rows[1]))], np.float64)
  stray = 2.0 ** -22 * (np.abs(o.astype(np.float64)) + c_max * r) + residual + 2.0 ** -40 * np.abs(mo)
  if np.any(stray >= _GRID_SLACK * r):
    return None
  values = (*o.tolist(), float(np.float32(map_resolution)), *mo_hi.tolist(), *mo_lo.reshape(-1).tolist(), float(mr))
  return KeepoutGrid(offset=(int(offset[0]), int(offset[1])), geometry=tuple(float(v) for v in values))


def grid_keepout(cost: jax.Array, mask: FilterMask, map_origin: jax.Array, map_resolution: jax.Array,
                 cells: jax.Array, state: KeepoutState, grid: KeepoutGrid, *,
                 config: KeepoutConfig) -> tuple[jax.Array, KeepoutState]:
  """`keepout_filter` (process(), whole window, every robot enabled) on K windows of the map's grid.

  Args:
    cost: uint8 [K, n, n]; mask: the FilterMask `grid` was proven for (traced values are
      compared with it); map_origin float32 [2], map_resolution float32 []: the static map's.
    cells: int32 [K, 2] (col, row) of each window's lower-left map cell.
    state: KeepoutState [K]; grid: static KeepoutGrid; config: static KeepoutConfig.

  Returns:
    (cost uint8 [K, n, n], KeepoutState [K]), the integers `keepout_filter` gives. Where the
    traced geometry is not the proven one (params swapped for a mask elsewhere), every robot
    is left untouched with `error` True, as `keepout_filter` leaves a robot whose geometry
    it cannot use.
  """
  k, n, _ = cost.shape
  hm, wm = mask.data.shape[1:]
  o, r, mo_hi, mo_lo, mr = (map_origin, map_resolution, mask.origin[0],
                            jnp.zeros((2, 2), _F32) if mask.origin_lo is None else mask.origin_lo[0],
                            mask.resolution[0])
  traced = jnp.concatenate([jnp.reshape(o, (2,)), jnp.reshape(r, (1,)), mo_hi, mo_lo.reshape(-1),
                            jnp.reshape(mr, (1,))]).astype(_F32)
  same = jnp.all(traced == jnp.asarray(grid.geometry, _F32))
  flat = mask.data.reshape(-1)
  steps = jnp.arange(n, dtype=jnp.int32)

  def one(c, row, col, s):
    mx = col + grid.offset[0] + steps
    my = row + grid.offset[1] + steps
    vx, vy = (mx >= 0) & (mx < wm), (my >= 0) & (my < hm)
    d = flat[jnp.clip(my, 0, hm - 1)[:, None] * wm + jnp.clip(mx, 0, wm - 1)[None, :]]
    run = same & jnp.any(vx) & jnp.any(vy)
    new = write_u8(c, d, vy[:, None] & vx[None, :] & run, s, config)
    return new, processed(s, run)

  new, out = jax.vmap(one)(cost, cells[:, 1], cells[:, 0], state)
  return new, dataclasses.replace(out, error=jnp.broadcast_to(~same, (k,)))


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
                   honour_lanes=None, grid: KeepoutGrid | None = None) -> tuple[Costmap, KeepoutState]:
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
    grid: static `KeepoutGrid` of `keepout` (`keepout_grid`): process() runs as
      `grid_keepout` (same integers); None: `keepout_filter`.

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
  cells = jnp.stack([col, row], axis=1)
  origin = map_origin[None, :] + cells.astype(_F32) * res
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
    if grid is None:
      costmap, kstate = keepout_filter(costmap, keepout, poses, keepout_state, config=_KEEPOUT)
    else:
      new, kstate = grid_keepout(cost, keepout, map_origin, res, cells, keepout_state, grid, config=_KEEPOUT)
      costmap = dataclasses.replace(costmap, cost=new)
    return _lanes(costmap, direction, poses, honour_lanes), kstate
  keepout_config = dataclasses.replace(keepout_config, aligned_fast_path=False)   # as _KEEPOUT
  primary = Costmap(cost, origin, jnp.full((k,), res, _F32))
  bounds = jnp.concatenate([origin, origin + n * res], axis=1)     # the rolling window redraws it all
  kstate, _ = keepout_update_bounds(primary, keepout, poses, keepout_state, bounds, config=keepout_config)
  if grid is None:
    primary, kstate2 = keepout_filter(primary, keepout, poses, kstate, config=keepout_config)
  else:
    new, kstate2 = grid_keepout(cost, keepout, map_origin, res, cells, kstate, grid, config=keepout_config)
    primary = dataclasses.replace(primary, cost=new)
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
