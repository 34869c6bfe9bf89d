"""Frozen, hashable configuration of the MJX fleet, validated eagerly where it is set.

Every field here is static under `jit` (it picks shapes or code paths); change
one with `dataclasses.replace` and expect one new compile. Units are SI.
"""

from __future__ import annotations

import dataclasses
import math

IMPLS = ("jax", "warp")
KEEPOUT_ESCAPE = ("off", "center", "footprint")


def _positive(owner: str, name: str, value, *, allow_zero: bool = False) -> float:
  if isinstance(value, bool):
    raise ValueError(f"{owner}.{name} must be a number; got {value!r}")
  try:
    v = float(value)
  except (TypeError, ValueError):
    raise ValueError(f"{owner}.{name} must be a number; got {value!r}") from None
  if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
    want = ">= 0" if allow_zero else "> 0"
    raise ValueError(f"{owner}.{name} must be finite and {want}; got {value!r}")
  return v


def _count(owner: str, name: str, value, lo: int = 1) -> int:
  if isinstance(value, bool) or int(value) != value or int(value) < lo:
    raise ValueError(f"{owner}.{name} must be an integer >= {lo}; got {value!r}")
  return int(value)


def _ratio(owner: str, a_name: str, a: float, b_name: str, b: float) -> int:
  """The integer a / b (within 1e-6), or ValueError naming both."""
  n = a / b
  if abs(n - round(n)) > 1e-6 * max(1.0, n) or round(n) < 1:
    raise ValueError(f"{owner}: {a_name} / {b_name} must be a whole number >= 1; got {a} / {b} = {n:.6g}")
  return int(round(n))


@dataclasses.dataclass(frozen=True)
class RobotConfig:
  """A differential-drive robot (Nav2 bringup defaults where Nav2 has one).

  Attributes:
    radius: m, circular footprint (Nav2 `robot_radius`).
    max_speed: m/s, linear speed cap; percent speed limits are relative to it.
    max_yaw_rate: rad/s.
    max_accel: m/s^2, linear acceleration and deceleration limit.
    max_yaw_accel: rad/s^2.
    footprint_padding: m, Nav2 `footprint_padding` (used for the inscribed radius).
  """
  radius: float = 0.22
  max_speed: float = 0.5
  max_yaw_rate: float = 1.5
  max_accel: float = 1.0
  max_yaw_accel: float = 3.0
  footprint_padding: float = 0.01

  def __post_init__(self):
    for f in dataclasses.fields(self):
      object.__setattr__(self, f.name, _positive("RobotConfig", f.name, getattr(self, f.name),
                                                 allow_zero=f.name == "footprint_padding"))


@dataclasses.dataclass(frozen=True)
class PlannerConfig:
  """The local planner: enumerated (v, w) targets rolled out with acceleration limits.

  Attributes:
    num_speeds: linear speed targets, evenly spaced in [0, max_speed].
    num_yaw_rates: yaw-rate targets, evenly spaced in [-max_yaw_rate, max_yaw_rate] (odd
      keeps 0).
    horizon: s, rollout length.
    rollout_dt: s, rollout step; collisions are also checked at interval midpoints.
    progress_weight, heading_weight, clearance_weight, speed_weight: score terms
      (progress along the navigation function per metre of reach, heading error to
      the field's descent direction in [0, 1], the highest cost along the rollout /
      252, and the unused fraction of max speed).
    goal_tolerance: m, Nav2 `xy_goal_tolerance`.
    monitor_margin: m, collision monitor: a candidate may not bring the robot
      closer than 2 * radius + monitor_margin to another robot's current position
      (unless it moves away from it).
    recovery_after: s, a robot slower than 0.02 m/s (not at its goal) for this
      long enters recovery: for `recovery_duration` s its score drops the heading
      term, rewards separation from other robots and prefers turning right
      (right-hand passing), which breaks symmetric robot-robot deadlocks.
    recovery_duration: s.
    reverse_speed: m/s, the backing-up speed candidates use (recovery mode only).
    cost_weight: score per unit of the mean cost along the rollout / 252 (the
      rollout points' costs, lethal and inscribed counted as 0 since they
      are rules, not costs): a gradient critic like MPPI's CostCritic, so a
      robot inside a band of raised costs (an AsymmetricInflationLayer's
      disfavoured side) moves toward its low side. 0 (the default) leaves it out
      of the program; the highest cost along the rollout stays in
      `clearance_weight`.
    keep_right_weight: score against left turns while another robot is ahead
      within 2 m (right-hand traffic, so robots meeting head-on both veer right).
    inscribed_is_collision: a rollout point on an inscribed (253) cell collides
      even when the robot stands on one: Nav2's controllers' rule for a
      circular robot (the centre on 253 means the footprint touches an
      obstacle). Off by default, so a robot can leave another robot's
      inflation; the keepout escape scenarios turn it on, where it is the rule
      that traps a robot in a zone's inscribed band (issue #6505).
  """
  num_speeds: int = 6
  num_yaw_rates: int = 9
  horizon: float = 1.5
  rollout_dt: float = 0.1
  progress_weight: float = 1.0
  heading_weight: float = 0.35
  clearance_weight: float = 0.3
  speed_weight: float = 0.05
  goal_tolerance: float = 0.25
  monitor_margin: float = 0.15
  recovery_after: float = 3.0
  recovery_duration: float = 3.0
  reverse_speed: float = 0.15
  keep_right_weight: float = 0.3
  inscribed_is_collision: bool = False
  cost_weight: float = 0.0

  def __post_init__(self):
    if not isinstance(self.inscribed_is_collision, bool):
      raise ValueError(f"PlannerConfig.inscribed_is_collision must be a bool; got {self.inscribed_is_collision!r}")
    object.__setattr__(self, "num_speeds", _count("PlannerConfig", "num_speeds", self.num_speeds, 2))
    object.__setattr__(self, "num_yaw_rates", _count("PlannerConfig", "num_yaw_rates", self.num_yaw_rates))
    for name in ("horizon", "rollout_dt", "goal_tolerance", "recovery_after", "recovery_duration"):
      object.__setattr__(self, name, _positive("PlannerConfig", name, getattr(self, name)))
    for name in ("progress_weight", "heading_weight", "clearance_weight", "speed_weight",
                 "monitor_margin", "reverse_speed", "keep_right_weight", "cost_weight"):
      object.__setattr__(self, name, _positive("PlannerConfig", name, getattr(self, name), allow_zero=True))
    _ratio("PlannerConfig", "horizon", self.horizon, "rollout_dt", self.rollout_dt)

  @property
  def num_rollout_steps(self) -> int:
    """Rollout points per candidate: horizon / rollout_dt (a whole number, checked at construction)."""
    return _ratio("PlannerConfig", "horizon", self.horizon, "rollout_dt", self.rollout_dt)


