"""Map I/O: Nav2 map_server loading and map_saver writing (spec §10).

`load_map` reads a map YAML and its image into an `OccupancyGrid` exactly as
Nav2's current (Eigen) `nav2_map_server::loadMapFromYaml` does: inclusive
float32 thresholds, free applied last, alpha < 255 meaning unknown in trinary
and scale, raw bytes wrapped to int8, and the image rows flipped so grid row 0
is the bottom image row. `load_map_image` is the pure NumPy pixel conversion it
uses. `save_map` writes `<name>.yaml` + image the way `map_saver` does.

Deliberate deviations from Nav2 (the project's issue asks for loud failures):
  - Bad input raises instead of returning a load status: `FileNotFoundError`
    for a missing YAML or image, `ValueError` (naming the file and the key)
    for everything else.
  - Nav2 does not check `resolution` or the thresholds when loading; we
    require a finite resolution > 0, thresholds in [0, 1] and
    `free_thresh < occupied_thresh` (so Nav2's "free wins" order is only
    visible when both thresholds round to the same float32).
  - Colour images are reduced to gray with Pillow's ITU-R 601 luma
    (`(19595 R + 38470 G + 7471 B + 2**15) >> 16`, i.e. `convert("L")`).
    GraphicsMagick's fixed-point luma may differ from it by 1 on some colours;
    gray images and colour pixels with R = G = B are exact.
  - 16-bit images (PGM with maxval > 255, 16-bit gray PNG) are scaled to 8 bits
    with `round(v / 257)` as a 16-bit-quantum GraphicsMagick build does; Pillow
    has already stretched PGM maxvals below 65535 to the full 16-bit range.
  - Saving supports only the formats Nav2 recommends (png, pgm, bmp); Nav2
    would warn and try any format GraphicsMagick can write.
"""

from __future__ import annotations

import json
import math
import os
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from PIL import Image

from jaxfilters import constants
from jaxfilters.grid import OccupancyGrid

__all__ = ["MAP_MODES", "load_map", "load_map_image", "save_map"]

# Map modes Nav2 understands (YAML `mode`, lower-cased); trinary is the default.
MAP_MODES = ("trinary", "scale", "raw")
_SAVE_FORMATS = ("png", "pgm", "bmp")
_PIL_FORMAT = {"png": "PNG", "pgm": "PPM", "bmp": "BMP"}
_YAML_SUFFIXES = (".yaml", ".yml")

# Trinary pixels map_saver writes (spec §10.3.3).
_SAVE_OCCUPIED, _SAVE_UNKNOWN, _SAVE_FREE = 0, 205, 254
# Thresholds a trinary save always writes (#5278).
_TRINARY_SAVED_OCCUPIED, _TRINARY_SAVED_FREE = 0.65, 0.196
_TRUE_WORDS = ("y", "yes", "true", "on")
_FALSE_WORDS = ("n", "no", "false", "off")


# --------------------------------------------------------------------------- pixels


def _check_mode(mode: Any, where: str = "mode") -> str:
  if not isinstance(mode, str) or mode.lower() not in MAP_MODES:
    raise ValueError(f"{where} must be one of {'/'.join(MAP_MODES)} (case-insensitive); "
                     f"got {mode!r}")
  return mode.lower()


def _check_thresholds(occupied_thresh: float, free_thresh: float,
                      where: str = "") -> tuple[float, float]:
  """Checks 0 <= free < occupied <= 1; `where` ("<file>: ") switches to YAML-key wording."""
  occ, free = float(occupied_thresh), float(free_thresh)
  name = (lambda key: f"key '{key}'") if where else (lambda key: key)
  for key, v in (("occupied_thresh", occ), ("free_thresh", free)):
    if not 0.0 <= v <= 1.0:  # also rejects NaN
      raise ValueError(f"{where}{name(key)} must lie in [0, 1]; got {v!r}")
  if not free < occ:
    raise ValueError(f"{where}{name('free_thresh')} must be < {name('occupied_thresh')}; got "
                     f"free_thresh {free!r} >= occupied_thresh {occ!r}")
  return occ, free


def _luma(rgb: np.ndarray) -> np.ndarray:
  """ITU-R 601 luma in Pillow's 16-bit fixed point (`Image.convert("L")`)."""
  r, g, b = (rgb[..., i].astype(np.uint32) for i in range(3))
  return ((19595 * r + 38470 * g + 7471 * b + 0x8000) >> 16).astype(np.uint8)


