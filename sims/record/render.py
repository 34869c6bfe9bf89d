"""Pictures of a fleet rollout with matplotlib (Agg): a PNG of trajectories and a GIF.

One drawing code for both pictures and for notebooks:

* `draw_scenario(ax, scenario)` draws the static map in metres (free white,
  obstacles dark grey, unknown light grey), the keepout zones and the speed
  zones, each mask placed by ITS OWN origin and resolution (`imshow` with the
  mask's `extent`), and returns the legend handles that name them;
* `fleet_figure(world, pose, speed)` adds the goal stations, the trajectories
  coloured by speed (colour bar outside the map, zone limits marked on it),
  start and end markers, a scale bar, a legend outside the map and a title
  with the scenario and the result;
* `render_png` saves that figure; `animation_frames` / `render_gif` animate
  the same scene (robots as discs to scale with a heading tick and a short
  speed trail).

Nothing here touches `matplotlib.pyplot` or the global backend: figures are
`matplotlib.figure.Figure` objects on an Agg canvas, so a notebook's inline
backend is left alone (call `display(fig)` there, or pass your own `ax` to
`draw_scenario`). Colours: keepout red; speed zones orange, purple, cyan, ...
(in zone order, strictest last); trajectories viridis (dark = slow, yellow = fast), which
contains no red, so a keepout zone never looks like a fast path.
"""

from __future__ import annotations

import io
import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.collections import EllipseCollection, LineCollection
from matplotlib.colors import Normalize, to_rgba
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.markers import MarkerStyle
from matplotlib.patches import Patch
from matplotlib.transforms import Affine2D
from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar
from PIL import Image

from jaxfilters import constants
from jaxfilters.grid import OccupancyGrid
from jaxfilters.keepout import occ_to_cost

FREE_COLOUR = "#ffffff"
OBSTACLE_COLOUR = "#3a3a3a"
UNKNOWN_COLOUR = "#c9c9c9"
KEEPOUT_COLOUR = "#d62728"           # red: absent from the viridis trajectory colours
KEEPOUT_ALPHA = 0.7
ZONE_COLOURS = ("#ff9f1c", "#9467bd", "#17becf", "#8c564b", "#e377c2", "#bcbd22", "#7f7f7f", "#1f77b4")
ZONE_ALPHA = 0.45
SPEED_CMAP = "viridis"
STATION_STYLE = dict(marker="s", s=42, facecolor="white", edgecolor="black", linewidths=1.3)
START_STYLE = dict(marker="o", s=36, facecolor="none", edgecolor="black", linewidths=1.3)
END_COLOUR = "black"


# ----------------------------------------------------------------------------- geometry


def grid_extent(grid: OccupancyGrid) -> tuple[float, float, float, float]:
  """The (left, right, bottom, top) edges in metres of a grid, from its own origin and resolution.

  Args:
    grid: an OccupancyGrid (row 0 is the lowest y).

  Returns:
    (x0, x1, y0, y1) in metres, for `imshow(..., origin="lower", extent=...)`.
  """
  x0, y0 = float(grid.origin[0]), float(grid.origin[1])
  return (x0, x0 + grid.width * grid.resolution, y0, y0 + grid.height * grid.resolution)


def _union(extents) -> tuple[float, float, float, float]:
  e = np.asarray(extents, np.float64)
  return float(e[:, 0].min()), float(e[:, 1].max()), float(e[:, 2].min()), float(e[:, 3].max())


def _nice_length(span: float) -> float:
  """A 1/2/5 x 10^k length close to a fifth of span (metres)."""
  target = span / 5.0
  k = math.floor(math.log10(target))
  return min((m * 10.0 ** k for m in (1, 2, 5, 10)), key=lambda v: abs(v - target))


# ----------------------------------------------------------------------------- zones


