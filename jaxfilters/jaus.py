"""JAUS CostMap2D codec: ReportCostMap2D / QueryCostMap2D bytes <-> NumPy, host only.

Two public versions of the message exist and differ on the wire
(/work/shared/spec/jaus_costmap2d.md, "the note" below); both are supported as
*profiles*:

  profile   Query / Report     MapWidth, MapHeight        data variants (vtag)
  "iop"     0xD738 / 0xD742    uint16 scaled [0, 10000] m  0 list, 1 confidence, 2 rle
  "design"  0x2C11 / 0x4C11    uint32 scaled [0, 10000] m  + 3 attractiveness (decode only)

Wire rules (note §1): little-endian, no padding, a uint16 message ID first, a
uint8 vtag before a variant, a uint16 element count before a list, a uint8
presence vector (bit i = i-th optional field) first in a query. Scaled
integers (note §2): `int = floor((real - lo) / step + 1/2)` with
`step = (hi - lo) / (2**bits - 1)` on encode (round half up, computed exactly
in rationals from the float64 value; never clamped: a real value outside
[lo, hi] is a ValueError) and `real = int * step + lo` on decode. Peers built on the JAUS Tool Set truncate instead of rounding, so
nothing here requires an exact round trip: `report_to_grid` accepts any value
within [-1/2, +1] LSB of the decoded one.

Every decoder treats its input as hostile: a truncated or oversized buffer, an
unknown message ID, a bad vtag or presence bit, a count that disagrees with the
grid or with the bytes left, and a value outside a field's value set all raise
`JausDecodeError` (a ValueError) carrying the byte offset and the reason, and
nothing else escapes for `bytes` input. Allocation is bounded by the buffer:
a count is checked against the bytes left before anything is read, and a
run-length list expands to at most 4095 cells per 2 bytes read.

Cell values and occupancy (`mapping`):
  "nav2" (default)  occupancy d -> cost round_half_up(2.54 d) (Nav2's mask
                    cost, 0..254), -1 -> 255; back: round_half_up(c / 2.54),
                    an exact inverse on every cost the forward map makes.
  "fkie"            the fkie ROS/IOP bridge: cost = 2 d (0..200), -1 -> 255;
                    back: c // 2, 255 -> -1 (a cost 201..254 is refused).
Variant values from Nav2 costs: the cost list carries them unchanged; the cost
and confidence list carries known cells with confidence 100 % and unknown
cells with confidence 0 (cost 0 in "iop", where 255 is not allowed; 255 in
"design"); the run-length list keeps 3 bits (`cost_to_rle_level`) and the
certainty bit.

Geometry (`axes`): the wire lists cells from the north-west (top-left) corner,
row by row west to east, so grid row 0 (lowest y) is the last wire row. The map
centre and rotation come from the grid's origin (x, y, yaw) rotated as
nav_msgs defines it. With axes="ros" (default, what the fkie bridge does)
MapCenterX/Y are the centre's x/y and MapRotation is the yaw; with axes="ned"
(the note's reading of the JAUS local frame as north-east-down with an ENU map)
MapCenterX = y, MapCenterY = x and MapRotation = -yaw.
"""

from __future__ import annotations

import dataclasses
import math
import struct
from collections.abc import Callable
from fractions import Fraction
from typing import NamedTuple, Union

import numpy as np

from jaxfilters import constants
from jaxfilters.grid import OccupancyGrid
from jaxfilters.validate import float32_values, int_values, resolution_value, short_repr

__all__ = [
    "AXES", "MAPPINGS", "PROFILES", "RLE_LEVEL_COST", "VARIANTS", "CostMap2DQuery",
    "CostMap2DReport", "GlobalPose", "JausDecodeError", "JausProfile", "JausTile", "LocalPose",
    "cost_to_occupancy", "cost_to_rle_level", "decode", "decode_query", "decode_report",
    "encode_query", "encode_report", "from_hex", "fuzz_target", "grid_to_report",
    "grid_to_reports", "occupancy_to_cost", "report_to_grid", "rle_level_to_cost", "to_hex",
]

VARIANTS = ("list", "confidence", "rle", "attractiveness")   # index = the data vtag
_LIST_NAMES = ("CostDataList", "CostAndConfidenceDataList", "RunLengthEncodedDataList",
               "CostOrAttractivenessList")
_ELEM_BYTES = (1, 2, 2, 1)
MAPPINGS = ("nav2", "fkie")
AXES = ("ros", "ned")
U16_MAX = 0xFFFF
RLE_MAX_RUN = 4095                 # the 12-bit NumberCellsSubField
# Nav2 cost each 3-bit run-length level decodes to: round(q * 254 / 7).
RLE_LEVEL_COST = np.array([0, 36, 73, 109, 145, 181, 218, 254], np.uint8)


class JausDecodeError(ValueError):
  """Bytes that are not a valid CostMap2D message.

  Attributes:
    offset: byte offset (from the start of the message ID) where the problem
      was found.
    reason: what was wrong and what was expected.
  """

  def __init__(self, offset: int, reason: str):
    super().__init__(f"JAUS CostMap2D decode error at byte {offset}: {reason}")
    self.offset = int(offset)
    self.reason = reason


