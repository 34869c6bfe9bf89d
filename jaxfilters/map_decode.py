"""Strict, bounded reading of map files: the YAML text and the image (PNG, Netpbm, BMP).

`map_io.load_map` reads files through this module so that hostile or damaged
files fail loudly and cheaply instead of decoding into a plausible wrong map:

  - Only regular files are opened (a FIFO, a directory or a device raises
    `ValueError` at once instead of blocking or reading forever).
  - Sizes are checked before anything large is allocated: the YAML against
    `MAX_YAML_BYTES`, the image's declared width x height against a cell cap
    (`MAX_MAP_CELLS` unless the caller passes another) and against what the
    file can hold (a 92-byte PNG cannot hold 13000 x 13000 pixels).
  - The YAML is parsed with PyYAML's safe loader minus aliases (no
    billion-laughs documents), merge keys, duplicate keys and nesting deeper
    than `MAX_YAML_DEPTH` (`strict_yaml.parse_yaml`, which Nav2 params files
    go through too, with their own caps).
  - PNG: every chunk's CRC, the chunk order, and the zlib stream (complete,
    Adler-32 checked, decompressing to exactly the declared size) are verified
    before Pillow decodes it; palette indices must lie inside the palette.
  - Netpbm (P1-P6): the header and raster are parsed here with NumPy (Pillow
    clamps samples above maxval, ignores surplus samples and decodes maxval !=
    255 one sample at a time in Python); the raster must have exactly the
    declared size and no sample may exceed maxval. Samples are scaled as
    Pillow scales them, so results equal Pillow's on every valid file. (A
    plain-text P1-P3 file cut inside its last number cannot be told from a
    shorter number; binary files have no such gap.)
  - BMP: uncompressed (BI_RGB / BI_BITFIELDS) only; the pixel array must be
    present in full.
  - Other formats (JPEG, GIF, TIFF, ...) are refused: they are lossy or carry
    no integrity check, so damage could not be told from content.

Every error is a `ValueError` (or `FileNotFoundError` for a missing file) with
a short message; long values are cut with `validate.short_repr`.
"""

from __future__ import annotations

import io
import os
import re
import stat
import struct
import zlib
from typing import Any

import numpy as np
from PIL import Image

from jaxfilters.strict_yaml import parse_yaml
from jaxfilters.validate import short_repr

__all__ = ["MAX_IMAGE_HEADER_BYTES", "MAX_MAP_CELLS", "MAX_YAML_BYTES", "MAX_YAML_DEPTH",
           "parse_map_yaml",
           "read_image", "read_regular_file"]

# Cell cap: 2**26 = 67,108,864 cells, e.g. 8192 x 8192 (410 m square at 5 cm/cell). The
# largest real map shipped with Nav2 here is 1674 x 1006 = 1.7 M cells; large warehouse and
# campus SLAM maps at 5 cm reach 6000 x 3000 (18 M), beyond a 4096 x 4096 cap. A grid at the
# cap is 64 MiB as int8; loading one (measured) adds about 0.2 GiB of peak memory for an 8-bit
# gray PGM or PNG and 0.55 GiB for an RGBA PNG, which bounds what any map file can make
# load_map allocate.
MAX_MAP_CELLS = 1 << 26
# A Nav2 map YAML is ~200 bytes; 64 KiB leaves room for comments and bounds the parser.
MAX_YAML_BYTES = 64 * 1024
# Nesting depth allowed in a map YAML (it needs 2: the mapping and the origin list).
MAX_YAML_DEPTH = 16
# Netpbm headers (with comments) and BMP/PNG headers must fit in this many leading bytes.
MAX_IMAGE_HEADER_BYTES = 64 * 1024
# Ancillary PNG chunks (text, ICC profiles, ...) and bytes after a BMP's pixel array.
_MAX_EXTRA_BYTES = 16 * 1024 * 1024
# Deflate cannot compress better than 1032:1, so the compressed pixel data of a PNG is at
# least 1/1032 of its raw size.
_DEFLATE_MAX_RATIO = 1032
_ERROR_TEXT_LIMIT = 200


def _cut(text: str, limit: int = _ERROR_TEXT_LIMIT) -> str:
  text = " ".join(str(text).split())
  return text if len(text) <= limit else text[:limit - 3] + "..."


# --------------------------------------------------------------------------- files


