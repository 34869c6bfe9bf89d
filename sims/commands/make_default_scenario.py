"""Writes the built-in warehouse scenario: sims/assets/default_{map,keepout,speed}.{yaml,pgm}.

Run once (`python -m sims.commands.make_default_scenario`); the generated files are
shipped in the repository and loaded with `jaxfilters.map_io.load_map`, exactly
as Nav2's map_server would load them. The layout is a 30 m x 20 m warehouse at
0.05 m cells (600 x 400 pixels, 240 kB per image):

* storage (x < -1 m): four rack columns of two racks each, with 2 m aisles
  and three cross aisles (bottom, a 3 m main aisle in the middle, top);
* a central corridor (-1 m < x < 3 m) and an open dock floor (x > 3 m) with a
  grid of pillars and a dividing wall with two doors;
* keepout zones (trinary mask, Nav2 type 0): a pick station on the dock
  floor, a maintenance bay in the bottom-right corner, and a closed aisle
  mouth between racks 1 and 2 that the planner must route around;
* speed zones (scale mask, Nav2 type 1, base 100, multiplier -1, thresholds
  1.0 / 0.0 like Nav2's bringup masks): a 50 % pedestrian crossing across the
  central corridor that most trips cross, and a 30 % zone along the docks.

Pixels are written by hand (not with `save_map`) because map_saver's scale
mode cannot write the 1.0 / 0.0 thresholds the bringup masks use; the loader
test in tests/fleet/test_scenario.py checks every value through `load_map`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from jaxfilters.cli import ArgumentParser  # one-line errors, exit code 2

ASSETS = Path(__file__).resolve().parents[1] / "assets"
RESOLUTION = 0.05
ORIGIN = (-15.0, -10.0)
WIDTH_M, HEIGHT_M = 30.0, 20.0

# Pixel values (8-bit gray, negate 0).
PX_OCCUPIED, PX_UNKNOWN, PX_FREE = 0, 205, 254          # trinary (map_saver's values)
PX_NO_LIMIT = 255                                       # scale: p = 0 -> 0 -> no limit
# Scale mode with occupied 1.0 / free 0.0: value = round(100 * (255 - px) / 255) (docs/nav2_semantics.md §10.2),
# and the speed limit is 100 - value percent.
PX_PERCENT_50 = 127                                     # 100 * 128/255 = 50.20 -> 50 -> 50 %
PX_PERCENT_30 = 76                                      # 100 * 179/255 = 70.20 -> 70 -> 30 %

SPEED_ZONES = {  # name: (pixel, limit percent, box x0, y0, x1, y1)
    "crossing_50pct": (PX_PERCENT_50, 50.0, (-1.0, -3.0, 3.0, 3.0)),
    "docks_30pct": (PX_PERCENT_30, 30.0, (11.5, -6.0, 14.8, 9.8)),
}
KEEPOUT_ZONES = {  # name: box x0, y0, x1, y1
    "pick_station": (6.8, 1.6, 9.2, 3.4),
    "maintenance_bay": (11.5, -9.8, 14.8, -7.0),
    "closed_aisle": (-11.5, -9.8, -9.5, -7.0),
}


def _shape() -> tuple[int, int]:
  return int(round(HEIGHT_M / RESOLUTION)), int(round(WIDTH_M / RESOLUTION))


def _box(img: np.ndarray, x0: float, y0: float, x1: float, y1: float, value: int) -> None:
  """Fills world box [x0, x1] x [y0, y1] of a bottom-row-first image with value."""
  h, w = img.shape
  c0 = max(0, int(round((x0 - ORIGIN[0]) / RESOLUTION)))
  c1 = min(w, int(round((x1 - ORIGIN[0]) / RESOLUTION)))
  r0 = max(0, int(round((y0 - ORIGIN[1]) / RESOLUTION)))
  r1 = min(h, int(round((y1 - ORIGIN[1]) / RESOLUTION)))
  img[r0:r1, c0:c1] = value


def static_map_pixels() -> np.ndarray:
  """uint8 [H, W] trinary pixels, row 0 = lowest y (flipped when written)."""
  img = np.full(_shape(), PX_FREE, np.uint8)
  x0, y0 = ORIGIN
  x1, y1 = x0 + WIDTH_M, y0 + HEIGHT_M
  t = 0.2
  for box in ((x0, y0, x1, y0 + t), (x0, y1 - t, x1, y1), (x0, y0, x0 + t, y1), (x1 - t, y0, x1, y1)):
    _box(img, *box, PX_OCCUPIED)
  # Racks: 1 m deep, two per column (a 3 m cross aisle at -1.5 < y < 1.5), 2 m aisles between columns.
  for cx in (-12.0, -9.0, -6.0, -3.0):
    for ry0, ry1 in ((-7.0, -1.5), (1.5, 7.0)):
      _box(img, cx - 0.5, ry0, cx + 0.5, ry1, PX_UNKNOWN)        # shelving: unknown inside
      for box in ((cx - 0.5, ry0, cx + 0.5, ry0 + 0.1), (cx - 0.5, ry1 - 0.1, cx + 0.5, ry1),
                  (cx - 0.5, ry0, cx - 0.4, ry1), (cx + 0.4, ry0, cx + 0.5, ry1)):
        _box(img, *box, PX_OCCUPIED)
  # Dock floor divider with two 2 m doors, and pillars.
  _box(img, 4.0, -9.8, 4.2, -5.0, PX_OCCUPIED)
  _box(img, 4.0, -3.0, 4.2, 5.0, PX_OCCUPIED)
  for px in (7.0, 10.5):
    for py in (-5.0, -1.0, 6.5):
      _box(img, px - 0.2, py - 0.2, px + 0.2, py + 0.2, PX_OCCUPIED)
  # Loading-dock bumpers along the right wall.
  for py in (-4.0, 0.0, 4.0, 8.0):
    _box(img, 14.4, py - 0.6, 14.8, py + 0.6, PX_OCCUPIED)
  return img


def keepout_pixels() -> np.ndarray:
  """uint8 [H, W] trinary keepout mask image (row 0 = lowest y): 0 (occupied) in KEEPOUT_ZONES, 254 elsewhere."""
  img = np.full(_shape(), PX_FREE, np.uint8)
  for box in KEEPOUT_ZONES.values():
    _box(img, *box, PX_OCCUPIED)
  return img


def speed_pixels() -> np.ndarray:
  """uint8 [H, W] scale-mode speed mask image (row 0 = lowest y): SPEED_ZONES pixels, 255 (no limit) elsewhere."""
  img = np.full(_shape(), PX_NO_LIMIT, np.uint8)
  for px, _, box in SPEED_ZONES.values():
    _box(img, *box, px)
  return img


def _write_pgm(path: Path, img: np.ndarray) -> None:
  h, w = img.shape
  with open(path, "wb") as f:
    f.write(f"P5\n{w} {h}\n255\n".encode())
    f.write(np.ascontiguousarray(img[::-1]).tobytes())      # image row 0 is the top (highest y)


def _write_yaml(path: Path, image: str, mode: str, occupied: float, free: float) -> None:
  path.write_text(
      f"image: {image}\nmode: {mode}\nresolution: {RESOLUTION}\n"
      f"origin: [{ORIGIN[0]}, {ORIGIN[1]}, 0.0]\nnegate: 0\n"
      f"occupied_thresh: {occupied}\nfree_thresh: {free}\n")


def write(out_dir: Path = ASSETS) -> list[Path]:
  """Writes the six scenario files (three PGM images and their YAMLs) into out_dir.

  Args:
    out_dir: destination folder (created if missing; default sims/assets).

  Returns:
    The written paths.
  """
  out_dir.mkdir(parents=True, exist_ok=True)
  written = []
  for name, img, mode, occ, free in (
      ("default_map", static_map_pixels(), "trinary", 0.65, 0.196),
      ("default_keepout", keepout_pixels(), "trinary", 0.65, 0.196),
      ("default_speed", speed_pixels(), "scale", 1.0, 0.0)):
    _write_pgm(out_dir / f"{name}.pgm", img)
    _write_yaml(out_dir / f"{name}.yaml", f"{name}.pgm", mode, occ, free)
    written += [out_dir / f"{name}.pgm", out_dir / f"{name}.yaml"]
  return written


def main(argv=None) -> None:
  """`python -m sims.commands.make_default_scenario [--out DIR]`: writes the files and prints their paths."""
  parser = ArgumentParser(prog="python -m sims.commands.make_default_scenario",
                                   description=__doc__.splitlines()[0])
  parser.add_argument("--out", type=Path, default=ASSETS, help="output folder (default sims/assets)")
  args = parser.parse_args(argv)
  for p in write(args.out):
    print(p)


if __name__ == "__main__":
  main()