@dataclasses.dataclass(frozen=True)
class JausProfile:
  """One wire version of the CostMap2D messages.

  Attributes:
    name: "iop" or "design".
    query_id: QueryCostMap2D message ID.
    report_id: ReportCostMap2D message ID.
    size_bits: integer width of MapWidth/MapHeight and MaxWidth/MaxHeight.
    size_range: (lo, hi) metres of those scaled integers.
    num_data_variants: data vtags allowed (VARIANTS[:n]).
    query_has_resolution: the query has the MaxNumberOfRows/Columns record
      (presence bit 0) before the size record.
    unknown_in_confidence_list: cost 255 (unknown) is allowed in the cost and
      confidence list (the 2024 text says so; the IOP value set stops at 254).
  """
  name: str
  query_id: int
  report_id: int
  size_bits: int
  size_range: tuple[float, float]
  num_data_variants: int
  query_has_resolution: bool
  unknown_in_confidence_list: bool

  @property
  def variants(self) -> tuple[str, ...]:
    """The data variant names this profile allows, in vtag order."""
    return VARIANTS[:self.num_data_variants]


PROFILES = {
    "iop": JausProfile("iop", 0xD738, 0xD742, 16, (0.0, 10000.0), 3, False, False),
    # Assumptions A1-A3 of the note: the uint32 size range, the RLE layout and the
    # confidence scaling of 0x4C11 equal IOP's.
    "design": JausProfile("design", 0x2C11, 0x4C11, 32, (0.0, 10000.0), 4, True, True),
}
_BY_ID = {p.report_id: (p, "report") for p in PROFILES.values()}
_BY_ID.update({p.query_id: (p, "query") for p in PROFILES.values()})


# --------------------------------------------------------------------------- scaled integers


@dataclasses.dataclass(frozen=True)
class _Scaled:
  name: str
  lo: float
  hi: float
  bits: int
  unit: str

  @property
  def max_int(self) -> int:
    return (1 << self.bits) - 1

  @property
  def step(self) -> float:
    return (self.hi - self.lo) / self.max_int

  def check(self, value, owner: str) -> float:
    """The value as float64 after the float32 and range checks (never clamped)."""
    float32_values(value, self.name, owner=owner)
    v = float(value)
    if not self.lo <= v <= self.hi:
      raise ValueError(f"{owner}: {self.name} must lie in [{self.lo:g}, {self.hi:g}] {self.unit} "
                       f"(the scaled integer's range; values are never clamped); got {v!r}")
    return v

  def encode(self, value, owner: str) -> int:
    """Exact round half up of (value - lo) / step, in rationals (no float tie errors)."""
    v = self.check(value, owner)
    x = (Fraction(v) - Fraction(self.lo)) * self.max_int / (Fraction(self.hi) - Fraction(self.lo))
    return math.floor(x + Fraction(1, 2))

  def decode(self, i: int) -> float:
    return min(max(i * self.step + self.lo, self.lo), self.hi)


_LAT = _Scaled("MapCenterLatitude", -90.0, 90.0, 32, "deg")
_LON = _Scaled("MapCenterLongitude", -180.0, 180.0, 32, "deg")
_CX = _Scaled("MapCenterX", -100000.0, 100000.0, 32, "m")
_CY = _Scaled("MapCenterY", -100000.0, 100000.0, 32, "m")
_ROT = _Scaled("MapRotation", -math.pi, math.pi, 16, "rad")
_CONF = _Scaled("Confidence", 0.0, 100.0, 8, "%")


def _size_field(profile: JausProfile, name: str) -> _Scaled:
  return _Scaled(name, *profile.size_range, profile.size_bits, "m")


# --------------------------------------------------------------------------- value types


@dataclasses.dataclass(frozen=True)
class LocalPose:
  """CostMap2DLocalPoseRec: the map centre in the platform's local frame.

  Attributes:
    x: MapCenterX, metres in [-100000, 100000] (32-bit, 4.66e-5 m steps).
    y: MapCenterY, metres in [-100000, 100000].
    rotation: MapRotation, radians in [-pi, pi] (16-bit, 9.59e-5 rad steps).

  Raises:
    ValueError: a value that is not finite and normal in float32, or outside
      its range (never clamped).
  """
  x: float
  y: float
  rotation: float

  def __post_init__(self):
    for field, spec in (("x", _CX), ("y", _CY), ("rotation", _ROT)):
      object.__setattr__(self, field, spec.check(getattr(self, field), "LocalPose"))


@dataclasses.dataclass(frozen=True)
class GlobalPose:
  """CostMap2DGlobalPoseRec: the map centre as WGS84 latitude/longitude.

  Attributes:
    latitude: degrees in [-90, 90] (32-bit).
    longitude: degrees in [-180, 180] (32-bit).
    rotation: radians in [-pi, pi] about the global Z axis (0 = north-aligned).

  Raises:
    ValueError: a value that is not finite and normal in float32, or outside
      its range (never clamped).
  """
  latitude: float
  longitude: float
  rotation: float

  def __post_init__(self):
    for field, spec in (("latitude", _LAT), ("longitude", _LON), ("rotation", _ROT)):
      object.__setattr__(self, field, spec.check(getattr(self, field), "GlobalPose"))


Pose = Union[LocalPose, GlobalPose]


