"""The zone filter's mask-type gate, and eager speed filter calls that neither copy the mask per robot nor recompile.
"""


import jax
import numpy as np

import jaxfilters as jf
from jaxfilters.grid import OccupancyGrid
from tests.compile_count import count_compiles


def _grid(data, res=1.0, origin=(0.0, 0.0)):
  return OccupancyGrid.create(np.asarray(data, np.int8), res, origin)


def test_zone_filter_ignores_a_mask_of_type_3():
  table = jf.ZoneTable.create(["v"], {"v": 1.0}, {5: {"v": 0.5}})
  data = np.full((4, 4), 5, np.int8)
  for t, applied in ((3, False), (4, True)):
    mask = jf.FilterMask.create(_grid(data), jf.FilterInfo.create(t))
    state, out = jf.zone_filter(mask, np.array([[1.5, 1.5, 0.0]], np.float32), jf.ZoneState.create(table, 1),
                                table)
    assert bool(out.event[0]) is applied and int(out.zone[0]) == (5 if applied else 0)
    assert float(out.params[0, 0]) == (0.5 if applied else 1.0) and not bool(out.error[0])


def test_eager_speed_filter_compiles_once_without_per_robot_mask_copies():
  b, h, w = 4096, 300, 200
  mask = jf.FilterMask.create(_grid(np.random.default_rng(0).integers(0, 100, (h, w)), 0.05, (0.0, 0.0)),
                              jf.FilterInfo.create(1, 100.0, -1.0))
  poses = np.random.default_rng(1).uniform(0, 9, (b, 3)).astype(np.float32)
  state, out = jf.speed_filter(mask, poses, jf.SpeedState.create(b))
  with count_compiles() as compiles:   # new values, same shapes: nothing compiles
    state, out = jf.speed_filter(mask, poses[::-1].copy(), state)
  assert compiles() == 0
  compiled = jax.jit(jf.speed_filter).lower(mask, poses, state).compile()
  temp = compiled.memory_analysis().temp_size_in_bytes
  assert temp < b * h * w // 10, temp        # a per-robot copy of the mask would be B*H*W bytes

