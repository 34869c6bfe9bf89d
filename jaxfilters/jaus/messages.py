"""Internal: the JAUS CostMap2D message types, profiles and scaled-integer fields.

The two wire versions of the messages (docs/jaus.md §0, §11 (1)-(3)) are
*profiles*:

  profile   Query / Report     MapWidth, MapHeight        data variants (vtag)
  "iop"     0xD738 / 0xD742    uint16 scaled [0, 10000] m  0 list, 1 confidence, 2 rle
  "design"  0x2C11 / 0x4C11    uint32 scaled [0, 10000] m  + 3 attractiveness (decode only)

Scaled integers (docs/jaus.md §2, §11 (4)): `int = floor((real - lo) / step + 1/2)`
with `step = (hi - lo) / (2**bits - 1)` on encode (round half up, computed
exactly in rationals from the float64 value; never clamped: a real value
outside [lo, hi] is a ValueError) and `real = int * step + lo` on decode.

The classes here are public through `jaxfilters.jaus`; the plain-named helpers
(`ScaledField`, `size_field`, `get_profile`, `check_report`, `rle_runs`,
`limit_problem`, `check_choice`) are shared with `jaus.wire` and `jaus.grid`.
"""

from __future__ import annotations

import dataclasses
import math
from fractions import Fraction
from typing import Union

import numpy as np

from jaxfilters import constants
from jaxfilters.validate import float32_values, int_values, short_repr

# Data variant names; the index is the data vtag.
VARIANTS = ("list", "confidence", "rle", "attractiveness")
# The wire name of each variant's list, and the bytes one element takes.
LIST_NAMES = ("CostDataList", "CostAndConfidenceDataList", "RunLengthEncodedDataList",
              "CostOrAttractivenessList")
ELEM_BYTES = (1, 2, 2, 1)
U16_MAX = 0xFFFF
RLE_MAX_RUN = 4095                 # the 12-bit NumberCellsSubField
# Nav2 cost each 3-bit run-length level decodes to: round(q * 254 / 7).
RLE_LEVEL_COST = np.array([0, 36, 73, 109, 145, 181, 218, 254], np.uint8)
# Cells converted at a time by table lookups (bounds the temporaries of a large grid).
LUT_BLOCK = 1 << 20


def apply_lut(table: np.ndarray, index: np.ndarray) -> np.ndarray:
  """table[index] computed a block of `LUT_BLOCK` cells at a time (same shape as index)."""
  out = np.empty(index.shape, table.dtype)
  flat, src = out.reshape(-1), np.ascontiguousarray(index).reshape(-1)
  for i in range(0, flat.size, LUT_BLOCK):
    flat[i:i + LUT_BLOCK] = table[src[i:i + LUT_BLOCK]]
  return out



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
    # docs/jaus.md §11 (2)-(3): the uint32 size range, the run-length layout and the
    # confidence scaling of 0x4C11 equal IOP's.
    "design": JausProfile("design", 0x2C11, 0x4C11, 32, (0.0, 10000.0), 4, True, True),
}



# --------------------------------------------------------------------------- scaled integers


@dataclasses.dataclass(frozen=True)
class ScaledField:
  """One scaled-integer field: `bits` unsigned bits over [lo, hi] (docs/jaus.md §2)."""
  name: str
  lo: float
  hi: float
  bits: int
  unit: str

  @property
  def max_int(self) -> int:
    """The largest integer the field holds, 2**bits - 1."""
    return (1 << self.bits) - 1

  @property
  def step(self) -> float:
    """One least significant bit in real units."""
    return (self.hi - self.lo) / self.max_int

  def check(self, value, owner: str) -> float:
    """The value as float64 after the float32 and range checks (never clamped)."""
    # A plain float well inside float32's normal range passes the float32 check; any other
    # value takes the full check (decoding thousands of tiles calls this for every field).
    if not (type(value) is float and (value == 0.0 or 1e-37 < abs(value) < 1e37)):
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
    """The real value of integer `i`: i * step + lo, kept inside [lo, hi]."""
    return min(max(i * self.step + self.lo, self.lo), self.hi)


LATITUDE = ScaledField("MapCenterLatitude", -90.0, 90.0, 32, "deg")
LONGITUDE = ScaledField("MapCenterLongitude", -180.0, 180.0, 32, "deg")
CENTER_X = ScaledField("MapCenterX", -100000.0, 100000.0, 32, "m")
CENTER_Y = ScaledField("MapCenterY", -100000.0, 100000.0, 32, "m")
ROTATION = ScaledField("MapRotation", -math.pi, math.pi, 16, "rad")
CONFIDENCE = ScaledField("Confidence", 0.0, 100.0, 8, "%")


