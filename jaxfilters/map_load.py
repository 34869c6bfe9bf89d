"""Map loading: Nav2 map_server's `loadMapFromYaml` (docs/nav2_semantics.md §10.1-10.2).

`load_map` reads a map YAML and its image into an `OccupancyGrid` exactly as
Nav2's current (Eigen) `nav2_map_server::loadMapFromYaml` does: inclusive
float32 thresholds, free applied last, alpha < 255 meaning unknown in trinary
and scale, raw bytes wrapped to int8, and the image rows flipped so grid row 0
is the bottom image row. `load_map_with_metadata` also returns the YAML's
settings as a `MapMetadata`. `load_map_image` is the pure NumPy pixel
conversion they use. Saving lives in `jaxfilters.map_save`; `jaxfilters.map_io`
is the public face of both. The deliberate deviations from Nav2 are listed in
`jaxfilters.map_io`'s docstring.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
from typing import Any

import numpy as np

from jaxfilters import constants, validate
from jaxfilters.grid import OccupancyGrid, geometry_values as _geometry
from jaxfilters.map_decode import MAX_MAP_CELLS, MAX_YAML_BYTES, parse_map_yaml, read_image
from jaxfilters.map_decode import read_regular_file
from jaxfilters.validate import short_repr

__all__ = ["MAP_MODES", "MAX_MAP_CELLS", "MAX_YAML_BYTES", "MapMetadata", "check_mode", "gray_table",
           "load_map", "load_map_image", "load_map_with_metadata"]

# Map modes Nav2 understands (YAML `mode`, lower-cased); trinary is the default.
MAP_MODES = ("trinary", "scale", "raw")
_TRUE_WORDS = ("y", "yes", "true", "on")
_FALSE_WORDS = ("n", "no", "false", "off")
# A number written as a YAML string ("5e-2", '2.5'): what yaml-cpp's stream conversion reads.
_DECIMAL = re.compile(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?")


# --------------------------------------------------------------------------- metadata


@dataclasses.dataclass(frozen=True)
class MapMetadata:
  """The settings of a Nav2 map YAML (docs/nav2_semantics.md §10.1), as `load_map_with_metadata` read them.

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
    return cls(check_mode(mode), res, org, occ, free, _check_negate(negate), image, image_path)


# --------------------------------------------------------------------------- pixels


def check_mode(mode: Any, where: str = "mode") -> str:
  """A map mode as Nav2 reads it (lower-cased, one of MAP_MODES), or ValueError naming `where`."""
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


def gray_table(mode: str, occupied: float, free: float, negate: bool) -> np.ndarray:
  """int8 [256]: the occupancy each opaque gray 0..255 loads as (docs/nav2_semantics.md §10.2).

  Loading reads pixels through it; `map_save` inverts it for exact saves.

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
  """Converts image pixels to OccupancyGrid values, as Nav2's map_io does (docs/nav2_semantics.md §10.2).

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
  mode = check_mode(mode)
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

  out = gray_table(mode, occ_thresh, free_thresh, negate)[gray[::-1]]
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
  mode = "trinary" if "mode" not in doc else check_mode(doc["mode"], f"{where}: key 'mode'")
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
  """Loads a Nav2 map (YAML + image) as map_server does (docs/nav2_semantics.md §10.1-10.2).

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
