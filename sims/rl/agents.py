"""One agent per robot in the fleet RL env (`NavEnvConfig(agents="per_robot")`): contacts and respawns.

In the per-robot mode every robot of a world is an agent of its own, driven by one policy with
shared parameters (the usual way of multi-agent JAX RL, as in JaxMARL and PufferLib: the agents
are folded into the batch; `sims.rl.fleet` trains it with rejax's PPO):

* observation float32 [K, 98]: each robot's own view (`sims.rl.observation.velocity_obs`, the
  nearest other robot included), the same 98 values whatever K is;
* action float32 [K, 2]: each robot's (v, w) in [-1, 1];
* reward and done float32 [K], and every metric float32 [K] (per robot, not summed).

Robot-robot contact is an exact disc test (`robot_contacts`): two robots touch when their
centres are less than 2 x `RobotConfig.radius` apart (the robots are discs; the MJX model has
no contacts, so robots would pass through each other). It is tested after every physics step
(100 Hz), like the static-obstacle test, so no contact between two controller ticks is missed.
A contact costs each robot in it `collision_penalty`, is counted in its
`metrics["robot_collisions"]` and ends both robots' episodes.

A robot's episode ends (done = 1) when it touches a static obstacle or another robot, or enters
a keepout zone with `keepout="terminate"`. The world goes on: the robot is respawned in the same
step (`respawn`: a spawn point of the env's layout at least `RESPAWN_CLEARANCE` from every other
robot, a random yaw, a new goal, the command and speed-filter state restarted), and its row of
the returned observation is its new episode's first observation. The other robots are not
disturbed. The world itself ends only at the time limit (`sims.rl.fleet.FleetAdapter`), which
ends every robot's episode at once. An evaluation (`sims.rl.fleet.evaluate_fleet_policy`)
counts each robot's first episode only, so every robot-episode it reports lasts until the
robot's own end or the time limit, with K robots on the floor throughout.

With `costmap_stop` the stop also sees the other robots (`robot_stop`): a robot's linear command
is stopped when a point of its look-ahead lies within 2 x radius of another robot's centre, as a
Nav2 controller's costmap (its obstacle layer) sees the robots around it. Turning stays free.
"""

import jax
import jax.numpy as jnp

from jaxfilters.speed import SpeedState
from sims.fleet import topk
from sims.rl import kernels
from sims.rl.task import NavTask

_F32 = jnp.float32
RESPAWN_CLEARANCE = 1.0   # m between a respawned robot's centre and every other robot's, where the layout allows


def robot_contacts(xy: jax.Array, radius: float) -> jax.Array:
  """Which robots touch another one: the exact disc test, centre distance < 2 x radius.

  Args:
    xy: float32 [K, 2] robot centres (m).
    radius: m, every robot's radius.

  Returns:
    bool [K]: robot i is closer than 2 x radius to some robot j != i.
  """
  k = xy.shape[0]
  d = jnp.linalg.norm(xy[:, None, :] - xy[None, :, :], axis=-1)
  d = jnp.where(jnp.eye(k, dtype=bool), jnp.inf, d)
  return jnp.any(d < 2.0 * radius, axis=1)


def robot_stop(qpos: jax.Array, cmd: jax.Array, dt: float, radius: float) -> tuple[jax.Array, jax.Array]:
  """Stops the linear command of robots whose look-ahead would touch another robot's disc.

  The look-ahead is `kernels.costmap_stop`'s (|v| x dt plus COSTMAP_STOP_MARGIN along the
  direction of motion, COSTMAP_STOP_SAMPLES points); a point closer than 2 x radius to another
  robot's centre blocks it. Turning is never blocked.

  Args:
    qpos: float32 [K, 3+] poses.
    cmd: float32 [K, 2] commands (v, w).
    dt: s, control period.
    radius: m.

  Returns:
    (cmd with v = 0 where blocked, bool [K] blocked).
  """
  k = qpos.shape[0]
  v = cmd[:, 0]
  th = qpos[:, 2]
  sign = jnp.where(v < 0, -1.0, 1.0)
  direction = sign[:, None] * jnp.stack([jnp.cos(th), jnp.sin(th)], axis=1)
  reach = jnp.abs(v) * dt + kernels.COSTMAP_STOP_MARGIN
  frac = jnp.arange(1, kernels.COSTMAP_STOP_SAMPLES + 1, dtype=_F32) / kernels.COSTMAP_STOP_SAMPLES
  pts = qpos[:, None, :2] + (reach[:, None] * frac[None, :])[..., None] * direction[:, None, :]   # [K, N, 2]
  d = jnp.linalg.norm(pts[:, :, None, :] - qpos[None, None, :, :2], axis=-1)                   # [K, N, K]
  d = jnp.where(jnp.eye(k, dtype=bool)[:, None, :], jnp.inf, d)
  blocked = jnp.any(d < 2.0 * radius, axis=(1, 2)) & (v != 0)
  return cmd.at[:, 0].set(jnp.where(blocked, 0.0, v)), blocked