def _as_uint8(name: str, arr: np.ndarray) -> np.ndarray:
  if not (np.issubdtype(arr.dtype, np.integer)):
    raise ValueError(f"{name} must hold integers 0..255; got dtype {arr.dtype}")
  if arr.size and (arr.min() < 0 or arr.max() > 255):
    raise ValueError(f"{name} must hold integers 0..255; got min {arr.min()} max {arr.max()}")
  return arr.astype(np.uint8)


def load_map_image(image, alpha=None, *, mode: str = "trinary", occupied_thresh: float,
                   free_thresh: float, negate: bool | int = False) -> np.ndarray:
  """Converts image pixels to OccupancyGrid values, as Nav2's map_io does (spec §10.2).

  Trinary and scale: `n = float32(g) / 255`, `occ = n` if negate else `1 - n`
  (float32); `occ >= float32(occupied_thresh)` gives 100, then
  `occ <= float32(free_thresh)` gives 0 (free is applied last, so it wins);
  otherwise trinary gives -1 and scale gives
  `int8(round_half_away(((occ - float32(free)) / float32(occupied - free)) * 100))`
  in float32, with the denominator subtracted in float64. Any pixel with
  alpha < 255 becomes -1. Raw: `int8(g)` with wrap-around; values < 0 or
  > 100 become -1; alpha and the thresholds are ignored.

  Args:
    image: integer 0..255 pixels in image order (row 0 = top): [H, W] gray,
      [H, W, 3] RGB (reduced with ITU-R 601 luma, see the module docstring),
      or [H, W, 2] gray+alpha / [H, W, 4] RGBA when `alpha` is None.
    alpha: optional integer 0..255 [H, W] alpha channel (255 = opaque).
    mode: "trinary", "scale" or "raw" (case-insensitive).
    occupied_thresh: in [0, 1], occupancy at or above which a cell is 100.
    free_thresh: in [0, 1], < occupied_thresh; occupancy at or below which a
      cell is 0.
    negate: true (any non-zero int) makes dark pixels free.

  Returns:
    int8 [H, W] grid values -1..100, flipped so grid row r is image row H-1-r.

  Raises:
    ValueError: bad shape or dtype, pixel values outside 0..255, an alpha of
      another shape or given twice, an unknown mode, thresholds outside [0, 1]
      or free_thresh >= occupied_thresh, or a negate that is not a bool/int.
  """
  mode = _check_mode(mode)
  occ_thresh, free_thresh = _check_thresholds(occupied_thresh, free_thresh)
  if isinstance(negate, (bool, np.bool_)):
    negate = bool(negate)
  elif isinstance(negate, (int, np.integer)):
    negate = int(negate) != 0
  else:
    raise ValueError(f"negate must be a bool or an int (non-zero = true); got {negate!r}")

  img = np.asarray(image)
  if img.ndim == 3 and img.shape[2] in (2, 4):
    if alpha is not None:
      raise ValueError(f"image of shape {img.shape} already carries alpha; pass alpha=None "
                       f"or a [H, W] / [H, W, 3] image")
    img, alpha = img[..., :-1], img[..., -1]
  if img.ndim == 3 and img.shape[2] == 1:
    img = img[..., 0]
  if not (img.ndim == 2 or (img.ndim == 3 and img.shape[2] == 3)):
    raise ValueError(f"image must be [H, W] gray or [H, W, 3] RGB (or [H, W, 2] / [H, W, 4] "
                     f"with alpha); got shape {img.shape}")
  if img.shape[0] == 0 or img.shape[1] == 0:
    raise ValueError(f"image must be non-empty; got shape {img.shape}")
  img = _as_uint8("image", img)
  gray = _luma(img) if img.ndim == 3 else img
  if alpha is not None:
    alpha = np.asarray(alpha)
    if alpha.shape != gray.shape:
      raise ValueError(f"alpha must have the image's [H, W] shape {gray.shape}; got {alpha.shape}")
    alpha = _as_uint8("alpha", alpha)

  if mode == "raw":
    value = gray.view(np.int8)
    out = np.where((value < constants.OCC_GRID_FREE) | (value > constants.OCC_GRID_OCCUPIED),
                   np.int8(constants.OCC_GRID_UNKNOWN), value)
  else:
    f32 = np.float32
    n = gray.astype(f32) / f32(255.0)
    occ = n if negate else f32(1.0) - n
    occ_t, free_t = f32(occ_thresh), f32(free_thresh)
    if mode == "trinary":
      middle = np.full(gray.shape, constants.OCC_GRID_UNKNOWN, np.int8)
    else:
      denom = f32(occ_thresh - free_thresh)  # float64 subtraction, then cast (as Nav2)
      with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        x = ((occ - free_t) / denom) * f32(100.0)
        # x is float32; adding 0.5 in float64 is exact, so this is std::round on float.
        rounded = np.sign(x) * np.floor(np.abs(x.astype(np.float64)) + 0.5)
      in_between = (occ > free_t) & (occ < occ_t)
      middle = np.where(in_between, rounded, 0.0).astype(np.int8)
    out = np.where(occ >= occ_t, np.int8(constants.OCC_GRID_OCCUPIED), middle)
    out = np.where(occ <= free_t, np.int8(constants.OCC_GRID_FREE), out)
    if alpha is not None:
      out = np.where(alpha < 255, np.int8(constants.OCC_GRID_UNKNOWN), out)
  return np.ascontiguousarray(out[::-1], dtype=np.int8)


