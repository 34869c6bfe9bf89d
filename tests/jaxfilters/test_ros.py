"""ROS message shapes (jaxfilters.ros): dicts both ways, validation, and rosbag2 round trips."""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest

from jaxfilters import ros
from jaxfilters.binary import BinaryResult
from jaxfilters.grid import OccupancyGrid
from jaxfilters.map_io import load_map
from jaxfilters.speed import SpeedResult
from jaxfilters.types import FilterInfo


def _grid(seed=0, h=5, w=7, yaw=0.4):
  rng = np.random.default_rng(seed)
  return OccupancyGrid.create(rng.integers(-1, 101, size=(h, w)), 0.05, (-1.5, 2.25, yaw), "odom")


# --------------------------------------------------------------------------- OccupancyGrid


def test_occupancy_grid_to_msg_fields():
  grid = _grid()
  msg = ros.occupancy_grid_to_msg(grid, stamp=ros.time_msg(12, 345), map_load_time=ros.time_msg(3))
  assert msg["header"] == {"stamp": {"sec": 12, "nanosec": 345}, "frame_id": "odom"}
  info = msg["info"]
  assert info["map_load_time"] == {"sec": 3, "nanosec": 0}
  assert info["resolution"] == float(np.float32(0.05)) and (info["width"], info["height"]) == (7, 5)
  assert info["origin"]["position"] == {"x": -1.5, "y": 2.25, "z": 0.0}
  q = info["origin"]["orientation"]
  assert (q["x"], q["y"]) == (0.0, 0.0)
  assert q["z"] == pytest.approx(math.sin(0.2)) and q["w"] == pytest.approx(math.cos(0.2))
  # Row-major from row 0 (lowest y): data[my * width + mx].
  for my in range(5):
    for mx in range(7):
      assert msg["data"][my * 7 + mx] == grid.data[my, mx]
  assert msg["data"].dtype == np.int8 and msg["data"].shape == (35,)


@pytest.mark.parametrize("yaw", [0.0, 1.0, -3.0, math.pi, 2.5])
def test_occupancy_grid_round_trip(yaw):
  grid = _grid(1, 3, 4, yaw)
  back = ros.occupancy_grid_from_msg(ros.occupancy_grid_to_msg(grid))
  assert np.array_equal(back.data, grid.data) and back.frame_id == "odom"
  assert back.resolution == float(np.float32(0.05))    # the message field is float32
  assert back.origin[:2] == (-1.5, 2.25)
  assert math.cos(back.origin[2] - yaw) == pytest.approx(1.0) and abs(back.origin[2]) <= math.pi


def test_occupancy_grid_from_plain_lists_and_other_quaternion_sign():
  msg = {"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "map"},
         "info": {"map_load_time": {"sec": 0, "nanosec": 0}, "resolution": 0.5, "width": 3,
                  "height": 2,
                  "origin": {"position": {"x": 1, "y": 2, "z": 0},
                             # -q is the same rotation as q: yaw +90 degrees
                             "orientation": {"x": 0, "y": 0, "z": -math.sqrt(0.5),
                                             "w": -math.sqrt(0.5)}}},
         "data": [0, 100, -1, 5, 6, 7]}
  grid = ros.occupancy_grid_from_msg(msg)
  assert grid.data.tolist() == [[0, 100, -1], [5, 6, 7]]
  assert grid.origin == pytest.approx((1.0, 2.0, math.pi / 2))


def _base_msg():
  return ros.occupancy_grid_to_msg(_grid(2, 2, 3))


