"""Property tests: mutated map files only ever raise ValueError / FileNotFoundError.

The mutators and seed maps are those of `tests/fuzz/fuzz_inputs.py` (the long
subprocess fuzzer); here hypothesis draws them in-process, a few hundred per
target, and adds oracles the fuzzer does not have:
  - a truncated binary image (PNG, PGM/PPM/PBM, BMP) never loads;
  - a single flipped bit anywhere in a PNG never loads (CRCs, zlib Adler-32);
  - a mutated PGM loads exactly when an independent plain-Python parser
    accepts it, and then to the same pixels;
  - a mutated 8-bit gray PNG that loads, and any valid one with random
    filter types, has the pixels a plain-Python unfilter of its zlib data gives;
  - valid maps written many ways (PNG bit depths, interlacing, IDAT splits,
    compression levels, Netpbm maxvals and comments, BMP, YAML styles) load to
    the grid the pixel conversion gives, and Netpbm decodes as Pillow does.
"""

from __future__ import annotations

import io
import random
import re
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings, strategies as st
from PIL import Image

from jaxfilters.map_io import load_map_image, load_map_with_metadata
from tests.fuzz import fuzz_inputs as fz

_HEALTH = [HealthCheck.too_slow, HealthCheck.function_scoped_fixture]


def fast(n: int):
  return settings(max_examples=n, deadline=None, suppress_health_check=_HEALTH)
KW = dict(mode="trinary", occupied_thresh=0.65, free_thresh=0.196)


def _expected(pixels, alpha=None) -> np.ndarray:
  return load_map_image(pixels, alpha, **KW)


def _load_image_bytes(data: bytes):
  """(outcome, grid or message) of loading `data` as the image of a fixed map YAML."""
  try:
    return "loaded", fz.run_image(data).data
  except FileNotFoundError as e:
    return "FileNotFoundError", str(e)
  except ValueError as e:
    return "ValueError", str(e)


# --------------------------------------------------------------------------- only two errors


@pytest.mark.parametrize("target", list(fz.TARGETS))
@fast(250)
@given(index=st.integers(0, 2**40))
def test_mutated_inputs_raise_only_value_or_file_errors(target, index):
  data, seed_k = fz.make_input(target, 1234, index)
  outcome, detail = fz.run_one(target, data, seed_k)
  assert outcome in fz.OK_OUTCOMES, f"{target} input {index}: {outcome}\n{detail}"


@pytest.mark.parametrize("target", list(fz.TARGETS))
def test_every_seed_loads_to_its_expected_grid(target):
  for k, seed in enumerate(fz.seeds_of(target)):
    grid = fz.TARGETS[target].run(seed.data)          # a valid seed never raises
    if seed.expected is not None:                     # the JAUS seeds check only that they decode
      np.testing.assert_array_equal(grid.data, seed.expected(), err_msg=f"{target} seed {k}")


# --------------------------------------------------------------------------- damage never loads


def _binary_seeds():
  pgm = [s for s in fz.pgm_seeds() if s[:2] in (b"P4", b"P5", b"P6")]
  return pgm + fz.png_seeds() + fz.bmp_seeds()


def test_every_truncation_of_a_binary_image_is_rejected():
  for k, data in enumerate(_binary_seeds()):
    for cut in range(len(data)):
      outcome, detail = _load_image_bytes(data[:cut])
      assert outcome == "ValueError", f"seed {k} cut to {cut} of {len(data)} bytes: {outcome}"