def speed_zones(scenario, max_speed: float | None = None) -> list[dict[str, Any]]:
  """The speed zones of a scenario's speed mask, as `sims.fleet.world.build_world` numbers them.

  Args:
    scenario: sims.fleet.scenario.Scenario (its speed mask, type, base and multiplier).
    max_speed: the robots' maximum speed in m/s, to convert percent limits; None
      leaves `limit_mps` unknown (nan) for percent masks.

  Returns:
    One dict per zone 1..Z-1 (zone 0, "no limit", is not drawn), strictest
    last as in `World.zone_labels`: `zone` (int id), `limit` (raw: percent or
    m/s), `limit_mps` (float, nan if unknown), `label` ("50 %" or "0.3 m/s"),
    `cells` (bool [Hs, Ws] on the speed mask's grid).
  """
  from sims.fleet.world import zone_tables   # the numbering the simulator's metrics use

  speed = max_speed if max_speed is not None else float("nan")
  table, _, limits, speeds = zone_tables(scenario, speed)
  zone_of_cell = table[scenario.speed.data.astype(np.uint8)]
  percent = scenario.speed_type == constants.SPEED_FILTER_PERCENT
  zones = []
  for z in range(1, len(limits)):
    label = f"{limits[z]:g} %" if percent else f"{limits[z]:g} m/s"
    zones.append(dict(zone=z, limit=float(limits[z]), limit_mps=float(speeds[z]), label=label,
                      cells=zone_of_cell == z))
  return zones


def zone_colour(index: int) -> str:
  """Colour of the index-th speed zone (0-based over zones 1..Z-1); none of them red.

  Args:
    index: 0 for zone 1, 1 for zone 2, ...

  Returns:
    A matplotlib colour string ("#rrggbb").
  """
  if index < len(ZONE_COLOURS):
    return ZONE_COLOURS[index]
  rgb = colormaps["twilight"]((index * 0.618) % 1.0)    # many zones: spread, never keepout red
  return "#%02x%02x%02x" % tuple(int(255 * c) for c in rgb[:3])


def _cells_image(cells: np.ndarray, colour: str, alpha: float) -> np.ndarray:
  img = np.zeros(cells.shape + (4,), np.float32)
  img[cells] = to_rgba(colour, alpha)
  return img


def draw_scenario(ax: Axes, scenario, *, max_speed: float | None = None,
                  show_map_on_top: bool = True) -> list:
  """Draws a scenario's map, keepout zones and speed zones in metres on `ax`.

  Each mask is drawn on its own grid: `imshow` with the extent from the mask's
  origin and resolution (`grid_extent`), so a mask of another size, origin or
  resolution than the map lands at its world place. Zones are drawn over the
  map's free cells and under its occupied and unknown cells (Nav2's masks also
  cover shelving, which would otherwise take the zone's colour; a robot is
  never there). The axes limits become the union of the map's and the masks'
  extents.

  Args:
    ax: a matplotlib Axes (made equal-aspect, labelled in metres).
    scenario: sims.fleet.scenario.Scenario.
    max_speed: robots' max speed in m/s, to show a percent zone's limit in m/s too.
    show_map_on_top: draw the map's occupied and unknown cells over the zones
      (False: zones cover them, to see a mask's whole shape).

  Returns:
    Legend handles (matplotlib artists with labels) for the map, the keepout
    and each speed zone that has at least one cell.
  """
  grid = scenario.map
  data = grid.data
  base = np.empty(data.shape + (4,), np.float32)
  base[:] = to_rgba(FREE_COLOUR)
  base[data == -1] = to_rgba(UNKNOWN_COLOUR)
  extent = grid_extent(grid)
  ax.imshow(base, origin="lower", extent=extent, interpolation="nearest", zorder=0)
  handles = [Patch(facecolor=OBSTACLE_COLOUR, label="obstacle (map)"),
             Patch(facecolor=UNKNOWN_COLOUR, edgecolor="#999999", label="unknown (map)")]

  zones = speed_zones(scenario, max_speed)
  sext = grid_extent(scenario.speed)
  for i, z in enumerate(zones):
    if not z["cells"].any():
      continue
    colour = zone_colour(i)
    ax.imshow(_cells_image(z["cells"], colour, ZONE_ALPHA), origin="lower", extent=sext,
              interpolation="nearest", zorder=1)
    mps = z["limit_mps"]
    extra = f" ({mps:.2g} m/s)" if scenario.speed_type == constants.SPEED_FILTER_PERCENT and np.isfinite(mps) else ""
    handles.append(Patch(facecolor=to_rgba(colour, ZONE_ALPHA), edgecolor=colour,
                         label=f"speed zone {z['label']}{extra}"))

  cost = np.asarray(occ_to_cost(scenario.keepout.data))
  lethal = (cost >= constants.INSCRIBED_INFLATED_OBSTACLE) & (cost != constants.NO_INFORMATION)
  partial = (cost > 0) & ~lethal & (cost != constants.NO_INFORMATION)
  kext = grid_extent(scenario.keepout)
  if partial.any():
    ax.imshow(_cells_image(partial, KEEPOUT_COLOUR, 0.25), origin="lower", extent=kext,
              interpolation="nearest", zorder=2)
    handles.append(Patch(facecolor=to_rgba(KEEPOUT_COLOUR, 0.25), edgecolor=KEEPOUT_COLOUR,
                         label="keepout mask: extra cost, not lethal"))
  if lethal.any():
    ax.imshow(_cells_image(lethal, KEEPOUT_COLOUR, KEEPOUT_ALPHA), origin="lower", extent=kext,
              interpolation="nearest", zorder=2)
    handles.append(Patch(facecolor=to_rgba(KEEPOUT_COLOUR, KEEPOUT_ALPHA), edgecolor=KEEPOUT_COLOUR,
                         label="keepout zone (no entry)"))

  if show_map_on_top:
    top = _cells_image(data >= 65, OBSTACLE_COLOUR, 1.0)
    top[data == -1] = to_rgba(UNKNOWN_COLOUR)
    ax.imshow(top, origin="lower", extent=extent, interpolation="nearest", zorder=3)
  x0, x1, y0, y1 = _union([extent, sext, kext])
  ax.set_xlim(x0, x1)
  ax.set_ylim(y0, y1)
  ax.set_aspect("equal")
  ax.set_xlabel("x (m)")
  ax.set_ylabel("y (m)")
  return handles