@pytest.mark.parametrize("edit, match", [
    (lambda m: m["info"].pop("width"), r"OccupancyGrid\.info\.width is missing"),
    (lambda m: m["info"].update(width=3.0), r"OccupancyGrid\.info\.width must be an integer"),
    (lambda m: m["info"].update(width=0), r"OccupancyGrid\.info\.width must lie in \[1, "),
    (lambda m: m["info"].update(height=True), r"info\.height must be an integer"),
    (lambda m: m.update(data=m["data"][:-1]), r"OccupancyGrid\.data has 5 values; .* = 6"),
    (lambda m: m.update(data=np.array([0, 1, 2, 3, 4, 101])), r"data values must lie in -1\.\.100"),
    (lambda m: m.update(data=[0, 1, 2, 3, 4, -2]), r"data values must lie in -1\.\.100"),
    (lambda m: m.update(data=[0.0] * 6), r"data must hold integers"),
    (lambda m: m["info"].update(resolution=0.0), r"info: resolution must be > 0"),
    (lambda m: m["info"].update(resolution=-0.05), r"resolution must be > 0"),
    (lambda m: m["info"].update(resolution=1e-50), r"resolution must be 0 or at least"),
    (lambda m: m["info"].update(resolution=1e39), r"resolution must fit float32"),
    (lambda m: m["info"].update(resolution=float("nan")), r"info\.resolution must be finite"),
    (lambda m: m["info"]["origin"]["position"].update(z=0.5), r"position\.z must be 0"),
    (lambda m: m["info"]["origin"]["position"].update(x=float("inf")), r"position\.x must be finite"),
    (lambda m: m["info"]["origin"]["orientation"].update(w=0.0, z=0.0), r"unit quaternion"),
    (lambda m: m["info"]["origin"]["orientation"].update(x=0.6, w=0.8, z=0.0),
     r"rotation about z only"),
    (lambda m: m["header"].update(frame_id=3), r"header\.frame_id must be a string"),
    (lambda m: m["header"]["stamp"].update(nanosec=10**9), r"header\.stamp\.nanosec must lie in"),
    (lambda m: m["info"].update(map_load_time=5), r"map_load_time must be a builtin_interfaces"),
    (lambda m: m.pop("header"), r"OccupancyGrid\.header is missing"),
])
def test_occupancy_grid_from_msg_names_the_bad_field(edit, match):
  msg = _base_msg()
  edit(msg)
  with pytest.raises(ValueError, match=match):
    ros.occupancy_grid_from_msg(msg)


def test_occupancy_grid_from_msg_rejects_non_dicts():
  with pytest.raises(ValueError, match="OccupancyGrid must be a dict"):
    ros.occupancy_grid_from_msg([1, 2])
  with pytest.raises(TypeError):
    ros.occupancy_grid_to_msg(np.zeros((2, 2)))


def test_real_map_to_msg_and_back(nav2_maps):
  grid = load_map(nav2_maps / "tb3_sandbox.yaml")
  msg = ros.occupancy_grid_to_msg(grid)
  assert (msg["info"]["width"], msg["info"]["height"]) == (384, 384)
  back = ros.occupancy_grid_from_msg(msg)
  assert np.array_equal(back.data, grid.data) and back.origin == (-10.0, -10.0, 0.0)


# --------------------------------------------------------------------------- filter info, speed, bool


def test_filter_info_both_ways_and_naming():
  info = FilterInfo.create(1, 100.0, -1.0)
  msg = ros.filter_info_to_msg(info, "/speed_filter_mask")
  assert msg == {"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""}, "type": 1,
                 "filter_mask_topic": "/speed_filter_mask", "base": 100.0, "multiplier": -1.0}
  back, topic = ros.filter_info_from_msg(msg)
  assert topic == "/speed_filter_mask"
  assert (int(back.type), float(back.base), float(back.multiplier)) == (1, 100.0, -1.0)
  # float32 fields: 0.1 travels as 0.10000000149011612 (docs/nav2_semantics.md §3).
  msg = ros.filter_info_to_msg(FilterInfo.create(2, 0.1, 0.2), "/m", naming="design")
  assert "map_mask_topic" in msg and "filter_mask_topic" not in msg
  assert msg["base"] == float(np.float32(0.1))
  back, topic = ros.filter_info_from_msg(msg)
  assert topic == "/m" and float(back.base) == float(np.float32(0.1))