@dataclasses.dataclass(frozen=True, eq=False)
class CostMap2DReport:
  """A ReportCostMap2D message, field for field (build it with `create`).

  Arrays are in wire order: row 0 is the northmost (top) row, columns run
  west to east, so a grid with row 0 = lowest y is `values[::-1]`.

  Attributes:
    profile: "iop" or "design".
    variant: "list", "confidence", "rle" or "attractiveness".
    map_width: MapWidth, metres (the decoded scaled value).
    map_height: MapHeight, metres.
    pose: LocalPose or GlobalPose of the map centre.
    values: uint8 [R, C] what the variant carries per cell: the cost byte
      ("list": 0..254, 255 unknown; "confidence": the cost byte), the 3-bit
      cost level 0..7 ("rle"), or the raw CostOrAttractiveness byte, whose
      meaning no public text defines ("attractiveness").
    confidence: float64 [R, C] percent 0..100 ("confidence" only, else None);
      multiples of 100/255 once decoded. 0 means the cost is unknown.
    known: bool [R, C] the certainty bit ("rle" only, else None).
  """
  profile: str
  variant: str
  map_width: float
  map_height: float
  pose: Pose
  values: np.ndarray
  confidence: np.ndarray | None = None
  known: np.ndarray | None = None

  @property
  def rows(self) -> int:
    """NumberOfRows (R)."""
    return int(self.values.shape[0])

  @property
  def cols(self) -> int:
    """NumberOfColumns (C)."""
    return int(self.values.shape[1])

  @classmethod
  def create(cls, values, *, map_width: float, map_height: float, pose: Pose,
             profile: str = "iop", variant: str = "list", confidence=None,
             known=None) -> "CostMap2DReport":
    """Validates and builds a report (see the class attributes for the fields).

    Raises:
      ValueError: an unknown profile or a variant the profile lacks; values
        not a 2-D integer array in the variant's value set (cost 255 in an IOP
        confidence list, a level above 7 in "rle"); confidence or known missing,
        extra or of another shape; confidence outside 0..100 or a known cell
        whose confidence rounds to 0; a size or pose outside its scaled range;
        more cells (or runs) than one message can carry.
      TypeError: pose not a LocalPose or GlobalPose.
    """
    prof = _profile(profile)
    if variant not in prof.variants:
      raise ValueError(f"variant must be one of {prof.variants} for profile {prof.name!r}; "
                       f"got {variant!r}")
    arr = np.asarray(values)
    if arr.ndim != 2:
      raise ValueError(f"CostMap2DReport values must be a 2-D [rows, cols] array; got shape "
                       f"{arr.shape}")
    hi = 7 if variant == "rle" else 255
    int_values(arr, f"values ({variant})", lo=0, hi=hi, owner="CostMap2DReport")
    arr = np.ascontiguousarray(arr, np.uint8)
    conf = kn = None
    if variant == "confidence":
      if confidence is None:
        raise ValueError("CostMap2DReport: the 'confidence' variant needs confidence [rows, cols] "
                         "(percent 0..100)")
      float32_values(confidence, "confidence", owner="CostMap2DReport")
      conf = np.asarray(confidence, np.float64)
    elif confidence is not None:
      raise ValueError(f"CostMap2DReport: confidence is only carried by the 'confidence' variant; "
                       f"got it with {variant!r}")
    if variant == "rle":
      if known is None:
        raise ValueError("CostMap2DReport: the 'rle' variant needs known [rows, cols] (bool)")
      kn = np.asarray(known)
      if kn.dtype != bool:
        raise ValueError(f"CostMap2DReport: known must be a bool array; got dtype {kn.dtype}")
    elif known is not None:
      raise ValueError(f"CostMap2DReport: known is only carried by the 'rle' variant; got it "
                       f"with {variant!r}")
    report = cls(prof.name, variant, float(map_width), float(map_height), pose, arr,
                 None if conf is None else np.ascontiguousarray(conf),
                 None if kn is None else np.ascontiguousarray(kn))
    _check_report(report)
    return report

  def nav2_cost(self) -> np.ndarray:
    """Nav2 costs in wire order: uint8 [R, C], 0..254, 255 unknown.

    "list": the bytes as sent; "confidence": the cost, or 255 where the
    confidence is 0 or the cost is 255; "rle": `rle_level_to_cost(level)`, or
    255 where the certainty bit is 0.

    Raises:
      ValueError: the "attractiveness" variant (its semantics are not public).
    """
    if self.variant == "list":
      return self.values.copy()
    if self.variant == "confidence":
      unknown = (self.confidence == 0) | (self.values == constants.NO_INFORMATION)
      return np.where(unknown, np.uint8(constants.NO_INFORMATION), self.values)
    if self.variant == "rle":
      return np.where(self.known, RLE_LEVEL_COST[self.values], np.uint8(constants.NO_INFORMATION))
    raise ValueError("CostOrAttractiveness values have no public definition (sign convention and "
                     "reserved values are unknown), so they cannot be read as Nav2 costs; use "
                     "report.values for the raw bytes")


@dataclasses.dataclass(frozen=True)
class CostMap2DQuery:
  """A QueryCostMap2D message; a field left None is absent (its presence bit is 0).

  Attributes:
    profile: "iop" or "design".
    max_rows, max_cols: MaxNumberOfRows/Columns (uint16), "design" only; both
      or neither.
    max_width, max_height: MaxWidth/MaxHeight metres (scaled like the report's
      MapWidth/MapHeight); both or neither.
    center: requested map centre (LocalPose or GlobalPose) or None.

  Raises:
    ValueError: an unknown profile, a half-given pair, rows/columns outside
      0..65535 or given for "iop", a size outside the scaled range.
    TypeError: a center that is not a LocalPose or GlobalPose.
  """
  profile: str = "iop"
  max_width: float | None = None
  max_height: float | None = None
  max_rows: int | None = None
  max_cols: int | None = None
  center: Pose | None = None

  def __post_init__(self):
    prof = _profile(self.profile)
    if (self.max_width is None) != (self.max_height is None):
      raise ValueError("CostMap2DQuery: give both max_width and max_height (one record) or neither")
    if (self.max_rows is None) != (self.max_cols is None):
      raise ValueError("CostMap2DQuery: give both max_rows and max_cols (one record) or neither")
    if self.max_rows is not None:
      if not prof.query_has_resolution:
        raise ValueError(f"CostMap2DQuery: profile {prof.name!r} has no MaxNumberOfRows/Columns; "
                         "use profile 'design' or leave max_rows/max_cols None")
      for name in ("max_rows", "max_cols"):
        v = getattr(self, name)
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 0 <= v <= U16_MAX:
          raise ValueError(f"CostMap2DQuery: {name} must be an integer in 0..65535; "
                           f"got {short_repr(v)}")
        object.__setattr__(self, name, int(v))
    if self.max_width is not None:
      for name, label in (("max_width", "MaxWidth"), ("max_height", "MaxHeight")):
        object.__setattr__(self, name, _size_field(prof, label).check(getattr(self, name),
                                                                      "CostMap2DQuery"))
    if self.center is not None and not isinstance(self.center, (LocalPose, GlobalPose)):
      raise TypeError(f"CostMap2DQuery: center must be a LocalPose or GlobalPose; got "
                      f"{type(self.center).__name__}")


