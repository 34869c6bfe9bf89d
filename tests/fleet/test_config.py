"""sims/fleet/config.py: FleetConfig refuses bad values; rates and hashing.
"""

from __future__ import annotations

import dataclasses

import pytest

from sims.fleet.config import FleetConfig, PlannerConfig, RobotConfig


@pytest.mark.parametrize("make", [
    lambda: RobotConfig(radius=0.0),
    lambda: RobotConfig(max_speed=-1.0),
    lambda: RobotConfig(max_accel=float("nan")),
    lambda: PlannerConfig(num_speeds=1),
    lambda: PlannerConfig(horizon=1.0, rollout_dt=0.3),
    lambda: FleetConfig(robots_per_world=0),
    lambda: FleetConfig(controller_hz=20.0, costmap_hz=3.0),
    lambda: FleetConfig(physics_dt=0.03),
    lambda: FleetConfig(impl="cuda"),
    lambda: FleetConfig(local_costmap_size=1.0),
    lambda: FleetConfig(robot="big"),
])
def test_config_rejects_bad_values(make):
  with pytest.raises(ValueError):
    make()


def test_config_rates_and_hashing():
  cfg = FleetConfig()
  assert (cfg.ticks_per_step, cfg.substeps_per_tick, cfg.step_seconds) == (4, 5, 0.2)
  assert hash(cfg) == hash(FleetConfig()) and cfg == dataclasses.replace(cfg)
  assert cfg.planner.num_rollout_steps == 15

