"""One-way lanes in the MJX fleet: with a direction mask no robot drives against the lane; without it one does.

A small map of two rooms joined by a 1 m corridor that is one-way eastbound.
Robot 0 starts in the west room heading for the east station, robot 1 in the
east room heading for the west station. With the lanes only measured
(FleetConfig.honour_lanes False, the same scenario and mask) robot 1 drives
west through the corridor and the metrics count wrong-way traversals (> 0:
the test can fail); honoured, the corridor is lethal in robot 1's costmap
while it faces west, so it never enters, and robot 0 still drives through.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfilters as jf
from jaxfilters import constants
from jaxfilters.keepout import KeepoutState
from sims.fleet import local_costmap
from sims.fleet.config import FleetConfig
from sims.fleet.env import FleetEnv
from sims.fleet.metrics import summarize
from sims.fleet.scenario import Scenario

RES = 0.1
EAST = 1                 # Scenario's default encoding: d = 1 is 0 degrees (east)
CFG = FleetConfig(robots_per_world=2, num_stations=2)
STEPS = 60               # 12 s
CORRIDOR = (3.0, 5.0, 1.5, 2.5)   # x0, x1, y0, y1 (m)


def _scenario(lanes: bool) -> Scenario:
  h, w = 40, 80                                    # 4 m x 8 m
  occ = np.full((h, w), constants.OCC_GRID_OCCUPIED, np.int8)
  occ[1:-1, 1:30] = 0                              # west room x in [0.1, 3.0)
  occ[1:-1, 50:-1] = 0                             # east room x in [5.0, 7.9)
  x0, x1, y0, y1 = (round(v / RES) for v in CORRIDOR)
  occ[y0:y1, x0:x1] = 0
  grid = lambda d: jf.OccupancyGrid.create(d, RES, (0.0, 0.0, 0.0))
  lanes_data = np.zeros((h, w), np.int8)
  lanes_data[y0:y1, x0 - 2:x1 + 2] = EAST           # the corridor and its two mouths
  return Scenario(name="corridor", map=grid(occ), keepout=grid(np.zeros((h, w), np.int8)),
                  speed=grid(np.zeros((h, w), np.int8)), direction=grid(lanes_data) if lanes else None)


def _run(honour: bool):
  env = FleetEnv.create(_scenario(True), dataclasses.replace(CFG, honour_lanes=honour), seed=0)
  stations = np.asarray(env.params.nav.stations)
  west, east = int(np.argmin(stations[:, 0])), int(np.argmax(stations[:, 0]))
  assert stations[west, 0] < CORRIDOR[0] and stations[east, 0] > CORRIDOR[1], stations
  s = env.reset_fn()(env.params, env.world_keys(jax.random.PRNGKey(0), 1))
  qpos = jnp.asarray([[[1.5, 2.0, 0.0], [6.5, 2.0, np.pi]]], jnp.float32)
  s = dataclasses.replace(s, data=s.data.replace(qpos=qpos), goal=jnp.asarray([[east, west]], jnp.int32),
                          progress_anchor=qpos[..., :2])
  s, frames = env.rollout_fn(STEPS)(env.params, s)
  return env, s, np.asarray(frames.pose)


@pytest.fixture(scope="module")
def with_lanes():
  return _run(True)


@pytest.fixture(scope="module")
def without_lanes():
  return _run(False)


def _summary(env, s):
  w = env.world
  return summarize(s.metrics, zone_labels=w.zone_labels, zone_limits=w.zone_limits, zone_speed=w.zone_speed,
                   speed_tolerance=CFG.speed_tolerance, seconds=STEPS * CFG.step_seconds)


def _in_corridor(pose):
  x0, x1, y0, y1 = CORRIDOR
  return (pose[..., 0] > x0) & (pose[..., 0] < x1) & (pose[..., 1] > y0) & (pose[..., 1] < y1)


def test_lanes_only_measured_a_robot_drives_against_the_lane(without_lanes):
  env, s, pose = without_lanes
  f = _summary(env, s)
  assert f["fleet"]["wrong_way_entries"] > 0 and f["fleet"]["wrong_way_steps"] > 0
  assert f["robots"][1]["wrong_way_entries"] > 0
  # Robot 1 drove into the corridor westbound (the recorded 5 Hz poses; it meets robot 0 there).
  inside = _in_corridor(pose[:, 0, 1])
  assert inside.any() and np.cos(pose[inside, 0, 1, 2]).min() < -0.9, pose[:, 0, 1]


def test_lanes_honoured_no_robot_drives_against_the_lane(with_lanes):
  env, s, pose = with_lanes
  f = _summary(env, s)
  assert f["fleet"]["wrong_way_entries"] == 0 and f["fleet"]["wrong_way_steps"] == 0, f["robots"]
  # Robot 1 (westbound) never entered the corridor; robot 0 drove through it eastbound.
  assert not _in_corridor(pose[:, 0, 1]).any()
  assert pose[:, 0, 0, 0].max() > CORRIDOR[1], pose[:, 0, 0, 0]
  assert f["fleet"]["contacts"] == 0


def test_no_direction_mask_no_direction_work():
  """The default path: no direction mask, no lane leaves in the params and the same metrics as before (zeros)."""
  scenario = dataclasses.replace(_scenario(True), direction=None)
  env = FleetEnv.create(scenario, CFG, seed=0)
  assert env.params.direction is None
  s = env.reset_fn()(env.params, env.world_keys(jax.random.PRNGKey(0), 1))
  assert int(s.metrics.wrong_way_entries.sum()) == 0


def test_local_costmaps_block_the_lane_against_the_heading_but_not_the_robots_own_cell(with_lanes):
  """A robot that turned against the lane inside it: the lane around it is lethal, its own cell is not
  (it can turn back); the same robot facing along the lane sees the lane open; honour_lanes False: untouched."""
  env, _, _ = with_lanes
  p, w = env.params, env.world
  poses = jnp.asarray([[4.0, 2.0, np.pi], [4.0, 2.0, 0.0]], jnp.float32)      # mid-corridor: west, east

  @jax.jit
  def build(honour):
    local, _ = local_costmap.local_costmaps(
        p.static_cost, p.map_origin, p.map_resolution, w.pad, p.keepout, poses, KeepoutState.create(2),
        n=w.window_cells, robot_radius=0.01, inflation=w.inflation, direction=p.direction, honour_lanes=honour)
    return local

  local, plain = build(jnp.asarray(True)), build(jnp.asarray(False))
  cost, base = np.asarray(local.cost), np.asarray(plain.cost)
  origin = np.asarray(local.origin)
  col, row = (np.floor((np.asarray(poses)[:, :2] - origin) / RES).astype(int)).T
  lane = (slice(row[0] - 3, row[0] + 4), slice(col[0] - 5, col[0] + 6))       # corridor cells around robot 0
  assert cost[0, row[0], col[0]] == base[0, row[0], col[0]] < constants.LETHAL_OBSTACLE   # its own cell
  assert cost[0, row[0], col[0] + 1] == cost[0, row[0], col[0] - 1] == constants.LETHAL_OBSTACLE
  assert (cost[0][lane] == constants.LETHAL_OBSTACLE).sum() == (cost[0][lane] >= 0).sum() - 1
  np.testing.assert_array_equal(cost[1], base[1])                               # facing along the lane
  assert (base[0][lane] < constants.LETHAL_OBSTACLE).all()


def test_scenario_load_reads_a_lane_mask_from_map_server_files(tmp_path):
  """Scenario.load with direction_yaml: the lane bytes of a raw-mode PGM arrive as the mask's cell values."""
  sc = _scenario(True)
  for name in ("map", "keepout", "speed"):
    jf.save_map(getattr(sc, name), tmp_path / f"{name}.yaml")
  lanes = np.asarray(sc.direction.data)
  h, w = lanes.shape
  (tmp_path / "lanes.pgm").write_bytes(b"P5\n%d %d\n255\n" % (w, h) + lanes[::-1].astype(np.uint8).tobytes())
  (tmp_path / "lanes.yaml").write_text(f"image: lanes.pgm\nmode: raw\nresolution: {RES}\norigin: [0.0, 0.0, 0.0]\n"
                                       "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
  loaded = Scenario.load(*(tmp_path / f"{n}.yaml" for n in ("map", "keepout", "speed")),
                         direction_yaml=tmp_path / "lanes.yaml")
  np.testing.assert_array_equal(loaded.direction.data, lanes)
  assert (loaded.direction_base, loaded.direction_multiplier) == (-5.0, 5.0)
  assert Scenario.load(*(tmp_path / f"{n}.yaml" for n in ("map", "keepout", "speed"))).direction is None
  with pytest.raises(ValueError, match="direction_base must be finite"):
    Scenario.load(*(tmp_path / f"{n}.yaml" for n in ("map", "keepout", "speed")),
                  direction_yaml=tmp_path / "lanes.yaml", direction_base=float("nan"))
