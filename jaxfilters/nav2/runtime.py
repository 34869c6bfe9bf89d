"""Internal: the ready filter bundles a Nav2 params file resolves to, and their one-call readout.

`jaxfilters.nav2.params` builds these from a `nav2_params.yaml`;
`Nav2Costmap.from_masks` builds them from masks with Nav2's default
parameters. Each `Nav2*Filter` carries its FilterMask and the settings its
filter function takes; `Nav2Costmap.readout` runs every enabled filter's first
cycle at B poses in one jitted call. The public names are re-exported by
`jaxfilters.nav2` and `jaxfilters`.

Where Nav2 logs an error (or a warning) about a filter's CostmapFilterInfo and
carries on (docs/nav2_semantics.md §3: keepout with base != 0 or
multiplier != 1, speed with a type other than 1 or 2, binary with a type
other than 3, zone with base or multiplier set), `info_warning` says so in
words and both builders warn with `Nav2ParamsWarning`.
"""

from __future__ import annotations

import dataclasses
import warnings
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from jaxfilters import geometry
from jaxfilters.asymmetric_inflation import AsymmetricInflationConfig
from jaxfilters.inflation import InflationConfig
from jaxfilters import validate
from jaxfilters.binary import BinaryResult, BinaryState, binary_filter
from jaxfilters.keepout import KeepoutConfig
from jaxfilters.query import keepout_cost_at
from jaxfilters.speed import LookaheadConfig, SpeedResult, SpeedState, speed_filter
from jaxfilters.types import FilterMask, pytree_dataclass, check_poses
from jaxfilters.zone import NUM_ZONES, ZoneResult, ZoneState, ZoneTable, zone_filter

__all__ = ["ASYMMETRIC_INFLATION_PLUGIN", "BINARY_PLUGIN", "COSTMAPS", "FRAME_DEFAULT", "INFLATION_PLUGIN",
           "KEEPOUT_PLUGIN", "SPEED_PLUGIN", "ZONE_PLUGIN", "Nav2BinaryFilter", "Nav2Costmap", "Nav2Filter",
           "Nav2InflationLayer", "Nav2KeepoutFilter", "Nav2ParamsWarning",
           "Nav2Readout", "Nav2SpeedFilter", "Nav2ZoneFilter", "ZoneSetpoint", "ZoneStateConfig",
           "info_warning", "speed_percentage"]

KEEPOUT_PLUGIN = "nav2_costmap_2d::KeepoutFilter"
SPEED_PLUGIN = "nav2_costmap_2d::SpeedFilter"
BINARY_PLUGIN = "nav2_costmap_2d::BinaryFilter"
ZONE_PLUGIN = "nav2_costmap_2d::ZoneParameterFilter"
INFLATION_PLUGIN = "nav2_costmap_2d::InflationLayer"
ASYMMETRIC_INFLATION_PLUGIN = "nav2_costmap_2d::AsymmetricInflationLayer"
COSTMAPS = ("global_costmap", "local_costmap")
# The frame Nav2's costmaps and map servers use when `global_frame` / `frame_id` is not set.
FRAME_DEFAULT = "map"


class Nav2ParamsWarning(UserWarning):
  """Something Nav2 would log and carry on with (a skipped zone, a clamped value, an ignored info)."""


def info_warning(kind: str, ftype: int, base: float, multiplier: float) -> str | None:
  """What Nav2 logs, and then carries on, when filter `kind` gets this CostmapFilterInfo; None if nothing.

  The rules of docs/nav2_semantics.md §3, §5.2, §6.2 and §7: KeepoutFilter
  logs an error for base != 0 or multiplier != 1 and ignores them (it never
  checks the type); SpeedFilter logs an error for a type other than 1 or 2
  and never subscribes to the mask; BinaryFilter likewise for a type other
  than 3; ZoneParameterFilter warns for a base or multiplier that is not the
  default and ignores them.

  Args:
    kind: "keepout", "speed", "binary" or "zone".
    ftype: the info's type.
    base: the info's base.
    multiplier: the info's multiplier.

  Returns:
    A sentence starting with what the info does ("sets base 2.5 / ...",
    "has type 0, ..."), to follow the info's name; or None.
  """
  nondefault = (base, multiplier) != (constants.BASE_DEFAULT, constants.MULTIPLIER_DEFAULT)
  if kind == "keepout" and nondefault:
    return (f"sets base {base} / multiplier {multiplier}; KeepoutFilter ignores them (Nav2 logs an error "
            "and carries on)")
  if kind == "speed" and speed_percentage(ftype) is None:
    return (f"has type {ftype}, not 1 (percent) or 2 (m/s); SpeedFilter logs an error and never subscribes "
            "to the mask, so it limits nothing")
  if kind == "binary" and ftype != constants.BINARY_FILTER:
    return (f"has type {ftype}, not 3; BinaryFilter logs an error and never subscribes to the mask, so its "
            "state never follows the mask")
  if kind == "zone" and nondefault:
    return f"sets base {base} / multiplier {multiplier}; ZoneParameterFilter warns and ignores them"
  return None