@pytest.mark.parametrize("edit, match", [
    (lambda m: m.update(type=6), r"type must be one of \(0, 1, 2, 3, 4, 5\)"),
    (lambda m: m.update(type=-1), r"type must lie in \[0, 255\]"),
    (lambda m: m.update(base=float("inf")), r"base must be finite"),
    (lambda m: m.update(multiplier=1e39), r"multiplier must fit float32"),
    (lambda m: m.update(filter_mask_topic=""), r"filter_mask_topic must not be empty"),
    (lambda m: m.update(map_mask_topic="/x"), r"exactly one of filter_mask_topic"),
    (lambda m: m.pop("filter_mask_topic"), r"got neither"),
    (lambda m: m.update(base="1"), r"base must be a number"),
])
def test_filter_info_from_msg_names_the_bad_field(edit, match):
  msg = ros.filter_info_to_msg(FilterInfo.create(0), "/keepout_filter_mask")
  edit(msg)
  with pytest.raises(ValueError, match=match):
    ros.filter_info_from_msg(msg)


def test_filter_info_to_msg_refusals():
  with pytest.raises(ValueError, match="must not be empty"):
    ros.filter_info_to_msg(FilterInfo.create(0), "")
  stacked = FilterInfo(np.array([0, 1]), np.array([0.0, 1.0], np.float32),
                       np.array([1.0, 1.0], np.float32))
  with pytest.raises(ValueError, match="one message per mask"):
    ros.filter_info_to_msg(stacked, "/m")
  with pytest.raises(ValueError, match="naming must be one of"):
    ros.filter_info_to_msg(FilterInfo.create(0), "/m", naming="ros1")


def test_speed_limit_and_max_speed():
  msg = ros.speed_limit_to_msg(35.0, True, frame_id="map", stamp=ros.time_msg(1, 2))
  assert msg == {"header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "map"},
                 "percentage": True, "speed_limit": 35.0}
  assert ros.speed_limit_from_msg(msg) == (35.0, True)
  old = ros.speed_limit_to_msg(0.5, False, naming="design")
  assert set(old) == {"header", "percentage", "max_speed"}
  assert ros.speed_limit_from_msg(old) == (0.5, False)
  for value, pct, match in ((101.0, True, "<= 100"), (-0.1, False, ">= 0"),
                            (float("nan"), False, "finite")):
    with pytest.raises(ValueError, match=match):
      ros.speed_limit_to_msg(value, pct)
  bad = dict(msg, max_speed=1.0)
  with pytest.raises(ValueError, match="exactly one of speed_limit"):
    ros.speed_limit_from_msg(bad)
  with pytest.raises(ValueError, match=r"SpeedLimit\.percentage must be a bool"):
    ros.speed_limit_from_msg(dict(msg, percentage=1))
  with pytest.raises(ValueError, match=r"SpeedLimit\.speed_limit must be >= 0 and <= 100"):
    ros.speed_limit_from_msg(dict(msg, speed_limit=150.0))


def test_speed_filter_outputs_to_messages():
  limit = np.array([0.0, 40.0, 1.2999999523162842, 55.5], np.float32)
  result = SpeedResult(limit, np.array([True, True, False, True]),
                       np.array([True, False, True, False]), np.array([True, True, True, False]))
  msgs = ros.speed_limit_msgs(result, frame_id="map", stamp=ros.time_msg(7))
  assert msgs[1] is None and msgs[3] is None            # Nav2 publishes only on change
  assert msgs[0]["speed_limit"] == 0.0 and msgs[0]["percentage"] is True
  assert msgs[2]["speed_limit"] == float(np.float32(1.3)) and msgs[2]["percentage"] is False
  assert msgs[2]["header"] == {"stamp": {"sec": 7, "nanosec": 0}, "frame_id": "map"}
  with pytest.raises(ValueError, match=r"\[B\] arrays"):
    ros.speed_limit_msgs(SpeedResult(limit, np.array([True]), np.array([True]), np.array([True])))


