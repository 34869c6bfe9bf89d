"""JAUS CostMap2D fuzz targets for `tests.fuzz.fuzz_inputs`: message bytes and message files.

    python -m tests.fuzz.fuzz_inputs --count 2000 --targets jaus,jaus-file

Targets (registered in `tests.fuzz.fuzz_inputs.TARGETS`):

  jaus       bytes -> `jaus.decode_all` (cell cap 2**22) -> the reports put together by
             `jaus.reports_to_grid` (a lone global-pose report with a given centre).
  jaus-file  the bytes written to a regular file -> `jaus.load_messages` (the file reader with
             its `MAX_FILE_BYTES` size cap and the `MAX_MAP_CELLS` cell cap, as the CLI reads
             it) -> `reports_to_grid`; a file the reader says looks like hex text is read again
             with hex=True, so hex seeds exercise the hex path.

Only ValueError (`JausDecodeError` for bytes and files) may escape. Seeds are the golden vectors
(tests/vectors/jaus/*.hex), the four tiles of a small map back to back (raw and as hex text; an
unmutated one must give the map back exactly), and a run-length message. `edit` is the
format-aware mutator: it sets the fields that size allocations and steer the parser (rows,
columns, the list count, the vtags, a run length, the message ID) to boundary values, and
repeats or cuts messages. Time per input is bounded by the caps (at most 2**26 cells, 4095 a
run) and by the harness's --timeout.
"""

from __future__ import annotations

import atexit
import functools
import os
import random
import shutil
import struct
import tempfile
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np

from jaxfilters import jaus
from jaxfilters.grid import OccupancyGrid

VECTORS = Path(__file__).resolve().parents[1] / "vectors" / "jaus"
_IDS = (0xD742, 0x4C11, 0xD738, 0x2C11)
_INTS = (0, 1, 2, 3, 7, 8, 255, 256, 4095, 4096, 16380, 32767, 65534, 65535)


class Seed(NamedTuple):
  """A valid input (the fields `tests.fuzz.fuzz_inputs` reads): bytes and its expected grid."""
  data: bytes
  expected: Callable[[], np.ndarray] | None = None


def _grid_of(msgs) -> OccupancyGrid | None:
  reports = [m for m in msgs if isinstance(m, jaus.CostMap2DReport)]
  # CostOrAttractiveness has no cost meaning (documented): decoding it is the whole test.
  reports = [r for r in reports if r.variant != "attractiveness"]
  if not reports:
    return None
  if len(reports) == 1 and isinstance(reports[0].pose, jaus.GlobalPose):
    return jaus.report_to_grid(reports[0], center=(0.0, 0.0, 0.0))
  return jaus.reports_to_grid(reports)


def run_bytes(data: bytes) -> OccupancyGrid | None:
  """Message bytes -> decoded messages -> (the reports) OccupancyGrid; only ValueError escapes."""
  return _grid_of(jaus.decode_all(data, max_cells=1 << 22))


@functools.cache
def _file() -> Path:
  shm = "/dev/shm" if os.access("/dev/shm", os.W_OK) else None
  root = Path(tempfile.mkdtemp(prefix="jaxfilters-fuzz-jaus-", dir=shm))
  atexit.register(shutil.rmtree, root, ignore_errors=True)
  return root / "m.bin"


def run_file(data: bytes) -> OccupancyGrid | None:
  """The bytes as a message file, read as the CLI reads it; only ValueError escapes."""
  path = _file()
  path.write_bytes(data)
  try:
    msgs = jaus.load_messages(path)
  except jaus.JausDecodeError as e:
    if "looks like hex text" not in e.reason:
      raise
    msgs = jaus.load_messages(path, hex=True)
  return _grid_of(msgs)


@functools.cache
def _tiled_map() -> tuple[OccupancyGrid, bytes]:
  rng = np.random.default_rng(3)
  data = rng.integers(-1, 101, size=(300, 260))
  data[rng.random(data.shape) < 0.4] = 0
  grid = OccupancyGrid.create(data, 0.05, (-3.2, 1.45, 0.3))
  tiles = jaus.grid_to_reports(grid, tiles=True)
  return grid, b"".join(jaus.encode_report(t.report) for t in tiles)


def vector_seeds() -> list[bytes]:
  """The golden vectors' bytes."""
  return [jaus.from_hex(p.read_text()) for p in sorted(VECTORS.glob("*.hex"))]


def seeds() -> list[Seed]:
  """Seeds of the `jaus` target: the golden vectors."""
  return [Seed(d) for d in vector_seeds()]


def file_seeds() -> list[Seed]:
  """Seeds of the `jaus-file` target: vectors, a tiled map (raw and hex), a run-length map."""
  grid, tiled = _tiled_map()
  board = OccupancyGrid.create(np.indices((40, 30)).sum(0) % 3 * 50, 0.1, (1.0, 2.0, 0.0))
  rle = jaus.encode_report(jaus.grid_to_report(board, variant="rle", profile="design",
                                               lossy=True))
  expected = lambda: grid.data  # noqa: E731
  return seeds() + [Seed(tiled, expected), Seed(jaus.to_hex(tiled).encode(), expected),
                    Seed(rle)]


def _count_at(data: bytes) -> int | None:
  """Offset of the first report's list count (None for a query or a short buffer)."""
  if len(data) < 2:
    return None
  (msg_id,) = struct.unpack_from("<H", data)
  if msg_id == 0xD742:
    return 2 + 8 + 11 + 1
  if msg_id == 0x4C11:
    return 2 + 12 + 11 + 1
  return None


def edit(data: bytes, rng: random.Random) -> bytes:
  """One JAUS-aware mutation of message bytes (see the module docstring)."""
  b = bytearray(data)
  at = _count_at(data)
  op = rng.randrange(8)
  if op == 0 and len(b) >= 6:            # NumberOfRows / NumberOfColumns
    struct.pack_into("<H", b, rng.choice((2, 4)), rng.choice(_INTS))
  elif op == 1 and at is not None and len(b) >= at + 2:   # the list count
    struct.pack_into("<H", b, at, rng.choice(_INTS))
  elif op == 2 and at is not None and len(b) > at:        # data vtag, pose vtag
    b[rng.choice((at - 1, at - 12))] = rng.randrange(5)
  elif op == 3 and at is not None and len(b) >= at + 4:   # a run-length word or a cost
    pos = at + 2 + 2 * rng.randrange((len(b) - at - 2) // 2)
    struct.pack_into("<H", b, pos, rng.choice((0x0008, 0xFFF8, 0xFFFF, 0x0000, 0x7FF9)))
  elif op == 4 and len(b) >= 2:          # another message ID
    struct.pack_into("<H", b, 0, rng.choice(_IDS))
  elif op == 5:                          # the message again, whole or cut
    b += data[:rng.randrange(len(data) + 1)] if rng.random() < 0.5 else data
  elif op == 6 and len(b) >= 14:         # MapWidth / MapHeight
    struct.pack_into("<H", b, rng.choice((6, 8)), rng.choice(_INTS))
  else:                                  # cut at a random point
    del b[rng.randrange(len(b) + 1):]
  return bytes(b)