def speed_percentage(ftype: int) -> bool | None:
  """True for speed info type 1 (percent), False for type 2 (m/s), None for a type SpeedFilter refuses."""
  return {constants.SPEED_FILTER_PERCENT: True, constants.SPEED_FILTER_ABSOLUTE: False}.get(ftype)


@dataclasses.dataclass(frozen=True, eq=False)
class Nav2Filter:
  """What one costmap filter of a params file resolves to (the fields every filter has).

  Attributes:
    name: the filter's name in the costmap's list ("keepout_filter").
    plugin: the pluginlib class, e.g. "nav2_costmap_2d::KeepoutFilter".
    enabled: Nav2 `enabled`; pass it as `enabled=` to the filter function.
    as_layer: listed under `plugins:` instead of `filters:`: Nav2 then runs it
      on the primary map before later layers such as inflation (docs/nav2_semantics.md §2.5).
    filter_info_topic: absolute CostmapFilterInfo topic it subscribes to
      (None for a costmap built with `Nav2Costmap.from_masks`).
    info_server: full node name of the info server publishing it (or None).
    mask_topic: absolute topic of the mask (or None).
    mask_server: full node name of the map_server serving the mask (or None).
    mask_yaml: path of the mask's map YAML.
    mask_frame: the mask server's `frame_id` (default "map"); when it differs
      from the costmap's `global_frame`, Nav2 uses TF: pass `transform=`
      (T_mask_from_global) to the filter function.
    mask: FilterMask with M = 1: int8 [1, H, W] data, float32 origin and
      resolution, and the info's type, float32 base and multiplier.
    transform_tolerance: seconds, Nav2's TF wait timeout.
  """
  name: str
  plugin: str
  enabled: bool
  as_layer: bool
  filter_info_topic: str | None
  info_server: str | None
  mask_topic: str | None
  mask_server: str | None
  mask_yaml: str
  mask_frame: str
  mask: FilterMask
  transform_tolerance: float


@dataclasses.dataclass(frozen=True, eq=False)
class Nav2KeepoutFilter(Nav2Filter):
  """A KeepoutFilter (docs/nav2_semantics.md §4); see Nav2Filter for the common fields.

  Attributes:
    config: KeepoutConfig from `override_lethal_cost` (default false) and
      `lethal_override_cost` (default 252, clamped to [0, 252] like Nav2).
  """
  config: KeepoutConfig


@dataclasses.dataclass(frozen=True, eq=False)
class Nav2SpeedFilter(Nav2Filter):
  """A SpeedFilter (docs/nav2_semantics.md §5); see Nav2Filter for the common fields.

  Attributes:
    percentage: True for info type 1 (percent), False for type 2 (m/s), None
      for any other type: Nav2 then never subscribes to the mask, and
      `speed_filter` likewise returns valid=False for every robot.
    speed_limit_topic: absolute SpeedLimit topic (default "speed_limit", joined
      with the costmap's parent namespace).
    lookahead: LookaheadConfig when `enable_path_lookahead` is true (use
      `speed_filter_lookahead`), else None (use `speed_filter`).
    path_topic: absolute path topic for the lookahead (default "plan").
    odom_topic: odometry topic as written (default "odom").
  """
  percentage: bool | None
  speed_limit_topic: str | None
  lookahead: LookaheadConfig | None
  path_topic: str | None
  odom_topic: str | None


@dataclasses.dataclass(frozen=True, eq=False)
class Nav2BinaryFilter(Nav2Filter):
  """A BinaryFilter (docs/nav2_semantics.md §6); see Nav2Filter for the common fields.

  Attributes:
    default_state: Nav2 `default_state` (default false).
    flip_threshold: Nav2 `flip_threshold` (default 50.0), a float32 value.
    binary_state_topic: Bool topic (default "binary_state"), resolved in the
      costmap node's namespace because BinaryFilter does not join it (§8.3).
  """
  default_state: bool
  flip_threshold: float
  binary_state_topic: str | None


