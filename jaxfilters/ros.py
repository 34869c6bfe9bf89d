"""ROS message shapes as plain dicts with ROS 2 field names, both ways; rosbag2 files as an extra.

Messages (dicts nest as the .msg files do; a `header` is
{"stamp": {"sec", "nanosec"}, "frame_id"}):

  nav_msgs/msg/OccupancyGrid        <-> OccupancyGrid        occupancy_grid_to_msg / _from_msg
  nav2_msgs/msg/CostmapFilterInfo   <-> FilterInfo + topic   filter_info_to_msg / _from_msg
  nav2_msgs/msg/SpeedLimit          <-> (limit, percentage)  speed_limit_to_msg / _from_msg,
                                        SpeedResult [B]      speed_limit_msgs
  std_msgs/msg/Bool                 <-> bool, BinaryResult   bool_to_msg / _from_msg, binary_state_msgs

The older names of Nav2's costmap filters design document (docs/nav2_semantics.md §8)
are available with naming="design":
nav2_msgs/msg/MaxSpeed (`max_speed` instead of `speed_limit`) and
CostmapFilterInfo's `map_mask_topic` (instead of `filter_mask_topic`).

Dicts hold what the wire holds: float32 fields (resolution, base, multiplier)
carry the float32-rounded value, and OccupancyGrid `data` is a flat row-major
int8 array (row 0 = lowest y). Every `*_from_msg` validates and raises
ValueError naming the field (e.g. "OccupancyGrid.info.width").

rosbag2 (optional, `pip install 'jaxfilters[ros]'`): `write_bag` / `read_bag`
store these dicts with the `rosbags` library, imported only inside them;
`typestore()` is a ROS 2 type store with the nav2_msgs types above registered
from the .msg definitions embedded here.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from typing import Any, NamedTuple

import numpy as np

from jaxfilters import constants
from jaxfilters.grid import OccupancyGrid
from jaxfilters.types import FilterInfo
from jaxfilters.validate import float32_values, resolution_value, short_repr

__all__ = [
    "BOOL", "COSTMAP_FILTER_INFO", "MAX_SPEED", "MSG_DEFINITIONS", "OCCUPANCY_GRID", "SPEED_LIMIT",
    "STORAGES", "BagMessage", "binary_state_msgs", "bool_from_msg", "bool_to_msg",
    "filter_info_from_msg",
    "filter_info_to_msg", "header_msg", "occupancy_grid_from_msg", "occupancy_grid_to_msg",
    "read_bag", "speed_limit_from_msg", "speed_limit_msgs", "speed_limit_to_msg", "time_msg",
    "typestore", "write_bag",
]

OCCUPANCY_GRID = "nav_msgs/msg/OccupancyGrid"
COSTMAP_FILTER_INFO = "nav2_msgs/msg/CostmapFilterInfo"
SPEED_LIMIT = "nav2_msgs/msg/SpeedLimit"
MAX_SPEED = "nav2_msgs/msg/MaxSpeed"
BOOL = "std_msgs/msg/Bool"
NAMINGS = ("nav2", "design")

# nav2_msgs definitions (field lines as in Nav2; comments ours). MaxSpeed is the design
# document's name for SpeedLimit (docs/nav2_semantics.md §8), so bags of that naming can be written.
MSG_DEFINITIONS = {
    COSTMAP_FILTER_INFO: """std_msgs/Header header
# filter type: 0 keepout/lanes, 1 speed limit in percent, 2 speed limit in m/s,
# 3 binary, 4 zone parameter
uint8 type
# topic of the filter mask (a nav_msgs/OccupancyGrid)
string filter_mask_topic
# filter value = mask data * multiplier + base
float32 base
float32 multiplier
""",
    SPEED_LIMIT: """std_msgs/Header header
# true: speed_limit is a percent of the maximum speed; false: m/s
bool percentage
# the limit; 0.0 means no limit
float64 speed_limit
""",
    MAX_SPEED: """std_msgs/Header header
