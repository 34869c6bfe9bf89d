"""Map-file fuzzer: mutated YAML / PGM / PNG / BMP inputs through load_map, in sandboxed workers.

    python -m tests.fuzz.fuzz_inputs --count 100000 [--seed S] [--targets yaml,pgm,png]
        [--mem-mb 1024] [--workers 2] [--timeout 10] [--out out/fuzz_failures]

Each input is a valid seed file (a small map written several ways) with 1-3
mutations: generic byte edits (bit flips, interesting bytes and integers,
truncation, deletion, insertion, duplication) and format-aware edits (YAML
values such as 1e-50, 1e39, 10**400, aliases, deep nesting, duplicate keys,
device paths; PGM header fields and samples above maxval; PNG IHDR fields,
IDAT contents and chunk order with the CRC fixed so the damage reaches the
decoder; BMP header fields). About 2 % of inputs are left unmutated and must
load to the seed's expected grid.

Inputs are generated from (seed, target, index), so any input can be rebuilt
from its index. Worker subprocesses (`--workers`) run them one at a time under
`resource.setrlimit(RLIMIT_AS, --mem-mb)`, set after their imports; the
parent kills a worker that takes longer than `--timeout` seconds on one input
and starts another. Outcomes: `loaded`, `ValueError`, `FileNotFoundError`;
anything else is a failure: another exception (MemoryError, OverflowError,
...), a timeout, a crash, an error message over 1000 characters, a loaded grid
that is not int8 -1..100, or an unmutated seed that fails or loads
differently. The first `--keep` failing inputs are written to `--out` with a
note of what happened. Exit status 1 if anything failed.

Targets live in the `TARGETS` registry (name -> `Target(run, seeds, edit)`:
`run(bytes)` raises on bad input, `seeds()` lists valid `Seed`s, `edit` is an
optional format-aware mutator), so another decoder is one line, e.g. the JAUS
codec with its golden vectors as seeds:

    TARGETS["jaus"] = Target(jaus.fuzz_target, lambda: [
        Seed(jaus.from_hex(p.read_text())) for p in Path("tests/vectors/jaus").glob("*.hex")])
"""

from __future__ import annotations

import argparse
import atexit
import dataclasses
import functools
import io
import json
import os
import random
import re
import resource
import selectors
import shutil
import struct
import subprocess
import sys
import tempfile
import time
import traceback
import zlib
from collections import Counter, defaultdict
from pathlib import Path
from typing import Any, Callable

import numpy as np
from PIL import Image

from jaxfilters.grid import OccupancyGrid
from jaxfilters.map_io import load_map, load_map_image
from tests.fuzz import fuzz_actions, fuzz_jaus, fuzz_params, fuzz_policy, fuzz_poses, fuzz_robot

OK_OUTCOMES = ("loaded", "ValueError", "FileNotFoundError")
MAX_MESSAGE = 1000
_ROOT = Path(__file__).resolve().parents[2]

# --------------------------------------------------------------------------- seed images

# 5 x 7 gray pixels around Nav2's thresholds (89/90 occupied edge, 205/206 free edge).
BASE = np.array([
    [0, 254, 254, 205, 206, 89, 90],
    [254, 0, 128, 100, 50, 255, 254],
    [205, 254, 0, 254, 254, 200, 1],
    [254, 254, 254, 0, 30, 60, 255],
    [90, 89, 206, 205, 254, 254, 0]], np.uint8)
ALPHA = np.where((np.arange(35).reshape(5, 7) % 4) == 0, 0, 255).astype(np.uint8)
PNG_SIG = b"\x89PNG\r\n\x1a\n"
ADAM7 = ((0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2),
         (0, 1, 1, 2))


def png_chunk(ctype: bytes, body: bytes) -> bytes:
  return struct.pack(">I", len(body)) + ctype + body + struct.pack(">I", zlib.crc32(ctype + body))


