"""StaticLayer: OccupancyGrid data -> Nav2 costs (`StaticLayer::interpretValue`, docs/nav2_semantics.md §1.5).

This is **not** the filters' mask conversion (docs/nav2_semantics.md §1.4, round(2.54 d)): the static
layer is trinary by default and maps the inscribed value 99 to 253 (pitfall 19).

Nav2 reads each int8 cell as uint8 (so -1 becomes 255, -2 becomes 254, ...) and
tests, in this order:

1. v == unknown_cost_value: 255 if track_unknown_space else 0;
2. v == inscribed_obstacle_cost_value: 253;
3. v >= lethal_threshold: 254 (every uint8 from 100 to 254 with the defaults,
   i.e. int8 100..127 and the negatives other than -1);
4. trinary_costmap: 0;
5. otherwise uint8(trunc(double(v) / lethal_threshold * 254)).

The conversion is a pure function of one byte, so it is evaluated once per
configuration on the host, in float64 exactly as Nav2 writes it, into a
256-entry table; the device only indexes that table. The table is therefore
bit-exact by construction. (For v < threshold the double result also equals the
integer `(v * 254) // threshold` for every threshold 1..100; tests check both.)
A threshold of 0 makes `v >= 0` always true, so every value that is neither
unknown nor inscribed is lethal and the division in step 5 is never reached.

The function is elementwise and works on any shape ([H, W], [B, H, W], ...), so
there is no per-robot kernel to vmap.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants

__all__ = ["StaticLayerConfig", "static_layer", "static_layer_table"]


def _check_int(name: str, value, lo: int | None = None, hi: int | None = None) -> int:
  if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
    raise ValueError(f"StaticLayerConfig.{name} must be an int; got {value!r}")
  value = int(value)
  if (lo is not None and value < lo) or (hi is not None and value > hi):
    raise ValueError(f"StaticLayerConfig.{name} must be in [{lo}, {hi}] (a uint8 cell "
                     f"value); got {value}")
  return value


@dataclasses.dataclass(frozen=True)
class StaticLayerConfig:
  """Costmap-level parameters read by the StaticLayer (Nav2 defaults).

  Frozen and hashable: it is a static argument, and each distinct config
  compiles its own (tiny) table. Change it with `dataclasses.replace`.

  Attributes:
    lethal_cost_threshold: int; Nav2 clamps it to [0, 100] (see
      `lethal_threshold`). Any int is accepted, as Nav2 accepts it.
    unknown_cost_value: int in [0, 255], compared with the cell read as uint8
      (255 is int8 -1).
    inscribed_obstacle_cost_value: int in [0, 255]; this value becomes 253.
    trinary_costmap: bool; below-threshold values become 0 instead of scaled.
    track_unknown_space: bool; unknown becomes 255 instead of 0.

  Raises:
    ValueError: a field of the wrong type or out of range.
  """
  lethal_cost_threshold: int = 100
  unknown_cost_value: int = 255
  inscribed_obstacle_cost_value: int = 99
  trinary_costmap: bool = True
  track_unknown_space: bool = False

  def __post_init__(self):
    # Normalise numpy scalars to Python ints so equal configs hash equally.
    object.__setattr__(self, "lethal_cost_threshold",
                       _check_int("lethal_cost_threshold", self.lethal_cost_threshold))
    object.__setattr__(self, "unknown_cost_value",
                       _check_int("unknown_cost_value", self.unknown_cost_value, 0, 255))
    object.__setattr__(self, "inscribed_obstacle_cost_value",
                       _check_int("inscribed_obstacle_cost_value",
                                  self.inscribed_obstacle_cost_value, 0, 255))
    for name in ("trinary_costmap", "track_unknown_space"):
      v = getattr(self, name)
      if not isinstance(v, (bool, np.bool_)):
        raise ValueError(f"StaticLayerConfig.{name} must be a bool; got {v!r}")
      object.__setattr__(self, name, bool(v))

  @property
  def lethal_threshold(self) -> int:
    """The threshold Nav2 uses: `max(min(lethal_cost_threshold, 100), 0)`."""
    return max(min(self.lethal_cost_threshold, 100), 0)


@functools.lru_cache(maxsize=64)
def _table(config: StaticLayerConfig) -> np.ndarray:
  t = config.lethal_threshold
  out = np.empty(256, np.uint8)
  for v in range(256):
    if v == config.unknown_cost_value:
      c = constants.NO_INFORMATION if config.track_unknown_space else constants.FREE_SPACE
    elif v == config.inscribed_obstacle_cost_value:
      c = constants.INSCRIBED_INFLATED_OBSTACLE
    elif v >= t:
      c = constants.LETHAL_OBSTACLE
    elif config.trinary_costmap:
      c = constants.FREE_SPACE
    else:
      # Nav2: `double scale = double(value) / lethal_threshold_; return scale * 254;`
      # (implicit double -> unsigned char conversion truncates; 0 <= result < 254).
      c = int(float(v) / t * constants.LETHAL_OBSTACLE)
    out[v] = c
  out.setflags(write=False)
  return out


def static_layer_table(config: StaticLayerConfig = StaticLayerConfig()) -> np.ndarray:
  """The full conversion as a host table.

  Args:
    config: the StaticLayer parameters.

  Returns:
    uint8 [256] (read-only): entry v is the cost of a cell whose byte, read as
    uint8, is v (int8 -1 is entry 255).
  """
  if not isinstance(config, StaticLayerConfig):
    raise TypeError(f"config must be a StaticLayerConfig; got {type(config).__name__}")
  return _table(config)


def static_layer(data, *, config: StaticLayerConfig = StaticLayerConfig()) -> jax.Array:
  """Converts OccupancyGrid data to StaticLayer costs, cell by cell (docs/nav2_semantics.md §1.5).

  Args:
    data: int8 array of any shape, e.g. [H, W] or [B, H, W]: OccupancyGrid
      values (-1 unknown, 0..100). uint8 is also accepted and taken as the raw
      bytes Nav2 reads (255 is -1).
    config: the StaticLayer parameters (static under `jit`).

  Returns:
    uint8 array of the same shape: Nav2 costs.

  Raises:
    ValueError: data of another dtype.
    TypeError: config that is not a StaticLayerConfig.
  """
  table = static_layer_table(config)
  with jax.named_scope("static_layer"):
    data = jnp.asarray(data)
    if data.dtype == jnp.int8:
      data = jax.lax.bitcast_convert_type(data, jnp.uint8)
    elif data.dtype != jnp.uint8:
      raise ValueError(f"static_layer expects int8 OccupancyGrid data (or its uint8 bytes); "
                       f"got {data.dtype}")
    return jnp.asarray(table)[data.astype(jnp.int32)]
