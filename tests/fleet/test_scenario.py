"""sims/fleet/scenario.py: the built-in scenario files (small, reproducible, loaded through map_io) and speed-limit conversion.
"""

from __future__ import annotations

from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

from jaxfilters import constants
from jaxfilters.grid import OccupancyGrid
from sims.fleet import planner
from sims.fleet.config import FleetConfig
from sims.fleet.scenario import Scenario
from sims.fleet.world import build_world


def _grid(data: np.ndarray, res: float = 0.05) -> OccupancyGrid:
  return OccupancyGrid.create(data.astype(np.int8), res, (0.0, 0.0, 0.0))


def test_default_scenario_files_are_small_and_reproducible(tmp_path):
  from sims.commands import make_default_scenario
  shipped = Path(make_default_scenario.ASSETS)
  total = sum((shipped / f"default_{n}.{e}").stat().st_size for n in ("map", "keepout", "speed")
              for e in ("yaml", "pgm"))
  assert total < 1_000_000
  make_default_scenario.write(tmp_path)
  for n in ("map", "keepout", "speed"):
    for e in ("yaml", "pgm"):
      assert (tmp_path / f"default_{n}.{e}").read_bytes() == (shipped / f"default_{n}.{e}").read_bytes()


def test_default_scenario_loads_through_map_io():
  sc = Scenario.default()
  assert sc.map.data.shape == (400, 600) and sc.map.resolution == pytest.approx(0.05)
  assert sorted(np.unique(sc.keepout.data).tolist()) == [0, 100]
  assert sorted(np.unique(sc.speed.data).tolist()) == [0, 50, 70]     # none, 50 %, 30 %
  assert sorted(np.unique(sc.map.data).tolist()) == [-1, 0, 100]


def test_limit_to_speed_percent_absolute_and_none():
  lim = jnp.asarray([50.0, 0.3, 0.0, 30.0, 80.0])
  percent = jnp.asarray([True, False, True, True, False])
  valid = jnp.asarray([True, True, True, False, True])
  out = np.asarray(planner.limit_to_speed(lim, percent, valid, 0.5))
  np.testing.assert_allclose(out, [0.25, 0.3, np.inf, np.inf, 80.0])   # 0.0 and invalid mean no limit


def test_absolute_speed_mask_zones():
  h, w = 40, 60
  occ = np.zeros((h, w))
  occ[:1], occ[-1:], occ[:, :1], occ[:, -1:] = 100, 100, 100, 100
  speed = np.zeros((h, w))
  speed[:, 20:30] = 3                                     # 3 * 0.1 + 0 = 0.3 m/s (type 2)
  speed[:, 40:45] = 9                                     # 0.9 m/s: above max speed, still a zone
  sc = Scenario("abs", _grid(occ, 0.1), _grid(np.zeros((h, w)), 0.1), _grid(speed, 0.1),
                speed_type=constants.SPEED_FILTER_ABSOLUTE, speed_base=0.0, speed_multiplier=0.1)
  world = build_world(sc, FleetConfig(robots_per_world=1, num_stations=2, local_costmap_size=3.0))
  assert world.zone_labels == ("none", "0.9 m/s", "0.3 m/s")
  np.testing.assert_allclose(world.zone_speed[1:], [0.9, 0.3], rtol=1e-6)
  cap = np.asarray(world.params.speed_cap)
  assert cap[20, 25] == pytest.approx(0.3) and np.isinf(cap[20, 5]) and cap[20, 19] == pytest.approx(0.3)

