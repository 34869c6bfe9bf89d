"""JAUS CostMap2D codec (jaxfilters.jaus) and the `jaxfilters jaus` CLI.

Golden vectors (tests/vectors/jaus/) are built here field by field from the
layout with `struct.pack` and exact rational rounding, never by the codec; the
tests check the files, encode the documented values to exactly those bytes and
decode the bytes back to the documented values. The examples of docs/jaus.md §9 are
copied as printed. Regenerate the vector files and their README with:

    PYTHONPATH=$PWD python -m tests.jaxfilters.test_jaus
"""

from __future__ import annotations

import dataclasses
import math
import re
import struct
import tracemalloc
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxfilters import cli
from jaxfilters import jaus as J
from jaxfilters.grid import OccupancyGrid
from jaxfilters.map_io import load_map, save_map

VECTOR_DIR = Path(__file__).resolve().parents[1] / "vectors" / "jaus"
PI = math.pi   # the XML's 3.14159265358979323846, as a float64

# Cost edge cases in wire order (row 0 = north): 0 free, 253 inscribed, 254 lethal, 255 unknown.
EDGE = ((0, 253, 254, 255), (1, 127, 128, 252))
LOCAL = {"kind": "local", "x": 12.5, "y": -3.25, "rotation": PI / 4}
LOCAL_ZERO = {"kind": "local", "x": 0.0, "y": 0.0, "rotation": 0.0}   # ties: 0x80000000, 0x8000
GLOBAL = {"kind": "global", "latitude": 48.137154, "longitude": 11.576124, "rotation": -1.5}
SIZE = {"map_width": 2.0, "map_height": 1.0}        # 4 columns x 2 rows of 0.5 m


def q(value: float, lo: float, hi: float, bits: int) -> int:
  """Scaled integer: floor((v - lo) * (2**bits - 1) / (hi - lo) + 1/2), exact in rationals."""
  x = (Fraction(value) - Fraction(lo)) * (2**bits - 1) / (Fraction(hi) - Fraction(lo))
  return (x.numerator * 2 + x.denominator) // (2 * x.denominator)


def rle_level(cost: int) -> int:
  """The class-keeping 3-bit quantization of docs/jaus.md §4, written as plain branches."""
  if cost == 0:
    return 0
  if cost >= 254:
    return 7
  return 1 + ((cost - 1) * 6) // 253


def long_rle_costs() -> list[list[int]]:
  """3 x 2000 cells: 4100 free, 1 unknown, 1899 lethal, row-major (runs cross rows)."""
  flat = [0] * 4100 + [255] + [254] * 1899
  return [flat[r * 2000:(r + 1) * 2000] for r in range(3)]


def rle_words(costs) -> list[int]:
  """CostAndRunLength words (cost | certain << 3 | length << 4), runs <= 4095, by a loop."""
  words = []
  flat = [c for row in costs for c in row]
  i = 0
  while i < len(flat):
    j = i
    while j < len(flat) and flat[j] == flat[i] and j - i < 4095:
      j += 1
    known = flat[i] != 255
    words.append((rle_level(flat[i]) if known else 0) | (int(known) << 3) | ((j - i) << 4))
    i = j
  return words


CASES = {
    "iop_report_list_local": {
        "msg": "report", "profile": "iop", "variant": "list", "pose": LOCAL, **SIZE,
        "values": EDGE},
    "iop_report_list_global": {
        "msg": "report", "profile": "iop", "variant": "list", "pose": GLOBAL, **SIZE,
        "values": EDGE},
    "iop_report_confidence_local": {
        "msg": "report", "profile": "iop", "variant": "confidence", "pose": LOCAL_ZERO, **SIZE,
        # IOP forbids cost 255 here: the unknown cell is (cost 0, confidence 0).
        "values": ((0, 253, 254, 0), (1, 127, 128, 252)),
        "confidence": ((100.0, 50.0, 100.0, 0.0), (1.0, 99.5, 100.0, 25.0))},
    "iop_report_rle_local": {
        "msg": "report", "profile": "iop", "variant": "rle", "pose": LOCAL, **SIZE,
        "costs": EDGE},
    "iop_report_rle_long": {
        "msg": "report", "profile": "iop", "variant": "rle", "pose": LOCAL,
        "map_width": 100.0, "map_height": 0.15, "costs": "long"},
    "design_report_list_local": {
        "msg": "report", "profile": "design", "variant": "list", "pose": LOCAL, **SIZE,
        "values": EDGE},
    "design_report_list_global": {
        "msg": "report", "profile": "design", "variant": "list", "pose": GLOBAL, **SIZE,
        "values": EDGE},
    "design_report_confidence_local": {
        "msg": "report", "profile": "design", "variant": "confidence", "pose": LOCAL, **SIZE,
        # The 2024 text allows cost 255 (unknown) in this list; confidence is 0 there.
        "values": EDGE, "confidence": ((100.0, 50.0, 100.0, 0.0), (1.0, 99.5, 100.0, 25.0))},
    "design_report_rle_local": {
        "msg": "report", "profile": "design", "variant": "rle", "pose": LOCAL_ZERO, **SIZE,
        "costs": EDGE},
    "design_report_attractiveness_local": {
        "msg": "report", "profile": "design", "variant": "attractiveness", "pose": LOCAL, **SIZE,
        "values": ((0, 1, 127, 128), (200, 253, 254, 255))},
    "iop_query_full": {
        "msg": "query", "profile": "iop", "max_width": 20.0, "max_height": 10.0, "center": LOCAL},
    "iop_query_global_center": {"msg": "query", "profile": "iop", "center": GLOBAL},
    "iop_query_empty": {"msg": "query", "profile": "iop"},
    "design_query_full": {
        "msg": "query", "profile": "design", "max_rows": 200, "max_cols": 400,
        "max_width": 20.0, "max_height": 10.0, "center": LOCAL},
    "design_query_size_only": {
        "msg": "query", "profile": "design", "max_width": 20.0, "max_height": 20.0},
    "design_query_empty": {"msg": "query", "profile": "design"},
}

# The worked examples of docs/jaus.md §9, as printed there.
SPEC_EXAMPLES = {
    "spec_example1_design_list":
        "114c0200030095d40900b98d060001931804805eeffe7fff9f0006000000feff0a0a",
    "spec_example2_design_rle":
        "114c0200030095d40900b98d060001931804805eeffe7fff9f02040028001f0010002900",
    "spec_example3_iop_list": "42d7020003000a00070001931804805eeffe7fff9f0006000000feff0a0a",
    "spec_example4_iop_rle": "42d7020003000a00070001931804805eeffe7fff9f02040028001f0010002900",
    "spec_query_iop_full": "38d7038300830001931804805eeffe7fff9f",
    "spec_query_design_size": "112c03c800c8006f1283006f128300",
}


def case_costs(case) -> tuple[tuple[int, ...], ...]:
  costs = case["costs"]
  return tuple(tuple(r) for r in (long_rle_costs() if costs == "long" else costs))


