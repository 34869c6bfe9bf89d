"""The fleet as a reinforcement-learning environment with MuJoCo Playground's `MjxEnv` contract.

    env = NavEnv.create()                                   # built-in warehouse, 1 robot per env
    state = env.reset(jax.random.PRNGKey(0))                # State(data, obs, reward, done, metrics, info)
    state = env.step(state, jnp.array([1.0, 0.0]))          # (v, w) in [-1, 1]

    train_env = wrapper.wrap_for_brax_training(             # mujoco_playground._src.wrapper
        env, episode_length=200, full_reset=True,
        randomization_fn=functools.partial(randomize_zones_and_goals, rng=keys))

One env is one world of K = `FleetConfig.robots_per_world` robots (1 by
default), built from the same `World` as `sims.fleet.env.FleetEnv`. One env step is
one local-costmap period (1 / costmap_hz, 0.2 s): `ticks_per_step` controller
ticks (20 Hz) of `substeps_per_tick` physics steps each.

Agents (`NavEnvConfig.agents`): "world" (the default, described below) makes the env one
agent; "per_robot" makes each robot an agent driven by one shared policy: obs [K, 98],
action [K, 2], reward, done and metrics [K], robot-robot contacts counted and penalised, a
robot respawned when its episode ends (`sims.rl.agents`).

Two modes (`NavEnvConfig.mode`):

* `"velocity"`: the action is float32 [2K], each robot's (v, w) in [-1, 1]
  scaled to (max_speed, max_yaw_rate). Every controller tick the command ramps
  toward it within the robot's acceleration limits, the Nav2 speed filter runs
  at the robot's pose (its state carried) and `clip_command` clips it to the
  limit in force, exactly as the fleet does; then MJX steps. Entering a lethal
  keepout cell ends the episode (`keepout="terminate"`) or only costs reward
  (`"penalty"`); touching a static obstacle (the robot centre on an inscribed
  or lethal cell of the inflated static layer, or off the map) always ends it.
* `"navigation"`: the action is int32 [K] goal station ids (-1 keeps the
  current goal), and the landed navigation stack (`FleetEnv.step`: local
  costmaps, planner, speed filter, clip) drives; the reward counts goals.

Observation (velocity mode), per robot, concatenated over K (float32 [K * 98]):
a `crop_cells` x `crop_cells` crop of the cost around the robot in its own
frame (max of the inflated static layer, inflated by a params file's local costmap
InflationLayer (`Scenario.layers`) or else the fleet's inflation, and
`jaxfilters.query.keepout_cost_at`, / 255, 81 values by default), the speed limit in force (cap / max_speed,
limited flag), the limit at 3 points ahead, the goal in the robot frame (dx, dy
/ 5 m, distance / 10 m, clipped), the navigation field's descent direction
(robot frame) and distance / 20 m, the velocity (commanded v, w and measured
speed, normalised), and the nearest other robot (robot frame, distance; 1.0
when there is none).

Reward (velocity mode), per robot, summed over K: `progress_weight` x metres of
navigation-distance progress, + `goal_bonus` per goal reached (a new goal is
then drawn), - `keepout_penalty` per keepout entry, - `collision_penalty`,
- `speed_penalty` x seconds above the mask's limit at the robot's position
(+ `FleetConfig.speed_tolerance`), - `clip_penalty` x (m/s x s) of commanded
speed the filter had to clip, - `approach_penalty` x (m/s x s) of command above
the limit 0.25-0.5 m ahead, - `time_penalty` per step.

Value problems never raise under `jit` (a traced value cannot be tested in Python): a velocity action
outside [-1, 1] is clipped and a non-finite one zeroed, and both are counted in
`metrics["bad_action"]`; a navigation action outside [-1, S) keeps the robot's
goal and is counted there too. Static problems (shape, dtype) raise
`ValueError`/`TypeError` at trace time.

The world (maps, navigation field, speed and keepout masks) and the goal
distribution ride in the model: `NavModel` is an `mjx.Model` with one more
pytree field, `task`, so Playground's domain-randomisation wrapper batches
zones and goals like any model field (`sims.rl.randomization.randomize_zones_and_goals`).

Auto-reset: Playground's `BraxAutoResetWrapper(full_reset=False)` restores
`data` and `obs` but not `info`; `step` notices (the pose differs from the one
it left) and restarts the per-episode state (command, speed-filter state), so
both reset styles are consistent. `full_reset=True` also draws a new goal.
"""

import copy
import dataclasses

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from ml_collections import config_dict

from sims.fleet.quiet_mjx import expected_warp_lines