# true: max_speed is a percent of the maximum speed; false: m/s
bool percentage
# the limit; 0.0 means no limit
float64 max_speed
""",
}

_INT32 = (-(2**31), 2**31 - 1)
_UINT32_MAX = 2**32 - 1
_QUAT_TOL = 1e-6
_ROS_DTYPE = {"byte": "uint8", "char": "uint8", "octet": "uint8"}   # ROS 2 names NumPy reads otherwise


# --------------------------------------------------------------------------- field checks


def _field(msg: Any, name: str, where: str) -> Any:
  if not isinstance(msg, dict):
    raise ValueError(f"{where} must be a dict (a ROS message); got {short_repr(msg)}")
  if name not in msg:
    raise ValueError(f"{where}.{name} is missing")
  return msg[name]


def _int(value: Any, where: str, lo: int, hi: int) -> int:
  if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
    raise ValueError(f"{where} must be an integer in [{lo}, {hi}]; got {short_repr(value)}")
  if not lo <= int(value) <= hi:
    raise ValueError(f"{where} must lie in [{lo}, {hi}]; got {int(value)}")
  return int(value)


def _float(value: Any, where: str) -> float:
  if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer,
                                                                   np.floating)):
    raise ValueError(f"{where} must be a number; got {short_repr(value)}")
  v = float(value)
  if not math.isfinite(v):
    raise ValueError(f"{where} must be finite; got {v!r}")
  return v


def _bool(value: Any, where: str) -> bool:
  if not isinstance(value, (bool, np.bool_)):
    raise ValueError(f"{where} must be a bool; got {short_repr(value)}")
  return bool(value)


def _str(value: Any, where: str, *, nonempty: bool = False) -> str:
  if not isinstance(value, str):
    raise ValueError(f"{where} must be a string; got {short_repr(value)}")
  if nonempty and not value:
    raise ValueError(f"{where} must not be empty")
  return value


def _f32(value: Any, where: str, **kw) -> float:
  owner, _, name = where.rpartition(".")
  return float(float32_values(_float(value, where), name, owner=owner, **kw))


def _naming(naming: str) -> str:
  if naming not in NAMINGS:
    raise ValueError(f"naming must be one of {NAMINGS}; got {short_repr(naming)}")
  return naming


# --------------------------------------------------------------------------- std / builtin


def time_msg(sec: int = 0, nanosec: int = 0) -> dict:
  """builtin_interfaces/msg/Time {"sec": int32, "nanosec": uint32 in [0, 1e9)}.

  Raises:
    ValueError: values that are not integers or out of range.
  """
  return {"sec": _int(sec, "Time.sec", *_INT32),
          "nanosec": _int(nanosec, "Time.nanosec", 0, 999_999_999)}


def _time(value: Any, where: str) -> dict:
  if value is None:
    return time_msg()
  if not isinstance(value, dict):
    raise ValueError(f"{where} must be a builtin_interfaces/Time dict {{sec, nanosec}}; got "
                     f"{short_repr(value)}")
  return {"sec": _int(_field(value, "sec", where), f"{where}.sec", *_INT32),
          "nanosec": _int(_field(value, "nanosec", where), f"{where}.nanosec", 0, 999_999_999)}


def header_msg(frame_id: str = "", stamp: dict | None = None) -> dict:
  """std_msgs/msg/Header {"stamp": Time, "frame_id": str}; stamp None gives time 0.

  Raises:
    ValueError: a frame_id that is not a string or a bad stamp.
  """
  return {"stamp": _time(stamp, "Header.stamp"), "frame_id": _str(frame_id, "Header.frame_id")}


def _header(msg: Any, where: str) -> dict:
  h = _field(msg, "header", where)
  return {"stamp": _time(_field(h, "stamp", f"{where}.header"), f"{where}.header.stamp"),
          "frame_id": _str(_field(h, "frame_id", f"{where}.header"), f"{where}.header.frame_id")}


def bool_to_msg(value: bool) -> dict:
  """std_msgs/msg/Bool {"data": bool} (what Nav2's BinaryFilter publishes)."""
  return {"data": _bool(value, "Bool.data")}


def bool_from_msg(msg: dict) -> bool:
  """std_msgs/msg/Bool -> bool.

  Raises:
    ValueError: not a dict, or `data` missing or not a bool.
  """
  return _bool(_field(msg, "data", "Bool"), "Bool.data")


def binary_state_msgs(result) -> list[dict | None]:
  """BinaryFilter output [B] -> per robot the std_msgs/Bool Nav2 would publish, or None.

  Args:
    result: a BinaryResult (binary_state bool [B], published bool [B]).

  Returns:
    List of B entries: {"data": state} where `published`, else None.
  """
  state = np.asarray(result.binary_state)
  published = np.asarray(result.published)
  if state.ndim != 1 or published.shape != state.shape:
    raise ValueError(f"BinaryResult fields must be [B] arrays; got binary_state {state.shape}, "
                     f"published {published.shape}")
  return [bool_to_msg(bool(s)) if p else None for s, p in zip(state, published)]


# --------------------------------------------------------------------------- OccupancyGrid


def occupancy_grid_to_msg(grid: OccupancyGrid, *, stamp: dict | None = None,
                          map_load_time: dict | None = None) -> dict:
  """OccupancyGrid -> nav_msgs/msg/OccupancyGrid dict.

  Args:
    grid: the map; int8 [H, W], row 0 = lowest y.
    stamp: header stamp (Time dict), default time 0.
    map_load_time: info.map_load_time (Time dict), default time 0.

  Returns:
    {"header": {stamp, frame_id = grid.frame_id}, "info": {map_load_time,
    resolution (float32-rounded), width, height, origin: {position {x, y, z=0},
    orientation: quaternion of the yaw about z}}, "data": int8 [H * W]
    row-major}.

  Raises:
    TypeError: not an OccupancyGrid.
    ValueError: a resolution that is not a positive normal float32, a
      non-finite origin, data outside -1..100.
  """
  if not isinstance(grid, OccupancyGrid):
    raise TypeError(f"occupancy_grid_to_msg expects an OccupancyGrid; got {type(grid).__name__}")
  data = np.asarray(grid.data)
  if data.ndim != 2 or data.size == 0 or data.min() < -1 or data.max() > 100:
    raise ValueError("OccupancyGrid data must be a non-empty [H, W] array of values -1..100")
  res = float(resolution_value(grid.resolution, owner="OccupancyGrid"))
  x, y, yaw = (float(v) for v in grid.origin)
  for name, v in (("x", x), ("y", y), ("yaw", yaw)):
    _float(v, f"OccupancyGrid.origin.{name}")
  return {
      "header": header_msg(grid.frame_id, stamp),
      "info": {
          "map_load_time": _time(map_load_time, "map_load_time"),
          "resolution": res,
          "width": int(data.shape[1]),
          "height": int(data.shape[0]),
          "origin": {"position": {"x": x, "y": y, "z": 0.0},
                     "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2),
                                     "w": math.cos(yaw / 2)}},
      },
      "data": np.ascontiguousarray(data, np.int8).ravel(),
  }


