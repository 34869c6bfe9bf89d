"""Nav2 params import: a `nav2_params.yaml` -> ready filter objects per costmap.

    params = load_params("sims/assets/nav2_params.yaml",
                         masks={"keepout_filter_mask_server": "sims/assets/default_keepout.yaml"},
                         substitutions={"KEEPOUT_ZONE_ENABLED": "True"})
    g = params.global_costmap
    state, out = speed_filter(g.speed.mask, poses, SpeedState.create(B), enabled=g.speed.enabled)
    costmap, ks = keepout_filter(costmap, g.keepout.mask, poses, ks,
                                 enabled=g.keepout.enabled, config=g.keepout.config)
    # A costmap with a ZoneParameterFilter (g.zone is None without one):
    zs, zr = zone_filter(g.zone.mask, poses, ZoneState.create(g.zone.table, B), g.zone.table)
    # Every enabled filter's first cycle at B poses, one jitted call:
    out = g.readout(poses)

The file is read the way Nav2 wires its filters (docs/nav2_semantics.md §3,
§4-§8):

* costmap nodes `global_costmap` / `local_costmap` list filters under
  `filters:` (and, to run one as a layer before inflation, under `plugins:`);
  the InflationLayer and AsymmetricInflationLayer entries of `plugins:` become
  `Nav2Costmap.layers` (`jaxfilters.nav2.layers`); other layers are not read;
  each filter names a `plugin` class and a `filter_info_topic`;
* `costmap_filter_info_server` nodes (any node with a top-level
  `filter_info_topic` or `mask_topic`, or named `*filter_info_server*`)
  publish `type`, `mask_topic`, `base`, `multiplier` on `filter_info_topic`
  (Nav2's defaults when absent: "costmap_filter_info", 0, "filter_mask", 0.0, 1.0);
* filter mask servers (map_server nodes with `topic_name` / `yaml_filename`,
  or named `*mask_server*`) serve `yaml_filename` on `topic_name` in frame
  `frame_id`; Nav2's bringup leaves `yaml_filename` to the launch file, so
  `masks={node: path}` supplies it.

Mask paths: a path given in `masks` is used as given (a relative one from the
current directory, like any path a program is handed). A relative
`yaml_filename` in the file is taken from the params file's folder, so a
params file and its masks can move together and load from any directory;
Nav2's map_server opens it from its process's working directory, which a
launch file sets, so there a relative `yaml_filename` is rare.

A filter is matched to its mask by topics: filter -> filter_info_topic -> info
server -> mask_topic -> mask server -> yaml_filename. Topic names are resolved
as ROS does: keepout, speed and zone filters join relative names with the
costmap's parent namespace (`joinWithParentNamespace`, docs/nav2_semantics.md
§8.3); the binary filter does not, so its relative names resolve in the
costmap node's own namespace (`/global_costmap/...`) and usually need a
leading '/'.

Parameters may be nested (`keepout_filter: {plugin: ...}`) or dotted
(`keepout_filter.plugin: ...`); ROS wildcard nodes (`/**:`) apply to every
node they match. `substitutions` play the role of the launch file's
RewrittenYaml value rewrites: a parameter whose string value equals a given name
is replaced by its value (a string is parsed as a YAML literal for non-string
parameters, so "True" is a bool). A string left in a bool or number parameter is
an error naming the placeholder and the parameter. Only the parameters the
filters use are read, so placeholders elsewhere in the file do not matter.

The file is read as strictly as a map YAML (`map_decode.parse_yaml`): a
regular file only (a FIFO or device is refused at once), at most
`MAX_PARAMS_BYTES`, no YAML aliases or merge keys, no duplicate keys, nesting
at most `MAX_PARAMS_DEPTH` deep. Substitution values are parsed the same way.

Where Nav2 logs and carries on (an info type a filter cannot use, a keepout
info with base or multiplier set, a zone id it skips, a clamped parameter),
this warns with `Nav2ParamsWarning` and does the same. Every problem with the
file raises `Nav2ParamsError` (a ValueError) naming the file, the node and the
key, in a message of at most a few hundred characters; a missing params or
mask file raises `FileNotFoundError`.
"""

from __future__ import annotations

import dataclasses
import math
import os
import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np