with expected_warp_lines():
  from mujoco import mjx

try:
  from mujoco_playground._src import mjx_env
except ImportError as e:  # pragma: no cover - exercised only without the extra
  raise ImportError("sims.rl.env needs MuJoCo Playground: pip install 'jaxfilters[rl]' "
                    f"(playground==0.2.0; {e})") from None

from jaxfilters import constants
from jaxfilters.asymmetric_inflation import AsymmetricInflationConfig
from jaxfilters.inflation import inflate
from jaxfilters.speed import SpeedState, speed_filter
from jaxfilters.static_layer import static_layer
from sims.fleet import navigation, planner, topk
from sims.rl import agents, kernels, observation
from sims.rl.observation import AHEAD
from sims.rl.task import NavTask
from sims.rl.kernels import clip_command
from sims.fleet.config import FleetConfig
from sims.fleet.env import ROBOT_XML, FleetEnv, WorldState, mjx_step
from sims.fleet.robot import RobotModel, planar_ctrl
from sims.fleet.scenario import Scenario
from sims.fleet.layouts import LayoutBank, LayoutConfig, bank_from_worlds, layout_worlds
from sims.fleet.world import STATIC_LAYER

_F32 = jnp.float32
MODES = ("velocity", "navigation")
KEEPOUT_MODES = ("terminate", "penalty")
AGENTS = ("world", "per_robot")
MAX_LAYOUTS = 1024         # zone layouts in a bank: each is a world built on the host, with map-sized masks
State = mjx_env.State


# ----------------------------------------------------------------------------- config


MAX_CONFIG_VALUE = 1e6     # largest float of a NavEnvConfig (reward weights, metres)


@dataclasses.dataclass(frozen=True)
class NavEnvConfig:
  """Static options of `NavEnv` (one compile per distinct config).

  Attributes:
    mode: "velocity" (action (v, w) per robot) or "navigation" (action = goal station ids).
    keepout: "terminate" (a keepout entry ends the episode) or "penalty" (it only costs reward).
    crop_cells: side of the observed cost crop (odd, >= 3).
    crop_spacing: m between crop samples (9 x 0.25 m covers 2 m around the robot).
    progress_weight: reward per metre of navigation-distance progress.
    goal_bonus: reward per goal reached.
    keepout_penalty: reward subtracted per keepout entry.
    collision_penalty: reward subtracted when the robot touches a static obstacle.
    speed_penalty: reward subtracted per second above the mask's speed limit.
    clip_penalty: reward subtracted per (m/s x s) of command the speed filter clipped.
    approach_penalty: reward subtracted per (m/s x s) by which the command at the end of a
      step exceeds the strictest speed-mask limit 0.25-0.5 m ahead in the direction of
      motion (teaches braking before
      a slower zone, where the reactive filter can only clip one controller tick late).
    time_penalty: reward subtracted per env step.
    goal_max_distance: m of navigation-field distance: a new goal is drawn among the stations
      at most this far from the robot (and more than 2 m away in a straight line), so every goal
      is reachable within an episode; 0 draws from every station.
    costmap_stop: velocity mode: the env stops a robot's linear command when its footprint
      would touch a keepout zone or a static obstacle within one control tick's travel plus
      0.1 m (turning stays free; `rl_kernels.costmap_stop`), the costmap check a Nav2
      controller applies to its own trajectories; metrics["costmap_stops"] counts the stopped
      robot-ticks. False: the policy alone keeps out (entries and collisions are counted and
      penalised). With agents "per_robot" it also stops a robot before another robot's disc.
    agents: "world": one agent per env (the K robots' observations concatenated [K * 98], action
      [2K], reward summed, done when one robot's episode ends); "per_robot" (velocity mode only):
      one agent per robot driven by one shared policy (`sims.rl.agents`): obs [K, 98], action
      [K, 2], reward, done and metrics [K]; a robot whose episode ends is respawned while the
      world goes on; a robot-robot contact ends both robots' episodes.
  """
  mode: str = "velocity"
  keepout: str = "terminate"
  crop_cells: int = 9
  crop_spacing: float = 0.25
  progress_weight: float = 1.0
  goal_bonus: float = 5.0
  keepout_penalty: float = 10.0
  collision_penalty: float = 10.0
  speed_penalty: float = 100.0
  clip_penalty: float = 2.0
  approach_penalty: float = 20.0
  time_penalty: float = 0.01
  goal_max_distance: float = 10.0
  costmap_stop: bool = False
  agents: str = "world"

  def __post_init__(self):
    if self.mode not in MODES:
      raise ValueError(f"NavEnvConfig.mode must be one of {MODES}; got {self.mode!r}")
    if self.keepout not in KEEPOUT_MODES:
      raise ValueError(f"NavEnvConfig.keepout must be one of {KEEPOUT_MODES}; got {self.keepout!r}")
    if self.agents not in AGENTS or (self.agents == "per_robot" and self.mode != "velocity"):
      raise ValueError(f"NavEnvConfig.agents must be one of {AGENTS} ('per_robot' in velocity mode only); "
                       f"got {self.agents!r} in {self.mode!r} mode")
    c = self.crop_cells
    if isinstance(c, bool) or int(c) != c or c < 3 or c % 2 == 0:
      raise ValueError(f"NavEnvConfig.crop_cells must be an odd integer >= 3; got {c!r}")
    object.__setattr__(self, "crop_cells", int(c))
    if not isinstance(self.costmap_stop, (bool, np.bool_)):
      raise ValueError(f"NavEnvConfig.costmap_stop must be True or False; got {self.costmap_stop!r}")
    object.__setattr__(self, "costmap_stop", bool(self.costmap_stop))
    for f in dataclasses.fields(self):
      if f.name in ("mode", "keepout", "crop_cells", "costmap_stop", "agents"):
        continue
      v = getattr(self, f.name)
      want = "> 0" if f.name == "crop_spacing" else ">= 0"
      if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) \
          or not np.isfinite(v) or v < 0 or (f.name == "crop_spacing" and v == 0):
        raise ValueError(f"NavEnvConfig.{f.name} must be a finite number {want}; got {v!r}")
      # The env computes in float32: a value float32 makes 0, subnormal or inf is refused, and the
      # weights and distances stay far enough below float32's range that rewards summed over an
      # episode stay finite.
      if v > MAX_CONFIG_VALUE or (v != 0 and abs(float(np.float32(v))) < np.finfo(np.float32).tiny):
        raise ValueError(f"NavEnvConfig.{f.name} must be 0 or a normal float32 in [{np.finfo(np.float32).tiny:.3g}, "
                         f"{MAX_CONFIG_VALUE:g}] ({want}); got {v!r}")
      object.__setattr__(self, f.name, float(v))