def _yaw(q: dict, where: str) -> float:
  qx, qy, qz, qw = (_float(_field(q, k, where), f"{where}.{k}") for k in ("x", "y", "z", "w"))
  norm = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
  if abs(norm - 1.0) > 1e-3:
    raise ValueError(f"{where} must be a unit quaternion; got norm {norm:.6g}")
  if abs(qx) > _QUAT_TOL * norm or abs(qy) > _QUAT_TOL * norm:
    raise ValueError(f"{where} must be a rotation about z only (x = y = 0): a grid origin "
                     f"has no roll or pitch; got x={qx!r}, y={qy!r}")
  return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def occupancy_grid_from_msg(msg: dict) -> OccupancyGrid:
  """nav_msgs/msg/OccupancyGrid dict -> OccupancyGrid.

  The stamps (header.stamp, info.map_load_time) are checked but not kept: an
  OccupancyGrid holds no time.

  Returns:
    OccupancyGrid: data int8 [height, width] (row 0 = lowest y), resolution as
    the float32 field holds it, origin (x, y, yaw), frame_id from the header.

  Raises:
    ValueError: a missing or mistyped field; width or height not in
      1..2**32-1; len(data) != width * height; data values outside -1..100;
      a resolution that is not a positive normal float32; origin position z
      != 0; an orientation that is not a unit quaternion about z. The message
      names the field.
  """
  w = "OccupancyGrid"
  header = _header(msg, w)
  info = _field(msg, "info", w)
  _time(_field(info, "map_load_time", f"{w}.info"), f"{w}.info.map_load_time")
  res = _f32(_field(info, "resolution", f"{w}.info"), f"{w}.info.resolution", positive=True)
  width = _int(_field(info, "width", f"{w}.info"), f"{w}.info.width", 1, _UINT32_MAX)
  height = _int(_field(info, "height", f"{w}.info"), f"{w}.info.height", 1, _UINT32_MAX)
  origin = _field(info, "origin", f"{w}.info")
  pos = _field(origin, "position", f"{w}.info.origin")
  px, py, pz = (_float(_field(pos, k, f"{w}.info.origin.position"),
                       f"{w}.info.origin.position.{k}") for k in ("x", "y", "z"))
  if pz != 0.0:
    raise ValueError(f"{w}.info.origin.position.z must be 0 (grids here are planar); got {pz!r}")
  yaw = _yaw(_field(origin, "orientation", f"{w}.info.origin"), f"{w}.info.origin.orientation")
  raw = _field(msg, "data", w)
  data = np.asarray(raw) if not isinstance(raw, (str, bytes)) else np.asarray([raw])
  if data.ndim != 1:
    raise ValueError(f"{w}.data must be a flat sequence of int8 values; got shape {data.shape}")
  if data.size != width * height:
    raise ValueError(f"{w}.data has {data.size} values; info.width * info.height = {width} * "
                     f"{height} = {width * height}")
  if data.dtype == bool or not np.issubdtype(data.dtype, np.integer):
    raise ValueError(f"{w}.data must hold integers -1..100; got dtype {data.dtype}")
  if data.min() < -1 or data.max() > 100:
    raise ValueError(f"{w}.data values must lie in -1..100; got min {data.min()} max {data.max()}")
  return OccupancyGrid.create(data.reshape(height, width), res, (px, py, yaw), header["frame_id"])