def _profile(name) -> JausProfile:
  if not isinstance(name, str) or name not in PROFILES:
    raise ValueError(f"profile must be one of {tuple(PROFILES)}; got {short_repr(name)}")
  return PROFILES[name]


# --------------------------------------------------------------------------- value mappings


def occupancy_to_cost(occupancy, *, mapping: str = "nav2") -> np.ndarray:
  """OccupancyGrid values -> Nav2 costs (see the module docstring for `mapping`).

  Args:
    occupancy: integer array of values -1..100.
    mapping: "nav2" (round_half_up(2.54 d)) or "fkie" (2 d).

  Returns:
    uint8 array of the same shape: 0..254 ("nav2") or 0..200 ("fkie"), 255 unknown.

  Raises:
    ValueError: non-integer values or values outside -1..100; unknown mapping.
  """
  _check_choice("mapping", mapping, MAPPINGS)
  d = int_values(occupancy, "occupancy", lo=-1, hi=100).astype(np.int32)
  cost = (d * 254 + 50) // 100 if mapping == "nav2" else 2 * d
  return np.where(d < 0, constants.NO_INFORMATION, cost).astype(np.uint8)


def cost_to_occupancy(cost, *, mapping: str = "nav2") -> np.ndarray:
  """Nav2 costs -> OccupancyGrid values (inverse of `occupancy_to_cost`).

  "nav2": round_half_up(c * 100 / 254), which gives back d for every cost
  `occupancy_to_cost` makes and the nearest occupancy for the others
  (253 -> 100); "fkie": c // 2. 255 -> -1 in both.

  Args:
    cost: integer array of costs 0..255.
    mapping: "nav2" or "fkie".

  Returns:
    int8 array of the same shape, values -1..100.

  Raises:
    ValueError: values outside 0..255, or ("fkie") a cost 201..254, which the
      fkie client would turn into an occupancy above 100.
  """
  _check_choice("mapping", mapping, MAPPINGS)
  c = int_values(cost, "cost", lo=0, hi=255).astype(np.int32)
  if mapping == "nav2":
    occ = (c * 200 + 254) // 508
  else:
    bad = (c > 200) & (c != constants.NO_INFORMATION)
    if np.any(bad):
      raise ValueError(f"the fkie mapping covers costs 0..200 (occupancy * 2) and 255; got cost "
                       f"{int(c[bad].flat[0])} ({int(bad.sum())} cells); use mapping='nav2'")
    occ = c // 2
  return np.where(c == constants.NO_INFORMATION, -1, occ).astype(np.int8)