@dataclasses.dataclass(frozen=True)
class ZoneSetpoint:
  """One Nav2 zone setpoint or nominal default: set `parameter` of `node` to `value`.

  Attributes:
    name: its name in the `setpoints` / `nominal_defaults` list.
    node: target node name.
    parameter: target parameter name.
    value: the value as written (bool, int, float, string or a list).
  """
  name: str
  node: str
  parameter: str
  value: Any


@dataclasses.dataclass(frozen=True)
class ZoneStateConfig:
  """One configured zone state of a ZoneParameterFilter.

  Attributes:
    name: its name in the `states` list.
    id: the mask value selecting it (1..127).
    setpoints: the setpoints it applies, in order.
  """
  name: str
  id: int
  setpoints: tuple[ZoneSetpoint, ...]


@dataclasses.dataclass(frozen=True, eq=False)
class Nav2ZoneFilter(Nav2Filter):
  """A ZoneParameterFilter (docs/nav2_semantics.md §7); see Nav2Filter for the common fields.

  Attributes:
    table: ZoneTable [Z = 128, P] for `zone_filter`: the configured states a
      mask can reach (ids 1..127) and the numeric parameters they set (bools
      as 1.0 / 0.0).
    parameters: the P table columns as (node, parameter); the table's column
      names are "node:parameter".
    states: every state Nav2 keeps (ids 1..255), with all setpoint values
      as written.
      Values a float32 table cannot hold (strings, lists, integers beyond
      2**24) are here but not in `table` (a warning names them).
    nominal_defaults: the values Nav2 restores in state 0, as written.
    state_event_topic: absolute UInt8 state-event topic (default
      "zone_filter_state", joined with the parent namespace).
  """
  table: ZoneTable
  parameters: tuple[tuple[str, str], ...]
  states: tuple[ZoneStateConfig, ...]
  nominal_defaults: tuple[ZoneSetpoint, ...]
  state_event_topic: str | None


@pytree_dataclass
class Nav2Readout:
  """What each enabled filter of a costmap gives on a fresh robot's first cycle, per pose.

  Attributes:
    speed: SpeedResult [B] (speed_limit 0.0 = no limit; valid False = nothing
      published: off the mask, an unknown cell or an unusable info type), or
      None without an enabled speed filter.
    keepout_cost: uint8 [B], the keepout mask's cost under the pose
      (round(2.54 d), docs/nav2_semantics.md §1.4; 255 off the mask or on an unknown cell), or None.
    binary: BinaryResult [B] (state starts False as Nav2's does), or None.
    zone: ZoneResult [B] (`error` True where the mask names a zone id the
      filter does not configure: Nav2 throws there), or None.
  """
  speed: SpeedResult | None
  keepout_cost: jax.Array | None
  binary: BinaryResult | None
  zone: ZoneResult | None


_KIND_FIELDS = {Nav2KeepoutFilter: "keepout", Nav2SpeedFilter: "speed", Nav2BinaryFilter: "binary",
                Nav2ZoneFilter: "zone"}


@dataclasses.dataclass(frozen=True)
class Nav2InflationLayer:
  """An inflation layer a costmap lists under `plugins:` (docs/nav2_semantics.md §9).

  Attributes:
    name: the layer's name in the costmap's `plugins:` list.
    plugin: INFLATION_PLUGIN or ASYMMETRIC_INFLATION_PLUGIN.
    config: the InflationConfig (for `inflate`) or AsymmetricInflationConfig (for
      `asymmetric_inflate`) holding the layer's parameters (Nav2's defaults where the
      file sets none), the costmap's `resolution` parameter (Nav2's default 0.1 when
      absent) and the inscribed radius of the costmap's padded footprint, or the
      InflationLayer's `custom_inscribed_radius` when >= 0. A global costmap that a
      static map sizes takes the map's resolution in Nav2: build it with
      `dataclasses.replace(layer.config, resolution=...)` (`inflate` and
      `asymmetric_inflate` raise on a Costmap whose resolution differs from the config's).
    plan_topic: the AsymmetricInflationLayer's path topic, resolved like Nav2's
      `joinWithParentNamespace`; None for an InflationLayer.
  """
  name: str
  plugin: str
  config: InflationConfig | AsymmetricInflationConfig
  plan_topic: str | None = None