# ----------------------------------------------------------------------------- model


class NavModel(mjx.Model):
  """An `mjx.Model` of one robot that also carries the `NavTask` (field `task`).

  `mjx.step` reads only the inherited fields; Playground's
  `BraxDomainRandomizationVmapWrapper` vmaps the whole model, so
  `model.tree_replace({"task.goal_logits": ...})` randomises goals per env.
  """
  task: NavTask


def nav_model(model: mjx.Model, task: NavTask) -> NavModel:
  """Attaches a task to an mjx.Model."""
  return NavModel(**{f.name: getattr(model, f.name) for f in dataclasses.fields(mjx.Model)}, task=task)


# ----------------------------------------------------------------------------- env


def check_layers(scenario: Scenario) -> None:
  """Refuses a scenario whose params list an AsymmetricInflationLayer (`Scenario.layers`).

  The env's inflated static layer, which observations and collisions read, is built
  once for every robot, so no robot's plan can shape it.

  Raises:
    ValueError: naming the layer.
  """
  asym = [x.name for x in scenario.layers if isinstance(x.config, AsymmetricInflationConfig)]
  if asym:
    raise ValueError(f"NavEnv: the RL env has no plan for AsymmetricInflationLayer '{asym[0]}' (its inflated "
                     "static layer, which observations and collisions read, is built once for every robot); "
                     "remove it from the params' local_costmap plugins, or run it with `jaxfilters fleet`")


