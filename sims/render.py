"""Pictures of a fleet rollout with Pillow: a PNG of trajectories and an optional GIF.

The background is the static map (free white, occupied black, unknown grey)
with keepout zones in red and speed zones tinted blue (darker = slower);
stations are small green squares. Trajectories are coloured by speed (blue
slow -> red at max speed). Images are scaled so the longer side is about
`max_side` pixels; image row 0 is the highest y, as in map images.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from jaxfilters import constants
from jaxfilters.keepout import occ_to_cost

_STOPS = np.array([[48, 18, 59], [40, 120, 240], [40, 200, 140], [250, 200, 40], [200, 30, 20]], np.float32)


def speed_colour(frac: np.ndarray) -> np.ndarray:
  """uint8 [..., 3] colours for speeds as a fraction of max speed (0..1)."""
  x = np.clip(np.asarray(frac, np.float32), 0.0, 1.0) * (len(_STOPS) - 1)
  i = np.minimum(np.floor(x).astype(int), len(_STOPS) - 2)
  t = (x - i)[..., None]
  return ((1 - t) * _STOPS[i] + t * _STOPS[i + 1]).astype(np.uint8)


def background(world) -> np.ndarray:
  """uint8 [H, W, 3] map image (row 0 = lowest y) with zones drawn on its free cells.

  Zones are only tinted where the static map is free: Nav2 masks often also
  cover walls and shelving (Nav2's warehouse keepout mask does), which would
  hide the map.
  """
  sc = world.scenario
  data = sc.map.data
  img = np.full(data.shape + (3,), 255, np.uint8)
  img[data == -1] = (190, 190, 190)
  img[(data >= 65)] = (0, 0, 0)
  if sc.speed.data.shape == data.shape:
    zone = np.asarray(world.params.zone_table)[sc.speed.data.astype(np.uint8)]
    nz = max(1, world.num_zones - 1)
    for z in range(1, world.num_zones):
      tint = np.array([225 - 90 * z / nz, 230 - 60 * z / nz, 255], np.float32)
      sel = (zone == z) & (data == 0)
      img[sel] = (0.5 * img[sel] + 0.5 * tint).astype(np.uint8)
  if sc.keepout.data.shape == data.shape:
    sel = (np.asarray(occ_to_cost(sc.keepout.data)) >= constants.INSCRIBED_INFLATED_OBSTACLE) & (data == 0)
    img[sel] = (0.4 * img[sel] + 0.6 * np.array([235, 40, 40])).astype(np.uint8)
  return img


class _Canvas:
  """World -> pixel transform for an upscaled, vertically flipped map image."""

  def __init__(self, world, max_side: int):
    grid = world.scenario.map
    self.h, self.w = grid.data.shape
    self.scale = max(0.25, min(4.0, max_side / max(self.h, self.w)))
    self.res = grid.resolution
    self.ox, self.oy = grid.origin[0], grid.origin[1]
    base = np.ascontiguousarray(background(world)[::-1])
    size = (max(1, int(self.w * self.scale)), max(1, int(self.h * self.scale)))
    self.image = Image.fromarray(base).resize(size, Image.NEAREST)

  def px(self, x, y):
    u = (np.asarray(x) - self.ox) / self.res * self.scale
    v = (self.h - (np.asarray(y) - self.oy) / self.res) * self.scale
    return u, v


def render_png(world, pose: np.ndarray, speed: np.ndarray, path, *, max_side: int = 1200) -> Path:
  """Draws trajectories coloured by speed.

  Args:
    world: sims.world.World.
    pose: float [T, B, 3] recorded poses; speed: float [T, B] (m/s).
    path: output PNG path.
    max_side: pixels of the longer image side (about).

  Returns:
    The written path.
  """
  c = _Canvas(world, max_side)
  draw = ImageDraw.Draw(c.image)
  r_px = max(2, int(world.config.robot.radius / c.res * c.scale))
  for sx, sy in world.stations:
    u, v = c.px(sx, sy)
    draw.rectangle([u - 3, v - 3, u + 3, v + 3], fill=(30, 160, 60))
  frac = speed / world.config.robot.max_speed
  colours = speed_colour(frac)
  t, b = pose.shape[:2]
  width = max(1, int(round(c.scale)))
  for i in range(b):
    u, v = c.px(pose[:, i, 0], pose[:, i, 1])
    for s in range(1, t):
      draw.line([(u[s - 1], v[s - 1]), (u[s], v[s])], fill=tuple(int(q) for q in colours[s, i]), width=width)
  for i in range(b):
    u, v = c.px(pose[-1, i, 0], pose[-1, i, 1])
    draw.ellipse([u - r_px, v - r_px, u + r_px, v + r_px], outline=(0, 0, 0), width=2)
  _legend(draw, c.image.size, world.config.robot.max_speed)
  path = Path(path)
  c.image.save(path)
  return path


def _font(size: int):
  try:
    return ImageFont.load_default(size=size)     # Pillow >= 10.1 (scalable when FreeType is there)
  except TypeError:
    return ImageFont.load_default()


def _legend(draw: ImageDraw.ImageDraw, size, max_speed: float) -> None:
  w, h = size
  x0, y0, bw = 10, h - 22, min(200, w // 3)
  font = _font(13)
  for i in range(bw):
    draw.line([(x0 + i, y0), (x0 + i, y0 + 10)], fill=tuple(int(q) for q in speed_colour(i / (bw - 1))))
  draw.text((x0, y0 - 15), "0", fill=(0, 0, 0), font=font)
  draw.text((x0 + bw - 50, y0 - 15), f"{max_speed:g} m/s", fill=(0, 0, 0), font=font)


def render_gif(world, pose: np.ndarray, speed: np.ndarray, path, *, max_side: int = 600,
               max_frames: int = 150, seconds_per_frame: float = 0.2, trail: int = 25) -> Path:
  """Animates robots (discs with a heading tick) with short speed-coloured trails.

  Args:
    world: sims.world.World.
    pose: float [T, B, 3]; speed: float [T, B].
    path: output GIF path.
    max_side, max_frames: size limits (frames are subsampled evenly).
    seconds_per_frame: simulated seconds between recorded poses.
    trail: recorded steps of trail behind each robot.

  Returns:
    The written path.
  """
  c = _Canvas(world, max_side)
  t, b = pose.shape[:2]
  stride = max(1, int(np.ceil(t / max_frames)))
  colours = speed_colour(speed / world.config.robot.max_speed)
  r_px = max(2, int(world.config.robot.radius / c.res * c.scale))
  frames = []
  for s in range(0, t, stride):
    img = c.image.copy()
    draw = ImageDraw.Draw(img)
    lo = max(0, s - trail)
    for i in range(b):
      u, v = c.px(pose[lo:s + 1, i, 0], pose[lo:s + 1, i, 1])
      for q in range(1, len(u)):
        draw.line([(u[q - 1], v[q - 1]), (u[q], v[q])], fill=tuple(int(x) for x in colours[lo + q, i]),
                  width=2)
      (x,), (y,) = c.px(pose[s:s + 1, i, 0], pose[s:s + 1, i, 1])
      draw.ellipse([x - r_px, y - r_px, x + r_px, y + r_px], fill=tuple(int(q) for q in colours[s, i]),
                   outline=(0, 0, 0))
      yaw = pose[s, i, 2]
      draw.line([(x, y), (x + r_px * np.cos(yaw), y - r_px * np.sin(yaw))], fill=(0, 0, 0), width=2)
    draw.text((5, 5), f"t = {s * seconds_per_frame:.1f} s", fill=(0, 0, 0), font=_font(14))
    frames.append(img.convert("P", palette=Image.ADAPTIVE, colors=64))
  path = Path(path)
  frames[0].save(path, save_all=True, append_images=frames[1:], optimize=False,
                 duration=max(20, int(1000 * seconds_per_frame * stride / 2)), loop=0)
  return path