def encode_png(samples, *, depth: int = 8, colour: int = 0, interlace: int = 0,
               palette: bytes | None = None, trns: bytes | None = None, idat_parts: int = 1,
               level: int = 6, extra: tuple = ()) -> bytes:
  """A minimal PNG writer for test inputs (filter 0 on every row; Pillow cannot interlace)."""
  a = np.asarray(samples)
  a = a[..., None] if a.ndim == 2 else a
  h, w, _ = a.shape

  def scanlines(sub: np.ndarray) -> bytes:
    out = []
    for row in sub:
      flat = row.reshape(-1).astype(np.uint32)
      if depth == 16:
        body = flat.astype(">u2").tobytes()
      elif depth == 8:
        body = flat.astype(np.uint8).tobytes()
      else:
        bits = (flat[:, None] >> np.arange(depth - 1, -1, -1)) & 1
        body = np.packbits(bits.astype(np.uint8).reshape(-1)).tobytes()
      out.append(b"\x00" + body)
    return b"".join(out)

  if interlace:
    raw = b"".join(scanlines(a[y0::dy, x0::dx]) for x0, y0, dx, dy in ADAM7
                   if a[y0::dy, x0::dx].shape[0] and a[y0::dy, x0::dx].shape[1])
  else:
    raw = scanlines(a)
  comp = zlib.compress(raw, level)
  cuts = np.linspace(0, len(comp), idat_parts + 1).astype(int)
  chunks = [png_chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, depth, colour, 0, 0, interlace))]
  if palette is not None:
    chunks.append(png_chunk(b"PLTE", palette))
  if trns is not None:
    chunks.append(png_chunk(b"tRNS", trns))
  chunks += [png_chunk(t, d) for t, d in extra]
  chunks += [png_chunk(b"IDAT", comp[a:b]) for a, b in zip(cuts[:-1], cuts[1:])]
  return PNG_SIG + b"".join(chunks) + png_chunk(b"IEND", b"")


def _pillow_bytes(img: Image.Image, fmt: str, **kw) -> bytes:
  buf = io.BytesIO()
  img.save(buf, format=fmt, **kw)
  return buf.getvalue()