# --------------------------------------------------------------------------- CostmapFilterInfo


def _scalar(leaf, name: str):
  arr = np.asarray(leaf)
  if arr.shape != ():
    raise ValueError(f"FilterInfo.{name} must be a scalar (one message per mask); got shape "
                     f"{arr.shape}")
  return arr.item()


def filter_info_to_msg(info: FilterInfo, filter_mask_topic: str, *, frame_id: str = "",
                       stamp: dict | None = None, naming: str = "nav2") -> dict:
  """FilterInfo + mask topic -> nav2_msgs/msg/CostmapFilterInfo dict.

  Args:
    info: FilterInfo with scalar leaves (type, base, multiplier).
    filter_mask_topic: the mask's topic, e.g. "/filter_mask".
    frame_id: header frame ("" as costmap_filter_info_server publishes it).
    stamp: header stamp, default time 0.
    naming: "nav2" (`filter_mask_topic`) or "design" (`map_mask_topic`).

  Returns:
    {"header", "type": int, "filter_mask_topic": str, "base": float32 value,
    "multiplier": float32 value}.

  Raises:
    ValueError: stacked (non-scalar) leaves, an unknown type, non-finite base
      or multiplier, an empty topic.
  """
  typ = int(_scalar(info.type, "type"))
  if typ not in constants.FILTER_TYPES:
    raise ValueError(f"FilterInfo.type must be one of {constants.FILTER_TYPES}; got {typ}")
  topic_key = "filter_mask_topic" if _naming(naming) == "nav2" else "map_mask_topic"
  return {
      "header": header_msg(frame_id, stamp),
      "type": typ,
      topic_key: _str(filter_mask_topic, f"CostmapFilterInfo.{topic_key}", nonempty=True),
      "base": _f32(_scalar(info.base, "base"), "CostmapFilterInfo.base"),
      "multiplier": _f32(_scalar(info.multiplier, "multiplier"), "CostmapFilterInfo.multiplier"),
  }


