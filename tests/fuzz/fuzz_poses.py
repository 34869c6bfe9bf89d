"""Fuzz target for `jaxfilters query --poses F.csv`: the pose-file reader (`jaxfilters.cli.read_poses`).

Registered in tests/fuzz/fuzz_inputs.py as the target "poses". Seeds are valid pose files (with and
without a header, two and three columns, CRLF, blank lines); `edit` mutates them with huge fields,
NaN / inf / out-of-float32 numbers, wrong column counts, binary junk, NUL bytes, unicode digits
and separators, and quoting. `run` must either return finite float32 poses [B, 3] or raise the
reader's one documented error, `CliError` (the CLI's exit 2), which it reports as ValueError.
"""

from __future__ import annotations

import random
from pathlib import Path

import numpy as np

from jaxfilters import cli

SEEDS = (
    b"x,y,yaw\n0.5,0.5,0.0\n1.5,-2.25,3.14\n",
    b"0,0\n1,2\n-3.5,4e-3\n",
    b"x,y\r\n1.0,2.0\r\n\r\n3.0,4.0\r\n",
    b"10.25, -7.5, 1.5707963\n\n\n-14.9,9.9,-3.0\n",
    b"\"1.0\",\"2.0\"\n3,4,0\n",
)

_NUMBERS = (b"nan", b"NaN", b"inf", b"-inf", b"1e39", b"-1e39", b"1e-45", b"1e-400", b"3.4e38",
            b"0x10", b"1_000", b"+5", b"-0", b"1" * 400, b"9" * 5000, b"", b" ", b"\"", b"'1'",
            "\u0661\u0662".encode(), "\uff11".encode(), "1\u00a0".encode(), "\u2028".encode(),
            "\U0001f600".encode(), b"\xff\xfe", b"\x00", b"\x1b[31m")


def seeds() -> list[bytes]:
  """The valid pose files the fuzzer mutates."""
  return list(SEEDS)


def edit(data: bytes, rng: random.Random) -> bytes:
  """One pose-file-aware mutation of `data`."""
  lines = data.split(b"\n")
  k = rng.randrange(len(lines))
  fields = lines[k].split(b",")
  op = rng.randrange(9)
  if op == 0:                                     # a huge field (over csv's 128 KB field limit or not)
    fields[rng.randrange(len(fields))] = b"1" * rng.choice((1000, 131_073, 300_000))
  elif op == 1:                                   # a special or hostile number
    fields[rng.randrange(len(fields))] = rng.choice(_NUMBERS)
  elif op == 2:                                   # wrong column count
    fields = fields[:rng.randrange(len(fields))] if rng.random() < 0.5 else fields + [b"1"] * rng.randint(1, 5)
  elif op == 3:                                   # binary junk inside a line
    pos = rng.randrange(len(lines[k]) + 1)
    junk = bytes(rng.randrange(256) for _ in range(rng.randint(1, 16)))
    lines[k] = lines[k][:pos] + junk + lines[k][pos:]
    return b"\n".join(lines)
  elif op == 4:                                   # many rows
    return data + b"1,2\n" * rng.choice((10, 1000, 100_000))
  elif op == 5:                                   # unicode separators and digits
    sep = rng.choice(("\u2028", "\u0085", "\x0b", "\x1c", "\r", "\uff0c", ";", "\t")).encode()
    return data.replace(rng.choice((b"\n", b",")), sep)
  elif op == 6:                                   # quoting
    fields = [b'"' + f + (b'"' if rng.random() < 0.7 else b"") for f in fields]
  elif op == 7:                                   # a long line of separators
    return data + b"," * rng.choice((100, 200_000)) + b"\n"
  else:                                           # a byte-order mark or an unknown encoding
    return rng.choice((b"\xef\xbb\xbf", b"\xff\xfe", b"\xfe\xff")) + data
  lines[k] = b",".join(fields)
  return b"\n".join(lines)


def run(data: bytes, folder: Path) -> np.ndarray:
  """Reads `data` as a pose file in `folder`; CliError comes back as ValueError, poses are checked."""
  path = folder / "poses.csv"
  path.write_bytes(data)
  try:
    poses, lines, echo = cli.read_poses(str(path))
  except cli.CliError as e:
    raise ValueError(str(e)) from None
  if poses.dtype != np.float32 or poses.ndim != 2 or poses.shape[1] != 3 or not np.isfinite(poses).all():
    raise AssertionError(f"read_poses returned {poses.dtype} {poses.shape} with non-finite values")
  if not (len(lines) == len(echo) == poses.shape[0] > 0):
    raise AssertionError("read_poses returned lists that do not match the poses")
  return poses