def pillow_reference(data: bytes) -> tuple[np.ndarray, np.ndarray | None]:
  """Pixels and alpha as the loader decoded them before strict decoding (Pillow only)."""
  with Image.open(io.BytesIO(data)) as img:
    img.load()
    if "transparency" in img.info and img.mode in ("1", "L", "P", "RGB"):
      img = img.convert("RGBA")
    if img.mode in ("I;16", "I;16B", "I"):
      return ((np.asarray(img).astype(np.int64) + 128) // 257).astype(np.uint8), None
    if img.mode in ("1", "L"):
      return np.asarray(img.convert("L")), None
    if img.mode == "LA":
      la = np.asarray(img)
      return la[..., 0], la[..., 1]
    if img.mode == "RGBA":
      rgba = np.asarray(img)
      return rgba[..., :3], rgba[..., 3]
    return np.asarray(img.convert("RGB")), None


def pgm_seeds() -> list[bytes]:
  b = BASE
  h, w = b.shape
  big = np.rint(b.astype(float) / 255 * 1000).astype(">u2")
  small = np.rint(b.astype(float) / 255 * 100).astype(np.uint8)
  bits = (b < 128).astype(np.uint8)
  return [
      b"P5\n%d %d\n255\n" % (w, h) + b.tobytes(),
      b"P5\n# written by a test\n%d %d\n# comment\n255\n" % (w, h) + b.tobytes(),
      b"P5 %d %d 65535\n" % (w, h) + (b.astype(">u2") * 257).tobytes(),
      b"P5\n%d %d\n1000\n" % (w, h) + big.tobytes(),
      b"P5\n%d %d\n100\n" % (w, h) + small.tobytes(),
      b"P2\n%d %d\n255\n" % (w, h) + "\n".join(" ".join(map(str, r)) for r in b).encode() + b"\n",
      b"P6\n%d %d\n255\n" % (w, h) + np.repeat(b[..., None], 3, 2).tobytes(),
      b"P3\n%d %d\n255\n" % (w, h) + " ".join(map(str, np.repeat(b, 3).tolist())).encode(),
      b"P4\n%d %d\n" % (w, h) + np.packbits(bits, axis=1).tobytes(),
      b"P1\n%d %d\n" % (w, h) + "\n".join("".join(map(str, r)) for r in bits).encode(),
  ]


def png_seeds() -> list[bytes]:
  b = BASE
  rgb = np.stack([b, b[::-1], b[:, ::-1]], axis=2)
  pal = bytes(np.repeat(np.array([0, 90, 205, 254], np.uint8), 3))
  index = np.searchsorted([0, 90, 205, 254], b, side="right") - 1
  return [
      encode_png(b),
      encode_png(b, interlace=1),
      encode_png(b, idat_parts=3, level=0, extra=((b"tEXt", b"Comment\x00map"),)),
      encode_png(b >> 7, depth=1),
      encode_png(b >> 6, depth=2, interlace=1),
      encode_png(b >> 4, depth=4),
      encode_png(b.astype(np.uint32) * 257, depth=16),
      encode_png(rgb, colour=2),
      encode_png(np.dstack([rgb, ALPHA]), colour=6, interlace=1),
      encode_png(np.dstack([b, ALPHA]), colour=4),
      encode_png(index, depth=2, colour=3, palette=pal, trns=b"\xff\x80"),
      encode_png(b, trns=b"\x00\xcd"),
      _pillow_bytes(Image.fromarray(b), "PNG", optimize=True),
      _pillow_bytes(Image.fromarray(np.dstack([rgb, ALPHA]), "RGBA"), "PNG"),
  ]


def bmp_seeds() -> list[bytes]:
  b = BASE
  rgb = np.stack([b, b[::-1], b[:, ::-1]], axis=2)
  pal = Image.fromarray((b >> 6).astype(np.uint8), "P")
  pal.putpalette([0, 0, 0, 90, 90, 90, 205, 205, 205, 254, 254, 254])
  return [
      _pillow_bytes(Image.fromarray(b), "BMP"),
      _pillow_bytes(Image.fromarray(rgb), "BMP"),
      _pillow_bytes(Image.fromarray(b < 128).convert("1"), "BMP"),
      _pillow_bytes(pal, "BMP"),
  ]


# --------------------------------------------------------------------------- YAML seeds

_YAML_SETTINGS = [
    dict(mode=None, occupied_thresh=0.65, free_thresh=0.196, negate=0),
    dict(mode="scale", occupied_thresh=1.0, free_thresh=0.0, negate=0),
    dict(mode="raw", occupied_thresh=0.65, free_thresh=0.196, negate=0),
    dict(mode="Trinary", occupied_thresh=0.65, free_thresh=0.25, negate=1),
    dict(mode="scale", occupied_thresh=0.99, free_thresh=0.01, negate=0),
]


def yaml_seeds() -> list[tuple[bytes, dict]]:
  out = []
  for i, s in enumerate(_YAML_SETTINGS):
    mode = f"mode: {s['mode']}\n" if s["mode"] else ""
    if i % 2 == 0:
      text = (f"image: m.pgm\n{mode}resolution: 0.05\norigin: [-10.0, -10.0, 0.0]\n"
              f"negate: {s['negate']}\noccupied_thresh: {s['occupied_thresh']}\n"
              f"free_thresh: {s['free_thresh']}\n")
    else:
      text = (f"# a map\nfree_thresh: '{s['free_thresh']}'\n{mode}negate: "
              f"{'true' if s['negate'] else 'false'}\norigin:\n  - -1\n  - '2.5'\n  - 0\n"
              f"occupied_thresh: {s['occupied_thresh']}\nresolution: 5e-2\nimage: \"m.pgm\"\n")
    out.append((text.encode(), s))
  return out


# --------------------------------------------------------------------------- mutators

INTERESTING_INTS = (0, 1, 2, 3, 7, 8, 16, 127, 128, 255, 256, 1023, 1032, 4096, 13000, 65535,
                    65536, 2**31 - 1, 2**31, 2**32 - 1)
_YAML_VALUES = ("1e-50", "1e39", "-1e39", "1" + "0" * 400, "-1", "0", "-0.0", ".nan", ".inf",
                "-.inf", "1e-40", "3.4e38", "[1, 2]", "[1.0, 2.0, 0.0, 0.0]", "{a: 1}", "~", "''",
                "!!binary aGVsbG8=", "2001-02-30", "2001-01-01", "yes", "&a [1, 2, 3]", "*a",
                "\"0x10\"", "0x10", "017", "1_000", "1:30", "/dev/zero", "/dev/null", "/", ".",
                "m.yaml", "missing.pgm", "../../../../etc/hostname", "a" * 5000, "\"\\x00\"",
                "!!python/object:os.system x", "? complex", "|\n  block", "\"\\u00e9\"")
_YAML_BOMB = ('a: &a ["x","x","x","x","x","x","x","x","x"]\nb: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a]\n'
              'c: &c [*b,*b,*b,*b,*b,*b,*b,*b,*b]\nd: &d [*c,*c,*c,*c,*c,*c,*c,*c,*c]\n'
              'e: &e [*d,*d,*d,*d,*d,*d,*d,*d,*d]\nf: &f [*e,*e,*e,*e,*e,*e,*e,*e,*e]\n'
              'g: &g [*f,*f,*f,*f,*f,*f,*f,*f,*f]\nimage: m.pgm\nresolution: *g\n')


def _generic(data: bytes, rng: random.Random) -> bytes:
  b = bytearray(data)
  op = rng.randrange(9)
  if not b:
    return bytes(rng.randbytes(rng.randrange(1, 16)))
  pos = rng.randrange(len(b))
  if op == 0:  # bit flips
    for _ in range(rng.choice((1, 1, 2, 4, 8))):
      i = rng.randrange(len(b))
      b[i] ^= 1 << rng.randrange(8)
  elif op == 1:  # interesting byte
    b[pos] = rng.choice((0, 1, 0x7F, 0x80, 0xFF, rng.randrange(256)))
  elif op == 2:  # interesting integer, big or little endian
    v = rng.choice(INTERESTING_INTS)
    n = rng.choice((1, 2, 4))
    raw = (v % (1 << (8 * n))).to_bytes(n, rng.choice(("big", "little")))
    b[pos:pos + n] = raw
  elif op == 3:  # truncate
    del b[rng.randrange(len(b)):]
  elif op == 4:  # delete a range
    del b[pos:pos + rng.randrange(1, 64)]
  elif op == 5:  # insert random bytes
    b[pos:pos] = rng.randbytes(rng.randrange(1, 32))
  elif op == 6:  # duplicate a range
    b[pos:pos] = b[pos:pos + rng.randrange(1, 256)]
  elif op == 7:  # append
    b += rng.randbytes(rng.randrange(1, 64))
  else:  # copy a range over another place
    src = rng.randrange(len(b))
    piece = b[src:src + rng.randrange(1, 32)]
    b[pos:pos + len(piece)] = piece
  return bytes(b)


def yaml_edit(data: bytes, rng: random.Random) -> bytes:
  text = data.decode("utf-8", "replace")
  lines = text.splitlines(keepends=True) or [""]
  op = rng.randrange(8)
  if op == 0:  # replace one number
    nums = list(re.finditer(r"-?\d+(\.\d+)?([eE]-?\d+)?", text))
    if nums:
      m = rng.choice(nums)
      text = text[:m.start()] + rng.choice(_YAML_VALUES) + text[m.end():]
  elif op == 1:  # replace one value
    i = rng.randrange(len(lines))
    key = lines[i].split(":", 1)[0] if ":" in lines[i] else "image"
    lines[i] = f"{key}: {rng.choice(_YAML_VALUES)}\n"
    text = "".join(lines)
  elif op == 2:
    text = _YAML_BOMB if rng.random() < 0.5 else text + "x: " + _YAML_BOMB.split("\n")[0][3:]
  elif op == 3:  # duplicate a line (a duplicate key)
    i = rng.randrange(len(lines))
    lines.insert(i, lines[i])
    text = "".join(lines)
  elif op == 4:  # deep nesting
    n = rng.choice((50, 500, 5000, 30000))
    text = text + "deep: " + "[" * n + "]" * (n if rng.random() < 0.5 else 0) + "\n"
  elif op == 5:  # too large
    text = text + "#" + "x" * rng.choice((1000, 70000)) + "\n"
  elif op == 6:  # delete a line
    del lines[rng.randrange(len(lines))]
    text = "".join(lines)
  else:
    return data + rng.choice((b"\xff\xfe", b"\x00", b"\xc3", b"\t: x\n", b"- y\n"))
  return text.encode("utf-8", "surrogateescape")


def pgm_edit(data: bytes, rng: random.Random) -> bytes:
  m = re.match(rb"(P\d)(\s+(?:#[^\n]*\n\s*)*)(\d+)(\s+)(\d+)(\s+)(?:(\d+)(\s))?", data)
  if not m:
    return _generic(data, rng)
  op = rng.randrange(5)
  groups = [g for g in m.groups()]
  if op == 0:  # a header field
    idx = rng.choice([i for i in (2, 4, 6) if groups[i] is not None])
    groups[idx] = rng.choice((b"0", b"1", b"2", b"13000", b"65535", b"65536", b"4294967297",
                              b"99999999999", b"-1", b"1e3", b"", b"#c\n5", b"007",
                              str(rng.choice(INTERESTING_INTS)).encode()))
  elif op == 1:  # the magic
    groups[0] = rng.choice((b"P1", b"P2", b"P3", b"P4", b"P5", b"P6", b"P7", b"Pf", b"P0"))
  elif op == 2:  # a sample above maxval or at the limits
    body = bytearray(data[m.end():])
    if body:
      body[rng.randrange(len(body))] = rng.choice((0xFF, 0xFE, 0x80, 101, 0x39))
    return data[:m.end()] + bytes(body)
  elif op == 3:  # raster one short / one long
    return data[:-1] if rng.random() < 0.5 else data + b"\x00"
  else:  # the whitespace after maxval
    if groups[7] is not None:
      groups[7] = rng.choice((b"", b"\r\n", b"  ", b"#"))
  head = b"".join(g for g in groups if g is not None)
  return head + data[m.end():]


def png_chunks(data: bytes) -> list[list] | None:
  if not data.startswith(PNG_SIG):
    return None
  pos, out = 8, []
  while pos + 12 <= len(data):
    length, ctype = struct.unpack(">I4s", data[pos:pos + 8])
    if pos + 12 + length > len(data):
      return None
    out.append([ctype, data[pos + 8:pos + 8 + length]])
    pos += 12 + length
  return out


def png_edit(data: bytes, rng: random.Random) -> bytes:
  chunks = png_chunks(data)
  if not chunks:
    return _generic(data, rng)
  fix_crc = rng.random() < 0.85
  op = rng.randrange(7)
  i = rng.randrange(len(chunks))
  if op == 0:  # an IHDR field
    body = bytearray(chunks[0][1])
    if len(body) == 13:
      field = rng.randrange(7)
      if field < 2:
        v = rng.choice(INTERESTING_INTS + (13000, 100000))
        body[4 * field:4 * field + 4] = (v % 2**32).to_bytes(4, "big")
      else:
        body[6 + field] = rng.choice((0, 1, 2, 3, 4, 5, 6, 8, 16, 32, 255))
      chunks[0][1] = bytes(body)
  elif op == 1:  # damage the compressed data itself
    idat = [c for c in chunks if c[0] == b"IDAT"]
    if idat:
      c = rng.choice(idat)
      c[1] = _generic(c[1], rng)
  elif op == 2:  # valid zlib holding other scanlines (short, long, bad filters)
    idat = [c for c in chunks if c[0] == b"IDAT"]
    if idat:
      try:
        raw = zlib.decompress(b"".join(c[1] for c in idat))
      except zlib.error:
        raw = b""
      raw = _generic(raw, rng) if raw else raw
      first = chunks.index(idat[0])
      chunks = [c for c in chunks if c[0] != b"IDAT"]
      chunks.insert(first, [b"IDAT", zlib.compress(raw)])
  elif op == 3:  # drop, duplicate or move a chunk
    c = chunks.pop(i)
    if rng.random() < 0.6:
      chunks.insert(rng.randrange(len(chunks) + 1), c)
      if rng.random() < 0.5:
        chunks.insert(rng.randrange(len(chunks) + 1), list(c))
  elif op == 4:  # insert a chunk
    ctype = rng.choice((b"tEXt", b"abCd", b"ABCD", b"PLTE", b"tRNS", b"IDAT", b"IEND", b"IHDR"))
    chunks.insert(rng.randrange(1, len(chunks) + 1), [ctype, rng.randbytes(rng.randrange(0, 40))])
  elif op == 5:  # the 92-byte bomb: huge declared size, tiny data
    w, h = rng.choice(((13000, 13000), (100000, 1), (1, 2**31 - 1), (4096, 4096), (8193, 8192)))
    chunks = [[b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)],
              [b"IDAT", zlib.compress(b"\x00" * rng.choice((10, 1000, 100000)))], [b"IEND", b""]]
  else:  # a chunk's length field (CRC left alone)
    fix_crc = False
  out = [PNG_SIG]
  for ctype, body in chunks:
    crc = zlib.crc32(ctype + body) if fix_crc else zlib.crc32(ctype + body) ^ rng.choice((0, 1))
    length = len(body)
    if op == 6 and rng.random() < 0.3:
      length = rng.choice((0, length + 1, max(0, length - 1), 2**31, 2**32 - 1))
    out.append(struct.pack(">I", length) + ctype + body + struct.pack(">I", crc))
  return b"".join(out)


