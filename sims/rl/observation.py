"""The RL env's observations (`sims.rl.env.NavEnv`): each robot's own view in velocity mode, and the
world's summary in navigation mode. What each value means is in `sims.rl.env`'s module docstring."""

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from sims.fleet import navigation
from sims.fleet.config import RobotConfig
from sims.fleet.env import WorldState
from sims.rl import kernels
from sims.rl.task import NavTask

_F32 = jnp.float32
AHEAD = (0.25, 0.5, 1.0)   # m, points ahead where the observation reads the speed limit


def crop_offsets(crop_cells: int, crop_spacing: float) -> np.ndarray:
  """float32 [C*C, 2]: the cost crop's sample points in the robot frame (forward, left), m."""
  r = (np.arange(crop_cells) - crop_cells // 2) * crop_spacing
  fx, ly = np.meshgrid(r, r, indexing="xy")          # rows: left offset, cols: forward offset
  return np.stack([fx.ravel(), ly.ravel()], axis=1).astype(np.float32)


def velocity_obs(task: NavTask, qpos: jax.Array, qvel: jax.Array, info: dict, robot: RobotConfig,
                 crop: np.ndarray) -> jax.Array:
  """Each robot's own view in velocity mode: float32 [K, D] (D = C*C + 17; see `sims.rl.env`).

  Args:
    task: the env's NavTask.
    qpos, qvel: float32 [K, 3] robot poses (x, y, yaw) and velocities.
    info: the env's per-episode state (goal, cmd, cap).
    robot: RobotConfig (max_speed, max_yaw_rate).
    crop: `crop_offsets(...)`.
  """
  r = robot
  p = task.world
  k = qpos.shape[0]
  pose = qpos[:, :3]
  c, s = jnp.cos(pose[:, 2]), jnp.sin(pose[:, 2])
  off = jnp.asarray(crop)                                                # [C2, 2]
  wx, wy = kernels.rotate(c[:, None], s[:, None], off[None, :, 0], off[None, :, 1])
  pts = jnp.stack([wx + pose[:, :1], wy + pose[:, 1:2]], axis=-1)       # [K, C2, 2]
  static = kernels.grid_value(task.static_inflated, p.map_origin, p.map_resolution, pts, constants.NO_INFORMATION)
  keep = kernels.keepout_cost(task, pts).astype(jnp.int32)
  keep = jnp.where(keep == constants.NO_INFORMATION, 0, keep)
  crop_obs = jnp.maximum(static, keep).astype(_F32) / 255.0             # [K, C2]

  cap = info["cap"]
  limited = jnp.isfinite(cap)
  cap_obs = jnp.stack([jnp.where(limited, jnp.minimum(cap / r.max_speed, 1.0), 1.0),
                       limited.astype(_F32)], axis=1)
  ahead = jnp.asarray(AHEAD, _F32)
  ahead_pts = pose[:, None, :2] + ahead[None, :, None] * jnp.stack([c, s], axis=1)[:, None, :]
  ahead_cap = kernels.mps_cap(task, ahead_pts, r.max_speed)
  ahead_obs = jnp.where(jnp.isfinite(ahead_cap), jnp.minimum(ahead_cap / r.max_speed, 1.0), 1.0)

  nav = task.bank.nav
  goal_xy = nav.stations[info["goal"]]
  d = goal_xy - pose[:, :2]
  gx, gy = kernels.rotate(c, -s, d[:, 0], d[:, 1])
  gdist = jnp.linalg.norm(d, axis=-1)
  goal_obs = jnp.stack([jnp.clip(gx / 5.0, -1, 1), jnp.clip(gy / 5.0, -1, 1),
                        jnp.minimum(gdist / 10.0, 1.0)], axis=1)
  desc = jax.vmap(lambda g, q: navigation.descent_direction(nav, g, q))(info["goal"], pose[:, :2])
  dx, dy = kernels.rotate(c, -s, desc[:, 0], desc[:, 1])
  ndist = jax.vmap(lambda g, q: navigation.nav_value(nav, g, q))(info["goal"], pose[:, :2])
  nav_obs = jnp.stack([dx, dy, jnp.minimum(ndist / 20.0, 1.0)], axis=1)

  spd = jnp.linalg.norm(qvel[:, :2], axis=-1)
  vel_obs = jnp.stack([info["cmd"][:, 0] / r.max_speed, info["cmd"][:, 1] / r.max_yaw_rate,
                       spd / r.max_speed], axis=1)

  rel = pose[None, :, :2] - pose[:, None, :2]                          # [K, K, 2] others - self
  dd = jnp.where(jnp.eye(k, dtype=bool), jnp.inf, jnp.linalg.norm(rel, axis=-1))
  j = jnp.argmin(dd, axis=1)
  near = rel[jnp.arange(k), j]
  ox, oy = kernels.rotate(c, -s, near[:, 0], near[:, 1])
  has = jnp.isfinite(jnp.min(dd, axis=1))
  other_obs = jnp.stack([jnp.where(has, jnp.clip(ox / 3.0, -1, 1), 0.0),
                         jnp.where(has, jnp.clip(oy / 3.0, -1, 1), 0.0),
                         jnp.where(has, jnp.minimum(jnp.min(dd, axis=1) / 3.0, 1.0), 1.0)], axis=1)
  per_robot = jnp.concatenate([crop_obs, cap_obs, ahead_obs, goal_obs, nav_obs, vel_obs, other_obs], axis=1)
  return per_robot.astype(_F32)


def navigation_obs(task: NavTask, ws: WorldState, robot: RobotConfig) -> jax.Array:
  """Navigation mode: per robot (x, y, cos, sin, goal x, goal y, cap, speed), then every station (x, y)."""
  p = task.world
  pose = ws.data.qpos[:, :3]
  scale = 10.0
  cap = ws.speed_cap
  per = jnp.stack([pose[:, 0] / scale, pose[:, 1] / scale, jnp.cos(pose[:, 2]), jnp.sin(pose[:, 2]),
                   p.nav.stations[ws.goal, 0] / scale, p.nav.stations[ws.goal, 1] / scale,
                   jnp.where(jnp.isfinite(cap), jnp.minimum(cap / robot.max_speed, 1.0), 1.0),
                   jnp.linalg.norm(ws.data.qvel[:, :2], axis=-1) / robot.max_speed], axis=1)
  return jnp.concatenate([per.reshape(-1), p.nav.stations.reshape(-1) / scale]).astype(_F32)


__all__ = ["AHEAD", "crop_offsets", "navigation_obs", "velocity_obs"]
