"""Plain float64 NumPy references of Nav2's filters, written from docs/nav2_semantics.md, loop by loop.

They mirror the C++ (double arithmetic, C casts) and share no code with
jaxfilters. Inputs are the float32 values the device sees, upcast to float64.
"""

import math

import numpy as np

NO_INFORMATION = 255


def mask_cost(d):
  d = int(d)
  if d == -1 or d < -1 or d > 100:
    return 255
  return int(math.floor(d * 254 / 100 + 0.5))


def world_to_map(wx, wy, ox, oy, res, w, h):
  wx, wy, ox, oy, res = map(float, (wx, wy, ox, oy, res))
  if not (math.isfinite(wx) and math.isfinite(wy)):
    return None
  if wx < ox or wy < oy:
    return None
  mx = int(math.floor((wx - ox) / res))
  my = int(math.floor((wy - oy) / res))
  if mx >= w or my >= h:
    return None
  return mx, my


def no_bounds(w, o, res):
  return int((float(w) - float(o)) / float(res))  # C++ cast truncates toward zero


def keepout_process(cost, origin, res, mask, mask_origin, mask_res, window, *, is_pose_lethal=False,
                    override=False, override_cost=252, transform=None, enabled=True, unknown_overwrite="inscribed"):
  """KeepoutFilter::process. Returns (new cost, ran) where ran=False on an early return.

  unknown_overwrite: "inscribed" (Nav2 main, PR #6329: an unknown old cell is written only
  when the mask cost is >= 253) or "any" (before #6329: whenever the mask cost is known).
  """
  if unknown_overwrite not in ("inscribed", "any"):
    raise ValueError(f"unknown_overwrite must be 'inscribed' or 'any'; got {unknown_overwrite!r}")
  cost = np.array(cost, dtype=np.int64)
  if not enabled:
    return cost.astype(np.uint8), False
  h, w = cost.shape
  hm, wm = mask.shape
  ox, oy = float(origin[0]), float(origin[1])
  res = float(res)
  mox, moy, mres = float(mask_origin[0]), float(mask_origin[1]), float(mask_res)
  min_i, min_j, max_i, max_j = [int(v) for v in window]
  if transform is None:
    half = 0.5 * mres
    gx0, gy0 = no_bounds(mox + half, ox, res), no_bounds(moy + half, oy, res)
    if gx0 >= max_i or gy0 >= max_j:
      return cost.astype(np.uint8), False
    gx0, gy0 = max(min_i, gx0), max(min_j, gy0)
    gx1, gy1 = no_bounds(mox + wm * mres + half, ox, res), no_bounds(moy + hm * mres + half, oy, res)
    if gx1 <= min_i or gy1 <= min_j:
      return cost.astype(np.uint8), False
    gx1, gy1 = min(max_i, gx1), min(max_j, gy1)
  else:
    gx0, gy0, gx1, gy1 = min_i, min_j, max_i, max_j
  for j in range(gy0, gy1):
    for i in range(gx0, gx1):
      old = cost[j, i]
      wx = ox + (i + 0.5) * res
      wy = oy + (j + 0.5) * res
      if transform is not None:
        tx, ty, yaw = (float(v) for v in transform)
        c, s = math.cos(yaw), math.sin(yaw)
        wx, wy = c * wx - s * wy + tx, s * wx + c * wy + ty
      cell = world_to_map(wx, wy, mox, moy, mres, wm, hm)
      if cell is None:
        continue
      data = mask_cost(mask[cell[1], cell[0]])
      if data == NO_INFORMATION:
        continue
      if data > old or (old == NO_INFORMATION and (unknown_overwrite == "any" or data >= 253)):
        cost[j, i] = override_cost if (override and is_pose_lethal) else data
  return cost.astype(np.uint8), True


def speed_limit_at(mask, mask_origin, mask_res, ftype, base, mult, x, y):
  """getSpeedLimitAtPose -> (limit, valid)."""
  hm, wm = mask.shape
  if ftype not in (1, 2):
    return 0.0, False
  cell = world_to_map(x, y, mask_origin[0], mask_origin[1], mask_res, wm, hm)
  if cell is None:
    return 0.0, False
  d = int(mask[cell[1], cell[0]])
  if d == -1:
    return 0.0, False
  if d == 0:
    return 0.0, True
  limit = d * float(mult) + float(base)
  if ftype == 1 and (limit < 0.0 or limit > 100.0):
    limit = 0.0
  if ftype == 2 and limit < 0.0:
    limit = 0.0
  return limit, True


class SpeedRef:
  def __init__(self):
    self.prev = 0.0

  def process(self, limit, valid, enabled=True):
    if not enabled or not valid:
      return self.prev, False
    changed = limit != self.prev
    self.prev = limit
    return limit, changed