def bmp_edit(data: bytes, rng: random.Random) -> bytes:
  if len(data) < 54:
    return _generic(data, rng)
  b = bytearray(data)
  field = rng.choice(((2, 4), (10, 4), (14, 4), (18, 4), (22, 4), (26, 2), (28, 2), (30, 4),
                      (46, 4)))
  pos, n = field
  v = rng.choice(INTERESTING_INTS + (-1, -7, 1, 4, 8, 24, 32))
  b[pos:pos + n] = (v % (1 << (8 * n))).to_bytes(n, "little")
  return bytes(b)


def mutate(data: bytes, rng: random.Random, edit: Callable | None) -> bytes:
  for _ in range(rng.choice((1, 1, 1, 2, 2, 3))):
    data = edit(data, rng) if edit is not None and rng.random() < 0.5 else _generic(data, rng)
  return data


# --------------------------------------------------------------------------- targets


@dataclasses.dataclass(frozen=True)
class Seed:
  """A valid input; `expected()` gives the grid it must load to (None: only that it loads)."""
  data: bytes
  expected: Callable[[], np.ndarray] | None = None


@dataclasses.dataclass(frozen=True)
class Target:
  """One fuzz target: `run(bytes)` loads an input (raising on bad ones)."""
  run: Callable[[bytes], Any]
  seeds: Callable[[], list[Seed]]
  edit: Callable[[bytes, random.Random], bytes] | None = None