def read_regular_file(path: str, what: str, *, max_bytes: int | None = None,
                      max_bytes_for: Any = None) -> bytes:
  """Reads a whole regular file, refusing anything else before reading a byte.

  Args:
    path: the file's path.
    what: what the file is ("map YAML file", "image file"), for messages.
    max_bytes: refuse a file larger than this many bytes (checked with fstat).
    max_bytes_for: optional callable(head: bytes, size: int) -> int | None that
      looks at the first `MAX_IMAGE_HEADER_BYTES` bytes and the file size and
      returns the largest size the file may have (or raises ValueError); the
      rest is read only if the file passes.

  Returns:
    The file's bytes.

  Raises:
    FileNotFoundError: the path does not exist (or is empty).
    ValueError: a FIFO, directory, device or socket; a file larger than
      allowed; a file that changes size while read; any other OS error
      (permission, loop of links, ...), with the OS reason.
  """
  if not path:
    raise FileNotFoundError(f"{what} name is empty")
  shown = path if len(path) <= 200 else path[:97] + "..." + path[-100:]
  try:
    # O_NONBLOCK: opening a FIFO with no writer returns at once instead of hanging.
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
  except FileNotFoundError:
    raise FileNotFoundError(f"{what} {shown} does not exist") from None
  except OSError as e:
    raise ValueError(f"cannot open {what} {shown}: {_cut(e.strerror or e)}") from None
  try:
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode):
      kind = ("a directory" if stat.S_ISDIR(st.st_mode) else "a FIFO" if stat.S_ISFIFO(st.st_mode)
              else "a device" if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode)
              else "a socket" if stat.S_ISSOCK(st.st_mode) else "not a regular file")
      raise ValueError(f"{what} {shown} is {kind}, not a regular file")
    size = st.st_size
    if max_bytes is not None and size > max_bytes:
      raise ValueError(f"{what} {shown} is {size} bytes; at most {max_bytes} are allowed")
    chunks, got = [], 0
    if max_bytes_for is not None:
      head = _read_exactly(fd, min(size, MAX_IMAGE_HEADER_BYTES))
      limit = max_bytes_for(head, size)
      if limit is not None and size > limit:
        raise ValueError(f"{what} {shown} is {size} bytes; its header allows at most {limit}")
      chunks, got = [head], len(head)
    while got < size:
      block = os.read(fd, min(size - got, 1 << 24))
      if not block:
        break
      chunks.append(block)
      got += len(block)
    if got != size or os.read(fd, 1):
      raise ValueError(f"{what} {shown} changed size while being read ({size} bytes at open)")
    return b"".join(chunks)
  except OSError as e:
    raise ValueError(f"cannot read {what} {shown}: {_cut(e.strerror or e)}") from None
  finally:
    os.close(fd)


def _read_exactly(fd: int, n: int) -> bytes:
  parts, got = [], 0
  while got < n:
    block = os.read(fd, n - got)
    if not block:
      break
    parts.append(block)
    got += len(block)
  return b"".join(parts)


# --------------------------------------------------------------------------- YAML


def parse_map_yaml(text: bytes, path: str) -> Any:
  """Parses map YAML bytes (UTF-8) with `parse_yaml` and the map's depth cap; returns the document.

  Raises:
    ValueError: as `parse_yaml`, naming `path`; a map YAML may nest at most
      `MAX_YAML_DEPTH` levels.
  """
  return parse_yaml(text, path, what="map YAML", max_depth=MAX_YAML_DEPTH)


# --------------------------------------------------------------------------- images


def _check_cells(width: int, height: int, max_cells: int, kind: str) -> None:
  if width < 1 or height < 1:
    raise ValueError(f"{kind} declares {width} x {height} pixels; both must be at least 1")
  if width * height > max_cells:
    raise ValueError(f"{kind} declares {width} x {height} = {width * height} cells; at most "
                     f"{max_cells} are allowed (the cell cap, MAX_MAP_CELLS by default)")


