"""Fleet throughput: robot-steps/s with all filters on, and the bare MJX step of the same robots.

    from sims.scale.bench import fleet_throughput
    on = fleet_throughput(1024, 200, filters=True)
    bare = fleet_throughput(1024, 200, filters=False)
    on["robot_steps_per_s"], bare["robot_steps_per_s"]

A robot-step is one physics step (mjx.step) of one robot. With filters on, a
robot-step also carries its share of the controller (speed filter, planner,
clip; 20 Hz) and of the local costmap (static layer, robots, inflation,
keepout filter; 5 Hz), so the two numbers measure what the filters and the
navigation stack cost on top of the physics. Compile time is measured apart
(ahead-of-time `lower().compile()`); run time is the best of `repeats` runs
after `block_until_ready`.
"""

from __future__ import annotations

import dataclasses
import math
import time

import jax
import jax.numpy as jnp
import numpy as np

from sims.fleet.quiet_mjx import expected_warp_lines

with expected_warp_lines():
  from mujoco import mjx

from sims.fleet.config import FleetConfig
from sims.fleet.env import FleetEnv, load_robot_model, mjx_step
from sims.fleet.scenario import Scenario


def _best_of(fn, args, repeats: int) -> float:
  best = math.inf
  for _ in range(repeats):
    t = time.perf_counter()
    jax.block_until_ready(fn(*args))
    best = min(best, time.perf_counter() - t)
  return best


def time_rollout(env: FleetEnv, num_worlds: int, env_steps: int, *, repeats: int = 3,
                 seed: int = 0) -> dict:
  """Compiles and times `env.rollout_fn(env_steps, record=False)` over `num_worlds` worlds.

  Args:
    env: a FleetEnv (or a subclass of it, e.g. a benchmark variant).
    num_worlds: W.
    env_steps: env steps per call (1 / costmap_hz s each).
    repeats: timed runs after compiling; the best is kept.
    seed: PRNG seed of the reset.

  Returns:
    dict with compile_s (ahead-of-time compile, s), run_s (best wall time of one call after a
    warm-up call, s) and cpu_s (least host CPU time of one call, all threads, s: on a shared
    CPU machine it varies less with other load than the wall time).
  """
  states = env.reset_fn()(env.params, env.world_keys(jax.random.PRNGKey(seed), num_worlds))
  jax.block_until_ready(states)
  run = env.rollout_fn(env_steps, record=False)
  t = time.perf_counter()
  compiled = run.compile(env.params, states)
  compile_s = time.perf_counter() - t
  jax.block_until_ready(compiled(env.params, states))          # warm-up, not timed
  run_s = cpu_s = math.inf
  for _ in range(repeats):
    t, c = time.perf_counter(), time.process_time()
    jax.block_until_ready(compiled(env.params, states))
    run_s, cpu_s = min(run_s, time.perf_counter() - t), min(cpu_s, time.process_time() - c)
  return {"compile_s": compile_s, "run_s": run_s, "cpu_s": cpu_s}


def bare_mjx_rollout(config: FleetConfig, num_robots: int, num_steps: int):
  """The bare MJX step of B robots: `lax.scan` of vmapped mjx.step, no filters.

  Each robot drives a constant differential-drive twist (0.4 m/s, 0.3 rad/s),
  turned into world velocities from its yaw every step, as the fleet does.

  Args:
    config: FleetConfig (physics timestep, robot radius, MJX impl).
    num_robots: B.
    num_steps: physics steps per call.

  Returns:
    (jitted fn(data) -> data after num_steps, the initial mjx.Data batched over
    B with random yaw).
  """
  m = load_robot_model(config)
  mx = mjx.put_model(m, impl=config.impl)
  d0 = mjx.make_data(m, impl=config.impl)
  rng = np.random.default_rng(0)
  qpos = np.zeros((num_robots, 3), np.float32)
  qpos[:, 2] = rng.uniform(-np.pi, np.pi, num_robots)
  data = jax.vmap(lambda q: d0.replace(qpos=q))(jnp.asarray(qpos))

  def step(d):
    th = d.qpos[2]
    ctrl = jnp.stack([0.4 * jnp.cos(th), 0.4 * jnp.sin(th), jnp.asarray(0.3, jnp.float32)])
    return mjx_step(mx, d, ctrl)

  def run(data):
    return jax.lax.scan(lambda d, _: (jax.vmap(step)(d), None), data, None, length=num_steps)[0]

  return jax.jit(run), data


def fleet_throughput(num_robots: int, num_steps: int, filters: bool = True, impl: str = "jax", *,
                     robots_per_world: int = 8, scenario: Scenario | None = None,
                     repeats: int = 3, seed: int = 0, config: FleetConfig | None = None) -> dict:
  """Measures fleet throughput in robot-steps/s.

  Args:
    num_robots: B, total robots. With filters on they are split into worlds of
      robots_per_world robots (the largest divisor of B not above it).
    num_steps: physics steps per robot (rounded up to whole env steps of
      1 / costmap_hz with filters on).
    filters: True runs the whole fleet step (filters, planner, metrics); False
      runs only mjx.step of the same robot model and batch.
    impl: MJX implementation, 'jax' or 'warp' (GPU only).
    robots_per_world: K robots per simulated warehouse.
    scenario: maps (default: the built-in warehouse).
    repeats: timed runs after compiling; the best is reported.
    seed: PRNG seed.
    config: a FleetConfig to measure instead of the defaults (its
      robots_per_world and impl are replaced by the arguments above).

  Returns:
    dict with robot_steps_per_s, robot_seconds_per_s (simulated robot-seconds
    per wall second: robot_steps_per_s x physics_dt), compile_s, run_s, num_robots, num_worlds,
    robots_per_world, physics_steps (per robot), filters, impl, device.

  Raises:
    ValueError: num_robots or num_steps < 1.
  """
  if num_robots < 1 or num_steps < 1:
    raise ValueError(f"num_robots and num_steps must be >= 1; got {num_robots}, {num_steps}")
  robots_per_world = max(d for d in range(1, min(robots_per_world, num_robots) + 1) if num_robots % d == 0)
  config = dataclasses.replace(config or FleetConfig(), robots_per_world=robots_per_world if filters else 1,
                               impl=impl)
  if filters:
    env = FleetEnv.create(scenario, config, seed=seed)
    num_worlds = num_robots // robots_per_world
    per_env_step = config.ticks_per_step * config.substeps_per_tick
    env_steps = -(-num_steps // per_env_step)
    physics_steps = env_steps * per_env_step
    timed = time_rollout(env, num_worlds, env_steps, repeats=repeats, seed=seed)
    compile_s, run_s = timed["compile_s"], timed["run_s"]
  else:
    num_worlds = num_robots
    physics_steps = num_steps
    run, data = bare_mjx_rollout(config, num_robots, num_steps)
    t = time.perf_counter()
    compiled = run.lower(data).compile()
    compile_s = time.perf_counter() - t
    run_s = _best_of(compiled, (data,), repeats)
  return {
      "robot_steps_per_s": num_robots * physics_steps / run_s,
      "robot_seconds_per_s": num_robots * physics_steps * config.physics_dt / run_s,
      "compile_s": compile_s,
      "run_s": run_s,
      "num_robots": num_robots,
      "num_worlds": num_worlds,
      "robots_per_world": robots_per_world if filters else 1,
      "physics_steps": physics_steps,
      "filters": bool(filters),
      "impl": impl,
      "device": str(jax.devices()[0].device_kind),
  }
