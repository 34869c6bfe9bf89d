"""The MJX fleet environment: one world's pure `reset(key)` / `step(state, action)`.

A world is one warehouse with K = `robots_per_world` robots (the built-in
sims/assets/planar_robot.xml, or your own MJCF base: sims/fleet/robot.py; one
MJX model per robot, stepped with `jax.vmap` over K). Worlds are independent; a fleet of B = W * K robots is W
worlds batched by one visible `jax.vmap` over `reset` and `step`
(`FleetEnv.rollout_fn`), and rolled out with `lax.scan`.

One `step` is one local-costmap period (1 / costmap_hz, 0.2 s by default):

1. apply the action (goal overrides; -1 keeps the current goal);
2. rebuild every robot's rolling local costmap (static layer, other robots,
   inflation, keepout filter, and with a direction mask the one-way lanes at
   each robot's heading; sims/fleet/local_costmap.py);
3. `lax.scan` over controller ticks (controller_hz, 20 Hz), each:
   pose from MJX -> speed filter (its state carried) -> goals and progress
   checker -> local planner on the local costmap, descending the shared
   navigation field with the speed-zone lookahead (sims/fleet/planner.py) -> clip
   linear (and optionally angular) velocity to the limit in force -> write ctrl
   -> `lax.scan` over physics steps (mjx.step), accumulating metrics.

With keepout escape (FleetConfig.keepout_escape 'center' or 'footprint') the
keepout filter runs as a layer before inflation with escape mode; a robot
whose keepout state says it is in a zone steers by the exit field (the
shortest way out) instead of its goal's field, and the footprint keepout
metrics are recorded. `robots_in_keepout` robots start in zones.

All rates are static, so nothing inside a step branches on a traced counter
(under `vmap` a `lax.cond` on batched data would run both branches).
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from sims.fleet.quiet_mjx import expected_warp_lines

with expected_warp_lines():
  from mujoco import mjx

from jaxfilters.footprint import window_cells
from jaxfilters.keepout import KeepoutState
from jaxfilters.speed import SpeedState, speed_filter
from jaxfilters.types import Costmap, pytree_dataclass
from sims.fleet import local_costmap, metrics as metrics_lib, navigation, planner
from sims.fleet.config import FleetConfig
from sims.fleet.robot import ROBOT_XML, RobotModel, RobotModelError, load_builtin_model, planar_ctrl
from sims.fleet.scenario import Scenario
from sims.fleet.world import World, WorldParams, build_world

_F32 = jnp.float32


@pytree_dataclass
class WorldState:
  """State of one world of K robots (every leaf gains a leading W under vmap).

  Attributes:
    data: mjx.Data batched over K robots (qpos = x, y, yaw).
    cmd: float32 [K, 2], the last command (v m/s, w rad/s).
    goal: int32 [K], station index of each robot's goal.
    speed: SpeedState [K] of the speed filter.
    speed_cap: float32 [K], speed limit in force (m/s; +inf = none).
    keepout: KeepoutState [K] of the keepout filter.
    local: Costmap [K] rolling local costmaps (uint8 [K, N, N]).
    plan_lut: uint16 [K, N, N], `planner.lookup_table` of each local costmap (built with it).
    progress_anchor: float32 [K, 2], progress checker reference position.
    progress_time: float32 [K], seconds since the robot last moved progress_radius.
    blocked_time: float32 [K], seconds slower than 0.02 m/s away from the goal.
    recovery_time: float32 [K], seconds of recovery mode left (planner).
    in_keepout, in_contact, in_near: bool [K], flags for edge-counted metrics.
    metrics: Metrics [K].
    key: PRNG key (uint32 [2]).
    time: float32 [], simulated seconds.
  """
  data: mjx.Data
  cmd: jax.Array
  goal: jax.Array
  speed: SpeedState
  speed_cap: jax.Array
  keepout: KeepoutState
  local: Costmap
  plan_lut: jax.Array
  progress_anchor: jax.Array
  progress_time: jax.Array
  blocked_time: jax.Array
  recovery_time: jax.Array
  in_keepout: jax.Array
  in_contact: jax.Array
  in_near: jax.Array
  metrics: metrics_lib.Metrics
  key: jax.Array
  time: jax.Array


@pytree_dataclass
class Frame:
  """What a rollout records per env step and robot (for plots and tests).

  Attributes:
    pose: float32 [..., K, 3] (x, y, yaw).
    speed: float32 [..., K] linear speed (m/s).
    cmd: float32 [..., K, 2] last command.
    goal: int32 [..., K].
    speed_cap: float32 [..., K] limit in force (m/s; +inf none).
  """
  pose: jax.Array
  speed: jax.Array
  cmd: jax.Array
  goal: jax.Array
  speed_cap: jax.Array


@pytree_dataclass
class TickFrame:
  """What a rollout records per controller tick and robot (for rosbag2 replay: sims/record/bag.py).

  Attributes:
    time: float32 [...] simulated time (s) at the start of the tick; the speed
      filter ran and the command was chosen then.
    pose: float32 [..., K, 3] (x, y, yaw) at the start of the tick, where the
      speed filter read the mask.
    cmd: float32 [..., K, 2] (v m/s, w rad/s), the tick's command after the speed clip.
    speed_limit: float32 [..., K] the speed filter's limit in force (Nav2's
      SpeedLimit value: percent or m/s by the mask type; 0.0 = no limit).
    speed_cap: float32 [..., K] that limit in m/s (+inf = none).
  """
  time: jax.Array
  pose: jax.Array
  cmd: jax.Array
  speed_limit: jax.Array
  speed_cap: jax.Array


def mjx_step(model: mjx.Model, data: mjx.Data, ctrl: jax.Array) -> mjx.Data:
  """mjx.step of one robot with ctrl written first.

  MJX broadcasts across ranks internally, so this traces with rank promotion
  allowed even where a caller (e.g. the test suite) sets it to 'raise'.

  Args:
    model: the robot's mjx.Model.
    data: one robot's mjx.Data (qpos = x m, y m, yaw rad).
    ctrl: float32 [nu] velocity-actuator targets (`sims.fleet.robot.planar_ctrl`).

  Returns:
    The mjx.Data one physics step (model timestep) later.
  """
  with jax.numpy_rank_promotion("allow"):
    return mjx.step(model, data.replace(ctrl=ctrl))


def load_robot_model(config: FleetConfig, robot: RobotModel | None = None) -> mujoco.MjModel:
  """The robot's MjModel with the config's timestep: `robot`'s (sims/fleet/robot.py), or with None
  the built-in sims/assets/planar_robot.xml (`ROBOT_XML`) drawn at the config's radius (contacts off)."""
  return load_builtin_model(config) if robot is None else robot.mj_model(config.physics_dt)