def filter_info_from_msg(msg: dict) -> tuple[FilterInfo, str]:
  """nav2_msgs/msg/CostmapFilterInfo dict -> (FilterInfo, mask topic).

  Accepts either `filter_mask_topic` (Nav2) or `map_mask_topic` (the design
  document's name, docs/nav2_semantics.md §8), not both.

  Raises:
    ValueError: a missing or mistyped field, a type outside 0..5, a base or
      multiplier that is not finite in float32, an empty topic.
  """
  w = "CostmapFilterInfo"
  _header(msg, w)
  keys = [k for k in ("filter_mask_topic", "map_mask_topic") if isinstance(msg, dict) and k in msg]
  if len(keys) != 1:
    raise ValueError(f"{w} must have exactly one of filter_mask_topic (Nav2) and map_mask_topic "
                     f"(Nav2's design document); got {keys or 'neither'}")
  topic = _str(msg[keys[0]], f"{w}.{keys[0]}", nonempty=True)
  typ = _int(_field(msg, "type", w), f"{w}.type", 0, 255)
  if typ not in constants.FILTER_TYPES:
    raise ValueError(f"{w}.type must be one of {constants.FILTER_TYPES} (0 keepout, 1 speed %, "
                     f"2 speed m/s, 3 binary, 4 zone, 5 direction); got {typ}")
  base = _f32(_field(msg, "base", w), f"{w}.base")
  multiplier = _f32(_field(msg, "multiplier", w), f"{w}.multiplier")
  return FilterInfo.create(typ, base, multiplier), topic


# --------------------------------------------------------------------------- SpeedLimit


def speed_limit_to_msg(speed_limit: float, percentage: bool, *, frame_id: str = "map",
                       stamp: dict | None = None, naming: str = "nav2") -> dict:
  """A speed limit -> nav2_msgs/msg/SpeedLimit (or the design document's MaxSpeed, docs/nav2_semantics.md §8) dict.

  Args:
    speed_limit: percent of the maximum speed (percentage True) or m/s; 0.0
      means no limit.
    percentage: the unit flag.
    frame_id: header frame (Nav2 uses the costmap's global frame).
    stamp: header stamp, default time 0.
    naming: "nav2" (`speed_limit`) or "design" (`max_speed`).

  Raises:
    ValueError: a limit that is not finite, negative, or above 100 percent.
  """
  key = "speed_limit" if _naming(naming) == "nav2" else "max_speed"
  return {"header": header_msg(frame_id, stamp), "percentage": _bool(percentage, "percentage"),
          key: _speed_value(speed_limit, bool(percentage), f"SpeedLimit.{key}")}


def _speed_value(value, percentage: bool, where: str) -> float:
  v = _float(value, where)
  if v < 0 or (percentage and v > 100):
    raise ValueError(f"{where} must be >= 0{' and <= 100 (percent)' if percentage else ' (m/s)'}; "
                     f"got {v!r}")
  return v