class BinaryRef:
  def __init__(self, default_state=False, threshold=50.0):
    self.state = False
    self.default = default_state
    self.threshold = threshold

  def process(self, mask, mask_origin, mask_res, base, mult, x, y):
    hm, wm = mask.shape
    cell = world_to_map(x, y, mask_origin[0], mask_origin[1], mask_res, wm, hm)
    if cell is None:
      self.state = self.default
      return True
    d = int(mask[cell[1], cell[0]])
    if d == -1:
      return False
    value = float(base) + d * float(mult)
    if value > self.threshold:
      if self.state == self.default:
        self.state = not self.default
        return True
      return False
    if self.state != self.default:
      self.state = self.default
      return True
    return False


class ZoneRef:
  """ZoneParameterFilter with a dict model of the target parameters."""

  def __init__(self, nominal, states):
    self.nominal = dict(nominal)
    self.states = {k: dict(v) for k, v in states.items()}
    self.current = 0
    self.initialized = False
    self.params = dict(nominal)

  def _apply(self, new):
    if new == 0:
      self.params.update(self.nominal)
      return
    prev = self.current
    if prev != 0:
      for name in self.states[prev]:
        if name not in self.states[new] and name in self.nominal:
          self.params[name] = self.nominal[name]
    self.params.update(self.states[new])

  def process(self, mask, mask_origin, mask_res, x, y):
    """Returns (event, error)."""
    hm, wm = mask.shape
    cell = world_to_map(x, y, mask_origin[0], mask_origin[1], mask_res, wm, hm)
    if cell is None:
      if self.initialized and self.current != 0:
        self._apply(0)
        self.current = 0
      return False, False
    d = int(mask[cell[1], cell[0]])
    if d < 0:
      return False, False
    if self.initialized and d == self.current:
      return False, False
    if d != 0 and d not in self.states:
      return False, True
    self._apply(d)
    self.current = d
    self.initialized = True
    return True, False


def _segment_distance(px, py, ax, ay, bx, by):
  ex, ey = bx - ax, by - ay
  len2 = ex * ex + ey * ey
  u = 0.0 if len2 == 0 else min(1.0, max(0.0, ((px - ax) * ex + (py - ay) * ey) / len2))
  return math.hypot(px - (ax + u * ex), py - (ay + u * ey))


def footprint_signed_distance(qx, qy, *, polygon=None, radius=None):
  """Signed distance (m) of a robot-frame point to the footprint: < 0 inside, 0 on the boundary.

  Polygon: even-odd interior (ray to +x), distance to the nearest edge. Disc: |q| - r.
  """
  if radius is not None:
    return math.hypot(qx, qy) - float(radius)
  pts = [(float(a), float(b)) for a, b in polygon]
  inside = False
  dist = math.inf
  for k, (ax, ay) in enumerate(pts):
    bx, by = pts[(k + 1) % len(pts)]
    if (ay > qy) != (by > qy) and qx < ax + (qy - ay) * (bx - ax) / (by - ay):
      inside = not inside
    dist = min(dist, _segment_distance(qx, qy, ax, ay, bx, by))
  return -dist if (inside and dist > 0) else dist


def footprint_in_zone(mask, mask_origin, mask_res, pose, *, polygon=None, radius=None, margin=0.0, eps=0.0):
  """The footprint robot-in-zone rule (jaxfilters/footprint.py), over every mask cell, in float64.

  A lethal cell (data 100, cost 253/254) counts when its centre, in the robot frame,
  lies within `margin` of the footprint (signed distance <= margin). Centres within
  `eps` of that boundary are undecided (float32 on the device).

  Returns:
    (surely, possibly): some lethal cell surely counts / possibly counts.
  """
  hm, wm = mask.shape
  ox, oy, res = float(mask_origin[0]), float(mask_origin[1]), float(mask_res)
  x, y, yaw = (float(v) for v in pose)
  if not all(math.isfinite(v) for v in (x, y, yaw)):
    return False, False
  c, s = math.cos(yaw), math.sin(yaw)
  surely = possibly = False
  for my in range(hm):
    for mx in range(wm):
      if mask_cost(mask[my, mx]) not in (253, 254):
        continue
      dx, dy = ox + (mx + 0.5) * res - x, oy + (my + 0.5) * res - y
      qx, qy = c * dx + s * dy, -s * dx + c * dy
      sd = footprint_signed_distance(qx, qy, polygon=polygon, radius=radius)
      surely |= sd <= margin - eps
      possibly |= sd <= margin + eps
  return surely, possibly


def centre_in_zone(mask, mask_origin, mask_res, x, y):
  """Nav2's robot-in-keepout test (docs/nav2_semantics.md §4.2): the centre's mask cell costs 253 or 254."""
  hm, wm = mask.shape
  cell = world_to_map(x, y, mask_origin[0], mask_origin[1], mask_res, wm, hm)
  return cell is not None and mask_cost(mask[cell[1], cell[0]]) in (253, 254)
