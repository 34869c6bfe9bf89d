"""Internal: the per-step kernels of the RL env (`sims.rl.env.NavEnv`): the speed clip, grid and mask reads
in the env's zone layout, and goal drawing."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxfilters import constants, geometry
from jaxfilters.query import keepout_cost_at, speed_limit_at
from sims.fleet import navigation, planner
from sims.fleet.config import RobotConfig
from sims.rl.task import NavTask

_F32 = jnp.float32


def clip_command(cmd: jax.Array, cap: jax.Array, robot: RobotConfig, limit_angular: bool) -> jax.Array:
  """The fleet's hard clip of commands to the speed limit in force (sims/fleet/env.py `_tick`).

  Args:
    cmd: float32 [K, 2] (v m/s, w rad/s).
    cap: float32 [K] speed cap in m/s (+inf = no limit), from `planner.limit_to_speed`.
    robot: RobotConfig (max_speed, max_yaw_rate).
    limit_angular: also scale the yaw rate by cap / max_speed (FleetConfig.limit_angular).

  Returns:
    float32 [K, 2]: |v| <= cap; |w| <= max_yaw_rate * min(cap / max_speed, 1) if limit_angular.
  """
  v = jnp.clip(cmd[:, 0], -cap, cap)
  w = cmd[:, 1]
  if limit_angular:
    w_cap = robot.max_yaw_rate * jnp.minimum(cap / robot.max_speed, 1.0)
    w = jnp.clip(w, -w_cap, w_cap)
  return jnp.stack([v, w], axis=1)


def grid_value(grid: jax.Array, origin: jax.Array, res: jax.Array, xy: jax.Array, fill: int) -> jax.Array:
  """uint8 grid value at points xy [..., 2] (exact worldToMap), `fill` off the grid (int32)."""
  h, w = grid.shape
  mx, my, ok = geometry.world_to_cell(xy[..., 0], xy[..., 1], origin, res, w, h)
  return jnp.where(ok, grid[my, mx].astype(jnp.int32), fill)


def rotate(c, s, x, y):
  return c * x - s * y, s * x + c * y


def layout_index(task: NavTask, lead: tuple[int, ...]) -> jax.Array:
  """The env's layout as a mask_index of the points' leading shape."""
  return jnp.broadcast_to(task.layout.astype(jnp.int32), lead)


def mps_cap(task: NavTask, xy: jax.Array, max_speed: float) -> jax.Array:
  """Speed limit of the env's speed mask at points xy [..., 2] in m/s (+inf: none, off-mask or unknown)."""
  limit, pct, valid = speed_limit_at(task.bank.speed, xy, mask_index=layout_index(task, xy.shape[:-1]))
  return planner.limit_to_speed(limit, pct, valid, max_speed)


def keepout_cost(task: NavTask, xy: jax.Array) -> jax.Array:
  """Keepout filter cost of the env's keepout mask at points xy [..., 2] (uint8; NO_INFORMATION off it)."""
  return keepout_cost_at(task.bank.keepout, xy, mask_index=layout_index(task, xy.shape[:-1]))


COSTMAP_STOP_MARGIN = 0.1   # m beyond one tick's travel: the robot's slowing down after a stop command
COSTMAP_STOP_SAMPLES = 4    # footprint checks along the look-ahead (<= 3.2 cm apart at 0.5 m/s, 20 Hz)


def costmap_stop(task: NavTask, qpos: jax.Array, cmd: jax.Array, dt: float) -> tuple[jax.Array, jax.Array]:
  """Stops the linear command of robots whose footprint would touch a keepout zone or a static obstacle.

  The look-ahead runs along the direction of motion (backwards when reversing) for
  |v| x dt (one control tick at the command) plus COSTMAP_STOP_MARGIN; a point where
  the keepout filter's cost or the inflated static layer's cost is >=
  INSCRIBED_INFLATED_OBSTACLE (the robot's disc there touches a lethal cell) blocks
  it. Turning is never blocked. This is the costmap check a Nav2 controller applies
  to its own trajectories (static layer, inflation, keepout filter), applied to the
  policy's command.

  Args:
    task: NavTask (the env's keepout mask, layout and inflated static layer).
    qpos: float32 [K, 3+] robot poses (x, y, yaw first).
    cmd: float32 [K, 2] commands (v, w) after the speed filter's clip.
    dt: s, control period.

  Returns:
    (cmd with v = 0 where blocked, bool [K] blocked).
  """
  v = cmd[:, 0]
  th = qpos[:, 2]
  sign = jnp.where(v < 0, -1.0, 1.0)
  direction = sign[:, None] * jnp.stack([jnp.cos(th), jnp.sin(th)], axis=1)
  reach = jnp.abs(v) * dt + COSTMAP_STOP_MARGIN
  frac = jnp.arange(1, COSTMAP_STOP_SAMPLES + 1, dtype=jnp.float32) / COSTMAP_STOP_SAMPLES
  pts = qpos[:, None, :2] + (reach[:, None] * frac[None, :])[..., None] * direction[:, None, :]
  p = task.world
  lethal = constants.INSCRIBED_INFLATED_OBSTACLE
  touches = (keepout_cost(task, pts) >= lethal) | (
      grid_value(task.static_inflated, p.map_origin, p.map_resolution, pts, constants.NO_INFORMATION) >= lethal)
  blocked = jnp.any(touches, axis=1) & (v != 0)
  return cmd.at[:, 0].set(jnp.where(blocked, 0.0, v)), blocked


def sample_goal(key, logits, xy, current, nav: navigation.NavField, max_dist: float, first, count: int):
  """A goal per robot among stations first .. first + count - 1 (the env's layout), drawn from the
  goal distribution: not the current one, > 2 m away in a straight line and within `max_dist` m
  of navigation distance (0: any) if possible, else relaxing those in that order.

  Returns:
    int32 [K] station ids of `nav` (first + s).
  """
  k = xy.shape[0]
  ids = first + jnp.arange(count, dtype=jnp.int32)
  stations = nav.stations[ids]
  lg = logits[ids]
  far = jnp.linalg.norm(stations[None] - xy[:, None], axis=-1) > 2.0
  if max_dist > 0:
    active = jnp.isfinite(lg)
    dist = jax.vmap(lambda q: jax.vmap(lambda g: navigation.nav_value(nav, g, q))(ids))(xy)   # [K, count]
    far = far & active[None, :] & (dist <= max_dist)
  other = ids[None, :] != current[:, None]
  base = jnp.broadcast_to(lg[None, :], (k, count))
  pick = jnp.where(far & other, base, -jnp.inf)
  pick = jnp.where(jnp.any(jnp.isfinite(pick), axis=1, keepdims=True), pick, jnp.where(other, base, -jnp.inf))
  pick = jnp.where(jnp.any(jnp.isfinite(pick), axis=1, keepdims=True), pick, base)
  j = jax.vmap(jax.random.categorical)(jax.random.split(key, k), pick).astype(jnp.int32)
  return ids[j]


__all__ = ["clip_command", "grid_value", "keepout_cost", "layout_index", "mps_cap", "rotate", "sample_goal"]