@dataclasses.dataclass(frozen=True, eq=False)
class FleetEnv:
  """Fleet environment over a built World.

  Build with `FleetEnv.create(scenario, config)`. `reset` and `step` act on ONE
  world; batch worlds with `jax.vmap`. The shared `params` are read from the
  env; `rollout_fn` passes them to `jit` as an argument (not as constants).

  Attributes:
    world: the host World (maps, stations, zones) with its WorldParams.
    mj_model: mujoco.MjModel of one robot.
    mjx_model: mjx.Model on the device.
    data0: mjx.Data template of one robot.
    params: WorldParams used by reset/step (the world's, or tracers inside jit).
    robot: the RobotModel driven (sims/fleet/robot.py), or None for the built-in robot.
  """
  world: World
  mj_model: mujoco.MjModel
  mjx_model: mjx.Model
  data0: mjx.Data
  params: WorldParams
  robot: RobotModel | None = None

  @classmethod
  def create(cls, scenario: Scenario | None = None, config: FleetConfig = FleetConfig(), *,
             seed: int = 0, robot: RobotModel | None = None) -> "FleetEnv":
    """Builds the world and the MJX model.

    Args:
      scenario: maps (default: the built-in warehouse).
      config: fleet configuration.
      seed: host seed for station and spawn selection.
      robot: your own base (`sims.fleet.robot.load_robot`); its radius replaces
        config.robot.radius (`env.config` shows it). None: the built-in robot.

    Raises:
      ValueError: impl 'warp' without a CUDA GPU or without warp-lang, or a
        scenario problem (see build_world).
      RobotModelError: a robot that is not a RobotModel, smaller than the map's cells, or one MJX cannot run.
    """
    if config.impl == "warp" and not any(d.platform == "gpu" for d in jax.devices()):
      raise ValueError("FleetConfig.impl='warp' needs a CUDA GPU and warp-lang "
                       "(pip install 'mujoco-mjx[warp]'); use impl='jax' on CPU")
    if config.impl == "warp":
      from mujoco.mjx import warp as mjx_warp  # noqa: PLC0415 - imported (quietly) with mujoco.mjx above
      if not mjx_warp.WARP_INSTALLED:
        from sims.fleet import quiet_mjx  # noqa: PLC0415
        said = "; ".join(quiet_mjx.WARP_MESSAGES) or "warp not importable"
        raise ValueError(f"FleetConfig.impl='warp' needs warp-lang, which mujoco.mjx could not import "
                         f"({said}); pip install 'jaxfilters[warp]'")
    scenario = scenario or Scenario.default()
    if robot is not None:
      if not isinstance(robot, RobotModel):
        raise RobotModelError(f"robot must be a RobotModel (sims.fleet.robot.load_robot); got {type(robot).__name__}")
      robot.check_resolution(float(scenario.map.resolution))
      config = robot.configure(config)
    world = build_world(scenario, config, seed=seed)
    m = load_robot_model(config, robot)
    # This process's first device: MJX's default, jax.devices()[0], belongs to process 0 in a
    # multi-process (jax.distributed) run, and other processes could not use its arrays.
    device = jax.local_devices()[0]
    try:
      mx = mjx.put_model(m, impl=config.impl, device=device)
    except NotImplementedError as e:
      raise RobotModelError(f"{robot.name if robot else ROBOT_XML}: MJX cannot run it ({e})") from None
    d0 = mjx.make_data(m, impl=config.impl, device=device)   # the MjModel form works for every impl
    return cls(world=world, mj_model=m, mjx_model=mx, data0=d0, params=world.params, robot=robot)

  @property
  def config(self) -> FleetConfig:
    """The FleetConfig the world was built with."""
    return self.world.config

  @property
  def num_robots(self) -> int:
    """K, robots per world."""
    return self.config.robots_per_world

  @property
  def zone_speeds(self) -> tuple[float, ...]:
    """Extra planner speeds: 1 % under each finite zone limit, so zones are driven at their limit."""
    return tuple(0.99 * v for v in self.world.zone_speed if np.isfinite(v))

  def with_params(self, params: WorldParams) -> "FleetEnv":
    """The same env reading `params` (e.g. tracers inside jit, or a swapped mask of the same shapes).

    Args:
      params: WorldParams with the same shapes as `self.params`.

    Returns:
      A new FleetEnv; self is unchanged. Where the world reads its keepout mask on the map's
      grid (`world.keepout_grid`), a keepout mask or map of other geometry in `params` is not
      read: every robot's `keepout.error` is True and no zone is written (build a new FleetEnv
      for it).
    """
    return dataclasses.replace(self, params=params)

  # ------------------------------------------------------------------ reset

  def reset(self, key: jax.Array) -> WorldState:
    """A fresh world: K robots at distinct spawn points with random yaw and goals.

    Args:
      key: PRNG key.

    Returns:
      WorldState of one world.
    """
    p, k = self.params, self.num_robots
    k_spawn, k_yaw, k_goal, k_state = jax.random.split(key, 4)
    num_spawns = p.spawns.shape[0]
    num_stations = p.nav.stations.shape[0]
    z = self.config.robots_in_keepout
    if z:
      k_spawn, k_zone = jax.random.split(k_spawn)
      xy = jnp.concatenate([p.zone_spawns[jax.random.choice(k_zone, p.zone_spawns.shape[0], (z,), replace=False)],
                            p.spawns[jax.random.choice(k_spawn, num_spawns, (k - z,), replace=False)]])
    else:
      xy = p.spawns[jax.random.choice(k_spawn, num_spawns, (k,), replace=False)]
    yaw = jax.random.uniform(k_yaw, (k,), _F32, -jnp.pi, jnp.pi)
    qpos = jnp.concatenate([xy, yaw[:, None]], axis=1)
    data = jax.vmap(lambda q: self.data0.replace(qpos=q))(qpos)
    goal = jax.random.choice(k_goal, num_stations, (k,), replace=k > num_stations).astype(jnp.int32)
    n = self.world.window_cells
    local = Costmap(jnp.zeros((k, n, n), jnp.uint8), jnp.zeros((k, 2), _F32),
                    jnp.full((k,), p.map_resolution, _F32))
    false = jnp.zeros((k,), bool)
    metrics = metrics_lib.Metrics.zeros(k, self.world.num_zones)
    in_keepout = false
    if self.keepout_escape:
      in_keepout = jax.vmap(lambda q: metrics_lib.in_keepout(p.keepout, q))(xy)
      now = self._footprint_in_keepout(xy)
      metrics = dataclasses.replace(metrics, started_in_keepout=now, footprint_now=now,
                                    footprint_last_time=jnp.where(now, 0.0, -1.0).astype(_F32))
    return WorldState(
        data=data, cmd=jnp.zeros((k, 2), _F32), goal=goal, speed=SpeedState.create(k),
        speed_cap=jnp.full((k,), jnp.inf, _F32), keepout=KeepoutState.create(k), local=local,
        plan_lut=jax.vmap(planner.lookup_table)(local.cost, jnp.ones((k, n, n), jnp.uint8)),
        progress_anchor=xy, progress_time=jnp.zeros((k,), _F32), blocked_time=jnp.zeros((k,), _F32),
        recovery_time=jnp.zeros((k,), _F32), in_keepout=in_keepout,
        in_contact=false, in_near=false,
        metrics=metrics, key=k_state,
        time=jnp.zeros((), _F32))

  # ------------------------------------------------------------------ step

  def step(self, state: WorldState, action: jax.Array) -> WorldState:
    """Advances one world by one local-costmap period.

    Args:
      state: WorldState of one world.
      action: int32 [K] goal station per robot; -1 keeps the robot's goal.

    Returns:
      The next WorldState.
    """
    return self._advance(state, action, record_ticks=False)[0]

  def step_ticks(self, state: WorldState, action: jax.Array) -> tuple[WorldState, TickFrame]:
    """`step`, also returning what each controller tick did.

    Args:
      state: WorldState of one world.
      action: int32 [K] goal station per robot; -1 keeps the robot's goal.

    Returns:
      (the next WorldState, TickFrame with leaves [ticks_per_step, ...]).
    """
    return self._advance(state, action, record_ticks=True)

  def _advance(self, state: WorldState, action: jax.Array, *, record_ticks: bool):
    cfg = self.config
    with jax.named_scope("fleet_step"):
      action = jnp.asarray(action, jnp.int32)
      override = action >= 0
      poses = state.data.qpos[:, :3]
      state = dataclasses.replace(
          state, goal=jnp.where(override, action, state.goal),
          progress_anchor=jnp.where(override[:, None], poses[:, :2], state.progress_anchor),
          progress_time=jnp.where(override, 0.0, state.progress_time))
      state = self._update_costmaps(state)
      t0 = state.time

      def tick(s, i):
        t = t0 + i.astype(_F32) * jnp.float32(cfg.control_dt)
        pose = s.data.qpos[:, :3]
        s = self._tick(s, t)
        return s, (self._tick_frame(s, t, pose) if record_ticks else None)

      state, ticks = jax.lax.scan(tick, state, jnp.arange(cfg.ticks_per_step))
      return dataclasses.replace(state, time=state.time + jnp.asarray(cfg.step_seconds, _F32)), ticks

  def _tick_frame(self, s: WorldState, t: jax.Array, pose: jax.Array) -> TickFrame:
    return TickFrame(time=t, pose=pose, cmd=s.cmd, speed_limit=s.speed.speed_limit_prev, speed_cap=s.speed_cap)

  def _pick_goals(self, key, goal, xy):
    """A new random station per robot: not its current goal, not another robot's, > 2 m away."""
    p = self.params
    k = goal.shape[0]
    s = p.nav.stations.shape[0]
    ids = jnp.arange(s, dtype=jnp.int32)
    others = ~jnp.eye(k, dtype=bool)
    taken = jnp.any(others[:, :, None] & (goal[None, :, None] == ids[None, None, :]), axis=1)
    far = jnp.linalg.norm(p.nav.stations[None, :, :] - xy[:, None, :], axis=-1) > 2.0
    not_current = goal[:, None] != ids[None, :]
    allowed = not_current & ~taken & far
    allowed = jnp.where(jnp.any(allowed, axis=1, keepdims=True), allowed, not_current)
    logits = jnp.where(allowed, 0.0, -jnp.inf)
    return jax.vmap(jax.random.categorical)(jax.random.split(key, k), logits).astype(jnp.int32)

  @property
  def keepout_escape(self) -> bool:
    """Whether keepout escape is on (FleetConfig.keepout_escape is not 'off')."""
    return self.config.keepout_escape != "off"

  def _footprint_in_keepout(self, xy: jax.Array) -> jax.Array:
    """bool [K]: each robot's footprint (its disc) on a lethal keepout cell (jaxfilters.footprint's rule)."""
    r = self.config.robot.radius
    window = window_cells(None, r, 0.0, float(np.float32(self.world.scenario.keepout.resolution)))
    return jax.vmap(lambda q: metrics_lib.footprint_in_keepout(self.params.keepout, q, radius=r,
                                                               window=window))(xy)

  def _update_costmaps(self, state: WorldState) -> WorldState:
    return self.update_costmaps(state)

  def robot_plans(self, state: WorldState) -> tuple[jax.Array, jax.Array]:
    """Each robot's plan to its goal (`navigation.trace_plan`) for an AsymmetricInflationLayer: float32
    [K, P, 2] world metres (the local costmaps' frame) and int32 [K] points in use, P = `world.plan_points`.
    Raises ValueError for a world without such a layer (P = 0: nothing reads plans)."""
    w = self.world
    if not w.plans_needed:
      raise ValueError("robot_plans: this world's local costmaps run no AsymmetricInflationLayer "
                       "(Scenario.layers), so no plan is traced")
    poses = state.data.qpos[:, :2]
    trace = functools.partial(navigation.trace_plan, self.params.nav, num_points=w.plan_points, step=w.plan_step)
    return jax.vmap(trace)(state.goal, poses)

  def update_costmaps(self, state: WorldState) -> WorldState:
    """Rebuilds every robot's local costmap, its keepout state and the planner's table of it at the
    current poses; the layers are `world.local_inflation_layers` (an AsymmetricInflationLayer reads
    each robot's own plan, `robot_plans`, and position)."""
    cfg, p = self.config, self.params
    poses = state.data.qpos[:, :3]
    paths = lengths = None
    if self.world.plans_needed:       # static: the default fleet traces nothing
      paths, lengths = self.robot_plans(state)
    local, kstate = local_costmap.local_costmaps(
        p.static_cost, p.map_origin, p.map_resolution, self.world.pad, p.keepout, poses,
        state.keepout, n=self.world.window_cells, robot_radius=cfg.robot.radius,
        inflation=self.world.inflation, keepout_config=self.world.keepout_config,
        layers=self.world.local_inflation_layers, paths=paths, path_lengths=lengths,
        direction=p.direction, honour_lanes=p.honour_lanes, grid=self.world.keepout_grid)
    return dataclasses.replace(state, local=local, keepout=kstate,
                               plan_lut=jax.vmap(planner.lookup_table)(local.cost))

  def _tick(self, s: WorldState, t0=None) -> WorldState:
    """One controller tick starting at time t0 (s; default s.time): the controller's command,
    then `substeps_per_tick` physics steps."""
    s, v, w = self._control(s)
    return self._physics(s, v, w, s.time if t0 is None else t0)

  def _control(self, s: WorldState) -> tuple[WorldState, jax.Array, jax.Array]:
    """Speed filter, goals and progress checker, recovery, planner and the clip of one tick.

    Returns:
      (the state with the tick's controller fields updated, v float32 [K] m/s, w float32 [K] rad/s).
    """
    cfg, p = self.config, self.params
    r = cfg.robot
    k = self.num_robots
    dt = cfg.control_dt
    poses = s.data.qpos[:, :3]
    key, k_goal = jax.random.split(s.key)

    # Speed filter (Nav2 SpeedFilter::process at the robot pose; state carried).
    speed_state, res = speed_filter(p.speed, poses, s.speed)
    cap = planner.limit_to_speed(res.speed_limit, res.percentage, jnp.ones((k,), bool), r.max_speed)

    # Goals and progress checker.
    reached = jnp.linalg.norm(poses[:, :2] - p.nav.stations[s.goal], axis=-1) < cfg.planner.goal_tolerance
    moved = jnp.linalg.norm(poses[:, :2] - s.progress_anchor, axis=-1) > cfg.progress_radius
    ptime = jnp.where(moved, 0.0, s.progress_time + dt)
    stuck = ptime > cfg.progress_timeout
    new_goal = reached | stuck
    goal = jnp.where(new_goal, self._pick_goals(k_goal, s.goal, poses[:, :2]), s.goal)
    anchor = jnp.where((moved | new_goal)[:, None], poses[:, :2], s.progress_anchor)
    ptime = jnp.where(new_goal, 0.0, ptime)
    m = dataclasses.replace(s.metrics, goals_reached=s.metrics.goals_reached + reached.astype(jnp.int32),
                            stuck_events=s.metrics.stuck_events + stuck.astype(jnp.int32))

    # Recovery mode after being blocked (robot-robot deadlocks).
    slow = jnp.linalg.norm(s.data.qvel[:, :2], axis=-1) < 0.02
    blocked = jnp.where(slow & ~new_goal & (s.recovery_time <= 0), s.blocked_time + dt, 0.0)
    start = blocked > cfg.planner.recovery_after
    recovery = jnp.where(start, cfg.planner.recovery_duration, jnp.maximum(s.recovery_time - dt, 0.0))
    blocked = jnp.where(start, 0.0, blocked)

    # Local planner, then the hard clip to the limit in force.
    # In a zone (escape mode on): steer by the exit field, nav.dist[S], the shortest way out.
    steer = jnp.where(s.keepout.is_pose_lethal, p.nav.stations.shape[0], goal) if self.keepout_escape else goal
    cmd, stopped = self._plan(s, poses, steer, cap, recovery > 0)
    v = jnp.clip(cmd[:, 0], -cap, cap)
    w = cmd[:, 1]
    if cfg.limit_angular:
      w_cap = r.max_yaw_rate * jnp.minimum(cap / r.max_speed, 1.0)
      w = jnp.clip(w, -w_cap, w_cap)
    cmd = jnp.stack([v, w], axis=1)
    m = dataclasses.replace(m, emergency_stops=m.emergency_stops + stopped.astype(jnp.int32))
    s = dataclasses.replace(
        s, cmd=cmd, goal=goal, speed=speed_state, speed_cap=cap, progress_anchor=anchor,
        progress_time=ptime, blocked_time=blocked, recovery_time=recovery, metrics=m, key=key)
    return s, v, w

  def _plan(self, s: WorldState, poses: jax.Array, goal: jax.Array, cap: jax.Array,
            recovering: jax.Array) -> tuple[jax.Array, jax.Array]:
    """The local planner of every robot: (command float32 [K, 2], stopped bool [K])."""
    p, k = self.params, self.num_robots
    plan = functools.partial(planner.plan_lut_one, nav=p.nav, speed_mask=p.speed, speed_cap=p.speed_cap,
                             config=self.config, extra_speeds=self.zone_speeds)
    cmd, info = jax.vmap(plan, in_axes=(0, 0, 0, 0, 0, 0, 0, 0, None, 0))(
        poses, s.cmd, goal, cap, recovering, s.plan_lut, s.local.origin,
        s.local.resolution, poses[:, :2], ~jnp.eye(k, dtype=bool))
    return cmd, info["stopped"]

  def _physics(self, s: WorldState, v: jax.Array, w: jax.Array, t0: jax.Array) -> WorldState:
    """`substeps_per_tick` physics steps at the twist (v, w) from time t0 (s) with the per-step
    metrics, then proximity."""
    cfg, p = self.config, self.params

    def substep(carry, j):
      data, m, in_k = carry
      ctrl = planar_ctrl(self.robot, v, w, data.qpos[:, 2])
      xy0 = data.qpos[:, :2]
      data = jax.vmap(lambda d, u: mjx_step(self.mjx_model, d, u))(data, ctrl)
      xy = data.qpos[:, :2]
      speed = jnp.linalg.norm(data.qvel[:, :2], axis=-1)
      zone = jax.vmap(lambda q: metrics_lib.zone_at(p.speed, p.zone_table, q))(xy)
      kin = jax.vmap(lambda q: metrics_lib.in_keepout(p.keepout, q))(xy)
      m, in_k = metrics_lib.physics_update(m, in_k, xy, jnp.linalg.norm(xy - xy0, axis=-1), speed,
                                           zone, kin, cfg.physics_dt)
      if p.direction is not None:       # one-way lanes (static: no work without a direction mask)
        m = metrics_lib.wrong_way_update(m, jax.vmap(lambda q, u: metrics_lib.wrong_way(p.direction, q, u))(
            xy, data.qvel[:, :2]))
      if self.keepout_escape:
        t = t0 + (j + 1).astype(_F32) * jnp.float32(cfg.physics_dt)
        m = metrics_lib.footprint_update(m, self._footprint_in_keepout(xy), t)
      return (data, m, in_k), None

    (data, m, in_k), _ = jax.lax.scan(substep, (s.data, s.metrics, s.in_keepout), jnp.arange(cfg.substeps_per_tick))
    m, contact, near = metrics_lib.proximity_update(m, s.in_contact, s.in_near, data.qpos[:, :2],
                                                   cfg.robot.radius, cfg.near_miss_margin)
    return dataclasses.replace(s, data=data, in_keepout=in_k, in_contact=contact, in_near=near, metrics=m)

  # ------------------------------------------------------------------ batching

  def frame(self, state: WorldState) -> Frame:
    """The recorded view of one world's state.

    Args:
      state: WorldState of one world.

    Returns:
      Frame with leaves [K, ...]: pose, speed (m/s), last command, goal, speed cap in force.
    """
    return Frame(pose=state.data.qpos[:, :3], speed=jnp.linalg.norm(state.data.qvel[:, :2], axis=-1),
                 cmd=state.cmd, goal=state.goal, speed_cap=state.speed_cap)

  def world_keys(self, key: jax.Array, num_worlds: int) -> jax.Array:
    """Per-world keys fold_in(key, w): world w's key does not depend on num_worlds.

    Args:
      key: PRNG key.
      num_worlds: W.

    Returns:
      uint32 [W, 2] keys, one per world.
    """
    return jax.vmap(lambda i: jax.random.fold_in(key, i))(jnp.arange(num_worlds))

  def reset_fn(self, *, mesh: jax.sharding.Mesh | None = None):
    """jit(vmap(reset)) over worlds: keys [W, 2] -> WorldState [W].

    With a 1-D `mesh` (sims/scale/sharding.py) the world axis of keys and states is
    sharded over its devices and params are replicated; W must split evenly.
    """
    fn = lambda params, keys: jax.vmap(self.with_params(params).reset)(keys)
    if mesh is None:
      return jax.jit(fn)
    worlds = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec(mesh.axis_names[0]))
    rep = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec())
    return jax.jit(fn, in_shardings=(rep, worlds), out_shardings=worlds)

  def rollout_fn(self, num_steps: int, *, record: bool = True, record_ticks: bool = False,
                 record_costmaps: int = 0, mesh: jax.sharding.Mesh | None = None) -> "Rollout":
    """A jitted rollout of `num_steps` env steps over W worlds (`lax.scan` of `vmap(step)`).

    `run(params, states, actions=None)` takes the WorldParams (a jit argument,
    so maps are not baked into the program), states WorldState [W] and
    optional actions int32 [num_steps, W, K] (None: no goal overrides). It
    returns (final states, frames) with Frame leaves [num_steps, W, K, ...],
    or None frames when record is False. Calling it again with new states of
    the same shapes compiles nothing. With a 1-D `mesh` (sims/scale/sharding.py)
    the world axis of states, actions and frames is sharded over its devices
    and params are replicated; the results equal the unsharded ones.

    With `record_ticks` the frames are a `Recording` instead: the Frame per
    step, a TickFrame per controller tick (leaves [num_steps, ticks_per_step,
    W, K, ...]) and, with `record_costmaps` = L > 0, the local costmaps of the
    first L robots (world-major order) at each step (`Costmap` leaves
    [num_steps, L, ...], cost uint8 [num_steps, L, N, N]).

    Args:
      num_steps: env steps per call (1 / costmap_hz seconds each).
      record: return a Frame per step (False: frames are None).
      record_ticks: return a Recording with per-tick frames (implies record).
      record_costmaps: L, local costmaps recorded per step (needs record_ticks;
        at most W * K, checked when called).
      mesh: optional 1-D jax.sharding.Mesh over the world axis.

    Returns:
      A Rollout (callable; `.compile(params, states)` compiles ahead of time).

    Raises:
      ValueError: record_costmaps < 0, or > 0 without record_ticks; record_ticks with a mesh.
    """
    if not isinstance(record_costmaps, int) or record_costmaps < 0:
      raise ValueError(f"record_costmaps must be an int >= 0; got {record_costmaps!r}")
    if record_costmaps and not record_ticks:
      raise ValueError("record_costmaps needs record_ticks=True")
    if record_ticks and mesh is not None:
      raise ValueError("record_ticks records on one device: build the rollout without a mesh")
    record = record or record_ticks

    def run(params, states, actions):
      env = self.with_params(params)

      def body(s, a):
        if not record_ticks:
          s = jax.vmap(env.step)(s, a)
          return s, (jax.vmap(env.frame)(s) if record else None)
        s, ticks = jax.vmap(env.step_ticks)(s, a)
        ticks = jax.tree.map(lambda x: jnp.swapaxes(x, 0, 1), ticks)   # [W, T, ...] -> [T, W, ...]
        local = None
        if record_costmaps:
          flat = jax.tree.map(lambda x: x.reshape((-1,) + x.shape[2:]), s.local)
          if record_costmaps > flat.cost.shape[0]:
            raise ValueError(f"record_costmaps ({record_costmaps}) exceeds the robots of the rollout "
                             f"({flat.cost.shape[0]})")
          local = jax.tree.map(lambda x: x[:record_costmaps], flat)
        return s, Recording(frame=jax.vmap(env.frame)(s), ticks=ticks, costmaps=local)

      return jax.lax.scan(body, states, actions)

    if mesh is None:
      return Rollout(jax.jit(run), num_steps, self.num_robots)
    spec = jax.sharding.PartitionSpec
    worlds = jax.sharding.NamedSharding(mesh, spec(mesh.axis_names[0]))
    time_major = jax.sharding.NamedSharding(mesh, spec(None, mesh.axis_names[0]))
    rep = jax.sharding.NamedSharding(mesh, spec())
    jitted = jax.jit(run, in_shardings=(rep, worlds, time_major),
                     out_shardings=(worlds, time_major if record else None))
    return Rollout(jitted, num_steps, self.num_robots)