def cost_to_rle_level(cost) -> np.ndarray:
  """Nav2 cost 0..254 -> the 3-bit run-length cost level 0..7, keeping each class.

  0 -> 0 (free), 254 -> 7 (non-traversable), 1..253 -> 1 + (c - 1) * 6 // 253
  (1..6), so no cost in between becomes free or lethal. Unknown (255) is
  carried by the certainty bit, not by a level.

  Raises:
    ValueError: values outside 0..254.
  """
  c = int_values(cost, "cost", lo=0, hi=254).astype(np.int32)
  level = np.where(c == 0, 0, np.where(c >= constants.LETHAL_OBSTACLE, 7, 1 + (c - 1) * 6 // 253))
  return level.astype(np.uint8)


def rle_level_to_cost(level) -> np.ndarray:
  """3-bit run-length level 0..7 -> Nav2 cost round(level * 254 / 7): 0, 36, ..., 218, 254.

  Raises:
    ValueError: values outside 0..7.
  """
  return RLE_LEVEL_COST[int_values(level, "rle level", lo=0, hi=7)]


def _check_choice(name: str, value, choices) -> None:
  if value not in choices:
    raise ValueError(f"{name} must be one of {choices}; got {short_repr(value)}")


# --------------------------------------------------------------------------- encoding


def _runs(values: np.ndarray, known: np.ndarray) -> np.ndarray:
  """uint16 [N] CostAndRunLength words (cost | certain << 3 | length << 4), row-major."""
  key = (values.ravel().astype(np.uint16) & 7) | (known.ravel().astype(np.uint16) << 3)
  if key.size == 0:
    return np.zeros((0,), np.uint16)
  starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
  lengths = np.diff(np.r_[starts, key.size])
  pieces = -(-lengths // RLE_MAX_RUN)             # runs longer than 4095 cells are split
  run_key = np.repeat(key[starts], pieces)
  run_len = np.full(run_key.shape, RLE_MAX_RUN, np.int64)
  last = np.cumsum(pieces) - 1
  run_len[last] = lengths - (pieces - 1) * RLE_MAX_RUN
  return (run_key | (run_len.astype(np.uint16) << 4)).astype(np.uint16)


def _limit_problem(profile: JausProfile, variant: str, rows: int, cols: int,
                   map_width: float, map_height: float, num_runs: int | None) -> str | None:
  """Why a map of this size cannot go into one message (None if it can)."""
  if rows > U16_MAX or cols > U16_MAX:
    return (f"NumberOfRows and NumberOfColumns are uint16 (at most 65535); got {rows} rows x "
            f"{cols} columns")
  hi = profile.size_range[1]
  if map_width > hi or map_height > hi:
    return (f"MapWidth and MapHeight hold at most {hi:g} m; got {map_width:g} m x "
            f"{map_height:g} m")
  name = _LIST_NAMES[VARIANTS.index(variant)]
  if variant == "rle":
    if num_runs is not None and num_runs > U16_MAX:
      return (f"{name} holds at most 65535 runs (its count is a uint16); this map needs "
              f"{num_runs}")
  elif rows * cols > U16_MAX:
    return (f"{name} holds at most 65535 cells (its count is a uint16); got {rows} x {cols} = "
            f"{rows * cols}")
  return None


def _check_report(report: CostMap2DReport) -> JausProfile:
  """Checks a report field by field (as `create` does); returns its profile."""
  prof = _profile(report.profile)
  if report.variant not in prof.variants:
    raise ValueError(f"variant must be one of {prof.variants} for profile {prof.name!r}; "
                     f"got {report.variant!r}")
  v = report.values
  if not isinstance(v, np.ndarray) or v.ndim != 2 or v.dtype != np.uint8:
    raise ValueError(f"CostMap2DReport values must be a uint8 [rows, cols] array (use "
                     f"CostMap2DReport.create); got {short_repr(v)}")
  if report.variant == "confidence":
    c = report.confidence
    if not isinstance(c, np.ndarray) or c.shape != v.shape:
      raise ValueError(f"CostMap2DReport: confidence must be a [rows, cols] = {v.shape} array; "
                       f"got {short_repr(c)}")
    if not np.all(np.isfinite(c)) or np.any((c < 0) | (c > 100)):
      raise ValueError("CostMap2DReport: confidence must be finite percent values in 0..100 "
                       "(never clamped)")
    if not prof.unknown_in_confidence_list and np.any(v == constants.NO_INFORMATION):
      raise ValueError(f"CostMap2DReport: profile {prof.name!r} does not allow cost 255 in the "
                       "cost and confidence list; send unknown cells as cost 0, confidence 0")
    known = v != constants.NO_INFORMATION
    raw = np.floor(c / _CONF.step + 0.5)
    if np.any(known & (c > 0) & (raw == 0)):
      raise ValueError(f"CostMap2DReport: a confidence above 0 but below {_CONF.step / 2:.3f} % "
                       "rounds to 0 on the wire, which means 'unknown cost'; use 0 or at least "
                       f"{_CONF.step / 2:.3f} %")
  if report.variant == "rle":
    if v.size and v.max() > 7:
      raise ValueError(f"CostMap2DReport: rle levels must lie in 0..7; got max {v.max()}")
    k = report.known
    if not isinstance(k, np.ndarray) or k.dtype != bool or k.shape != v.shape:
      raise ValueError(f"CostMap2DReport: known must be a bool [rows, cols] = {v.shape} array; "
                       f"got {short_repr(k)}")
  if not isinstance(report.pose, (LocalPose, GlobalPose)):
    raise TypeError(f"CostMap2DReport: pose must be a LocalPose or GlobalPose; got "
                    f"{type(report.pose).__name__}")
  for label, value in (("MapWidth", report.map_width), ("MapHeight", report.map_height)):
    _size_field(prof, label).check(value, "CostMap2DReport")
  runs = len(_runs(v, report.known)) if report.variant == "rle" else None
  problem = _limit_problem(prof, report.variant, *v.shape, 0.0, 0.0, runs)
  if problem:
    raise ValueError(f"CostMap2DReport too large for one message: {problem}; encode a window of "
                     "the map or split it with grid_to_reports(..., tiles=True)")
  return prof


def _pack_pose(pose: Pose) -> bytes:
  if isinstance(pose, GlobalPose):
    return struct.pack("<BIIH", 0, _LAT.encode(pose.latitude, "GlobalPose"),
                       _LON.encode(pose.longitude, "GlobalPose"),
                       _ROT.encode(pose.rotation, "GlobalPose"))
  return struct.pack("<BIIH", 1, _CX.encode(pose.x, "LocalPose"), _CY.encode(pose.y, "LocalPose"),
                     _ROT.encode(pose.rotation, "LocalPose"))


def encode_report(report: CostMap2DReport) -> bytes:
  """ReportCostMap2D -> bytes (message ID first, no transport header).

  Layout: uint16 ID; CostMap2DRec (uint16 rows, uint16 cols, MapWidth,
  MapHeight: uint16 "iop" / uint32 "design"); uint8 pose vtag (0 global,
  1 local) + uint32, uint32, uint16; uint8 data vtag + uint16 count + the
  elements (1 byte per cell, 2 per cell for cost + confidence, 2 per run).

  Raises:
    ValueError: any check of `CostMap2DReport.create` fails.
    NotImplementedError: the "attractiveness" variant (no public definition of
      its values; decoding keeps the raw bytes).
  """
  if not isinstance(report, CostMap2DReport):
    raise TypeError(f"encode_report expects a CostMap2DReport; got {type(report).__name__}")
  prof = _check_report(report)
  if report.variant == "attractiveness":
    raise NotImplementedError("encoding CostOrAttractivenessList is refused: no public text "
                              "defines its values (sign convention, reserved values); decode "
                              "keeps them as raw bytes")
  size_fmt = "H" if prof.size_bits == 16 else "I"
  head = struct.pack(f"<HHH{size_fmt}{size_fmt}", prof.report_id, report.rows, report.cols,
                     _size_field(prof, "MapWidth").encode(report.map_width, "CostMap2DReport"),
                     _size_field(prof, "MapHeight").encode(report.map_height, "CostMap2DReport"))
  vtag = VARIANTS.index(report.variant)
  if report.variant == "list":
    payload, count = report.values.tobytes(), report.values.size
  elif report.variant == "confidence":
    raw = np.floor(report.confidence / _CONF.step + 0.5).clip(0, 255).astype(np.uint8)
    payload = np.stack([report.values, raw], -1).tobytes()
    count = report.values.size
  else:
    words = _runs(report.values, report.known)
    payload, count = words.astype("<u2").tobytes(), len(words)
  return head + _pack_pose(report.pose) + struct.pack("<BH", vtag, count) + payload


def encode_query(query: CostMap2DQuery) -> bytes:
  """QueryCostMap2D -> bytes: uint16 ID, uint8 presence vector, the present fields.

  "iop" bits: 0 MaxWidth/MaxHeight (uint16 scaled), 1 centre. "design" bits:
  0 MaxNumberOfRows/Columns (uint16), 1 MaxWidth/MaxHeight (uint32 scaled),
  2 centre. The centre is a uint8 vtag (0 global, 1 local) + the pose record.
  """
  if not isinstance(query, CostMap2DQuery):
    raise TypeError(f"encode_query expects a CostMap2DQuery; got {type(query).__name__}")
  prof = _profile(query.profile)
  fields, bits, bit = [], 0, 0
  if prof.query_has_resolution:
    if query.max_rows is not None:
      bits |= 1 << bit
      fields.append(struct.pack("<HH", query.max_rows, query.max_cols))
    bit += 1
  if query.max_width is not None:
    bits |= 1 << bit
    fmt = "<HH" if prof.size_bits == 16 else "<II"
    fields.append(struct.pack(fmt, _size_field(prof, "MaxWidth").encode(query.max_width, "query"),
                              _size_field(prof, "MaxHeight").encode(query.max_height, "query")))
  bit += 1
  if query.center is not None:
    bits |= 1 << bit
    fields.append(_pack_pose(query.center))
  return struct.pack("<HB", prof.query_id, bits) + b"".join(fields)


# --------------------------------------------------------------------------- decoding


class _Reader:
  """Bounds-checked little-endian reads over one buffer."""

  def __init__(self, data: bytes):
    self.data = data
    self.pos = 0

  def left(self) -> int:
    return len(self.data) - self.pos

  def need(self, n: int, what: str) -> int:
    if n > self.left():
      raise JausDecodeError(self.pos, f"truncated: {what} needs {n} bytes, {self.left()} left")
    start = self.pos
    self.pos += n
    return start

  def unpack(self, fmt: str, what: str) -> tuple:
    start = self.need(struct.calcsize(fmt), what)
    return struct.unpack_from(fmt, self.data, start)


def _read_pose(r: _Reader, what: str) -> Pose:
  at = r.pos
  (vtag,) = r.unpack("<B", f"{what} vtag")
  if vtag > 1:
    raise JausDecodeError(at, f"{what} vtag {vtag} is not 0 (global pose) or 1 (local pose)")
  a, b, rot = r.unpack("<IIH", "CostMap2DGlobalPoseRec" if vtag == 0 else "CostMap2DLocalPoseRec")
  if vtag == 0:
    return GlobalPose(_LAT.decode(a), _LON.decode(b), _ROT.decode(rot))
  return LocalPose(_CX.decode(a), _CY.decode(b), _ROT.decode(rot))


def _read_report(r: _Reader, prof: JausProfile, max_cells: int | None) -> CostMap2DReport:
  size_fmt = "H" if prof.size_bits == 16 else "I"
  rows, cols, w, h = r.unpack(f"<HH{size_fmt}{size_fmt}", "CostMap2DRec")
  pose = _read_pose(r, "CostMap2DPoseVar")
  at = r.pos
  (vtag,) = r.unpack("<B", "CostMap2DDataVar vtag")
  if vtag >= prof.num_data_variants:
    raise JausDecodeError(at, f"CostMap2DDataVar vtag {vtag} is not one of 0..{prof.num_data_variants - 1} "
                          f"{prof.variants} of profile {prof.name!r} (message ID 0x{prof.report_id:04X})")
  variant, name = VARIANTS[vtag], _LIST_NAMES[vtag]
  at = r.pos
  (count,) = r.unpack("<H", f"{name} count")
  nbytes = count * _ELEM_BYTES[vtag]
  if nbytes > r.left():
    raise JausDecodeError(at, f"{name} count {count} needs {nbytes} bytes, only {r.left()} left")
  cells = rows * cols
  if variant != "rle" and count != cells:
    raise JausDecodeError(at, f"{name} count {count} != NumberOfRows x NumberOfColumns = "
                          f"{rows} x {cols} = {cells}")
  if max_cells is not None and cells > max_cells:
    raise JausDecodeError(2, f"{rows} x {cols} = {cells} cells exceeds max_cells={max_cells}")
  start = r.need(nbytes, name)
  confidence = known = None
  if variant == "rle":
    words = np.frombuffer(r.data, "<u2", count, start).astype(np.uint16)
    lengths = (words >> 4).astype(np.int64)
    total = int(lengths.sum())
    if total != cells:
      raise JausDecodeError(at, f"{name}: the runs cover {total} cells, but NumberOfRows x "
                            f"NumberOfColumns = {rows} x {cols} = {cells}")
    values = np.repeat((words & 7).astype(np.uint8), lengths).reshape(rows, cols)
    known = np.repeat((words & 8) != 0, lengths).reshape(rows, cols)
  elif variant == "confidence":
    pairs = np.frombuffer(r.data, np.uint8, nbytes, start).reshape(count, 2)
    if not prof.unknown_in_confidence_list:
      bad = np.flatnonzero(pairs[:, 0] == constants.NO_INFORMATION)
      if bad.size:
        raise JausDecodeError(start + 2 * int(bad[0]), f"{name}: cost 255 is not allowed in profile "
                              f"{prof.name!r} (value set 0..254; unknown is confidence 0)")
    values = pairs[:, 0].reshape(rows, cols).copy()
    confidence = (pairs[:, 1].astype(np.float64) * _CONF.step).reshape(rows, cols)
  else:
    values = np.frombuffer(r.data, np.uint8, count, start).reshape(rows, cols).copy()
  size = _size_field(prof, "MapWidth")
  return CostMap2DReport(prof.name, variant, size.decode(w), size.decode(h), pose, values,
                         confidence, known)


def _read_query(r: _Reader, prof: JausProfile) -> CostMap2DQuery:
  at = r.pos
  (pv,) = r.unpack("<B", "presence vector")
  num_optional = 3 if prof.query_has_resolution else 2
  if pv >> num_optional:
    raise JausDecodeError(at, f"presence vector 0x{pv:02X} sets bits above bit {num_optional - 1}; "
                          f"QueryCostMap2D (profile {prof.name!r}) has {num_optional} optional fields")
  kw, bit = {}, 0
  if prof.query_has_resolution:
    if pv & 1:
      kw["max_rows"], kw["max_cols"] = r.unpack("<HH", "QueryCostMap2DResolutionRec")
    bit = 1
  if pv >> bit & 1:
    fmt = "<HH" if prof.size_bits == 16 else "<II"
    w, h = r.unpack(fmt, "QueryCostMap2DRec (MaxWidth, MaxHeight)")
    size = _size_field(prof, "MaxWidth")
    kw["max_width"], kw["max_height"] = size.decode(w), size.decode(h)
  if pv >> (bit + 1) & 1:
    kw["center"] = _read_pose(r, "QueryCostMap2DCenterVar")
  return CostMap2DQuery(prof.name, **kw)


def decode(data: bytes, *, max_cells: int | None = None) -> CostMap2DReport | CostMap2DQuery:
  """Bytes of one CostMap2D message (ID first) -> CostMap2DReport or CostMap2DQuery.

  The profile comes from the message ID. Decoded reals are `int * step + lo`
  exactly; nothing requires them to round-trip (a JTS peer truncates).

  Args:
    data: bytes, bytearray or memoryview of exactly one message.
    max_cells: optional cap on rows x columns of a report (the run-length list
      can describe up to 4095 cells per 2 bytes).

  Returns:
    The message; `values` arrays are new, writable copies.

  Raises:
    JausDecodeError: anything wrong with the bytes (offset and reason given):
      too short, bytes left over, an unknown message ID, a vtag or presence bit
      the profile does not define, a count that disagrees with the bytes left
      or with NumberOfRows x NumberOfColumns, runs that do not cover the grid,
      cost 255 in an IOP cost and confidence list.
    TypeError: data that is not bytes-like.
  """
  if not isinstance(data, (bytes, bytearray, memoryview)):
    raise TypeError(f"decode expects bytes; got {type(data).__name__}")
  r = _Reader(bytes(data))
  (msg_id,) = r.unpack("<H", "message ID")
  if msg_id not in _BY_ID:
    known = ", ".join(f"0x{i:04X}" for i in sorted(_BY_ID))
    raise JausDecodeError(0, f"message ID 0x{msg_id:04X} is not a CostMap2D message (expected "
                          f"one of {known})")
  prof, kind = _BY_ID[msg_id]
  msg = _read_report(r, prof, max_cells) if kind == "report" else _read_query(r, prof)
  if r.left():
    raise JausDecodeError(r.pos, f"{r.left()} bytes left over after the end of the message")
  return msg


def decode_report(data: bytes, *, max_cells: int | None = None) -> CostMap2DReport:
  """`decode`, requiring a ReportCostMap2D (a query raises JausDecodeError at byte 0)."""
  msg = decode(data, max_cells=max_cells)
  if not isinstance(msg, CostMap2DReport):
    raise JausDecodeError(0, f"expected a ReportCostMap2D; got a QueryCostMap2D (profile "
                          f"{msg.profile!r})")
  return msg


def decode_query(data: bytes) -> CostMap2DQuery:
  """`decode`, requiring a QueryCostMap2D (a report raises JausDecodeError at byte 0)."""
  msg = decode(data)
  if not isinstance(msg, CostMap2DQuery):
    raise JausDecodeError(0, f"expected a QueryCostMap2D; got a ReportCostMap2D (profile "
                          f"{msg.profile!r})")
  return msg


def fuzz_target(data: bytes) -> None:
  """Input-fuzzer entry: decodes `data`; only JausDecodeError may escape."""
  decode(data)


def to_hex(data: bytes, *, per_line: int = 16) -> str:
  """Bytes -> lower-case hex pairs separated by spaces, `per_line` pairs a line."""
  h = bytes(data).hex()
  pairs = [h[i:i + 2] for i in range(0, len(h), 2)]
  lines = [" ".join(pairs[i:i + per_line]) for i in range(0, len(pairs), per_line)]
  return "\n".join(lines) + "\n"


def from_hex(text: str) -> bytes:
  """Hex text (pairs, any whitespace between them) -> bytes.

  Raises:
    ValueError: a character that is not a hex digit or whitespace, or an odd
      number of digits.
  """
  try:
    return bytes.fromhex(text)
  except ValueError as e:
    raise ValueError(f"invalid hex text ({e}); expected hex digit pairs separated by "
                     "whitespace") from None


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


def _window_report(grid, window, res, origin, prof, variant, mapping, axes, pose, confidence):
  col, row, width, height = window
  occ = grid.data[row:row + height, col:col + width]
  cost = occupancy_to_cost(occ, mapping=mapping)[::-1]
  conf = None if confidence is None else confidence[row:row + height, col:col + width][::-1]
  values, conf, known = _variant_arrays(cost, variant, prof, conf)
  map_w, map_h = width * res, height * res
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
                    tiles: bool | Callable[[int, int], tuple[int, int]] = False) -> list[JausTile]:
  """An OccupancyGrid (or a window of it) -> ReportCostMap2D messages.

  Args:
    grid: the map; int8 [H, W] values -1..100, row 0 = lowest y.
    window: (col, row, width, height) in cells, (col, row) the lower-left cell;
      None for the whole grid. Must lie inside the grid (never clipped).
    profile: "iop" or "design".
    variant: "list", "confidence" or "rle".
    mapping: "nav2" or "fkie" occupancy -> cost (module docstring).
    axes: "ros" or "ned" (module docstring).
    pose: a GlobalPose to send instead of the local pose computed from the
      grid's origin (single message only: tile centres cannot be derived).
    confidence: optional float [H, W] percent per grid cell (grid order) for
      the "confidence" variant; unknown cells always send 0. Default 100.
    tiles: False: the window must fit one message; True: split it (halving
      the longer side) until every piece fits; a function (rows, cols) ->
      (tile_rows, tile_cols): split into tiles of that size, row-major from the
      lower-left, edge tiles smaller.

  Returns:
    [JausTile(window, report)], one per message, each with its own centre.

  Raises:
    ValueError: a bad option, window, grid or confidence; a tile or a map too
      large for one message (the message names the limit: 65535 cells in a
      list, 65535 runs, 65535 rows or columns, 10000 m); a centre outside
      +-100000 m.
    NotImplementedError: variant "attractiveness".
  """
  prof = _profile(profile)
  _check_choice("mapping", mapping, MAPPINGS)
  _check_choice("axes", axes, AXES)
  if variant not in prof.variants:
    raise ValueError(f"variant must be one of {prof.variants} for profile {prof.name!r}; "
                     f"got {short_repr(variant)}")
  if variant == "attractiveness":
    raise NotImplementedError("encoding CostOrAttractivenessList is refused: no public text "
                              "defines its values (sign convention, reserved values)")
  res, origin = _grid_geometry(grid, "grid_to_reports")
  win = _check_window(grid, window)
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
      runs = len(_runs(values, known))
    return _limit_problem(prof, variant, height, width, width * res, height * res, runs)

  windows = []
  if tiles is False or tiles is None:
    why = problem(win)
    if why:
      raise ValueError(f"map window of {win[2]} x {win[3]} cells (width x height) does not fit one "
                       f"ReportCostMap2D: {why}; encode a smaller window (CLI: --window) or "
                       "split it into tiles (tiles=True)")
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
  return [JausTile(w, _window_report(grid, w, res, origin, prof, variant, mapping, axes, pose,
                                     confidence)) for w in windows]


def grid_to_report(grid: OccupancyGrid, **options) -> CostMap2DReport:
  """One ReportCostMap2D of a grid or window; refuses a map that needs tiles.

  Takes the options of `grid_to_reports` except `tiles`.

  Raises:
    ValueError: as `grid_to_reports` (a map too large names the limit).
  """
  if "tiles" in options:
    raise ValueError("grid_to_report makes one message; use grid_to_reports(..., tiles=...)")
  return grid_to_reports(grid, **options)[0].report


def _simplest(lo: float, hi: float, target: float) -> float:
  """The decimal with the fewest digits in [lo, hi], nearest `target` among those."""
  for digits in range(0, 16):
    scale = 10.0 ** digits
    a, b = math.ceil(lo * scale - 1e-9), math.floor(hi * scale + 1e-9)
    if a <= b:
      return min(max(round(target * scale), a), b) / scale
  return target


def _tolerance(value: float, step: float) -> tuple[float, float]:
  """Reals a rounding (+-step/2) or truncating (+step) peer may have sent as `value`."""
  return value - step / 2, value + step


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
  prof = _check_report(report)
  _check_choice("mapping", mapping, MAPPINGS)
  _check_choice("axes", axes, AXES)
  if report.rows == 0 or report.cols == 0:
    raise ValueError(f"report has {report.rows} rows x {report.cols} columns; an OccupancyGrid "
                     "needs at least one cell")
  occ = cost_to_occupancy(report.nav2_cost(), mapping=mapping)[::-1]
  size_step = _size_field(prof, "MapWidth").step
  w_lo, w_hi = _tolerance(report.map_width, size_step)
  h_lo, h_hi = _tolerance(report.map_height, size_step)
  lo = max(w_lo / report.cols, h_lo / report.rows, 0.0)
  hi = min(w_hi / report.cols, h_hi / report.rows)
  if resolution is not None:
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
    res = _simplest(lo, hi, (lo + hi) / 2) if snap else report.map_width / report.cols
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
    rot = _simplest(*_tolerance(p.rotation, _ROT.step), p.rotation) if snap else p.rotation
    cx, cy, yaw = (p.x, p.y, rot) if axes == "ros" else (p.y, p.x, -rot)
  dx, dy = _rot(yaw, res * report.cols / 2, res * report.rows / 2)
  ox, oy = cx - dx, cy - dy
  if snap and center is None:
    # The centre's error carries over to the origin unchanged (same rotation and size).
    ox, oy = (_simplest(*_tolerance(v, _CX.step), v) for v in (ox, oy))
  return OccupancyGrid.create(occ, res, (ox, oy, yaw), frame_id)

