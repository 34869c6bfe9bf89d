"""Layers then filters, in Nav2's order (docs/nav2_semantics.md §2.5).

`LayeredCostmap::updateMap` with filters: the *primary* map gets the plugins
(static layer, obstacles, inflation), is copied into the *combined* map, and
the filters run on the combined map only. So filter output is never inflated.
The inflation layers (`LayersConfig.layers`: InflationLayer and
AsymmetricInflationLayer, `LayersConfig.from_nav2` takes them from a params
file's `plugins:`) run in their `plugins:` order; an AsymmetricInflationLayer
reads each robot's plan (`paths`, `path_lengths`) and position (the poses').
`keepout_as_layer=True` models users who list the keepout filter under
`plugins:` before the inflation layer (docs PR #972): it then runs on the
primary map and its zones are inflated. With escape mode on, cells written
with `lethal_override_cost` (<= 252) are not inflation sources, so a zone the
robot is escaping has no inscribed band; with `KeepoutConfig(robot_in_zone=
"footprint")` escape lasts until the whole footprint (grown by
`escape_clearance`) is out, so the band that returns cannot hold the robot
(issue #6505; jaxfilters/footprint.py).

Each call is one Nav2 cycle: every layer's and filter's updateBounds, then
every updateCosts. The layers here redraw the whole map (a rolling local
costmap and a freshly loaded global costmap do), so their bounds are the map's
extent; the keepout filter's updateBounds then runs the robot-in-zone test of
its escape mode (`override_lethal_cost`) before its process() writes the zones.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from jaxfilters.asymmetric_inflation import AsymmetricInflationConfig, asymmetric_inflate
from jaxfilters.inflation import InflationConfig, inflate
from jaxfilters import validate
from jaxfilters.keepout import KeepoutConfig, KeepoutState, keepout_filter, keepout_update_bounds
from jaxfilters.nav2.runtime import Nav2Costmap
from jaxfilters.speed import SpeedResult, SpeedState, speed_filter
from jaxfilters.static_layer import StaticLayerConfig, static_layer
from jaxfilters.types import Costmap, FilterMask, check_poses, pytree_dataclass


@dataclasses.dataclass(frozen=True)
class LayersConfig:
  """Static pipeline configuration.

  Attributes:
    static: StaticLayerConfig for the occupancy -> cost conversion.
    inflation: InflationConfig, or None for no inflation layer (shorthand for
      `layers=(inflation,)`; give one of the two).
    keepout: KeepoutConfig for the keepout filter.
    keepout_as_layer: run keepout on the primary map before inflation.
    layers: the inflation layers in `plugins:` order, each an InflationConfig
      (`inflate`) or an AsymmetricInflationConfig (`asymmetric_inflate`, which
      needs `paths` and `path_lengths` in `costmap_pipeline`).
  """
  static: StaticLayerConfig = StaticLayerConfig()
  inflation: InflationConfig | None = None
  keepout: KeepoutConfig = KeepoutConfig()
  keepout_as_layer: bool = False
  layers: tuple[InflationConfig | AsymmetricInflationConfig, ...] = ()

  def __post_init__(self):
    if not isinstance(self.static, StaticLayerConfig):
      raise ValueError(f"static must be a StaticLayerConfig; got {type(self.static).__name__}")
    if self.inflation is not None and not isinstance(self.inflation, InflationConfig):
      raise ValueError(f"inflation must be an InflationConfig or None; got {type(self.inflation).__name__}")
    if not isinstance(self.keepout, KeepoutConfig):
      raise ValueError(f"keepout must be a KeepoutConfig; got {type(self.keepout).__name__}")
    if not isinstance(self.layers, tuple) or not all(
        isinstance(x, (InflationConfig, AsymmetricInflationConfig)) for x in self.layers):
      raise ValueError("layers must be a tuple of InflationConfig / AsymmetricInflationConfig; got "
                       f"{validate.short_repr(self.layers)}")
    if self.inflation is not None and self.layers:
      raise ValueError("give the inflation layers either as inflation= (one InflationConfig) or as layers= "
                       "(in plugins: order), not both")

  @property
  def inflation_layers(self) -> tuple[InflationConfig | AsymmetricInflationConfig, ...]:
    """The inflation layers run in order: `layers`, or `(inflation,)`, or none."""
    return self.layers or (() if self.inflation is None else (self.inflation,))

  @property
  def needs_paths(self) -> bool:
    """Whether an AsymmetricInflationLayer is configured (`costmap_pipeline` then needs `paths`)."""
    return any(isinstance(x, AsymmetricInflationConfig) for x in self.layers)

  @classmethod
  def from_nav2(cls, costmap: Nav2Costmap, *, resolution: float | None = None, **kwargs) -> LayersConfig:
    """The LayersConfig running a params file's inflation layers in its `plugins:` order.

    Args:
      costmap: a `Nav2Costmap` (`load_params(...).costmap(name)`); its `layers`
        (InflationLayer, AsymmetricInflationLayer) become `layers`, each with its
        parameters, the costmap's resolution and its footprint's inscribed radius.
      resolution: metres per cell of the costmaps the pipeline gets, when it is not
        the costmap's `resolution` parameter (a global costmap sized by its static
        map takes the map's); None keeps each layer's.
      **kwargs: the other LayersConfig fields (static, keepout, keepout_as_layer).

    Returns:
      The LayersConfig.

    Raises:
      TypeError: `costmap` that is not a Nav2Costmap.
      ValueError: `inflation` or `layers` in kwargs, or a resolution the layer
        configs reject.
    """
    if not isinstance(costmap, Nav2Costmap):
      raise TypeError(f"from_nav2 takes a Nav2Costmap (load_params(...).costmap(name)); got "
                       f"{type(costmap).__name__}")
    for key in ("inflation", "layers"):
      if key in kwargs:
        raise ValueError(f"from_nav2 takes the inflation layers from the costmap; got {key}= as well")
    layers = tuple(x.config for x in costmap.layers)
    if resolution is not None:
      layers = tuple(dataclasses.replace(x, resolution=resolution) for x in layers)
    return cls(layers=layers, **kwargs)


@pytree_dataclass
class PipelineOutput:
  """One costmap cycle.

  Attributes:
    primary: Costmap, layers only (what plugins see).
    combined: Costmap, layers then filters (what planners and controllers see).
    keepout_state: KeepoutState [B] or None.
    speed_state: SpeedState [B] or None.
    speed: SpeedResult [B] or None.
  """
  primary: Costmap
  combined: Costmap
  keepout_state: KeepoutState | None
  speed_state: SpeedState | None
  speed: SpeedResult | None


def costmap_pipeline(static_data, origin, resolution, poses, *, config: LayersConfig,
                     obstacles=None, keepout_mask: FilterMask | None = None,
                     keepout_state: KeepoutState | None = None, speed_mask: FilterMask | None = None,
                     speed_state: SpeedState | None = None, mask_index=None,
                     enabled=None, new_keepout_mask=None, paths=None, path_lengths=None) -> PipelineOutput:
  """Static layer (+ obstacles) -> inflation layers -> filters on the combined map.

  Args:
    static_data: int8 [B, H, W] occupancy under each robot's costmap.
    origin: float [B, 2]; resolution: float [B] (must equal the inflation
      config's resolution in float32).
    poses: float [B, 3].
    config: static LayersConfig.
    obstacles: optional bool [B, H, W] marked lethal (obstacle layer: other
      robots, sensor hits).
    keepout_mask, keepout_state: keepout filter inputs (both or neither).
    speed_mask, speed_state: speed filter inputs (both or neither).
    mask_index, enabled: passed to the filters.
    new_keepout_mask: optional bool [B] or scalar: a new keepout mask arrived
      since the last cycle (Nav2's updateBounds then grows the bounds and
      skips the robot-in-zone test this cycle).
    paths, path_lengths: each robot's plan, float32 [B, P, 2] in world metres in
      the costmaps' frame and int32 [B] points in use, for an
      AsymmetricInflationLayer in `config.layers` (required then, refused
      otherwise); the robot position it reads is `poses[:, :2]` as float32.

  Returns:
    PipelineOutput.

  Raises:
    ValueError: inputs that go together given alone (keepout_mask and
      keepout_state, speed_mask and speed_state, paths and path_lengths), an
      AsymmetricInflationLayer without paths or paths without one, and what
      the layers and filters reject.
  """
  with jax.named_scope("costmap_pipeline"):
    if (keepout_mask is None) != (keepout_state is None):
      raise ValueError("keepout_mask and keepout_state go together; got only one of them")
    if (speed_mask is None) != (speed_state is None):
      raise ValueError("speed_mask and speed_state go together; got only one of them")
    if (paths is None) != (path_lengths is None):
      raise ValueError("paths and path_lengths go together; got only one of them")
    if config.needs_paths and paths is None:
      raise ValueError("config.layers has an AsymmetricInflationLayer, which reads each robot's plan: pass "
                       "paths (float32 [B, P, 2], metres in the costmaps' frame) and path_lengths (int32 [B])")
    if paths is not None and not config.needs_paths:
      raise ValueError("paths were given but config.layers has no AsymmetricInflationLayer to read them")
    cost = static_layer(static_data, config=config.static)
    if obstacles is not None:
      obstacles = jnp.asarray(obstacles)
      if obstacles.shape != cost.shape or obstacles.dtype != jnp.bool_:
        raise ValueError(f"obstacles must be bool {tuple(cost.shape)}; got {obstacles.dtype}{tuple(obstacles.shape)}")
      # ObstacleLayer uses max-combination: marking raises a cell to lethal.
      cost = jnp.where(obstacles, jnp.uint8(constants.LETHAL_OBSTACLE), cost)
    primary = _geometry(cost, origin, resolution)
    bounds_error = None
    if keepout_mask is not None:
      # updateBounds pass (docs/nav2_semantics.md §2.5, §4.2): layers redraw the whole map.
      b = cost.shape[0]
      res = primary.resolution if primary.resolution_lo is None else (
          primary.resolution + primary.resolution_lo[:, 0] + primary.resolution_lo[:, 1])
      org = primary.origin
      size = jnp.asarray([cost.shape[2], cost.shape[1]], jnp.float32)
      bounds = jnp.concatenate([org, org + size[None, :] * res[:, None]], axis=1)
      keepout_state, _ = keepout_update_bounds(primary, keepout_mask, poses, keepout_state,
                                               jnp.broadcast_to(bounds, (b, 4)),
                                               new_mask=new_keepout_mask, mask_index=mask_index,
                                               enabled=enabled, config=config.keepout)
      bounds_error = keepout_state.error
    if keepout_mask is not None and config.keepout_as_layer:
      primary, keepout_state = keepout_filter(primary, keepout_mask, poses, keepout_state,
                                              mask_index=mask_index, enabled=enabled, config=config.keepout)
    for layer in config.inflation_layers:
      if isinstance(layer, AsymmetricInflationConfig):
        primary = asymmetric_inflate(primary, paths=paths, path_lengths=path_lengths,
                                     robot_xy=check_poses(poses, cost.shape[0])[:, :2], config=layer)
      else:
        primary = inflate(primary, config=layer)
    combined = primary
    if keepout_mask is not None and not config.keepout_as_layer:
      combined, keepout_state = keepout_filter(primary, keepout_mask, poses, keepout_state,
                                               mask_index=mask_index, enabled=enabled, config=config.keepout)
    if bounds_error is not None:
      # process() sets `error` for its own reason (mask_index); keep updateBounds' too
      # (a "footprint" config's mask finer than min_mask_resolution).
      keepout_state = dataclasses.replace(keepout_state, error=keepout_state.error | bounds_error)
    speed = None
    if speed_mask is not None:
      speed_state, speed = speed_filter(speed_mask, poses, speed_state, mask_index=mask_index, enabled=enabled)
    return PipelineOutput(primary, combined, keepout_state, speed_state, speed)


def _geometry(cost, origin, resolution) -> Costmap:
  """The primary map's Costmap; host float64 geometry is carried exactly (Costmap.create)."""
  b = cost.shape[0]
  if isinstance(origin, jax.core.Tracer) or isinstance(resolution, jax.core.Tracer):
    return Costmap(cost, jnp.broadcast_to(jnp.asarray(origin, jnp.float32), (b, 2)),
                   jnp.broadcast_to(jnp.asarray(resolution, jnp.float32), (b,)))
  o = validate.float32_values(origin, "origin", owner="costmap_pipeline")
  validate.resolution_value(resolution, owner="costmap_pipeline")
  o64 = np.broadcast_to(np.asarray(origin, np.float64), (b, 2))
  r64 = np.broadcast_to(np.asarray(resolution, np.float64), (b,))
  del o
  op, rp = validate.split_float64(o64), validate.split_float64(r64)
  arr = lambda x: jnp.asarray(np.ascontiguousarray(x))
  lo = lambda x: None if not np.any(x) else arr(x)
  return Costmap(cost, arr(op[..., 0]), arr(rp[..., 0]), lo(op[..., 1:]), lo(rp[..., 1:]))
