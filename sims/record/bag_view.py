"""A picture of a fleet bag (sims/record/bag.py) as a viewer would show it: the map, masks and robots, one
robot's local costmap, and its commanded speed against the limit in force.

It reads the bag back through its messages only (`jaxfilters.ros.read_bag`), so what it draws is
what the bag holds: the map and masks from `/map` and the mask topics, the speed filter's
type/base/multiplier from `/speed_costmap_filter_info`, the robots from `/tf`, the commands from
`/robot_<i>/cmd_vel`, the limit from `/robot_<i>/speed_cap`. The map panel uses the drawing code
of the fleet pictures (`sims.record.render.draw_scenario`).
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

import numpy as np
import yaml
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from jaxfilters import ros
from sims.record import render
from sims.record.bag import KEEPOUT_MASK_TOPIC, MAP_TOPIC, SPEED_INFO_TOPIC, SPEED_MASK_TOPIC
from sims.fleet.scenario import Scenario

__all__ = ["MAX_METADATA_BYTES", "bag_figure", "check_bag_files", "render_bag_png"]

MAX_METADATA_BYTES = 2 ** 20


def _regular_file(path: str, what: str) -> os.stat_result:
  """os.stat of a regular file (following links), or ValueError: a FIFO, device or folder is never opened."""
  try:
    st = os.stat(path)
  except FileNotFoundError:
    raise FileNotFoundError(f"{what} {path} does not exist") from None
  except OSError as e:
    raise ValueError(f"{what} {path}: cannot read it ({e.strerror or e})") from None
  if not stat.S_ISREG(st.st_mode):
    raise ValueError(f"{what} {path} is not a regular file (a FIFO, device or folder is refused)")
  return st


def check_bag_files(path) -> None:
  """Checks a rosbag2 folder's files before any is opened, so that reading it cannot block or flood.

  metadata.yaml must be a regular file of at most MAX_METADATA_BYTES holding
  valid YAML with `rosbag2_bagfile_information.relative_file_paths`, and every
  file it names, and every .mcap/.db3 file in the folder, a regular file.

  Raises:
    FileNotFoundError: no such folder, no metadata.yaml, or a named file missing.
    ValueError: anything else wrong (one line naming the file).
  """
  path = os.fspath(path)
  if not os.path.isdir(path):
    raise FileNotFoundError(f"rosbag2 folder {path} does not exist" if not os.path.exists(path) else
                            f"{path} is not a folder (a rosbag2 bag is a folder)")
  meta = os.path.join(path, "metadata.yaml")
  st = _regular_file(meta, "rosbag2 metadata")
  if st.st_size > MAX_METADATA_BYTES:
    raise ValueError(f"{meta} is {st.st_size} bytes; a bag's metadata.yaml is at most {MAX_METADATA_BYTES}")
  with open(meta, "rb") as f:        # a regular file (checked): reading cannot block
    raw = f.read(MAX_METADATA_BYTES + 1)
  try:
    doc = yaml.safe_load(raw.decode("utf-8"))
  except UnicodeDecodeError as e:
    raise ValueError(f"{meta} is not UTF-8 text (byte {e.start})") from None
  except yaml.YAMLError as e:
    mark = getattr(e, "problem_mark", None)
    where = "" if mark is None else f" at line {mark.line + 1}, column {mark.column + 1}"
    problem = str(getattr(e, "problem", None) or type(e).__name__).replace("\n", " ")
    raise ValueError(f"{meta} is not valid YAML{where}: {problem}") from None
  info = doc.get("rosbag2_bagfile_information") if isinstance(doc, dict) else None
  files = info.get("relative_file_paths") if isinstance(info, dict) else None
  if not isinstance(files, list) or not all(isinstance(n, str) and n for n in files):
    raise ValueError(f"{meta} is not rosbag2 metadata: it needs rosbag2_bagfile_information."
                     "relative_file_paths, a list of file names")
  names = set(files) | {n for n in os.listdir(path) if n.endswith((".mcap", ".db3"))}
  for name in sorted(names):
    _regular_file(os.path.join(path, name), "bag file")


def _by_topic(path) -> dict[str, list]:
  out: dict[str, list] = {}
  for m in ros.read_bag(path):
    out.setdefault(m.topic, []).append(m)
  return out


def _scenario(msgs: dict) -> Scenario:
  for topic in (MAP_TOPIC, KEEPOUT_MASK_TOPIC, SPEED_MASK_TOPIC, SPEED_INFO_TOPIC):
    if topic not in msgs:
      raise ValueError(f"the bag has no {topic} topic: not a fleet bag (sims/record/bag.py)")
  info, _ = ros.filter_info_from_msg(msgs[SPEED_INFO_TOPIC][0].msg)
  return Scenario(name="bag", map=ros.occupancy_grid_from_msg(msgs[MAP_TOPIC][0].msg),
                  keepout=ros.occupancy_grid_from_msg(msgs[KEEPOUT_MASK_TOPIC][0].msg),
                  speed=ros.occupancy_grid_from_msg(msgs[SPEED_MASK_TOPIC][0].msg),
                  speed_type=int(np.asarray(info.type)), speed_base=float(np.asarray(info.base)),
                  speed_multiplier=float(np.asarray(info.multiplier)))


def _tracks(msgs: dict) -> tuple[np.ndarray, np.ndarray]:
  """(time [T] s, xy [T, R, 2]) from /tf."""
  times, xy = [], []
  for m in msgs.get("/tf", []):
    times.append(m.timestamp * 1e-9)
    xy.append([(t["transform"]["translation"]["x"], t["transform"]["translation"]["y"])
               for t in m.msg["transforms"]])
  return np.asarray(times), np.asarray(xy, np.float64).reshape(len(times), -1, 2)


def _series(msgs: dict, topic: str, value) -> tuple[np.ndarray, np.ndarray]:
  ms = msgs.get(topic, [])
  return np.array([m.timestamp * 1e-9 for m in ms]), np.array([value(m.msg) for m in ms], np.float64)


def _busiest_robot(msgs: dict, robots: int) -> int:
  """The robot whose speed limit changed most often, preferring robots with local costmaps."""
  with_costmaps = [i for i in range(robots) if f"/robot_{i}/local_costmap/costmap" in msgs]
  pool = with_costmaps or list(range(robots))
  changes = [len(msgs.get(f"/robot_{i}/speed_limit", [])) for i in pool]
  return pool[int(np.argmax(changes))]


def bag_figure(path, *, robot: int | None = None, width_in: float = 13.0, dpi: float = 100.0) -> Figure:
  """The bag as a three-panel figure (see the module docstring).

  Args:
    path: a rosbag2 folder written by `sims.record.bag.write_fleet_bag`.
    robot: which robot's local costmap and speed to show (None: the robot whose
      limit changed most often, among those with local costmaps if any).
    width_in, dpi: figure size.

  Returns:
    A matplotlib Figure on an Agg canvas.

  Raises:
    FileNotFoundError: no such folder or file (`check_bag_files`).
    ValueError: a file that is not a regular file or malformed metadata.yaml
      (`check_bag_files`), not a fleet bag, or no such robot in it.
  """
  check_bag_files(path)
  msgs = _by_topic(path)
  scenario = _scenario(msgs)
  t, xy = _tracks(msgs)
  if robot is None:
    robot = _busiest_robot(msgs, xy.shape[1])
  if not 0 <= robot < xy.shape[1]:
    raise ValueError(f"robot {robot} is not in the bag ({xy.shape[1]} robots recorded)")
  fig = Figure(figsize=(width_in, width_in * 0.42), dpi=dpi)
  FigureCanvasAgg(fig)
  grid = fig.add_gridspec(2, 3, width_ratios=(1.5, 0.8, 1.4), height_ratios=(1, 1))
  ax_map = fig.add_subplot(grid[:, 0])
  handles = render.draw_scenario(ax_map, scenario)
  colours = colormaps["tab10"]
  for i in range(xy.shape[1]):
    ax_map.plot(xy[:, i, 0], xy[:, i, 1], lw=1.0, color=colours(i % 10), zorder=4)
    ax_map.plot(*xy[-1, i], "o", ms=4, color=colours(i % 10), zorder=5)
  ax_map.annotate(f"robot_{robot}", xy[-1, robot], xytext=(6, 6), textcoords="offset points", fontsize=8,
                  color=colours(robot % 10), fontweight="bold", zorder=6)
  ax_map.set_title(f"/map, masks and /tf ({xy.shape[1]} robots, {t[-1]:.0f} s)", fontsize=10)
  ax_map.legend(handles=handles, fontsize=6, loc="lower left", framealpha=0.9)

  ax_cost = fig.add_subplot(grid[:, 1])
  costmaps = msgs.get(f"/robot_{robot}/local_costmap/costmap", [])
  if costmaps:
    # The update with the most non-free cells: the moment the costmap has the most to show.
    m = max(costmaps, key=lambda c: int(np.count_nonzero(np.asarray(c.msg["data"]) > 0)))
    local = ros.occupancy_grid_from_msg(m.msg)
    ext = render.grid_extent(local)
    ax_cost.set_facecolor("#cfe3f5")     # unknown cells (-1) are left transparent
    ax_cost.imshow(np.ma.masked_less(local.data, 0), origin="lower", extent=ext, cmap="Greys",
                   vmin=0, vmax=100, interpolation="nearest")
    k = int(np.searchsorted(t, m.timestamp * 1e-9))
    ax_cost.plot(*xy[min(k, len(t) - 1), robot], "o", ms=6, mfc="none", mec="tab:blue")
    ax_cost.set_title(f"/robot_{robot}/local_costmap/costmap\n(t = {m.timestamp * 1e-9:.1f} s; "
                      "white free, black lethal)", fontsize=9)
    ax_cost.set_xlabel("x (m)")
    ax_cost.set_aspect("equal")
  else:
    ax_cost.set_axis_off()
    ax_cost.text(0.5, 0.5, "no local costmaps\nrecorded", ha="center", va="center")

  ax_v = fig.add_subplot(grid[0, 2])
  tv, v = _series(msgs, f"/robot_{robot}/cmd_vel", lambda m: m["linear"]["x"])
  tc, cap = _series(msgs, f"/robot_{robot}/speed_cap", lambda m: m["data"])
  ax_v.plot(tv, v, lw=1.0, label=f"/robot_{robot}/cmd_vel linear.x (m/s)")
  ax_v.step(tc, cap, where="post", lw=1.4, color="tab:red", label=f"/robot_{robot}/speed_cap (m/s)")
  ax_v.set_ylabel("m/s")
  ax_v.legend(fontsize=7, loc="lower right")
  ax_v.set_title("commanded speed against the limit in force", fontsize=10)
  ax_l = fig.add_subplot(grid[1, 2], sharex=ax_v)
  tl, lim = _series(msgs, f"/robot_{robot}/speed_limit", lambda m: m["speed_limit"])
  percent = scenario.speed_type == 1
  ax_l.step(np.append(tl, t[-1]), np.append(lim, lim[-1]) if len(lim) else [], where="post",
            color="tab:purple", label=f"/robot_{robot}/speed_limit ({'%' if percent else 'm/s'}, 0 = none)")
  ax_l.plot(tl, lim, "o", ms=3, color="tab:purple")
  ax_l.set_xlabel("simulated time (s)")
  ax_l.legend(fontsize=7, loc="upper right")
  fig.tight_layout()
  return fig


def render_bag_png(path, out, *, robot: int | None = None) -> Path:
  """Writes `bag_figure(path, robot=robot)` as a PNG at `out` and returns its path."""
  out = Path(out)
  fig = bag_figure(path, robot=robot)
  fig.savefig(out, format="png")
  return out