def _pose_fields(pose: dict, label: str) -> list[tuple]:
  if pose["kind"] == "global":
    return [(f"{label} vtag", "<B", 0, "0 = CostMap2DGlobalPoseRec"),
            ("MapCenterLatitude", "<I", q(pose["latitude"], -90, 90, 32),
             f"{pose['latitude']!r} deg, scaled [-90, 90]"),
            ("MapCenterLongitude", "<I", q(pose["longitude"], -180, 180, 32),
             f"{pose['longitude']!r} deg, scaled [-180, 180]"),
            ("MapRotation", "<H", q(pose["rotation"], -PI, PI, 16),
             f"{pose['rotation']!r} rad, scaled [-pi, pi]")]
  return [(f"{label} vtag", "<B", 1, "1 = CostMap2DLocalPoseRec"),
          ("MapCenterX", "<I", q(pose["x"], -1e5, 1e5, 32), f"{pose['x']!r} m, scaled [-1e5, 1e5]"),
          ("MapCenterY", "<I", q(pose["y"], -1e5, 1e5, 32), f"{pose['y']!r} m, scaled [-1e5, 1e5]"),
          ("MapRotation", "<H", q(pose["rotation"], -PI, PI, 16),
           f"{pose['rotation']!r} rad, scaled [-pi, pi]")]


def fields(case: dict) -> list[tuple]:
  """(field, struct format, int or tuple of ints, meaning) rows of a case, in wire order."""
  iop = case["profile"] == "iop"
  bits, size_fmt = (16, "<H") if iop else (32, "<I")
  rng = f"scaled [0, 10000] m as uint{bits}"
  if case["msg"] == "query":
    rows = [("MessageID", "<H", 0xD738 if iop else 0x2C11,
             f"QueryCostMap2D ({'IOP' if iop else 'design'})")]
    has_rc, has_size, has_c = "max_rows" in case, "max_width" in case, "center" in case
    pv = (has_size | has_c << 1) if iop else (has_rc | has_size << 1 | has_c << 2)
    rows.append(("PresenceVector", "<B", pv, "bit i = i-th optional field present"))
    if has_rc:
      rows += [("MaxNumberOfRows", "<H", case["max_rows"], "plain uint16"),
               ("MaxNumberOfColumns", "<H", case["max_cols"], "plain uint16")]
    if has_size:
      rows += [("MaxWidth", size_fmt, q(case["max_width"], 0, 10000, bits),
                f"{case['max_width']!r} m, {rng}"),
               ("MaxHeight", size_fmt, q(case["max_height"], 0, 10000, bits),
                f"{case['max_height']!r} m, {rng}")]
    if has_c:
      rows += _pose_fields(case["center"], "QueryCostMap2DCenterVar")
    return rows
  vtag = ("list", "confidence", "rle", "attractiveness").index(case["variant"])
  if case["variant"] == "rle":
    costs = case_costs(case)
    nrows, ncols = len(costs), len(costs[0])
  else:
    nrows, ncols = len(case["values"]), len(case["values"][0])
  rows = [("MessageID", "<H", 0xD742 if iop else 0x4C11,
           f"ReportCostMap2D ({'IOP' if iop else 'design'})"),
          ("NumberOfRows", "<H", nrows, "plain uint16"),
          ("NumberOfColumns", "<H", ncols, "plain uint16"),
          ("MapWidth", size_fmt, q(case["map_width"], 0, 10000, bits),
           f"{case['map_width']!r} m, {rng}"),
          ("MapHeight", size_fmt, q(case["map_height"], 0, 10000, bits),
           f"{case['map_height']!r} m, {rng}")]
  rows += _pose_fields(case["pose"], "CostMap2DPoseVar")
  rows.append(("CostMap2DDataVar vtag", "<B", vtag, ["0 = CostDataList", "1 = CostAndConfidenceDataList",
                                                     "2 = RunLengthEncodedDataList",
                                                     "3 = CostOrAttractivenessList"][vtag]))
  if case["variant"] == "rle":
    words = rle_words(costs)
    rows.append(("count", "<H", len(words), "number of runs"))
    rows.append(("CostAndRunLength x count", f"<{len(words)}H", tuple(words),
                 "uint16 LE each: cost bits 0-2, certain bit 3, cells bits 4-15"))
    return rows
  flat = [v for r in case["values"] for v in r]
  rows.append(("count", "<H", len(flat), "number of cells = rows x columns"))
  if case["variant"] == "confidence":
    conf = [q(p, 0, 100, 8) for r in case["confidence"] for p in r]
    pairs = tuple(v for pair in zip(flat, conf) for v in pair)
    rows.append(("(Cost, Confidence) x count", f"<{len(pairs)}B", pairs,
                 "uint8 cost, uint8 confidence scaled [0, 100] %"))
  else:
    name = "Cost" if case["variant"] == "list" else "CostOrAttractiveness"
    rows.append((f"{name} x count", f"<{len(flat)}B", tuple(flat),
                 "uint8 each, row-major from the north-west cell"))
  return rows


def message_bytes(case: dict) -> bytes:
  out = b""
  for _, fmt, value, _ in fields(case):
    out += struct.pack(fmt, *value) if isinstance(value, tuple) else struct.pack(fmt, value)
  return out


def hex_text(data: bytes) -> str:
  h = data.hex()
  pairs = [h[i:i + 2] for i in range(0, len(h), 2)]
  return "\n".join(" ".join(pairs[i:i + 16]) for i in range(0, len(pairs), 16)) + "\n"


def _show(value) -> str:
  if isinstance(value, tuple):
    if len(value) > 12:
      return " ".join(f"0x{v:04X}" if v > 255 else str(v) for v in value[:6]) + f" ... ({len(value)} values)"
    return " ".join(f"0x{v:04X}" if v > 255 else str(v) for v in value)
  return f"{value} (0x{value:X})"


_INTRO = """# JAUS CostMap2D golden vectors

One message per `.hex` file: the JAUS message from its uint16 MessageID on
(no JUDP/transport header), as lower-case hex byte pairs separated by spaces
and newlines (`bytes.fromhex(text)` reads it). Every multi-byte integer is
**little-endian**; fields are packed without padding. Layout, profiles and
scaling: docs/jaus.md and the package jaxfilters/jaus/.

Profiles: `iop` = QueryCostMap2D 0xD738 / ReportCostMap2D 0xD742, MapWidth and
MapHeight uint16; `design` = 0x2C11 / 0x4C11, MapWidth and MapHeight uint32
(scale range [0, 10000] m assumed, as IOP).

Scaled integers: `int = floor((real - lo) * (2**bits - 1) / (hi - lo) + 1/2)`
computed exactly (round half up), `real = int * (hi - lo) / (2**bits - 1) + lo`.
Ranges: MapWidth/MapHeight/MaxWidth/MaxHeight [0, 10000] m; MapCenterX/Y
[-100000, 100000] m (uint32); MapCenterLatitude [-90, 90] deg, Longitude
[-180, 180] deg (uint32); MapRotation [-pi, pi] rad (uint16, pi =
3.141592653589793); Confidence [0, 100] % (uint8).

Cells are listed row-major from the north-west (top-left) cell; row 0 is the
northmost row. Edge costs: 0 free, 253 inscribed, 254 lethal, 255 unknown.
Run-length words: cost level bits 0-2 (Nav2 cost c -> 0 if c == 0, 7 if
c >= 254, else 1 + (c - 1) * 6 // 253), certainty bit 3 (1 known; unknown
cells send level 0), cell count bits 4-15 (runs of at most 4095 cells, which
may cross rows).

`tests/jaxfilters/test_jaus.py` builds every file field by field with `struct.pack` (the
tables below) and checks that each file equals that construction, that
jaxfilters.jaus encodes the documented values to exactly these bytes (except
the attractiveness vector, whose encoding is refused) and decodes the bytes
back to them. The `spec_*` files are the docs/jaus.md §9 worked
examples copied as printed. Regenerate with
`PYTHONPATH=$PWD python -m tests.jaxfilters.test_jaus` (then review the diff).
"""


