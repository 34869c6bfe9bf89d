"""Nav2 params import: a `nav2_params.yaml` -> ready filter objects per costmap.

    params = load_params("nav2_params.yaml",
                         masks={"keepout_filter_mask_server": "warehouse_keepout.yaml",
                                "speed_filter_mask_server": "warehouse_speed.yaml"},
                         substitutions={"KEEPOUT_ZONE_ENABLED": "True",
                                        "SPEED_ZONE_ENABLED": "True"})
    g = params.global_costmap
    state, out = speed_filter(g.speed.mask, poses, SpeedState.create(B), enabled=g.speed.enabled)
    costmap, ks = keepout_filter(costmap, g.keepout.mask, poses, ks,
                                 enabled=g.keepout.enabled, config=g.keepout.config)
    # A costmap with a ZoneParameterFilter (g.zone is None without one):
    zs, zr = zone_filter(g.zone.mask, poses, ZoneState.create(g.zone.table, B), g.zone.table)
    # Every enabled filter's first cycle at B poses, one jitted call:
    out = g.readout(poses)

The file is read the way Nav2 wires its filters (spec §3, §4-§8):

* costmap nodes `global_costmap` / `local_costmap` list filters under
  `filters:` (and, to run one as a layer before inflation, under `plugins:`);
  each filter names a `plugin` class and a `filter_info_topic`;
* `costmap_filter_info_server` nodes (any node with a top-level
  `filter_info_topic` or `mask_topic`, or named `*filter_info_server*`)
  publish `type`, `mask_topic`, `base`, `multiplier` on `filter_info_topic`
  (Nav2's defaults when absent: "costmap_filter_info", 0, "filter_mask", 0.0, 1.0);
* filter mask servers (map_server nodes with `topic_name` / `yaml_filename`,
  or named `*mask_server*`) serve `yaml_filename` (relative to the params
  file) on `topic_name` in frame `frame_id`; Nav2's bringup leaves
  `yaml_filename` to the launch file, so `masks={node: path}` supplies it.

A filter is matched to its mask by topics: filter -> filter_info_topic -> info
server -> mask_topic -> mask server -> yaml_filename. Topic names are resolved
as ROS does: keepout, speed and zone filters join relative names with the
costmap's parent namespace (`joinWithParentNamespace`, spec §8.3); the binary
filter does not, so its relative names resolve in the costmap node's own
namespace (`/global_costmap/...`) and usually need a leading '/'.

Parameters may be nested (`keepout_filter: {plugin: ...}`) or dotted
(`keepout_filter.plugin: ...`); ROS wildcard nodes (`/**:`) apply to every
node they match. `substitutions` play the role of the launch file's
RewrittenYaml value rewrites: a parameter whose string value equals a given name
is replaced by its value (a string is parsed as a YAML literal for non-string
parameters, so "True" is a bool). A string left in a bool or number parameter is
an error naming the placeholder and the parameter. Only the parameters the
filters use are read, so placeholders elsewhere in the file do not matter.

Where Nav2 logs and carries on (an info type a filter cannot use, a zone id it
skips, a clamped parameter), this warns with `Nav2ParamsWarning` and does the
same. Unknown plugins, missing required keys and wrongly typed values raise
`ValueError`; missing files raise `FileNotFoundError`; both name the file, the
node and the key.
"""

from __future__ import annotations

import dataclasses
import fnmatch
import math
import os
import warnings
from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import yaml

from jaxfilters import constants
from jaxfilters import geometry
from jaxfilters import validate
from jaxfilters.binary import BinaryResult, BinaryState, binary_filter
from jaxfilters.keepout import KeepoutConfig, occ_to_cost
from jaxfilters.map_io import load_map
from jaxfilters.speed import LookaheadConfig, SpeedResult, SpeedState, speed_filter
from jaxfilters.types import FilterInfo, FilterMask, pytree_dataclass, check_poses
from jaxfilters.zone import NUM_ZONES, ZoneResult, ZoneState, ZoneTable, zone_filter

KEEPOUT_PLUGIN = "nav2_costmap_2d::KeepoutFilter"
SPEED_PLUGIN = "nav2_costmap_2d::SpeedFilter"
BINARY_PLUGIN = "nav2_costmap_2d::BinaryFilter"
ZONE_PLUGIN = "nav2_costmap_2d::ZoneParameterFilter"
COSTMAPS = ("global_costmap", "local_costmap")

