"""The MJX fleet end to end: speed compliance, zero keepout entries, determinism, batching, compiles.

Compiled rollouts are shared through module-scoped fixtures (each distinct
shape costs ~10-15 s of XLA compile on a 2-core CPU), and every rollout here
uses 5-step (1 s) chunks of one jitted function.

Physics tolerance of the compliance checks: FleetConfig.speed_tolerance
(0.01 m/s). The velocity actuators follow the command with a 0.01 s time
constant and never overshoot, and commands are clipped to the limit in force,
so the measured margin is far smaller.
"""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from PIL import Image

from jaxfilters import cli
from sims.fleet.config import FleetConfig
from sims.fleet.env import FleetEnv
from sims.fleet.scenario import Scenario

CHUNK = 5          # env steps (of 0.2 s) per jitted call: 1 s simulated
TOL = FleetConfig().speed_tolerance


class Fleet:
  """An env with its jitted reset and 5-step rollout, compiled once per module."""

  def __init__(self, env: FleetEnv):
    self.env = env
    self.reset = env.reset_fn()
    self.run = env.rollout_fn(CHUNK)

  def start(self, num_worlds: int, seed: int = 0):
    return self.reset(self.env.params, self.env.world_keys(jax.random.PRNGKey(seed), num_worlds))

  def roll(self, states, chunks: int, actions=None):
    frames = []
    for _ in range(chunks):
      states, fr = self.run(self.env.params, states, actions)
      frames.append(fr)
    return states, jax.tree.map(lambda *a: np.concatenate([np.asarray(x) for x in a]), *frames)


@pytest.fixture(scope="module")
def fleet() -> Fleet:
  """Default warehouse, 4 robots per world."""
  return Fleet(FleetEnv.create(config=FleetConfig(robots_per_world=4)))


@pytest.fixture(scope="module")
def fleet_run(fleet):
  """4 worlds x 4 robots for 90 s on the default warehouse."""
  states = fleet.start(4, seed=1)
  return fleet.roll(states, 90)


def _check_compliance(world, metrics, frames):
  zm = np.asarray(metrics.zone_max_speed).reshape(-1, world.num_zones)
  for z in range(1, world.num_zones):
    assert zm[:, z].max() <= world.zone_speed[z] + TOL, f"zone {world.zone_labels[z]} speed {zm[:, z].max()}"
  assert int(np.asarray(metrics.keepout_steps).sum()) == 0
  assert int(np.asarray(metrics.keepout_entries).sum()) == 0
  # Every command is within the limit in force (the clip), at every recorded step.
  assert np.all(frames.cmd[..., 0] <= frames.speed_cap + 1e-6)


def test_speed_compliance_and_no_keepout_default(fleet, fleet_run):
  states, frames = fleet_run
  w = fleet.env.world
  _check_compliance(w, states.metrics, frames)
  zone_time = np.asarray(states.metrics.zone_time).reshape(-1, w.num_zones).sum(0)
  assert np.all(zone_time[1:] > 5.0), f"speed zones not exercised: {zone_time}"
  assert int(np.asarray(states.metrics.goals_reached).sum()) >= 8
  assert int(np.asarray(states.metrics.contacts).sum()) == 0
  # Robots really slow down in zones: some robot drove within 5 % of each zone's limit.
  zm = np.asarray(states.metrics.zone_max_speed).reshape(-1, w.num_zones)
  assert np.all(zm[:, 1:].max(0) > 0.95 * np.asarray(w.zone_speed[1:]))
  # The limit in force is the zone's limit wherever the robot centre is in a zone.
  assert np.isin(np.round(frames.speed_cap[np.isfinite(frames.speed_cap)], 4),
                 np.round(np.asarray(w.zone_speed[1:], np.float32), 4)).all()


def test_metrics_distance_matches_trajectory(fleet, fleet_run):
  states, frames = fleet_run
  path = np.linalg.norm(np.diff(frames.pose[..., :2], axis=0), axis=-1).sum(0)     # [W, K], 5 Hz chords
  dist = np.asarray(states.metrics.distance)
  assert np.all(dist >= path - 1e-3) and np.all(dist <= path * 1.05 + 0.2)


def test_same_seed_same_rollout(fleet):
  a, fa = fleet.roll(fleet.start(4, seed=7), 2)
  b, fb = fleet.roll(fleet.start(4, seed=7), 2)
  c, _ = fleet.roll(fleet.start(4, seed=8), 2)
  for x, y in zip(jax.tree.leaves((a, fa)), jax.tree.leaves((b, fb))):
    np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
  assert not np.array_equal(np.asarray(a.data.qpos), np.asarray(c.data.qpos))


def test_step_compiles_once(fleet):
  states = fleet.start(4, seed=3)
  states, _ = fleet.run(fleet.env.params, states)             # compiled already (or now)
  compiles = []
  listener = lambda name, secs, **kw: compiles.append(name) if "backend_compile" in name else None
  jax.monitoring.register_event_duration_secs_listener(listener)
  try:
    for _ in range(3):
      states, _ = fleet.run(fleet.env.params, states)
    jax.block_until_ready(states)
  finally:
    jax.monitoring.unregister_event_duration_listener(listener)
  assert compiles == []
  assert fleet.run._cache_size() == 1