def readme_text() -> str:
  parts = [_INTRO]
  for name, case in CASES.items():
    data = message_bytes(case)
    parts.append(f"\n## {name}.hex ({len(data)} bytes)\n")
    if case["msg"] == "report" and case["variant"] == "rle":
      costs = case_costs(case)
      desc = ("3 rows x 2000 columns of Nav2 costs: 4100 x 0, one 255, 1899 x 254 in row-major "
              "order" if case["costs"] == "long" else f"Nav2 costs (wire order) {costs}")
      parts.append(f"Run-length list of {desc}.\n")
    elif case["msg"] == "report":
      parts.append(f"Values (wire order): {case['values']}"
                   + (f"; confidence %: {case['confidence']}" if "confidence" in case else "")
                   + ".\n")
    parts.append("\n| bytes | field | format | value | meaning |\n|---|---|---|---|---|\n")
    at = 0
    for fname, fmt, value, meaning in fields(case):
      n = struct.calcsize(fmt)
      parts.append(f"| {at}-{at + n - 1} | {fname} | `{fmt}` | {_show(value)} | {meaning} |\n")
      at += n
  parts.append("\n## The worked examples of docs/jaus.md §9\n\n")
  for name, text in SPEC_EXAMPLES.items():
    parts.append(f"- `{name}.hex`: `{text}`\n")
  parts.append("\nExamples 1 and 3 carry costs [[0, 0, 254], [255, 10, 10]] (2 rows x 3 columns), "
               "MapWidth 1.5 m, MapHeight 1.0 m, local pose (12.5 m, -3.25 m, pi/4); 2 and 4 are "
               "their run-length lists (10 -> level 1). The queries: IOP max 20 m x 20 m with that "
               "local centre; design max 200 x 200 cells and 20 m x 20 m.\n")
  return "".join(parts)


def write_vectors() -> None:
  VECTOR_DIR.mkdir(parents=True, exist_ok=True)
  for name, case in CASES.items():
    (VECTOR_DIR / f"{name}.hex").write_text(hex_text(message_bytes(case)), encoding="ascii")
  for name, text in SPEC_EXAMPLES.items():
    (VECTOR_DIR / f"{name}.hex").write_text(hex_text(bytes.fromhex(text)), encoding="ascii")
  (VECTOR_DIR / "README.md").write_text(readme_text(), encoding="utf-8")




# =========================================================================== tests

VECTOR_FILES = sorted(p.stem for p in VECTOR_DIR.glob("*.hex"))


def _read_vector(name: str) -> bytes:
  return bytes.fromhex((VECTOR_DIR / f"{name}.hex").read_text(encoding="ascii"))


def _pose(d: dict | None):
  if d is None:
    return None
  if d["kind"] == "global":
    return J.GlobalPose(d["latitude"], d["longitude"], d["rotation"])
  return J.LocalPose(d["x"], d["y"], d["rotation"])


def _documented_message(case: dict):
  """The case's documented values as the codec's message object."""
  if case["msg"] == "query":
    return J.CostMap2DQuery(case["profile"], case.get("max_width"), case.get("max_height"),
                            case.get("max_rows"), case.get("max_cols"), _pose(case.get("center")))
  kw = dict(map_width=case["map_width"], map_height=case["map_height"], pose=_pose(case["pose"]),
            profile=case["profile"], variant=case["variant"])
  if case["variant"] == "rle":
    costs = case_costs(case)
    levels = [[rle_level(c) if c != 255 else 0 for c in row] for row in costs]
    known = [[c != 255 for c in row] for row in costs]
    return J.CostMap2DReport.create(np.array(levels, np.uint8), known=np.array(known), **kw)
  conf = None if "confidence" not in case else np.array(case["confidence"])
  return J.CostMap2DReport.create(np.array(case["values"], np.uint8), confidence=conf, **kw)


def test_every_vector_file_is_documented_and_built_field_by_field():
  assert set(VECTOR_FILES) == set(CASES) | set(SPEC_EXAMPLES)
  for name, case in CASES.items():
    assert _read_vector(name) == message_bytes(case), name
  for name, text in SPEC_EXAMPLES.items():
    assert _read_vector(name) == bytes.fromhex(text), name
  assert (VECTOR_DIR / "README.md").read_text(encoding="utf-8") == readme_text()


def test_scaled_integers_of_docs_jaus():
  # The table of docs/jaus.md §2 and §9, hand-checked there: these pin the rounding rule.
  assert q(1.5, 0, 10000, 32) == 0x0009D495 and q(1.0, 0, 10000, 32) == 429497
  assert q(1.5, 0, 10000, 16) == 10 and q(1.0, 0, 10000, 16) == 7
  assert q(12.5, -1e5, 1e5, 32) == 0x80041893 and q(-3.25, -1e5, 1e5, 32) == 0x7FFEEF5E
  assert q(PI / 4, -PI, PI, 16) == 0x9FFF
  assert q(0.0, -PI, PI, 16) == 0x8000 and q(0.0, -1e5, 1e5, 32) == 0x80000000   # exact ties
  assert q(50.0, 0, 100, 8) == 128 and q(100.0, 0, 100, 8) == 255


@pytest.mark.parametrize("name", sorted(CASES))
def test_encode_documented_values_gives_the_vector_bytes(name):
  case = CASES[name]
  msg = _documented_message(case)
  if case.get("variant") == "attractiveness":
    with pytest.raises(NotImplementedError, match="no public text"):
      J.encode_report(msg)
    return
  encode = J.encode_query if case["msg"] == "query" else J.encode_report
  assert encode(msg) == _read_vector(name)


def _step(lo, hi, bits):
  return (hi - lo) / (2**bits - 1)