def test_every_bit_flip_of_a_png_is_rejected():
  data = fz.png_seeds()[0]  # 8-bit gray, one IDAT
  for bit in range(8 * len(data)):
    b = bytearray(data)
    b[bit // 8] ^= 1 << (bit % 8)
    outcome, _ = _load_image_bytes(bytes(b))
    assert outcome == "ValueError", f"bit {bit} flipped still loads"


@fast(200)
@given(seed=st.sampled_from(range(len(fz.png_seeds()))), data=st.data())
def test_random_bit_flips_of_any_png_are_rejected(seed, data):
  png = bytearray(fz.png_seeds()[seed])
  for bit in data.draw(st.lists(st.integers(0, 8 * len(png) - 1), min_size=1, max_size=4,
                                unique=True)):
    png[bit // 8] ^= 1 << (bit % 8)
  assert _load_image_bytes(bytes(png))[0] == "ValueError"


# --------------------------------------------------------------------------- PGM oracle

_PGM_WS = b" \t\n\r\v\f"


def ref_pgm(data: bytes) -> np.ndarray | None:
  """Plain-Python P2/P5 reader (Netpbm spec + Pillow's scaling); None if invalid."""
  m = re.match(rb"P([25])", data)
  if not m:
    return None
  pos, fields = 2, []
  if len(data) > 2 and data[2] not in _PGM_WS and data[2:3] != b"#":
    return None
  while len(fields) < 3:
    while pos < len(data) and (data[pos] in _PGM_WS or data[pos:pos + 1] == b"#"):
      if data[pos:pos + 1] == b"#":
        while pos < len(data) and data[pos] not in b"\r\n":
          pos += 1
        if pos >= len(data):
          return None
      pos += 1
    start = pos
    while pos < len(data) and 48 <= data[pos] <= 57:
      pos += 1
    token = data[start:pos]
    last_binary = len(fields) == 2 and m.group(1) == b"5"
    ends = _PGM_WS if last_binary else _PGM_WS + b"#"
    if not token or len(token) > 10 or (pos < len(data) and data[pos] not in ends):
      return None
    fields.append(int(token))
  width, height, maxval = fields
  if width < 1 or height < 1 or not 1 <= maxval <= 65535:
    return None
  n = width * height
  if m.group(1) == b"5":
    raster = data[pos + 1:]
    size = 1 if maxval < 256 else 2
    if pos >= len(data) or len(raster) != n * size:
      return None
    values = [raster[i] if size == 1 else raster[2 * i] * 256 + raster[2 * i + 1] for i in range(n)]
  else:
    text = re.sub(rb"#[^\r\n]*", b" ", data[pos:])
    tokens = text.split()
    if len(tokens) != n or not all(t.isdigit() and len(t) <= 10 for t in tokens):
      return None
    values = [int(t) for t in tokens]
  if any(v > maxval for v in values):
    return None
  if maxval == 255:
    gray = values
  elif maxval < 256:
    gray = [round(v / maxval * 255) for v in values]
  else:
    gray = [(round(v / maxval * 65535) + 128) // 257 for v in values]
  return np.array(gray, np.uint8).reshape(height, width)


@fast(400)
@given(index=st.integers(0, 2**40))
def test_mutated_pgm_loads_exactly_when_a_reference_parser_accepts_it(index):
  rng = random.Random(index)
  seeds = [s for s in fz.pgm_seeds() if s[:2] in (b"P2", b"P5")]
  data = fz.mutate(rng.choice(seeds), rng, fz.pgm_edit)
  want = ref_pgm(data)
  outcome, got = _load_image_bytes(data)
  if want is None:
    assert outcome == "ValueError", f"reference rejects {data[:40]!r}... but load_map {outcome}"
  else:
    assert outcome == "loaded", f"reference accepts {data[:40]!r}... but: {got}"
    np.testing.assert_array_equal(got, _expected(want))


# --------------------------------------------------------------------------- PNG oracle


def ref_png_gray8(data: bytes) -> tuple[int, int, np.ndarray] | None:
  """IHDR and plain-Python unfiltered pixels of an 8-bit gray non-interlaced PNG, else None."""
  chunks = fz.png_chunks(data)
  if not chunks or chunks[0][0] != b"IHDR" or len(chunks[0][1]) != 13:
    return None
  w, h, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", chunks[0][1])
  if (depth, colour, interlace) != (8, 0, 0) or any(c[0] == b"tRNS" for c in chunks):
    return None
  raw = zlib.decompressobj().decompress(b"".join(c[1] for c in chunks if c[0] == b"IDAT"))
  prev, rows = [0] * w, []
  for y in range(h):
    f, line = raw[y * (w + 1)], list(raw[y * (w + 1) + 1:(y + 1) * (w + 1)])
    for x in range(w):
      a, b, c = (line[x - 1] if x else 0), prev[x], (prev[x - 1] if x else 0)
      if f == 1:
        line[x] = (line[x] + a) & 255
      elif f == 2:
        line[x] = (line[x] + b) & 255
      elif f == 3:
        line[x] = (line[x] + (a + b) // 2) & 255
      elif f == 4:
        p = a + b - c
        pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
        line[x] = (line[x] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
    rows.append(line)
    prev = line
  return w, h, np.array(rows, np.uint8)


@fast(300)
@given(index=st.integers(0, 2**40))
def test_mutated_gray_png_that_loads_has_the_reference_pixels(index):
  rng = random.Random(index)
  seed = fz.png_seeds()[rng.choice((0, 2, 12))]  # 8-bit gray seeds
  data = fz.mutate(seed, rng, fz.png_edit)
  outcome, got = _load_image_bytes(data)
  if outcome == "loaded":
    ref = ref_png_gray8(data)
    if ref is not None:
      np.testing.assert_array_equal(got, _expected(ref[2]))


@fast(60)
@given(h=st.integers(1, 8), w=st.integers(1, 8), data=st.data())
def test_any_filtered_scanlines_decode_as_the_reference_unfilters_them(h, w, data):
  # Every byte string with filter types 0..4 is valid PNG data: sub, up, average and Paeth
  # rows must come out as the plain-Python unfilter says.
  rows = [bytes([data.draw(st.integers(0, 4))]) + data.draw(st.binary(min_size=w, max_size=w))
          for _ in range(h)]
  png = (fz.PNG_SIG + fz.png_chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
         + fz.png_chunk(b"IDAT", zlib.compress(b"".join(rows))) + fz.png_chunk(b"IEND", b""))
  outcome, got = _load_image_bytes(png)
  assert outcome == "loaded", got
  np.testing.assert_array_equal(got, _expected(ref_png_gray8(png)[2]))


# --------------------------------------------------------------------------- valid maps load

images = st.integers(1, 9).flatmap(lambda h: st.integers(1, 9).flatmap(
    lambda w: st.lists(st.integers(0, 255), min_size=h * w, max_size=h * w).map(
        lambda v: np.array(v, np.uint8).reshape(h, w))))


@fast(120)
@given(img=images, interlace=st.integers(0, 1), parts=st.integers(1, 4), level=st.integers(0, 9),
       depth=st.sampled_from([1, 2, 4, 8, 16]), alpha=st.booleans(), data=st.data())
def test_valid_pngs_load_identically(img, interlace, parts, level, depth, alpha, data):
  if depth < 8:
    img = img >> (8 - depth)
    pixels = (img.astype(int) * 255 // ((1 << depth) - 1)).astype(np.uint8)
    png = fz.encode_png(img, depth=depth, interlace=interlace, idat_parts=parts, level=level)
    a = None
  elif alpha:
    a = data.draw(st.sampled_from([0, 128, 255])) * np.ones_like(img)
    a[0, 0] = 255
    png = fz.encode_png(np.dstack([img, a]), colour=4, depth=8, interlace=interlace,
                        idat_parts=parts, level=level)
    pixels = img
  else:
    samples = img.astype(np.uint32) * (257 if depth == 16 else 1)
    png = fz.encode_png(samples, depth=depth, interlace=interlace, idat_parts=parts, level=level)
    pixels, a = img, None
  outcome, got = _load_image_bytes(png)
  assert outcome == "loaded", got
  np.testing.assert_array_equal(got, _expected(pixels, a))
  np.testing.assert_array_equal(got, _expected(*fz.pillow_reference(png)))


@fast(120)
@given(img=images, magic=st.sampled_from([b"P2", b"P3", b"P5", b"P6"]),
       maxval=st.integers(1, 65535),
       comment=st.booleans(), sep=st.sampled_from([b" ", b"\n", b"\t", b"\r\n", b"  \n"]))
def test_netpbm_decodes_as_pillow_does(img, magic, maxval, comment, sep):
  channels = 3 if magic in (b"P3", b"P6") else 1
  samples = np.rint(np.repeat(img[..., None], channels, 2).astype(float) / 255 * maxval)
  samples = samples.astype(np.int64).reshape(img.shape[0], -1)
  h, w = img.shape
  head = magic + sep + (b"# a comment\n" if comment else b"") + b"%d%s%d%s%d" % (
      w, sep, h, sep, maxval)
  if magic in (b"P5", b"P6"):
    body = samples.astype(np.uint8 if maxval < 256 else ">u2").tobytes()
    pnm = head + b"\n" + body
  else:
    pnm = head + sep + b"\n".join(b" ".join(b"%d" % v for v in row) for row in samples) + b"\n"
  outcome, got = _load_image_bytes(pnm)
  assert outcome == "loaded", got
  np.testing.assert_array_equal(got, _expected(*fz.pillow_reference(pnm)))


@fast(60)
@given(img=images, mode=st.sampled_from(["L", "RGB", "P", "1", "RGBA"]))
def test_valid_bmps_load_identically(img, mode):
  pil = Image.fromarray(img)
  if mode == "RGB":
    pil = Image.fromarray(np.dstack([img, img[::-1], 255 - img]))
  elif mode == "RGBA":
    pil = Image.fromarray(np.dstack([img, img, img, np.full_like(img, 255)]), "RGBA")
  elif mode != "L":
    pil = pil.convert(mode)
  buf = io.BytesIO()
  pil.save(buf, "BMP")
  outcome, got = _load_image_bytes(buf.getvalue())
  assert outcome == "loaded", got
  np.testing.assert_array_equal(got, _expected(*fz.pillow_reference(buf.getvalue())))


@fast(60)
@given(order=st.permutations(["image", "resolution", "origin", "negate", "occupied_thresh",
                              "free_thresh", "mode"]),
       quote=st.sets(st.sampled_from(["resolution", "free_thresh", "occupied_thresh"])),
       flow=st.booleans(), comments=st.booleans(),
       mode=st.sampled_from(["trinary", "Scale", "RAW"]),
       negate=st.sampled_from(["0", "1", "true", "false", "'1'"]))
def test_yaml_written_any_way_loads_identically(tmp_path_factory, order, quote, flow, comments,
                                                mode, negate):
  d = tmp_path_factory.mktemp("y")
  (d / "m.pgm").write_bytes(fz.pgm_seeds()[0])
  values = dict(image="m.pgm", resolution="0.05", origin="[-1.5, 2.25, 0.5]", negate=negate,
                occupied_thresh="0.65", free_thresh="0.196", mode=mode)
  for k in quote:
    values[k] = f"'{values[k]}'"
  items = [(k, values[k]) for k in order]
  if flow:
    text = "{" + ", ".join(f"{k}: {v}" for k, v in items) + "}\n"
  else:
    text = "".join((f"# {k}\n" if comments else "") + f"{k}: {v}\n" for k, v in items)
  (d / "m.yaml").write_text(text)
  grid, meta = load_map_with_metadata(d / "m.yaml")
  want_negate = yaml.safe_load(negate.strip("'")) not in (0, False)
  np.testing.assert_array_equal(grid.data, load_map_image(fz.BASE, mode=mode, occupied_thresh=0.65,
                                                          free_thresh=0.196, negate=want_negate))
  assert (grid.resolution, grid.origin) == (0.05, (-1.5, 2.25, 0.5))
  assert (meta.mode, meta.negate, meta.image) == (mode.lower(), want_negate, "m.pgm")


def test_fuzz_cli_runs_and_counts(tmp_path):
  """The subprocess fuzzer end to end: a short run, its table, and a bad argument."""
  import subprocess
  import sys
  root = Path(__file__).resolve().parents[2]
  run = subprocess.run([sys.executable, "-m", "tests.fuzz.fuzz_inputs", "--count", "60", "--workers",
                        "1", "--targets", "yaml,png", "--out", str(tmp_path / "f")], cwd=root,
                       capture_output=True, text=True, timeout=120)
  assert run.returncode == 0, run.stdout + run.stderr
  lines = run.stdout.splitlines()
  assert lines[0].split()[:2] == ["target", "inputs"]
  assert [ln.split()[:2] for ln in lines[1:3]] == [["yaml", "30"], ["png", "30"]]
  assert "60 inputs in" in lines[3] and "failures: 0" in lines[3]
  bad = subprocess.run([sys.executable, "-m", "tests.fuzz.fuzz_inputs", "--targets", "yaml,gif"],
                       cwd=root, capture_output=True, text=True, timeout=60)
  assert bad.returncode == 2 and "unknown gif" in bad.stderr