def _sniff(head: bytes) -> str:
  if head.startswith(b"\x89PNG\r\n\x1a\n"):
    return "png"
  if len(head) >= 2 and head[:1] == b"P" and head[1:2] in b"123456":
    return "netpbm"
  if head.startswith(b"BM"):
    return "bmp"
  if not head:
    raise ValueError("the file is empty")
  guess = ("JPEG" if head.startswith(b"\xff\xd8") else "GIF" if head.startswith(b"GIF8")
           else "TIFF" if head[:4] in (b"II*\x00", b"MM\x00*") else "PAM or PFM"
           if head[:2] in (b"P7", b"Pf", b"PF") else None)
  what = f"a {guess} file" if guess else f"not an image this loader knows (starts {head[:8]!r})"
  raise ValueError(f"{what}; map images must be PNG, PGM/PPM/PBM or uncompressed BMP")


def read_image(path: str, *, max_cells: int = MAX_MAP_CELLS
               ) -> tuple[np.ndarray, np.ndarray | None]:
  """Reads and strictly decodes a map image file.

  Args:
    path: the image file (PNG, Netpbm P1-P6, or uncompressed BMP).
    max_cells: largest width x height accepted (checked before decoding).

  Returns:
    (pixels, alpha): uint8 pixels in image order (row 0 = top), [H, W] gray
    (Netpbm colour: [H, W, 3] RGB), and a uint8 [H, W] alpha (255 = opaque) or
    None. 16-bit gray samples are scaled with round(v / 257); PNG and BMP
    colour is reduced with Pillow's ITU-R 601 luma (`convert("L")`).

  Raises:
    FileNotFoundError: the file does not exist.
    ValueError: not a regular file; an unsupported format; a declared size
      over `max_cells` or larger than the file can hold; a truncated, corrupt
      or over-long file; samples above maxval; palette indices outside the
      palette. The message says which.
  """
  state: dict[str, Any] = {}

  def limit(head: bytes, size: int) -> int:
    state["kind"] = kind = _sniff(head)
    if kind == "png":
      state["png"] = info = _png_header(head, max_cells)
      return info["raw_len"] + info["raw_len"] // 16 + 1024 + _MAX_EXTRA_BYTES
    if kind == "netpbm":
      state["pnm"] = info = _pnm_header(head, max_cells)
      if info["raster"] is not None:  # binary: the exact size is known before reading
        _pnm_check_size(info, size)
      return info["max_len"]
    state["bmp"] = info = _bmp_header(head, size, max_cells)
    return info["end"] + _MAX_EXTRA_BYTES

  data = read_regular_file(path, "image file", max_bytes_for=limit)
  kind = state["kind"]
  if kind == "netpbm":
    return _pnm_pixels(data, state["pnm"]), None
  if kind == "png":
    _png_verify(data, state["png"])
  else:
    _bmp_check_indices(data, state["bmp"])
  return _pillow_pixels(data, kind, state[kind])


# --------------------------------------------------------------------------- PNG

_PNG_DEPTHS = {0: (1, 2, 4, 8, 16), 2: (8, 16), 3: (1, 2, 4, 8), 4: (8, 16), 6: (8, 16)}
_PNG_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}
_ADAM7 = ((0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2),
          (0, 1, 1, 2))


