"""The JAUS CostMap2D wire codec: message bytes <-> `CostMap2DReport` / `CostMap2DQuery`.

Wire rules (docs/jaus.md §1): little-endian, no padding, a uint16 message ID
first, a uint8 vtag before a variant, a uint16 element count before a list, a
uint8 presence vector (bit i = i-th optional field) first in a query. Peers
built on the JAUS Tool Set truncate scaled integers instead of rounding, so
nothing here requires an exact round trip (docs/jaus.md §2).

Every decoder treats its input as hostile (docs/jaus.md §11, decoder policy):
a truncated or oversized buffer, an unknown message ID, a bad vtag or presence
bit, a count that disagrees with the grid or with the bytes left, a declared
grid larger than `max_cells` (`MAX_MAP_CELLS` by default) or than its run
lengths can describe, and a value outside a field's value set all raise
`JausDecodeError` (a ValueError) carrying the byte offset and the reason, and
nothing else escapes for `bytes` input. Sizes are checked before anything is
allocated: a count against the bytes left, and rows x columns against the cap
and against the count (a run-length list describes at most 4095 cells per
2-byte run).

Files (`read_message_file`, `load_messages`) hold one message or several
back to back (the tiles of a map larger than one message, docs/jaus.md §12),
raw or as hex text. Only regular files of at most `MAX_FILE_BYTES` (raw;
three times that as hex) holding at most `MAX_MESSAGES` messages are read, so
a FIFO or a device fails at once; every problem with the file is a
`JausDecodeError` too, with `offset` None.
"""

from __future__ import annotations

import struct

import numpy as np

from jaxfilters import constants
from jaxfilters.jaus.messages import (CONFIDENCE, CENTER_X, CENTER_Y, ELEM_BYTES, LATITUDE,
                                      LIST_NAMES, LONGITUDE, PROFILES, RLE_MAX_RUN, ROTATION,
                                      VARIANTS, CostMap2DQuery, CostMap2DReport, GlobalPose,
                                      JausProfile, LocalPose, Pose, check_report, get_profile,
                                      rle_runs, size_field)
from jaxfilters.map_decode import MAX_MAP_CELLS, read_regular_file

# The largest message file read, in raw bytes: a map of MAX_MAP_CELLS cells in the
# cost-and-confidence list (2 bytes a cell) plus 1 MiB for the message headers of its tiles.
# Hex text takes three characters a byte, so a hex file may be three times as large.
MAX_FILE_BYTES = 2 * MAX_MAP_CELLS + (1 << 20)
# The most messages `decode_all` reads from one buffer: a map at the cell cap needs about 2048
# tiles of 32768 cells; 3-byte empty queries could otherwise make millions of objects, and tiny
# tiles seconds of work each thousand.
MAX_MESSAGES = 4096


class JausDecodeError(ValueError):
  """Bytes (or a file) that are not valid CostMap2D messages.

  Attributes:
    offset: byte offset (from the start of the buffer, the first message's
      ID) where the problem was found; None for a problem with the file itself
      (missing, not a regular file, too large, unreadable, not hex text).
    reason: what was wrong and what was expected.
  """

  def __init__(self, offset: int | None, reason: str):
    at = "" if offset is None else f" at byte {offset}"
    super().__init__(f"JAUS CostMap2D decode error{at}: {reason}")
    self.offset = None if offset is None else int(offset)
    self.reason = reason


_BY_ID = {p.report_id: (p, "report") for p in PROFILES.values()}
_BY_ID.update({p.query_id: (p, "query") for p in PROFILES.values()})

def _pack_pose(pose: Pose) -> bytes:
  if isinstance(pose, GlobalPose):
    return struct.pack("<BIIH", 0, LATITUDE.encode(pose.latitude, "GlobalPose"),
                       LONGITUDE.encode(pose.longitude, "GlobalPose"),
                       ROTATION.encode(pose.rotation, "GlobalPose"))
  return struct.pack("<BIIH", 1, CENTER_X.encode(pose.x, "LocalPose"),
                     CENTER_Y.encode(pose.y, "LocalPose"),
                     ROTATION.encode(pose.rotation, "LocalPose"))


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
  prof = check_report(report)
  if report.variant == "attractiveness":
    raise NotImplementedError("encoding CostOrAttractivenessList is refused: no public text "
                              "defines its values (sign convention, reserved values); decode "
                              "keeps them as raw bytes")
  size_fmt = "H" if prof.size_bits == 16 else "I"
  head = struct.pack(f"<HHH{size_fmt}{size_fmt}", prof.report_id, report.rows, report.cols,
                     size_field(prof, "MapWidth").encode(report.map_width, "CostMap2DReport"),
                     size_field(prof, "MapHeight").encode(report.map_height, "CostMap2DReport"))
  vtag = VARIANTS.index(report.variant)
  if report.variant == "list":
    payload, count = report.values.tobytes(), report.values.size
  elif report.variant == "confidence":
    raw = np.floor(report.confidence / CONFIDENCE.step + 0.5).clip(0, 255).astype(np.uint8)
    payload = np.stack([report.values, raw], -1).tobytes()
    count = report.values.size
  else:
    words = rle_runs(report.values, report.known)
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
  prof = get_profile(query.profile)
  fields, bits, bit = [], 0, 0
  if prof.query_has_resolution:
    if query.max_rows is not None:
      bits |= 1 << bit
      fields.append(struct.pack("<HH", query.max_rows, query.max_cols))
    bit += 1
  if query.max_width is not None:
    bits |= 1 << bit
    fmt = "<HH" if prof.size_bits == 16 else "<II"
    fields.append(struct.pack(fmt, size_field(prof, "MaxWidth").encode(query.max_width, "query"),
                              size_field(prof, "MaxHeight").encode(query.max_height, "query")))
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
    return GlobalPose(LATITUDE.decode(a), LONGITUDE.decode(b), ROTATION.decode(rot))
  return LocalPose(CENTER_X.decode(a), CENTER_Y.decode(b), ROTATION.decode(rot))


