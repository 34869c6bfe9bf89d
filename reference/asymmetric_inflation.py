"""Plain float64 NumPy reference of Nav2's AsymmetricInflationLayer, loop by loop.

Transcribed from Nav2 `nav2_costmap_2d/plugins/asymmetric_inflation_layer.cpp` (main at
a3a97043: `updateCosts`, `extractLocalPathSegments`, `buildPathSpatialHash`,
`computeObstacleSide`, `seedDistanceMap`, `applyInflation`, `computeAsymmetricCaches`) and
`plugins/inflation_layer.cpp` (`updateCosts`, `computeCost`), for one robot and one update
window that is the whole map, with the path already in the costmap frame. Python floats
are C++ doubles; the distance transform's distances are float32 square roots of exact
integer squared distances (Nav2's `DistanceTransform` on these inputs), found here by brute
force. Shares no code with jaxfilters.
"""

from __future__ import annotations

import math

import numpy as np

LETHAL = 254
INSCRIBED = 253
UNKNOWN = 255
PRECISION = 100          # COST_LUT_PRECISION


def cell_distance(world_dist: float, resolution: float) -> int:
  """Costmap2D::cellDistance: max(0, ceil(d / res))."""
  return int(max(0.0, math.ceil(world_dist / resolution)))


def cost_lut(r_cells: int, resolution: float, inscribed: float, csf: float) -> list[int]:
  """computeCaches / computeAsymmetricCaches: LUT[k] for the distance k / 100 cells."""
  lut = []
  for k in range(r_cells * PRECISION + 2):
    distance = k / PRECISION
    if distance == 0.0:
      lut.append(LETHAL)
    elif distance * resolution <= inscribed:
      lut.append(INSCRIBED)
    else:
      lut.append(int((INSCRIBED - 1) * math.exp(-csf * (distance * resolution - inscribed))))
  return lut


def _distances(seeds: np.ndarray) -> np.ndarray:
  """float32 [H, W] Euclidean distance in cells to the nearest seed (inf without seeds)."""
  h, w = seeds.shape
  sy, sx = np.nonzero(seeds)
  out = np.full((h, w), np.inf, np.float32)
  if sy.size == 0:
    return out
  for y in range(h):
    for x in range(w):
      out[y, x] = np.sqrt(np.float32(int(np.min((sy - y) ** 2 + (sx - x) ** 2))))
  return out


def _lut_index(dist: np.float32, lut_len: int) -> int:
  return min(lut_len - 1, int(np.float32(np.float32(dist * np.float32(PRECISION)) + np.float32(0.5))))


def symmetric_pass(cost, *, r_cells, lut, inflate_unknown, inflate_around_unknown):
  """InflationLayer::updateCosts over the whole map (pass 1)."""
  src = (cost == LETHAL) | (inflate_around_unknown & (cost == UNKNOWN))
  dist = _distances(src)
  out = cost.astype(np.int64).copy()
  h, w = cost.shape
  for y in range(h):
    for x in range(w):
      if dist[y, x] > np.float32(r_cells):
        continue
      c = lut[_lut_index(dist[y, x], len(lut))]
      old = int(cost[y, x])
      if old == UNKNOWN and (c > 0 if inflate_unknown else c >= INSCRIBED):
        out[y, x] = c
      else:
        out[y, x] = max(old, c)
  return out


def local_segments(path, robot_xy, *, origin, resolution, size_x, size_y, inflation_radius, goal_threshold):
  """extractLocalPathSegments, the path in the costmap frame: [((ax, ay), (bx, by)), ...]."""
  path = [(float(x), float(y)) for x, y in path]
  if len(path) < 2:
    return []
  gx, gy = path[-1]
  if math.hypot(gx - float(robot_xy[0]), gy - float(robot_xy[1])) <= goal_threshold:
    return []
  map_min_x, map_min_y = float(origin[0]), float(origin[1])
  map_max_x = map_min_x + float(size_x) * resolution
  map_max_y = map_min_y + float(size_y) * resolution
  segs = []
  for i in range(1, len(path)):
    (ax, ay), (bx, by) = path[i - 1], path[i]
    if (max(ax, bx) + inflation_radius < map_min_x or min(ax, bx) - inflation_radius > map_max_x
        or max(ay, by) + inflation_radius < map_min_y or min(ay, by) - inflation_radius > map_max_y):
      continue
    segs.append(((ax, ay), (bx, by)))
  return segs


