"""Fuzz target for the Gymnasium envs' host-side action check (`sims.rl.gym.check_actions`).

An input is either `J` + JSON text (nested lists of numbers, what a user passes as a Python list)
or `B` + one dtype byte + raw bytes (a NumPy array of that dtype, 2 columns where the length
allows): actions for a NavVectorEnv of 2 envs, shape [2, 2]. The check must return float32
[2, 2] finite values in [-1, 1] with no subnormal (`run` asserts it) or raise ValueError.
"""

from __future__ import annotations

import json
import random

import numpy as np

SHAPE = (2, 2)
DTYPES = (np.float64, np.float32, np.float16, np.int32, np.int64, np.uint8, np.bool_, np.complex64)


def run(data: bytes) -> None:
  """Checks one input; ValueError for a rejected action, AssertionError if an accepted one is bad."""
  from sims.rl.gym import check_actions
  if data[:1] == b"J":
    obj = json.loads(data[1:].decode("utf-8"))
  elif data[:1] == b"B" and len(data) >= 2:
    dtype = np.dtype(DTYPES[data[1] % len(DTYPES)])
    body = data[2:]
    body = body[:len(body) - len(body) % dtype.itemsize]
    obj = np.frombuffer(body, dtype)
    if obj.size % 2 == 0 and obj.size:
      obj = obj.reshape(-1, 2)
  else:
    raise ValueError("not an action input (first byte J or B)")
  a = check_actions(obj, SHAPE, "fuzz")
  assert isinstance(a, np.ndarray) and a.dtype == np.float32 and a.shape == SHAPE, (a.dtype, a.shape)
  assert np.all(np.isfinite(a)) and np.all(np.abs(a) <= 1.0), a
  assert not np.any((a != 0) & (np.abs(a) < np.finfo(np.float32).tiny)), a


def seeds() -> list[bytes]:
  out = [b"J" + json.dumps(v).encode() for v in ([[0.5, -0.25], [0.0, 1.0]], [[-1, 1], [0.125, -0.999]],
                                                  [[0.0, 0.0], [0.0, 0.0]])]
  for dt in (np.float64, np.float32):
    arr = np.asarray([[0.5, -0.25], [1.0, -1.0]], dt)
    out.append(b"B" + bytes([DTYPES.index(dt)]) + arr.tobytes())
  return out


_ODD = ("NaN", "Infinity", "-Infinity", "1e-50", "-2e-39", "1e400", "1.0000001", "-0", "true", "null",
        '"0.5"', "[0.5]", "[]", "{}", "1" * 400)


def edit(data: bytes, rng: random.Random) -> bytes:
  """Format-aware edits: odd JSON numbers and shapes, or odd float bit patterns in the binary form."""
  if data[:1] == b"J":
    text = data[1:].decode("utf-8", "replace")
    op = rng.randrange(3)
    if op == 0:
      nums = [t for t in text.replace("[", " ").replace("]", " ").replace(",", " ").split() if t]
      if nums:
        text = text.replace(rng.choice(nums), rng.choice(_ODD), 1)
    elif op == 1:
      text = "[" * rng.choice((1, 3, 40)) + text + "]" * rng.choice((0, 1, 3, 40))
    else:
      text = text.replace("],", rng.choice(("], [0.1, 0.2],", "],", "], 0.3,")), 1)
    return b"J" + text.encode("utf-8")
  if data[:1] != b"B" or len(data) < 2:               # generic edits broke the header: start a binary one
    data = b"B" + bytes([rng.randrange(len(DTYPES))]) + data[1:]
  body = bytearray(data[2:])
  if len(body) >= 8:
    i = rng.randrange(0, len(body) - 7, 1)
    body[i:i + 8] = rng.choice((np.float64("nan"), np.float64("inf"), np.float64(1e-50), np.float64(5e-324),
                                np.float64(1.0000001), np.float64(-1e300))).tobytes()
  dtype_byte = data[1] if rng.random() < 0.7 else rng.randrange(256)
  return b"B" + bytes([dtype_byte]) + bytes(body)