@pytree_dataclass
class Recording:
  """What a rollout built with `record_ticks=True` returns per env step.

  Attributes:
    frame: Frame, leaves [num_steps, W, K, ...].
    ticks: TickFrame, leaves [num_steps, ticks_per_step, W, K, ...] (time [num_steps, ticks_per_step, W]).
    costmaps: Costmap of the first L robots, leaves [num_steps, L, ...], or None.
  """
  frame: Frame
  ticks: TickFrame
  costmaps: Costmap | None


class Rollout:
  """A jitted fleet rollout; `actions=None` is filled in on the host, so it never retraces.

  Call it as `run(params, states, actions=None)`; `run.compile(params, states)`
  compiles ahead of time (for timing) and returns a callable of the same form.
  """

  def __init__(self, jitted, num_steps: int, robots_per_world: int):
    self.jitted = jitted
    self.num_steps = num_steps
    self.robots_per_world = robots_per_world
    self._idle = {}

  def _actions(self, states: WorldState, actions):
    if actions is not None:
      return actions
    num_worlds = states.time.shape[0]
    if num_worlds not in self._idle:
      self._idle[num_worlds] = jnp.full((self.num_steps, num_worlds, self.robots_per_world), -1, jnp.int32)
    return self._idle[num_worlds]

  def __call__(self, params: WorldParams, states: WorldState, actions=None):
    """Runs the rollout.

    Args:
      params: WorldParams (shared by every world).
      states: WorldState [W].
      actions: optional int32 [num_steps, W, K] goal overrides (-1 keeps the
        current goal); None: no overrides.

    Returns:
      (final WorldState [W], Frame with leaves [num_steps, W, K, ...] or None
      when the rollout was built with record=False).
    """
    return self.jitted(params, states, self._actions(states, actions))

  def lower(self, params: WorldParams, states: WorldState, actions=None):
    """`jax.jit(...).lower` of the rollout for these arguments (see `__call__`); for inspecting HLO."""
    return self.jitted.lower(params, states, self._actions(states, actions))

  def compile(self, params: WorldParams, states: WorldState):
    """Compiles ahead of time (to time compilation apart from running).

    Args:
      params, states: example arguments; later calls must have the same shapes.

    Returns:
      A callable `(params, states, actions=None) -> (states, frames)` like `__call__`.
    """
    compiled = self.lower(params, states).compile()
    return lambda params, states, actions=None: compiled(params, states, self._actions(states, actions))

  def _cache_size(self) -> int:
    return self.jitted._cache_size()
