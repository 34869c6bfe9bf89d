"""Your own robot (sims/fleet/robot.py): the MJCF interface's checks, and the two example bases in the fleet.

The checks are one table of broken variants of examples/robots/diff_drive.xml, each refused with
RobotModelError naming the problem. The fleet runs (one compile per example, shared by a
module-scoped fixture) drive 2 robots of each base on the default warehouse with its keepout and
speed filters: the differential drive with keepout escape's footprint test, the omni base with the
filter after inflation (Nav2's placement; the program `jaxfilters fleet --robot omni_base.xml
--robots 2` compiles, so tests/commands/test_fleet_robot.py finds it in the session's cache); both
with 0 keepout entries and no speed excess.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sims.fleet import robot as R
from sims.fleet.config import FleetConfig
from sims.fleet.env import FleetEnv
from sims.fleet.world import SPAWN_SPACING, spawn_spacing

REPO = Path(__file__).resolve().parents[2]
DIFF = REPO / "examples" / "robots" / "diff_drive.xml"
OMNI = REPO / "examples" / "robots" / "omni_base.xml"
TOL = FleetConfig().speed_tolerance


def test_examples_load_with_their_drive_and_radius():
  d, o = R.load_robot(DIFF), R.load_robot(OMNI)
  assert (d.drive, d.radius, d.num_ctrl) == ("diff_drive", 0.30, 3)
  assert (o.drive, o.radius, o.num_ctrl) == ("omni", 0.18, 3)
  names = lambda m: [m.actuator(i).name for i in range(m.nu)]
  assert names(d.mj_model(0.01))[d.forward] == "v" and names(d.mj_model(0.01))[d.yaw] == "wz"
  assert names(o.mj_model(0.01))[o.forward] == "vx" and names(o.mj_model(0.01))[o.yaw] == "wz"
  assert R.robot_from_xml(DIFF.read_bytes(), name="d") == R.robot_from_xml(DIFF.read_text(), name="d")


def test_the_fleet_sets_its_physics_options():
  m = R.load_robot(OMNI).mj_model(0.005)
  assert m.opt.timestep == 0.005
  assert m.opt.integrator == R.mujoco.mjtIntegrator.mjINT_IMPLICITFAST
  assert m.opt.jacobian == R.mujoco.mjtJacobian.mjJAC_SPARSE


BASE = DIFF.read_text()


def _sub(old: str, new: str) -> str:
  assert BASE.count(old) == 1, old
  return BASE.replace(old, new)


_RADIUS = '<numeric name="jaxfilters_radius" data="0.30"/>'
_JX, _JY = '<joint name="x" type="slide" axis="1 0 0"/>', '<joint name="y" type="slide" axis="0 1 0"/>'
_V = '<velocity name="v" site="base_link" gear="1 0 0 0 0 0" kv="3150"/>'
BROKEN = [
    ("no base", _sub('<body name="base"', '<body name="chassis_body"'), "no body named 'base'"),
    ("base off origin", _sub('<body name="base" pos="0 0 0.12">', '<body name="base" pos="0.1 0 0.12">'),
     "x = y = 0"),
    ("base rotated", _sub('<body name="base" pos="0 0 0.12">', '<body name="base" pos="0 0 0.12" euler="0 0 0.3">'),
     "no rotation"),
    ("joints swapped", _sub(_JX + "\n      " + _JY, _JY + "\n      " + _JX),
     "joint 0 must be a slide along (1, 0, 0)"),
    ("a free joint", _sub('<joint name="yaw" type="hinge" axis="0 0 1"/>', '').replace(
        '<joint name="x" type="slide" axis="1 0 0"/>', '').replace('<joint name="y" type="slide" axis="0 1 0"/>',
                                                                   '<freejoint/>'), "exactly 3 joints"),
    ("extra joint", _sub('<site name="base_link"/>', '<site name="base_link"/><body><joint type="hinge"/>'
                         '<geom size="0.01" mass="0.1"/></body>'), "exactly 3 joints"),
    ("limited joint", _sub('axis="1 0 0"/>', 'axis="1 0 0" range="-5 5"/>'), "no limits"),
    ("damped joint", _sub('axis="0 1 0"/>', 'axis="0 1 0" damping="3"/>'), "no damping"),
    ("hinge off centre", _sub('type="hinge" axis="0 0 1"/>', 'type="hinge" axis="0 0 1" pos="0.1 0 0"/>'),
     "through the origin"),
    ("no radius", _sub(_RADIUS, ""), "no footprint radius"),
    ("radius tiny", _sub(_RADIUS, _RADIUS.replace("0.30", "0.01")), "in [0.05, 2.0]"),
    ("radius huge", _sub(_RADIUS, _RADIUS.replace("0.30", "3")), "in [0.05, 2.0]"),
    ("radius nan", _sub(_RADIUS, _RADIUS.replace("0.30", "nan")), "NaN, infinite"),
    ("radius two numbers", _sub(_RADIUS, _RADIUS.replace("0.30", "0.3 0.3")), "no footprint radius"),
    ("geom outside radius", _sub(_RADIUS, _RADIUS.replace("0.30", "0.27")), "outside the footprint"),
    ("contacts on", _sub('<flag contact="disable"/>', ""), "contacts must be off"),
    ("world geom", _sub("<worldbody>", '<worldbody><geom type="plane" size="5 5 0.1"/>'), "world body"),
    ("include", _sub("<worldbody>", '<include file="other.xml"/><worldbody>'), "<include> is refused"),
    ("mesh file", _sub("<worldbody>", '<asset><mesh name="m" file="/etc/passwd"/></asset><worldbody>'),
     "attribute file="),
    ("mesh dir", _sub('<compiler angle="radian"', '<compiler meshdir="/etc" angle="radian"'), "meshdir="),
    ("doctype", '<!DOCTYPE m [<!ENTITY a "b">]>' + BASE, "DOCTYPE"),
    ("size", _sub("<worldbody>", '<size memory="100G"/><worldbody>'), "<size> is refused"),
    ("replicate", _sub("<worldbody>", '<worldbody><replicate count="2" offset="1 0 0"><body/></replicate>'),
     "<replicate> is refused"),
    ("not xml", BASE[:200], "not well-formed XML"),
    ("not mujoco", BASE.replace("<mujoco", "<robot", 1).replace("</mujoco>", "</robot>"), "root element"),
    ("deep nesting", _sub("</worldbody>", "<body>" * 40 + "</body>" * 40 + "</worldbody>"), "nested more than"),
    ("unknown element", _sub("<worldbody>", "<nonsense/><worldbody>"), "MuJoCo cannot compile it"),
    ("actuator missing", _sub(_V, ""), "actuators must be"),
    ("omni names on diff gears", _sub('name="no_slip"', 'name="vy"'), "actuators must be"),
    ("position actuator", _sub(_V, '<position name="v" site="base_link" gear="1 0 0 0 0 0" kp="100"/>'),
     "<velocity> actuator"),
    ("joint transmission", _sub(_V, '<velocity name="v" joint="x" kv="3150"/>'), "site 'base_link'"),
    ("wrong gear", _sub(_V, _V.replace('gear="1 0 0 0 0 0"', 'gear="2 0 0 0 0 0"')), 'gear "1 0 0 0 0 0"'),
    ("ctrlrange", _sub(_V, _V.replace("/>", ' ctrlrange="-0.3 0.3"/>')), "no ctrlrange"),
    ("slow servo", _sub(_V, _V.replace('kv="3150"', 'kv="100"')), "too slowly"),
    ("kv huge", _sub(_V, _V.replace('kv="3150"', 'kv="1e9"')), "kv in (0, 1e+06]"),
    ("site moved", _sub('<site name="base_link"/>', '<site name="base_link" pos="0.1 0 0"/>'), "origin of 'base'"),
    ("no site", _sub('<site name="base_link"/>', ""), "base_link"),
    ("equality", _sub("<actuator>", '<equality><joint joint1="x" joint2="y"/></equality><actuator>'), "equality"),
]


@pytest.mark.parametrize("xml, words", [b[1:] for b in BROKEN], ids=[b[0] for b in BROKEN])
def test_broken_robots_are_refused_with_one_line(xml, words):
  with pytest.raises(R.RobotModelError) as e:
    R.robot_from_xml(xml, name="r.xml")
  msg = str(e.value)
  assert words in msg and msg.startswith("r.xml: ") and "\n" not in msg and len(msg) < 600, msg


def test_files_that_are_not_regular_small_utf8_are_refused(tmp_path):
  big = tmp_path / "big.xml"
  big.write_bytes(b" " * (R.MAX_BYTES + 1))
  latin = tmp_path / "latin.xml"
  latin.write_bytes(BASE.replace("0.30", "0.30\xe9").encode("latin-1"))
  fifo = tmp_path / "fifo.xml"
  os.mkfifo(fifo)
  for path, words in ((tmp_path / "none.xml", "does not exist"), (tmp_path, "not a regular file"),
                      (fifo, "not a regular file"), (big, "at most 1048576 bytes"), (latin, "not UTF-8")):
    with pytest.raises(R.RobotModelError, match=words):
      R.load_robot(path)
  with pytest.raises(R.RobotModelError, match="at most"):
    R.robot_from_xml(b" " * (R.MAX_BYTES + 1))


def test_builtin_robot_is_not_the_interface():
  """The built-in robot's actuators act on world-frame joints: it is the fleet's default, not a --robot file."""
  with pytest.raises(R.RobotModelError, match="base_link"):
    R.load_robot(R.ROBOT_XML)


def test_planar_ctrl_drives_the_forward_and_yaw_actuators():
  v, w, th = jnp.asarray([0.4, -0.2]), jnp.asarray([1.0, 0.5]), jnp.asarray([0.3, -2.0])
  for path in (DIFF, OMNI):
    r = R.load_robot(path)
    ctrl = np.asarray(R.planar_ctrl(r, v, w, th))
    want = np.zeros((2, 3), np.float32)
    want[:, r.forward], want[:, r.yaw] = v, w
    np.testing.assert_array_equal(ctrl, want)
  world = np.asarray(R.planar_ctrl(None, v, w, th))          # the built-in robot: rotated into the world
  np.testing.assert_allclose(world, np.stack([v * np.cos(th), v * np.sin(th), w], 1), rtol=1e-6)


def test_spawn_spacing_grows_with_the_robot():
  assert spawn_spacing(FleetConfig()) == SPAWN_SPACING
  big = R.load_robot(DIFF).configure(FleetConfig())
  assert spawn_spacing(big) == SPAWN_SPACING
  huge = FleetConfig(robot=FleetConfig().robot.__class__(radius=0.6))
  assert spawn_spacing(huge) == pytest.approx(1.3)


def test_a_robot_smaller_than_the_map_cells_is_refused():
  r = R.load_robot(OMNI)
  with pytest.raises(R.RobotModelError, match="below the map resolution"):
    r.check_resolution(0.2)
  r.check_resolution(0.05)


def test_a_robot_the_config_cannot_hold_is_refused():
  """A radius the FleetConfig refuses (the local costmap must cover the planner's reach) is a ValueError."""
  xml = BASE.replace(_RADIUS, _RADIUS.replace("0.30", "1.5"))
  with pytest.raises(ValueError, match="local_costmap_size"):
    R.robot_from_xml(xml).configure(FleetConfig())


# ----------------------------------------------------------------------------- in the fleet

CHUNK, CHUNKS = 5, 15          # 15 s simulated in 1 s chunks (the CLI's shape with --chunk-seconds 1)


def _zone_crossings(env) -> list[tuple[int, int]]:
  """(spawn index, station index) per speed zone: the shortest spawn-to-station segment of 3-8 m, both ends
  outside every zone, whose middle third lies in the zone (host NumPy on the speed mask), so a robot placed
  there and sent to that station drives through the zone."""
  sc = env.world.scenario.speed
  zone = np.asarray(env.params.zone_table)[sc.data.astype(np.uint8)]
  res = float(sc.resolution)

  def zone_at(p):
    c = np.floor((p[..., 0] - sc.origin[0]) / res).astype(int)
    r = np.floor((p[..., 1] - sc.origin[1]) / res).astype(int)
    inside = (r >= 0) & (r < zone.shape[0]) & (c >= 0) & (c < zone.shape[1])
    return np.where(inside, zone[np.clip(r, 0, zone.shape[0] - 1), np.clip(c, 0, zone.shape[1] - 1)], -1)

  spawns, stations = np.asarray(env.world.spawns), np.asarray(env.world.stations)
  t = np.linspace(1 / 3, 2 / 3, 9)[:, None]
  out = []
  for k in range(1, env.world.num_zones):
    best = min((float(np.linalg.norm(g - s)), i, j) for i, s in enumerate(spawns) for j, g in enumerate(stations)
               if 3 <= np.linalg.norm(g - s) <= 8 and zone_at(s) == 0 and zone_at(g) == 0
               and np.all(zone_at(s + t * (g - s)) == k))
    out.append(best[1:])
  return out


@pytest.fixture(scope="module", params=[(DIFF, "footprint"), (OMNI, "off")], ids=["diff_drive", "omni"])
def robot_run(request):
  path, escape = request.param
  robot = R.load_robot(path)
  env = FleetEnv.create(config=FleetConfig(robots_per_world=2, keepout_escape=escape), robot=robot)
  states = env.reset_fn()(env.params, env.world_keys(jax.random.PRNGKey(2), 1))
  # Robot k starts beside speed zone k + 1 with a goal across it (the default warehouse has 2 zones).
  crossing = _zone_crossings(env)
  assert len(crossing) == env.num_robots
  qpos, goals = np.array(states.data.qpos), np.full((CHUNK, 1, env.num_robots), -1, np.int32)
  for k, (spawn, station) in enumerate(crossing):
    qpos[0, k, :2] = np.asarray(env.world.spawns)[spawn]
    goals[0, 0, k] = station
  states = dataclasses.replace(states, data=states.data.replace(qpos=jnp.asarray(qpos)))
  run, frames = env.rollout_fn(CHUNK), []
  for c in range(CHUNKS):
    states, f = run(env.params, states, jnp.asarray(goals) if c == 0 else None)
    frames.append(f)
  return robot, env, states, jax.tree.map(lambda *a: np.concatenate([np.asarray(x) for x in a]), *frames)


def test_the_robot_radius_flows_into_the_world(robot_run):
  robot, env, _, _ = robot_run
  assert env.robot is robot and env.config.robot.radius == robot.radius
  assert env.world.config.robot.radius == robot.radius
  assert env.world.inflation.inscribed_radius >= robot.radius
  if env.world.keepout_config is not None:
    assert env.world.keepout_config.robot_radius == np.float32(robot.radius)
  assert env.mj_model.nu == 3 and env.mj_model.opt.timestep == env.config.physics_dt
  spawns = np.asarray(env.world.spawns)
  gaps = np.linalg.norm(spawns[:, None] - spawns[None], axis=-1) + np.eye(len(spawns)) * 1e9
  assert gaps.min() >= 2 * robot.radius


def test_each_robot_keeps_out_of_keepout_and_under_the_speed_limits(robot_run):
  _, env, states, frames = robot_run
  w, m = env.world, states.metrics
  assert int(np.asarray(m.keepout_entries).sum()) == 0 and int(np.asarray(m.keepout_steps).sum()) == 0
  if env.keepout_escape:
    assert int(np.asarray(m.footprint_entries).sum()) == 0
  zm = np.asarray(m.zone_max_speed).reshape(-1, w.num_zones)
  for z in range(1, w.num_zones):
    assert zm[:, z].max() <= w.zone_speed[z] + TOL, (w.zone_labels[z], zm[:, z].max())
  zone_time = np.asarray(m.zone_time).reshape(-1, w.num_zones).sum(0)
  assert np.all(zone_time[1:] > 1.0), f"speed zones not driven: {zone_time}"
  assert np.all(zm[:, 1:].max(0) > 0.9 * np.asarray(w.zone_speed[1:])), "robots crept through the zones"
  assert np.all(frames.speed <= env.config.robot.max_speed + TOL)
  assert np.all(frames.cmd[..., 0] <= frames.speed_cap + 1e-6)
  assert int(np.asarray(m.contacts).sum()) == 0
  assert float(np.asarray(m.distance).sum()) > 2 * CHUNK * CHUNKS * 0.2 * 0.2, "the robots hardly moved"


def test_the_base_moves_as_its_commands_say(robot_run):
  """The last step's velocity in the base frame: forward as commanded, no sideways slip."""
  _, _, states, frames = robot_run
  yaw = np.asarray(states.data.qpos)[0, :, 2]
  vel = np.asarray(states.data.qvel)[0]
  forward = np.cos(yaw) * vel[:, 0] + np.sin(yaw) * vel[:, 1]
  lateral = -np.sin(yaw) * vel[:, 0] + np.cos(yaw) * vel[:, 1]
  np.testing.assert_allclose(forward, frames.cmd[-1, 0, :, 0], atol=0.02)
  np.testing.assert_allclose(vel[:, 2], frames.cmd[-1, 0, :, 1], atol=0.05)
  assert np.all(np.abs(lateral) < 0.03), lateral
