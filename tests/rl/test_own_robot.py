"""NavEnv.create(robot=...): the RL env on your own MJCF base (sims/fleet/robot.py), its radius in the
costmaps the observations and collisions read, and its actuators driven by the policy's (v, w)."""

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sims.fleet.robot import RobotModelError, load_robot
from sims.rl.env import NavEnv

DIFF = Path(__file__).resolve().parents[2] / "examples" / "robots" / "diff_drive.xml"


def test_the_env_drives_the_robot_with_its_radius():
  robot = load_robot(DIFF)
  env = NavEnv.create(robot=robot)
  default = NavEnv.create()
  assert env.fleet_config.robot.radius == robot.radius == 0.30
  assert env.xml_path == robot.name and env.mj_model.nu == 3
  # The bigger robot's inflated static layer (what observations and collisions read) is wider.
  wide, narrow = np.asarray(env.mjx_model.task.static_inflated), np.asarray(default.mjx_model.task.static_inflated)
  assert np.sum(wide >= 253) > np.sum(narrow >= 253)
  state = jax.jit(env.reset)(jax.random.PRNGKey(3))
  yaw0 = float(state.data.qpos[0, 2])
  step = jax.jit(env.step)
  for _ in range(3):                                      # full speed ahead, no turn: 0.6 s
    state = step(state, jnp.asarray([1.0, 0.0], jnp.float32))
  vel = np.asarray(state.data.qvel[0])
  yaw = float(state.data.qpos[0, 2])
  forward = np.cos(yaw) * vel[0] + np.sin(yaw) * vel[1]
  lateral = -np.sin(yaw) * vel[0] + np.cos(yaw) * vel[1]
  speed_cap = float(np.asarray(state.info["cap"])[0])
  assert forward > 0.05 and forward <= min(env.fleet_config.robot.max_speed, speed_cap) + 0.01
  assert abs(lateral) < 1e-3 and abs(yaw - yaw0) < 1e-3


def test_the_env_refuses_what_is_not_a_robot_model():
  with pytest.raises(RobotModelError, match="must be a RobotModel"):
    NavEnv.create(robot=str(DIFF))