from jaxfilters import constants
from jaxfilters import validate
from jaxfilters.keepout import KeepoutConfig
from jaxfilters.map_io import load_map
from jaxfilters.nav2.document import (MAX_MESSAGE, Nav2ParamsError, Node, Reader, cut, nodes_of,
                                      parent_namespace, read_document, resolve_topic, show)
from jaxfilters.nav2.layers import inflation_layers
from jaxfilters.nav2.runtime import (BINARY_PLUGIN, COSTMAPS, FRAME_DEFAULT, KEEPOUT_PLUGIN, SPEED_PLUGIN,
                                     ZONE_PLUGIN, Nav2BinaryFilter, Nav2Costmap, Nav2KeepoutFilter,
                                     Nav2ParamsWarning, Nav2SpeedFilter, Nav2ZoneFilter, ZoneSetpoint,
                                     ZoneStateConfig, info_warning, speed_percentage)
from jaxfilters.speed import LookaheadConfig
from jaxfilters.types import FilterInfo, FilterMask
from jaxfilters.zone import NUM_ZONES, ZoneTable

__all__ = ["Nav2Params", "load_params"]


def _warn(message: str) -> None:
  warnings.warn(message, Nav2ParamsWarning, stacklevel=3)


# CostmapFilterInfo server and map_server defaults (docs/nav2_semantics.md §8.4).
_INFO_DEFAULTS = {"filter_info_topic": "costmap_filter_info", "type": 0, "mask_topic": "filter_mask",
                  "base": constants.BASE_DEFAULT, "multiplier": constants.MULTIPLIER_DEFAULT}
_MASK_TOPIC_DEFAULT = "map"


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
      raise Nav2ParamsError(f"costmap must be one of {COSTMAPS}; got {show(name)}")
    found = getattr(self, name)
    if found is None:
      raise Nav2ParamsError(f"{self.path}: has no {name} node (a '{name}: {name}: ros__parameters:' entry)")
    return found


class _Loader:
  """State of one load_params call: nodes, servers, substitutions and a mask cache."""

  def __init__(self, path: str, masks: Mapping[str, Any], substitutions: Mapping[str, Any]):
    self.path = path
    self.nodes = nodes_of(read_document(path), path)
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
        raise Nav2ParamsError(f"masks names {show(node_name)}, which is not a filter mask server in {path} "
                         f"(mask servers: {names or 'none'})")

  def reader(self, node: Node) -> Reader:
    return Reader(node, self.path, self.subs, self.used)

  def _unique(self, servers, topic, key, default, what, filt_where, hint):
    found = [n for n in servers
             if resolve_topic(self.reader(n).get(key, "str", default), n.namespace, self.reader(n).where, key) == topic]
    if not found:
      have = sorted({resolve_topic(self.reader(n).get(key, "str", default), n.namespace, "", key) for n in servers})
      raise Nav2ParamsError(f"{filt_where}: no {what} in {self.path} publishes {topic!r} (found: "
                       f"{have or 'none'}){hint}")
    if len(found) > 1:
      raise Nav2ParamsError(f"{filt_where}: several {what}s publish {topic!r}: "
                       f"{', '.join(n.full_name for n in found)}")
    return found[0]

  def info_server(self, topic: str, filt_where: str, hint: str) -> Node:
    return self._unique(self.info_servers, topic, "filter_info_topic", _INFO_DEFAULTS["filter_info_topic"],
                        "costmap_filter_info_server", filt_where, hint)

  def mask_server(self, topic: str, filt_where: str, hint: str) -> Node:
    return self._unique(self.mask_servers, topic, "topic_name", _MASK_TOPIC_DEFAULT, "filter mask server",
                        filt_where, hint)

  def mask_grid(self, server: Node):
    """(OccupancyGrid, yaml path) that `server` serves, loaded once per file."""
    r = self.reader(server)
    given = [k for k in (server.name, server.full_name) if k in self.masks]
    if given:
      self.masks_used.add(given[0])
      yaml_path, key = os.fspath(self.masks[given[0]]), f"masks[{given[0]!r}]"
    else:
      if not r.has("yaml_filename"):
        raise Nav2ParamsError(f"{r.where}: missing parameter 'yaml_filename' (Nav2's bringup sets it from the "
                         f"launch file): pass masks={{{server.name!r}: 'mask.yaml'}} "
                         f"(CLI: --mask {server.name}=MASK.yaml)")
      yaml_path, key = r.get("yaml_filename", "str"), "parameter 'yaml_filename'"
      if not os.path.isabs(yaml_path) and not yaml_path.startswith("~"):
        yaml_path = os.path.join(os.path.dirname(self.path), yaml_path)
    if yaml_path not in self._grids:
      if not os.path.exists(os.path.expanduser(yaml_path)):
        raise FileNotFoundError(cut(f"{r.where}: mask file {yaml_path} ({key}) does not exist", MAX_MESSAGE))
      try:
        grid = load_map(yaml_path)
      except FileNotFoundError as e:
        raise FileNotFoundError(cut(f"{r.where} ({key}): {e}", MAX_MESSAGE)) from e
      except ValueError as e:
        raise Nav2ParamsError(f"{r.where} ({key}): {e}") from e
      validate.resolution_value(grid.resolution, owner=f"{r.where}: mask {yaml_path}")
      validate.float32_values(grid.origin[:2], "origin", owner=f"{r.where}: mask {yaml_path}")
      self._grids[yaml_path] = grid
    return self._grids[yaml_path], yaml_path