def _where_rows(mask, new, old):
  return jax.tree.map(lambda a, b: jnp.where(mask.reshape(mask.shape + (1,) * (a.ndim - 1)), a, b), new, old)


def respawn(key: jax.Array, task: NavTask, data0, data, info: dict, mask: jax.Array, goal_max_distance: float):
  """Respawns the robots in `mask` while the others drive on (velocity mode's per-episode state).

  Each respawned robot gets a distinct spawn point of the env's layout (clear of its keepout
  zones), at least RESPAWN_CLEARANCE m from every robot that is not respawned where the layout
  has enough such points (else the farthest-ranked valid ones), a yaw ~ U(-pi, pi), zero
  velocity, a new goal (`kernels.sample_goal`), a zero command and a fresh speed-filter state.

  Args:
    key: PRNG key.
    task: the env's NavTask.
    data0: mjx.Data of one robot at rest (`FleetEnv.data0`).
    data: mjx.Data [K] after the step.
    info: the env's per-episode state after the step (goal, cmd, speed, cap, last_qpos, in_keepout).
    mask: bool [K], the robots to respawn.
    goal_max_distance: NavEnvConfig.goal_max_distance.

  Returns:
    (data, info) with the masked robots respawned and the others unchanged.
  """
  k = mask.shape[0]
  k_spawn, k_yaw, k_goal = jax.random.split(key, 3)
  bank, lay = task.bank, task.layout
  pts = bank.spawns[lay]                                                 # [P, 2]
  p_max = pts.shape[0]
  d = jnp.linalg.norm(pts[:, None, :] - data.qpos[None, :, :2], axis=-1)   # [P, K]
  nearest = jnp.min(jnp.where(mask[None, :], jnp.inf, d), axis=1)
  u = jax.random.uniform(k_spawn, (p_max,))
  score = jnp.where(jnp.arange(p_max) < bank.spawn_count[lay], jnp.where(nearest > RESPAWN_CLEARANCE, 1.0 + u, u),
                    -1.0)
  _, idx = topk.top_k(score, k)                       # best first: the clear points
  rank = jnp.clip(jnp.cumsum(mask) - 1, 0, k - 1)     # the i-th respawned robot takes the i-th point
  xy = pts[idx[rank]]
  yaw = jax.random.uniform(k_yaw, (k,), _F32, -jnp.pi, jnp.pi)
  fresh = jax.vmap(lambda q: data0.replace(qpos=q))(jnp.concatenate([xy, yaw[:, None]], axis=1))
  data = _where_rows(mask, fresh, data)
  per = bank.stations_per_layout
  goal = kernels.sample_goal(k_goal, task.goal_logits, xy, jnp.full((k,), -1, jnp.int32), bank.nav,
                             goal_max_distance, lay * per, per)
  info = dict(info, goal=jnp.where(mask, goal, info["goal"]), cmd=_where_rows(mask, jnp.zeros((k, 2), _F32), info["cmd"]),
              speed=_where_rows(mask, SpeedState.create(k), info["speed"]),
              cap=jnp.where(mask, jnp.inf, info["cap"]), in_keepout=jnp.where(mask, False, info["in_keepout"]),
              last_qpos=data.qpos)
  return data, info


__all__ = ["RESPAWN_CLEARANCE", "respawn", "robot_contacts", "robot_stop"]