def test_bool_and_binary_state():
  assert ros.bool_to_msg(True) == {"data": True}
  assert ros.bool_from_msg({"data": np.bool_(False)}) is False
  for bad in ({"data": 1}, {"data": "true"}, {}, [True]):
    with pytest.raises(ValueError):
      ros.bool_from_msg(bad)
  result = BinaryResult(np.array([True, False, True]), np.array([True, True, False]),
                        np.array([True, True, True]))
  assert ros.binary_state_msgs(result) == [{"data": True}, {"data": False}, None]


def test_time_and_header():
  assert ros.time_msg() == {"sec": 0, "nanosec": 0}
  assert ros.header_msg("base_link", ros.time_msg(-5, 999_999_999)) == {
      "stamp": {"sec": -5, "nanosec": 999_999_999}, "frame_id": "base_link"}
  for kw, match in ((dict(sec=2**31), r"Time\.sec"), (dict(nanosec=-1), r"Time\.nanosec"),
                    (dict(sec=1.5), "integer")):
    with pytest.raises(ValueError, match=match):
      ros.time_msg(**kw)


# --------------------------------------------------------------------------- rosbag2


def _all_messages():
  grid = _grid(3, 6, 9, 0.3)
  return grid, [
      ("/map", ros.OCCUPANCY_GRID, 1_000, ros.occupancy_grid_to_msg(grid, stamp=ros.time_msg(1))),
      ("/costmap_filter_info", ros.COSTMAP_FILTER_INFO, 2_000,
       ros.filter_info_to_msg(FilterInfo.create(1, 100.0, -1.0), "/speed_filter_mask")),
      ("/speed_limit", ros.SPEED_LIMIT, 3_000, ros.speed_limit_to_msg(40.0, True)),
      ("/max_speed", ros.MAX_SPEED, 4_000, ros.speed_limit_to_msg(0.7, False, naming="design")),
      ("/binary_state", ros.BOOL, 5_000, ros.bool_to_msg(True)),
      ("/speed_limit", ros.SPEED_LIMIT, 6_000, ros.speed_limit_to_msg(0.0, True)),
  ]


def _same(a, b):
  if isinstance(a, dict):
    return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
  if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
    return np.array_equal(np.asarray(a), np.asarray(b))
  return a == b and type(a) is type(b)


@pytest.mark.parametrize("version", [8, 9])
def test_bag_write_then_read_back(tmp_path, version):
  grid, messages = _all_messages()
  path = tmp_path / "bag"
  ros.write_bag(path, reversed(messages), version=version)    # any order in, time order out
  back = ros.read_bag(path)
  assert [(m.topic, m.msgtype, m.timestamp) for m in back] == [m[:3] for m in messages]
  for got, (_, _, _, msg) in zip(back, messages):
    assert _same(msg, got.msg), (msg, got.msg)
  assert np.array_equal(ros.occupancy_grid_from_msg(back[0].msg).data, grid.data)
  info, topic = ros.filter_info_from_msg(back[1].msg)
  assert topic == "/speed_filter_mask" and float(info.base) == 100.0
  assert ros.speed_limit_from_msg(back[3].msg) == (0.7, False)
  only = ros.read_bag(path, topics=["/speed_limit"])
  assert [m.msg["speed_limit"] for m in only] == [40.0, 0.0]