def _float32(r: Reader, key: str, default: float) -> float:
  """A number parameter, checked in float32 terms (finite, not flushed to 0), returned as written."""
  value = r.get(key, "float", default)
  validate.float32_values(value, f"parameter '{key}'", owner=r.where)
  return value


def _filter(ld: _Loader, costmap: Node, name: str, as_layer: bool):
  r = ld.reader(costmap)
  fw = f"{r.where}: filter '{name}'"
  plugin = r.get(f"{name}.plugin", "str")
  cls = {KEEPOUT_PLUGIN: Nav2KeepoutFilter, SPEED_PLUGIN: Nav2SpeedFilter, BINARY_PLUGIN: Nav2BinaryFilter,
         ZONE_PLUGIN: Nav2ZoneFilter}.get(plugin)
  if cls is None:
    raise Nav2ParamsError(f"{fw}: unknown plugin {plugin!r} (parameter '{name}.plugin'); expected one of "
                     f"{KEEPOUT_PLUGIN}, {SPEED_PLUGIN}, {BINARY_PLUGIN}, {ZONE_PLUGIN}")
  binary = cls is Nav2BinaryFilter
  # BinaryFilter does not join its topics with the parent namespace (docs/nav2_semantics.md §8.3).
  topic_ns = costmap.namespace if binary else parent_namespace(costmap.namespace)
  hint = (" (BinaryFilter does not join relative topics with the parent namespace, docs/nav2_semantics.md "
          "§8.3, so they resolve in the costmap's namespace: use an absolute '/topic')") if binary else ""
  enabled = r.get(f"{name}.enabled", "bool", True)
  info_topic = resolve_topic(r.get(f"{name}.filter_info_topic", "str"), topic_ns, r.where, f"{name}.filter_info_topic")
  tolerance = _float32(r, f"{name}.transform_tolerance", 0.1)

  info_node = ld.info_server(info_topic, fw, hint)
  ir = ld.reader(info_node)
  ftype = ir.get("type", "int", _INFO_DEFAULTS["type"])
  base = _float32(ir, "base", _INFO_DEFAULTS["base"])
  mult = _float32(ir, "multiplier", _INFO_DEFAULTS["multiplier"])
  try:
    info = FilterInfo.create(ftype, base, mult)
  except ValueError as e:
    raise Nav2ParamsError(f"{ir.where}: parameter 'type': {e}") from None
  mask_topic = resolve_topic(ir.get("mask_topic", "str", _INFO_DEFAULTS["mask_topic"]), topic_ns, ir.where,
                        "mask_topic")
  mask_node = ld.mask_server(mask_topic, fw, hint)
  grid, yaml_path = ld.mask_grid(mask_node)
  frame = ld.reader(mask_node).get("frame_id", "str", FRAME_DEFAULT)
  common = dict(name=name, plugin=plugin, enabled=enabled, as_layer=as_layer, filter_info_topic=info_topic,
                info_server=info_node.full_name, mask_topic=mask_topic, mask_server=mask_node.full_name,
                mask_yaml=yaml_path, mask_frame=frame, mask=FilterMask.create(grid, info),
                transform_tolerance=tolerance)
  kind = {Nav2KeepoutFilter: "keepout", Nav2SpeedFilter: "speed", Nav2BinaryFilter: "binary",
          Nav2ZoneFilter: "zone"}[cls]
  said = info_warning(kind, ftype, base, mult)
  if said is not None:
    _warn(f"{fw}: its info server {info_node.full_name} {said}")
  join = lambda key, default: resolve_topic(r.get(f"{name}.{key}", "str", default), topic_ns, r.where, f"{name}.{key}")

  if cls is Nav2KeepoutFilter:
    override = r.get(f"{name}.override_lethal_cost", "bool", False)
    cost = r.get(f"{name}.lethal_override_cost", "int", constants.MAX_NON_OBSTACLE)
    if not 0 <= cost <= constants.MAX_NON_OBSTACLE:
      _warn(f"{fw}: lethal_override_cost {show(cost)} is clamped to [0, {constants.MAX_NON_OBSTACLE}] as Nav2 "
            "does")
      cost = min(max(cost, 0), constants.MAX_NON_OBSTACLE)
    return cls(config=KeepoutConfig(override_lethal_cost=override, lethal_override_cost=cost), **common)

  if cls is Nav2SpeedFilter:
    percentage = speed_percentage(ftype)
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
      # Nav2 PR #6522's parameters (docs/nav2_semantics.md §5.7); absent = Nav2 main's behaviour.
      rewind = _float32(r, f"{name}.max_path_rewind", 0.0)
      if rewind < 0:
        raise Nav2ParamsError(f"{fw}: max_path_rewind {show(rewind)} is negative; expected 0 (forward-only "
                              "start index, as Nav2 main) or the metres of path the index may move back")
      lookahead = LookaheadConfig(max_decel=decel, min_lookahead=lo, max_lookahead=hi, max_path_rewind=rewind,
                                  clear_path_on_reset=r.get(f"{name}.clear_path_on_reset", "bool", False))
    return cls(percentage=percentage, speed_limit_topic=join("speed_limit_topic", "speed_limit"),
               lookahead=lookahead, path_topic=join("path_topic", "plan"),
               odom_topic=r.get(f"{name}.odom_topic", "str", "odom"), **common)

  if cls is Nav2BinaryFilter:
    return cls(default_state=r.get(f"{name}.default_state", "bool", False),
               flip_threshold=_float32(r, f"{name}.flip_threshold", 50.0),
               binary_state_topic=join("binary_state_topic", "binary_state"), **common)

  return _zone_filter(r, name, fw, common, join("state_event_topic", "zone_filter_state"))