def speed_limit_from_msg(msg: dict) -> tuple[float, bool]:
  """SpeedLimit (or MaxSpeed) dict -> (speed_limit, percentage).

  Raises:
    ValueError: not exactly one of speed_limit / max_speed, a missing or
      mistyped field, a limit that is not finite, negative, or above 100 %.
  """
  w = "SpeedLimit"
  _header(msg, w)
  keys = [k for k in ("speed_limit", "max_speed") if isinstance(msg, dict) and k in msg]
  if len(keys) != 1:
    raise ValueError(f"{w} must have exactly one of speed_limit (Nav2) and max_speed (design "
                     f"document MaxSpeed); got {keys or 'neither'}")
  percentage = _bool(_field(msg, "percentage", w), f"{w}.percentage")
  return _speed_value(msg[keys[0]], percentage, f"{w}.{keys[0]}"), percentage


def speed_limit_msgs(result, *, frame_id: str = "map", stamp: dict | None = None,
                     naming: str = "nav2") -> list[dict | None]:
  """SpeedFilter output [B] -> per robot the SpeedLimit Nav2 would publish, or None.

  Args:
    result: a SpeedResult (speed_limit float32 [B], percentage bool [B],
      changed bool [B]).
    frame_id, stamp, naming: as `speed_limit_to_msg`.

  Returns:
    List of B entries: a message where `changed` (Nav2 publishes only on a
    change), else None. The float32 limit is carried exactly in the float64 field.
  """
  limit = np.asarray(result.speed_limit)
  percentage = np.asarray(result.percentage)
  changed = np.asarray(result.changed)
  if limit.ndim != 1 or percentage.shape != limit.shape or changed.shape != limit.shape:
    raise ValueError(f"SpeedResult fields must be [B] arrays; got speed_limit {limit.shape}, "
                     f"percentage {percentage.shape}, changed {changed.shape}")
  return [speed_limit_to_msg(float(v), bool(p), frame_id=frame_id, stamp=stamp, naming=naming)
          if c else None for v, p, c in zip(limit, percentage, changed)]


# --------------------------------------------------------------------------- rosbag2 (extra)


class BagMessage(NamedTuple):
  """One message of a rosbag2 file: topic, ROS type name, receive time (ns), the dict."""
  topic: str
  msgtype: str
  timestamp: int
  msg: dict


def _rosbags():
  try:
    import rosbags.rosbag2 as rosbag2
    import rosbags.typesys as typesys
  except ImportError as e:
    raise ImportError("reading and writing rosbag2 files needs the optional 'rosbags' package; "
                      "install it with: pip install 'jaxfilters[ros]'") from e
  return rosbag2, typesys


def typestore(store: str = "ros2_humble"):
  """A rosbags type store for `store` with nav2_msgs CostmapFilterInfo, SpeedLimit, MaxSpeed.

  Args:
    store: a rosbags.typesys.Stores value ("ros2_humble", "ros2_jazzy", ...).

  Raises:
    ImportError: rosbags is not installed (install jaxfilters[ros]).
    ValueError: an unknown store name.
  """
  _, typesys = _rosbags()
  try:
    ts = typesys.get_typestore(typesys.Stores(store))
  except ValueError:
    names = [s.value for s in typesys.Stores if s.value.startswith("ros2")]
    raise ValueError(f"store must be one of {names}; got {short_repr(store)}") from None
  types = {}
  for name, text in MSG_DEFINITIONS.items():
    if name not in ts.types:
      types.update(typesys.get_types_from_msg(text, name))
  ts.register(types)
  return ts