def spatial_hash(segs, r):
  """buildPathSpatialHash: bucket (bx, by) -> segment indices in insertion order."""
  table: dict[tuple[int, int], list[int]] = {}
  for p, ((ax, ay), (bx, by)) in enumerate(segs):
    lo_x, hi_x = min(ax, bx) - r, max(ax, bx) + r
    lo_y, hi_y = min(ay, by) - r, max(ay, by) + r
    for kx in range(math.floor(lo_x / r), math.floor(hi_x / r) + 1):
      for ky in range(math.floor(lo_y / r), math.floor(hi_y / r) + 1):
        table.setdefault((kx, ky), []).append(p)
  return table


def obstacle_side(cx, cy, candidates, segs, r) -> int:
  """computeObstacleSide: +1 left, -1 right, 0 neutral."""
  min_dist_sq = 1.7976931348623157e308
  best_cross = 0.0
  for p in candidates:
    (ax, ay), (bx, by) = segs[p]
    if cx < min(ax, bx) - r or cx > max(ax, bx) + r:
      continue
    if cy < min(ay, by) - r or cy > max(ay, by) + r:
      continue
    abx, aby = bx - ax, by - ay
    len_sq = abx * abx + aby * aby
    acx, acy = cx - ax, cy - ay
    if len_sq < 1e-6:
      dist_sq = acx * acx + acy * acy
      cross = 0.0
    else:
      t = min(max((acx * abx + acy * aby) / len_sq, 0.0), 1.0)
      pdx, pdy = acx - t * abx, acy - t * aby
      dist_sq = pdx * pdx + pdy * pdy
      cross = abx * acy - aby * acx
    if dist_sq < min_dist_sq:
      min_dist_sq, best_cross = dist_sq, cross
  if min_dist_sq > r * r:
    return 0
  return 1 if best_cross > 0.0 else (-1 if best_cross < 0.0 else 0)


def asymmetric_inflate(cost, path, robot_xy, *, origin, resolution, inflation_radius=2.0,
                       cost_scaling_factor_left=4.0, cost_scaling_factor_right=4.0, goal_distance_threshold=1.5,
                       inscribed_radius, inflate_unknown=False, inflate_around_unknown=False, enabled=True):
  """AsymmetricInflationLayer::updateCosts over the whole map for one robot: uint8 [H, W]."""
  cost = np.asarray(cost, np.uint8)
  h, w = cost.shape
  r_cells = cell_distance(inflation_radius, resolution)
  if not enabled or r_cells == 0:
    return cost.copy()
  left, right = float(cost_scaling_factor_left), float(cost_scaling_factor_right)
  lut = cost_lut(r_cells, resolution, inscribed_radius, max(left, right))
  out = symmetric_pass(cost, r_cells=r_cells, lut=lut, inflate_unknown=inflate_unknown,
                       inflate_around_unknown=inflate_around_unknown)
  segs = local_segments(path, robot_xy, origin=origin, resolution=resolution, size_x=w, size_y=h,
                        inflation_radius=inflation_radius, goal_threshold=goal_distance_threshold)
  if not segs or left == right:
    return out.astype(np.uint8)
  table = spatial_hash(segs, inflation_radius)
  disfavoured = 1 if left < right else -1
  ox, oy = float(origin[0]), float(origin[1])

  def traversable(x, y):
    c = out[y, x]
    return (c != LETHAL and c != UNKNOWN) if inflate_around_unknown else c != LETHAL

  seeds = np.zeros((h, w), bool)
  for j in range(h):
    for i in range(w):
      c = out[j, i]
      if c != LETHAL and not (inflate_around_unknown and c == UNKNOWN):
        continue
      edge = i == 0 or i == w - 1 or j == 0 or j == h - 1
      if not (edge or traversable(i - 1, j) or traversable(i + 1, j) or traversable(i, j - 1)
              or traversable(i, j + 1)):
        continue
      cx = ox + (i + 0.5) * resolution
      cy = oy + (j + 0.5) * resolution
      key = (math.floor(cx / inflation_radius), math.floor(cy / inflation_radius))
      if key not in table:
        continue
      side = obstacle_side(cx, cy, table[key], segs, inflation_radius)
      if side != 0 and side == disfavoured:
        seeds[j, i] = True
  dist = _distances(seeds)
  lut_d = cost_lut(r_cells, resolution, inscribed_radius, min(left, right))
  for j in range(h):
    for i in range(w):
      if dist[j, i] > np.float32(r_cells):
        continue
      c = lut_d[_lut_index(dist[j, i], len(lut_d))]
      if c > out[j, i]:
        out[j, i] = c
  return out.astype(np.uint8)