# --------------------------------------------------------------------------- YAML


def _number(doc: dict, key: str, where: str) -> float:
  if key not in doc:
    raise ValueError(f"{where}: missing required key '{key}'")
  v = doc[key]
  if isinstance(v, (int, float)) and not isinstance(v, bool):
    return float(v)
  if isinstance(v, str):  # yaml-cpp reads quoted numbers, and PyYAML reads 5e-2 as a string
    try:
      return float(v.strip())
    except ValueError:
      pass
  raise ValueError(f"{where}: key '{key}' must be a number; got {v!r}")


def _negate(doc: dict, where: str) -> bool:
  if "negate" not in doc:
    raise ValueError(f"{where}: missing required key 'negate'")
  v = doc["negate"]
  if isinstance(v, bool):
    return v
  if isinstance(v, int):
    return v != 0
  if isinstance(v, str):  # yaml-cpp tries int first, then bool
    s = v.strip()
    try:
      return int(s) != 0
    except ValueError:
      if s.lower() in _TRUE_WORDS:
        return True
      if s.lower() in _FALSE_WORDS:
        return False
  raise ValueError(f"{where}: key 'negate' must be an int (non-zero = true) or a bool; got {v!r}")


def _read_yaml(path: str) -> dict:
  try:
    with open(path, encoding="utf-8") as f:
      doc = yaml.safe_load(f)
  except (yaml.YAMLError, UnicodeDecodeError) as e:
    raise ValueError(f"{path}: invalid map YAML: {e}") from e
  except IsADirectoryError as e:
    raise ValueError(f"{path}: map YAML path is a directory, not a file") from e
  if not isinstance(doc, dict):
    raise ValueError(f"{path}: map YAML must be a mapping with keys image, resolution, origin, "
                     f"negate, occupied_thresh, free_thresh (mode optional); "
                     f"got {type(doc).__name__}")
  return doc


def _expand_home(path: str) -> str:
  # Nav2 expands only a leading "~/", and only when HOME is set.
  home = os.environ.get("HOME")
  if path.startswith("~/") and home:
    return home + path[1:]
  return path


# --------------------------------------------------------------------------- image files