def add_scale_bar(ax: Axes, *, length: float | None = None) -> AnchoredSizeBar:
  """A scale bar just above the map's top-right corner (outside the map).

  Args:
    ax: the map axes (data units metres, equal aspect).
    length: bar length in metres (default: 1, 2 or 5 x 10^k near a fifth of the width).

  Returns:
    The AnchoredSizeBar artist.
  """
  x0, x1 = ax.get_xlim()
  length = _nice_length(abs(x1 - x0)) if length is None else float(length)
  bar = AnchoredSizeBar(ax.transData, length, f"{length:g} m", loc="lower right",
                        bbox_to_anchor=(1.0, 1.0), bbox_transform=ax.transAxes, borderpad=0.1,
                        pad=0.1, sep=3, frameon=False, size_vertical=0, label_top=True)
  ax.add_artist(bar)
  return bar


# ----------------------------------------------------------------------------- fleet figure


def _check_rollout(pose, speed) -> tuple[np.ndarray, np.ndarray]:
  pose = np.asarray(pose, np.float64)
  speed = np.asarray(speed, np.float64)
  if pose.ndim != 3 or pose.shape[2] != 3 or pose.shape[0] < 1 or pose.shape[1] < 1:
    raise ValueError(f"pose must be float [T, B, 3] (x, y, yaw) with T, B >= 1; got shape {pose.shape}")
  if speed.shape != pose.shape[:2]:
    raise ValueError(f"speed must be float [T, B] = {pose.shape[:2]} to match pose; got shape {speed.shape}")
  for name, a in (("pose", pose), ("speed", speed)):
    bad = ~np.isfinite(a)
    if bad.any():
      raise ValueError(f"{name} has {int(bad.sum())} non-finite values (a broken rollout); "
                       "every recorded value must be finite to be drawn")
  return pose, speed


def _result_line(summary: dict | None) -> str:
  if summary is None:
    return "result: not given"
  f = summary["fleet"] if "fleet" in summary else summary
  speed_ok = "PASS" if f["speed_compliant"] else "FAIL"
  keep_ok = f["keepout_entries"] == 0 and f.get("keepout_steps", 0) == 0
  if f.get("footprint_entries") is not None:
    keep_ok = bool(f["keepout_ok"])
    keep = (f"footprint entries {f['footprint_entries']}, escaped {f['robots_escaped']}/"
            f"{f['robots_started_in_keepout']}")
  else:
    keep = f"keepout entries {f['keepout_entries']}"
  return (f"speed compliance {speed_ok}  |  {keep} "
          f"({'PASS' if keep_ok else 'FAIL'})  |  goals reached {f['goals_reached']}")


def _figure_size(extent, width_in: float) -> tuple[float, float]:
  """Figure (width, height) in inches: the width is kept (the legend needs it), the map at most 9 in tall."""
  ratio = (extent[3] - extent[2]) / (extent[1] - extent[0])
  map_h = min((width_in - 1.9) * ratio, 9.0)  # 1.9 in: y labels on the left, colour bar on the right
  return (width_in, map_h + 2.4)              # 2.4 in: two title lines above, the legend below