def _setpoint(r: Reader, prefix: str, name: str, fw: str, what: str) -> ZoneSetpoint | None:
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


def _zone_filter(r: Reader, name: str, fw: str, common: dict, event_topic: str) -> Nav2ZoneFilter:
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
      raise Nav2ParamsError(f"{fw}: states '{ids[sid]}' and '{sname}' both have id {sid} ('{name}.{sname}.id')")
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
    raise Nav2ParamsError(f"{fw}: {e}") from None
  return Nav2ZoneFilter(table=table, parameters=tuple(columns), states=tuple(states), nominal_defaults=nominal,
                        state_event_topic=event_topic, **common)


def _costmap(ld: _Loader, node: Node) -> Nav2Costmap:
  r = ld.reader(node)
  frame = r.get("global_frame", "str", FRAME_DEFAULT)
  resolution = None
  if r.has("resolution"):
    resolution = r.get("resolution", "float")
    try:
      validate.resolution_value(resolution, owner=r.where, name="parameter 'resolution'")
    except ValueError as e:   # a plain ValueError before: every problem with the file is a Nav2ParamsError
      raise Nav2ParamsError(str(e)) from None
  names = [(n, False) for n in r.get("filters", "str_list", [])]
  plugins = r.get("plugins", "str_list", [])
  for n in plugins:
    if r.has(f"{n}.plugin") and r.get(f"{n}.plugin", "str") in (KEEPOUT_PLUGIN, SPEED_PLUGIN, BINARY_PLUGIN,
                                                                ZONE_PLUGIN):
      names.append((n, True))
  seen = set()
  for n, _ in names:
    if n in seen:
      raise Nav2ParamsError(f"{r.where}: filter '{n}' is listed twice in 'filters'/'plugins'")
    seen.add(n)
  filters = tuple(_filter(ld, node, n, as_layer) for n, as_layer in names)
  return Nav2Costmap(name=node.name, node=node.full_name, global_frame=frame, resolution=resolution,
                     filters=filters, layers=inflation_layers(r, node, plugins))


