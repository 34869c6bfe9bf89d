"""JAUS CostMap2D reports <-> OccupancyGrid: cell values, geometry and tiling. Host only.

Cell values and occupancy: `mapping` as in `jaxfilters.jaus.costs`.
Variant values from Nav2 costs (docs/jaus.md §11 (6)-(7)): the cost list
carries them unchanged; the cost and confidence list carries known cells with
confidence 100 % and unknown cells with confidence 0 (cost 0 in "iop", where
255 is not allowed; 255 in "design"); the run-length list keeps 3 bits
(`cost_to_rle_level`) and the certainty bit, so it is lossy: encoding a grid
whose costs are not all among `RLE_LEVEL_COST` needs `lossy=True`, and a
decoded run-length report says `quantised`.

Geometry (`axes`, docs/jaus.md §11 (9)-(10)): the wire lists cells from the
north-west (top-left) corner, row by row west to east, so grid row 0 (lowest
y) is the last wire row. The map centre and rotation come from the grid's
origin (x, y, yaw) rotated as nav_msgs defines it. With axes="ros" (default,
what the fkie bridge does) MapCenterX/Y are the centre's x/y and MapRotation
is the yaw; with axes="ned" (docs/jaus.md §6: the JAUS local frame as
north-east-down with an ENU map) MapCenterX = y, MapCenterY = x and
MapRotation = -yaw.

A map larger than one message goes out as tiles (`grid_to_reports`), each a
complete report with its own centre, and `reports_to_grid` puts tiles back
together (docs/jaus.md §12).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import NamedTuple

import numpy as np

from jaxfilters import constants
from jaxfilters.grid import OccupancyGrid
from jaxfilters.jaus.costs import (MAPPINGS, cost_to_occupancy, cost_to_rle_level,
                                   occupancy_to_cost)
from jaxfilters.jaus.messages import (CENTER_X, RLE_LEVEL_COST, ROTATION, CostMap2DReport,
                                      GlobalPose, JausProfile, LocalPose, check_choice,
                                      check_report, get_profile, limit_problem, rle_runs,
                                      size_field)
from jaxfilters.map_decode import MAX_MAP_CELLS
from jaxfilters.validate import float32_values, int_values, resolution_value, short_repr

# Report axes conventions (module docstring).
AXES = ("ros", "ned")


# --------------------------------------------------------------------------- grids


class JausTile(NamedTuple):
  """One message of a tiled map: `window` (col, row, width, height) in grid cells."""
  window: tuple[int, int, int, int]
  report: CostMap2DReport


def _rot(yaw: float, x: float, y: float) -> tuple[float, float]:
  c, s = math.cos(yaw), math.sin(yaw)
  return c * x - s * y, s * x + c * y


def _grid_geometry(grid: OccupancyGrid, owner: str) -> tuple[float, tuple[float, float, float]]:
  if not isinstance(grid, OccupancyGrid):
    raise TypeError(f"{owner} expects an OccupancyGrid (see jaxfilters.load_map); got "
                    f"{type(grid).__name__}")
  resolution_value(grid.resolution, owner=owner)
  origin = tuple(float(v) for v in grid.origin)
  if len(origin) != 3:
    raise ValueError(f"{owner}: grid origin must be (x, y, yaw); got {grid.origin!r}")
  float32_values(origin, "origin", owner=owner)
  return float(grid.resolution), origin


def _check_window(grid: OccupancyGrid, window) -> tuple[int, int, int, int]:
  if window is None:
    return 0, 0, grid.width, grid.height
  w = np.asarray(window)
  if w.shape != (4,):
    raise ValueError(f"window must be (col, row, width, height); got {short_repr(window)}")
  if w.dtype == bool or not np.issubdtype(w.dtype, np.integer):
    raise ValueError(f"window (col, row, width, height) must be integers; got {short_repr(window)}")
  col, row, width, height = (int(v) for v in w)
  if col < 0 or row < 0:
    raise ValueError(f"window col and row must be >= 0 (cells of the grid); got col {col}, "
                     f"row {row}")
  if width < 1 or height < 1:
    raise ValueError(f"window width and height must be >= 1 cell; got {width} x {height}")
  if col + width > grid.width or row + height > grid.height:
    raise ValueError(f"window (col {col}, row {row}, width {width}, height {height}) must lie "
                     f"inside the {grid.width} x {grid.height} (width x height) grid")
  return col, row, width, height


def _variant_arrays(cost: np.ndarray, variant: str, prof: JausProfile, confidence):
  """Nav2 costs (wire order) -> (values, confidence, known) of a variant."""
  unknown = cost == constants.NO_INFORMATION
  if variant == "list":
    return cost, None, None
  if variant == "confidence":
    if confidence is None:
      conf = np.where(unknown, 0.0, 100.0)
    else:
      conf = np.where(unknown, 0.0, confidence)
    fill = constants.NO_INFORMATION if prof.unknown_in_confidence_list else 0
    return np.where(unknown, np.uint8(fill), cost), conf, None
  if variant == "rle":
    level = cost_to_rle_level(np.where(unknown, 0, cost))
    return np.where(unknown, np.uint8(0), level), None, ~unknown
  raise NotImplementedError("encoding CostOrAttractivenessList is refused: no public text defines "
                            "its values (sign convention, reserved values)")


def _check_size_recoverable(prof: JausProfile, res: float, map_w: float, map_h: float,
                            rows: int, cols: int) -> None:
  """Refuses sizes from which `report_to_grid` could not derive the cell size.

  A MapWidth and MapHeight below half a step of the profile's size integer go
  out as 0 m (an "iop" 1 x 1 map of 0.05 m cells: one step is 0.153 m), and
  the receiver cannot tell the cell size; the decoder would refuse the message.
  """
  size = size_field(prof, "MapWidth")
  w_dec = size.decode(size.encode(map_w, "grid_to_reports"))
  h_dec = size.decode(size.encode(map_h, "grid_to_reports"))
  lo, hi = resolution_interval(prof, w_dec, h_dec, rows, cols)
  if lo <= 0.0 or not lo * (1 - 1e-12) <= res <= hi * (1 + 1e-12):
    need = math.ceil(size.step / 2 / res)
    raise ValueError(
        f"a map of {cols} x {rows} cells (width x height) of {res:g} m is {map_w:g} m x "
        f"{map_h:g} m, which profile {prof.name!r} sends as {w_dec:.6g} m x {h_dec:.6g} m "
        f"(its {prof.size_bits}-bit MapWidth/MapHeight step is {size.step:.4g} m): the receiver "
        f"could not tell the cell size; use profile 'design' (steps of "
        f"{size_field(get_profile('design'), 'MapWidth').step:.2g} m) or a window at least "
        f"{need} cells wide or high")


def _check_resolution_recovered(prof: JausProfile, res: float,
                                reports: list[CostMap2DReport]) -> None:
  """Refuses reports from which the decoder's snapped resolution is not `res`.

  The decoder (`reports_to_grid`, `report_to_grid` for one report) takes the
  shortest decimal inside every report's interval of cell sizes; it must equal
  the grid's resolution to float32 precision (the filters compute in float32).
  """
  size = size_field(prof, "MapWidth")
  bounds = []
  for r in reports:
    w = size.decode(size.encode(r.map_width, "grid_to_reports"))
    h = size.decode(size.encode(r.map_height, "grid_to_reports"))
    bounds.append(resolution_interval(prof, w, h, r.rows, r.cols))
  lo, hi = max(b[0] for b in bounds), min(b[1] for b in bounds)
  got = _simplest(lo, hi, (lo + hi) / 2, positive=True) if 0.0 < lo <= hi else None
  if got is not None and abs(got - res) <= res * 2.0 ** -20:
    return
  cells = max(r.cols for r in reports), max(r.rows for r in reports)
  raise ValueError(
      f"the receiver would read the cell size of this {cells[0]} x {cells[1]} cell map (width x "
      f"height) as {got if got is not None else 'unknown'} m, not {res:g} m: profile "
      f"{prof.name!r} sends MapWidth/MapHeight in {size.step:.4g} m steps; use profile 'design' "
      f"({size_field(get_profile('design'), 'MapWidth').step:.2g} m steps), a larger window, or "
      "check_resolution=False if the receiver is given the resolution")


def _check_rle_exact(grid: OccupancyGrid, win, mapping: str) -> None:
  """Refuses a grid whose costs the run-length list would change (lossy=False)."""
  col, row, width, height = win
  cost = occupancy_to_cost(grid.data[row:row + height, col:col + width], mapping=mapping)
  bad = (cost != constants.NO_INFORMATION) & ~np.isin(cost, RLE_LEVEL_COST)
  if not bad.any():
    return
  r, c = (int(v) for v in np.argwhere(bad)[0])
  occ = grid.data[row:row + height, col:col + width]
  pairs = sorted({(int(o), int(k)) for o, k in zip(occ[bad][:4096], cost[bad][:4096])})
  shown = ", ".join(f"{o} (cost {k} -> {int(RLE_LEVEL_COST[cost_to_rle_level(k)])})"
                    for o, k in pairs[:6]) + (", ..." if len(pairs) > 6 else "")
  raise ValueError(
      f"the run-length variant keeps 3 bits of cost (costs {RLE_LEVEL_COST.tolist()}), and "
      f"{int(bad.sum())} cells of this map have other values, first at cell (col {col + c}, "
      f"row {row + r}); occupancy {shown}; pass lossy=True (CLI: --lossy) to quantise them, or "
      "use variant 'list' or 'confidence' (lossless)")


def _window_report(grid, window, res, origin, prof, variant, mapping, axes, pose, confidence):
  col, row, width, height = window
  occ = grid.data[row:row + height, col:col + width]
  cost = occupancy_to_cost(occ, mapping=mapping)[::-1]
  conf = None if confidence is None else confidence[row:row + height, col:col + width][::-1]
  values, conf, known = _variant_arrays(cost, variant, prof, conf)
  map_w, map_h = width * res, height * res
  _check_size_recoverable(prof, res, map_w, map_h, height, width)
  if pose is None:
    yaw = origin[2]
    dx, dy = _rot(yaw, (col + width / 2) * res, (row + height / 2) * res)
    cx, cy = origin[0] + dx, origin[1] + dy
    if axes == "ros":
      pose = LocalPose(cx, cy, math.remainder(yaw, 2 * math.pi))
    else:
      pose = LocalPose(cy, cx, math.remainder(-yaw, 2 * math.pi))
  return CostMap2DReport.create(values, map_width=map_w, map_height=map_h, pose=pose,
                                profile=prof.name, variant=variant, confidence=conf, known=known)


def grid_to_reports(grid: OccupancyGrid, *, window=None, profile: str = "iop",
                    variant: str = "list", mapping: str = "nav2", axes: str = "ros",
                    pose: GlobalPose | None = None, confidence=None,
                    tiles: bool | Callable[[int, int], tuple[int, int]] = False,
                    lossy: bool = False, check_resolution: bool = True) -> list[JausTile]:
  """An OccupancyGrid (or a window of it) -> ReportCostMap2D messages.

  Args:
    grid: the map; int8 [H, W] values -1..100, row 0 = lowest y.
    window: (col, row, width, height) in cells, (col, row) the lower-left cell;
      None for the whole grid. Must lie inside the grid (never clipped).
    profile: "iop" or "design".
    variant: "list", "confidence" or "rle".
    mapping: "nav2" or "fkie" occupancy -> cost (`jaxfilters.jaus.costs`).
    axes: "ros" or "ned" (module docstring).
    pose: a GlobalPose to send instead of the local pose computed from the
      grid's origin (single message only: tile centres cannot be derived).
    confidence: optional float [H, W] percent per grid cell (grid order) for
      the "confidence" variant; unknown cells always send 0. Default 100.
    tiles: False: the window must fit one message; True: split it (halving
      the longer side) until every piece fits; a function (rows, cols) ->
      (tile_rows, tile_cols): split into tiles of that size, row-major from the
      lower-left, edge tiles smaller.
    lossy: allow the "rle" variant to quantise costs to its 3-bit levels.
      Without it a grid with a cost outside `RLE_LEVEL_COST` is refused (the
      error names the first cell and the values); the other variants are
      lossless and ignore it.
    check_resolution: refuse a map whose cell size `report_to_grid` (or
      `reports_to_grid` for tiles) would not read back from MapWidth and
      MapHeight: with "iop" sizes (0.153 m steps) a 2 x 2 map of 0.05 m cells
      would come back with 0.1 m cells. False: the receiver is given the
      resolution another way (`report_to_grid(..., resolution=)`).

  Returns:
    [JausTile(window, report)], one per message, each with its own centre.

  Raises:
    ValueError: a bad option, window, grid or confidence; a tile or a map too
      large for one message (the message names the limit: 65535 cells in a
      list, 65535 runs, 65535 rows or columns, 10000 m); a centre outside
      +-100000 m; a map so small that its size rounds to 0 m on the wire (the
      receiver could not tell the cell size; docs/jaus.md §11 (4)); with
      `check_resolution`, a map whose cell size the receiver would read as
      another value (docs/jaus.md §11 (9)); "rle" costs that need `lossy=True`.
    NotImplementedError: variant "attractiveness".
  """
  prof = get_profile(profile)
  check_choice("mapping", mapping, MAPPINGS)
  check_choice("axes", axes, AXES)
  if variant not in prof.variants:
    raise ValueError(f"variant must be one of {prof.variants} for profile {prof.name!r}; "
                     f"got {short_repr(variant)}")
  if variant == "attractiveness":
    raise NotImplementedError("encoding CostOrAttractivenessList is refused: no public text "
                              "defines its values (sign convention, reserved values)")
  for name, flag in (("lossy", lossy), ("check_resolution", check_resolution)):
    if not isinstance(flag, bool):
      raise ValueError(f"{name} must be True or False; got {short_repr(flag)}")
  res, origin = _grid_geometry(grid, "grid_to_reports")
  win = _check_window(grid, window)
  if variant == "rle" and not lossy:
    _check_rle_exact(grid, win, mapping)
  if pose is not None and not isinstance(pose, GlobalPose):
    raise TypeError(f"pose must be a GlobalPose or None (the local pose comes from the grid); got "
                    f"{type(pose).__name__}")
  if confidence is not None:
    if variant != "confidence":
      raise ValueError(f"confidence is only sent by the 'confidence' variant; got variant "
                       f"{variant!r}")
    confidence = float32_values(confidence, "confidence", owner="grid_to_reports").astype(np.float64)
    if confidence.shape != grid.data.shape:
      raise ValueError(f"confidence must be [H, W] = {grid.data.shape} like the grid; got "
                       f"{confidence.shape}")

  def problem(w):
    _, _, width, height = w
    runs = None
    if variant == "rle":
      cost = occupancy_to_cost(grid.data[w[1]:w[1] + height, w[0]:w[0] + width], mapping=mapping)
      values, _, known = _variant_arrays(cost[::-1], variant, prof, None)
      runs = len(rle_runs(values, known))
    return limit_problem(prof, variant, height, width, width * res, height * res, runs)

  windows = []
  if tiles is False or tiles is None:
    why = problem(win)
    if why:
      raise ValueError(f"map window of {win[2]} x {win[3]} cells (width x height) does not fit one "
                       f"ReportCostMap2D: {why}; encode a smaller window (CLI: --window) or "
                       "split it into tiles (grid_to_reports(..., tiles=True); the CLI does "
                       "so unless --single)")
    windows = [win]
  elif tiles is True:
    todo = [win]
    while todo:
      w = todo.pop(0)
      why = problem(w)
      if not why:
        windows.append(w)
      elif w[2] == 1 and w[3] == 1:
        raise ValueError(f"a single cell does not fit one ReportCostMap2D: {why}")
      elif w[2] >= w[3]:
        half = w[2] // 2
        todo[:0] = [(w[0], w[1], half, w[3]), (w[0] + half, w[1], w[2] - half, w[3])]
      else:
        half = w[3] // 2
        todo[:0] = [(w[0], w[1], w[2], half), (w[0], w[1] + half, w[2], w[3] - half)]
    windows.sort(key=lambda w: (w[1], w[0]))
  elif callable(tiles):
    shape = tiles(win[3], win[2])
    try:
      th, tw = (int(v) for v in int_values(np.asarray(shape), "tiles() result", lo=1,
                                            hi=2**31 - 1))
    except (TypeError, ValueError) as e:
      raise ValueError(f"tiles function must return (tile_rows, tile_cols), integers >= 1; got "
                       f"{short_repr(shape)} ({e})") from None
    for r0 in range(win[1], win[1] + win[3], th):
      for c0 in range(win[0], win[0] + win[2], tw):
        w = (c0, r0, min(tw, win[0] + win[2] - c0), min(th, win[1] + win[3] - r0))
        why = problem(w)
        if why:
          raise ValueError(f"tile {w} (col, row, width, height) does not fit one "
                           f"ReportCostMap2D: {why}")
        windows.append(w)
  else:
    raise ValueError(f"tiles must be False, True or a function (rows, cols) -> (tile_rows, "
                     f"tile_cols); got {short_repr(tiles)}")
  if pose is not None and len(windows) > 1:
    raise ValueError("a GlobalPose can only be sent with a single message; tile centres would "
                     "need a geodetic projection of the grid")
  out = [JausTile(w, _window_report(grid, w, res, origin, prof, variant, mapping, axes, pose,
                                    confidence)) for w in windows]
  if check_resolution:
    _check_resolution_recovered(prof, res, [t.report for t in out])
  return out


def grid_to_report(grid: OccupancyGrid, **options) -> CostMap2DReport:
  """One ReportCostMap2D of a grid or window; refuses a map that needs tiles.

  Takes the options of `grid_to_reports` except `tiles`.

  Raises:
    ValueError: as `grid_to_reports` (a map too large names the limit).
  """
  if "tiles" in options:
    raise ValueError("grid_to_report makes one message; use grid_to_reports(..., tiles=...)")
  return grid_to_reports(grid, **options)[0].report


def _simplest(lo: float, hi: float, target: float, *, positive: bool = False) -> float:
  """The decimal with the fewest digits in [lo, hi], nearest `target` among those.

  With `positive` the decimal is > 0 (a cell size), even where lo is tiny.
  """
  for digits in range(0, 16):
    scale = 10.0 ** digits
    a, b = math.ceil(lo * scale - 1e-9), math.floor(hi * scale + 1e-9)
    if positive:
      a = max(a, 1)
    if a <= b:
      return min(max(round(target * scale), a), b) / scale
  return target


def _tolerance(value: float, step: float) -> tuple[float, float]:
  """Reals a rounding (+-step/2) or truncating (+step) peer may have sent as `value`."""
  return value - step / 2, value + step


def resolution_interval(prof: JausProfile, map_width: float, map_height: float, rows: int,
                        cols: int) -> tuple[float, float]:
  """[lo, hi] metres per cell that decoded MapWidth / cols and MapHeight / rows allow.

  Each size may be off by -1/2 LSB (a rounding peer) to +1 LSB (a truncating
  peer); lo is 0 when both sizes are 0 on the wire (no lower bound: the cell
  size cannot be told), and lo > hi when the cells cannot be square.
  """
  step = size_field(prof, "MapWidth").step
  w_lo, w_hi = _tolerance(map_width, step)
  h_lo, h_hi = _tolerance(map_height, step)
  return max(w_lo / cols, h_lo / rows, 0.0), min(w_hi / cols, h_hi / rows)


def report_to_grid(report: CostMap2DReport, *, mapping: str = "nav2", axes: str = "ros",
                   resolution: float | None = None, center=None, snap: bool = True,
                   frame_id: str = "map") -> OccupancyGrid:
  """A ReportCostMap2D -> OccupancyGrid (row 0 = lowest y).

  The message holds no resolution: cells are MapWidth / NumberOfColumns wide
  and MapHeight / NumberOfRows high, each known to within the quantization of
  the scaled integers (from -1/2 LSB, a rounding peer, to +1 LSB, a truncating
  peer; 0.15 m for "iop" sizes). With `snap` (default) each of resolution,
  rotation and origin x, y becomes the decimal with the fewest digits inside
  that tolerance (so a map with 0.05 m cells at origin (-10, -10) sent by
  either profile comes back with exactly those numbers); with snap=False the
  plain quotient MapWidth / columns and the decoded values are used (as fkie
  does).

  Args:
    report: a decoded (or built) report of variant list, confidence or rle.
    mapping: "nav2" or "fkie" cost -> occupancy.
    axes: "ros" or "ned", as used to encode.
    resolution: metres per cell to use instead of the estimate; it must agree
      with both MapWidth / cols and MapHeight / rows within the tolerance.
    center: (x, y, yaw) of the map centre in the grid frame; required for a
      GlobalPose report (lat/lon cannot be placed in a map frame here), and
      overrides a local pose.
    snap: see above.
    frame_id: the grid's frame.

  Returns:
    OccupancyGrid with int8 [rows, cols] values -1..100 and origin (x, y, yaw)
    of the lower-left corner.

  Raises:
    ValueError: an "attractiveness" report; an empty map (0 rows or columns);
      cells that cannot be square within the tolerance; a resolution that
      disagrees with the message; a GlobalPose report without `center`; costs
      the mapping cannot turn into occupancy ("fkie" and a cost 201..254).
  """
  occ, res, origin = _report_cells(report, mapping, axes, resolution, center, snap)
  return OccupancyGrid.create(occ, res, origin, frame_id)


def _report_cells(report: CostMap2DReport, mapping: str, axes: str, resolution, center,
                  snap: bool, *, resolution_checked: bool = False):
  """report_to_grid without building the grid: (int8 [rows, cols] grid order, res, origin)."""
  prof = check_report(report, count_runs=False)
  check_choice("mapping", mapping, MAPPINGS)
  check_choice("axes", axes, AXES)
  if report.rows == 0 or report.cols == 0:
    raise ValueError(f"report has {report.rows} rows x {report.cols} columns; an OccupancyGrid "
                     "needs at least one cell")
  occ = cost_to_occupancy(report.nav2_cost(), mapping=mapping)[::-1]
  lo, hi = resolution_interval(prof, report.map_width, report.map_height, report.rows,
                               report.cols)
  if resolution is not None:
    if not resolution_checked:
      resolution_value(resolution, owner="report_to_grid")
    res = float(resolution)
    if not lo - 1e-12 <= res <= hi + 1e-12:
      raise ValueError(f"resolution {res!r} disagrees with the message: MapWidth {report.map_width:.6g} m "
                       f"/ {report.cols} columns and MapHeight {report.map_height:.6g} m / "
                       f"{report.rows} rows allow [{lo:.6g}, {hi:.6g}] m")
  else:
    if lo > hi:
      raise ValueError(f"cells are not square: MapWidth / columns = {report.map_width / report.cols:.6g} m "
                       f"and MapHeight / rows = {report.map_height / report.rows:.6g} m differ by more "
                       "than the message's precision; pass resolution= to choose one")
    if lo <= 0.0 or (not snap and report.map_width <= 0.0):
      raise ValueError(f"MapWidth {report.map_width:.6g} m and MapHeight {report.map_height:.6g} m "
                       f"for {report.cols} x {report.rows} cells: the sizes are 0 on the wire, so "
                       "the cell size cannot be told; pass resolution= (metres per cell)")
    if snap:
      res = _simplest(lo, hi, (lo + hi) / 2, positive=True)
    else:
      res = report.map_width / report.cols
    resolution_value(res, owner="report_to_grid (MapWidth / NumberOfColumns)")
  if center is not None:
    if np.shape(center) != (3,):
      raise ValueError(f"center must be (x, y, yaw) of the map centre; got {short_repr(center)}")
    float32_values(center, "center", owner="report_to_grid")
    cx, cy, yaw = (float(v) for v in center)
  elif isinstance(report.pose, GlobalPose):
    raise ValueError("the report gives its centre as latitude/longitude; pass center=(x, y, yaw) "
                     "of the map centre in the grid frame")
  else:
    p = report.pose
    rot = _simplest(*_tolerance(p.rotation, ROTATION.step), p.rotation) if snap else p.rotation
    cx, cy, yaw = (p.x, p.y, rot) if axes == "ros" else (p.y, p.x, -rot)
  dx, dy = _rot(yaw, res * report.cols / 2, res * report.rows / 2)
  ox, oy = cx - dx, cy - dy
  if snap and center is None:
    # The centre's error carries over to the origin unchanged (same rotation and size).
    ox, oy = (_simplest(*_tolerance(v, CENTER_X.step), v) for v in (ox, oy))
  return occ, res, (ox, oy, yaw)


def reports_to_grid(reports: Iterable[CostMap2DReport], *, mapping: str = "nav2",
                    axes: str = "ros", resolution: float | None = None, snap: bool = True,
                    frame_id: str = "map", max_cells: int = MAX_MAP_CELLS) -> OccupancyGrid:
  """The tiles of one map (`grid_to_reports`, or a peer's) -> one OccupancyGrid.

  Every tile is placed by its own centre on the grid of the first one: all
  share one resolution (the simplest value inside every tile's tolerance, or
  `resolution`) and one rotation, and each tile's corner must fall on a cell
  corner of the first tile's grid. Cells no tile covers are unknown (-1), as
  a CostMap2D service reports cells outside its map (docs/jaus.md §3.5). One
  report gives `report_to_grid`'s result.

  Args:
    reports: local-pose reports of variant list, confidence or rle.
    mapping, axes, resolution, snap, frame_id: as `report_to_grid`.
    max_cells: cap on the cells of the assembled grid (the tiles' bounding
      box), checked before it is allocated.

  Returns:
    OccupancyGrid covering the bounding box of the tiles.

  Raises:
    ValueError: no report; anything `report_to_grid` refuses; a GlobalPose
      tile (tiles are placed by local centres); tiles whose resolutions or
      rotations disagree, that fall between cells of the first tile's grid,
      or that overlap; a bounding box over `max_cells`.
  """
  reports = list(reports)
  if not reports:
    raise ValueError("reports_to_grid needs at least one ReportCostMap2D")
  if len(reports) == 1:
    return report_to_grid(reports[0], mapping=mapping, axes=axes, resolution=resolution,
                          snap=snap, frame_id=frame_id)
  for i, rep in enumerate(reports):
    if not isinstance(rep, CostMap2DReport):
      raise TypeError(f"reports_to_grid expects CostMap2DReport tiles; tile {i} is a "
                      f"{type(rep).__name__}")
    if not isinstance(rep.pose, LocalPose):
      raise ValueError(f"tile {i} gives its centre as latitude/longitude; tiles are placed by "
                       "local centres (decode it alone with report_to_grid(..., center=...))")
  if resolution is not None:
    resolution_value(resolution, owner="reports_to_grid")
  else:
    bounds = [resolution_interval(get_profile(r.profile), r.map_width, r.map_height, r.rows,
                                  r.cols) for r in reports]
    lo, hi = max(b[0] for b in bounds), min(b[1] for b in bounds)
    if lo > hi:
      raise ValueError("the tiles' MapWidth / columns and MapHeight / rows allow no common "
                       "resolution; pass resolution= to choose one")
    if lo <= 0.0:
      raise ValueError("the tiles' sizes are 0 on the wire, so the cell size cannot be told; "
                       "pass resolution= (metres per cell)")
    if snap:
      resolution = _simplest(lo, hi, (lo + hi) / 2, positive=True)
    else:
      big = max(reports, key=lambda r: r.cols)
      resolution = big.map_width / big.cols
  cells = [_report_cells(r, mapping, axes, resolution, None, snap, resolution_checked=True)
           for r in reports]
  res, (x0, y0, yaw) = cells[0][1], cells[0][2]
  places = []
  for i, (occ, _, (ox, oy, oyaw)) in enumerate(cells):
    if abs(math.remainder(oyaw - yaw, 2 * math.pi)) > 1.5 * ROTATION.step:
      raise ValueError(f"tile {i} is rotated by {oyaw:.6g} rad and tile 0 by {yaw:.6g} "
                       "rad; tiles of one map share one rotation")
    u, v = _rot(-yaw, ox - x0, oy - y0)
    u, v = u / res, v / res
    iu, iv = round(u), round(v)
    if abs(u - iu) > 0.25 or abs(v - iv) > 0.25:
      raise ValueError(f"tile {i} starts {u:.3f} x {v:.3f} cells from tile 0's corner, not on a "
                       "cell corner of its grid; the tiles are not of one map")
    places.append((iu, iv, occ))
  c0, r0 = min(p[0] for p in places), min(p[1] for p in places)
  width = max(p[0] + p[2].shape[1] for p in places) - c0
  height = max(p[1] + p[2].shape[0] for p in places) - r0
  if width * height > max_cells:
    raise ValueError(f"the tiles span {width} x {height} = {width * height} cells (width x "
                     f"height), more than max_cells={max_cells} (MAX_MAP_CELLS unless given)")
  data = np.full((height, width), -1, np.int8)
  covered = np.zeros((height, width), bool)
  for i, (iu, iv, occ) in enumerate(places):
    rows = slice(iv - r0, iv - r0 + occ.shape[0])
    cols = slice(iu - c0, iu - c0 + occ.shape[1])
    if covered[rows, cols].any():
      raise ValueError(f"tile {i} overlaps an earlier tile; the tiles of one map cover each cell "
                       "once")
    covered[rows, cols] = True
    data[rows, cols] = occ
  dx, dy = _rot(yaw, c0 * res, r0 * res)
  ox, oy = x0 + dx, y0 + dy
  if snap:
    ox, oy = (_simplest(*_tolerance(v, CENTER_X.step), v) for v in (ox, oy))
  return OccupancyGrid.create(data, res, (ox, oy, yaw), frame_id)