def test_bag_typestore_round_trip(tmp_path):
  """The bag carries our definitions: a store knowing only those decodes every message."""
  from rosbags.rosbag2 import Reader
  from rosbags.typesys import Stores, get_types_from_msg, get_typestore

  _, messages = _all_messages()
  ros.write_bag(tmp_path / "bag", messages)
  ours = ros.typestore()
  fresh = get_typestore(Stores.EMPTY)
  with Reader(tmp_path / "bag") as reader:
    for conn in reader.connections:
      types = get_types_from_msg(conn.msgdef.data, conn.msgtype)
      fresh.register(types)
      if conn.msgtype in ros.MSG_DEFINITIONS:
        assert conn.digest == ours.hash_rihs01(conn.msgtype)
        assert fresh.fielddefs[conn.msgtype] == ours.fielddefs[conn.msgtype]
    decoded = [fresh.deserialize_cdr(raw, conn.msgtype) for conn, _, raw in reader.messages()]
  assert decoded[2].speed_limit == 40.0 and decoded[1].filter_mask_topic == "/speed_filter_mask"
  assert decoded[3].max_speed == 0.7 and decoded[0].info.width == 9
  # The nav2 field lines are those of the message definitions, in order.
  fields = [name for name, _ in ours.fielddefs[ros.COSTMAP_FILTER_INFO][1]]
  assert fields == ["header", "type", "filter_mask_topic", "base", "multiplier"]
  assert [n for n, _ in ours.fielddefs[ros.SPEED_LIMIT][1]] == ["header", "percentage", "speed_limit"]


def test_bag_errors(tmp_path):
  _, messages = _all_messages()
  ros.write_bag(tmp_path / "bag", messages[:1])
  with pytest.raises(FileExistsError, match="already exists"):
    ros.write_bag(tmp_path / "bag", messages[:1])
  cases = [
      ([("/x", "nav2_msgs/msg/Nope", 0, {})], "unknown message type"),
      ([("/x", ros.BOOL, -1, {"data": True})], r"timestamp \(ns\) must lie in"),
      ([("/x", ros.BOOL, 0, {"data": True, "extra": 1})], r"has fields \['extra'\]"),
      ([("/x", ros.BOOL, 0, {})], r"Bool\.data is missing"),
      ([("/x", ros.SPEED_LIMIT, 0, dict(messages[2][3], percentage="yes"))],
       r"percentage must be a bool"),
      ([("", ros.BOOL, 0, {"data": True})], "topic must not be empty"),
      ([("/x", ros.BOOL, 0)], r"\(topic, msgtype, timestamp_ns, dict\)"),
  ]
  for msgs, match in cases:
    with pytest.raises(ValueError, match=match):
      ros.write_bag(tmp_path / "other", msgs)
    assert not (tmp_path / "other").exists()
  bad = dict(messages[0][3], data=np.full(54, 300))
  with pytest.raises(ValueError, match=r"data must hold int8 integers"):
    ros.write_bag(tmp_path / "other", [("/map", ros.OCCUPANCY_GRID, 0, bad)])
  with pytest.raises(ValueError, match="version must be 8 or 9"):
    ros.write_bag(tmp_path / "other", [], version=5)
  with pytest.raises(ValueError, match="store must be one of"):
    ros.typestore("ros2_rolling_nope")
  with pytest.raises(FileNotFoundError):
    ros.read_bag(tmp_path / "missing")
  (tmp_path / "empty").mkdir()
  with pytest.raises(ValueError, match="not a readable rosbag2 folder"):
    ros.read_bag(tmp_path / "empty")


def test_missing_rosbags_says_how_to_install(monkeypatch, tmp_path):
  for name in [m for m in sys.modules if m == "rosbags" or m.startswith("rosbags.")]:
    monkeypatch.delitem(sys.modules, name)
  monkeypatch.setitem(sys.modules, "rosbags", None)     # import rosbags -> ImportError
  for call in (lambda: ros.typestore(), lambda: ros.read_bag(tmp_path),
               lambda: ros.write_bag(tmp_path / "b", [])):
    with pytest.raises(ImportError, match=r"pip install 'jaxfilters\[ros\]'"):
      call()
  # The dict converters never need it.
  assert ros.bool_to_msg(False) == {"data": False}