_TMP_PARENT: str | None = None  # the parent's temporary folder, for workers


def _fast_tmp() -> str | None:
  """A RAM-backed folder when there is one: writing two files per input on a disk costs ms."""
  return "/dev/shm" if os.access("/dev/shm", os.W_OK) else None


@functools.cache
def workdir() -> Path:
  """Per-process folder: yaml/ (a fixed m.pgm beside the fuzzed m.yaml) and img/."""
  root = Path(tempfile.mkdtemp(prefix="jaxfilters-fuzz-", dir=_TMP_PARENT or _fast_tmp()))
  if _TMP_PARENT is None:
    atexit.register(shutil.rmtree, root, ignore_errors=True)
  (root / "yaml").mkdir()
  (root / "img").mkdir()
  (root / "yaml" / "m.pgm").write_bytes(pgm_seeds()[0])
  (root / "img" / "m.yaml").write_text(
      "image: m.img\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n"
      "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
  return root


def run_yaml(data: bytes) -> OccupancyGrid:
  path = workdir() / "yaml" / "m.yaml"
  path.write_bytes(data)
  return load_map(path)


def run_image(data: bytes) -> OccupancyGrid:
  (workdir() / "img" / "m.img").write_bytes(data)
  return load_map(workdir() / "img" / "m.yaml")


def _image_expected(data: bytes) -> Callable[[], np.ndarray]:
  def expected() -> np.ndarray:
    pixels, alpha = pillow_reference(data)
    return load_map_image(pixels, alpha, mode="trinary", occupied_thresh=0.65, free_thresh=0.196)
  return expected


def _yaml_expected(settings: dict) -> Callable[[], np.ndarray]:
  return lambda: load_map_image(BASE, mode=settings["mode"] or "trinary",
                                occupied_thresh=settings["occupied_thresh"],
                                free_thresh=settings["free_thresh"], negate=settings["negate"])


TARGETS: dict[str, Target] = {
    "yaml": Target(run_yaml, lambda: [Seed(d, _yaml_expected(s)) for d, s in yaml_seeds()],
                   yaml_edit),
    "pgm": Target(run_image, lambda: [Seed(d, _image_expected(d)) for d in pgm_seeds()], pgm_edit),
    "png": Target(run_image, lambda: [Seed(d, _image_expected(d)) for d in png_seeds()], png_edit),
    "bmp": Target(run_image, lambda: [Seed(d, _image_expected(d)) for d in bmp_seeds()], bmp_edit),
    "jaus": Target(fuzz_jaus.run_bytes, fuzz_jaus.seeds, fuzz_jaus.edit),
    "jaus-file": Target(fuzz_jaus.run_file, fuzz_jaus.file_seeds, fuzz_jaus.edit),
    "params": Target(fuzz_params.run, fuzz_params.seeds, fuzz_params.edit),
    "poses": Target(lambda d: fuzz_poses.run(d, workdir()), lambda: [Seed(d) for d in fuzz_poses.seeds()],
                    fuzz_poses.edit),
    "policy-json": Target(fuzz_policy.run_json, lambda: [Seed(d) for d in fuzz_policy.json_seeds()],
                          fuzz_policy.json_edit),
    "policy-msgpack": Target(fuzz_policy.run_msgpack, lambda: [Seed(d) for d in fuzz_policy.msgpack_seeds()],
                             fuzz_policy.msgpack_edit),
    "gym-actions": Target(fuzz_actions.run, lambda: [Seed(d) for d in fuzz_actions.seeds()], fuzz_actions.edit),
    "robot": Target(fuzz_robot.run, lambda: [Seed(d) for d in fuzz_robot.seeds()], fuzz_robot.edit),
}


@functools.cache
def seeds_of(target: str) -> list[Seed]:
  return TARGETS[target].seeds()


def make_input(target: str, seed: int, index: int) -> tuple[bytes, int | None]:
  """Input number `index` of `target`: (bytes, the seed number if it is an unmutated seed)."""
  rng = random.Random(f"{seed}/{target}/{index}")
  seeds = seeds_of(target)
  k = rng.randrange(len(seeds))
  data = seeds[k].data
  if rng.random() >= 0.02:
    data = mutate(data, rng, TARGETS[target].edit)
  return data, (k if data == seeds[k].data else None)


def run_one(target: str, data: bytes, seed_k: int | None) -> tuple[str, str]:
  """Runs one input; returns (outcome, detail). Failures start with 'failure:'."""
  try:
    grid = TARGETS[target].run(data)
  except FileNotFoundError as e:
    outcome, message = "FileNotFoundError", str(e)
  except ValueError as e:
    outcome, message = "ValueError", str(e)
  except Exception as e:  # noqa: BLE001 - any other exception is what the fuzzer looks for
    tb = traceback.format_exception(e)
    return f"failure:{type(e).__name__}", "".join(tb)[-3000:]
  else:
    if isinstance(grid, OccupancyGrid):
      d = np.asarray(grid.data)
      if d.dtype != np.int8 or d.ndim != 2 or d.min() < -1 or d.max() > 100:
        return "failure:bad-grid", f"dtype {d.dtype} shape {d.shape}"
      if seed_k is not None and seeds_of(target)[seed_k].expected is not None:
        want = seeds_of(target)[seed_k].expected()
        if d.shape != want.shape or not np.array_equal(d, want):
          return "failure:valid-changed", f"seed {seed_k} loaded to another grid"
    return "loaded", ""
  if seed_k is not None:
    return "failure:valid-rejected", f"seed {seed_k}: {outcome}: {message[:500]}"
  if len(message) > MAX_MESSAGE:
    return "failure:long-message", f"{len(message)} characters: {message[:300]}"
  return outcome, message[:200]


# --------------------------------------------------------------------------- worker


def _vm_bytes() -> int:
  with open("/proc/self/status") as f:
    for line in f:
      if line.startswith("VmSize:"):
        return int(line.split()[1]) * 1024
  return 0


def _worker(args) -> int:
  import warnings
  global _TMP_PARENT
  _TMP_PARENT = args.tmp
  warnings.simplefilter("ignore")  # Pillow's warnings are not failures
  for target in TARGETS:  # build seeds and expected grids before the memory limit
    for s in seeds_of(target):
      if s.expected is not None:
        s.expected()
  workdir()
  limit = args.mem_mb * 1024 * 1024
  used = _vm_bytes()
  if used >= limit:
    print(f"error: --mem-mb {args.mem_mb} is below this worker's address space after its "
          f"imports ({used >> 20} MiB)", flush=True)
    return 2
  resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
  print(f"ready {used >> 20}", flush=True)
  for line in sys.stdin:
    target, index = line.split()
    data, seed_k = make_input(target, args.seed, int(index))
    outcome, detail = run_one(target, data, seed_k)
    print(json.dumps([int(index), outcome, detail]), flush=True)
  return 0


class _Worker:
  def __init__(self, args, number: int, log_dir: Path, tmp: str):
    self.log = open(log_dir / f"worker-{number}.log", "ab")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(_ROOT)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]))
    self.proc = subprocess.Popen(
        [sys.executable, "-m", "tests.fuzz.fuzz_inputs", "--worker", "--seed", str(args.seed),
         "--mem-mb", str(args.mem_mb), "--tmp", tmp], cwd=_ROOT, env=env, stdin=subprocess.PIPE,
        stdout=subprocess.PIPE, stderr=self.log, text=True, bufsize=1)
    line = self.proc.stdout.readline()
    if not line.startswith("ready"):
      self.kill()
      raise SystemExit(f"fuzz worker failed to start: {line.strip() or 'no output'} "
                       f"(see {self.log.name})")
    self.job: tuple[str, int, float] | None = None

  def send(self, target: str, index: int, timeout: float) -> None:
    self.job = (target, index, time.monotonic() + timeout)
    try:
      self.proc.stdin.write(f"{target} {index}\n")
      self.proc.stdin.flush()
    except BrokenPipeError:
      pass  # the worker died; reading its output gives EOF, recorded as a crash

  def kill(self) -> None:
    self.proc.kill()
    self.proc.wait()
    self.log.close()