@dataclasses.dataclass(frozen=True)
class FleetConfig:
  """One simulated world: `robots_per_world` robots sharing one warehouse.

  Attributes:
    robots_per_world: K robots per world; they see each other (local costmaps,
      collision monitor, proximity metrics). Worlds are independent and batched
      by `jax.vmap`, so B = num_worlds * K robots in total.
    robot: RobotConfig.
    planner: PlannerConfig.
    controller_hz: Nav2 `controller_frequency` (20 Hz).
    costmap_hz: local costmap `update_frequency` (5 Hz); controller_hz / costmap_hz
      must be whole: one env step is one costmap period.
    physics_dt: s, MuJoCo timestep; 1 / (controller_hz * physics_dt) must be whole.
    local_costmap_size: m, side of the square rolling window (Nav2 3 m).
    inflation_radius: m, local and global inflation (Nav2 bringup 0.55).
    cost_scaling_factor: 1/m (Nav2 bringup 3.0).
    nav_resolution: m, target cell size of the shared navigation grid (a whole
      multiple of the map resolution is used).
    num_stations: goal stations picked on the map.
    limit_angular: also scale the yaw rate by the speed limit (Nav2 consumers
      scale all axes in absolute mode; off by default: linear only).
    progress_radius, progress_timeout: Nav2 SimpleProgressChecker (0.5 m in
      10 s); a robot that fails it counts as stuck and gets a new goal.
    near_miss_margin: m, robot pairs closer than 2 * radius + this count as a near miss
      (closer than 2 * radius is a contact).
    speed_tolerance: m/s, physics tolerance of the compliance check (the
      velocity actuators lag the command with a 0.01 s time constant).
    impl: MJX implementation, 'jax' (default, the CPU path) or 'warp' (GPU
      only, needs warp-lang).
    keepout_escape: the local costmaps' keepout: 'off' (Nav2's default
      placement: the filter after inflation, no escape mode), 'center' (the
      filter as a layer before inflation with Nav2's escape mode,
      `override_lethal_cost`, and its centre-cell test) or 'footprint' (the
      same with the footprint test of jaxfilters/footprint.py and
      `band_clearance`). With escape, a robot in a zone heads for the nearest
      way out (the exit field, WorldParams.nav.dist[S]), the footprint keepout
      metrics are recorded, and the inflation's inscribed radius is raised to
      `world.keepout_inscribed_radius` so that the planner, which checks the
      cell under the robot centre, keeps the footprint out of zones.
    robots_in_keepout: robots per world that start with their footprint on a
      lethal keepout cell (spawn points from WorldParams.zone_spawns); the
      rest start on clear cells.
    honour_lanes: with a direction mask (Scenario.direction, one-way lanes):
      True makes every lane cell a robot's heading is not allowed on lethal in
      its local costmap; False only measures wrong-way driving (the baseline
      the lanes are compared with). Without a direction mask it changes nothing.
      Carried as data (WorldParams.honour_lanes), so both settings run one
      compiled program.
  """
  robots_per_world: int = 8
  robot: RobotConfig = RobotConfig()
  planner: PlannerConfig = PlannerConfig()
  controller_hz: float = 20.0
  costmap_hz: float = 5.0
  physics_dt: float = 0.01
  local_costmap_size: float = 3.0
  inflation_radius: float = 0.55
  cost_scaling_factor: float = 3.0
  nav_resolution: float = 0.1
  num_stations: int = 24
  limit_angular: bool = False
  progress_radius: float = 0.5
  progress_timeout: float = 10.0
  near_miss_margin: float = 0.05
  speed_tolerance: float = 0.01
  impl: str = "jax"
  keepout_escape: str = "off"
  robots_in_keepout: int = 0
  honour_lanes: bool = True

  def __post_init__(self):
    o = "FleetConfig"
    object.__setattr__(self, "robots_per_world", _count(o, "robots_per_world", self.robots_per_world))
    object.__setattr__(self, "num_stations", _count(o, "num_stations", self.num_stations, 2))
    if not isinstance(self.robot, RobotConfig):
      raise ValueError(f"{o}.robot must be a RobotConfig; got {type(self.robot).__name__}")
    if not isinstance(self.planner, PlannerConfig):
      raise ValueError(f"{o}.planner must be a PlannerConfig; got {type(self.planner).__name__}")
    for name in ("controller_hz", "costmap_hz", "physics_dt", "local_costmap_size",
                 "inflation_radius", "cost_scaling_factor", "nav_resolution", "progress_radius",
                 "progress_timeout"):
      object.__setattr__(self, name, _positive(o, name, getattr(self, name)))
    for name in ("near_miss_margin", "speed_tolerance"):
      object.__setattr__(self, name, _positive(o, name, getattr(self, name), allow_zero=True))
    if not isinstance(self.honour_lanes, bool):
      raise ValueError(f"{o}.honour_lanes must be a bool; got {self.honour_lanes!r}")
    if not isinstance(self.limit_angular, bool):
      raise ValueError(f"{o}.limit_angular must be a bool; got {self.limit_angular!r}")
    if self.impl not in IMPLS:
      raise ValueError(f"{o}.impl must be one of {IMPLS}; got {self.impl!r}")
    if self.keepout_escape not in KEEPOUT_ESCAPE:
      raise ValueError(f"{o}.keepout_escape must be one of {KEEPOUT_ESCAPE}; got {self.keepout_escape!r}")
    object.__setattr__(self, "robots_in_keepout", _count(o, "robots_in_keepout", self.robots_in_keepout, 0))
    if self.robots_in_keepout > self.robots_per_world:
      raise ValueError(f"{o}.robots_in_keepout must be <= robots_per_world ({self.robots_per_world}); "
                       f"got {self.robots_in_keepout}")
    if self.robots_in_keepout and self.keepout_escape == "off":
      raise ValueError(f"{o}.robots_in_keepout = {self.robots_in_keepout} needs keepout_escape 'center' or "
                       "'footprint': without escape mode a robot started in a zone is deadlocked (docs/nav2_semantics.md §4.6)")
    if self.num_stations < 2:
      raise ValueError(f"{o}.num_stations must be >= 2; got {self.num_stations}")
    _ratio(o, "controller_hz", self.controller_hz, "costmap_hz", self.costmap_hz)
    _ratio(o, "1 / controller_hz", 1.0 / self.controller_hz, "physics_dt", self.physics_dt)
    if self.local_costmap_size < 2 * (self.robot.max_speed * self.planner.horizon + self.robot.radius):
      raise ValueError(f"{o}.local_costmap_size ({self.local_costmap_size} m) must cover the planner's "
                       f"reach on both sides: >= 2 * (max_speed * horizon + radius) = "
                       f"{2 * (self.robot.max_speed * self.planner.horizon + self.robot.radius):.3g} m")

  @property
  def control_dt(self) -> float:
    """Seconds per controller tick (1 / controller_hz)."""
    return 1.0 / self.controller_hz

  @property
  def ticks_per_step(self) -> int:
    """Controller ticks per env step (one local-costmap period)."""
    return _ratio("FleetConfig", "controller_hz", self.controller_hz, "costmap_hz", self.costmap_hz)

  @property
  def substeps_per_tick(self) -> int:
    """Physics steps per controller tick."""
    return _ratio("FleetConfig", "1 / controller_hz", 1.0 / self.controller_hz, "physics_dt", self.physics_dt)

  @property
  def step_seconds(self) -> float:
    """Simulated seconds per env step."""
    return 1.0 / self.costmap_hz
