"""A fleet run as a rosbag2 folder (MCAP storage) for Foxglove, RViz (`ros2 bag play`) and PlotJuggler.

`write_fleet_bag` turns a rollout's recording (`FleetEnv.rollout_fn(...,
record_ticks=True)`, gathered on the host with `host_recording`) into the
topics a Nav2 system publishes, stamped with simulated time:

| topic | type | when |
| --- | --- | --- |
| `/map` | nav_msgs/msg/OccupancyGrid | once, latched |
| `/keepout_filter_mask`, `/speed_filter_mask` | nav_msgs/msg/OccupancyGrid | once, latched (Nav2's mask servers) |
| `/keepout_costmap_filter_info`, `/speed_costmap_filter_info` | nav2_msgs/msg/CostmapFilterInfo | once, latched (Nav2's info servers) |
| `/tf` | tf2_msgs/msg/TFMessage | every controller tick: `map -> robot_<i>/base_link` of every recorded robot |
| `/robot_<i>/cmd_vel` | geometry_msgs/msg/Twist | every controller tick: the command after the speed clip |
| `/robot_<i>/speed_limit` | nav2_msgs/msg/SpeedLimit | at the first tick (the limit in force, 0.0 = none), then whenever it changes, as Nav2's SpeedFilter publishes |
| `/robot_<i>/speed_cap` | std_msgs/msg/Float64 | every controller tick: the limit in force in m/s (max_speed where there is none), to plot against cmd_vel |
| `/robot_<i>/local_costmap/costmap` | nav_msgs/msg/OccupancyGrid | every local-costmap update, for the first `costmap_robots` robots, values as Nav2's costmap publisher writes them |
| `/fleet/summary` | std_msgs/msg/String | once at the end: the run's summary as JSON |

Topic names follow the nav2_params.yaml that ships with the built-in scenario
(`keepout_filter_mask`, `speed_filter_mask`, `*_costmap_filter_info`); the
nav2_msgs types are registered from their .msg definitions (jaxfilters.ros),
so any reader decodes them by name. Writing needs the `ros` extra (rosbags).

Besides metadata.yaml and the .mcap file, the folder holds `MARKER_NAME`, a
small text file naming the files written: `check_bag_dir(..., overwrite=True)`
replaces a folder only when that file proves this module made it and the
folder holds nothing else, so no user's folder is ever deleted.
"""

from __future__ import annotations

import json
import math
import os
import stat
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from jaxfilters import constants, ros
from jaxfilters.grid import OccupancyGrid
from jaxfilters.types import FilterInfo

__all__ = ["MARKER_HEADER", "MARKER_NAME", "BagError", "FleetRecording", "bag_files", "check_bag_dir", "host_recording", "remove_bag", "write_fleet_bag"]

MAP_TOPIC = "/map"
KEEPOUT_MASK_TOPIC = "/keepout_filter_mask"
SPEED_MASK_TOPIC = "/speed_filter_mask"
KEEPOUT_INFO_TOPIC = "/keepout_costmap_filter_info"
SPEED_INFO_TOPIC = "/speed_costmap_filter_info"
SUMMARY_TOPIC = "/fleet/summary"
TWIST = "geometry_msgs/msg/Twist"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
FLOAT64 = "std_msgs/msg/Float64"
STRING = "std_msgs/msg/String"


class BagError(ValueError):
  """A bag folder that cannot be written (exists and is not empty, not a folder, not writable)."""


@dataclass(frozen=True)
class FleetRecording:
  """A fleet run's recording on the host, for the first R robots (world-major order).

  Attributes:
    time: float64 [T] start of each controller tick (s).
    pose: float32 [T, R, 3] (x, y, yaw) at the start of each tick.
    cmd: float32 [T, R, 2] (v m/s, w rad/s) chosen at that tick, after the speed clip.
    speed_limit: float32 [T, R] the SpeedFilter's limit in force at that tick (0 = none).
    speed_cap: float32 [T, R] that limit in m/s (+inf = none).
    end_time: float, simulated time at the end of the run (s).
    end_pose: float32 [R, 3] poses at the end of the run.
    costmap_time: float64 [S] time of each local-costmap update (s).
    costmap: uint8 [S, L, N, N] local costmaps of the first L robots (L may be 0).
    costmap_origin: float32 [S, L, 2] lower-left corners (m).
    costmap_resolution: float32 [S, L] (m per cell).
  """
  time: np.ndarray
  pose: np.ndarray
  cmd: np.ndarray
  speed_limit: np.ndarray
  speed_cap: np.ndarray
  end_time: float
  end_pose: np.ndarray
  costmap_time: np.ndarray
  costmap: np.ndarray
  costmap_origin: np.ndarray
  costmap_resolution: np.ndarray


