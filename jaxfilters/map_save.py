"""Map saving: Nav2 map_saver's `saveMapToFile` (docs/nav2_semantics.md §10.3).

`save_map` writes `<name>.yaml` + image the way `map_saver` does, or, given a
`MapMetadata`, so that `map_load.load_map` reads the map back exactly. The
deliberate deviations from Nav2 are listed in `jaxfilters.map_io`'s docstring.
"""

from __future__ import annotations

import json
import os
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from PIL import Image

from jaxfilters import constants, validate
from jaxfilters.grid import OccupancyGrid, geometry_values
from jaxfilters.map_load import MapMetadata, check_mode, gray_table
from jaxfilters.validate import short_repr

__all__ = ["save_map"]

_SAVE_FORMATS = ("png", "pgm", "bmp")
_PIL_FORMAT = {"png": "PNG", "pgm": "PPM", "bmp": "BMP"}
_YAML_SUFFIXES = (".yaml", ".yml")

# Trinary pixels map_saver writes (docs/nav2_semantics.md §10.3.3).
_SAVE_OCCUPIED, _SAVE_UNKNOWN, _SAVE_FREE = 0, 205, 254
# Thresholds a trinary save always writes (#5278).
_TRINARY_SAVED_OCCUPIED, _TRINARY_SAVED_FREE = 0.65, 0.196


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
  """Grid -> (uint8 [H, W] gray in image order, uint8 alpha or None) (docs/nav2_semantics.md §10.3.3)."""
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
  table = gray_table(meta.mode, meta.occupied_thresh, meta.free_thresh, meta.negate)
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
  mode = check_mode("trinary" if mode is None else mode)
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
  """Writes `<path>.yaml` and `<path>.<format>` as Nav2's map_saver does (docs/nav2_semantics.md §10.3).

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
  resolution, origin = geometry_values(grid.resolution, grid.origin, "grid", "resolution", "origin")

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
