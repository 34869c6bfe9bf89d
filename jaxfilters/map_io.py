"""Map I/O: Nav2 map_server loading and map_saver writing (spec §10).

`load_map` reads a map YAML and its image into an `OccupancyGrid` exactly as
Nav2's current (Eigen) `nav2_map_server::loadMapFromYaml` does: inclusive
float32 thresholds, free applied last, alpha < 255 meaning unknown in trinary
and scale, raw bytes wrapped to int8, and the image rows flipped so grid row 0
is the bottom image row. `load_map_with_metadata` also returns the YAML's
settings as a `MapMetadata`. `load_map_image` is the pure NumPy pixel
conversion they use. `save_map` writes `<name>.yaml` + image the way
`map_saver` does, or, given a `MapMetadata`, so that the map loads back exactly.

Deliberate deviations from Nav2 (the project's issue asks for loud failures):
  - Bad input raises instead of returning a load status: `FileNotFoundError`
    for a missing YAML or image, `ValueError` (naming the file and the key)
    for everything else, whatever the files contain.
  - Nav2 does not check `resolution` or the thresholds when loading; we
    require resolution and origin to be finite and normal in float32 (the
    device's precision; resolution > 0), thresholds in [0, 1] and
    `free_thresh < occupied_thresh` (so Nav2's "free wins" order is only
    visible when both thresholds round to the same float32).
  - Files are read strictly (`jaxfilters.map_decode`): regular files only;
    YAML at most `MAX_YAML_BYTES`, without aliases, merge keys or duplicate
    keys; images PNG, Netpbm (P1-P6) or uncompressed BMP only, at most
    `MAX_MAP_CELLS` cells, complete and uncorrupted (PNG CRCs and zlib stream,
    exact Netpbm raster sizes, samples <= maxval, palette indices inside the
    palette). Nav2 reads any format GraphicsMagick knows.
  - Colour images are reduced to gray with Pillow's ITU-R 601 luma
    (`(19595 R + 38470 G + 7471 B + 2**15) >> 16`, i.e. `convert("L")`).
    GraphicsMagick's fixed-point luma may differ from it by 1 on some colours;
    gray images and colour pixels with R = G = B are exact.
  - 16-bit gray images (PGM with maxval > 255, 16-bit gray PNG) are scaled to
    8 bits with `round(v / 257)` as a 16-bit-quantum GraphicsMagick build does;
    Pillow has already stretched PGM maxvals below 65535 to the full 16-bit
    range. 16-bit colour PNGs are reduced by Pillow to the high byte of each
    sample (GraphicsMagick rounds; they may differ by 1 before the luma).
  - Saving supports only the formats Nav2 recommends (png, pgm, bmp); Nav2
    would warn and try any format GraphicsMagick can write. Numbers are written
    with the shortest repr that reads back as the same float64 (Nav2 writes
    resolution, origin x/y and scale thresholds to 3 decimals, so 0.0004 m
    became 0.000), and the origin yaw as given (Nav2 normalises it to
    (-pi, pi] through a quaternion).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from PIL import Image

from jaxfilters import constants, validate
from jaxfilters.grid import OccupancyGrid, geometry_values as _geometry
from jaxfilters.map_decode import MAX_MAP_CELLS, MAX_YAML_BYTES, parse_map_yaml, read_image
from jaxfilters.map_decode import read_regular_file
from jaxfilters.validate import short_repr

__all__ = ["MAP_MODES", "MAX_MAP_CELLS", "MAX_YAML_BYTES", "MapMetadata", "load_map",
           "load_map_image", "load_map_with_metadata", "save_map"]

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
# A number written as a YAML string ("5e-2", '2.5'): what yaml-cpp's stream conversion reads.
_DECIMAL = re.compile(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?")


# --------------------------------------------------------------------------- metadata


@dataclasses.dataclass(frozen=True)
class MapMetadata:
  """The settings of a Nav2 map YAML (spec §10.1), as `load_map_with_metadata` read them.

  Attributes:
    mode: "trinary", "scale" or "raw" (lower-cased).
    resolution: metres per cell (the YAML's float64 value).
    origin: (x, y, yaw): metres, metres, radians; lower-left corner of cell (0, 0).
    occupied_thresh: in [0, 1]; occupancy at or above which a cell is 100.
    free_thresh: in [0, occupied_thresh); occupancy at or below which a cell is 0.
    negate: True if dark pixels are free.
    image: the YAML's `image` value as written ("" for metadata made by hand).
    image_path: the image file as load_map resolved it ("" for metadata made by hand).
  """
  mode: str
  resolution: float
  origin: tuple[float, float, float]
  occupied_thresh: float
  free_thresh: float
  negate: bool
  image: str = ""
  image_path: str = ""

  @classmethod
  def create(cls, *, resolution: float, origin=(0.0, 0.0, 0.0), mode: str = "trinary",
             occupied_thresh: float = 0.65, free_thresh: float = 0.196, negate: bool = False,
             image: str = "", image_path: str = "") -> "MapMetadata":
    """Validates and builds metadata (the checks `load_map` makes on a YAML).

    Args:
      resolution: metres per cell; finite, > 0 and a normal float32.
      origin: (x, y) or (x, y, yaw), finite and representable in float32.
      mode: "trinary", "scale" or "raw" (case-insensitive).
      occupied_thresh: in [0, 1].
      free_thresh: in [0, 1], < occupied_thresh.
      negate: bool (or an int, non-zero = true).
      image: the image name to record.
      image_path: the resolved image path to record.

    Raises:
      ValueError: any value outside the ranges above.
    """
    owner = "MapMetadata.create"
    res, org = _geometry(resolution, origin, owner, "resolution", "origin")
    occ, free = _check_thresholds(occupied_thresh, free_thresh)
    if not isinstance(image, str) or not isinstance(image_path, str):
      raise ValueError(f"{owner}: image and image_path must be strings; got "
                       f"{short_repr(image)}, {short_repr(image_path)}")
    return cls(_check_mode(mode), res, org, occ, free, _check_negate(negate), image, image_path)


# --------------------------------------------------------------------------- pixels


def _check_mode(mode: Any, where: str = "mode") -> str:
  if not isinstance(mode, str) or mode.lower() not in MAP_MODES:
    raise ValueError(f"{where} must be one of {'/'.join(MAP_MODES)} (case-insensitive); "
                     f"got {short_repr(mode)}")
  return mode.lower()


def _check_negate(negate: Any) -> bool:
  if isinstance(negate, (bool, np.bool_)):
    return bool(negate)
  if isinstance(negate, (int, np.integer)):
    return int(negate) != 0
  raise ValueError(f"negate must be a bool or an int (non-zero = true); got {short_repr(negate)}")


def _check_thresholds(occupied_thresh: Any, free_thresh: Any,
                      where: str = "") -> tuple[float, float]:
  """Checks 0 <= free < occupied <= 1 (finite, normal in float32); `where` names a YAML file."""
  name = (lambda key: f"key '{key}'") if where else (lambda key: key)
  out = []
  for key, v in (("occupied_thresh", occupied_thresh), ("free_thresh", free_thresh)):
    v32 = validate.float32_values(v, name(key), owner=where)
    if v32.shape != ():
      raise ValueError(f"{where + ': ' if where else ''}{name(key)} must be one number; got "
                       f"{short_repr(v)}")
    f = float(np.asarray(v, dtype=np.float64))
    if not 0.0 <= f <= 1.0:
      raise ValueError(f"{where + ': ' if where else ''}{name(key)} must lie in [0, 1]; got "
                       f"{f!r}")
    out.append(f)
  occ, free = out
  if not free < occ:
    raise ValueError(f"{where + ': ' if where else ''}{name('free_thresh')} must be < "
                     f"{name('occupied_thresh')}; got free_thresh {free!r} >= occupied_thresh "
                     f"{occ!r}")
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


def _gray_table(mode: str, occupied: float, free: float, negate: bool) -> np.ndarray:
  """int8 [256]: the occupancy each opaque gray 0..255 loads as (spec §10.2).

  Every pixel is converted independently, so one table of the 256 grays,
  computed with the exact float32 operations, is the whole conversion.
  """
  gray = np.arange(256, dtype=np.uint8)
  if mode == "raw":
    value = gray.view(np.int8)
    return np.where((value < constants.OCC_GRID_FREE) | (value > constants.OCC_GRID_OCCUPIED),
                    np.int8(constants.OCC_GRID_UNKNOWN), value).astype(np.int8)
  f32 = np.float32
  n = gray.astype(f32) / f32(255.0)
  occ = n if negate else f32(1.0) - n
  occ_t, free_t = f32(occupied), f32(free)
  if mode == "trinary":
    middle = np.full(gray.shape, constants.OCC_GRID_UNKNOWN, np.int8)
  else:
    denom = f32(occupied - free)  # float64 subtraction, then cast (as Nav2)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
      x = ((occ - free_t) / denom) * f32(100.0)
      # x is float32; adding 0.5 in float64 is exact, so this is std::round on float.
      rounded = np.sign(x) * np.floor(np.abs(x.astype(np.float64)) + 0.5)
    in_between = (occ > free_t) & (occ < occ_t)
    middle = np.where(in_between, rounded, 0.0).astype(np.int8)
  out = np.where(occ >= occ_t, np.int8(constants.OCC_GRID_OCCUPIED), middle)
  return np.where(occ <= free_t, np.int8(constants.OCC_GRID_FREE), out).astype(np.int8)


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
      cell is 0. Both must be finite and 0 or normal in float32.
    negate: true (any non-zero int) makes dark pixels free.

  Returns:
    int8 [H, W] grid values -1..100, flipped so grid row r is image row H-1-r.

  Raises:
    ValueError: bad shape or dtype, pixel values outside 0..255, an alpha of
      another shape or given twice, an unknown mode, thresholds outside [0, 1],
      free_thresh >= occupied_thresh or not a float32-representable number, or
      a negate that is not a bool/int.
  """
  mode = _check_mode(mode)
  occ_thresh, free_thresh = _check_thresholds(occupied_thresh, free_thresh)
  negate = _check_negate(negate)

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

  out = _gray_table(mode, occ_thresh, free_thresh, negate)[gray[::-1]]
  if alpha is not None and mode != "raw":
    out[alpha[::-1] < 255] = constants.OCC_GRID_UNKNOWN
  return np.ascontiguousarray(out, dtype=np.int8)


# --------------------------------------------------------------------------- YAML


def _number(value: Any, key: str, where: str) -> float:
  """A YAML number as yaml-cpp reads it (int, float, or a decimal number in a string)."""
  if isinstance(value, (int, float)) and not isinstance(value, bool):
    try:
      return float(value)
    except OverflowError:  # an int beyond float64
      raise ValueError(f"{where}: key '{key}' must be a number that fits float32; got "
                       f"{short_repr(value)}") from None
  if isinstance(value, str) and _DECIMAL.fullmatch(value.strip()):
    # yaml-cpp reads quoted numbers, and PyYAML reads 5e-2 as a string.
    return float(value.strip())
  raise ValueError(f"{where}: key '{key}' must be a number; got {short_repr(value)}")


def _required(doc: dict, key: str, where: str) -> Any:
  if key not in doc:
    raise ValueError(f"{where}: missing required key '{key}'")
  return doc[key]


def _negate(doc: dict, where: str) -> bool:
  v = _required(doc, "negate", where)
  if isinstance(v, bool):
    return v
  if isinstance(v, int):
    return v != 0
  if isinstance(v, str) and len(v) <= 32:  # yaml-cpp tries int first, then bool
    s = v.strip()
    if re.fullmatch(r"[-+]?[0-9]+", s):
      return int(s) != 0
    if s.lower() in _TRUE_WORDS:
      return True
    if s.lower() in _FALSE_WORDS:
      return False
  raise ValueError(f"{where}: key 'negate' must be an int (non-zero = true) or a bool; got "
                   f"{short_repr(v)}")


def _expand_home(path: str) -> str:
  # Nav2 expands only a leading "~/", and only when HOME is set.
  home = os.environ.get("HOME")
  if path.startswith("~/") and home:
    return home + path[1:]
  return path


def load_map_with_metadata(yaml_path: str | os.PathLike, *, max_cells: int = MAX_MAP_CELLS
                           ) -> tuple[OccupancyGrid, MapMetadata]:
  """Loads a Nav2 map (YAML + image) as map_server does and returns its settings too.

  YAML keys: `image` (relative to the YAML's directory unless absolute),
  `resolution`, `origin` ([x, y, yaw]), `free_thresh`, `occupied_thresh`,
  `negate` (int, non-zero = true, or bool) and optional `mode`
  (trinary/scale/raw, case-insensitive, default trinary). A YAML path starting
  with `~/` is expanded from $HOME when HOME is set.

  Unlike Nav2, which returns a status and does not check the values of
  resolution or the thresholds, this raises on bad input (see the module
  docstring for all deviations). The files are read strictly: the YAML must be
  a regular file of at most `MAX_YAML_BYTES` (64 KiB) without aliases or
  duplicate keys; the image a regular PNG, Netpbm or uncompressed BMP file,
  complete and uncorrupted, of at most `max_cells` cells, checked from its
  header before anything is decoded. `MAX_MAP_CELLS` is 2**26 (67,108,864,
  e.g. 8192 x 8192: a 410 m square at 5 cm per cell), which admits large real
  facility maps (a 4096 x 4096 cap would not: 300 x 150 m at 5 cm is 18 M
  cells) while bounding what a map file can make this allocate: a map at the
  cap adds about 0.2 GiB of peak memory (8-bit gray) to 0.55 GiB (RGBA PNG).

  Args:
    yaml_path: path of the map YAML file.
    max_cells: the largest width x height accepted.

  Returns:
    (grid, metadata): an OccupancyGrid with int8 [H, W] data -1..100 (row 0 =
    bottom image row), the YAML's resolution (metres/cell, float64) and origin
    (x, y, yaw), frame_id "map"; and the YAML's settings as a MapMetadata.

  Raises:
    FileNotFoundError: the YAML or the image file does not exist (or the path
      is empty).
    ValueError: anything else, for any file content: not a regular file, too
      large, invalid YAML, a missing key, an empty `image`, an `origin` that is
      not 3 numbers, resolution/origin not finite or not normal in float32
      (resolution 1e-50 becomes 0 on the device, 1e39 becomes inf), an unknown
      `mode`, a `negate` that is not an int or bool, thresholds outside [0, 1]
      or free_thresh >= occupied_thresh, an image that is truncated, corrupt,
      of an unsupported format or larger than `max_cells`. Messages name the
      file and the key and stay short.
  """
  if isinstance(max_cells, (bool, np.bool_)) or not isinstance(max_cells, (int, np.integer)) \
      or max_cells < 1:
    raise ValueError(f"max_cells must be a positive int; got {short_repr(max_cells)}")
  path = _expand_home(os.fspath(yaml_path))
  if not path:
    raise FileNotFoundError("map YAML file name is empty")
  text = read_regular_file(path, "map YAML file", max_bytes=MAX_YAML_BYTES)
  doc = parse_map_yaml(text, path)
  where = f"map YAML {path}"
  if not isinstance(doc, dict):
    raise ValueError(f"{path}: map YAML must be a mapping with keys image, resolution, origin, "
                     f"negate, occupied_thresh, free_thresh (mode optional); "
                     f"got {type(doc).__name__}")

  # Keys in Nav2's order, so the first problem reported is the one Nav2 hits.
  image = _required(doc, "image", where)
  if image is None or image == "":
    raise ValueError(f"{where}: key 'image' is empty")
  if not isinstance(image, str):
    raise ValueError(f"{where}: key 'image' must be a file name string; got {short_repr(image)}")
  if "\x00" in image:
    raise ValueError(f"{where}: key 'image' holds a NUL character: {short_repr(image)}")
  image_path = image if os.path.isabs(image) else os.path.join(os.path.dirname(path), image)

  resolution = _number(_required(doc, "resolution", where), "resolution", where)
  origin = _required(doc, "origin", where)
  if not isinstance(origin, (list, tuple)) or len(origin) != 3:
    n = len(origin) if isinstance(origin, (list, tuple)) else type(origin).__name__
    raise ValueError(f"{where}: key 'origin' must be a sequence of 3 numbers [x, y, yaw]; got {n} "
                     f"({short_repr(origin)})")
  origin = tuple(_number(v, "origin", where) for v in origin)
  free_thresh = _number(_required(doc, "free_thresh", where), "free_thresh", where)
  occupied_thresh = _number(_required(doc, "occupied_thresh", where), "occupied_thresh", where)
  mode = "trinary" if "mode" not in doc else _check_mode(doc["mode"], f"{where}: key 'mode'")
  negate = _negate(doc, where)

  # Checks Nav2 does not make, in the float32 terms the device sees.
  resolution, origin = _geometry(resolution, origin, where, "key 'resolution'", "key 'origin'")
  occupied_thresh, free_thresh = _check_thresholds(occupied_thresh, free_thresh, where)

  try:
    pixels, alpha = read_image(image_path, max_cells=max_cells)
  except FileNotFoundError:
    raise FileNotFoundError(f"{where}: image file {short_repr(image_path, 200)} (key 'image') "
                            f"does not exist") from None
  except ValueError as e:
    raise ValueError(f"{where}: key 'image': cannot decode image file "
                     f"{short_repr(image_path, 200)}: {e}") from None
  data = load_map_image(pixels, alpha, mode=mode, occupied_thresh=occupied_thresh,
                        free_thresh=free_thresh, negate=negate)
  grid = OccupancyGrid.create(data, resolution, origin, frame_id="map")
  meta = MapMetadata(mode=mode, resolution=resolution, origin=origin,
                     occupied_thresh=occupied_thresh, free_thresh=free_thresh, negate=negate,
                     image=image, image_path=image_path)
  return grid, meta


def load_map(yaml_path: str | os.PathLike) -> OccupancyGrid:
  """Loads a Nav2 map (YAML + image) as map_server does (spec §10.1-10.2).

  The same as `load_map_with_metadata(yaml_path)[0]`; see it for the YAML
  keys, the strict file checks and the `MAX_MAP_CELLS` cap.

  Args:
    yaml_path: path of the map YAML file.

  Returns:
    OccupancyGrid with int8 [H, W] data (row 0 = bottom image row), the YAML's
    resolution (metres/cell) and origin (x, y, yaw), frame_id "map".

  Raises:
    FileNotFoundError: the YAML or the image file does not exist (or the path
      is empty).
    ValueError: anything else, for any file content (see
      `load_map_with_metadata`). Messages name the file and the key.
  """
  return load_map_with_metadata(yaml_path)[0]


# --------------------------------------------------------------------------- saving


def _yaml_scalar(s: str) -> str:
  try:
    plain_ok = yaml.safe_load(s) == s and "\n" not in s
  except yaml.YAMLError:
    plain_ok = False
  return s if plain_ok else json.dumps(s)  # a JSON string is a valid YAML double-quoted scalar


def _yaml_float(x: float) -> str:
  """Shortest text that PyYAML and yaml-cpp both read back as the same float64."""
  text = repr(float(x))  # shortest round trip: '0.0004', '1e-05', '1e+22', '-0.0'
  if "e" in text:
    mantissa, exponent = text.split("e")
    if "." not in mantissa:  # YAML 1.1 floats need a dot ('1e-05' would be a string)
      mantissa += ".0"
    text = f"{mantissa}e{exponent}"  # repr's exponent is signed, as YAML 1.1 needs
  elif "." not in text:
    text += ".0"
  if yaml.safe_load(text) != float(x):  # cannot happen for finite x; never write a wrong value
    raise ValueError(f"cannot write {x!r} so that it reads back exactly")
  return text


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


def _nav2_gray(value: int, mode: str) -> int:
  """The pixel map_saver writes for one valid cell value (trinary cells are -1/0/100)."""
  if mode == "raw":
    return value if 0 <= value <= 100 else 255
  if mode == "scale":
    return ((100 - value) * 255 + 50) // 100
  return {0: _SAVE_FREE, 100: _SAVE_OCCUPIED}.get(value, _SAVE_UNKNOWN)


def _exact_pixels(data: np.ndarray, meta: MapMetadata,
                  with_alpha: bool) -> tuple[np.ndarray, np.ndarray | None]:
  """Pixels that `load_map_image` turns back into exactly `data` under `meta`'s settings.

  For each cell value, the gray map_saver would write (inverted for negate) if
  it loads back as that value, else the nearest gray that does. Unknown cells
  in scale mode are transparent, as map_saver writes them.

  Raises:
    ValueError: a value no pixel loads back as (e.g. 37 in trinary, unknown
      cells in scale mode without alpha, or thresholds too close together).
  """
  table = _gray_table(meta.mode, meta.occupied_thresh, meta.free_thresh, meta.negate)
  grays = np.arange(256)
  lut_gray = np.zeros(256, np.uint8)  # indexed by cell value + 128
  lut_alpha = np.full(256, 255, np.uint8)
  for value in np.unique(data).tolist():
    if meta.mode == "scale" and value == constants.OCC_GRID_UNKNOWN:
      if not with_alpha:
        raise ValueError("cannot save unknown (-1) cells in scale mode without transparency; "
                         "save as png")
      lut_gray[value + 128], lut_alpha[value + 128] = 128, 0
      continue
    hits = grays[table == value]
    if hits.size == 0:
      raise ValueError(f"cannot save cell value {value}: no 8-bit gray loads back as {value} in "
                       f"{meta.mode} mode with occupied_thresh {meta.occupied_thresh!r}, "
                       f"free_thresh {meta.free_thresh!r}, negate {int(meta.negate)}")
    preferred = _nav2_gray(value, meta.mode)
    if meta.negate and meta.mode != "raw":
      preferred = 255 - preferred
    lut_gray[value + 128] = hits[np.argmin(np.abs(hits - preferred))]
  index = data[::-1].astype(np.int16) + 128
  alpha = lut_alpha[index] if meta.mode == "scale" and with_alpha else None
  return lut_gray[index], alpha


def _save_settings(mode, occupied_thresh, free_thresh) -> tuple[str, float, float]:
  """Nav2's checkSaveParameters: mode and thresholds (0.0 means the default)."""
  mode = _check_mode("trinary" if mode is None else mode)
  occupied = 0.65 if occupied_thresh is None else occupied_thresh
  free = 0.25 if free_thresh is None else free_thresh
  for name, v in (("occupied_thresh", occupied), ("free_thresh", free)):
    validate.float32_values(v, name)
    if np.ndim(v) != 0:
      raise ValueError(f"{name} must be one number; got {short_repr(v)}")
  occupied, free = float(occupied), float(free)
  occupied = 0.65 if occupied == 0.0 else occupied
  free = 0.25 if free == 0.0 else free
  if occupied > 1.0:
    raise ValueError(f"occupied_thresh must be 1.0 or less; got {occupied!r}")
  if free < 0.0:
    raise ValueError(f"free_thresh must be 0.0 or greater; got {free!r}")
  if occupied <= free:
    raise ValueError(f"free_thresh must be smaller than occupied_thresh; got free_thresh {free!r}, "
                     f"occupied_thresh {occupied!r}")
  return mode, occupied, free


def _check_metadata(metadata: Any, grid_res: float, grid_origin: tuple, mode, occupied_thresh,
                    free_thresh) -> MapMetadata:
  if not isinstance(metadata, MapMetadata):
    raise TypeError(f"metadata must be a MapMetadata; got {type(metadata).__name__}")
  meta = MapMetadata.create(  # re-checks a hand-made or replaced instance
      resolution=metadata.resolution, origin=metadata.origin, mode=metadata.mode,
      occupied_thresh=metadata.occupied_thresh, free_thresh=metadata.free_thresh,
      negate=metadata.negate, image=metadata.image, image_path=metadata.image_path)
  for name, given, have in (("mode", mode, meta.mode),
                            ("occupied_thresh", occupied_thresh, meta.occupied_thresh),
                            ("free_thresh", free_thresh, meta.free_thresh)):
    if given is not None and (given.lower() if name == "mode" and isinstance(given, str)
                              else given) != have:
      raise ValueError(f"{name} {short_repr(given)} disagrees with metadata.{name} {have!r}; "
                       f"pass one, or dataclasses.replace(metadata, {name}=...)")
  if meta.resolution != grid_res or meta.origin != grid_origin:
    raise ValueError(f"metadata resolution/origin ({meta.resolution!r}, {meta.origin!r}) differ "
                     f"from the grid's ({grid_res!r}, {grid_origin!r}); the grid's are written, "
                     f"so make them agree with dataclasses.replace")
  return meta


def save_map(grid: OccupancyGrid, path: str | os.PathLike, *,
             metadata: MapMetadata | None = None, mode: str | None = None,
             free_thresh: float | None = None, occupied_thresh: float | None = None,
             image_format: str | None = None) -> tuple[Path, Path]:
  """Writes `<path>.yaml` and `<path>.<format>` as Nav2's map_saver does (spec §10.3).

  Without `metadata` (map_saver): mode defaults to trinary; thresholds default
  to occupied 0.65 / free 0.25, and 0.0 also means "unset". Pixels (image row
  y is grid row H-1-y), with `fi = rint(free * 100)` and
  `oi = rint(occupied * 100)`:
    - trinary: cell < 0 or > 100 -> 205; cell <= fi -> 254; cell >= oi -> 0;
      else 205 (the free test comes first); written 8-bit gray.
    - scale: gray = round(2.55 * (100 - cell)), opaque; an invalid cell is
      gray 128, fully transparent; written RGBA (png keeps the alpha; pgm and
      bmp cannot, so they warn and write gray only, as Nav2 warns).
    - raw: the cell value; an invalid cell -> 255; written 8-bit gray.
  The YAML holds image (base name), mode, resolution, origin [x, y, yaw],
  negate 0, and the thresholds: always 0.65 / 0.196 for trinary, else the
  save thresholds. Like map_saver this is lossy (trinary thresholds the
  cells; scale with thresholds other than 1.0 / 0.0 shifts them).

  With `metadata` (e.g. from `load_map_with_metadata`): the YAML gets its
  mode, thresholds (0.0 is a real value here) and negate, and every pixel is
  chosen so that `load_map` of the written YAML returns exactly `grid.data`:
  map_saver's pixel where it loads back right (inverted for negate), else the
  nearest gray that does. A value no pixel can reproduce raises instead.

  Numbers are written with Python's shortest round-trip repr (0.0004 stays
  0.0004; Nav2 writes 3 decimals), so resolution, origin and thresholds read
  back as the same float64.

  Args:
    grid: the map; int8 [H, W] data, row 0 = lowest y; resolution and origin
      finite and normal in float32.
    path: output name with or without an extension (".yaml"/".yml" or an image
      extension, which also picks the format); "" gives `map_<unix seconds>`
      in the working directory, as Nav2 does. The folder must exist.
    metadata: the map settings to write back; its resolution and origin must
      equal the grid's. Explicit `mode`/thresholds must agree with it.
    mode: "trinary", "scale" or "raw" (case-insensitive); default trinary.
    free_thresh: in [0, 1); without metadata 0.0 or None means 0.25.
    occupied_thresh: in (free_thresh, 1]; without metadata 0.0 or None means
      0.65.
    image_format: "png", "pgm" or "bmp" (case-insensitive); None takes the
      path's extension, then metadata.image's, then png for scale and pgm
      otherwise.

  Returns:
    (yaml_path, image_path) of the written files.

  Raises:
    TypeError: grid is not an OccupancyGrid, or metadata not a MapMetadata.
    ValueError: occupied_thresh > 1, free_thresh < 0, occupied_thresh <=
      free_thresh, thresholds not finite / normal in float32, an unknown mode
      or image format, an extension that disagrees with image_format, a grid
      that is not a non-empty 2-D integer array with a valid resolution and
      origin, metadata that disagrees with the grid or the arguments, or (with
      metadata) a cell value that cannot be written so it loads back. Nothing
      is written when it raises.
    OSError: the files cannot be written (e.g. the folder does not exist).
  """
  if not isinstance(grid, OccupancyGrid):
    raise TypeError(f"save_map expects an OccupancyGrid; got {type(grid).__name__}")
  data = np.asarray(grid.data)
  if data.ndim != 2 or data.shape[0] == 0 or data.shape[1] == 0:
    raise ValueError(f"grid data must be a non-empty 2-D [H, W] array; got shape {data.shape}")
  if not np.issubdtype(data.dtype, np.integer) or (data.min() < -128 or data.max() > 127):
    raise ValueError(f"grid data must be int8 occupancy values; got dtype {data.dtype}")
  resolution, origin = _geometry(grid.resolution, grid.origin, "grid", "resolution", "origin")

  if metadata is not None:
    meta = _check_metadata(metadata, resolution, origin, mode, occupied_thresh, free_thresh)
    mode, occupied, free = meta.mode, meta.occupied_thresh, meta.free_thresh
  else:
    meta = None
    mode, occupied, free = _save_settings(mode, occupied_thresh, free_thresh)

  base, image_format = _save_paths(path, image_format)
  if not image_format and meta is not None:
    suffix = Path(meta.image).suffix.lower()[1:]
    image_format = suffix if suffix in _SAVE_FORMATS else None
  if image_format is None or image_format == "":
    image_format = "png" if mode == "scale" else "pgm"
  image_format = image_format.lower()
  if image_format not in _SAVE_FORMATS:
    raise ValueError(f"image_format must be one of {', '.join(_SAVE_FORMATS)}; "
                     f"got {image_format!r}")

  if meta is not None:
    gray, alpha = _exact_pixels(data, meta, with_alpha=image_format == "png")
  else:
    if mode == "scale" and image_format != "png":
      warnings.warn(f"map mode 'scale' needs transparency, but format {image_format!r} cannot "
                    f"keep it here; unknown cells will load as gray 128. Consider 'png'.",
                    stacklevel=2)
    fi = int(np.rint(free * 100.0))
    oi = int(np.rint(occupied * 100.0))
    gray, alpha = _save_pixels(data, mode, fi, oi)

  image_path = Path(f"{base}.{image_format}")
  yaml_path = Path(f"{base}.yaml")
  if mode == "trinary" and meta is None:
    occ_text, free_text = f"{_TRINARY_SAVED_OCCUPIED}", f"{_TRINARY_SAVED_FREE}"
  else:
    occ_text, free_text = _yaml_float(occupied), _yaml_float(free)
  text = (f"image: {_yaml_scalar(image_path.name)}\n"
          f"mode: {mode}\n"
          f"resolution: {_yaml_float(resolution)}\n"
          f"origin: [{', '.join(_yaml_float(v) for v in origin)}]\n"
          f"negate: {int(meta.negate) if meta is not None else 0}\n"
          f"occupied_thresh: {occ_text}\n"
          f"free_thresh: {free_text}\n")

  if alpha is not None and image_format == "png":
    img = Image.fromarray(np.dstack([gray, gray, gray, alpha]), mode="RGBA")
  else:
    img = Image.fromarray(gray, mode="L")
  img.save(image_path, format=_PIL_FORMAT[image_format])
  yaml_path.write_text(text, encoding="utf-8")
  return yaml_path, image_path