def load_params(path: str | os.PathLike, *, masks: Mapping[str, str | os.PathLike] | None = None,
                substitutions: Mapping[str, Any] | None = None,
                costmaps: tuple[str, ...] = COSTMAPS) -> Nav2Params:
  """Reads a Nav2 params file into ready filter objects for its costmaps.

  See the module docstring for how nodes, topics and placeholders are read.

  Args:
    path: the `nav2_params.yaml`.
    masks: mask server node name (or full name) -> map YAML path, for servers
      whose `yaml_filename` the launch file sets; it wins over `yaml_filename`.
      These paths are used as given (relative ones from the current
      directory); a relative `yaml_filename` in the file is taken from the
      params file's folder.
    substitutions: placeholder -> value (e.g. {"KEEPOUT_ZONE_ENABLED": "True"});
      a string value is parsed as a YAML literal (strictly, as the file is)
      where the parameter is not a string.
    costmaps: which costmaps to load (default both); loading one skips the
      other's masks and placeholders.

  Returns:
    Nav2Params with a Nav2Costmap per costmap node found (None where absent).

  Warns:
    Nav2ParamsWarning: where Nav2 logs an error or a warning and carries on
      (an info whose base, multiplier or type the filter ignores or refuses, a
      skipped zone state or setpoint, a clamped parameter), and for a
      substitution or `masks` entry nothing used.

  Raises:
    FileNotFoundError: the params file or a mask file does not exist.
    Nav2ParamsError: (a ValueError) not a regular file (a FIFO, a device, a
      directory), over `MAX_PARAMS_BYTES`; invalid YAML, an alias, a merge or
      duplicate key, nesting deeper than `MAX_PARAMS_DEPTH`, a name over
      `MAX_NAME_CHARS`; no costmap node, or several with one name; an
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
      raise Nav2ParamsError(f"{what} must be a mapping with non-empty string keys; got {show(mapping)}")
  for name, mask in masks.items():
    if not isinstance(mask, (str, os.PathLike)):
      raise Nav2ParamsError(f"masks[{show(name)}] must be a path (str or os.PathLike); got {show(mask)}")
  costmaps = tuple(costmaps) if isinstance(costmaps, (tuple, list)) else (costmaps,)
  if not costmaps or any(not isinstance(c, str) or c not in COSTMAPS for c in costmaps):
    raise Nav2ParamsError(f"costmaps must name some of {COSTMAPS}; got {show(costmaps)}")
  ld = _Loader(path, masks, substitutions)
  found = {}
  for cname in costmaps:
    nodes = [n for n in ld.nodes if n.name == cname]
    if len(nodes) > 1:
      raise Nav2ParamsError(f"{path}: several {cname} nodes ({', '.join(n.full_name for n in nodes)}); "
                       "load a file with one robot's parameters")
    found[cname] = _costmap(ld, nodes[0]) if nodes else None
  if not any(found.values()):
    raise Nav2ParamsError(f"{path}: no {' or '.join(costmaps)} node (expected e.g. "
                     f"'{costmaps[0]}: {costmaps[0]}: ros__parameters:')")
  unused = tuple(sorted(set(substitutions) - ld.used))
  for name in unused:
    _warn(f"{path}: substitution {show(name)} replaced no parameter the costmap filters read")
  for name in sorted(set(masks) - ld.masks_used):
    _warn(f"{path}: masks[{show(name)}] names a mask server no loaded filter uses")
  return Nav2Params(path=path, global_costmap=found.get("global_costmap"),
                    local_costmap=found.get("local_costmap"), unused_substitutions=unused)
