"""sims/fleet/metrics.py kernels on hand-built cases: physics and proximity updates, zone and keepout lookups, summaries.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from sims.fleet import metrics as metrics_lib
from sims.fleet.scenario import Scenario


def test_physics_update_hand_built():
  m = metrics_lib.Metrics.zeros(3, 3)
  prev = jnp.asarray([False, True, False])
  speed = jnp.asarray([0.5, 0.2, 0.1])
  zone = jnp.asarray([0, 2, 1])
  keep = jnp.asarray([False, True, True])
  step = jnp.asarray([0.005, 0.002, 0.001])
  for _ in range(4):
    m, prev = metrics_lib.physics_update(m, prev, jnp.zeros((3, 2)), step, speed, zone, keep, 0.01)
  np.testing.assert_allclose(np.asarray(m.distance), [0.02, 0.008, 0.004], rtol=1e-6)
  np.testing.assert_allclose(np.asarray(m.zone_time), [[0.04, 0, 0], [0, 0, 0.04], [0, 0.04, 0]], atol=1e-7)
  np.testing.assert_allclose(np.asarray(m.zone_max_speed), [[0.5, 0, 0], [0, 0, 0.2], [0, 0.1, 0]])
  assert np.asarray(m.keepout_steps).tolist() == [0, 4, 4]
  assert np.asarray(m.keepout_entries).tolist() == [0, 0, 1]     # robot 1 was already inside


def test_proximity_update_hand_built():
  m = metrics_lib.Metrics.zeros(4, 1)
  xy = jnp.asarray([[0.0, 0.0], [0.40, 0.0], [5.0, 0.0], [5.47, 0.0]])
  c, n = jnp.zeros(4, bool), jnp.zeros(4, bool)
  for _ in range(3):                                   # a standing pair counts once
    m, c, n = metrics_lib.proximity_update(m, c, n, xy, 0.22, 0.05)
  assert np.asarray(m.contacts).tolist() == [1, 1, 0, 0]
  assert np.asarray(m.near_misses).tolist() == [1, 1, 1, 1]
  np.testing.assert_allclose(np.asarray(m.min_separation), [0.4, 0.4, 0.47, 0.47], rtol=1e-5)
  m, c, n = metrics_lib.proximity_update(m, c, n, xy.at[1, 0].set(3.0), 0.22, 0.05)
  m, c, n = metrics_lib.proximity_update(m, c, n, xy, 0.22, 0.05)   # apart, then back: a new event
  assert np.asarray(m.contacts).tolist() == [2, 2, 0, 0]


def test_zone_and_keepout_lookups_on_default_maps():
  from jaxfilters.types import FilterInfo, FilterMask
  from sims.fleet.world import zone_tables
  sc = Scenario.default()
  table, labels, _, _ = zone_tables(sc, 0.5)
  speed = FilterMask.create(sc.speed, FilterInfo.create(1, 100.0, -1.0))
  keepout = FilterMask.create(sc.keepout, FilterInfo.create(0))
  pts = jnp.asarray([[0.0, 0.0], [13.0, 5.0], [-10.0, 5.0], [8.0, 2.5], [100.0, 0.0], [-0.99, -2.99],
                     [-1.0, -3.0]], jnp.float32)
  zones = np.asarray(jax.jit(jax.vmap(lambda q: metrics_lib.zone_at(speed, jnp.asarray(table), q)))(pts))
  keep = np.asarray(jax.jit(jax.vmap(lambda q: metrics_lib.in_keepout(keepout, q)))(pts))
  assert labels == ("none", "50%", "30%")
  # The zone's lower-left corner cell starts at (-1, -3) in decimal, but float32(0.05) > 0.05, so
  # Nav2's floor((w - o) / res) puts the point (-1, -3) itself one cell outside.
  assert zones.tolist() == [1, 2, 0, 0, 0, 1, 0]
  assert keep.tolist() == [False, False, False, True, False, False, False]


def test_summarize_flags_violations():
  m = metrics_lib.Metrics.zeros(2, 2)
  m = dataclasses.replace(m, zone_max_speed=jnp.asarray([[0.5, 0.27], [0.4, 0.2]]),
                          keepout_entries=jnp.asarray([0, 1]))
  out = metrics_lib.summarize(jax.tree.map(lambda a: a[None], m), zone_labels=("none", "50%"),
                              zone_limits=(0.0, 50.0), zone_speed=(np.inf, 0.25), speed_tolerance=0.01,
                              seconds=1.0)
  f = out["fleet"]
  assert [z["compliant"] for z in f["zones"]] == [True, False]
  assert not f["speed_compliant"] and f["keepout_entries"] == 1 and len(out["robots"]) == 2