def host_recording(chunks, *, robots: int, step_seconds: float) -> FleetRecording:
  """Joins the Recordings of consecutive rollout calls (from time 0) into one FleetRecording.

  Times are counted on the host from the step and tick indices (tick j of the
  run starts at j * step_seconds / ticks_per_step), so stamps are exact
  multiples of the controller period rather than float32 sums.

  Args:
    chunks: sequence of `sims.fleet.env.Recording` (leaves [num_steps, ...]) in run order.
    robots: R, how many robots to keep (the first R in world-major order).
    step_seconds: simulated seconds per env step (FleetConfig.step_seconds).

  Returns:
    FleetRecording of the first `robots` robots.
  """
  times, poses, cmds, limits, caps, ends = [], [], [], [], [], []
  ctimes, costs, corigins, cres = [], [], [], []
  step = 0
  for rec in chunks:
    t = rec.ticks
    n, ticks, w, k = np.asarray(t.pose).shape[:4]
    times.append((step * ticks + np.arange(n * ticks)) * (float(step_seconds) / ticks))
    poses.append(np.asarray(t.pose).reshape(n * ticks, w * k, 3)[:, :robots])
    cmds.append(np.asarray(t.cmd).reshape(n * ticks, w * k, 2)[:, :robots])
    limits.append(np.asarray(t.speed_limit).reshape(n * ticks, w * k)[:, :robots])
    caps.append(np.asarray(t.speed_cap).reshape(n * ticks, w * k)[:, :robots])
    ends.append(np.asarray(rec.frame.pose).reshape(n, w * k, 3)[:, :robots])
    # Costmaps are rebuilt at the start of each step, from the poses of the step's first tick.
    ctimes.append((step + np.arange(n)) * float(step_seconds))
    if rec.costmaps is not None:
      costs.append(np.asarray(rec.costmaps.cost))
      corigins.append(np.asarray(rec.costmaps.origin))
      cres.append(np.asarray(rec.costmaps.resolution))
    step += n
  costmap = np.concatenate(costs) if costs else np.zeros((0, 0, 1, 1), np.uint8)
  return FleetRecording(
      time=np.concatenate(times), pose=np.concatenate(poses), cmd=np.concatenate(cmds),
      speed_limit=np.concatenate(limits), speed_cap=np.concatenate(caps),
      end_time=step * float(step_seconds), end_pose=np.concatenate(ends)[-1],
      costmap_time=np.concatenate(ctimes) if costs else np.zeros((0,)),
      costmap=costmap,
      costmap_origin=np.concatenate(corigins) if costs else np.zeros((0, 0, 2), np.float32),
      costmap_resolution=np.concatenate(cres) if costs else np.zeros((0, 0), np.float32))


# Every bag folder `write_fleet_bag` makes holds this file: a fixed first line, then the names of the
# files it wrote. `--overwrite` replaces a folder only when the marker proves the tool made it and
# the folder holds nothing but those regular files.
MARKER_NAME = ".jaxfilters_fleet_bag"
MARKER_HEADER = "jaxfilters fleet bag: written by sims.record.bag.write_fleet_bag, replaced only by it (--overwrite)"
_MARKER_MAX_BYTES = 4096


def _bag_error(path, text: str) -> BagError:
  return BagError(f"--bag {os.fspath(path)}: {text}")


def _regular(path: Path) -> bool:
  """A regular file itself (lstat: a symbolic link, FIFO or folder is not)."""
  return stat.S_ISREG(os.lstat(path).st_mode)


def bag_files(path: str | os.PathLike) -> list[str]:
  """The files of a bag folder this module wrote, all that `--overwrite` may remove.

  Args:
    path: an existing folder.

  Returns:
    Every entry's name (the marker, metadata.yaml, the .mcap file).

  Raises:
    BagError: the folder is not one `write_fleet_bag` made (no marker, a marker
      that is not ours, an entry the marker does not list, an entry that is not a
      regular file), so nothing in it may be removed.
  """
  path = Path(path)
  refuse = ("holds files other than a bag this tool wrote; --overwrite replaces only a folder made by "
            f"jaxfilters fleet --bag (with its {MARKER_NAME} file, metadata.yaml and the .mcap file, nothing else)")
  try:
    names = sorted(os.listdir(path))
    if MARKER_NAME not in names or not _regular(path / MARKER_NAME):
      raise _bag_error(path, f"{refuse}: no {MARKER_NAME} file")
    with open(path / MARKER_NAME, "rb") as f:     # a regular file (checked above): reading cannot block
      raw = f.read(_MARKER_MAX_BYTES + 1)
  except OSError as e:
    raise _bag_error(path, f"cannot read it ({e.strerror or e})") from None
  try:
    lines = raw.decode("utf-8").split("\n")
  except UnicodeDecodeError:
    lines = []
  listed = {n for n in lines[1:] if n}
  if len(raw) > _MARKER_MAX_BYTES or not lines or lines[0] != MARKER_HEADER or not listed or \
      not all(n == "metadata.yaml" or (n.endswith(".mcap") and "/" not in n and n != ".mcap") for n in listed):
    raise _bag_error(path, f"{refuse}: {MARKER_NAME} is not one this tool writes")
  for name in names:
    if name != MARKER_NAME and name not in listed:
      raise _bag_error(path, f"{refuse}: it holds {name!r}")
    try:
      if not _regular(path / name):
        raise _bag_error(path, f"{refuse}: {name!r} is not a regular file")
    except OSError as e:
      raise _bag_error(path, f"cannot read it ({e.strerror or e})") from None
  return names