def _parse_args(argv):
  p = argparse.ArgumentParser(prog="python -m tests.fuzz.fuzz_inputs",
                              description=__doc__.split("\n\n")[0])
  p.add_argument("--count", type=int, default=1000, help="inputs in all (default 1000)")
  p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
  p.add_argument("--targets", default=",".join(TARGETS),
                 help=f"comma-separated, from {', '.join(TARGETS)} (default all)")
  p.add_argument("--mem-mb", type=int, default=1024,
                 help="RLIMIT_AS of each worker in MiB, set after its imports, which take "
                      "about 450 MiB of address space (default 1024)")
  p.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
  p.add_argument("--timeout", type=float, default=10.0,
                 help="seconds one input may take before its worker is killed (default 10)")
  p.add_argument("--out", default="out/fuzz_failures", help="folder for failing inputs")
  p.add_argument("--keep", type=int, default=20, help="failing inputs to save (default 20)")
  p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
  p.add_argument("--tmp", default=None, help=argparse.SUPPRESS)
  args = p.parse_args(argv)
  targets = [t.strip() for t in args.targets.split(",") if t.strip()]
  unknown = [t for t in targets if t not in TARGETS]
  if unknown or not targets:
    p.error(f"--targets: unknown {', '.join(unknown) or '(none given)'}; "
            f"choose from {', '.join(TARGETS)}")
  if args.count < 1 or args.workers < 1 or args.mem_mb < 64 or args.timeout <= 0:
    p.error("--count and --workers must be >= 1, --mem-mb >= 64, --timeout > 0")
  args.target_list = targets
  return args