def _read_report(r: _Reader, prof: JausProfile, max_cells: int | None) -> CostMap2DReport:
  size_fmt = "H" if prof.size_bits == 16 else "I"
  rec_at = r.pos
  rows, cols, w, h = r.unpack(f"<HH{size_fmt}{size_fmt}", "CostMap2DRec")
  pose = _read_pose(r, "CostMap2DPoseVar")
  at = r.pos
  (vtag,) = r.unpack("<B", "CostMap2DDataVar vtag")
  if vtag >= prof.num_data_variants:
    raise JausDecodeError(at, f"CostMap2DDataVar vtag {vtag} is not one of 0..{prof.num_data_variants - 1} "
                          f"{prof.variants} of profile {prof.name!r} (message ID 0x{prof.report_id:04X})")
  variant, name = VARIANTS[vtag], LIST_NAMES[vtag]
  at = r.pos
  (count,) = r.unpack("<H", f"{name} count")
  nbytes = count * ELEM_BYTES[vtag]
  if nbytes > r.left():
    raise JausDecodeError(at, f"{name} count {count} needs {nbytes} bytes, only {r.left()} left")
  cells = rows * cols
  if variant != "rle" and count != cells:
    raise JausDecodeError(at, f"{name} count {count} != NumberOfRows x NumberOfColumns = "
                          f"{rows} x {cols} = {cells}")
  start = r.need(nbytes, name)
  if variant == "rle":
    # The run lengths (2 bytes each, at most 4095 cells a run) must describe exactly the
    # declared grid: this bounds the cells by the message length before any cell exists.
    words = np.frombuffer(r.data, "<u2", count, start).astype(np.uint16)
    lengths = (words >> 4).astype(np.int64)
    total = int(lengths.sum())
    if total != cells:
      raise JausDecodeError(at, f"{name}: the runs cover {total} cells, but NumberOfRows x "
                            f"NumberOfColumns = {rows} x {cols} = {cells}")
  if max_cells is not None and cells > max_cells:
    raise JausDecodeError(rec_at, f"{rows} x {cols} = {cells} cells exceeds max_cells={max_cells} "
                          f"(the cell cap, MAX_MAP_CELLS = {MAX_MAP_CELLS} unless given)")
  confidence = known = None
  if variant == "rle":
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
    confidence = (pairs[:, 1].astype(np.float64) * CONFIDENCE.step).reshape(rows, cols)
  else:
    values = np.frombuffer(r.data, np.uint8, count, start).reshape(rows, cols).copy()
  size = size_field(prof, "MapWidth")
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
    size = size_field(prof, "MaxWidth")
    kw["max_width"], kw["max_height"] = size.decode(w), size.decode(h)
  if pv >> (bit + 1) & 1:
    kw["center"] = _read_pose(r, "QueryCostMap2DCenterVar")
  return CostMap2DQuery(prof.name, **kw)


def _read_message(r: _Reader, max_cells: int | None) -> CostMap2DReport | CostMap2DQuery:
  at = r.pos
  (msg_id,) = r.unpack("<H", "message ID")
  if msg_id not in _BY_ID:
    known = ", ".join(f"0x{i:04X}" for i in sorted(_BY_ID))
    raise JausDecodeError(at, f"message ID 0x{msg_id:04X} is not a CostMap2D message (expected "
                          f"one of {known})")
  prof, kind = _BY_ID[msg_id]
  return _read_report(r, prof, max_cells) if kind == "report" else _read_query(r, prof)


def _as_bytes(data, owner: str) -> bytes:
  if not isinstance(data, (bytes, bytearray, memoryview)):
    raise TypeError(f"{owner} expects bytes; got {type(data).__name__}")
  return bytes(data)


def _check_cap(max_cells) -> None:
  if max_cells is not None and (isinstance(max_cells, bool) or not isinstance(max_cells, int)
                                or max_cells < 0):
    raise ValueError(f"max_cells must be an integer >= 0 or None; got {max_cells!r}")