def size_field(profile: JausProfile, name: str) -> ScaledField:
  """The MapWidth/MapHeight/MaxWidth/MaxHeight field of a profile (uint16 or uint32)."""
  return ScaledField(name, *profile.size_range, profile.size_bits, "m")


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
    for field, spec in (("x", CENTER_X), ("y", CENTER_Y), ("rotation", ROTATION)):
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
    for field, spec in (("latitude", LATITUDE), ("longitude", LONGITUDE), ("rotation", ROTATION)):
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
  def quantised(self) -> bool:
    """True for the "rle" variant, whose costs are 3-bit levels (docs/jaus.md §4).

    A decoded run-length report gives each known cell one of the eight costs
    of `RLE_LEVEL_COST`, the level's cost rather than the cost the sender
    had (a speed-mask cell of occupancy 20, cost 51, comes back as cost 73,
    occupancy 29); every other variant carries the cost byte as sent.
    """
    return self.variant == "rle"

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
    prof = get_profile(profile)
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
    check_report(report)
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
      # Index (certainty << 3 | level) into one 16-entry table, a block at a time, so a
      # decoded grid at the cell cap needs no temporary larger than a block.
      table = np.concatenate([np.full(8, constants.NO_INFORMATION, np.uint8), RLE_LEVEL_COST])
      out = np.empty(self.values.shape, np.uint8)
      flat, levels, known = out.reshape(-1), self.values.reshape(-1), self.known.reshape(-1)
      for i in range(0, flat.size, LUT_BLOCK):
        j = i + LUT_BLOCK
        flat[i:j] = table[(levels[i:j] & 7) | (known[i:j].view(np.uint8) << 3)]
      return out
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
    prof = get_profile(self.profile)
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
        object.__setattr__(self, name, size_field(prof, label).check(getattr(self, name),
                                                                      "CostMap2DQuery"))
    if self.center is not None and not isinstance(self.center, (LocalPose, GlobalPose)):
      raise TypeError(f"CostMap2DQuery: center must be a LocalPose or GlobalPose; got "
                      f"{type(self.center).__name__}")


def get_profile(name) -> JausProfile:
  """PROFILES[name]; ValueError naming the choices for anything else."""
  if not isinstance(name, str) or name not in PROFILES:
    raise ValueError(f"profile must be one of {tuple(PROFILES)}; got {short_repr(name)}")
  return PROFILES[name]



def check_choice(name: str, value, choices) -> None:
  """ValueError unless `value` is one of `choices` (an option such as mapping or axes)."""
  if value not in choices:
    raise ValueError(f"{name} must be one of {choices}; got {short_repr(value)}")


def rle_runs(values: np.ndarray, known: np.ndarray) -> np.ndarray:
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


def limit_problem(profile: JausProfile, variant: str, rows: int, cols: int,
                   map_width: float, map_height: float, num_runs: int | None) -> str | None:
  """Why a map of this size cannot go into one message (None if it can)."""
  if rows > U16_MAX or cols > U16_MAX:
    return (f"NumberOfRows and NumberOfColumns are uint16 (at most 65535); got {rows} rows x "
            f"{cols} columns")
  hi = profile.size_range[1]
  if map_width > hi or map_height > hi:
    return (f"MapWidth and MapHeight hold at most {hi:g} m; got {map_width:g} m x "
            f"{map_height:g} m")
  name = LIST_NAMES[VARIANTS.index(variant)]
  if variant == "rle":
    if num_runs is not None and num_runs > U16_MAX:
      return (f"{name} holds at most 65535 runs (its count is a uint16); this map needs "
              f"{num_runs}")
  elif rows * cols > U16_MAX:
    return (f"{name} holds at most 65535 cells (its count is a uint16); got {rows} x {cols} = "
            f"{rows * cols}")
  return None


def check_report(report: CostMap2DReport, *, count_runs: bool = True) -> JausProfile:
  """Checks a report field by field (as `create` does); returns its profile.

  `count_runs=False` skips counting the runs of an "rle" report against the
  65535-run limit, which matters only for encoding it (a pass over every cell).
  """
  prof = get_profile(report.profile)
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
    raw = np.floor(c / CONFIDENCE.step + 0.5)
    if np.any(known & (c > 0) & (raw == 0)):
      raise ValueError(f"CostMap2DReport: a confidence above 0 but below {CONFIDENCE.step / 2:.3f} % "
                       "rounds to 0 on the wire, which means 'unknown cost'; use 0 or at least "
                       f"{CONFIDENCE.step / 2:.3f} %")
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
    size_field(prof, label).check(value, "CostMap2DReport")
  runs = len(rle_runs(v, report.known)) if report.variant == "rle" and count_runs else None
  problem = limit_problem(prof, report.variant, *v.shape, 0.0, 0.0, runs)
  if problem:
    raise ValueError(f"CostMap2DReport too large for one message: {problem}; encode a window of "
                     "the map or split it with grid_to_reports(..., tiles=True)")
  return prof