def main(argv=None) -> int:
  args = _parse_args(argv)
  if args.worker:
    return _worker(args)
  out = Path(args.out)
  out.mkdir(parents=True, exist_ok=True)
  counts: dict[str, Counter] = defaultdict(Counter)
  kept = 0
  started = time.monotonic()
  tmp = tempfile.TemporaryDirectory(prefix="jaxfilters-fuzz-", dir=_fast_tmp())
  workers = [_Worker(args, n, out, tmp.name) for n in range(args.workers)]
  sel = selectors.DefaultSelector()
  for w in workers:
    sel.register(w.proc.stdout, selectors.EVENT_READ, w)
  jobs = iter(range(args.count))
  done = 0

  def record(target: str, index: int, outcome: str, detail: str) -> None:
    nonlocal kept, done
    counts[target][outcome] += 1
    done += 1
    if outcome.startswith("failure:") and kept < args.keep:
      kept += 1
      data, seed_k = make_input(target, args.seed, index)
      stem = out / f"{target}-{index}"
      stem.with_suffix(".bin").write_bytes(data)
      stem.with_suffix(".txt").write_text(f"target {target}, index {index}, seed {args.seed}, "
                                          f"unmutated seed {seed_k}\n{outcome}\n{detail}\n")

  def replace(w: _Worker) -> _Worker:
    sel.unregister(w.proc.stdout)
    w.kill()
    fresh = _Worker(args, workers.index(w), out, tmp.name)
    workers[workers.index(w)] = fresh
    sel.register(fresh.proc.stdout, selectors.EVENT_READ, fresh)
    return fresh

  def feed(w: _Worker) -> None:
    index = next(jobs, None)
    if index is not None:
      w.send(args.target_list[index % len(args.target_list)], index, args.timeout)

  try:
    for w in workers:
      feed(w)
    while any(w.job for w in workers):
      now = time.monotonic()
      wait = max(0.0, min(w.job[2] for w in workers if w.job) - now)
      for key, _ in sel.select(timeout=wait):
        w = key.data
        line = w.proc.stdout.readline()
        target, index, _ = w.job
        w.job = None
        if not line:
          rc = w.proc.poll()
          record(target, index, "failure:crash", f"worker ended (exit status {rc})")
          w = replace(w)
        else:
          got_index, outcome, detail = json.loads(line)
          assert got_index == index, (got_index, index)
          record(target, index, outcome, detail)
        feed(w)
      now = time.monotonic()
      for w in list(workers):
        if w.job and now > w.job[2]:
          target, index, _ = w.job
          record(target, index, "failure:timeout", f"no result within {args.timeout} s")
          w = replace(w)
          feed(w)
      if done and done % 10000 == 0:
        print(f"... {done} inputs, {time.monotonic() - started:.0f} s", file=sys.stderr,
              flush=True)
  finally:
    for w in workers:
      w.kill()
    tmp.cleanup()
  wall = time.monotonic() - started

  outcomes = list(OK_OUTCOMES) + sorted({o for c in counts.values() for o in c} - set(OK_OUTCOMES))
  width = max(len(o) for o in outcomes)
  print(f"{'target':<8}{'inputs':>9}  " + "  ".join(f"{o:>{width}}" for o in outcomes))
  for target in args.target_list:
    c = counts[target]
    print(f"{target:<8}{sum(c.values()):>9}  " + "  ".join(f"{c[o]:>{width}}" for o in outcomes))
  failures = sum(n for c in counts.values() for o, n in c.items() if o.startswith("failure:"))
  print(f"{done} inputs in {wall:.1f} s ({done / wall:.0f}/s) with {args.workers} workers, "
        f"RLIMIT_AS {args.mem_mb} MiB, timeout {args.timeout:g} s, seed {args.seed}; "
        f"failures: {failures}" + (f" (first {kept} saved in {out})" if kept else ""))
  return 1 if failures else 0


if __name__ == "__main__":
  sys.exit(main())