def check_bag_dir(path: str | os.PathLike, *, overwrite: bool = False) -> Path:
  """Checks, before a run, that a bag folder can be written at `path`.

  Args:
    path: the bag folder: new, or an existing empty folder, or (overwrite) a
      bag folder `write_fleet_bag` made (`bag_files`: nothing else is ever deleted).
    overwrite: replace an existing non-empty folder.

  Returns:
    The path.

  Raises:
    BagError: an empty path, a symbolic link, the current folder or one holding
      it, a file in the way (at the path or one of its parents), a folder that is
      not empty (without overwrite) or not a bag this module wrote (with it), or
      a place where no folder can be created (the nearest existing folder is
      probed; missing parents are created when the bag is written).
  """
  if os.fspath(path) == "":
    raise BagError("--bag must name a folder; got ''")
  path = target = Path(path)
  try:
    if path.is_symlink():
      raise _bag_error(path, "is a symbolic link; name the folder itself")
    if path.exists() and not path.is_dir():
      raise _bag_error(path, "exists and is not a folder")
    here, target = Path.cwd().resolve(), path.resolve()
    if here == target or target in here.parents:
      raise _bag_error(path, "is the current folder or holds it; name a new folder for the bag")
    if path.is_dir() and any(path.iterdir()):
      if not overwrite:
        raise _bag_error(path, "folder is not empty (pass --overwrite to replace a bag this tool wrote)")
      bag_files(path)
    target = target.parent                   # the folder is (re)made there: rosbag2's writer creates it
    while not target.exists():               # missing parents are created when the bag is written
      target = target.parent
    if not target.is_dir():
      raise _bag_error(path, f"{target} is not a folder")
    os.rmdir(tempfile.mkdtemp(prefix=".jaxfilters_probe_", dir=target))
  except OSError as e:
    raise _bag_error(path, f"cannot create a folder in {target} ({e.strerror or e})") from None
  except ValueError as e:
    if isinstance(e, BagError):
      raise
    raise BagError(f"--bag {os.fspath(path)!r}: not a usable path ({e})") from None
  return path


def remove_bag(path: str | os.PathLike) -> None:
  """Removes a bag folder `bag_files` accepts: its listed files one by one, then the (empty) folder.

  Raises:
    BagError: the folder is not one this module wrote (nothing is removed).
    OSError: the folder changed meanwhile (a new entry: the folder stays).
  """
  path = Path(path)
  for name in bag_files(path):
    os.unlink(path / name)
  os.rmdir(path)              # fails, removing nothing more, if anything appeared meanwhile


def _stamp(t: float) -> dict:
  ns = int(round(t * 1e9))
  return ros.time_msg(ns // 1_000_000_000, ns % 1_000_000_000)


def _ns(t: float) -> int:
  return int(round(t * 1e9))


def _quat(yaw: float) -> dict:
  return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}


def _tf(t: float, poses: np.ndarray) -> dict:
  return {"transforms": [
      {"header": ros.header_msg("map", _stamp(t)), "child_frame_id": f"robot_{i}/base_link",
       "transform": {"translation": {"x": float(p[0]), "y": float(p[1]), "z": 0.0},
                     "rotation": _quat(float(p[2]))}}
      for i, p in enumerate(poses)]}


def _grid(data: np.ndarray, origin, resolution: float, frame: str = "map") -> OccupancyGrid:
  return OccupancyGrid(data=data, resolution=float(resolution),
                       origin=(float(origin[0]), float(origin[1]), 0.0), frame_id=frame)