@pytest.mark.parametrize("name", sorted(CASES))
def test_decode_vector_gives_the_documented_values(name):
  case = CASES[name]
  msg = J.decode(_read_vector(name))
  rows = {f[0]: f[2] for f in fields(case)}
  bits = 16 if case["profile"] == "iop" else 32
  assert msg.profile == case["profile"]
  if case["msg"] == "query":
    assert isinstance(msg, J.CostMap2DQuery)
    for key, wire in (("max_width", "MaxWidth"), ("max_height", "MaxHeight")):
      if key in case:
        assert getattr(msg, key) == pytest.approx(rows[wire] * _step(0, 10000, bits), rel=1e-12)
        assert abs(getattr(msg, key) - case[key]) <= _step(0, 10000, bits) / 2
      else:
        assert getattr(msg, key) is None
    assert msg.max_rows == case.get("max_rows") and msg.max_cols == case.get("max_cols")
    pose_doc = case.get("center")
    pose = msg.center
  else:
    assert isinstance(msg, J.CostMap2DReport) and msg.variant == case["variant"]
    assert (msg.rows, msg.cols) == (rows["NumberOfRows"], rows["NumberOfColumns"])
    assert msg.map_width == pytest.approx(rows["MapWidth"] * _step(0, 10000, bits), rel=1e-12)
    assert msg.map_height == pytest.approx(rows["MapHeight"] * _step(0, 10000, bits), rel=1e-12)
    if case["variant"] == "rle":
      costs = np.array(case_costs(case))
      assert np.array_equal(msg.known, costs != 255)
      assert np.array_equal(msg.values, np.vectorize(rle_level)(np.where(costs == 255, 0, costs)))
      lut = [round(k * 254 / 7) for k in range(8)]
      expect = [[255 if c == 255 else lut[rle_level(c)] for c in row] for row in case_costs(case)]
      assert np.array_equal(msg.nav2_cost(), np.array(expect))
    else:
      assert np.array_equal(msg.values, np.array(case["values"]))
    if case["variant"] == "confidence":
      raw = np.array([[q(p, 0, 100, 8) for p in r] for r in case["confidence"]])
      assert np.allclose(msg.confidence, raw * 100 / 255, rtol=0, atol=1e-12)
      assert np.all(np.abs(msg.confidence - np.array(case["confidence"])) <= 100 / 255 / 2)
    if case["variant"] == "attractiveness":
      with pytest.raises(ValueError, match="no public definition"):
        msg.nav2_cost()
    pose_doc, pose = case["pose"], msg.pose
  if pose_doc is None:
    assert pose is None
    return
  if pose_doc["kind"] == "global":
    specs = (("latitude", -90, 90, 32), ("longitude", -180, 180, 32), ("rotation", -PI, PI, 16))
    wire = ("MapCenterLatitude", "MapCenterLongitude", "MapRotation")
  else:
    specs = (("x", -1e5, 1e5, 32), ("y", -1e5, 1e5, 32), ("rotation", -PI, PI, 16))
    wire = ("MapCenterX", "MapCenterY", "MapRotation")
  for (key, lo, hi, nbits), w in zip(specs, wire):
    step = _step(lo, hi, nbits)
    assert getattr(pose, key) == pytest.approx(rows[w] * step + lo, rel=1e-12, abs=1e-9)
    assert abs(getattr(pose, key) - pose_doc[key]) <= step / 2 + 1e-12


@pytest.mark.parametrize("name", sorted(SPEC_EXAMPLES))
def test_spec_worked_examples(name):
  data = bytes.fromhex(SPEC_EXAMPLES[name])
  msg = J.decode(data)
  encode = J.encode_query if isinstance(msg, J.CostMap2DQuery) else J.encode_report
  assert encode(msg) == data                       # decode -> encode is exact
  if isinstance(msg, J.CostMap2DReport):
    lut = {0: 0, 10: 36, 254: 254, 255: 255} if msg.variant == "rle" else {c: c for c in range(256)}
    expect = [[lut[c] for c in row] for row in ((0, 0, 254), (255, 10, 10))]
    assert np.array_equal(msg.nav2_cost(), np.array(expect))
    assert msg.pose.x == pytest.approx(12.5, abs=5e-5) and msg.pose.y == pytest.approx(-3.25, abs=5e-5)
    assert msg.pose.rotation == pytest.approx(PI / 4, abs=1e-4)
    values = msg.nav2_cost() if msg.variant == "list" else None
    if values is not None:   # re-encoding the documented reals gives the bytes
      again = J.CostMap2DReport.create(values, map_width=1.5, map_height=1.0,
                                       pose=J.LocalPose(12.5, -3.25, PI / 4), profile=msg.profile)
      assert J.encode_report(again) == data


# --------------------------------------------------------------------------- mappings