@dataclasses.dataclass(frozen=True, eq=False)
class Nav2Costmap:
  """The filters of one Nav2 costmap (`global_costmap` or `local_costmap`).

  Attributes:
    name: "global_costmap" or "local_costmap" (or what `from_masks` was given).
    node: full node name, e.g. "/global_costmap/global_costmap".
    global_frame: the costmap's `global_frame` (Nav2 default "map"); poses
      given to the filters are in this frame.
    resolution: the costmap's `resolution` (metres per cell) where the file
      sets it, else None.
    filters: every filter in Nav2's order (`filters:` then filter plugins
      listed under `plugins:`).
    layers: the inflation layers listed under `plugins:`, in their order
      (`Nav2InflationLayer`); other layers (static, obstacle, voxel) are not read.
  """
  name: str
  node: str
  global_frame: str
  resolution: float | None
  filters: tuple[Nav2Filter, ...]
  layers: tuple[Nav2InflationLayer, ...] = ()

  def _layer(self, plugin: str) -> Nav2InflationLayer | None:
    found = [layer for layer in self.layers if layer.plugin == plugin]
    if len(found) > 1:
      raise ValueError(f"{self.name} has {len(found)} {plugin} layers ({', '.join(x.name for x in found)}); "
                       "pick one from .layers")
    return found[0] if found else None

  @property
  def inflation(self) -> Nav2InflationLayer | None:
    """The InflationLayer, or None (ValueError if there are several)."""
    return self._layer(INFLATION_PLUGIN)

  @property
  def asymmetric_inflation(self) -> Nav2InflationLayer | None:
    """The AsymmetricInflationLayer, or None (ValueError if there are several)."""
    return self._layer(ASYMMETRIC_INFLATION_PLUGIN)

  def _one(self, cls):
    found = [f for f in self.filters if type(f) is cls]
    if len(found) > 1:
      raise ValueError(f"{self.name} has {len(found)} {cls.__name__[4:]}s "
                       f"({', '.join(f.name for f in found)}); pick one from .filters")
    return found[0] if found else None

  @property
  def keepout(self) -> Nav2KeepoutFilter | None:
    """The keepout filter, or None (ValueError if there are several)."""
    return self._one(Nav2KeepoutFilter)

  @property
  def speed(self) -> Nav2SpeedFilter | None:
    """The speed filter, or None (ValueError if there are several)."""
    return self._one(Nav2SpeedFilter)

  @property
  def binary(self) -> Nav2BinaryFilter | None:
    """The binary filter, or None (ValueError if there are several)."""
    return self._one(Nav2BinaryFilter)

  @property
  def zone(self) -> Nav2ZoneFilter | None:
    """The zone parameter filter, or None (ValueError if there are several)."""
    return self._one(Nav2ZoneFilter)

  def foreign_frames(self) -> tuple[str, ...]:
    """Mask frames of enabled filters that differ from `global_frame` (they need a transform)."""
    return tuple(sorted({f.mask_frame for f in self.filters
                         if f.enabled and f.mask_frame != self.global_frame}))

  @classmethod
  def from_masks(cls, *, keepout: FilterMask | None = None, speed: FilterMask | None = None,
                 binary: FilterMask | None = None, zone: FilterMask | None = None,
                 name: str = "masks", frame: str = FRAME_DEFAULT) -> "Nav2Costmap":
    """A costmap whose filters use these masks with Nav2's default parameters.

    Keepout: KeepoutConfig(); speed: percentage from the mask's info type;
    binary: default_state false, flip_threshold 50.0; zone: every id 1..127 is
    a configured state that sets no parameter. All masks and poses are in
    `frame`; topics and servers are None.

    Warns:
      Nav2ParamsWarning: a mask whose info Nav2 would log an error about and
        then ignore or not use (`info_warning`): a keepout mask with base != 0
        or multiplier != 1, a speed mask whose type is not 1 or 2 (its filter
        limits nothing), a binary mask whose type is not 3, a zone mask with
        base or multiplier set.

    Raises:
      ValueError: a mask that is not a single (M = 1) FilterMask.
    """
    made = []
    for kind, mask in (("keepout", keepout), ("speed", speed), ("binary", binary), ("zone", zone)):
      if mask is None:
        continue
      if not isinstance(mask, FilterMask) or mask.num_masks != 1:
        raise ValueError(f"{kind} must be a FilterMask with one mask (M = 1); got {validate.short_repr(mask)}")
      common = dict(name=kind, enabled=True, as_layer=False, filter_info_topic=None, info_server=None,
                    mask_topic=None, mask_server=None, mask_yaml="", mask_frame=frame, mask=mask,
                    transform_tolerance=0.1)
      ftype = int(mask.info.type[0])
      said = info_warning(kind, ftype, float(mask.info.base[0]), float(mask.info.multiplier[0]))
      if said is not None:
        warnings.warn(f"from_masks: the {kind} mask's info {said}", Nav2ParamsWarning, stacklevel=2)
      if kind == "keepout":
        made.append(Nav2KeepoutFilter(plugin=KEEPOUT_PLUGIN, config=KeepoutConfig(), **common))
      elif kind == "speed":
        made.append(Nav2SpeedFilter(plugin=SPEED_PLUGIN, percentage=speed_percentage(ftype), speed_limit_topic=None,
                                    lookahead=None, path_topic=None, odom_topic=None, **common))
      elif kind == "binary":
        made.append(Nav2BinaryFilter(plugin=BINARY_PLUGIN, default_state=False, flip_threshold=50.0,
                                     binary_state_topic=None, **common))
      else:
        table = ZoneTable.create([], {}, {z: {} for z in range(1, NUM_ZONES)})
        made.append(Nav2ZoneFilter(plugin=ZONE_PLUGIN, table=table, parameters=(), states=tuple(
            ZoneStateConfig(str(z), z, ()) for z in range(1, NUM_ZONES)), nominal_defaults=(),
            state_event_topic=None, **common))
    return cls(name=name, node="", global_frame=frame, resolution=None, filters=tuple(made))

  def readout(self, poses, *, transform=None) -> Nav2Readout:
    """Every enabled filter's first cycle at each pose, each pose a fresh robot (one jitted call).

    Args:
      poses: float [B, 3] (x, y, yaw) in `global_frame`; rounded to float32.
      transform: float [3] T_mask_from_global (x, y, yaw), required when an
        enabled filter's mask frame differs from `global_frame` (Nav2 gets it
        from TF) and refused otherwise.

    Returns:
      Nav2Readout with B results per enabled filter (None for absent or
      disabled ones).

    Raises:
      ValueError: bad poses, a missing or needless transform, masks in two
        foreign frames, or two enabled filters of one kind.
    """
    poses = check_poses(poses, np.shape(poses)[0] if np.ndim(poses) else 0)
    foreign = self.foreign_frames()
    if transform is None and foreign:
      raise ValueError(f"{self.name}: masks in frame {foreign[0]!r} differ from the costmap's global_frame "
                       f"{self.global_frame!r}; pass transform=T_mask_from_global (x, y, yaw), which "
                       "Nav2 takes from TF")
    if transform is not None:
      if not foreign:
        raise ValueError(f"{self.name}: every mask is in the costmap's global_frame {self.global_frame!r}; "
                         "transform is only for masks in another frame")
      if len(foreign) > 1:
        raise ValueError(f"{self.name}: masks in several frames {foreign} differ from global_frame "
                         f"{self.global_frame!r}; one transform cannot serve them")
      transform = validate.float32_values(transform, "transform", owner=self.name)
      if transform.shape != (3,):
        raise ValueError(f"{self.name}: transform must be (x, y, yaw), shape (3,); got {transform.shape}")
    parts = {}
    for f in self.filters:
      if not f.enabled:
        continue
      kind = _KIND_FIELDS[type(f)]
      if kind in parts:
        raise ValueError(f"{self.name} has two enabled {kind} filters; readout takes one of each kind")
      tf = None if f.mask_frame == self.global_frame else jnp.asarray(transform)
      extra = ()
      if kind == "binary":
        extra = (jnp.asarray(f.default_state), jnp.float32(f.flip_threshold))
      elif kind == "zone":
        extra = (f.table,)
      parts[kind] = (f.mask, tf, extra)
    return _readout(parts, poses)





@jax.jit
def _readout(parts, poses):
  b = poses.shape[0]
  speed = keepout = binary = zone = None
  if "speed" in parts:
    mask, tf, _ = parts["speed"]
    _, speed = speed_filter(mask, poses, SpeedState.create(b), transform=tf)
  if "keepout" in parts:
    mask, tf, _ = parts["keepout"]
    x, y = poses[:, 0], poses[:, 1]
    if tf is not None:
      x, y = geometry.transform_points(tf, x, y)
    keepout = keepout_cost_at(mask, jnp.stack([x, y], axis=1), mask_index=jnp.zeros((b,), jnp.int32))
  if "binary" in parts:
    mask, tf, (default_state, threshold) = parts["binary"]
    _, binary = binary_filter(mask, poses, BinaryState.create(b), default_state=default_state,
                              flip_threshold=threshold, transform=tf)
  if "zone" in parts:
    mask, tf, (table,) = parts["zone"]
    _, zone = zone_filter(mask, poses, ZoneState.create(table, b), table, transform=tf)
  return Nav2Readout(speed, keepout, binary, zone)