def _png_raw_len(width: int, height: int, bits_per_pixel: int, interlaced: bool) -> int:
  """Bytes of filtered scanlines (one filter byte per row) zlib must produce."""
  def rows(w: int, h: int) -> int:
    return 0 if w == 0 or h == 0 else h * (1 + (w * bits_per_pixel + 7) // 8)
  if not interlaced:
    return rows(width, height)
  return sum(rows((width - x0 + dx - 1) // dx, (height - y0 + dy - 1) // dy)
             for x0, y0, dx, dy in _ADAM7)


def _png_header(head: bytes, max_cells: int) -> dict:
  if len(head) < 33:
    raise ValueError(f"PNG file truncated in its header ({len(head)} bytes)")
  length, ctype = struct.unpack(">I4s", head[8:16])
  if ctype != b"IHDR" or length != 13:
    raise ValueError(f"PNG must start with a 13-byte IHDR chunk; got {ctype!r} of {length} bytes")
  if zlib.crc32(head[12:29]) != struct.unpack(">I", head[29:33])[0]:
    raise ValueError("PNG IHDR chunk is corrupt (CRC mismatch)")
  width, height, depth, colour, compression, filt, interlace = struct.unpack(">IIBBBBB",
                                                                             head[16:29])
  if width > 2**31 - 1 or height > 2**31 - 1:
    raise ValueError(f"PNG declares {width} x {height} pixels; each must be < 2**31")
  if colour not in _PNG_DEPTHS or depth not in _PNG_DEPTHS[colour]:
    raise ValueError(f"PNG declares colour type {colour} with bit depth {depth}, which PNG "
                     f"does not allow")
  if compression != 0 or filt != 0 or interlace not in (0, 1):
    raise ValueError(f"PNG declares compression {compression}, filter {filt}, interlace "
                     f"{interlace}; PNG allows 0, 0 and 0/1")
  _check_cells(width, height, max_cells, "PNG")
  raw_len = _png_raw_len(width, height, depth * _PNG_CHANNELS[colour], interlace == 1)
  return dict(width=width, height=height, depth=depth, colour=colour, raw_len=raw_len)


def _png_verify(data: bytes, info: dict) -> None:
  """Walks every chunk (CRC, order) and checks the zlib stream is whole and exactly sized."""
  view = memoryview(data)
  pos, idat, idat_done, plte, trns = 8, [], False, None, None
  while True:
    if pos + 12 > len(data):
      raise ValueError(f"PNG file truncated: chunk header at byte {pos} runs past the end "
                       f"({len(data)} bytes; IEND missing)")
    length, ctype = struct.unpack(">I4s", data[pos:pos + 8])
    if length > 2**31 - 1 or not ctype.isalpha() or not ctype.isascii():
      raise ValueError(f"PNG file corrupt: bad chunk header at byte {pos} "
                       f"({short_repr(ctype)}, length {length})")
    end = pos + 12 + length
    if end > len(data):
      raise ValueError(f"PNG file truncated: chunk {ctype.decode()} at byte {pos} needs "
                       f"{length} bytes; the file ends {end - len(data)} bytes early")
    body = view[pos + 8:pos + 8 + length]
    if zlib.crc32(view[pos + 4:pos + 8 + length]) != struct.unpack(">I", data[end - 4:end])[0]:
      raise ValueError(f"PNG file corrupt: chunk {ctype.decode()} at byte {pos} fails its CRC")
    name = ctype.decode()
    if pos == 8 and name != "IHDR":
      raise ValueError("PNG must start with an IHDR chunk")
    if name == "IHDR" and pos != 8:
      raise ValueError("PNG has a second IHDR chunk")
    if name == "IDAT":
      if idat_done:
        raise ValueError("PNG IDAT chunks are not consecutive")
      idat.append(body)
    elif idat:
      idat_done = True
    if name == "PLTE":
      if plte is not None or idat or length % 3 or not 3 <= length <= 768:
        raise ValueError(f"PNG has a bad PLTE chunk ({length} bytes)")
      plte = length // 3
    elif name == "tRNS":
      trns = bytes(body)
    elif name == "IEND":
      if length:
        raise ValueError("PNG IEND chunk must be empty")
      if end != len(data):
        raise ValueError(f"PNG has {len(data) - end} bytes after its IEND chunk")
      break
    elif name[0].isupper() and name not in ("IHDR", "IDAT"):
      raise ValueError(f"PNG has an unknown critical chunk {name}")
    pos = end
  if not idat:
    raise ValueError("PNG has no IDAT (pixel data) chunk")
  if info["colour"] == 3 and plte is None:
    raise ValueError("palette PNG has no PLTE chunk")
  compressed = sum(len(b) for b in idat)
  need = info["raw_len"]
  if need > _DEFLATE_MAX_RATIO * compressed:
    raise ValueError(f"PNG declares {info['width']} x {info['height']} pixels ({need} bytes of "
                     f"scanlines) but holds only {compressed} compressed bytes, less than "
                     f"deflate's 1/{_DEFLATE_MAX_RATIO} minimum: truncated or corrupt")
  inflater, produced = zlib.decompressobj(), 0
  try:
    for block in idat:
      buf = block
      while buf:
        if inflater.eof:
          raise ValueError("PNG holds data after the end of its zlib stream")
        produced += len(inflater.decompress(buf, 1 << 20))
        if produced > need:
          raise ValueError(f"PNG pixel data decompresses to more than the {need} bytes "
                           f"{info['width']} x {info['height']} pixels need")
        buf = inflater.unconsumed_tail
    produced += len(inflater.flush())
  except zlib.error as e:
    raise ValueError(f"PNG pixel data is corrupt (zlib: {_cut(e)})") from None
  if not inflater.eof or inflater.unused_data:
    raise ValueError("PNG pixel data is truncated (the zlib stream does not end)"
                     if not inflater.eof else "PNG holds data after the end of its zlib stream")
  if produced != need:
    raise ValueError(f"PNG pixel data decompresses to {produced} bytes; {info['width']} x "
                     f"{info['height']} pixels need {need} (truncated or corrupt)")
  info["palette_size"], info["trns"] = plte, trns


# --------------------------------------------------------------------------- Netpbm

_WS = b" \t\n\r\v\f"


def _pnm_header(head: bytes, max_cells: int) -> dict:
  magic = head[1] - ord("0")  # 1..6 (sniffed)
  if len(head) > 2 and head[2] not in _WS and head[2:3] != b"#":
    raise ValueError(f"Netpbm magic P{magic} must be followed by whitespace")
  fields, pos = [], 2
  names = ("width", "height") + (() if magic in (1, 4) else ("maxval",))
  for name in names:
    while True:  # whitespace and comments (to the end of the line)
      while pos < len(head) and head[pos] in _WS:
        pos += 1
      if pos < len(head) and head[pos:pos + 1] == b"#":
        ends = [i for i in (head.find(b"\n", pos), head.find(b"\r", pos)) if i >= 0]
        if not ends:
          raise ValueError(f"Netpbm header comment runs past the first "
                           f"{MAX_IMAGE_HEADER_BYTES} bytes or the end of the file")
        pos = min(ends) + 1
        continue
      break
    start = pos
    while pos < len(head) and 48 <= head[pos] <= 57:
      pos += 1
    token = head[start:pos]
    # A comment may end any field but the last of a binary file, which one whitespace ends.
    ends = _WS if name == names[-1] and magic in (4, 5, 6) else _WS + b"#"
    if not token or len(token) > 10 or (pos < len(head) and head[pos] not in ends):
      bad = head[start:start + 12]
      raise ValueError(f"Netpbm header field {name} must be a decimal number of at most 10 "
                       f"digits; got {short_repr(bad) if bad else 'the end of the header'}")
    fields.append(int(token))
  if pos >= len(head) and magic in (4, 5, 6):
    raise ValueError(f"Netpbm header does not end within the file's first "
                     f"{MAX_IMAGE_HEADER_BYTES} bytes (or the file has no raster)")
  width, height = fields[0], fields[1]
  maxval = fields[2] if len(fields) == 3 else 1
  if not 1 <= maxval <= 65535:
    raise ValueError(f"Netpbm maxval must be 1..65535; got {maxval}")
  _check_cells(width, height, max_cells, f"Netpbm P{magic}")
  channels = 3 if magic in (3, 6) else 1
  samples = width * height * channels
  if magic in (4, 5, 6):
    offset = pos + 1  # exactly one whitespace character ends the header
    raster = height * ((width + 7) // 8) if magic == 4 else samples * (1 if maxval < 256 else 2)
    max_len = offset + raster
  else:
    offset, raster = pos, None
    # Plain rasters: 1..12 bytes per sample (digits, whitespace); comments get 64 KiB.
    max_len = offset + 12 * samples + MAX_IMAGE_HEADER_BYTES
  return dict(magic=magic, width=width, height=height, maxval=maxval, channels=channels,
              samples=samples, offset=offset, raster=raster, max_len=max_len)


def _pnm_check_size(info: dict, size: int) -> None:
  """A binary raster must fill the file exactly."""
  have, need = size - info["offset"], info["raster"]
  magic, width, height = info["magic"], info["width"], info["height"]
  if have < need:
    raise ValueError(f"Netpbm P{magic} raster truncated: {width} x {height} needs {need} "
                     f"bytes after the header; the file holds {max(have, 0)}")
  if have > need:
    raise ValueError(f"Netpbm P{magic} file has {have - need} bytes after its {width} x "
                     f"{height} raster (wrong header or several images)")


def _pnm_pixels(data: bytes, info: dict) -> np.ndarray:
  magic, width, height, maxval = info["magic"], info["width"], info["height"], info["maxval"]
  offset, samples = info["offset"], info["samples"]
  if magic in (4, 5, 6):
    _pnm_check_size(info, len(data))
    need = info["raster"]
    if magic == 4:
      rows = np.frombuffer(data, np.uint8, need, offset).reshape(height, -1)
      bits = np.unpackbits(rows, axis=1)[:, :width]
      return np.where(bits == 1, 0, 255).astype(np.uint8)  # PBM 1 = black
    values = np.frombuffer(data, np.uint8 if maxval < 256 else ">u2", samples, offset)
  else:
    values = _plain_samples(data[offset:], info)
  if values.size and int(values.max()) > maxval:
    first = int(np.argmax(values > maxval))
    raise ValueError(f"Netpbm P{magic} sample {first} is {int(values[first])}, above maxval "
                     f"{maxval}")
  shape = (height, width, 3) if info["channels"] == 3 else (height, width)
  values = values.reshape(shape)
  if magic == 1:
    return np.where(values == 1, 0, 255).astype(np.uint8)
  # Pillow's scaling, so results equal Image.open(...) on every valid file.
  if maxval == 255:
    return values.astype(np.uint8)
  if maxval < 256 or info["channels"] == 3:
    return np.rint(values.astype(np.float64) / maxval * 255.0).astype(np.uint8)
  wide = np.rint(values.astype(np.float64) / maxval * 65535.0).astype(np.int64)
  return ((wide + 128) // 257).astype(np.uint8)


_COMMENT = re.compile(rb"#[^\r\n]*")


def _plain_samples(text: bytes, info: dict) -> np.ndarray:
  magic, samples = info["magic"], info["samples"]
  body = _COMMENT.sub(b" ", text)
  if magic == 1:  # plain PBM digits need no separators
    digits = b"".join(body.split())
    if digits.strip(b"01"):
      bad = digits.lstrip(b"01")[:1]
      raise ValueError(f"Netpbm P1 raster holds {bad!r}; only 0 and 1 are allowed")
    tokens = np.frombuffer(digits, np.uint8) - ord("0")
  else:
    parts = body.split()
    for tok in parts:
      if not tok.isdigit() or len(tok) > 10:
        raise ValueError(f"Netpbm P{magic} raster holds {short_repr(tok[:12])}; samples must "
                         f"be decimal numbers")
    tokens = np.array([int(t) for t in parts], np.int64)
  if tokens.size != samples:
    raise ValueError(f"Netpbm P{magic} raster holds {tokens.size} samples; {info['width']} x "
                     f"{info['height']} needs {samples} "
                     f"({'truncated' if tokens.size < samples else 'surplus data'})")
  return tokens


# --------------------------------------------------------------------------- BMP

_BMP_DIB = (12, 40, 52, 56, 64, 108, 124)


def _bmp_header(head: bytes, size: int, max_cells: int) -> dict:
  if len(head) < 26:
    raise ValueError(f"BMP file truncated in its header ({len(head)} bytes)")
  offset, dib = struct.unpack("<I I", head[10:18])
  if dib not in _BMP_DIB:
    raise ValueError(f"BMP info header size {dib} is not one of {_BMP_DIB}")
  if len(head) < 14 + dib:
    raise ValueError("BMP file truncated in its info header")
  if dib == 12:
    width, height, planes, bpp = struct.unpack("<HHHH", head[18:26])
    compression, colours = 0, 0
  else:
    width, height, planes, bpp, compression = struct.unpack("<iiHHI", head[18:34])
    colours = struct.unpack("<I", head[46:50])[0] if dib >= 40 else 0
  if compression not in (0, 3):
    raise ValueError(f"BMP compression {compression} is not supported; map images must be "
                     f"uncompressed BMP (BI_RGB or BI_BITFIELDS)")
  if planes != 1 or bpp not in (1, 4, 8, 16, 24, 32):
    raise ValueError(f"BMP declares {planes} planes and {bpp} bits per pixel; need 1 plane "
                     f"and 1/4/8/16/24/32 bits")
  if width <= 0 or height == 0 or height == -2**31:
    raise ValueError(f"BMP declares {width} x {height} pixels")
  height = abs(height)
  _check_cells(width, height, max_cells, "BMP")
  if bpp <= 8:
    palette = colours or (1 << bpp)
    if palette > (1 << bpp):
      raise ValueError(f"BMP declares {palette} palette colours for {bpp}-bit pixels")
  else:
    palette = None
  stride = ((width * bpp + 31) // 32) * 4
  end = offset + stride * height
  if offset < 14 + dib or end > size:
    raise ValueError(f"BMP pixel array ({stride * height} bytes at byte {offset}) does not fit "
                     f"the {size}-byte file: truncated or corrupt")
  return dict(width=width, height=height, end=end, palette_size=palette, offset=offset,
              stride=stride, bpp=bpp)


def _bmp_check_indices(data: bytes, info: dict) -> None:
  """Palette indices must name palette entries (Pillow would read missing ones as black)."""
  bpp, palette, width = info["bpp"], info["palette_size"], info["width"]
  if palette is None or palette == 1 << bpp:
    return
  rows = np.frombuffer(data, np.uint8, info["stride"] * info["height"], info["offset"])
  rows = rows.reshape(info["height"], info["stride"])
  if bpp == 8:
    index = rows[:, :width]
  else:
    bits = np.unpackbits(rows, axis=1)[:, :width * bpp].reshape(info["height"], width, bpp)
    index = (bits * (1 << np.arange(bpp - 1, -1, -1, dtype=np.uint8))).sum(axis=2)
  if index.size and int(index.max()) >= palette:
    raise ValueError(f"BMP palette index {int(index.max())} is outside the {palette}-colour "
                     f"palette")


# --------------------------------------------------------------------------- Pillow


def _pillow_pixels(data: bytes, kind: str, info: dict) -> tuple[np.ndarray, np.ndarray | None]:
  """Decodes a verified PNG or BMP with Pillow; checks size and palette indices."""
  fmt = "PNG" if kind == "png" else "BMP"
  try:
    with Image.open(io.BytesIO(data), formats=[fmt]) as img:
      img.load()
      if img.size != (info["width"], info["height"]):
        raise ValueError(f"decoded {img.size[0]} x {img.size[1]} pixels; the header declares "
                         f"{info['width']} x {info['height']}")
      return _pixels_of(img, info)
  except (ValueError, MemoryError):
    raise
  except Exception as e:  # noqa: BLE001 - whatever Pillow's decoder raises on damaged data
    raise ValueError(f"{fmt} file corrupt: {type(e).__name__}: {_cut(e)}") from None


def _pixels_of(img: Image.Image, info: dict) -> tuple[np.ndarray, np.ndarray | None]:
  mode = img.mode
  if mode == "P" and info.get("colour") == 3:
    index = np.asarray(img)
    if index.size and int(index.max()) >= info["palette_size"]:
      raise ValueError(f"palette index {int(index.max())} is outside the "
                       f"{info['palette_size']}-colour palette")
  if mode in ("I;16", "I;16L", "I;16B", "I;16N", "I"):
    wide = np.asarray(img).astype(np.int64)
    if wide.size and (wide.min() < 0 or wide.max() > 65535):
      raise ValueError(f"{mode} pixels outside 0..65535 (min {wide.min()}, max {wide.max()})")
    alpha = None
    key = img.info.get("transparency")
    if isinstance(key, int):  # a 16-bit tRNS gray key is an alpha channel to GraphicsMagick
      alpha = np.where(wide == key, 0, 255).astype(np.uint8)
    return ((wide + 128) // 257).astype(np.uint8), alpha
  if info.get("depth") == 16 and info.get("colour") == 2 and info.get("trns") is not None:
    raise ValueError("16-bit RGB PNG with a tRNS colour key is not supported (Pillow reduces "
                     "the samples to 8 bits before the key can be matched); save it with an "
                     "alpha channel instead")
  if "transparency" in img.info and mode in ("1", "L", "P", "RGB"):
    img = img.convert("RGBA")  # a tRNS colour key is an alpha channel to GraphicsMagick
    mode = img.mode
  if mode == "F":
    raise ValueError("floating-point images (Pillow mode F) are not supported")
  # Colour is reduced here with Pillow's convert("L"), the luma load_map_image uses, so a
  # large colour map never holds more than one byte per cell and channel at a time.
  if mode in ("LA", "La", "RGBA", "RGBa", "PA"):
    if mode not in ("LA", "RGBA"):
      img = img.convert("LA" if mode == "La" else "RGBA")
    alpha = np.asarray(img.getchannel("A"))
    return np.asarray(img.convert("L")), alpha
  return np.asarray(img.convert("L")), None  # 1, L, RGB, RGBX, P, ...