def _scene(world, pose: np.ndarray, speed: np.ndarray, *, summary: dict | None, width_in: float,
           dpi: float, robot_handles: Sequence, title_extra: str = "") -> tuple[Figure, Axes, Normalize]:
  """The static part shared by the PNG and every GIF frame."""
  sc = world.scenario
  max_speed = float(world.config.robot.max_speed)
  extents = [grid_extent(g) for g in (sc.map, sc.keepout, sc.speed)]
  fig = Figure(figsize=_figure_size(_union(extents), width_in), dpi=dpi, layout="constrained")
  FigureCanvasAgg(fig)
  ax = fig.add_subplot()
  handles = draw_scenario(ax, sc, max_speed=max_speed)
  st = np.asarray(world.stations)
  ax.scatter(st[:, 0], st[:, 1], zorder=5, **STATION_STYLE)
  handles.append(Line2D([], [], linestyle="none", markersize=7, marker=STATION_STYLE["marker"],
                        markerfacecolor="white", markeredgecolor="black",
                        label=f"goal station ({len(st)})"))
  handles.extend(robot_handles)
  add_scale_bar(ax)

  top = float(speed.max())
  norm = Normalize(0.0, max_speed)
  cbar = fig.colorbar(ScalarMappable(norm, SPEED_CMAP), ax=ax, location="right", shrink=0.9,
                      pad=0.02, fraction=0.04, extend="max" if top > max_speed else "neither")
  cbar.set_label("robot speed (m/s)")
  zones = speed_zones(sc, max_speed)
  for i, z in enumerate(zones):
    if np.isfinite(z["limit_mps"]) and z["limit_mps"] <= max_speed:
      cbar.ax.axhline(z["limit_mps"], color=zone_colour(i), linewidth=3)
      cbar.ax.axhline(z["limit_mps"], color="black", linewidth=0.6)
  if zones:
    handles.append(Line2D([], [], color=zone_colour(0), linewidth=3,
                          label="zone limit (on the colour bar)"))

  b = pose.shape[1]
  seconds = pose.shape[0] * float(world.config.step_seconds)
  fleet = None if summary is None else summary.get("fleet", summary)
  total = b if fleet is None else int(fleet["robots"])
  robots = f"{total} robot{'s' if total != 1 else ''}" + ("" if total == b else f" ({b} drawn)")
  fig.suptitle(f"{sc.name}: {robots}, {seconds:g} s simulated{title_extra}\n"
               f"{_result_line(summary)}", fontsize=11)
  renderer = fig.canvas.get_renderer()
  for ncols in range(min(4, len(handles)), 0, -1):      # as many columns as fit the figure's width
    legend = fig.legend(handles=handles, loc="outside lower center", ncols=ncols, fontsize=8,
                        frameon=False)
    if ncols == 1 or legend.get_window_extent(renderer).width <= 0.98 * fig.bbox.width:
      break
    legend.remove()
  return fig, ax, norm


def _segments(pose: np.ndarray) -> np.ndarray:
  """float [B * (T - 1), 2, 2] segments of every robot's path (robot-major)."""
  xy = np.transpose(pose[:, :, :2], (1, 0, 2))             # [B, T, 2]
  return np.stack([xy[:, :-1], xy[:, 1:]], axis=2).reshape(-1, 2, 2)


def fleet_figure(world, pose: np.ndarray, speed: np.ndarray, *, summary: dict | None = None,
                 width_in: float = 9.0, dpi: float = 110.0) -> Figure:
  """The whole rollout on one map: trajectories coloured by speed, stations, start and end.

  Args:
    world: sims.fleet.world.World (its scenario masks, stations and robot config).
    pose: float [T, B, 3] recorded poses (x m, y m, yaw rad), T env steps of
      `world.config.step_seconds`.
    speed: float [T, B] linear speed (m/s).
    summary: `sims.fleet.metrics.summarize` output (or its "fleet" dict) for the
      title's result line; None writes "result: not given".
    width_in, dpi: figure width in inches and resolution.

  Returns:
    A matplotlib Figure on an Agg canvas; `fig.axes[0]` is the map axes (data
    units metres), `fig.axes[1]` the colour bar.

  Raises:
    ValueError: pose or speed of the wrong shape, or non-finite values.
  """
  pose, speed = _check_rollout(pose, speed)
  robot_handles = [
      Line2D([], [], linestyle="none", marker="o", markersize=6, markerfacecolor="none",
             markeredgecolor="black", label="robot start"),
      Line2D([], [], linestyle="none", marker=">", markersize=7, color=END_COLOUR,
             label="robot end (points along heading)"),
      Line2D([], [], color=colormaps[SPEED_CMAP](0.75), linewidth=2, label="trajectory (colour = speed)"),
  ]
  fig, ax, norm = _scene(world, pose, speed, summary=summary, width_in=width_in, dpi=dpi,
                         robot_handles=robot_handles)
  b = pose.shape[1]
  if pose.shape[0] > 1:
    seg_speed = 0.5 * (speed[:-1] + speed[1:]).T.reshape(-1)
    lines = LineCollection(_segments(pose), cmap=SPEED_CMAP, norm=norm, linewidths=1.6 if b <= 16 else 1.0,
                           zorder=4, capstyle="round")
    lines.set_array(seg_speed)
    ax.add_collection(lines)
  ax.scatter(pose[0, :, 0], pose[0, :, 1], zorder=6, **START_STYLE)
  for i in range(b):
    ax.scatter(pose[-1, i, 0], pose[-1, i, 1], s=55, color=END_COLOUR, edgecolors="white", linewidths=0.6,
               marker=MarkerStyle(">", transform=Affine2D().rotate(float(pose[-1, i, 2]))), zorder=7)
  return fig