def _to_ros(ts, msgtype: str, value: Any, where: str):
  from rosbags.interfaces import Nodetype  # noqa: PLC0415 - optional dependency

  if not isinstance(value, dict):
    raise ValueError(f"{where} must be a dict for {msgtype}; got {short_repr(value)}")
  _, fields = ts.fielddefs[msgtype]
  names = [f for f, _ in fields]
  extra = sorted(set(value) - set(names))
  if extra:
    raise ValueError(f"{where} has fields {extra} that {msgtype} does not define ({names})")
  kwargs = {}
  for name, (node, desc) in fields:
    v = _field(value, name, where)
    at = f"{where}.{name}"
    if node == Nodetype.NAME:
      kwargs[name] = _to_ros(ts, desc, v, at)
    elif node == Nodetype.BASE:
      kwargs[name] = _base_value(desc[0], v, at)
    else:
      (enode, edesc), _ = desc
      if enode == Nodetype.NAME:
        kwargs[name] = [_to_ros(ts, edesc, e, f"{at}[{i}]") for i, e in enumerate(v)]
      elif edesc[0] in ("string", "bool"):
        kwargs[name] = [_base_value(edesc[0], e, f"{at}[{i}]") for i, e in enumerate(v)]
      else:
        arr = np.asarray(v)
        dtype = np.dtype(_ROS_DTYPE.get(edesc[0], edesc[0]))
        if arr.size and np.issubdtype(dtype, np.integer):
          info = np.iinfo(dtype)
          if (arr.dtype == bool or not np.issubdtype(arr.dtype, np.integer)
              or arr.min() < info.min or arr.max() > info.max):
            raise ValueError(f"{at} must hold {edesc[0]} integers; got dtype {arr.dtype}")
        kwargs[name] = np.ascontiguousarray(arr, dtype).ravel()
  return ts.types[msgtype](**kwargs)


def _base_value(typ: str, v: Any, where: str):
  if typ == "string":
    return _str(v, where)
  if typ == "bool":
    return _bool(v, where)
  if typ.startswith("float"):
    return _float(v, where) if typ == "float64" else _f32(v, where)
  info = np.iinfo(np.dtype(_ROS_DTYPE.get(typ, typ)))
  return _int(v, where, int(info.min), int(info.max))


def _from_ros(ts, msgtype: str, obj) -> dict:
  from rosbags.interfaces import Nodetype  # noqa: PLC0415

  out = {}
  for name, (node, desc) in ts.fielddefs[msgtype][1]:
    v = getattr(obj, name)
    if node == Nodetype.NAME:
      out[name] = _from_ros(ts, desc, v)
    elif node == Nodetype.BASE:
      out[name] = v
    elif desc[0][0] == Nodetype.NAME:
      out[name] = [_from_ros(ts, desc[0][1], e) for e in v]
    else:
      out[name] = v if isinstance(v, np.ndarray) else list(v)
  return out


STORAGES = ("sqlite3", "mcap")