# CostmapFilterInfo server and map_server defaults (spec §8.4).
_INFO_DEFAULTS = {"filter_info_topic": "costmap_filter_info", "type": 0, "mask_topic": "filter_mask",
                  "base": constants.BASE_DEFAULT, "multiplier": constants.MULTIPLIER_DEFAULT}
_MASK_TOPIC_DEFAULT = "map"
_FRAME_DEFAULT = "map"
_REQUIRED = object()
_KINDS = {"bool": "a bool (true/false)", "int": "an integer", "float": "a number",
          "str": "a string", "str_list": "a list of strings", "value": "a value"}


class Nav2ParamsWarning(UserWarning):
  """Something Nav2 would log and carry on with (a skipped zone, a clamped value, ...)."""


def _warn(message: str) -> None:
  warnings.warn(message, Nav2ParamsWarning, stacklevel=3)


# --------------------------------------------------------------------------- results


@dataclasses.dataclass(frozen=True, eq=False)
class Nav2Filter:
  """What one costmap filter of a params file resolves to (the fields every filter has).

  Attributes:
    name: the filter's name in the costmap's list ("keepout_filter").
    plugin: the pluginlib class, e.g. "nav2_costmap_2d::KeepoutFilter".
    enabled: Nav2 `enabled`; pass it as `enabled=` to the filter function.
    as_layer: listed under `plugins:` instead of `filters:`: Nav2 then runs it
      on the primary map before later layers such as inflation (spec §2.5).
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
  """A KeepoutFilter (spec §4); see Nav2Filter for the common fields.

  Attributes:
    config: KeepoutConfig from `override_lethal_cost` (default false) and
      `lethal_override_cost` (default 252, clamped to [0, 252] like Nav2).
  """
  config: KeepoutConfig


@dataclasses.dataclass(frozen=True, eq=False)
class Nav2SpeedFilter(Nav2Filter):
  """A SpeedFilter (spec §5); see Nav2Filter for the common fields.

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
  """A BinaryFilter (spec §6); see Nav2Filter for the common fields.

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
  """A ZoneParameterFilter (spec §7); see Nav2Filter for the common fields.

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
      (round(2.54 d), spec §1.4; 255 off the mask or on an unknown cell), or None.
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
  """
  name: str
  node: str
  global_frame: str
  resolution: float | None
  filters: tuple[Nav2Filter, ...]

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
                 name: str = "masks", frame: str = _FRAME_DEFAULT) -> "Nav2Costmap":
    """A costmap whose filters use these masks with Nav2's default parameters.

    Keepout: KeepoutConfig(); speed: percentage from the mask's info type;
    binary: default_state false, flip_threshold 50.0; zone: every id 1..127 is
    a configured state that sets no parameter. All masks and poses are in
    `frame`; topics and servers are None.

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
      if kind == "keepout":
        made.append(Nav2KeepoutFilter(plugin=KEEPOUT_PLUGIN, config=KeepoutConfig(), **common))
      elif kind == "speed":
        pct = {constants.SPEED_FILTER_PERCENT: True, constants.SPEED_FILTER_ABSOLUTE: False}.get(ftype)
        made.append(Nav2SpeedFilter(plugin=SPEED_PLUGIN, percentage=pct, speed_limit_topic=None,
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


@dataclasses.dataclass(frozen=True, eq=False)
class Nav2Params:
  """The costmap filters a Nav2 params file configures.

  Attributes:
    path: the params file.
    global_costmap: Nav2Costmap of the `global_costmap` node, or None when the
      file has none (or it was not asked for).
    local_costmap: likewise for `local_costmap`.
    unused_substitutions: substitution names that replaced no parameter read.
  """
  path: str
  global_costmap: Nav2Costmap | None
  local_costmap: Nav2Costmap | None
  unused_substitutions: tuple[str, ...] = ()

  def costmap(self, name: str) -> Nav2Costmap:
    """The costmap called `name` ("global_costmap" / "local_costmap").

    Raises:
      ValueError: an unknown name or a costmap the file does not configure.
    """
    if name not in COSTMAPS:
      raise ValueError(f"costmap must be one of {COSTMAPS}; got {name!r}")
    found = getattr(self, name)
    if found is None:
      raise ValueError(f"{self.path}: has no {name} node (a '{name}: {name}: ros__parameters:' entry)")
    return found


def _keepout_cost_one(data, origin, res, xy):
  h, w = data.shape
  mx, my, inside = geometry.world_to_cell(xy[0], xy[1], origin, res, w, h)
  return jnp.where(inside, occ_to_cost(data[my, mx]), jnp.uint8(constants.NO_INFORMATION))


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
    keepout = jax.vmap(lambda p: _keepout_cost_one(mask.data[0], mask.origin[0], mask.resolution[0], p))(
        jnp.stack([x, y], axis=1))
  if "binary" in parts:
    mask, tf, (default_state, threshold) = parts["binary"]
    _, binary = binary_filter(mask, poses, BinaryState.create(b), default_state=default_state,
                              flip_threshold=threshold, transform=tf)
  if "zone" in parts:
    mask, tf, (table,) = parts["zone"]
    _, zone = zone_filter(mask, poses, ZoneState.create(table, b), table, transform=tf)
  return Nav2Readout(speed, keepout, binary, zone)


# --------------------------------------------------------------------------- reading the file


@dataclasses.dataclass
class _Node:
  segments: tuple[str, ...]          # namespace segments + node name
  params: dict[str, Any]             # dotted parameter name -> YAML value

  @property
  def name(self) -> str:
    return self.segments[-1]

  @property
  def namespace(self) -> str:
    return "".join("/" + s for s in self.segments[:-1])

  @property
  def full_name(self) -> str:
    return self.namespace + "/" + self.name


def _flatten(tree: dict, prefix: str, out: dict, where: str) -> dict:
  for key, value in tree.items():
    name = prefix + str(key)
    if isinstance(value, dict):
      _flatten(value, name + ".", out, where)
    elif name in out:
      raise ValueError(f"{where}: parameter '{name}' is given twice")
    else:
      out[name] = value
  return out


def _segments(key) -> list[str]:
  return [s for s in str(key).split("/") if s]


def _wildcard_match(pattern: tuple[str, ...], segs: tuple[str, ...]) -> bool:
  if not pattern:
    return not segs
  if pattern[0] == "**":
    return any(_wildcard_match(pattern[1:], segs[i:]) for i in range(len(segs) + 1))
  return bool(segs) and fnmatch.fnmatchcase(segs[0], pattern[0]) and _wildcard_match(pattern[1:], segs[1:])


def _nodes(doc: dict, path: str) -> list[_Node]:
  """Every node of a ROS 2 params document, wildcard parameters merged in (node's own win)."""
  concrete: dict[tuple[str, ...], dict] = {}
  wild: list[tuple[tuple[str, ...], dict]] = []

  def walk(tree: dict, segs: tuple[str, ...]):
    for key, value in tree.items():
      if key == "ros__parameters":
        where = f"{path}: node '/{'/'.join(segs)}'"
        if not segs:
          raise ValueError(f"{path}: 'ros__parameters' at the top level belongs to no node")
        if value is None:
          value = {}
        if not isinstance(value, dict):
          raise ValueError(f"{where}: ros__parameters must be a mapping; got {validate.short_repr(value)}")
        flat = _flatten(value, "", {}, where)
        if any("*" in s for s in segs):
          wild.append((segs, flat))
        else:
          concrete.setdefault(segs, {}).update(flat)
      elif isinstance(value, dict):
        walk(value, segs + tuple(_segments(key)))

  walk(doc, ())
  nodes = []
  for segs, params in concrete.items():
    merged = {}
    for pattern, flat in wild:
      if _wildcard_match(pattern, segs):
        merged.update(flat)
    merged.update(params)
    nodes.append(_Node(segs, merged))
  return nodes


def _resolve(topic: str, namespace: str, where: str, key: str) -> str:
  """An absolute topic name: '/x' as is, 'x' inside `namespace`."""
  if not topic:
    raise ValueError(f"{where}: parameter '{key}' must name a topic; got an empty string")
  if topic.startswith("~"):
    raise ValueError(f"{where}: parameter '{key}': private topic names ('~/...') are not supported; "
                     f"got {topic!r}")
  full = topic if topic.startswith("/") else f"{namespace}/{topic}"
  return "".join("/" + s for s in full.split("/") if s)


def _parent(namespace: str) -> str:
  return namespace.rsplit("/", 1)[0] if namespace else ""


class _Reader:
  """Typed access to one node's parameters with placeholder substitution."""

  def __init__(self, node: _Node, path: str, substitutions: Mapping[str, Any], used: set[str]):
    self.node = node
    self.where = f"{path}: node '{node.full_name}'"
    self._subs = substitutions
    self._used = used

  def has(self, key: str) -> bool:
    return key in self.node.params

  def get(self, key: str, kind: str, default: Any = _REQUIRED) -> Any:
    if key not in self.node.params:
      if default is _REQUIRED:
        raise ValueError(f"{self.where}: missing required parameter '{key}'")
      return default
    value = self.node.params[key]
    placeholder = None
    if isinstance(value, str) and value in self._subs:
      self._used.add(value)
      placeholder, value = value, self._subs[value]
      if isinstance(value, str) and kind != "str":
        try:
          value = yaml.safe_load(value)
        except yaml.YAMLError:
          pass  # stays a string: reported below as not a literal of this kind
    return self._check(key, value, kind, placeholder)

  def _check(self, key: str, v: Any, kind: str, placeholder: str | None) -> Any:
    ok = {"bool": isinstance(v, bool),
          "int": isinstance(v, int) and not isinstance(v, bool),
          "float": isinstance(v, (int, float)) and not isinstance(v, bool),
          "str": isinstance(v, str),
          "str_list": isinstance(v, list) and all(isinstance(s, str) for s in v),
          "value": v is not None and not isinstance(v, dict)}[kind]
    if ok:
      return float(v) if kind == "float" else v
    msg = f"{self.where}: parameter '{key}' must be {_KINDS[kind]}; got {validate.short_repr(v)}"
    if placeholder is not None:
      msg += f" from substitution {placeholder!r}"
    elif isinstance(v, str) and kind != "str":
      msg += (f", an unresolved launch placeholder? pass substitutions={{{v!r}: ...}} "
              f"(CLI: --set {v}=VALUE)")
    raise ValueError(msg)


def _read_yaml(path: str) -> dict:
  if not os.path.exists(path):
    raise FileNotFoundError(f"params file {path} does not exist")
  if os.path.isdir(path):
    raise ValueError(f"params file {path} is a directory, not a file")
  try:
    with open(path, encoding="utf-8") as f:
      doc = yaml.safe_load(f)
  except (yaml.YAMLError, UnicodeDecodeError) as e:
    first = str(e).splitlines()[0] if str(e) else type(e).__name__
    raise ValueError(f"{path}: invalid params YAML: {first}") from e
  if not isinstance(doc, dict):
    raise ValueError(f"{path}: a params file must be a mapping of node names to "
                     f"'ros__parameters:'; got {type(doc).__name__}")
  return doc


class _Loader:
  """State of one load_params call: nodes, servers, substitutions and a mask cache."""

  def __init__(self, path: str, masks: Mapping[str, Any], substitutions: Mapping[str, Any]):
    self.path = path
    self.nodes = _nodes(_read_yaml(path), path)
    self.subs = substitutions
    self.used: set[str] = set()
    self.masks = dict(masks)
    self.masks_used: set[str] = set()
    self._grids: dict[str, Any] = {}
    self.info_servers = [n for n in self.nodes if "filter_info_topic" in n.params or "mask_topic" in n.params
                         or "filter_info_server" in n.name]
    self.mask_servers = [n for n in self.nodes if "topic_name" in n.params or "yaml_filename" in n.params
                         or "mask_server" in n.name]
    for node_name in self.masks:
      if not any(node_name in (n.name, n.full_name) for n in self.mask_servers):
        names = sorted(n.name for n in self.mask_servers)
        raise ValueError(f"masks names {node_name!r}, which is not a filter mask server in {path} "
                         f"(mask servers: {names or 'none'})")

  def reader(self, node: _Node) -> _Reader:
    return _Reader(node, self.path, self.subs, self.used)

  def _unique(self, servers, topic, key, default, what, filt_where, hint):
    found = [n for n in servers
             if _resolve(self.reader(n).get(key, "str", default), n.namespace, self.reader(n).where, key) == topic]
    if not found:
      have = sorted({_resolve(self.reader(n).get(key, "str", default), n.namespace, "", key) for n in servers})
      raise ValueError(f"{filt_where}: no {what} in {self.path} publishes {topic!r} (found: "
                       f"{have or 'none'}){hint}")
    if len(found) > 1:
      raise ValueError(f"{filt_where}: several {what}s publish {topic!r}: "
                       f"{', '.join(n.full_name for n in found)}")
    return found[0]

  def info_server(self, topic: str, filt_where: str, hint: str) -> _Node:
    return self._unique(self.info_servers, topic, "filter_info_topic", _INFO_DEFAULTS["filter_info_topic"],
                        "costmap_filter_info_server", filt_where, hint)

  def mask_server(self, topic: str, filt_where: str, hint: str) -> _Node:
    return self._unique(self.mask_servers, topic, "topic_name", _MASK_TOPIC_DEFAULT, "filter mask server",
                        filt_where, hint)

  def mask_grid(self, server: _Node):
    """(OccupancyGrid, yaml path) that `server` serves, loaded once per file."""
    r = self.reader(server)
    given = [k for k in (server.name, server.full_name) if k in self.masks]
    if given:
      self.masks_used.add(given[0])
      yaml_path, key = os.fspath(self.masks[given[0]]), f"masks[{given[0]!r}]"
    else:
      if not r.has("yaml_filename"):
        raise ValueError(f"{r.where}: missing parameter 'yaml_filename' (Nav2's bringup sets it from the "
                         f"launch file): pass masks={{{server.name!r}: 'mask.yaml'}} "
                         f"(CLI: --mask {server.name}=MASK.yaml)")
      yaml_path, key = r.get("yaml_filename", "str"), "parameter 'yaml_filename'"
      if not os.path.isabs(yaml_path) and not yaml_path.startswith("~"):
        yaml_path = os.path.join(os.path.dirname(self.path), yaml_path)
    if yaml_path not in self._grids:
      if not os.path.exists(os.path.expanduser(yaml_path)):
        raise FileNotFoundError(f"{r.where}: mask file {yaml_path} ({key}) does not exist")
      try:
        grid = load_map(yaml_path)
      except FileNotFoundError as e:
        raise FileNotFoundError(f"{r.where} ({key}): {e}") from e
      except ValueError as e:
        raise ValueError(f"{r.where} ({key}): {e}") from e
      validate.resolution_value(grid.resolution, owner=f"{r.where}: mask {yaml_path}")
      validate.float32_values(grid.origin[:2], "origin", owner=f"{r.where}: mask {yaml_path}")
      self._grids[yaml_path] = grid
    return self._grids[yaml_path], yaml_path


def _float32(r: _Reader, key: str, default: float) -> float:
  """A number parameter, checked in float32 terms (finite, not flushed to 0), returned as written."""
  value = r.get(key, "float", default)
  validate.float32_values(value, f"parameter '{key}'", owner=r.where)
  return value


def _filter(ld: _Loader, costmap: _Node, name: str, as_layer: bool):
  r = ld.reader(costmap)
  fw = f"{r.where}: filter '{name}'"
  plugin = r.get(f"{name}.plugin", "str")
  cls = {KEEPOUT_PLUGIN: Nav2KeepoutFilter, SPEED_PLUGIN: Nav2SpeedFilter, BINARY_PLUGIN: Nav2BinaryFilter,
         ZONE_PLUGIN: Nav2ZoneFilter}.get(plugin)
  if cls is None:
    raise ValueError(f"{fw}: unknown plugin {plugin!r} (parameter '{name}.plugin'); expected one of "
                     f"{KEEPOUT_PLUGIN}, {SPEED_PLUGIN}, {BINARY_PLUGIN}, {ZONE_PLUGIN}")
  binary = cls is Nav2BinaryFilter
  # BinaryFilter does not join its topics with the parent namespace (spec §8.3).
  topic_ns = costmap.namespace if binary else _parent(costmap.namespace)
  hint = (" (BinaryFilter does not join relative topics with the parent namespace, spec §8.3, so they "
          "resolve in the costmap's namespace: use an absolute '/topic')") if binary else ""
  enabled = r.get(f"{name}.enabled", "bool", True)
  info_topic = _resolve(r.get(f"{name}.filter_info_topic", "str"), topic_ns, r.where, f"{name}.filter_info_topic")
  tolerance = _float32(r, f"{name}.transform_tolerance", 0.1)

  info_node = ld.info_server(info_topic, fw, hint)
  ir = ld.reader(info_node)
  ftype = ir.get("type", "int", _INFO_DEFAULTS["type"])
  base = _float32(ir, "base", _INFO_DEFAULTS["base"])
  mult = _float32(ir, "multiplier", _INFO_DEFAULTS["multiplier"])
  try:
    info = FilterInfo.create(ftype, base, mult)
  except ValueError as e:
    raise ValueError(f"{ir.where}: parameter 'type': {e}") from None
  mask_topic = _resolve(ir.get("mask_topic", "str", _INFO_DEFAULTS["mask_topic"]), topic_ns, ir.where,
                        "mask_topic")
  mask_node = ld.mask_server(mask_topic, fw, hint)
  grid, yaml_path = ld.mask_grid(mask_node)
  frame = ld.reader(mask_node).get("frame_id", "str", _FRAME_DEFAULT)
  common = dict(name=name, plugin=plugin, enabled=enabled, as_layer=as_layer, filter_info_topic=info_topic,
                info_server=info_node.full_name, mask_topic=mask_topic, mask_server=mask_node.full_name,
                mask_yaml=yaml_path, mask_frame=frame, mask=FilterMask.create(grid, info),
                transform_tolerance=tolerance)
  nondefault = (base, mult) != (constants.BASE_DEFAULT, constants.MULTIPLIER_DEFAULT)
  join = lambda key, default: _resolve(r.get(f"{name}.{key}", "str", default), topic_ns, r.where, f"{name}.{key}")

  if cls is Nav2KeepoutFilter:
    if nondefault:
      _warn(f"{fw}: its info server {info_node.full_name} sets base {base} / multiplier {mult}; "
            "KeepoutFilter ignores them (Nav2 logs an error and carries on)")
    override = r.get(f"{name}.override_lethal_cost", "bool", False)
    cost = r.get(f"{name}.lethal_override_cost", "int", constants.MAX_NON_OBSTACLE)
    if not 0 <= cost <= constants.MAX_NON_OBSTACLE:
      _warn(f"{fw}: lethal_override_cost {cost} is clamped to [0, {constants.MAX_NON_OBSTACLE}] as Nav2 does")
    return cls(config=KeepoutConfig(override_lethal_cost=override, lethal_override_cost=cost), **common)

  if cls is Nav2SpeedFilter:
    percentage = {constants.SPEED_FILTER_PERCENT: True, constants.SPEED_FILTER_ABSOLUTE: False}.get(ftype)
    if percentage is None:
      _warn(f"{fw}: info server {info_node.full_name} has type {ftype}, not 1 (percent) or 2 (m/s); "
            "SpeedFilter logs an error and never subscribes to the mask, so it limits nothing")
    lookahead = None
    if r.get(f"{name}.enable_path_lookahead", "bool", False):
      decel = _float32(r, f"{name}.max_decel", -0.5)
      lo = _float32(r, f"{name}.min_lookahead", 0.3)
      hi = _float32(r, f"{name}.max_lookahead", 5.0)
      if decel >= 0:
        _warn(f"{fw}: max_decel {decel} is not negative; Nav2 warns and looks ahead max_lookahead")
      if lo < 0:
        _warn(f"{fw}: min_lookahead {lo} < 0 is clamped to 0 as Nav2 does")
      if hi < max(lo, 0.0):
        _warn(f"{fw}: max_lookahead {hi} < min_lookahead is raised to it as Nav2 does")
      lookahead = LookaheadConfig(max_decel=decel, min_lookahead=lo, max_lookahead=hi)
    return cls(percentage=percentage, speed_limit_topic=join("speed_limit_topic", "speed_limit"),
               lookahead=lookahead, path_topic=join("path_topic", "plan"),
               odom_topic=r.get(f"{name}.odom_topic", "str", "odom"), **common)

  if cls is Nav2BinaryFilter:
    if ftype != constants.BINARY_FILTER:
      _warn(f"{fw}: info server {info_node.full_name} has type {ftype}, not 3; BinaryFilter logs an "
            "error and never subscribes to the mask, so its state never follows the mask")
    return cls(default_state=r.get(f"{name}.default_state", "bool", False),
               flip_threshold=_float32(r, f"{name}.flip_threshold", 50.0),
               binary_state_topic=join("binary_state_topic", "binary_state"), **common)

  if nondefault:
    _warn(f"{fw}: its info server {info_node.full_name} sets base {base} / multiplier {mult}; "
          "ZoneParameterFilter warns and ignores them")
  return _zone_filter(r, name, fw, common, join("state_event_topic", "zone_filter_state"))


def _setpoint(r: _Reader, prefix: str, name: str, fw: str, what: str) -> ZoneSetpoint | None:
  node = r.get(f"{prefix}.{name}.node", "str", "")
  param = r.get(f"{prefix}.{name}.parameter", "str", "")
  value = r.get(f"{prefix}.{name}.value", "value", None) if r.has(f"{prefix}.{name}.value") else None
  if not node or not param or value is None:
    missing = [k for k, v in (("node", node), ("parameter", param), ("value", value)) if v in ("", None)]
    _warn(f"{fw}: {what} '{name}' has no {'/'.join(missing)} ('{prefix}.{name}.{missing[0]}'); "
          "Nav2 logs an error and skips it")
    return None
  return ZoneSetpoint(name, node, param, value)


def _table_value(v: Any) -> float | None:
  """v as a float32 table entry, or None if float32 cannot hold it."""
  if isinstance(v, bool):
    return 1.0 if v else 0.0
  if isinstance(v, int):
    return float(v) if abs(v) <= 2 ** 24 else None
  if isinstance(v, float):
    with np.errstate(over="ignore", under="ignore"):
      v32 = np.float32(v)
    if (math.isfinite(v) and not np.isfinite(v32)) or (v != 0 and abs(v) < validate.F32_TINY):
      return None
    return float(v32)
  return None


def _zone_filter(r: _Reader, name: str, fw: str, common: dict, event_topic: str) -> Nav2ZoneFilter:
  states, ids = [], {}
  for sname in r.get(f"{name}.states", "str_list", []):
    sid = r.get(f"{name}.{sname}.id", "int")
    if not 1 <= sid <= 255:
      _warn(f"{fw}: state '{sname}' has id {sid} ('{name}.{sname}.id'), outside [1, 255]; Nav2 logs an "
            "error and skips the state")
      continue
    if sid >= NUM_ZONES:
      _warn(f"{fw}: state '{sname}' has id {sid}; int8 masks only reach 1..{NUM_ZONES - 1}, so the state "
            "can never apply (it is in .states but not in the table)")
    if sid in ids:
      raise ValueError(f"{fw}: states '{ids[sid]}' and '{sname}' both have id {sid} ('{name}.{sname}.id')")
    ids[sid] = sname
    points = [_setpoint(r, f"{name}.{sname}", p, fw, f"setpoint of state '{sname}'")
              for p in r.get(f"{name}.{sname}.setpoints", "str_list", [])]
    states.append(ZoneStateConfig(sname, sid, tuple(p for p in points if p is not None)))
  nominal = [_setpoint(r, f"{name}.nominal_defaults", n, fw, "nominal default")
             for n in r.get(f"{name}.nominal_defaults", "str_list", [])]
  nominal = tuple(p for p in nominal if p is not None)

  nominal_keys = {(p.node, p.parameter) for p in nominal}
  for s in states:
    for p in s.setpoints:
      if (p.node, p.parameter) not in nominal_keys:
        _warn(f"{fw}: state '{s.name}' sets {p.node}:{p.parameter}, which has no nominal default; "
              "Nav2 warns that it will not be restored")
  # Columns: every (node, parameter) whose values all fit a float32 table.
  values: dict[tuple[str, str], list[Any]] = {}
  for p in (*nominal, *(p for s in states for p in s.setpoints)):
    values.setdefault((p.node, p.parameter), []).append(p.value)
  columns = [k for k, vs in values.items() if all(_table_value(v) is not None for v in vs)]
  left_out = [f"{n}:{p}" for (n, p) in values if (n, p) not in columns]
  if left_out:
    _warn(f"{fw}: parameters {left_out} have values a float32 ZoneTable cannot hold (strings, lists, "
          "integers beyond 2**24); they are kept in .states / .nominal_defaults only")
  col = lambda p: f"{p.node}:{p.parameter}"
  keep = {f"{n}:{p}" for n, p in columns}
  try:
    table = ZoneTable.create(
        [f"{n}:{p}" for n, p in columns],
        {col(p): _table_value(p.value) for p in nominal if col(p) in keep},
        {s.id: {col(p): _table_value(p.value) for p in s.setpoints if col(p) in keep}
         for s in states if s.id < NUM_ZONES})
  except ValueError as e:
    raise ValueError(f"{fw}: {e}") from None
  return Nav2ZoneFilter(table=table, parameters=tuple(columns), states=tuple(states), nominal_defaults=nominal,
                        state_event_topic=event_topic, **common)


def _costmap(ld: _Loader, node: _Node) -> Nav2Costmap:
  r = ld.reader(node)
  frame = r.get("global_frame", "str", _FRAME_DEFAULT)
  resolution = None
  if r.has("resolution"):
    resolution = r.get("resolution", "float")
    validate.resolution_value(resolution, owner=r.where, name="parameter 'resolution'")
  names = [(n, False) for n in r.get("filters", "str_list", [])]
  for n in r.get("plugins", "str_list", []):
    if r.has(f"{n}.plugin") and r.get(f"{n}.plugin", "str") in (KEEPOUT_PLUGIN, SPEED_PLUGIN, BINARY_PLUGIN,
                                                                ZONE_PLUGIN):
      names.append((n, True))
  seen = set()
  for n, _ in names:
    if n in seen:
      raise ValueError(f"{r.where}: filter '{n}' is listed twice in 'filters'/'plugins'")
    seen.add(n)
  filters = tuple(_filter(ld, node, n, as_layer) for n, as_layer in names)
  return Nav2Costmap(name=node.name, node=node.full_name, global_frame=frame, resolution=resolution,
                     filters=filters)


def load_params(path: str | os.PathLike, *, masks: Mapping[str, str | os.PathLike] | None = None,
                substitutions: Mapping[str, Any] | None = None,
                costmaps: tuple[str, ...] = COSTMAPS) -> Nav2Params:
  """Reads a Nav2 params file into ready filter objects for its costmaps.

  See the module docstring for how nodes, topics and placeholders are read.

  Args:
    path: the `nav2_params.yaml`.
    masks: mask server node name (or full name) -> map YAML path, for servers
      whose `yaml_filename` the launch file sets; it wins over `yaml_filename`.
      Relative paths are taken from the current directory; a relative
      `yaml_filename` from the params file's directory.
    substitutions: placeholder -> value (e.g. {"KEEPOUT_ZONE_ENABLED": "True"}).
    costmaps: which costmaps to load (default both); loading one skips the
      other's masks and placeholders.

  Returns:
    Nav2Params with a Nav2Costmap per costmap node found (None where absent).

  Raises:
    FileNotFoundError: the params file or a mask file does not exist.
    ValueError: invalid YAML; no costmap node, or several with one name; an
      unknown plugin; a missing required key (`plugin`, `filter_info_topic`,
      a zone state's `id`, a matched mask server's `yaml_filename`); a value of
      the wrong type or an unresolved placeholder; a filter whose topics match
      no (or several) info or mask servers; a bad mask file; a `masks` key that
      names no mask server. Messages name the file, the node and the key.
  """
  path = os.fspath(path)
  masks = {} if masks is None else masks
  substitutions = {} if substitutions is None else substitutions
  for what, mapping in (("masks", masks), ("substitutions", substitutions)):
    if not isinstance(mapping, Mapping) or not all(isinstance(k, str) and k for k in mapping):
      raise ValueError(f"{what} must be a mapping with non-empty string keys; got {validate.short_repr(mapping)}")
  costmaps = tuple(costmaps)
  if not costmaps or any(c not in COSTMAPS for c in costmaps):
    raise ValueError(f"costmaps must name some of {COSTMAPS}; got {costmaps!r}")
  ld = _Loader(path, masks, substitutions)
  found = {}
  for cname in costmaps:
    nodes = [n for n in ld.nodes if n.name == cname]
    if len(nodes) > 1:
      raise ValueError(f"{path}: several {cname} nodes ({', '.join(n.full_name for n in nodes)}); "
                       "load a file with one robot's parameters")
    found[cname] = _costmap(ld, nodes[0]) if nodes else None
  if not any(found.values()):
    raise ValueError(f"{path}: no {' or '.join(costmaps)} node (expected e.g. "
                     f"'{costmaps[0]}: {costmaps[0]}: ros__parameters:')")
  unused = tuple(sorted(set(substitutions) - ld.used))
  for name in unused:
    _warn(f"{path}: substitution {name!r} replaced no parameter the costmap filters read")
  for name in sorted(set(masks) - ld.masks_used):
    _warn(f"{path}: masks[{name!r}] names a mask server no loaded filter uses")
  return Nav2Params(path=path, global_costmap=found.get("global_costmap"),
                    local_costmap=found.get("local_costmap"), unused_substitutions=unused)