def _image_pixels(path: str, where: str) -> tuple[np.ndarray, np.ndarray | None]:
  """Decodes an image file to ([H, W] gray or [H, W, 3] RGB uint8, alpha or None)."""
  try:
    with Image.open(path) as img:
      img.load()
      if "transparency" in img.info and img.mode in ("1", "L", "P", "RGB"):
        img = img.convert("RGBA")  # a tRNS colour key is an alpha channel to GraphicsMagick
      mode = img.mode
      if mode in ("I;16", "I;16L", "I;16B", "I;16N", "I"):
        wide = np.asarray(img).astype(np.int64)
        if wide.size and (wide.min() < 0 or wide.max() > 65535):
          raise ValueError(f"{mode} pixels outside 0..65535 (min {wide.min()}, max {wide.max()})")
        return ((wide + 128) // 257).astype(np.uint8), None
      if mode == "F":
        raise ValueError("floating-point images (Pillow mode F) are not supported")
      if mode in ("1", "L"):
        return np.asarray(img.convert("L")), None
      if mode in ("LA", "La"):
        la = np.asarray(img.convert("LA"))
        return la[..., 0], la[..., 1]
      if mode in ("RGBA", "RGBa", "PA"):
        rgba = np.asarray(img.convert("RGBA"))
        return rgba[..., :3], rgba[..., 3]
      return np.asarray(img.convert("RGB")), None  # RGB, RGBX, P, CMYK, YCbCr, ...
  except FileNotFoundError:
    raise
  except (OSError, SyntaxError, ValueError, Image.DecompressionBombError) as e:
    raise ValueError(f"{where}: cannot decode image file {path}: {e}") from e


def load_map(yaml_path: str | os.PathLike) -> OccupancyGrid:
  """Loads a Nav2 map (YAML + image) as map_server does (spec §10.1-10.2).

  YAML keys: `image` (relative to the YAML's directory unless absolute),
  `resolution`, `origin` ([x, y, yaw]), `free_thresh`, `occupied_thresh`,
  `negate` (int, non-zero = true, or bool) and optional `mode`
  (trinary/scale/raw, case-insensitive, default trinary). A YAML path starting
  with `~/` is expanded from $HOME when HOME is set.

  Unlike Nav2, which returns a status and does not check the values of
  resolution or the thresholds, this raises on bad input (see the module
  docstring for all deviations).

  Args:
    yaml_path: path of the map YAML file.

  Returns:
    OccupancyGrid with int8 [H, W] data (row 0 = bottom image row), the YAML's
    resolution (metres/cell) and origin (x, y, yaw), frame_id "map".

  Raises:
    FileNotFoundError: the YAML or the image file does not exist (or the path
      is empty).
    ValueError: invalid YAML; a missing key; an empty `image`; an `origin`
      that is not 3 finite numbers; an unknown `mode`; a `negate` that is not
      an int or bool; a resolution that is not finite and > 0; thresholds
      outside [0, 1] or free_thresh >= occupied_thresh; an image that cannot
      be decoded or is empty. Messages name the file and the key.
  """
  path = _expand_home(os.fspath(yaml_path))
  if not path:
    raise FileNotFoundError("map YAML file name is empty")
  if not os.path.exists(path):
    raise FileNotFoundError(f"map YAML file {path} does not exist")
  doc = _read_yaml(path)
  where = f"map YAML {path}"

  # Keys in Nav2's order, so the first problem reported is the one Nav2 hits.
  if "image" not in doc:
    raise ValueError(f"{where}: missing required key 'image'")
  image = doc["image"]
  if image is None or image == "":
    raise ValueError(f"{where}: key 'image' is empty")
  if not isinstance(image, str):
    raise ValueError(f"{where}: key 'image' must be a file name string; got {image!r}")
  image_path = image if os.path.isabs(image) else os.path.join(os.path.dirname(path), image)

  resolution = _number(doc, "resolution", where)
  if "origin" not in doc:
    raise ValueError(f"{where}: missing required key 'origin'")
  origin = doc["origin"]
  if not isinstance(origin, (list, tuple)) or len(origin) != 3:
    n = len(origin) if isinstance(origin, (list, tuple)) else type(origin).__name__
    raise ValueError(f"{where}: key 'origin' must be a sequence of 3 numbers [x, y, yaw]; got {n} "
                     f"({origin!r})")
  origin = tuple(_number({"origin": v}, "origin", where) for v in origin)
  if not all(math.isfinite(v) for v in origin):
    raise ValueError(f"{where}: key 'origin' must hold finite numbers; got {origin!r}")
  free_thresh = _number(doc, "free_thresh", where)
  occupied_thresh = _number(doc, "occupied_thresh", where)
  mode = "trinary" if "mode" not in doc else _check_mode(doc["mode"], f"{where}: key 'mode'")
  negate = _negate(doc, where)

  # Checks Nav2 does not make.
  if not (math.isfinite(resolution) and resolution > 0):
    raise ValueError(f"{where}: key 'resolution' must be a finite number > 0 (metres/cell); "
                     f"got {resolution!r}")
  _check_thresholds(occupied_thresh, free_thresh, f"{where}: ")

  if not os.path.exists(image_path):
    raise FileNotFoundError(f"{where}: image file {image_path} (key 'image') does not exist")
  if os.path.isdir(image_path):
    raise ValueError(f"{where}: key 'image' names a directory, not an image file: {image_path}")
  pixels, alpha = _image_pixels(image_path, f"{where}: key 'image'")
  if pixels.shape[0] == 0 or pixels.shape[1] == 0:
    raise ValueError(f"{where}: image file {image_path} (key 'image') is empty ({pixels.shape})")
  data = load_map_image(pixels, alpha, mode=mode, occupied_thresh=occupied_thresh,
                        free_thresh=free_thresh, negate=negate)
  return OccupancyGrid(data=data, resolution=resolution, origin=origin, frame_id="map")


# --------------------------------------------------------------------------- saving


def _yaml_scalar(s: str) -> str:
  try:
    plain_ok = yaml.safe_load(s) == s and "\n" not in s
  except yaml.YAMLError:
    plain_ok = False
  return s if plain_ok else json.dumps(s)  # a JSON string is a valid YAML double-quoted scalar


def _save_paths(path, image_format: str | None) -> tuple[str, str | None]:
  name = os.fspath(path)
  if name == "":
    name = f"map_{int(time.time())}"  # as Nav2's checkSaveParameters
  suffix = Path(name).suffix.lower()
  if suffix in _YAML_SUFFIXES:
    return name[: -len(suffix)], image_format
  if suffix[1:] in _SAVE_FORMATS:
    if image_format is not None and image_format.lower() != suffix[1:]:
      raise ValueError(f"path {name!r} ends in {suffix!r} but image_format is {image_format!r}; "
                       f"give one or make them agree")
    return name[: -len(suffix)], suffix[1:]
  return name, image_format


def _save_pixels(data: np.ndarray, mode: str, fi: int,
                 oi: int) -> tuple[np.ndarray, np.ndarray | None]:
  """Grid -> (uint8 [H, W] gray in image order, uint8 alpha or None) (spec §10.3.3)."""
  cell = data[::-1].astype(np.int16)
  invalid = (cell < constants.OCC_GRID_FREE) | (cell > constants.OCC_GRID_OCCUPIED)
  if mode == "trinary":
    gray = np.where(cell <= fi, _SAVE_FREE, np.where(cell >= oi, _SAVE_OCCUPIED, _SAVE_UNKNOWN))
    return np.where(invalid, _SAVE_UNKNOWN, gray).astype(np.uint8), None
  if mode == "scale":
    # gray = (100 - cell) / 100 at 8 bits, rounded half up; GraphicsMagick's own
    # quantum rounding may differ by 1 where 2.55 * (100 - cell) ends in .5.
    gray = ((100 - cell) * 255 + 50) // 100
    gray = np.where(invalid, 128, gray).astype(np.uint8)  # gray 0.5, fully transparent
    return gray, np.where(invalid, 0, 255).astype(np.uint8)
  return np.where(invalid, 255, cell).astype(np.uint8), None


def save_map(grid: OccupancyGrid, path: str | os.PathLike, *, mode: str = "trinary",
             free_thresh: float = 0.25, occupied_thresh: float = 0.65,
             image_format: str | None = None) -> tuple[Path, Path]:
  """Writes `<path>.yaml` and `<path>.<format>` as Nav2's map_saver does (spec §10.3).

  Thresholds equal to 0.0 mean "unset" and become occupied 0.65 / free 0.25.
  Pixels (image row y is grid row H-1-y), with `fi = rint(free * 100)` and
  `oi = rint(occupied * 100)`:
    - trinary: cell < 0 or > 100 -> 205; cell <= fi -> 254; cell >= oi -> 0;
      else 205 (the free test comes first); written 8-bit gray.
    - scale: gray = round(2.55 * (100 - cell)), opaque; an invalid cell is
      gray 128, fully transparent; written RGBA (png keeps the alpha; pgm and
      bmp cannot, so they warn and write gray only, as Nav2 warns).
    - raw: the cell value; an invalid cell -> 255; written 8-bit gray.
  The YAML holds image (base name), mode, resolution (3 decimals),
  origin [x (3 dp), y (3 dp), yaw], negate 0, and the thresholds: always
  0.65 / 0.196 for trinary, else the save thresholds to 3 decimals.

  Args:
    grid: the map; int8 [H, W] data, row 0 = lowest y.
    path: output name with or without an extension (".yaml"/".yml" or an image
      extension, which also picks the format); "" gives `map_<unix seconds>`
      in the working directory, as Nav2 does. The folder must exist.
    mode: "trinary", "scale" or "raw" (case-insensitive).
    free_thresh: in [0, 1); 0.0 means the default 0.25.
    occupied_thresh: in (free_thresh, 1]; 0.0 means the default 0.65.
    image_format: "png", "pgm" or "bmp" (case-insensitive); None gives png for
      scale and pgm otherwise.

  Returns:
    (yaml_path, image_path) of the written files.

  Raises:
    TypeError: grid is not an OccupancyGrid.
    ValueError: occupied_thresh > 1, free_thresh < 0, occupied_thresh <=
      free_thresh, non-finite thresholds, an unknown mode or image format, an
      extension that disagrees with image_format, or a grid that is not a
      non-empty 2-D integer array with finite resolution > 0 and a 2/3-number
      finite origin.
    OSError: the files cannot be written (e.g. the folder does not exist).
  """
  if not isinstance(grid, OccupancyGrid):
    raise TypeError(f"save_map expects an OccupancyGrid; got {type(grid).__name__}")
  data = np.asarray(grid.data)
  if data.ndim != 2 or data.shape[0] == 0 or data.shape[1] == 0:
    raise ValueError(f"grid data must be a non-empty 2-D [H, W] array; got shape {data.shape}")
  if not np.issubdtype(data.dtype, np.integer) or (data.min() < -128 or data.max() > 127):
    raise ValueError(f"grid data must be int8 occupancy values; got dtype {data.dtype}")
  resolution = float(grid.resolution)
  if not (math.isfinite(resolution) and resolution > 0):
    raise ValueError(f"grid resolution must be a finite number > 0; got {grid.resolution!r}")
  origin = tuple(float(v) for v in grid.origin)
  if len(origin) == 2:
    origin = (*origin, 0.0)
  if len(origin) != 3 or not all(math.isfinite(v) for v in origin):
    raise ValueError(f"grid origin must be 2 or 3 finite numbers; got {grid.origin!r}")

  mode = _check_mode(mode)
  occupied, free = float(occupied_thresh), float(free_thresh)
  if occupied == 0.0:
    occupied = 0.65
  if free == 0.0:
    free = 0.25
  if not (math.isfinite(occupied) and math.isfinite(free)):
    raise ValueError(f"thresholds must be finite; got occupied_thresh {occupied_thresh!r}, "
                     f"free_thresh {free_thresh!r}")
  if occupied > 1.0:
    raise ValueError(f"occupied_thresh must be 1.0 or less; got {occupied!r}")
  if free < 0.0:
    raise ValueError(f"free_thresh must be 0.0 or greater; got {free!r}")
  if occupied <= free:
    raise ValueError(f"free_thresh must be smaller than occupied_thresh; got free_thresh {free!r}, "
                     f"occupied_thresh {occupied!r}")

  base, image_format = _save_paths(path, image_format)
  if image_format is None or image_format == "":
    image_format = "png" if mode == "scale" else "pgm"
  image_format = image_format.lower()
  if image_format not in _SAVE_FORMATS:
    raise ValueError(f"image_format must be one of {', '.join(_SAVE_FORMATS)}; "
                     f"got {image_format!r}")
  if mode == "scale" and image_format != "png":
    warnings.warn(f"map mode 'scale' needs transparency, but format {image_format!r} cannot keep "
                  f"it here; unknown cells will load as gray 128. Consider 'png'.", stacklevel=2)

  fi = int(np.rint(free * 100.0))
  oi = int(np.rint(occupied * 100.0))
  gray, alpha = _save_pixels(data, mode, fi, oi)
  if alpha is not None and image_format == "png":
    img = Image.fromarray(np.dstack([gray, gray, gray, alpha]), mode="RGBA")
  else:
    img = Image.fromarray(gray, mode="L")
  image_path = Path(f"{base}.{image_format}")
  yaml_path = Path(f"{base}.yaml")
  img.save(image_path, format=_PIL_FORMAT[image_format])

  yaw = math.atan2(math.sin(origin[2]), math.cos(origin[2]))  # yaw -> quaternion -> yaw
  if mode == "trinary":
    occ_text, free_text = f"{_TRINARY_SAVED_OCCUPIED}", f"{_TRINARY_SAVED_FREE}"
  else:
    occ_text, free_text = f"{occupied:.3f}", f"{free:.3f}"
  text = (f"image: {_yaml_scalar(image_path.name)}\n"
          f"mode: {mode}\n"
          f"resolution: {resolution:.3f}\n"
          f"origin: [{origin[0]:.3f}, {origin[1]:.3f}, {yaw!r}]\n"
          f"negate: 0\n"
          f"occupied_thresh: {occ_text}\n"
          f"free_thresh: {free_text}\n")
  yaml_path.write_text(text, encoding="utf-8")
  return yaml_path, image_path