def decode(data: bytes, *, max_cells: int | None = MAX_MAP_CELLS
           ) -> CostMap2DReport | CostMap2DQuery:
  """Bytes of one CostMap2D message (ID first) -> CostMap2DReport or CostMap2DQuery.

  The profile comes from the message ID. Decoded reals are `int * step + lo`
  exactly; nothing requires them to round-trip (a JTS peer truncates).

  Args:
    data: bytes, bytearray or memoryview of exactly one message.
    max_cells: cap on rows x columns of a report, checked before any cell
      array exists (the run-length list can describe up to 4095 cells per
      2 bytes); `MAX_MAP_CELLS` (2**26), the map loader's cap, by default;
      None for no cap.

  Returns:
    The message; `values` arrays are new, writable copies.

  Raises:
    JausDecodeError: anything wrong with the bytes (offset and reason given):
      too short, bytes left over, an unknown message ID, a vtag or presence bit
      the profile does not define, a count that disagrees with the bytes left
      or with NumberOfRows x NumberOfColumns, runs that do not cover the grid,
      more cells than `max_cells`, cost 255 in an IOP cost and confidence list.
    TypeError: data that is not bytes-like.
  """
  _check_cap(max_cells)
  r = _Reader(_as_bytes(data, "decode"))
  msg = _read_message(r, max_cells)
  if r.left():
    raise JausDecodeError(r.pos, f"{r.left()} bytes left over after the end of the message")
  return msg


def decode_all(data: bytes, *, max_cells: int | None = MAX_MAP_CELLS
               ) -> list[CostMap2DReport | CostMap2DQuery]:
  """Bytes of one or more CostMap2D messages back to back -> the messages, in order.

  Each message's length follows from its own fields, so no separator is
  needed (docs/jaus.md §12); this is how `grid_to_reports` tiles are stored
  in one file.

  Args:
    data: bytes of at least one complete message.
    max_cells: cap on the cells of all reports together (checked before each
      report's cells are allocated); `MAX_MAP_CELLS` by default, None for no cap.
      At most `MAX_MESSAGES` messages are read.

  Returns:
    The decoded messages.

  Raises:
    JausDecodeError: no bytes, or anything `decode` refuses in any message
      (offsets count from the start of `data`); a last message cut short;
      more than `MAX_MESSAGES` messages.
    TypeError: data that is not bytes-like.
  """
  _check_cap(max_cells)
  r = _Reader(_as_bytes(data, "decode_all"))
  if not r.left():
    raise JausDecodeError(0, "no message: the input is empty")
  out, left = [], max_cells
  while r.left():
    if len(out) == MAX_MESSAGES:
      raise JausDecodeError(r.pos, f"more than MAX_MESSAGES = {MAX_MESSAGES} messages; a map at "
                            "the cell cap needs about 2048 tiles")
    msg = _read_message(r, left)
    if left is not None and isinstance(msg, CostMap2DReport):
      left -= msg.rows * msg.cols
    out.append(msg)
  return out


def decode_report(data: bytes, *, max_cells: int | None = MAX_MAP_CELLS) -> CostMap2DReport:
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



def read_message_file(path, *, hex: bool = False) -> bytes:
  """The message bytes of a file: a regular file of at most `MAX_FILE_BYTES`.

  Args:
    path: the file (str or os.PathLike).
    hex: the file is hex text (`to_hex`), at most 3 x MAX_FILE_BYTES long.

  Returns:
    The bytes (hex text converted).

  Raises:
    JausDecodeError (offset None): the file does not exist, is a FIFO,
      directory, device or socket (refused before reading, so nothing blocks),
      is larger than the cap, cannot be read, or (hex) is not hex text. A raw
      file that looks like hex text gets a hint to pass hex=True when decoded
      (`load_messages`).
  """
  path = str(path)
  what = "JAUS message file (hex)" if hex else "JAUS message file"
  cap = 3 * MAX_FILE_BYTES if hex else MAX_FILE_BYTES
  try:
    raw = read_regular_file(path, what, max_bytes=cap)
  except (OSError, ValueError) as e:   # FileNotFoundError is an OSError
    raise JausDecodeError(None, str(e)) from None
  if not hex:
    return raw
  try:
    return from_hex(raw.decode("ascii"))
  except (UnicodeDecodeError, ValueError) as e:
    raise JausDecodeError(None, f"{what} {path} is not hex text ({str(e)[:120]}); for raw "
                          "bytes drop --hex (hex=False)") from None


_HEX_CHARS = frozenset(b"0123456789abcdefABCDEF \t\r\n")


def load_messages(path, *, hex: bool = False, max_cells: int | None = MAX_MAP_CELLS
                  ) -> list[CostMap2DReport | CostMap2DQuery]:
  """`decode_all` of `read_message_file(path, hex=hex)`.

  Raises:
    JausDecodeError: any problem with the file or its bytes (one error type;
      a ValueError). A raw file whose bytes are all hex digits and spaces
      that fails to decode says to pass hex=True.
  """
  data = read_message_file(path, hex=hex)
  try:
    return decode_all(data, max_cells=max_cells)
  except JausDecodeError as e:
    if not hex and data and set(data[:4096]) <= _HEX_CHARS:
      raise JausDecodeError(e.offset, f"{e.reason} (the file looks like hex text: add --hex on "
                            "the command line, hex=True in Python)") from None
    raise