def write_bag(path: str | os.PathLike, messages: Iterable[tuple[str, str, int, dict]], *,
              store: str = "ros2_humble", version: int = 8, storage: str = "sqlite3",
              latched: Iterable[str] = ()) -> None:
  """Writes (topic, msgtype, timestamp_ns, dict) messages to a new rosbag2 folder.

  Args:
    path: the bag folder to create (must not exist).
    messages: (topic, ROS type name such as OCCUPANCY_GRID, receive time in
      ns >= 0, the message dict) tuples, in time order or not.
    store: the rosbags type store (ROS distribution) to serialize with.
    version: rosbag2 metadata version, 8 or 9.
    storage: "sqlite3" (rosbag2's older default) or "mcap" (the default
      since ROS 2 Iron; what Foxglove and PlotJuggler open directly).
    latched: topics recorded with a transient-local, reliable QoS (as Nav2's
      map and mask servers publish), so `ros2 bag play` re-offers them to
      late subscribers such as RViz.

  Raises:
    ImportError: rosbags is not installed (install jaxfilters[ros]).
    FileExistsError: the path exists.
    ValueError: an unknown type, a bad timestamp, a dict that does not match
      its type (the message names the field), an unknown store or version.
  """
  rosbag2, _ = _rosbags()
  ts = typestore(store)
  if version not in (8, 9):
    raise ValueError(f"version must be 8 or 9 (rosbag2 metadata); got {short_repr(version)}")
  if storage not in STORAGES:
    raise ValueError(f"storage must be one of {STORAGES}; got {short_repr(storage)}")
  latched = set(latched)
  path = os.fspath(path)
  if os.path.exists(path):
    raise FileExistsError(f"rosbag2 folder {path} already exists; choose a new path")
  items = []
  for i, item in enumerate(messages):
    if not isinstance(item, tuple) or len(item) != 4:
      raise ValueError(f"messages[{i}] must be (topic, msgtype, timestamp_ns, dict); got "
                       f"{short_repr(item)}")
    topic, msgtype, stamp, msg = item
    _str(topic, f"messages[{i}] topic", nonempty=True)
    if msgtype not in ts.types:
      raise ValueError(f"messages[{i}]: unknown message type {short_repr(msgtype)} for store "
                       f"{store!r}")
    stamp = _int(stamp, f"messages[{i}] timestamp (ns)", 0, 2**63 - 1)
    items.append((topic, msgtype, stamp, _to_ros(ts, msgtype, msg, f"messages[{i}] {msgtype}")))
  plugin = rosbag2.StoragePlugin.MCAP if storage == "mcap" else rosbag2.StoragePlugin.SQLITE3
  items.sort(key=lambda item: item[2])
  with rosbag2.Writer(path, version=version, storage_plugin=plugin) as writer:
    connections = {}
    for topic, msgtype, stamp, obj in items:
      key = (topic, msgtype)
      if key not in connections:
        qos = (_latched_qos(),) if topic in latched else ()
        connections[key] = writer.add_connection(topic, msgtype, typestore=ts, offered_qos_profiles=qos)
      writer.write(connections[key], stamp, ts.serialize_cdr(obj, msgtype))


def _latched_qos():
  from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness,  # noqa: PLC0415
                                  QosReliability, QosTime)

  never = QosTime(0, 0)
  return Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL, never, never,
             QosLiveliness.AUTOMATIC, never, False)


def read_bag(path: str | os.PathLike, *, topics: Iterable[str] | None = None,
             store: str = "ros2_humble") -> list[BagMessage]:
  """Reads a rosbag2 folder into BagMessage(topic, msgtype, timestamp_ns, dict) in time order.

  Types the store lacks are built from the definitions the bag carries (so a
  bag with other nav2_msgs versions still reads); the embedded nav2_msgs
  definitions are the fallback for bags without definitions.

  Args:
    path: the bag folder.
    topics: only these topics (None: all).
    store: the rosbags type store to start from.

  Raises:
    ImportError: rosbags is not installed (install jaxfilters[ros]).
    FileNotFoundError: no such folder.
    ValueError: not a readable rosbag2 folder, or a type with no definition.
  """
  rosbag2, typesys = _rosbags()
  ts = typestore(store)
  path = os.fspath(path)
  if not os.path.isdir(path):
    raise FileNotFoundError(f"rosbag2 folder {path} does not exist")
  wanted = None if topics is None else set(topics)
  out = []
  try:
    reader = rosbag2.Reader(path)
    reader.open()
  except Exception as e:  # noqa: BLE001 - rosbags raises its own error types
    raise ValueError(f"{path} is not a readable rosbag2 folder: {e}") from None
  try:
    conns = [c for c in reader.connections if wanted is None or c.topic in wanted]
    for c in conns:
      if c.msgtype not in ts.types:
        text = getattr(getattr(c, "msgdef", None), "data", "")
        if not text:
          raise ValueError(f"{path}: topic {c.topic} has type {c.msgtype}, which the bag does not "
                           "define and the type store lacks")
        ts.register(typesys.get_types_from_msg(text, c.msgtype))
    for c, stamp, raw in reader.messages(connections=conns):
      obj = ts.deserialize_cdr(raw, c.msgtype)
      out.append(BagMessage(c.topic, c.msgtype, int(stamp), _from_ros(ts, c.msgtype, obj)))
  finally:
    reader.close()
  return out