def fleet_messages(scenario, rec: FleetRecording, *, max_speed: float, summary: dict | None = None):
  """The (topic, type, timestamp_ns, dict) messages of a run (see the module docstring)."""
  percent = scenario.speed_type == constants.SPEED_FILTER_PERCENT
  out = [
      (MAP_TOPIC, ros.OCCUPANCY_GRID, 0, ros.occupancy_grid_to_msg(scenario.map)),
      (KEEPOUT_MASK_TOPIC, ros.OCCUPANCY_GRID, 0, ros.occupancy_grid_to_msg(scenario.keepout)),
      (SPEED_MASK_TOPIC, ros.OCCUPANCY_GRID, 0, ros.occupancy_grid_to_msg(scenario.speed)),
      (KEEPOUT_INFO_TOPIC, ros.COSTMAP_FILTER_INFO, 0,
       ros.filter_info_to_msg(FilterInfo.create(constants.KEEPOUT_FILTER), KEEPOUT_MASK_TOPIC, frame_id="map")),
      (SPEED_INFO_TOPIC, ros.COSTMAP_FILTER_INFO, 0,
       ros.filter_info_to_msg(FilterInfo.create(scenario.speed_type, scenario.speed_base,
                                                scenario.speed_multiplier), SPEED_MASK_TOPIC, frame_id="map")),
  ]
  robots = rec.pose.shape[1]
  prev = np.zeros((robots,), np.float32)   # Nav2's SpeedFilter starts from 0.0 (no limit)
  for j, t in enumerate(rec.time):
    ns = _ns(t)
    out.append(("/tf", TF_MESSAGE, ns, _tf(t, rec.pose[j])))
    for i in range(robots):
      v, w = (float(x) for x in rec.cmd[j, i])
      out.append((f"/robot_{i}/cmd_vel", TWIST, ns, {"linear": {"x": v, "y": 0.0, "z": 0.0},
                                                     "angular": {"x": 0.0, "y": 0.0, "z": w}}))
      limit = rec.speed_limit[j, i]
      if j == 0 or limit != prev[i]:
        out.append((f"/robot_{i}/speed_limit", ros.SPEED_LIMIT, ns,
                    ros.speed_limit_to_msg(float(limit), percent, stamp=_stamp(t))))
      cap = float(rec.speed_cap[j, i])
      out.append((f"/robot_{i}/speed_cap", FLOAT64, ns, {"data": min(cap, float(max_speed))}))
    prev = rec.speed_limit[j]
  out.append(("/tf", TF_MESSAGE, _ns(rec.end_time), _tf(rec.end_time, rec.end_pose)))
  for s, t in enumerate(rec.costmap_time):
    for i in range(rec.costmap.shape[1]):
      grid = _grid(constants.costmap_to_occupancy(rec.costmap[s, i]), rec.costmap_origin[s, i],
                   rec.costmap_resolution[s, i])
      out.append((f"/robot_{i}/local_costmap/costmap", ros.OCCUPANCY_GRID, _ns(t),
                  ros.occupancy_grid_to_msg(grid, stamp=_stamp(t))))
  if summary is not None:
    out.append((SUMMARY_TOPIC, STRING, _ns(rec.end_time), {"data": json.dumps(summary, sort_keys=True)}))
  return out


def write_fleet_bag(path: str | os.PathLike, scenario, rec: FleetRecording, *, max_speed: float,
                    summary: dict | None = None, overwrite: bool = False) -> Path:
  """Writes a fleet run as a rosbag2 folder in MCAP storage (topics: the module docstring).

  Args:
    path: the bag folder (new or empty; with `overwrite`, replaced).
    scenario: sims.fleet.scenario.Scenario of the run (map, masks, speed filter info).
    rec: FleetRecording (`host_recording`).
    max_speed: the robots' maximum speed (m/s), the `/robot_<i>/speed_cap` value where no limit holds.
    summary: the run's summary (JSON-serialisable) for `/fleet/summary`.
    overwrite: replace a bag folder this function wrote earlier (`bag_files`).

  Returns:
    The bag folder: metadata.yaml, the .mcap file and the marker MARKER_NAME
    (the names of the files written), which lets a later `overwrite` prove the
    folder is a bag this function made.

  Raises:
    BagError: the folder cannot be written (see `check_bag_dir`).
    ImportError: rosbags is not installed (pip install 'jaxfilters[ros]').
  """
  path = check_bag_dir(path, overwrite=overwrite)
  messages = fleet_messages(scenario, rec, max_speed=max_speed, summary=summary)
  if path.is_dir():
    if any(path.iterdir()):
      remove_bag(path)
    else:
      os.rmdir(path)
  path.parent.mkdir(parents=True, exist_ok=True)
  latched = (MAP_TOPIC, KEEPOUT_MASK_TOPIC, SPEED_MASK_TOPIC, KEEPOUT_INFO_TOPIC, SPEED_INFO_TOPIC)
  ros.write_bag(path, messages, storage="mcap", latched=latched)
  written = sorted(os.listdir(path))
  (path / MARKER_NAME).write_text("\n".join([MARKER_HEADER, *written]) + "\n", encoding="utf-8")
  return path