def _save_png(fig: Figure, path: Path) -> Path:
  """PNG through a 256-colour palette (the figure has far fewer distinct colours)."""
  buf = io.BytesIO()
  fig.savefig(buf, format="png")
  buf.seek(0)
  with Image.open(buf) as im:
    im.convert("RGB").quantize(256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(
        path, optimize=True)
  return path


def render_png(world, pose: np.ndarray, speed: np.ndarray, path, *, summary: dict | None = None,
               width_in: float = 9.0, dpi: float = 110.0) -> Path:
  """Writes `fleet_figure` as a PNG (about 1000 px wide, under 200 kB).

  Args:
    world: sims.fleet.world.World.
    pose: float [T, B, 3] recorded poses (m, m, rad); speed: float [T, B] (m/s).
    path: output PNG path.
    summary: `sims.fleet.metrics.summarize` output for the title (PASS/FAIL, keepout entries).
    width_in, dpi: figure width (inches) and resolution.

  Returns:
    The written path.

  Raises:
    ValueError: see `fleet_figure`.
  """
  return _save_png(fleet_figure(world, pose, speed, summary=summary, width_in=width_in, dpi=dpi), Path(path))


def animation_frames(world, pose: np.ndarray, speed: np.ndarray, *, summary: dict | None = None,
                     max_frames: int = 150, seconds_per_frame: float = 0.2, trail: int = 25,
                     playback_speed: float = 2.0, width_in: float = 7.0,
                     dpi: float = 80.0) -> tuple[Figure, list[np.ndarray], int]:
  """The GIF's frames: the PNG's scene with robots to scale and speed trails, one per kept step.

  Each frame draws every robot as a disc of its true radius filled with its
  current speed colour, a tick along its heading, and the last `trail`
  recorded steps of its path, over the scene `fleet_figure` draws (map, zones,
  stations, colour bar, legend, title). The scene is drawn once; frames blit
  the moving artists over it.

  Args:
    world: sims.fleet.world.World.
    pose: float [T, B, 3] recorded poses (m, m, rad); speed: float [T, B] (m/s).
    summary: `sims.fleet.metrics.summarize` output for the title.
    max_frames: at most this many frames (recorded steps are subsampled evenly).
    seconds_per_frame: simulated seconds between recorded poses.
    trail: recorded steps of trail behind each robot.
    playback_speed: simulated seconds per second of animation (shown in the title).
    width_in, dpi: frame size.

  Returns:
    (figure, frames, stride): the Figure holding the last frame (`fig.axes[0]`
    is the map axes), uint8 [H, W, 3] frames, and the recorded steps per frame.

  Raises:
    ValueError: see `fleet_figure`, or max_frames < 1, seconds_per_frame or
      playback_speed not > 0, trail < 0.
  """
  pose, speed = _check_rollout(pose, speed)
  if max_frames < 1 or not seconds_per_frame > 0 or not playback_speed > 0 or trail < 0:
    raise ValueError(f"need max_frames >= 1, seconds_per_frame > 0, playback_speed > 0, trail >= 0; got "
                     f"{max_frames}, {seconds_per_frame}, {playback_speed}, {trail}")
  radius = float(world.config.robot.radius)
  robot_handles = [Line2D([], [], linestyle="none", marker="o", markersize=8,
                          markerfacecolor=colormaps[SPEED_CMAP](0.6), markeredgecolor="black",
                          label="robot, to scale (fill = speed, tick = heading)"),
                   Line2D([], [], color=colormaps[SPEED_CMAP](0.75), linewidth=2,
                          label=f"last {trail * seconds_per_frame:g} s of path")]
  fig, ax, norm = _scene(world, pose, speed, summary=summary, width_in=width_in, dpi=dpi,
                         robot_handles=robot_handles, title_extra=f" ({playback_speed:g}x speed)")
  cmap = colormaps[SPEED_CMAP]
  t, b = pose.shape[:2]
  trails = LineCollection([], cmap=SPEED_CMAP, norm=norm, linewidths=1.5, zorder=4, animated=True)
  discs = EllipseCollection(np.full(b, 2 * radius), np.full(b, 2 * radius), np.zeros(b), units="xy",
                            offsets=pose[0, :, :2], offset_transform=ax.transData, edgecolors="black",
                            linewidths=0.8, zorder=6, animated=True)
  ticks = LineCollection([], colors="black", linewidths=1.2, zorder=7, animated=True)
  clock = ax.text(0.01, 0.99, "", transform=ax.transAxes, ha="left", va="top", fontsize=9, zorder=8,
                  bbox=dict(facecolor="white", edgecolor="none", alpha=0.85, pad=2), animated=True)
  for a in (trails, discs, ticks):
    ax.add_collection(a)
  canvas = fig.canvas
  canvas.draw()
  background = canvas.copy_from_bbox(fig.bbox)
  stride = max(1, math.ceil(t / max_frames))
  frames = []
  for s in range(0, t, stride):
    lo = max(0, s - trail)
    if s > lo:
      trails.set_segments(_segments(pose[lo:s + 1]))
      trails.set_array(0.5 * (speed[lo:s] + speed[lo + 1:s + 1]).T.reshape(-1))
    else:
      trails.set_segments([])
    xy = pose[s, :, :2]
    discs.set_offsets(xy)
    discs.set_facecolor(cmap(norm(speed[s])))
    head = xy + radius * np.stack([np.cos(pose[s, :, 2]), np.sin(pose[s, :, 2])], axis=1)
    ticks.set_segments(np.stack([xy, head], axis=1))
    clock.set_text(f"t = {s * seconds_per_frame:.1f} s")
    canvas.restore_region(background)
    for a in (trails, discs, ticks, clock):
      ax.draw_artist(a)
    frames.append(np.asarray(canvas.buffer_rgba())[..., :3].copy())
  return fig, frames, stride


def render_gif(world, pose: np.ndarray, speed: np.ndarray, path, *, summary: dict | None = None,
               max_frames: int = 150, seconds_per_frame: float = 0.2, trail: int = 25,
               playback_speed: float = 2.0, width_in: float = 7.0, dpi: float = 80.0) -> Path:
  """Writes `animation_frames` as a looping GIF on one shared 256-colour palette.

  One palette for every frame (built from the first and last frames and the
  whole speed colour map), so the static scene does not flicker.

  Args:
    world: sims.fleet.world.World.
    pose: float [T, B, 3] recorded poses; speed: float [T, B] (m/s).
    path: output GIF path.
    summary, max_frames, seconds_per_frame, trail, playback_speed, width_in,
      dpi: see `animation_frames`; a frame lasts
      seconds_per_frame * stride / playback_speed seconds (at least 20 ms).

  Returns:
    The written path.

  Raises:
    ValueError: see `animation_frames`.
  """
  _, frames, stride = animation_frames(world, pose, speed, summary=summary, max_frames=max_frames,
                                       seconds_per_frame=seconds_per_frame, trail=trail,
                                       playback_speed=playback_speed, width_in=width_in, dpi=dpi)
  images = [Image.fromarray(f) for f in frames]
  cmap = colormaps[SPEED_CMAP]
  h, w = frames[0].shape[:2]
  strip = (np.asarray(cmap(np.linspace(0, 1, 64)))[None, :, :3] * 255).astype(np.uint8).repeat(8, 0)
  sample = Image.new("RGB", (w, 2 * h + 8))
  sample.paste(images[0], (0, 0))
  sample.paste(images[-1], (0, h))
  sample.paste(Image.fromarray(strip).resize((w, 8)), (0, 2 * h))
  palette = sample.quantize(256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
  out = [im.quantize(palette=palette, dither=Image.Dither.NONE) for im in images]
  path = Path(path)
  out[0].save(path, save_all=True, append_images=out[1:], optimize=False, loop=0,
              duration=max(20, int(round(1000 * seconds_per_frame * stride / playback_speed))))
  return path