class NavEnv(mjx_env.MjxEnv):
  """The fleet world as a Playground `MjxEnv` (see the module docstring).

  Build with `NavEnv.create(...)`. `reset(rng)` and `step(state, action)` act
  on one env (one world of K robots); batch with `jax.vmap` or Playground's
  `wrap_for_brax_training`.
  """

  def __init__(self, fleet: FleetEnv, config: NavEnvConfig, bank: LayoutBank | None = None,
               layout_worlds: tuple = ()):
    fc = fleet.config
    super().__init__(config_dict.ConfigDict({"ctrl_dt": fc.step_seconds, "sim_dt": fc.physics_dt}))
    self._fleet = fleet
    self._nav = config
    w = fleet.world
    if bank is None:
      bank = bank_from_worlds([w])
      layout_worlds = (w,)
    if bank.num_layouts > 1 and config.mode != "velocity":
      raise ValueError("NavEnv: zone layouts (layouts > 1) need velocity mode; navigation mode drives the "
                       "fleet on the scenario's own zones")
    self._layout_worlds = tuple(layout_worlds)
    check_layers(w.scenario)
    # The local costmap's inflation layers (a params file's InflationLayer, else the fleet's inflation).
    inflated = static_layer(jnp.asarray(w.scenario.map.data)[None], config=STATIC_LAYER)
    for layer in w.local_inflation_layers:
      inflated = inflate(inflated, config=layer)
    inflated = np.asarray(inflated[0])
    task = NavTask(world=w.params, static_inflated=jnp.asarray(inflated),
                   # Every station of every layout may be a goal: an env draws only among its own layout's.
                   goal_logits=jnp.zeros((bank.nav.stations.shape[0],), _F32),
                   bank=bank, layout=jnp.zeros((), jnp.int32), navigation_mode=config.mode == "navigation")
    self._mjx_model = nav_model(fleet.mjx_model, task)
    self._crop = observation.crop_offsets(config.crop_cells, config.crop_spacing)

  @classmethod
  def create(cls, scenario: Scenario | None = None, fleet_config: FleetConfig | None = None,
             config: NavEnvConfig = NavEnvConfig(), *, seed: int = 0, layouts: int = 1,
             layout_seed: int = 0, layout_config: LayoutConfig = LayoutConfig(),
             robot: RobotModel | None = None) -> "NavEnv":
    """Builds the world (as `FleetEnv.create`), the bank of zone layouts and the env.

    Args:
      scenario: maps (default: the built-in warehouse).
      fleet_config: FleetConfig (default: FleetConfig(robots_per_world=1)).
      config: NavEnvConfig.
      seed: host seed for station and spawn selection.
      layouts: L in [1, MAX_LAYOUTS] zone layouts in the bank (`sims.fleet.layouts`): 1 is the scenario's own zones;
        more adds random keepout and speed zones (velocity mode only), drawn per env by
        `sims.rl.randomization.randomize_zones_and_goals`.
      layout_seed: host seed of the random layouts (different seeds give layouts never seen
        with another).
      layout_config: how random layouts are drawn.
      robot: your own base (`sims.fleet.robot.load_robot`, as `FleetEnv.create`): its radius
        replaces fleet_config.robot.radius. None: the built-in robot.

    Raises:
      ValueError: a bad config or scenario (see FleetEnv.create, build_world), layouts < 1,
        layouts > 1 in navigation mode, or a scenario with an AsymmetricInflationLayer
        (`check_layers`); RobotModelError (a ValueError) for a robot the fleet refuses.
      TypeError: config of the wrong type.
    """
    if not isinstance(config, NavEnvConfig):
      raise TypeError(f"config must be a NavEnvConfig; got {type(config).__name__}")
    fleet_config = FleetConfig(robots_per_world=1) if fleet_config is None else fleet_config
    if not isinstance(fleet_config, FleetConfig):
      raise TypeError(f"fleet_config must be a FleetConfig; got {type(fleet_config).__name__}")
    if isinstance(layouts, bool) or not isinstance(layouts, (int, np.integer)) or layouts < 1:
      raise ValueError(f"layouts must be an integer >= 1; got {layouts!r}")
    if layouts > MAX_LAYOUTS:
      raise ValueError(f"layouts must be at most {MAX_LAYOUTS} (each is a world built on the host); got {layouts!r}")
    if scenario is not None:
      check_layers(scenario)          # before the world is built
    fleet = FleetEnv.create(scenario, fleet_config, seed=seed, robot=robot)
    if layouts == 1:
      return cls(fleet, config)
    if config.mode != "velocity":
      raise ValueError("NavEnv.create: zone layouts (layouts > 1) need velocity mode; navigation mode drives "
                       "the fleet on the scenario's own zones")
    cfg = dataclasses.replace(layout_config, include_scenario=False)
    worlds = layout_worlds(fleet.world.scenario, fleet.config, int(layouts) - 1, layout_seed, cfg)
    bank = bank_from_worlds([fleet.world, *worlds])
    return cls(fleet, config, bank, (fleet.world, *worlds))

  # ------------------------------------------------------------------ contract

  @property
  def xml_path(self) -> str:
    return str(ROBOT_XML) if self._fleet.robot is None else self._fleet.robot.name

  @property
  def mj_model(self) -> mujoco.MjModel:
    return self._fleet.mj_model

  @property
  def mjx_model(self) -> NavModel:
    return self._mjx_model

  @property
  def action_size(self) -> int:
    """2K (velocity mode), K (navigation mode) or 2, each robot's (agents "per_robot")."""
    k = self.num_robots
    if self._nav.agents == "per_robot":
      return 2
    return 2 * k if self._nav.mode == "velocity" else k

  @property
  def observation_size(self) -> int:
    return int(jax.eval_shape(self.reset, jax.ShapeDtypeStruct((2,), jnp.uint32)).obs.shape[-1])

  # ------------------------------------------------------------------ helpers

  @property
  def fleet(self) -> FleetEnv:
    return self._fleet

  @property
  def nav_config(self) -> NavEnvConfig:
    return self._nav

  @property
  def fleet_config(self) -> FleetConfig:
    return self._fleet.config

  @property
  def num_robots(self) -> int:
    return self._fleet.num_robots

  @property
  def num_stations(self) -> int:
    """S, goal stations of the scenario (navigation mode's action range)."""
    return int(self._fleet.world.params.nav.stations.shape[0])

  @property
  def num_layouts(self) -> int:
    """L, zone layouts in the bank (1: the scenario's own)."""
    return self._mjx_model.task.bank.num_layouts

  def with_model(self, model: NavModel) -> "NavEnv":
    """A shallow copy of the env that reads `model` (the same shapes: e.g. one env's randomised
    model, or `env.mjx_model.tree_replace({"task.layout": l})` to drive in layout l). Pass the
    model as a jit argument to compile one program for every model."""
    env = copy.copy(self)
    env._mjx_model = model
    return env

  @property
  def layout_worlds(self) -> tuple:
    """The L `World`s of the bank (their scenarios hold each layout's masks, for pictures)."""
    return self._layout_worlds

  def _check_action(self, action) -> jax.Array:
    a = jnp.asarray(action)
    k = self.num_robots
    if self._nav.agents == "per_robot" and a.shape != (k, 2):
      raise ValueError(f"NavEnv.step (agents 'per_robot'): action must be float [K, 2] = ({k}, 2), each "
                       f"robot's (v, w) in [-1, 1]; got shape {tuple(a.shape)}")
    if self._nav.agents == "world" and self._nav.mode == "velocity" and a.shape != (2 * k,):
      raise ValueError(f"NavEnv.step (velocity mode): action must be float [2K] = ({2 * k},), each "
                       f"robot's (v, w) in [-1, 1]; got shape {tuple(a.shape)}")
    if self._nav.mode == "velocity":
      if not jnp.issubdtype(a.dtype, jnp.floating):
        raise TypeError(f"NavEnv.step (velocity mode): action must be floating point; got {a.dtype}")
      return a.astype(_F32)
    if a.shape != (k,):
      raise ValueError(f"NavEnv.step (navigation mode): action must be int [K] = ({k},) goal station "
                       f"ids in [0, {self.num_stations}) or -1 to keep the goal; got shape {tuple(a.shape)}")
    if a.dtype == bool or not jnp.issubdtype(a.dtype, jnp.integer):
      raise TypeError(f"NavEnv.step (navigation mode): action must be integer station ids; got {a.dtype}")
    return a.astype(jnp.int32)

  # ------------------------------------------------------------------ reset

  def reset(self, rng: jax.Array) -> State:
    """A fresh env: K robots at distinct spawn points, random yaw, goals from the goal distribution.

    Args:
      rng: PRNG key (uint32 [2]).

    Returns:
      State with obs float32 [observation_size], reward and done float32 [] (0),
      metrics (float32 [] each) and info (the per-episode state); with agents "per_robot"
      obs float32 [K, observation_size] and reward, done and metrics float32 [K].
    """
    task = self._mjx_model.task
    fleet = self._fleet.with_params(task.world)
    k_world, k_goal, k_rng, k_spawn = jax.random.split(rng, 4)
    ws = fleet.reset(k_world)
    if self._nav.mode == "navigation":
      xy = ws.data.qpos[:, :2]
      goal = kernels.sample_goal(k_goal, task.goal_logits, xy, jnp.full((self.num_robots,), -1, jnp.int32),
                          task.world.nav, self._nav.goal_max_distance, 0, self.num_stations)
    else:
      # Distinct spawn points of the env's layout (clear of its keepout zones).
      bank, lay = task.bank, task.layout
      p_max = bank.spawns.shape[1]
      score = jnp.where(jnp.arange(p_max) < bank.spawn_count[lay], jax.random.uniform(k_spawn, (p_max,)), -1.0)
      _, idx = topk.top_k(score, self.num_robots)   # lax.top_k would gather a sharded batch
      xy = bank.spawns[lay][idx]
      qpos = ws.data.qpos.at[:, :2].set(xy)
      ws = dataclasses.replace(ws, data=ws.data.replace(qpos=qpos))
      per = bank.stations_per_layout
      goal = kernels.sample_goal(k_goal, task.goal_logits, xy, jnp.full((self.num_robots,), -1, jnp.int32),
                          bank.nav, self._nav.goal_max_distance, lay * per, per)
    ws = dataclasses.replace(ws, goal=goal)
    zero = jnp.zeros((self.num_robots,) if self._nav.agents == "per_robot" else (), _F32)
    metrics = {name: zero for name in self._metric_names()}
    if self._nav.mode == "navigation":
      info = {"rng": k_rng, "world": ws}
      obs = observation.navigation_obs(task, ws, self.fleet_config.robot)
    else:
      k = self.num_robots
      info = {"rng": k_rng, "goal": goal, "cmd": jnp.zeros((k, 2), _F32), "speed": SpeedState.create(k),
              "cap": jnp.full((k,), jnp.inf, _F32), "last_qpos": ws.data.qpos,
              "in_keepout": jnp.zeros((k,), bool)}
      obs = self._obs(task, ws.data, info)
    return State(data=ws.data, obs=obs, reward=zero, done=zero, metrics=metrics, info=info)

  def _metric_names(self):
    names = ("progress", "goals_reached", "keepout_entries", "collisions", "speed_violation_s",
             "speed_violation_after_clip_s", "speed_violation_outside_entry_s", "clipped", "costmap_stops", "bad_action")
    return names + ("robot_collisions",) if self._nav.agents == "per_robot" else names

  # ------------------------------------------------------------------ step

  def step(self, state: State, action: jax.Array) -> State:
    """Advances one env by one costmap period (0.2 s by default).

    Args:
      state: State of one env.
      action: velocity mode float32 [2K], (v, w) per robot in [-1, 1] ([K, 2] with agents
        "per_robot"); navigation mode int32 [K], goal station ids (-1 keeps the goal).

    Returns:
      The next State: reward float32 [], done float32 [] (1.0 ends the episode),
      metrics of this step (float32 [] each, summed over robots); with agents "per_robot"
      reward, done and metrics float32 [K], per robot (`sims.rl.agents`).

    Raises:
      ValueError / TypeError: an action of the wrong shape or dtype.
    """
    action = self._check_action(action)
    with jax.named_scope("nav_env_step"):
      if self._nav.mode == "navigation":
        return self._step_navigation(state, action)
      return self._step_velocity(state, action)

  def _step_velocity(self, state: State, action: jax.Array) -> State:
    fc, cfg, r = self.fleet_config, self._nav, self.fleet_config.robot
    task = self._mjx_model.task
    p = task.world
    k = self.num_robots
    model = self._mjx_model
    info = dict(state.info)
    per_robot = cfg.agents == "per_robot"

    bad = ~jnp.isfinite(action) | (jnp.abs(action) > 1.0)
    a = jnp.clip(jnp.where(jnp.isfinite(action), action, 0.0), -1.0, 1.0).reshape(k, 2)
    target = a * jnp.asarray([[r.max_speed, r.max_yaw_rate]], _F32)

    data = state.data
    qpos = data.qpos
    # Playground's cached auto-reset swaps data, not info: restart the episode state then.
    swapped = jnp.any(qpos != info["last_qpos"])
    cmd = jnp.where(swapped, 0.0, info["cmd"])
    speed = jax.tree.map(lambda fresh, old: jnp.where(swapped, fresh, old), SpeedState.create(k), info["speed"])
    in_k = jnp.where(swapped, False, info["in_keepout"])
    goal = info["goal"]
    nav = task.bank.nav
    stations = nav.stations
    dist0 = jax.vmap(lambda g, q: navigation.nav_value(nav, g, q))(goal, qpos[:, :2])

    dt = fc.control_dt
    step_acc = jnp.asarray([[r.max_accel * dt, r.max_yaw_accel * dt]], _F32)
    tol = fc.speed_tolerance

    def tick(carry, _):
      data, cmd, speed, in_k, prev_cap, acc = carry
      poses = data.qpos[:, :3]
      speed, res = speed_filter(task.bank.speed, poses, speed, mask_index=kernels.layout_index(task, (k,)))
      cap = planner.limit_to_speed(res.speed_limit, res.percentage, jnp.ones((k,), bool), r.max_speed)
      ramped = cmd + jnp.clip(target - cmd, -step_acc, step_acc)
      clipped = clip_command(ramped, cap, r, fc.limit_angular)
      excess = jnp.sum(jnp.abs(ramped - clipped), axis=1) * dt
      if cfg.costmap_stop:
        clipped, stopped = kernels.costmap_stop(task, data.qpos, clipped, dt)
        if per_robot:
          clipped, by_robot = agents.robot_stop(data.qpos, clipped, dt, r.radius)
          stopped = stopped | by_robot
      else:
        stopped = jnp.zeros((k,), bool)
      v, w = clipped[:, 0], clipped[:, 1]

      # An entry tick: the filter published a lower limit than at the last tick, or (below) the
      # robot crosses into a slower zone during this tick, before the filter can see it.
      entry = cap < prev_cap

      def substep(c, _):
        data, in_k, entries, collide, over, late_s, crossed, outside, *touch = c
        ctrl = planar_ctrl(self._fleet.robot, v, w, data.qpos[:, 2])
        data = jax.vmap(lambda d, u: mjx_step(model, d, u))(data, ctrl)
        xy = data.qpos[:, :2]
        kin = kernels.keepout_cost(task, xy) >= constants.INSCRIBED_INFLATED_OBSTACLE
        hit = kernels.grid_value(task.static_inflated, p.map_origin, p.map_resolution, xy,
                          constants.NO_INFORMATION) >= constants.INSCRIBED_INFLATED_OBSTACLE
        spd = jnp.linalg.norm(data.qvel[:, :2], axis=-1)
        pos_cap = kernels.mps_cap(task, xy, r.max_speed)
        over_limit = spd > pos_cap + tol
        # Above the limit this tick's filter already published: the clip did not hold it.
        late = spd > cap + tol
        crossed = crossed | (pos_cap < cap)
        out = over_limit & ~crossed
        return (data, kin, entries + (kin & ~in_k), collide | hit,
                over + over_limit.astype(_F32) * fc.physics_dt, late_s + late.astype(_F32) * fc.physics_dt,
                crossed, outside + out.astype(_F32) * fc.physics_dt,
                *[t | agents.robot_contacts(xy, r.radius) for t in touch]), None

      zeros_b = jnp.zeros((k,), bool)
      zeros_f = jnp.zeros((k,), _F32)
      (data, in_k, entries, collide, over, late, _, outside, *touch), _ = jax.lax.scan(
          substep, (data, in_k, zeros_b.astype(jnp.int32), zeros_b, zeros_f, zeros_f, entry, zeros_f,
                    *[zeros_b] * per_robot), None, length=fc.substeps_per_tick)
      acc = jax.tree.map(jnp.add, acc, {"entries": entries, "collide": collide.astype(jnp.int32),
                                        "over": over, "late": late, "outside": outside, "excess": excess,
                                        "stops": stopped.astype(jnp.int32),
                                        **({"robot": touch[0].astype(jnp.int32)} if touch else {})})
      return (data, clipped, speed, in_k, cap, acc), cap

    acc0 = {"entries": jnp.zeros((k,), jnp.int32), "collide": jnp.zeros((k,), jnp.int32),
            "over": jnp.zeros((k,), _F32), "late": jnp.zeros((k,), _F32), "outside": jnp.zeros((k,), _F32),
            "excess": jnp.zeros((k,), _F32), "stops": jnp.zeros((k,), jnp.int32),
            **({"robot": jnp.zeros((k,), jnp.int32)} if per_robot else {})}
    prev_cap = jnp.where(swapped, jnp.inf, info["cap"])
    (data, cmd, speed, in_k, _, acc), caps = jax.lax.scan(tick, (data, cmd, speed, in_k, prev_cap, acc0), None,
                                                          length=fc.ticks_per_step)
    xy = data.qpos[:, :2]
    dist1 = jax.vmap(lambda g, q: navigation.nav_value(nav, g, q))(goal, xy)
    reach = 2.0 * r.max_speed * fc.step_seconds
    progress = jnp.clip(dist0 - dist1, -reach, reach)
    reached = jnp.linalg.norm(xy - stations[goal], axis=-1) < fc.planner.goal_tolerance
    rng, k_goal = jax.random.split(info["rng"])
    per = task.bank.stations_per_layout
    goal = jnp.where(reached, kernels.sample_goal(k_goal, task.goal_logits, xy, goal, nav, cfg.goal_max_distance,
                                           task.layout * per, per), goal)

    c_end, s_end = jnp.cos(data.qpos[:, 2]), jnp.sin(data.qpos[:, 2])
    ahead = jnp.asarray(AHEAD[:2], _F32)
    motion = jnp.where(cmd[:, :1] < 0, -1.0, 1.0) * jnp.stack([c_end, s_end], axis=1)   # reversing too
    ahead_pts = xy[:, None, :] + ahead[None, :, None] * motion[:, None, :]
    ahead_cap = jnp.min(kernels.mps_cap(task, ahead_pts, r.max_speed), axis=1)
    approach = jnp.maximum(jnp.abs(cmd[:, 0]) - ahead_cap, 0.0) * fc.step_seconds
    collided = acc["collide"] > 0
    entered = acc["entries"] > 0
    reward = (cfg.progress_weight * progress + cfg.goal_bonus * reached
              - cfg.keepout_penalty * acc["entries"] - cfg.collision_penalty * collided
              - cfg.speed_penalty * acc["over"] - cfg.clip_penalty * acc["excess"]
              - cfg.approach_penalty * approach - cfg.time_penalty)          # [K]
    info.update(rng=rng, goal=goal, cmd=cmd, speed=speed, cap=caps[-1], last_qpos=data.qpos, in_keepout=in_k)
    fold = (lambda x: x) if per_robot else jnp.sum          # per robot, or summed over the world's robots
    metrics = dict(state.metrics)      # keys wrappers added (Brax's EvalWrapper adds "reward") stay
    metrics.update({"progress": fold(progress), "goals_reached": fold(reached).astype(_F32),
               "keepout_entries": fold(acc["entries"]).astype(_F32),
               "collisions": fold(collided).astype(_F32), "speed_violation_s": fold(acc["over"]),
               "speed_violation_after_clip_s": fold(acc["late"]),
               "speed_violation_outside_entry_s": fold(acc["outside"]),
               "costmap_stops": fold(acc["stops"]).astype(_F32),
               "clipped": fold(acc["excess"]), "bad_action": fold(jnp.sum(bad.reshape(k, 2), axis=1)).astype(_F32)})
    if per_robot:
      # Each robot's episode ends on its own; the robot is respawned and the world goes on (sims.rl.agents).
      touched = acc["robot"] > 0
      metrics["robot_collisions"] = touched.astype(_F32)
      reward = reward - cfg.collision_penalty * touched
      done = collided | touched | (entered if cfg.keepout == "terminate" else False)
      rng, k_respawn = jax.random.split(rng)
      data, info = agents.respawn(k_respawn, task, self._fleet.data0, data, dict(info, rng=rng), done,
                                  cfg.goal_max_distance)
    else:
      reward = jnp.sum(reward)
      done = jnp.any(collided) | (jnp.any(entered) if cfg.keepout == "terminate" else False)
    obs = self._obs(task, data, info)
    return state.replace(data=data, obs=obs, reward=reward.astype(_F32), done=done.astype(_F32),
                         metrics=metrics, info=info)

  def _step_navigation(self, state: State, action: jax.Array) -> State:
    cfg = self._nav
    task = self._mjx_model.task
    fleet = self._fleet.with_params(task.world)
    ws: WorldState = state.info["world"]
    # A cached auto-reset restores data only: put it back into the world state.
    ws = dataclasses.replace(ws, data=state.data)
    s = self.num_stations
    bad = (action < -1) | (action >= s)
    ws = fleet.step(ws, jnp.where(bad, -1, action))
    old, new = state.info["world"].metrics, ws.metrics
    goals = jnp.sum(new.goals_reached - old.goals_reached)
    entries = jnp.sum(new.keepout_entries - old.keepout_entries)
    reward = cfg.goal_bonus * goals - cfg.keepout_penalty * entries - cfg.time_penalty
    done = (entries > 0) if cfg.keepout == "terminate" else jnp.asarray(False)
    zero = jnp.zeros((), _F32)
    metrics = dict(state.metrics)
    metrics.update({name: zero for name in self._metric_names()})
    metrics.update(goals_reached=goals.astype(_F32), keepout_entries=entries.astype(_F32),
                   bad_action=jnp.sum(bad).astype(_F32))
    info = dict(state.info, world=ws)
    return state.replace(data=ws.data, obs=observation.navigation_obs(task, ws, self.fleet_config.robot), reward=reward.astype(_F32),
                         done=done.astype(_F32), metrics=metrics, info=info)

  def _obs(self, task: NavTask, data: mjx.Data, info: dict) -> jax.Array:
    """float32 [K * D] (agents "world") or [K, D] ("per_robot"); see the module docstring."""
    per_robot = observation.velocity_obs(task, data.qpos, data.qvel, info, self.fleet_config.robot, self._crop)
    return per_robot if self._nav.agents == "per_robot" else per_robot.reshape(-1)


__all__ = ["AGENTS", "AHEAD", "KEEPOUT_MODES", "MODES", "NavEnv", "NavEnvConfig", "NavModel", "NavTask", "State",
           "clip_command", "nav_model"]