def test_occupancy_cost_mappings_against_loops():
  occ = np.arange(-1, 101)
  nav2 = [255 if d < 0 else math.floor(Fraction(254 * d, 100) + Fraction(1, 2)) for d in occ]
  assert np.array_equal(J.occupancy_to_cost(occ), nav2)
  assert np.array_equal(J.occupancy_to_cost(occ, mapping="fkie"), [255 if d < 0 else 2 * d for d in occ])
  # Nav2's published key values (docs/nav2_semantics.md §1.4).
  assert [int(J.occupancy_to_cost(np.array([d]))[0]) for d in (1, 25, 50, 75, 99, 100)] == [
      3, 64, 127, 191, 251, 254]
  # Back: exact inverse on the image, nearest occupancy (half up) for every other cost.
  cost = np.arange(256)
  back = J.cost_to_occupancy(cost)
  for c in range(255):
    dists = [abs(Fraction(254 * d, 100) - c) for d in range(101)]
    best = min(range(101), key=lambda d: (dists[d], -d))
    assert back[c] == best, c
  assert back[255] == -1
  assert np.array_equal(J.cost_to_occupancy(J.occupancy_to_cost(occ)), occ)
  assert np.array_equal(J.cost_to_occupancy(np.arange(0, 201), mapping="fkie"), np.arange(201) // 2)
  assert J.cost_to_occupancy(np.array([255]), mapping="fkie")[0] == -1
  with pytest.raises(ValueError, match="fkie mapping covers costs 0..200"):
    J.cost_to_occupancy(np.array([0, 254]), mapping="fkie")
  for bad in (np.array([101]), np.array([-2]), np.array([1.5])):
    with pytest.raises(ValueError):
      J.occupancy_to_cost(bad)
  with pytest.raises(ValueError, match="mapping must be one of"):
    J.occupancy_to_cost(occ, mapping="ros")


def test_rle_levels_keep_each_class():
  cost = np.arange(255)
  level = J.cost_to_rle_level(cost)
  assert np.array_equal(level, [rle_level(c) for c in cost])
  assert level[0] == 0 and level[254] == 7 and set(level[1:254]) == {1, 2, 3, 4, 5, 6}
  assert np.array_equal(J.rle_level_to_cost(np.arange(8)), [0, 36, 73, 109, 145, 181, 218, 254])
  assert np.array_equal(J.cost_to_rle_level(J.rle_level_to_cost(np.arange(8))), np.arange(8))
  with pytest.raises(ValueError):
    J.cost_to_rle_level(np.array([255]))


# --------------------------------------------------------------------------- grids


def _random_grid(rng, h, w, yaw=0.0, res=0.05, origin=(-3.2, 1.45)):
  data = rng.integers(-1, 101, size=(h, w))
  data[rng.random((h, w)) < 0.3] = 0       # runs for the run-length list
  return OccupancyGrid.create(data, res, (*origin, yaw))


def _expected_occ(grid_data, variant, mapping):
  """Reference: occupancy -> Nav2 cost -> variant -> cost -> occupancy, by plain loops."""
  out = np.empty_like(grid_data)
  for (r, c), d in np.ndenumerate(grid_data):
    cost = 255 if d < 0 else (math.floor(Fraction(254 * int(d), 100) + Fraction(1, 2))
                              if mapping == "nav2" else 2 * int(d))
    if variant == "rle" and cost != 255:
      cost = round(rle_level(cost) * 254 / 7)
    if cost == 255:
      out[r, c] = -1
    elif mapping == "nav2":
      out[r, c] = math.floor(Fraction(cost * 100, 254) + Fraction(1, 2))
    else:
      out[r, c] = cost // 2
  return out


@pytest.mark.parametrize("profile", ["iop", "design"])
@pytest.mark.parametrize("variant", ["list", "confidence", "rle"])
def test_grid_round_trip(profile, variant):
  rng = np.random.default_rng(7)
  for h, w, yaw, mapping, axes in ((5, 7, 0.0, "nav2", "ros"), (9, 4, 1.0, "fkie", "ned"),
                                   (1, 13, -2.5, "nav2", "ned")):
    grid = _random_grid(rng, h, w, yaw)
    if mapping == "fkie" and variant == "rle":
      continue   # 3-bit levels decode to costs above 200, outside the fkie range
    report = J.grid_to_report(grid, profile=profile, variant=variant, mapping=mapping, axes=axes,
                              lossy=variant == "rle", check_resolution=profile == "design")
    msg = J.decode_report(J.encode_report(report))
    back = J.report_to_grid(msg, mapping=mapping, axes=axes)
    assert np.array_equal(back.data, _expected_occ(grid.data, variant, mapping))
    if variant != "rle":
      assert np.array_equal(back.data, grid.data)
    if profile == "design":   # 2.3e-6 m size steps: the simplest decimal is the original
      assert back.resolution == grid.resolution
      assert back.origin == pytest.approx(grid.origin, abs=1e-12)
    else:   # 0.15 m size steps say little about a 0.35 m map: the resolution must be given
      assert abs(back.resolution * w - msg.map_width) <= 10000 / 65535
      placed = J.report_to_grid(msg, mapping=mapping, axes=axes, resolution=grid.resolution)
      assert placed.origin == pytest.approx(grid.origin, abs=1e-12)


def test_window_geometry_and_wire_order():
  grid = _random_grid(np.random.default_rng(1), 6, 8, yaw=0.7, res=0.25, origin=(10.0, -4.0))
  col, row, width, height = 2, 1, 5, 3
  report = J.grid_to_report(grid, window=(col, row, width, height), profile="design")
  sub = grid.data[row:row + height, col:col + width]
  assert np.array_equal(report.values, J.occupancy_to_cost(sub)[::-1])   # row 0 = north
  c, s = math.cos(0.7), math.sin(0.7)
  dx, dy = (col + width / 2) * 0.25, (row + height / 2) * 0.25
  assert report.pose.x == pytest.approx(10.0 + c * dx - s * dy, abs=1e-12)
  assert report.pose.y == pytest.approx(-4.0 + s * dx + c * dy, abs=1e-12)
  assert report.pose.rotation == pytest.approx(0.7)
  assert (report.map_width, report.map_height) == (1.25, 0.75)
  ned = J.grid_to_report(grid, window=(col, row, width, height), axes="ned")
  assert (ned.pose.x, ned.pose.y, ned.pose.rotation) == pytest.approx(
      (report.pose.y, report.pose.x, -0.7))
  back = J.report_to_grid(J.decode_report(J.encode_report(report)))
  assert np.array_equal(back.data, sub)
  ox, oy = 10.0 + c * col * 0.25 - s * row * 0.25, -4.0 + s * col * 0.25 + c * row * 0.25
  assert back.origin == pytest.approx((ox, oy, 0.7), abs=1e-4)   # 4.7e-5 m centre steps


def test_window_and_option_errors():
  grid = _random_grid(np.random.default_rng(2), 4, 5)
  for window, match in (((0, 0, 6, 1), "inside the 5 x 4"), ((-1, 0, 1, 1), ">= 0"),
                        ((0, 0, 0, 1), ">= 1 cell"), ((0.5, 0, 1, 1), "integers"),
                        ((0, 0, 1), "col, row, width, height")):
    with pytest.raises(ValueError, match=match):
      J.grid_to_report(grid, window=window)
  with pytest.raises(ValueError, match="variant must be one of"):
    J.grid_to_report(grid, variant="attractiveness")      # not an IOP variant
  with pytest.raises(NotImplementedError):
    J.grid_to_report(grid, profile="design", variant="attractiveness")
  with pytest.raises(ValueError, match="axes must be one of"):
    J.grid_to_report(grid, axes="enu")
  with pytest.raises(ValueError, match="profile must be one of"):
    J.grid_to_report(grid, profile="jaus")
  far = OccupancyGrid.create(grid.data, 0.05, (100000.0, 0.0, 0.0))
  with pytest.raises(ValueError, match=r"MapCenterX must lie in \[-100000, 100000\]"):
    J.grid_to_report(far)


def test_scaled_values_are_validated_not_clamped():
  for kw, match in ((dict(x=100000.001), "MapCenterX must lie"), (dict(rotation=3.15), "MapRotation"),
                    (dict(y=float("nan")), "finite"), (dict(x=float("inf")), "finite"),
                    (dict(x=1e-40), "subnormal"), (dict(y=1e39), "float32")):
    args = dict(x=0.0, y=0.0, rotation=0.0) | kw
    with pytest.raises(ValueError, match=match):
      J.LocalPose(**args)
  with pytest.raises(ValueError, match="MapCenterLatitude must lie"):
    J.GlobalPose(90.5, 0.0, 0.0)
  pose = J.LocalPose(0.0, 0.0, 0.0)
  with pytest.raises(ValueError, match=r"MapWidth must lie in \[0, 10000\]"):
    J.CostMap2DReport.create(np.zeros((1, 1), np.uint8), map_width=10000.5, map_height=1.0,
                             pose=pose)
  with pytest.raises(ValueError, match="confidence must be finite percent"):
    J.CostMap2DReport.create(np.zeros((1, 1), np.uint8), map_width=1, map_height=1, pose=pose,
                             variant="confidence", confidence=[[100.5]])
  with pytest.raises(ValueError, match="rounds to 0 on the wire"):
    J.CostMap2DReport.create(np.zeros((1, 1), np.uint8), map_width=1, map_height=1, pose=pose,
                             variant="confidence", confidence=[[0.1]])
  with pytest.raises(ValueError, match="does not allow cost 255"):
    J.CostMap2DReport.create(np.full((1, 1), 255, np.uint8), map_width=1, map_height=1,
                             pose=pose, variant="confidence", confidence=[[0.0]])
  with pytest.raises(ValueError, match=r"in \[0, 7\]"):
    J.CostMap2DReport.create(np.full((1, 1), 8, np.uint8), map_width=1, map_height=1, pose=pose,
                             variant="rle", known=np.ones((1, 1), bool))
  with pytest.raises(ValueError, match="both max_width and max_height"):
    J.CostMap2DQuery("iop", max_width=3.0)
  with pytest.raises(ValueError, match="no MaxNumberOfRows"):
    J.CostMap2DQuery("iop", max_rows=3, max_cols=3)


def test_truncating_peer_within_one_lsb_gives_the_same_grid():
  grid = _random_grid(np.random.default_rng(3), 20, 30, yaw=0.3, res=0.05, origin=(-10.0, 2.5))
  for profile in ("iop", "design"):
    exact = J.encode_report(J.grid_to_report(grid, profile=profile))
    msg = J.decode_report(exact)
    bits, fmt = (16, "<H") if profile == "iop" else (32, "<I")

    def trunc(v, lo, hi, nbits):   # the JAUS Tool Set's C cast
      return math.floor((Fraction(v) - Fraction(lo)) * (2**nbits - 1) / (Fraction(hi) - Fraction(lo)))

    c, s = math.cos(0.3), math.sin(0.3)
    cx = -10.0 + c * 0.75 - s * 0.5
    cy = 2.5 + s * 0.75 + c * 0.5
    head = struct.pack("<HHH", msg_id := (0xD742 if profile == "iop" else 0x4C11), 20, 30)
    head += struct.pack(fmt, trunc(1.5, 0, 10000, bits)) + struct.pack(fmt, trunc(1.0, 0, 10000, bits))
    head += struct.pack("<BIIH", 1, trunc(cx, -1e5, 1e5, 32), trunc(cy, -1e5, 1e5, 32),
                        trunc(0.3, -PI, PI, 16))
    peer = head + exact[len(head):]
    assert peer != exact and msg_id
    a, b = J.report_to_grid(msg), J.report_to_grid(J.decode_report(peer))
    assert np.array_equal(a.data, grid.data) and np.array_equal(b.data, grid.data)
    assert a.resolution == b.resolution == 0.05
    assert a.origin == pytest.approx((-10.0, 2.5, 0.3), abs=1e-12)
    assert b.origin == pytest.approx((-10.0, 2.5, 0.3), abs=1e-12)


def test_report_to_grid_options_and_refusals():
  grid = _random_grid(np.random.default_rng(4), 4, 6, res=0.5, origin=(1.0, 2.0))
  msg = J.decode_report(J.encode_report(J.grid_to_report(grid)))   # iop: 0.15 m size steps
  raw = J.report_to_grid(msg, snap=False)
  assert raw.resolution == pytest.approx(msg.map_width / 6)           # fkie: width / columns
  assert J.report_to_grid(msg, resolution=0.5).resolution == 0.5
  with pytest.raises(ValueError, match="disagrees with the message"):
    J.report_to_grid(msg, resolution=0.6)
  odd = dataclasses.replace(msg, map_height=msg.map_height * 2)
  with pytest.raises(ValueError, match="not square"):
    J.report_to_grid(odd)
  glob = dataclasses.replace(msg, pose=J.GlobalPose(48.0, 11.0, 0.0))
  with pytest.raises(ValueError, match="latitude/longitude; pass center"):
    J.report_to_grid(glob)
  placed = J.report_to_grid(glob, center=(4.0, 3.0, 0.0))
  assert placed.origin == pytest.approx((4.0 - 1.5, 3.0 - 1.0, 0.0))
  attr = J.decode_report(_read_vector("design_report_attractiveness_local"))
  with pytest.raises(ValueError, match="no public definition"):
    J.report_to_grid(attr)
  empty = J.CostMap2DReport.create(np.zeros((0, 3), np.uint8), map_width=0.0, map_height=0.0,
                                   pose=J.LocalPose(0, 0, 0))
  assert J.decode_report(J.encode_report(empty)).values.shape == (0, 3)
  with pytest.raises(ValueError, match="at least one cell"):
    J.report_to_grid(empty)


def test_too_large_is_refused_naming_the_limit_or_tiled():
  rng = np.random.default_rng(5)
  grid = _random_grid(rng, 300, 260)
  with pytest.raises(ValueError, match=r"at most 65535 cells .* 300 x 260 = 78000"):
    J.grid_to_report(grid)
  with pytest.raises(ValueError, match="at most 65535 cells"):
    J.encode_report(dataclasses.replace(J.grid_to_report(grid, window=(0, 0, 10, 10)),
                                        values=np.zeros((300, 260), np.uint8)))
  for tiles in (True, lambda rows, cols: (120, 100)):
    out = J.grid_to_reports(grid, tiles=tiles)
    cover = np.zeros(grid.data.shape, int)
    for tile in out:
      col, row, w, h = tile.window
      cover[row:row + h, col:col + w] += 1
      back = J.report_to_grid(J.decode_report(J.encode_report(tile.report)))
      assert np.array_equal(back.data, grid.data[row:row + h, col:col + w])
      assert back.origin == pytest.approx((-3.2 + col * 0.05, 1.45 + row * 0.05, 0.0), abs=1e-12)
    assert np.all(cover == 1) and len(out) > 1
  with pytest.raises(ValueError, match=r"tile \(0, 0, 260, 300\).*65535 cells"):
    J.grid_to_reports(grid, tiles=lambda rows, cols: (rows, cols))
  with pytest.raises(ValueError, match="tiles function must return"):
    J.grid_to_reports(grid, tiles=lambda rows, cols: (0, 5))
  # Run-length: a checkerboard needs a run per cell but where runs join across rows.
  board = OccupancyGrid.create(np.indices((260, 260)).sum(0) % 2 * 100, 0.05)
  runs = len(rle_words([[254 if d else 0 for d in row] for row in board.data[::-1]]))
  assert runs == 260 * 260 - 259
  with pytest.raises(ValueError, match=f"at most 65535 runs .* needs {runs}"):
    J.grid_to_report(board, variant="rle")
  tiles = J.grid_to_reports(board, variant="rle", tiles=True)
  assert sum(t.window[2] * t.window[3] for t in tiles) == 260 * 260 and len(tiles) == 2
  with pytest.raises(ValueError, match="GlobalPose can only be sent with a single message"):
    J.grid_to_reports(grid, pose=J.GlobalPose(0, 0, 0), tiles=True)


def test_rle_long_runs_split_and_cross_rows():
  costs = np.array(long_rle_costs(), np.uint8)
  grid = OccupancyGrid.create(J.cost_to_occupancy(costs)[::-1], 0.05)
  report = J.grid_to_report(grid, variant="rle")
  data = J.encode_report(report)
  words = np.frombuffer(data, "<u2", offset=len(data) - 8)
  assert [(w & 7, w >> 3 & 1, w >> 4) for w in words] == [(0, 1, 4095), (0, 1, 5), (0, 0, 1),
                                                           (7, 1, 1899)]


# --------------------------------------------------------------------------- hostile input


def _valid_messages() -> list[bytes]:
  return [_read_vector(n) for n in VECTOR_FILES]


def test_every_truncation_and_extension_raises_the_documented_error():
  for data in _valid_messages():
    for n in range(len(data)):
      with pytest.raises(J.JausDecodeError) as err:
        J.decode(data[:n])
      assert 0 <= err.value.offset <= n and err.value.reason
    with pytest.raises(J.JausDecodeError, match="1 bytes left over") as err:
      J.decode(data + b"\x00")
    assert err.value.offset == len(data)


def _report(name="iop_report_list_local") -> bytearray:
  return bytearray(_read_vector(name))


def test_specific_hostile_cases_name_offset_and_reason():
  cases = []
  b = _report(); b[0:2] = b"\x34\x12"; cases.append((b, 0, "message ID 0x1234"))
  b = _report(); b[10] = 2; cases.append((b, 10, "CostMap2DPoseVar vtag 2"))
  b = _report(); b[21] = 3; cases.append((b, 21, "CostMap2DDataVar vtag 3 is not one of 0..2"))
  b = _report("design_report_list_local"); b[25] = 4; cases.append((b, 25, "vtag 4"))
  b = _report(); b[22:24] = struct.pack("<H", 9); cases.append((b, 22, "count 9 needs 9 bytes"))
  b = _report(); b[22:24] = struct.pack("<H", 7); b = b[:-1]
  cases.append((b, 22, r"count 7 != NumberOfRows x NumberOfColumns = 2 x 4 = 8"))
  b = _report("iop_report_rle_local"); b[2:4] = struct.pack("<H", 3)
  cases.append((b, 22, "runs cover 8 cells, but .* 3 x 4 = 12"))
  b = _report("iop_report_confidence_local"); b[24 + 6] = 255
  cases.append((b, 30, "cost 255 is not allowed"))
  b = bytearray(_read_vector("iop_query_empty")); b[2] = 0x04
  cases.append((b, 2, "presence vector 0x04 sets bits above bit 1"))
  b = bytearray(_read_vector("design_query_empty")); b[2] = 0x08
  cases.append((b, 2, "above bit 2"))
  for data, offset, match in cases:
    with pytest.raises(J.JausDecodeError, match=match) as err:
      J.decode(bytes(data))
    assert err.value.offset == offset, match
  with pytest.raises(J.JausDecodeError, match="expected a ReportCostMap2D"):
    J.decode_report(_read_vector("iop_query_full"))
  with pytest.raises(J.JausDecodeError, match="expected a QueryCostMap2D"):
    J.decode_query(_read_vector("iop_report_list_local"))
  with pytest.raises(J.JausDecodeError, match="exceeds max_cells=7"):
    J.decode(_read_vector("iop_report_list_local"), max_cells=7)
  assert isinstance(J.JausDecodeError(0, "x"), ValueError)
  with pytest.raises(TypeError):
    J.decode("42d7")


def test_huge_counts_in_tiny_buffers_allocate_nothing():
  # RLE claiming 65535 x 65535 cells (4.3e9) with 2 runs in a 40-byte buffer, and a cost
  # list claiming 65535 elements: both must fail before any cell array exists.
  head = struct.pack("<HHHII", 0x4C11, 65535, 65535, 1, 1) + struct.pack("<BIIH", 1, 0, 0, 0)
  rle = head + struct.pack("<BH", 2, 2) + struct.pack("<HH", 0xFFF8, 0xFFF8)
  lst = head + struct.pack("<BH", 0, 65535) + b"\x00" * 12
  assert len(rle) == 32 and len(lst) == 40
  tracemalloc.start()
  try:
    for data, match in ((rle, "runs cover 8190 cells"), (lst, "count 65535 needs 65535 bytes")):
      with pytest.raises(J.JausDecodeError, match=match):
        J.decode(data)
    _, peak = tracemalloc.get_traced_memory()
  finally:
    tracemalloc.stop()
  assert peak < 64 * 1024


_MUTATIONS = st.one_of(
    st.tuples(st.just("set"), st.integers(0, 10**6), st.integers(0, 255)),
    st.tuples(st.just("insert"), st.integers(0, 10**6), st.binary(min_size=1, max_size=8)),
    st.tuples(st.just("delete"), st.integers(0, 10**6), st.integers(1, 8)),
    st.tuples(st.just("truncate"), st.integers(0, 10**6), st.just(0)),
)


def _decode_bounded(data: bytes) -> None:
  tracemalloc.start()
  try:
    try:
      J.fuzz_target(data)
    except J.JausDecodeError as e:
      assert 0 <= e.offset <= len(data) and e.reason
    _, peak = tracemalloc.get_traced_memory()
  finally:
    tracemalloc.stop()
  assert peak <= 64 * 1024 + 2048 * len(data) * 8   # RLE: <= 4095 cells of 9 bytes per 2 bytes


@settings(max_examples=300)
@given(st.sampled_from(VECTOR_FILES), st.lists(_MUTATIONS, min_size=1, max_size=4))
def test_fuzz_mutated_vectors(name, mutations):
  data = bytearray(_read_vector(name))
  for op, pos, arg in mutations:
    pos = pos % (len(data) + 1)
    if op == "set" and data:
      data[pos % len(data)] = arg
    elif op == "insert":
      data[pos:pos] = arg
    elif op == "delete":
      del data[pos:pos + arg]
    elif op == "truncate":
      del data[pos:]
  _decode_bounded(bytes(data))


@settings(max_examples=300)
@given(st.sampled_from([b"\x42\xd7", b"\x11\x4c", b"\x38\xd7", b"\x11\x2c", b""]),
       st.binary(max_size=300))
def test_fuzz_random_bytes(prefix, tail):
  _decode_bounded(prefix + tail)


@given(st.integers(0, 40), st.integers(0, 40), st.sampled_from(["list", "confidence", "rle"]),
       st.sampled_from(["iop", "design"]), st.integers(0, 2**32 - 1))
def test_fuzz_random_valid_reports_round_trip(rows, cols, variant, profile, seed):
  rng = np.random.default_rng(seed)
  cost = rng.choice(np.array([0, 1, 127, 252, 253, 254, 255], np.uint8), size=(rows, cols))
  pose = J.LocalPose(float(rng.uniform(-1e5, 1e5)), float(rng.uniform(-1e5, 1e5)),
                     float(rng.uniform(-PI, PI)))
  if variant == "list":
    rep = J.CostMap2DReport.create(cost, map_width=cols * 0.1, map_height=rows * 0.1, pose=pose,
                                   profile=profile)
  elif variant == "confidence":
    unknown = cost == 255
    conf = np.where(unknown, 0.0, rng.integers(1, 256, size=cost.shape) * 100 / 255)
    vals = np.where(unknown & (profile == "iop"), 0, cost).astype(np.uint8)
    rep = J.CostMap2DReport.create(vals, map_width=cols * 0.1, map_height=rows * 0.1, pose=pose,
                                   profile=profile, variant=variant, confidence=conf)
  else:
    rep = J.CostMap2DReport.create(rng.integers(0, 8, size=cost.shape).astype(np.uint8),
                                   known=rng.random(cost.shape) < 0.7, map_width=cols * 0.1,
                                   map_height=rows * 0.1, pose=pose, profile=profile,
                                   variant=variant)
  data = J.encode_report(rep)
  back = J.decode_report(data)
  assert J.encode_report(back) == data
  assert np.array_equal(back.values, rep.values)
  if variant == "confidence":
    assert np.allclose(back.confidence, rep.confidence, atol=1e-9)
  if variant == "rle":
    assert np.array_equal(back.known, rep.known)
  assert abs(back.pose.x - pose.x) <= 2e5 / (2**32 - 1) / 2 + 1e-9


def test_hex_helpers():
  data = bytes(range(40))
  text = J.to_hex(data)
  assert text.splitlines()[0] == " ".join(f"{i:02x}" for i in range(16))
  assert J.from_hex(text) == data and J.from_hex(text.upper().replace("\n", "  ")) == data
  for bad in ("0g", "abc"):
    with pytest.raises(ValueError, match="invalid hex text"):
      J.from_hex(bad)


def test_jaus_module_is_host_only():
  source = Path(J.__file__).read_text(encoding="utf-8")
  assert not re.search(r"^\s*(import|from)\s+jax(\.|\s|$)", source, re.M)


# --------------------------------------------------------------------------- CLI


def _cli(args, capsys):
  code = cli.main(args)
  out, err = capsys.readouterr()
  return code, out, err


def _window_roundtrip(yaml_path, window, tmp_path, capsys, extra=()):
  grid = load_map(yaml_path)
  bin_path, out_yaml = tmp_path / "m.bin", tmp_path / "back.yaml"
  code, out, err = _cli(["jaus", "encode", str(yaml_path), "--out", str(bin_path),
                         "--window", *map(str, window), *extra], capsys)
  assert code == 0 and err == "" and "ReportCostMap2D" in out
  code, out, err = _cli(["jaus", "decode", str(bin_path), "--out", str(out_yaml),
                         *[e for e in extra if e == "--hex"]], capsys)
  assert code == 0 and err == "", err
  back = load_map(out_yaml)
  col, row, w, h = window
  assert np.array_equal(back.data, grid.data[row:row + h, col:col + w])
  assert back.resolution == pytest.approx(grid.resolution)
  assert back.origin[:2] == pytest.approx((grid.origin[0] + col * grid.resolution,
                                           grid.origin[1] + row * grid.resolution), abs=1e-3)
  return back


def test_cli_round_trip_generated_map(tmp_path, capsys):
  rng = np.random.default_rng(11)
  grid = _random_grid(rng, 40, 50, res=0.05, origin=(-1.0, 2.0))
  yaml_path, _ = save_map(grid, tmp_path / "gen", mode="raw")
  _window_roundtrip(yaml_path, (3, 5, 30, 20), tmp_path, capsys)
  _window_roundtrip(yaml_path, (0, 0, 50, 40), tmp_path, capsys, ("--hex", "--profile", "design"))


def test_cli_round_trip_real_nav2_maps(nav2_maps, tmp_path, capsys):
  _window_roundtrip(nav2_maps / "tb3_sandbox.yaml", (150, 120, 200, 160), tmp_path, capsys)
  _window_roundtrip(nav2_maps / "speed_mask.yaml", (100, 100, 150, 200), tmp_path, capsys,
                    ("--profile", "design"))    # values 0, 19, 50: saved raw, lossless


def test_cli_wrong_arguments(tmp_path, capsys):
  grid = _random_grid(np.random.default_rng(12), 300, 300)
  yaml_path, _ = save_map(grid, tmp_path / "big", mode="raw")
  good = tmp_path / "ok.bin"
  assert _cli(["jaus", "encode", str(yaml_path), "--out", str(good), "--window", "0", "0", "4",
               "4"], capsys)[0] == 0
  (tmp_path / "query.bin").write_bytes(bytes.fromhex("38d700"))
  (tmp_path / "short.bin").write_bytes(good.read_bytes()[:15])
  (tmp_path / "hex.txt").write_text(J.to_hex(good.read_bytes()))
  (tmp_path / "attr.bin").write_bytes(_read_vector("design_report_attractiveness_local"))
  cases = [
      (["encode", str(yaml_path), "--out", str(good), "--single"], "at most 65535 cells"),
      (["encode", str(yaml_path), "--out", str(good), "--window", "0", "0", "301", "1"],
       "--window"),
      (["encode", str(yaml_path), "--out", str(good), "--window", "0", "0", "x", "1"],
       "invalid int value"),
      (["encode", str(yaml_path), "--out", str(good), "--window", "0", "0", "1"],
       "expected 4 arguments"),
      (["encode", str(yaml_path), "--out", str(good), "--variant", "attractiveness"],
       "invalid choice"),
      (["encode", str(yaml_path), "--out", str(good), "--profile", "v2"], "invalid choice"),
      (["encode", str(tmp_path / "nope.yaml"), "--out", str(good)], "does not exist"),
      (["encode", str(yaml_path), "--out", str(tmp_path / "no" / "x.bin"), "--window", "0",
        "0", "4", "4"], "cannot write"),
      (["encode", str(yaml_path)], "--out"),
      (["decode", str(tmp_path / "nope.bin"), "--out", str(tmp_path / "x.yaml")], "cannot read"),
      (["decode", str(tmp_path / "short.bin"), "--out", str(tmp_path / "x.yaml")],
       "decode error at byte 11: truncated"),
      (["decode", str(tmp_path / "hex.txt"), "--out", str(tmp_path / "x.yaml")], "add --hex"),
      (["decode", str(good), "--out", str(tmp_path / "x.yaml"), "--hex"], "not hex text"),
      (["decode", str(tmp_path / "query.bin"), "--out", str(tmp_path / "x.yaml")],
       "QueryCostMap2D"),
      (["decode", str(tmp_path / "attr.bin"), "--out", str(tmp_path / "x.yaml")],
       "no public definition"),
      (["decode", str(good), "--out", str(tmp_path / "x.yaml"), "--resolution", "0.3"],
       "disagrees with the message"),
      (["decode", str(good), "--out", str(tmp_path / "x.yaml"), "--resolution", "-1"], "> 0"),
      (["decode", str(good), "--out", str(tmp_path / "no" / "x.yaml")], "cannot write"),
      ([], "required"),
  ]
  for args, match in cases:
    try:
      code, out, err = _cli(["jaus", *args], capsys)
    except SystemExit as e:   # argparse errors exit through ArgumentParser.error
      code, (out, err) = e.code, capsys.readouterr()
    assert code == 2, (args, err)
    assert match in err, (args, err)
    assert len(err.strip().splitlines()) == 1, err
  assert not (tmp_path / "x.yaml").exists()


if __name__ == "__main__":
  write_vectors()
  print(f"wrote {len(CASES) + len(SPEC_EXAMPLES)} vectors and README.md to {VECTOR_DIR}")