def test_world_keys_do_not_depend_on_batch(fleet):
  k = jax.random.PRNGKey(4)
  np.testing.assert_array_equal(np.asarray(fleet.env.world_keys(k, 64)[:1]),
                                np.asarray(fleet.env.world_keys(k, 1)))


def test_robot0_of_b64_equals_b1():
  """One robot per world: robot 0 of a 64-robot rollout equals a 1-robot rollout with the same inputs."""
  f = Fleet(FleetEnv.create(config=FleetConfig(robots_per_world=1)))
  big, fbig = f.roll(f.start(64, seed=5), 2)
  one, fone = f.roll(f.start(1, seed=5), 2)
  np.testing.assert_allclose(fbig.pose[:, :1], fone.pose, atol=1e-4)
  np.testing.assert_array_equal(fbig.goal[:, :1], fone.goal)
  for x, y in zip(jax.tree.leaves(big.metrics), jax.tree.leaves(one.metrics)):
    np.testing.assert_allclose(np.asarray(x)[:1], np.asarray(y), rtol=1e-4, atol=1e-4)


def test_hand_built_metric_cases(fleet):
  """Known metric values from hand-placed robots (one case per world)."""
  env, w = fleet.env, fleet.env.world
  states = fleet.start(4, seed=2)
  qpos = np.array(states.data.qpos)
  goal = np.array(states.goal)
  ptime = np.array(states.progress_time)
  stations = np.asarray(w.stations)
  # World 0: robot 0 stands on its goal station -> one goal reached, new goal.
  qpos[0, 0, :2] = stations[goal[0, 0]]
  # World 1: robot 0 has made no progress for just under the timeout -> one stuck event.
  ptime[1, 0] = env.config.progress_timeout - 0.01
  # World 2: robot 0 starts inside the pick-station keepout zone -> it stops there:
  # 1 entry and every physics step of the chunk counted (5 steps x 4 ticks x 5 substeps).
  qpos[2, 0, :2] = (8.0, 2.5)
  # World 3: robots 0 and 1 start 0.40 m apart (closer than 2 x 0.22) -> one contact event each;
  # robot 2 sits in the 30 % zone.
  qpos[3, 0, :2] = (-3.0, 8.0)
  qpos[3, 1, :2] = (-2.6, 8.0)
  qpos[3, 2, :2] = (13.0, 3.0)
  far = np.linalg.norm(qpos[3, :, None, :2] - qpos[3, None, :, :2], axis=-1) + np.eye(4) * 9
  assert far[3].min() > 1.0 and far[2].min() > 1.0
  states = dataclasses.replace(
      states, data=states.data.replace(qpos=jnp.asarray(qpos)), progress_time=jnp.asarray(ptime),
      progress_anchor=jnp.asarray(qpos[..., :2]))
  states, frames = fleet.roll(states, 1)
  m = jax.tree.map(np.asarray, states.metrics)
  assert m.goals_reached[0, 0] == 1 and frames.goal[-1, 0, 0] != goal[0, 0]
  assert m.stuck_events[1, 0] == 1 and m.stuck_events[1, 1:].sum() == 0
  assert m.keepout_entries[2, 0] == 1 and m.keepout_steps[2, 0] == CHUNK * 4 * 5
  assert m.keepout_steps[2, 1:].sum() == 0 and m.keepout_steps[[0, 1, 3]].sum() == 0
  assert m.emergency_stops[2, 0] == CHUNK * 4                    # every candidate blocked, every tick
  assert m.contacts[3, 0] == 1 and m.contacts[3, 1] == 1 and m.contacts[3, 2:].sum() == 0
  assert m.min_separation[3, 0] == pytest.approx(0.40, abs=0.02)
  assert m.zone_time[3, 2, 2] > 0.5 and m.zone_max_speed[3, 2, 2] <= w.zone_speed[2] + TOL
  # A robot standing still accumulates (almost) no distance; the keepout robot never moved.
  assert m.distance[2, 0] < 0.01


def test_warehouse_compliance(nav2_maps):
  """Nav2's own warehouse (0.03 m cells; skipped with the reason when ../shared/maps/nav2 is absent)."""
  maps = nav2_maps
  sc = Scenario.load(maps / "warehouse.yaml", maps / "warehouse_keepout.yaml", maps / "warehouse_speed.yaml")
  f = Fleet(FleetEnv.create(sc, FleetConfig(robots_per_world=4)))
  w = f.env.world
  assert w.zone_labels == ("none", "80%") and w.window_cells == 100
  # Send every robot to the stations nearest the 80 % zones, so the zones are crossed.
  zone = np.asarray(w.params.zone_table)[sc.speed.data.astype(np.uint8)] == 1
  zone &= sc.map.data == 0
  rows, cols = np.nonzero(zone)
  zxy = np.stack([sc.speed.origin[0] + (cols + 0.5) * sc.speed.resolution,
                  sc.speed.origin[1] + (rows + 0.5) * sc.speed.resolution], axis=1)[::50]
  near = np.argsort([np.min(np.linalg.norm(zxy - s, axis=1)) for s in w.stations])
  states = f.start(2, seed=0)
  actions = np.full((CHUNK, 2, 4), -1, np.int32)
  actions[0] = near[:8].reshape(2, 4)
  states, frames = f.roll(states, 1, jnp.asarray(actions))
  states, more = f.roll(states, 59)
  frames = jax.tree.map(lambda a, b: np.concatenate([a, b]), frames, more)
  _check_compliance(w, states.metrics, frames)
  assert float(np.asarray(states.metrics.zone_time)[..., 1].sum()) > 1.0


