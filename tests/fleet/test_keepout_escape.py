"""Keepout escape in the MJX fleet (issue #6505): robots started in zones leave, none is stuck, none enters.

One footprint-mode fleet (2 worlds x 6 robots, 3 per world started with their
footprint on a lethal keepout cell) runs 20 s on the built-in warehouse, with
Nav2's controller rule that an inscribed (253) cell under the robot centre is
a collision. The contrast with Nav2's centre-cell test uses the same world and
the same recorded poses: its local costmap traps the robot in the zone's band.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfilters as jf
from sims.fleet import local_costmap, navigation, planner
from sims.fleet.config import FleetConfig, PlannerConfig
from sims.fleet.env import FleetEnv
from sims.fleet.metrics import summarize
from reference import nav2 as reference
from reference import planner as ref_planner

CFG = FleetConfig(robots_per_world=6, keepout_escape="footprint", robots_in_keepout=3, num_stations=8,
                  planner=PlannerConfig(inscribed_is_collision=True))
WORLDS = 2
STEPS = 25            # env steps (0.2 s) per jitted call
CALLS = 4             # 20 s simulated
T_ESCAPE = 10.0       # s: every robot started in a zone is out (and stays out) by then


@pytest.fixture(scope="module")
def escape_run():
  env = FleetEnv.create(config=CFG, seed=0)
  start = env.reset_fn()(env.params, env.world_keys(jax.random.PRNGKey(0), WORLDS))
  run = env.rollout_fn(STEPS)
  states, frames = start, []
  for _ in range(CALLS):
    states, fr = run(env.params, states)
    frames.append(fr)
  frames = jax.tree.map(lambda *a: np.concatenate([np.asarray(x) for x in a]), *frames)
  return env, start, states, frames


def _lethal_centres(env):
  """float64 [N, 2] world centres of the lethal keepout cells (the reference's cells, vectorised)."""
  g = env.world.scenario.keepout
  rows, cols = np.nonzero(g.data == 100)
  res = float(np.float32(g.resolution))
  return np.stack([g.origin[0] + (cols + 0.5) * res, g.origin[1] + (rows + 0.5) * res], axis=1)


def _footprint_on_zone(centres, xy, radius):
  """bool [...]: a lethal cell centre within the robot's disc (the reference rule for a disc, vectorised)."""
  d2 = np.min(np.sum((xy[..., None, :] - centres) ** 2, axis=-1), axis=-1)
  return d2 <= radius * radius


def test_started_in_zones_leave_the_shortest_way_and_none_enters(escape_run):
  env, start, states, frames = escape_run
  w = env.world
  seconds = CALLS * STEPS * CFG.step_seconds
  summary = summarize(states.metrics, zone_labels=w.zone_labels, zone_limits=w.zone_limits,
                      zone_speed=w.zone_speed, speed_tolerance=CFG.speed_tolerance, seconds=seconds,
                      footprint=True, escape_within=T_ESCAPE)
  f = summary["fleet"]
  assert f["robots_started_in_keepout"] == WORLDS * CFG.robots_in_keepout
  assert f["robots_escaped"] == f["robots_started_in_keepout"], summary["robots"]
  assert f["escape_time_max_s"] <= T_ESCAPE and f["robots_in_keepout_at_end"] == 0
  assert f["footprint_entries"] == 0 and f["keepout_entries_started_outside"] == 0
  assert f["keepout_steps_started_outside"] == 0 and f["keepout_ok"]
  assert f["contacts"] == 0 and f["speed_compliant"]
  m = jax.tree.map(np.asarray, states.metrics)
  started = m.started_in_keepout
  assert started[:, :CFG.robots_in_keepout].all() and not started[:, CFG.robots_in_keepout:].any()
  assert m.footprint_steps[~started].sum() == 0 and m.footprint_steps[started].min() > 0

  # Cross-check with the reference rule: at reset, on the recorded 5 Hz poses, and at the end.
  centres = _lethal_centres(env)
  r = CFG.robot.radius
  x0 = np.asarray(start.data.qpos[..., :2], np.float64)
  np.testing.assert_array_equal(_footprint_on_zone(centres, x0, r), started)
  on = _footprint_on_zone(centres, frames.pose[..., :2].astype(np.float64), r)        # [T, W, K]
  assert not on[:, ~started].any()                                                     # never, from outside
  last = np.where(on.any(0), (np.argmax(on[::-1], axis=0) * -1 + on.shape[0]), 0)      # frames until out
  assert not on[-1].any() and (last[started] * CFG.step_seconds <= T_ESCAPE).all()
  # Every started robot really stood in a zone: the reference says so at its spawn.
  g = env.world.scenario.keepout
  for wi, k in zip(*np.nonzero(started)):
    surely, _ = reference.footprint_in_zone(g.data, g.origin[:2], np.float32(g.resolution), (*x0[wi, k], 0.0),
                                            radius=r)
    assert surely

  # The shortest way out: the path driven until the footprint cleared is at most the exit field's
  # distance at the spawn plus 0.8 m (a differential drive turns on arcs; the field ends outside the
  # inscribed band, the release a little before it).
  s = int(env.params.nav.stations.shape[0])
  for wi, k in zip(*np.nonzero(started)):
    n = int(np.ceil(m.footprint_last_time[wi, k] / CFG.step_seconds))
    path = np.concatenate([x0[wi, k][None], frames.pose[:n + 1, wi, k, :2]])
    driven = np.linalg.norm(np.diff(path, axis=0), axis=1).sum()
    way_out = float(navigation.nav_value(env.params.nav, jnp.int32(s), jnp.asarray(x0[wi, k], jnp.float32)))
    assert driven <= way_out + 0.8, (wi, k, driven, way_out)


def test_nav2_centre_test_traps_where_the_footprint_test_releases(escape_run):
  """Same world, same poses: the first recorded pose where an escaping robot's centre has left its zone
  while its footprint is still in it. Nav2's centre test ends escape there; the zone is lethal again and
  inflated, the robot's centre cell is inscribed, and every planner candidate collides (stuck, #6505).
  The footprint test keeps escape on: the zone stays 252 and the robot drives on."""
  env, start, states, frames = escape_run
  p, w = env.params, env.world
  g = w.scenario.keepout
  centres = _lethal_centres(env)
  started = np.asarray(states.metrics.started_in_keepout)
  centre_cfg = jf.KeepoutConfig(override_lethal_cost=True)                 # Nav2: centre-cell test

  def plan(poses, cmd, goal, escaping, kcfg):
    # The local costmaps eagerly (the jitted filter is shared by both configs), the planner jitted once.
    k = poses.shape[0]
    kstate = dataclasses.replace(jf.KeepoutState.create(k), is_pose_lethal=escaping)
    local, kstate = local_costmap.local_costmaps(
        p.static_cost, p.map_origin, p.map_resolution, w.pad, p.keepout, poses, kstate, n=w.window_cells,
        robot_radius=CFG.robot.radius, inflation=w.inflation, keepout_config=kcfg)
    stopped, here = evaluate(poses, cmd, goal, kstate.is_pose_lethal, local)
    return stopped, here, kstate.is_pose_lethal

  @jax.jit
  def evaluate(poses, cmd, goal, escaping, local):
    k = poses.shape[0]
    steer = jnp.where(escaping, p.nav.stations.shape[0], goal)
    one = functools.partial(planner.plan_one, nav=p.nav, speed_mask=p.speed, speed_cap=p.speed_cap, config=CFG,
                            extra_speeds=env.zone_speeds)
    hard = jax.vmap(planner.hard_cells)(local.cost)
    _, info = jax.vmap(one, in_axes=(0, 0, 0, None, None, 0, 0, 0, 0, None, 0))(
        poses, cmd, steer, jnp.inf, False, local.cost, hard, local.origin, local.resolution, poses[:, :2],
        ~jnp.eye(k, dtype=bool))
    here = jax.vmap(ref_planner.local_cost_at)(local.cost, local.origin, local.resolution, poses[:, :2])
    return info["stopped"], here

  checked = 0
  for wi, k in zip(*np.nonzero(started)):
    pose = frames.pose[:, wi, k]
    centre_in = np.array([reference.centre_in_zone(g.data, g.origin[:2], np.float32(g.resolution), x, y)
                          for x, y in pose[:, :2]])
    foot_in = _footprint_on_zone(centres, pose[:, :2].astype(np.float64), CFG.robot.radius)
    was_in = np.maximum.accumulate(centre_in)
    hits = np.nonzero(was_in & ~centre_in & foot_in)[0]
    if len(hits) == 0:
      continue                                   # its centre never stood in the zone (a straddler)
    i = int(hits[0])
    poses = jnp.asarray(frames.pose[i, wi])
    cmd = jnp.asarray(frames.cmd[i, wi])
    goal = jnp.asarray(frames.goal[i, wi])
    escaping = jnp.zeros((CFG.robots_per_world,), bool).at[k].set(True)
    stop_c, here_c, on_c = plan(poses, cmd, goal, escaping, centre_cfg)
    stop_f, here_f, on_f = plan(poses, cmd, goal, escaping, w.keepout_config)
    assert not bool(on_c[k]) and int(here_c[k]) == 253 and bool(stop_c[k])        # Nav2: trapped
    assert bool(on_f[k]) and int(here_f[k]) < 253 and not bool(stop_f[k])          # footprint: drives on
    checked += 1
  assert checked >= 2


@pytest.mark.parametrize("argv, words", [
    (["--robots-in-keepout", "2"], ["--robots-in-keepout needs --keepout-escape"]),
    (["--keepout-escape", "footprint", "--robots-in-keepout", "-1"], ["argument --robots-in-keepout: must lie in [0, 1,024]; got -1"]),
    (["--keepout-escape", "footprint", "--robots", "4", "--robots-in-keepout", "5"], ["robots per world (4)"]),
    (["--keepout-escape", "sideways"], ["invalid choice: 'sideways'"]),
])
def test_fleet_escape_options_are_usage_errors(argv, words, capsys, tmp_path):
  from jaxfilters import cli
  rc = cli.main(["fleet", "--out", str(tmp_path / "o"), "--steps", "1", *argv])
  err = capsys.readouterr().err
  assert rc == 2 and all(w in err for w in words), err