def test_cli_fleet_writes_outputs(tmp_path, capsys):
  out = tmp_path / "demo"
  rc = cli.main(["fleet", "--robots", "3", "--steps", "10", "--chunk-seconds", "1", "--out", str(out),
                 "--animate", "--no-cache", "--seed", "1", "--bag", str(tmp_path / "bag"), "--bag-costmaps", "1"])
  assert rc == 0
  bag = sorted((tmp_path / "bag").glob("*.mcap"))
  assert len(bag) == 1 and (tmp_path / "bag" / "metadata.yaml").is_file()
  from mcap.reader import make_reader
  with open(bag[0], "rb") as f:
    topics = {c.topic for c in make_reader(f).get_summary().channels.values()}
  assert {"/map", "/tf", "/robot_2/cmd_vel", "/robot_0/local_costmap/costmap", "/fleet/summary"} <= topics
  assert "/robot_1/local_costmap/costmap" not in topics
  summary = json.loads((out / "summary.json").read_text())
  assert summary["fleet"]["robots"] == 3 and len(summary["robots"]) == 3
  assert summary["fleet"]["keepout_entries"] == 0 and summary["fleet"]["speed_compliant"]
  assert summary["config"]["robots_per_world"] == 3 and summary["timing"]["compile_s"] > 0
  with Image.open(out / "trajectories.png") as im:
    assert im.size[0] >= 600
  with Image.open(out / "fleet.gif") as im:
    assert im.n_frames == 10
  text = capsys.readouterr().out
  assert "speed compliance" in text and "keepout entries 0" in text


def test_cli_rejects_bad_arguments(capsys):
  assert cli.main(["fleet", "--robots", "5", "--robots-per-world", "2"]) == 2
  assert cli.main(["fleet", "--map", "x.yaml"]) == 2
  err = capsys.readouterr().err
  assert "--robots-per-world" in err and "Traceback" not in err


def test_cli_bench_without_harness(monkeypatch, capsys):
  monkeypatch.setitem(sys.modules, "benchmarks.run", None)        # import raises ImportError
  if "benchmarks" in sys.modules:       # an earlier test imported the harness: `from benchmarks import run`
    monkeypatch.delattr(sys.modules["benchmarks"], "run", raising=False)   # would find the attribute
  assert cli.main(["bench"]) == 1                                 # internal error, one line
  assert "benchmarks/run.py" in capsys.readouterr().err


def test_large_batch_does_not_deadlock():
  """B = 1280 > 1200 robots in one scanned batch (the dense-jacobian LAPACK deadlock on CPU).

  Runs in a subprocess with a timeout so a regression fails instead of hanging the suite: the
  robot model keeps the sparse jacobian (the fix, sims/assets/planar_robot.xml) and the bare MJX
  step of 1,280 robots runs one env step (20 physics steps). The fleet step vmaps the same
  mjx.step of the same model over its W x K robots, so this is the batch that deadlocked; the
  full fleet step at 1,280 robots (a program of its own, the larger part of this test's time) is
  no longer compiled here, and its throughput beside the bare step's, a speed figure, is the
  benchmarks' `fleet` entry (filters on and bare MJX, benchmarks/run.py).
  """
  code = textwrap.dedent("""
      import json, mujoco
      from sims.scale.bench import fleet_throughput
      from sims.fleet.env import load_robot_model
      from sims.fleet.config import FleetConfig
      m = load_robot_model(FleetConfig())
      assert m.opt.jacobian == mujoco.mjtJacobian.mjJAC_SPARSE
      bare = fleet_throughput(1280, 20, filters=False, repeats=1)
      print(json.dumps(bare))
  """)
  env = dict(os.environ)  # conftest already chose the XLA:CPU flags (jaxfilters/xla_flags.py)
  proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                        cwd=Path(__file__).resolve().parents[2], env=env)
  assert proc.returncode == 0, proc.stderr[-2000:]
  bare = json.loads(proc.stdout.strip().splitlines()[-1])
  assert bare["num_robots"] == bare["num_worlds"] == 1280 and bare["physics_steps"] == 20
  assert bare["robot_steps_per_s"] > 0


def test_cli_bench_runs_the_harness(capsys):
  assert cli.main(["bench", "--quick", "--only", "speed,baseline_speed", "--json"]) == 0
  report = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
  speed = report["results"]["speed"]
  assert speed["unit"] == "robots/s" and speed["throughput"] > 0 and speed["steady_s"] > 0
  assert report["device"]["platform"] == "cpu" and "speedup_vs_numpy" in speed
