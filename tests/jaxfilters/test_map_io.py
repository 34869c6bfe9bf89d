"""Tests for jaxfilters.map_io against docs/nav2_semantics.md §10 (Nav2 map_server / map_saver)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import given, settings, strategies as st
from PIL import Image

from jaxfilters.grid import OccupancyGrid
from jaxfilters.validate import F32_TINY
from jaxfilters.map_io import MAP_MODES, load_map, load_map_image, save_map

MAPS = Path(__file__).resolve().parents[2].parent / "shared" / "maps" / "nav2"


def _maps_dir() -> Path:
  if not MAPS.is_dir():
    pytest.skip(f"real Nav2 maps not found at {MAPS} (they live in ../shared/maps/nav2 next to "
                f"the repo; a fresh clone does not have them)")
  return MAPS


# --------------------------------------------------------------------------- reference


def _ref_pixel(g: int, mode: str, occupied: float, free: float, negate: bool,
               alpha: int = 255) -> int:
  """One pixel, written out scalar by scalar from docs/nav2_semantics.md §10.2."""
  if mode == "raw":
    v = g - 256 if g >= 128 else g
    return -1 if v < 0 or v > 100 else v
  f32 = np.float32
  n = f32(g) / f32(255.0)
  occ = n if negate else f32(1.0) - n
  if mode == "trinary":
    cell = -1
  else:
    x = float(((occ - f32(free)) / f32(occupied - free)) * f32(100.0))
    cell = int(math.copysign(math.floor(abs(x) + 0.5), x))
  if occ >= f32(occupied):
    cell = 100
  if occ <= f32(free):
    cell = 0
  if alpha < 255:
    cell = -1
  return cell


G_ALL = np.arange(256, dtype=np.uint8)[None, :]  # one image row holding every gray value


def _row(mode, occupied, free, negate=False, alpha=None):
  return load_map_image(G_ALL, alpha, mode=mode, occupied_thresh=occupied, free_thresh=free,
                        negate=negate)[0].tolist()


# --------------------------------------------------------------------------- pixel rules

TABLE_G = [0, 89, 90, 127, 128, 191, 200, 205, 206, 253, 254, 255]
# docs/nav2_semantics.md §10.2 worked table, one column each: (mode, occupied, free) -> values for TABLE_G.
TABLE = {
    ("trinary", 0.65, 0.196): [100, 100, -1, -1, -1, -1, -1, -1, 0, 0, 0, 0],
    ("trinary", 0.65, 0.25): [100, 100, -1, -1, -1, -1, 0, 0, 0, 0, 0, 0],
    ("scale", 0.65, 0.196): [100, 100, 99, 67, 67, 12, 4, 0, 0, 0, 0, 0],
    ("scale", 0.99, 0.01): [100, 65, 65, 50, 50, 25, 21, 19, 19, 0, 0, 0],
    ("scale", 1.0, 0.0): [100, 65, 65, 50, 50, 25, 22, 20, 19, 1, 0, 0],
    ("raw", 0.65, 0.196): [0, 89, 90, -1, -1, -1, -1, -1, -1, -1, -1, -1],
}


@pytest.mark.parametrize("column", list(TABLE), ids=lambda c: f"{c[0]}-{c[1]}-{c[2]}")
def test_worked_table(column):
  mode, occupied, free = column
  img = np.array([TABLE_G], np.uint8)
  got = load_map_image(img, mode=mode, occupied_thresh=occupied, free_thresh=free, negate=0)
  assert got.dtype == np.int8 and got.shape == (1, len(TABLE_G))
  assert got[0].tolist() == TABLE[column]


@settings(max_examples=60, deadline=None)
@given(mode=st.sampled_from(MAP_MODES), negate=st.booleans(),
       free=st.one_of(st.just(0.0), st.floats(F32_TINY, 0.999)), span=st.floats(1e-3, 1.0))
def test_matches_scalar_reference_for_every_gray(mode, negate, free, span):
  occupied = min(1.0, free + span)
  got = _row(mode, occupied, free, negate)
  assert got == [_ref_pixel(g, mode, occupied, free, negate) for g in range(256)]


def test_trinary_default_boundaries():
  row = _row("trinary", 0.65, 0.196)
  assert row[89] == 100 and row[90] == -1
  assert row[205] == -1 and row[206] == 0
  assert row == [100 if g <= 89 else 0 if g >= 206 else -1 for g in range(256)]


def test_trinary_default_boundaries_negated():
  for negate in (1, True, 7, -1):
    row = _row("trinary", 0.65, 0.196, negate)
    assert row == [0 if g <= 49 else 100 if g >= 166 else -1 for g in range(256)]


def test_scale_205_is_free_with_defaults():
  row = _row("scale", 0.65, 0.196)
  assert row[205] == 0 and row[89] == 100 and row[206] == 0


def test_scale_negated_mirrors():
  plain, negated = _row("scale", 0.65, 0.196), _row("scale", 0.65, 0.196, True)
  # 1 - g/255 and (255 - g)/255 round alike in float32 for these thresholds except at ties.
  assert negated[0] == 0 and negated[255] == 100
  assert sum(a != b for a, b in zip(plain, negated[::-1])) <= 2


def test_free_applied_last_wins():
  # free < occupied in float64, equal in float32: a pixel on the threshold is free.
  occ32 = np.float32(1.0) - np.float32(100) / np.float32(255.0)
  free = float(occ32)
  occupied = free + 1e-12
  assert np.float32(occupied) == np.float32(free)
  for mode in ("trinary", "scale"):
    got = load_map_image(np.array([[100]], np.uint8), mode=mode, occupied_thresh=occupied,
                         free_thresh=free)
    assert got[0, 0] == 0


def test_raw_wraps_bytes():
  row = _row("raw", 0.65, 0.196)
  assert row[:101] == list(range(101))
  assert row[101:] == [-1] * 155  # 101..127 too big, 128..255 wrap negative
  assert _row("raw", 0.65, 0.196, negate=True) == row  # negate is ignored in raw


@pytest.mark.parametrize("mode", MAP_MODES)
def test_alpha(mode):
  gray = np.array([[0, 0, 0, 254, 254, 254]], np.uint8)
  alpha = np.array([[255, 254, 0, 255, 128, 0]], np.uint8)
  got = load_map_image(gray, alpha, mode=mode, occupied_thresh=0.65, free_thresh=0.196)[0].tolist()
  if mode == "raw":
    assert got == [0, 0, 0, -1, -1, -1]  # alpha ignored; 254 is -1 by value
  else:
    assert got == [100, -1, -1, 0, -1, -1]
  rgba = np.dstack([gray, gray, gray, alpha])
  assert load_map_image(rgba, mode=mode, occupied_thresh=0.65, free_thresh=0.196)[0].tolist() == got


def test_raw_alpha_ignored_on_valid_values():
  gray = np.array([[7, 50, 100]], np.uint8)
  got = load_map_image(gray, np.zeros_like(gray), mode="raw", occupied_thresh=0.65,
                       free_thresh=0.196)
  assert got.tolist() == [[7, 50, 100]]


def test_rows_are_flipped():
  img = np.array([[0, 255], [255, 255], [255, 0]], np.uint8)  # top row first
  got = load_map_image(img, mode="trinary", occupied_thresh=0.65, free_thresh=0.196)
  assert got.tolist() == [[0, 100], [0, 0], [100, 0]]


def test_rgb_uses_pillow_luma():
  rng = np.random.default_rng(0)
  rgb = rng.integers(0, 256, (16, 16, 3), dtype=np.uint8)
  luma = np.asarray(Image.fromarray(rgb).convert("L"))
  kw = dict(mode="raw", occupied_thresh=0.65, free_thresh=0.196)
  np.testing.assert_array_equal(load_map_image(rgb, **kw), load_map_image(luma, **kw))
  gray3 = np.repeat(G_ALL[..., None], 3, axis=2)  # R = G = B is exact
  assert load_map_image(gray3, **kw)[0].tolist() == _row("raw", 0.65, 0.196)


@pytest.mark.parametrize("kwargs, match", [
    (dict(image=np.zeros((2, 2), np.float32)), "integers 0..255"),
    (dict(image=np.full((2, 2), 256, np.int32)), "0..255"),
    (dict(image=np.zeros((2, 2, 5), np.uint8)), r"\[H, W\]"),
    (dict(image=np.zeros((0, 3), np.uint8)), "non-empty"),
    (dict(image=np.zeros((2, 2), np.uint8), alpha=np.zeros((3, 2), np.uint8)), "alpha"),
    (dict(image=np.zeros((2, 2, 4), np.uint8), alpha=np.zeros((2, 2), np.uint8)), "alpha"),
    (dict(image=np.zeros((2, 2), np.uint8), mode="bogus"), "mode"),
    (dict(image=np.zeros((2, 2), np.uint8), free_thresh=-0.1), "free_thresh"),
    (dict(image=np.zeros((2, 2), np.uint8), occupied_thresh=1.5), "occupied_thresh"),
    (dict(image=np.zeros((2, 2), np.uint8), free_thresh=0.7), "free_thresh must be < occupied"),
    (dict(image=np.zeros((2, 2), np.uint8), occupied_thresh=float("nan")), "occupied_thresh"),
    (dict(image=np.zeros((2, 2), np.uint8), negate="yes"), "negate"),
])
def test_load_map_image_rejects(kwargs, match):
  args = dict(mode="trinary", occupied_thresh=0.65, free_thresh=0.196) | kwargs
  image = args.pop("image")
  with pytest.raises(ValueError, match=match):
    load_map_image(image, **args)


def test_mode_is_case_insensitive():
  kw = dict(occupied_thresh=0.65, free_thresh=0.196)
  np.testing.assert_array_equal(load_map_image(G_ALL, mode="SCALE", **kw),
                                load_map_image(G_ALL, mode="scale", **kw))


# --------------------------------------------------------------------------- real maps

TESTMAP = np.array([
    [0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
    [100, 100, 100, 100, 0, 0, 100, 100, 100, 0],
    [100, 100, 100, 100, 0, 0, 100, 100, 100, 0],
    [100, 0, 0, 0, 0, 0, 0, 0, 0, 0],
    [100, 0, 0, 0, 0, 0, 0, 0, 0, 0],
    [100, 0, 0, 0, 0, 0, 100, 100, 0, 0],
    [100, 0, 0, 0, 0, 0, 100, 100, 0, 0],
    [100, 0, 0, 0, 0, 0, 100, 100, 0, 0],
    [100, 0, 0, 0, 0, 0, 100, 100, 0, 0],
    [100, 0, 0, 0, 0, 0, 0, 0, 0, 0],
], np.int8)


def _write_yaml(path: Path, **fields) -> Path:
  path.write_text(yaml.safe_dump(fields, default_flow_style=None))
  return path


def test_testmap_png():
  grid = load_map(_maps_dir() / "testmap.yaml")
  assert isinstance(grid, OccupancyGrid)
  assert grid.data.dtype == np.int8 and grid.data.shape == (10, 10)
  assert grid.data[9].tolist() == [100] + [0] * 9
  assert grid.data[0].tolist() == [0] * 10
  np.testing.assert_array_equal(grid.data, TESTMAP)
  assert grid.resolution == pytest.approx(0.1)
  assert grid.origin == (2.0, 3.0, 1.0)
  assert grid.frame_id == "map"


@pytest.mark.parametrize("fmt", ["pgm", "bmp"])
def test_testmap_pgm_and_bmp_give_same_grid(tmp_path, fmt):
  maps = _maps_dir()
  if fmt == "pgm":
    image = str(maps / "testmap.pgm")  # absolute path: used as is
  else:
    Image.open(maps / "testmap.png").save(tmp_path / "testmap.bmp")
    image = "testmap.bmp"  # relative to the YAML's folder
  y = _write_yaml(tmp_path / "t.yaml", image=image, resolution=0.1, origin=[2.0, 3.0, 1.0],
                  occupied_thresh=0.65, free_thresh=0.196, negate=0, mode="trinary")
  grid = load_map(y)
  np.testing.assert_array_equal(grid.data, TESTMAP)
  assert grid.origin == (2.0, 3.0, 1.0)


REAL_MAPS = {
    "warehouse": ((1674, 1006), 0.03, (-15.1, -25.0, 0.0)),
    "warehouse_keepout": ((1674, 1006), 0.03, (-15.1, -25.0, 0.0)),
    "warehouse_speed": ((1674, 1006), 0.03, (-15.1, -25.0, 0.0)),
    "keepout_mask": ((384, 384), 0.05, (-10.0, -10.0, 0.0)),
    "speed_mask": ((384, 384), 0.05, (-10.0, -10.0, 0.0)),
    "tb3_sandbox": ((384, 384), 0.05, (-10.0, -10.0, 0.0)),
    "testmap": ((10, 10), 0.1, (2.0, 3.0, 1.0)),
}


@pytest.mark.parametrize("name", list(REAL_MAPS))
def test_real_map_loads(name):
  shape, resolution, origin = REAL_MAPS[name]
  grid = load_map(_maps_dir() / f"{name}.yaml")
  assert grid.data.shape == shape and grid.data.dtype == np.int8
  assert grid.resolution == pytest.approx(resolution)
  assert grid.origin == pytest.approx(origin)
  assert grid.data.min() >= -1 and grid.data.max() <= 100
  OccupancyGrid.create(grid.data, grid.resolution, grid.origin)  # passes the grid's own checks


def test_every_yaml_in_maps_dir_is_covered():
  maps = _maps_dir()
  names = {p.stem for p in maps.glob("*.yaml")} - {"nav2_params"}
  assert names == set(REAL_MAPS)


def test_warehouse_speed_mask_values():
  grid = load_map(_maps_dir() / "warehouse_speed.yaml")  # scale, occupied 1.0 / free 0.0
  values, counts = np.unique(grid.data, return_counts=True)
  # gray 255/254 -> 0 (no limit), 204/205 -> 20 (80 % speed), 0 -> 100.
  assert values.tolist() == [0, 20, 100]
  assert counts[1] > 0.05 * grid.data.size  # the slow-down zones are a real area


def test_trinary_masks_are_trinary():
  maps = _maps_dir()
  for name in ("warehouse_keepout", "keepout_mask", "tb3_sandbox"):
    assert set(np.unique(load_map(maps / f"{name}.yaml").data).tolist()) <= {-1, 0, 100}
  speed = load_map(maps / "speed_mask.yaml").data  # system-test mask: scale 0.99 / 0.01
  assert set(np.unique(speed).tolist()) == {0, 19, 50}


# --------------------------------------------------------------------------- image formats


def _load_png(tmp_path: Path, img: Image.Image, mode="trinary", name="m.png") -> np.ndarray:
  img.save(tmp_path / name)
  y = _write_yaml(tmp_path / "m.yaml", image=name, resolution=0.05, origin=[0, 0, 0],
                  occupied_thresh=0.65, free_thresh=0.196, negate=0, mode=mode)
  return load_map(y).data


@pytest.mark.parametrize("mode", MAP_MODES)
def test_rgba_and_la_png_alpha(tmp_path, mode):
  gray = np.array([[0, 0, 254, 254, 50]], np.uint8)
  alpha = np.array([[255, 0, 255, 200, 255]], np.uint8)
  expected = load_map_image(gray, alpha, mode=mode, occupied_thresh=0.65, free_thresh=0.196)
  rgba = Image.fromarray(np.dstack([gray, gray, gray, alpha]), "RGBA")
  np.testing.assert_array_equal(_load_png(tmp_path, rgba, mode), expected)
  la = Image.fromarray(np.dstack([gray, alpha]), "LA")
  np.testing.assert_array_equal(_load_png(tmp_path, la, mode), expected)


def test_palette_png_with_transparency(tmp_path):
  img = Image.fromarray(np.array([[0, 1, 2]], np.uint8), "P")
  img.putpalette([0, 0, 0, 254, 254, 254, 254, 254, 254] + [0] * 759)
  img.info["transparency"] = 2
  img.save(tmp_path / "p.png", transparency=2)
  got = _load_png(tmp_path, Image.open(tmp_path / "p.png"), name="p2.png")
  assert got.tolist() == [[100, 0, -1]]


def test_sixteen_bit_pgm_is_scaled(tmp_path):
  vals = np.array([[0, 89 * 257, 206 * 257, 65535]], ">u2")
  (tmp_path / "w.pgm").write_bytes(b"P5\n4 1\n65535\n" + vals.tobytes())
  y = _write_yaml(tmp_path / "w.yaml", image="w.pgm", resolution=0.05, origin=[0, 0, 0],
                  occupied_thresh=0.65, free_thresh=0.196, negate=0)
  assert load_map(y).data.tolist() == [[100, 100, 0, 0]]
  y = _write_yaml(tmp_path / "w.yaml", image="w.pgm", resolution=0.05, origin=[0, 0, 0],
                  occupied_thresh=0.65, free_thresh=0.196, negate=0, mode="raw")
  assert load_map(y).data.tolist() == [[0, 89, -1, -1]]


# --------------------------------------------------------------------------- YAML parsing


def _good_fields(**over):
  fields = dict(image="m.pgm", resolution=0.05, origin=[1.0, 2.0, 0.5], negate=0,
                occupied_thresh=0.65, free_thresh=0.196)
  fields.update(over)
  return {k: v for k, v in fields.items() if v is not _DROP}


_DROP = object()


@pytest.fixture
def mapdir(tmp_path):
  Image.fromarray(np.array([[0, 128, 254]], np.uint8)).save(tmp_path / "m.pgm")
  return tmp_path


def _load_fields(mapdir: Path, **over) -> OccupancyGrid:
  return load_map(_write_yaml(mapdir / "m.yaml", **_good_fields(**over)))


@pytest.mark.parametrize("mode, expected", [
    (_DROP, [-1]), ("trinary", [-1]), ("Trinary", [-1]), ("SCALE", [67]), ("Raw", [-1])])
def test_mode_key(mapdir, mode, expected):
  grid = _load_fields(mapdir, mode=mode)
  assert grid.data[0, 1:2].tolist() == expected
  assert grid.data[0, 0] == (0 if mode in ("Raw",) else 100)


@pytest.mark.parametrize("negate, flipped", [
    (0, False), (1, True), (2, True), (-1, True), (True, True), (False, False),
    ("1", True), ("0", False), ("yes", True), ("off", False)])
def test_negate_key(mapdir, negate, flipped):
  grid = _load_fields(mapdir, negate=negate)
  assert grid.data[0].tolist() == ([0, -1, 100] if flipped else [100, -1, 0])


def test_numbers_as_yaml_cpp_reads_them(mapdir):
  (mapdir / "m.yaml").write_text(  # PyYAML reads 5e-2 as a string; yaml-cpp as a double
      "image: m.pgm\nresolution: 5e-2\norigin: [-1, '2.5', 0]\nnegate: false\n"
      "occupied_thresh: 1\nfree_thresh: 0\n")
  grid = load_map(mapdir / "m.yaml")
  assert grid.resolution == 0.05 and grid.origin == (-1.0, 2.5, 0.0)


def test_home_expansion(mapdir, monkeypatch):
  _write_yaml(mapdir / "m.yaml", **_good_fields())
  monkeypatch.setenv("HOME", str(mapdir))
  assert load_map("~/m.yaml").data.shape == (1, 3)


def test_image_relative_to_yaml_dir(mapdir, monkeypatch, tmp_path_factory):
  _write_yaml(mapdir / "m.yaml", **_good_fields())
  monkeypatch.chdir(tmp_path_factory.mktemp("elsewhere"))
  assert load_map(mapdir / "m.yaml").data.shape == (1, 3)


# --------------------------------------------------------------------------- bad input


def test_missing_yaml(tmp_path):
  missing = tmp_path / "nope.yaml"
  with pytest.raises(FileNotFoundError, match=re.escape(str(missing))):
    load_map(missing)
  with pytest.raises(FileNotFoundError, match="empty"):
    load_map("")


def test_missing_image(mapdir):
  y = _write_yaml(mapdir / "m.yaml", **_good_fields(image="gone.pgm"))
  with pytest.raises(FileNotFoundError, match=r"gone\.pgm.*'image'") as e:
    load_map(y)
  assert str(y) in str(e.value)


@pytest.mark.parametrize("text, match", [
    ("image: [unclosed\n", "invalid map YAML"),
    ("- just\n- a list\n", "mapping"),
    ("", "mapping"),
])
def test_invalid_yaml(mapdir, text, match):
  (mapdir / "m.yaml").write_text(text)
  with pytest.raises(ValueError, match=match) as e:
    load_map(mapdir / "m.yaml")
  assert str(mapdir / "m.yaml") in str(e.value)


@pytest.mark.parametrize("key", ["image", "resolution", "origin", "free_thresh", "occupied_thresh",
                                 "negate"])
def test_missing_key(mapdir, key):
  with pytest.raises(ValueError, match=f"missing required key '{key}'") as e:
    _load_fields(mapdir, **{key: _DROP})
  assert str(mapdir / "m.yaml") in str(e.value)


@pytest.mark.parametrize("over, key", [
    (dict(image=""), "image"),
    (dict(image=None), "image"),
    (dict(image=12), "image"),
    (dict(origin=[1.0, 2.0]), "origin"),
    (dict(origin=[1.0, 2.0, 0.0, 0.0]), "origin"),
    (dict(origin=1.0), "origin"),
    (dict(origin=[1.0, "x", 0.0]), "origin"),
    (dict(origin=[1.0, float("nan"), 0.0]), "origin"),
    (dict(mode="ternary"), "mode"),
    (dict(mode=None), "mode"),
    (dict(negate=1.5), "negate"),
    (dict(negate="maybe"), "negate"),
    (dict(resolution="fine"), "resolution"),
    (dict(resolution=0.0), "resolution"),
    (dict(resolution=-0.05), "resolution"),
    (dict(resolution=float("inf")), "resolution"),
    (dict(resolution=float("nan")), "resolution"),
    (dict(free_thresh=-0.1), "free_thresh"),
    (dict(occupied_thresh=1.01), "occupied_thresh"),
    (dict(occupied_thresh=True), "occupied_thresh"),
    (dict(free_thresh=0.65), "free_thresh"),
    (dict(free_thresh=0.8), "free_thresh"),
])
def test_bad_values(mapdir, over, key):
  with pytest.raises(ValueError, match=f"key '{key}'") as e:
    _load_fields(mapdir, **over)
  assert str(mapdir / "m.yaml") in str(e.value)


@pytest.mark.parametrize("content", [b"", b"not an image at all", b"P5\n3 1\n255\n\x00"])
def test_undecodable_image(mapdir, content):
  (mapdir / "m.pgm").write_bytes(content)
  with pytest.raises(ValueError, match=r"cannot decode image file .*m\.pgm") as e:
    _load_fields(mapdir)
  assert "'image'" in str(e.value)


def test_image_is_directory(mapdir):
  (mapdir / "d").mkdir()
  with pytest.raises(ValueError, match="directory"):
    _load_fields(mapdir, image="d")


# --------------------------------------------------------------------------- saving

ALL_CELLS = np.arange(-1, 101, dtype=np.int8)


def _grid(values=ALL_CELLS, shape=(6, 17), origin=(-1.25, 3.5, 0.0), resolution=0.05):
  return OccupancyGrid(np.asarray(values, np.int8).reshape(shape), resolution, origin)


def test_trinary_round_trip_025_065(tmp_path):
  yml, img = save_map(_grid(), tmp_path / "m", free_thresh=0.25, occupied_thresh=0.65)
  assert (yml.name, img.name) == ("m.yaml", "m.pgm")
  back = load_map(yml)
  cells = ALL_CELLS.astype(int)
  expected = np.where(cells < 0, -1, np.where(cells <= 25, 0, np.where(cells >= 65, 100, -1)))
  np.testing.assert_array_equal(back.data.ravel(), expected)
  assert back.data.shape == (6, 17)
  assert back.resolution == pytest.approx(0.05) and back.origin == (-1.25, 3.5, 0.0)


def test_trinary_save_pixels_and_yaml(tmp_path):
  yml, img = save_map(_grid(), tmp_path / "m", free_thresh=0.196, occupied_thresh=0.65,
                      image_format="PNG")
  assert img.suffix == ".png"
  pixels = np.asarray(Image.open(img))
  assert Image.open(img).mode == "L"
  cells = _grid().data[::-1].astype(int)  # image row y is grid row H-1-y
  fi, oi = 20, 65  # rint(19.6) = 20
  expected = np.where(cells < 0, 205, np.where(cells <= fi, 254, np.where(cells >= oi, 0, 205)))
  np.testing.assert_array_equal(pixels, expected)
  doc = yaml.safe_load(yml.read_text())
  assert doc == dict(image="m.png", mode="trinary", resolution=0.05, origin=[-1.25, 3.5, 0.0],
                     negate=0, occupied_thresh=0.65, free_thresh=0.196)


def test_trinary_yaml_always_writes_065_0196(tmp_path):
  yml, _ = save_map(_grid(), tmp_path / "m", free_thresh=0.1, occupied_thresh=0.9)
  doc = yaml.safe_load(yml.read_text())
  assert (doc["occupied_thresh"], doc["free_thresh"]) == (0.65, 0.196)


def test_raw_round_trip(tmp_path):
  data = np.arange(-128, 128, dtype=np.int8)
  yml, img = save_map(_grid(data, (16, 16)), tmp_path / "r", mode="raw")
  assert img.suffix == ".pgm"
  pixels = np.asarray(Image.open(img))[::-1].ravel()
  assert pixels.tolist() == [255 if v < 0 or v > 100 else v for v in data.tolist()]
  back = load_map(yml).data.ravel()
  assert back.tolist() == [-1 if v < 0 or v > 100 else v for v in data.tolist()]


def test_scale_round_trip_within_one(tmp_path):
  yml, img = save_map(_grid(), tmp_path / "s", mode="scale", free_thresh=0.001, occupied_thresh=1.0)
  assert img.suffix == ".png" and Image.open(img).mode == "RGBA"
  doc = yaml.safe_load(yml.read_text())
  assert (doc["mode"], doc["occupied_thresh"], doc["free_thresh"]) == ("scale", 1.0, 0.001)
  back = load_map(yml).data.ravel().astype(int)
  cells = ALL_CELLS.astype(int)
  assert back[0] == -1  # unknown survives through the alpha channel
  assert np.abs(back[1:] - cells[1:]).max() <= 1
  assert back[1] == 0 and back[-1] == 100


def test_scale_save_pixels(tmp_path):
  _, img = save_map(_grid(), tmp_path / "s", mode="scale")
  rgba = np.asarray(Image.open(img))[::-1].reshape(-1, 4).astype(int)
  cells = ALL_CELLS.astype(int)
  assert (rgba[:, 0] == rgba[:, 1]).all() and (rgba[:, 1] == rgba[:, 2]).all()
  assert rgba[0, 3] == 0 and rgba[0, 0] in (127, 128)  # invalid: gray 0.5, transparent
  assert (rgba[1:, 3] == 255).all()
  np.testing.assert_array_equal(rgba[1:, 0], np.floor(2.55 * (100 - cells[1:]) + 0.5 + 1e-9))


def test_scale_to_pgm_warns(tmp_path):
  with pytest.warns(UserWarning, match="transparency"):
    _, img = save_map(_grid(), tmp_path / "s", mode="scale", image_format="pgm")
  assert Image.open(img).mode == "L"


@pytest.mark.parametrize("given, yaml_name, image_name", [
    ("m", "m.yaml", "m.pgm"), ("m.yaml", "m.yaml", "m.pgm"), ("m.png", "m.yaml", "m.png"),
    ("m.BMP", "m.yaml", "m.bmp"), ("m.v2", "m.v2.yaml", "m.v2.pgm")])
def test_save_path_with_or_without_extension(tmp_path, given, yaml_name, image_name):
  yml, img = save_map(_grid(), tmp_path / given)
  assert (yml.name, img.name) == (yaml_name, image_name)
  assert yml.is_file() and img.is_file()
  assert yaml.safe_load(yml.read_text())["image"] == image_name
  assert load_map(yml).data.shape == (6, 17)


def test_save_empty_name_uses_timestamp(tmp_path, monkeypatch):
  monkeypatch.chdir(tmp_path)
  yml, img = save_map(_grid(), "")
  assert re.fullmatch(r"map_\d+\.yaml", yml.name) and (tmp_path / img).is_file()


def test_save_writes_exact_numbers(tmp_path):
  # map_saver writes 3 decimals (1.235, -7.890) and a quaternion-normalised yaw; we write
  # the shortest repr that reads back as the same float64.
  yml, _ = save_map(_grid(origin=(1.23456, -7.89012, 4.0)), tmp_path / "o")
  text = yml.read_text()
  assert "resolution: 0.05\n" in text and "origin: [1.23456, -7.89012, 4.0]\n" in text
  back = load_map(yml)
  assert back.origin == (1.23456, -7.89012, 4.0) and back.resolution == 0.05


@pytest.mark.parametrize("free, occupied", [(2.0, 2.0), (-2.0, -2.0), (0.7, 0.2), (0.5, 0.5),
                                            (0.1, float("nan"))])
def test_save_invalid_thresholds(tmp_path, free, occupied):
  with pytest.raises(ValueError, match="thresh"):
    save_map(_grid(), tmp_path / "m", free_thresh=free, occupied_thresh=occupied)
  assert not list(tmp_path.iterdir())


def test_save_zero_thresholds_use_defaults(tmp_path):
  yml, _ = save_map(_grid(), tmp_path / "m", mode="scale", free_thresh=0.0, occupied_thresh=0.0)
  doc = yaml.safe_load(yml.read_text())
  assert (doc["occupied_thresh"], doc["free_thresh"]) == (0.65, 0.25)
  assert "occupied_thresh: 0.65\nfree_thresh: 0.25\n" in yml.read_text()


def test_save_write_error(tmp_path):
  with pytest.raises(OSError):
    save_map(_grid(), tmp_path / "no_such_dir" / "m")


@pytest.mark.parametrize("kwargs, error, match", [
    (dict(mode="ternary"), ValueError, "mode"),
    (dict(image_format="jpg"), ValueError, "image_format"),
    (dict(path="m.png", image_format="pgm"), ValueError, "image_format"),
    (dict(grid="not a grid"), TypeError, "OccupancyGrid"),
    (dict(grid=_grid(resolution=0.0)), ValueError, "resolution"),
])
def test_save_rejects(tmp_path, kwargs, error, match):
  args = dict(grid=_grid(), path="m") | kwargs
  grid, path = args.pop("grid"), tmp_path / args.pop("path")
  with pytest.raises(error, match=match):
    save_map(grid, path, **args)


# =========================================================================== strict loading, exact saving
# Hostile files fail loudly and cheaply; metadata round-trips exactly.

import dataclasses  # noqa: E402
import os  # noqa: E402
import struct  # noqa: E402
import threading  # noqa: E402
import time as _time  # noqa: E402
import zlib  # noqa: E402

import jaxfilters  # noqa: E402
from jaxfilters import map_decode  # noqa: E402
from jaxfilters.map_io import MAX_MAP_CELLS, MapMetadata, load_map_with_metadata  # noqa: E402
from tests.fuzz.fuzz_inputs import encode_png, png_chunk  # noqa: E402


def _yaml_text(path: Path, **over) -> Path:
  """A map YAML with raw (unquoted) YAML text for the given keys."""
  fields = dict(image="m.pgm", resolution="0.05", origin="[1.0, 2.0, 0.5]", negate="0",
                occupied_thresh="0.65", free_thresh="0.196") | over
  path.write_text("".join(f"{k}: {v}\n" for k, v in fields.items()))
  return path


# --------------------------------------------------------------------------- float32 geometry

# resolution 1e-50 is 0.0 in float32: every pose up and right of the origin, even 1e6 m away,
# gives (x - ox) / res = inf and lands "in the mask"; 1e39 is inf in float32.
BAD_RESOLUTIONS = [1e-50, 1e-39, 1e39, -1e39, 0.0, -0.05, float("nan"), float("inf"), 10**400,
                   True, [0.05, 0.05], "0.05"]
BAD_ORIGINS = [(1e39, 0.0, 0.0), (0.0, -1e39), (1e-50, 0.0, 0.0), (0.0, 0.0, 1e-45),
               (0.0, float("nan")), (10**400, 0.0), (0.0,), (0.0, 0.0, 0.0, 0.0),
               ((0.0, 0.0), (0.0, 0.0)), "ab"]


@pytest.mark.parametrize("resolution", BAD_RESOLUTIONS, ids=repr)
def test_grid_create_rejects_resolution(resolution):
  with pytest.raises(ValueError, match="OccupancyGrid.create: resolution") as e:
    OccupancyGrid.create(np.zeros((2, 2), np.int8), resolution)
  assert len(str(e.value)) < 300


@pytest.mark.parametrize("origin", BAD_ORIGINS, ids=repr)
def test_grid_create_rejects_origin(origin):
  with pytest.raises(ValueError, match="OccupancyGrid.create: origin"):
    OccupancyGrid.create(np.zeros((2, 2), np.int8), 0.05, origin)


@pytest.mark.parametrize("frame_id", ["", 5, None])
def test_grid_create_rejects_frame_id(frame_id):
  with pytest.raises(ValueError, match="frame_id"):
    OccupancyGrid.create(np.zeros((2, 2), np.int8), 0.05, frame_id=frame_id)


def test_grid_create_keeps_float64_values():
  g = OccupancyGrid.create(np.array([[-1, 0, 100]], np.int16), 0.05, (1.1, -2.2))
  assert g.data.dtype == np.int8 and g.data.tolist() == [[-1, 0, 100]]
  assert type(g.resolution) is float and g.resolution == 0.05
  assert g.origin == (1.1, -2.2, 0.0) and all(type(v) is float for v in g.origin)
  g = OccupancyGrid.create(np.zeros((1, 1), np.int8), np.float32(0.05), np.array([0.0, 1.0, 3.0]))
  assert g.resolution == float(np.float32(0.05)) and g.origin == (0.0, 1.0, 3.0)
  tiny = float(np.finfo(np.float32).tiny)  # the smallest normal float32 is still accepted
  assert OccupancyGrid.create(np.zeros((1, 1), np.int8), tiny, (-tiny, 3e38)).resolution == tiny


@pytest.mark.parametrize("key, value", [
    ("resolution", "1e-50"), ("resolution", "1.0e-50"), ("resolution", "1e39"),
    ("resolution", "1.0e+39"), ("resolution", "1" + "0" * 400), ("resolution", "'1e-45'"),
    ("origin", "[1e39, 0, 0]"), ("origin", "[0, 1.0e-50, 0]"), ("origin", "[0, 0, 1.0e+39]"),
    ("origin", "[1" + "0" * 400 + ", 0, 0]"), ("free_thresh", "1.0e-40"),
    ("occupied_thresh", "1" + "0" * 400), ("free_thresh", "'1_0'"), ("resolution", "'nan'"),
    ("resolution", "'\u0660.\u0660\u0665'"), ("negate", "'\u0661'"),  # Arabic-Indic digits
])
def test_load_map_rejects_values_float32_cannot_hold(mapdir, key, value):
  y = _yaml_text(mapdir / "m.yaml", **{key: value})
  with pytest.raises(ValueError, match=f"key '{key}'") as e:
    load_map(y)
  assert str(y) in str(e.value) and len(str(e.value)) < 400


def test_load_map_image_rejects_huge_threshold():
  with pytest.raises(ValueError, match="occupied_thresh"):
    load_map_image(G_ALL, occupied_thresh=10**400, free_thresh=0.1)
  with pytest.raises(ValueError, match="free_thresh"):
    load_map_image(G_ALL, occupied_thresh=0.5, free_thresh=1e-42)


# --------------------------------------------------------------------------- regular files only


def _finishes(fn, seconds: float = 10.0):
  """Runs fn in a thread; returns (finished, exception or None)."""
  out = {}

  def run():
    try:
      fn()
      out["error"] = None
    except BaseException as e:  # noqa: BLE001
      out["error"] = e
  t = threading.Thread(target=run, daemon=True)
  t.start()
  t.join(seconds)
  return not t.is_alive(), out.get("error")


def _release_fifo(fifo: Path) -> None:
  """Unblocks a reader stuck in open() on the FIFO (what the old loader did)."""
  try:
    os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
  except OSError:
    pass  # no reader waiting


@pytest.mark.parametrize("which", ["yaml", "image"])
def test_fifo_raises_at_once(mapdir, which):
  fifo = mapdir / "fifo"
  os.mkfifo(fifo)
  y = mapdir / "fifo" if which == "yaml" else _write_yaml(mapdir / "m.yaml",
                                                           **_good_fields(image="fifo"))
  try:
    finished, error = _finishes(lambda: load_map(y), 5.0)
  finally:
    _release_fifo(fifo)
  assert finished, "load_map blocked on a FIFO"
  assert isinstance(error, ValueError) and "FIFO" in str(error)


@pytest.mark.parametrize("which, path, kind", [
    ("yaml", "/dev/null", "device"), ("image", "/dev/zero", "device"), ("yaml", ".", "directory")])
def test_non_regular_files_raise(mapdir, which, path, kind):
  if not os.path.exists(path):
    pytest.skip(f"{path} does not exist here")
  if which == "yaml":
    y = mapdir if path == "." else Path(path)
  else:
    y = _write_yaml(mapdir / "m.yaml", **_good_fields(image=path))
  finished, error = _finishes(lambda: load_map(y), 5.0)
  assert finished and isinstance(error, ValueError) and kind in str(error)


# --------------------------------------------------------------------------- YAML parsing

_BOMB = ('a: &a ["x","x","x","x","x","x","x","x","x"]\nb: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a]\n'
         'c: &c [*b,*b,*b,*b,*b,*b,*b,*b,*b]\nd: &d [*c,*c,*c,*c,*c,*c,*c,*c,*c]\n'
         'e: &e [*d,*d,*d,*d,*d,*d,*d,*d,*d]\nf: &f [*e,*e,*e,*e,*e,*e,*e,*e,*e]\n'
         'g: &g [*f,*f,*f,*f,*f,*f,*f,*f,*f]\nh: &h [*g,*g,*g,*g,*g,*g,*g,*g,*g]\n'
         'image: m.pgm\nresolution: *h\n')


@pytest.mark.parametrize("text, match", [
    (_BOMB, "alias"),
    ("image: m.pgm\nresolution: 0.05\nresolution: 0.1\n", "duplicate key 'resolution'"),
    ("base: &b {negate: 0}\n<<: *b\nimage: m.pgm\n", "alias"),
    ("<<: {negate: 0}\nimage: m.pgm\n", "merge key"),
    ("image: m.pgm\ndeep: " + "[" * 40000 + "\n", "deeper than 16"),
    ("image: m.pgm\nx: " + "[" * 17 + "]" * 17 + "\n", "deeper than 16"),
    ("image: m.pgm\norigin: [2001-02-30, 0, 0]\n", "invalid map YAML"),
    ("image: m.pgm\n---\nimage: n.pgm\n", "invalid map YAML"),
    ("image: m.pgm\n[1, 2]: 3\n", "unhashable"),
    ("image: !!python/object/apply:os.system ['true']\n", "invalid map YAML"),
])
def test_hostile_yaml(mapdir, text, match):
  (mapdir / "m.yaml").write_text(text)
  start = _time.perf_counter()
  with pytest.raises(ValueError, match=match) as e:
    load_map(mapdir / "m.yaml")
  assert _time.perf_counter() - start < 30.0   # a blow-up (exponential parsing, a huge allocation) takes far longer; not a speed test
  assert str(mapdir / "m.yaml") in str(e.value) and len(str(e.value)) < 600


def test_yaml_size_cap_and_encoding(mapdir):
  y = _write_yaml(mapdir / "m.yaml", **_good_fields())
  y.write_text(y.read_text() + "#" + "x" * map_decode.MAX_YAML_BYTES + "\n")
  with pytest.raises(ValueError, match="bytes; at most 65536"):
    load_map(y)
  y.write_bytes(b"image: m\xff.pgm\n")
  with pytest.raises(ValueError, match="not UTF-8"):
    load_map(y)


def test_long_values_are_cut_in_messages(mapdir):
  for over in (dict(image="a" * 5000 + ".pgm"), dict(origin=["x" * 5000, 0, 0]),
               dict(negate="y" * 5000), dict(mode="z" * 5000), dict(image=["i"] * 5000)):
    with pytest.raises((ValueError, FileNotFoundError)) as e:
      _load_fields(mapdir, **over)
    assert len(str(e.value)) < 700, (over.keys(), len(str(e.value)))


# --------------------------------------------------------------------------- PNG strictness

GRAY = np.array([[0, 254, 254, 205], [254, 0, 100, 255], [30, 254, 0, 206]], np.uint8)


def _png_map(mapdir: Path, png: bytes) -> Path:
  (mapdir / "p.png").write_bytes(png)
  return _write_yaml(mapdir / "p.yaml", **_good_fields(image="p.png"))


def _loads_to(y: Path, pixels: np.ndarray, alpha=None) -> None:
  expected = load_map_image(pixels, alpha, mode="trinary", occupied_thresh=0.65, free_thresh=0.196)
  np.testing.assert_array_equal(load_map(y).data, expected)


def _png_with_raw(raw: bytes, width: int, height: int, level: int = 6) -> bytes:
  ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
  return (b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr) +
          png_chunk(b"IDAT", zlib.compress(raw, level)) + png_chunk(b"IEND", b""))


def _rows(pixels: np.ndarray) -> bytes:
  return b"".join(b"\x00" + r.tobytes() for r in pixels)


def test_png_reference_files_load(mapdir):
  _loads_to(_png_map(mapdir, _png_with_raw(_rows(GRAY), 4, 3)), GRAY)
  _loads_to(_png_map(mapdir, encode_png(GRAY, interlace=1, idat_parts=3)), GRAY)


def test_png_zlib_stream_ending_early_raises(mapdir):
  # A complete zlib stream holding 2 of 3 rows: Pillow fills the missing row with 0 (occupied).
  y = _png_map(mapdir, _png_with_raw(_rows(GRAY)[:10], 4, 3))
  with pytest.raises(ValueError, match=r"cannot decode image file .*p\.png.*decompresses to 10 "
                                       r"bytes; 4 x 3 pixels need 15"):
    load_map(y)


def test_png_corrupt_pixel_data_with_valid_crc_raises(mapdir):
  # Stored (level 0) deflate with a flipped data byte and every CRC valid: the only check left
  # is zlib's Adler-32, which Pillow never reads when it sits in a later IDAT chunk (as here)
  # because it stops once it has every row; the old loader read pixel 254 as 190.
  comp = bytearray(zlib.compress(_rows(GRAY), 0))
  comp[2 + 5 + 3] ^= 0x40  # zlib header, stored-block header, then row 0's third pixel
  png = (b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", struct.pack(">IIBBBBB", 4, 3, 8, 0, 0, 0, 0))
         + png_chunk(b"IDAT", bytes(comp[:-4])) + png_chunk(b"IDAT", bytes(comp[-4:]))
         + png_chunk(b"IEND", b""))
  with pytest.raises(ValueError, match="corrupt.*incorrect data check"):
    load_map(_png_map(mapdir, png))


def test_png_damage_raises(mapdir):
  good = _png_with_raw(_rows(GRAY), 4, 3)
  cases = {
      "truncated": (good[:-5], "truncated"),
      "crc": (good[:40] + bytes([good[40] ^ 1]) + good[41:], "CRC"),
      "trailing": (good + b"junk", "after its IEND"),
      "no IEND": (good[:-12], "IEND missing"),
      "critical chunk": (good[:-12] + png_chunk(b"ABCD", b"") + good[-12:], "unknown critical"),
  }
  for name, (png, match) in cases.items():
    y = _png_map(mapdir, png)
    with pytest.raises(ValueError, match=match):
      load_map(y)


def test_png_palette_index_outside_palette_raises(mapdir):
  index = np.array([[0, 1, 2, 3]], np.uint8)  # indices 2, 3 have no colour: Pillow reads black
  png = encode_png(index, colour=3, palette=bytes([0, 0, 0, 254, 254, 254]))
  with pytest.raises(ValueError, match="palette index 3 is outside the 2-colour palette"):
    load_map(_png_map(mapdir, png))


def test_png_bomb_rejected_before_decoding(mapdir):
  # 92 bytes declaring 13000 x 13000: Pillow would allocate 169 MB (2.4 GB in the old RGBA path).
  ihdr = struct.pack(">IIBBBBB", 13000, 13000, 8, 2, 0, 0, 0)
  png = (b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr) +
         png_chunk(b"IDAT", zlib.compress(b"\x00" * 100)) + png_chunk(b"IEND", b""))
  y = _png_map(mapdir, png)
  start = _time.perf_counter()
  with pytest.raises(ValueError, match="MAX_MAP_CELLS"):
    load_map(y)
  ihdr = struct.pack(">IIBBBBB", 4096, 4096, 8, 0, 0, 0, 0)  # under the cap, too little data
  (mapdir / "p.png").write_bytes(b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr) +
                                 png_chunk(b"IDAT", zlib.compress(b"\x00" * 100)) +
                                 png_chunk(b"IEND", b""))
  with pytest.raises(ValueError, match="holds only 12 compressed bytes"):
    load_map(y)
  assert _time.perf_counter() - start < 30.0   # a blow-up (exponential parsing, a huge allocation) takes far longer; not a speed test


def test_cell_cap_is_checked_from_the_header(mapdir):
  assert MAX_MAP_CELLS == 2**26
  y = _png_map(mapdir, encode_png(GRAY))
  assert load_map_with_metadata(y, max_cells=12)[0].data.shape == (3, 4)
  with pytest.raises(ValueError, match="4 x 3 = 12 cells; at most 11"):
    load_map_with_metadata(y, max_cells=11)
  (mapdir / "m.pgm").write_bytes(b"P5\n8193 8192\n255\n" + b"\x00" * 10)
  with pytest.raises(ValueError, match="8193 x 8192 = 67117056 cells; at most 67108864"):
    _load_fields(mapdir)


def test_sixteen_bit_png_transparency(mapdir):
  raw = b"\x00" + struct.pack(">4H", 0, 1000, 65535, 1000)
  png = (b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", struct.pack(">IIBBBBB", 4, 1, 16, 0, 0, 0, 0))
         + png_chunk(b"tRNS", struct.pack(">H", 1000)) + png_chunk(b"IDAT", zlib.compress(raw))
         + png_chunk(b"IEND", b""))
  assert load_map(_png_map(mapdir, png)).data.tolist() == [[100, -1, 0, -1]]
  rgb16 = encode_png(np.full((1, 2, 3), 1000), depth=16, colour=2,
                     trns=struct.pack(">3H", 1000, 1000, 1000))
  with pytest.raises(ValueError, match="16-bit RGB PNG with a tRNS"):
    load_map(_png_map(mapdir, rgb16))


# --------------------------------------------------------------------------- Netpbm / BMP / others


@pytest.mark.parametrize("content, match", [
    (b"P5\n3 1\n100\n\x00\xc8\x32", "sample 1 is 200, above maxval 100"),
    (b"P5\n2 1\n1000\n\x00\x05\x03\xe9", "sample 1 is 1001, above maxval 1000"),
    (b"P2\n3 1\n100\n0 200 50\n", "sample 1 is 200, above maxval 100"),
    (b"P2\n3 1\n255\n0 20 50 7\n", "holds 4 samples.*surplus"),
    (b"P2\n3 1\n255\n0 20\n", "holds 2 samples.*truncated"),
    (b"P2\n3 1\n255\n0 1_0 5\n", "decimal"),
    (b"P1\n3 1\n0 2 1\n", "only 0 and 1"),
    (b"P5\n3 1\n255\n\x00\x01", "truncated: 3 x 1 needs 3 bytes"),
    (b"P5\n3 1\n255\n\x00\x01\x02\x03", "1 bytes after"),
    (b"P5\n3 1\n0\n\x00\x01\x02", "maxval must be 1..65535"),
    (b"P5\n3 1\n70000\n" + b"\x00" * 6, "maxval must be 1..65535"),
    (b"P5\n0 1\n255\n", "at least 1"),
    (b"P5\n3 x\n255\n\x00\x01\x02", "height must be a decimal"),
    (b"P5\n3 1\n255#c\n\x00\x01\x02", "maxval must be a decimal"),
    (b"P5\n13000 13000\n255\n\x00", "13000 x 13000 = 169000000 cells"),
    (b"P7\nWIDTH 1\n", "PAM or PFM"),
    (b"\xff\xd8\xff\xe0 JFIF", "JPEG"),
    (b"GIF89a....", "GIF"),
])
def test_netpbm_and_format_errors(mapdir, content, match):
  (mapdir / "m.pgm").write_bytes(content)
  with pytest.raises(ValueError, match=match) as e:
    _load_fields(mapdir)
  assert "cannot decode image file" in str(e.value) and "'image'" in str(e.value)


def test_huge_declared_sizes_are_refused_before_reading(mapdir, monkeypatch):
  reads = []
  real_read = os.read
  monkeypatch.setattr(map_decode.os, "read", lambda fd, n: reads.append(n) or real_read(fd, n))
  (mapdir / "m.pgm").write_bytes(b"P5\n4000 4000\n255\n" + b"\x00" * 100_000)
  with pytest.raises(ValueError, match="raster truncated: 4000 x 4000 needs 16000000 bytes"):
    _load_fields(mapdir)
  (mapdir / "m.pgm").write_bytes(b"P5\n40 40\n255\n" + b"\x00" * 100_000)
  with pytest.raises(ValueError, match="98400 bytes after its 40 x 40 raster"):
    _load_fields(mapdir)
  (mapdir / "m.pgm").write_bytes(b"P2\n2 2\n255\n" + b" " * 200_000)
  with pytest.raises(ValueError, match="header allows at most 65594"):
    _load_fields(mapdir)
  assert max(reads) <= map_decode.MAX_IMAGE_HEADER_BYTES  # only the header was read


def test_bmp_errors(mapdir):
  buf = __import__("io").BytesIO()
  Image.fromarray(GRAY).save(buf, "BMP")
  good = buf.getvalue()
  (mapdir / "b.bmp").write_bytes(good)
  y = _write_yaml(mapdir / "b.yaml", **_good_fields(image="b.bmp"))
  _loads_to(y, GRAY)
  for content, match in ((good[:-4], "does not fit"),
                         (good[:30] + struct.pack("<I", 1) + good[34:], "compression 1"),
                         (good[:46] + struct.pack("<I", 2) + good[50:], "palette index")):
    (mapdir / "b.bmp").write_bytes(content)
    with pytest.raises(ValueError, match=match):
      load_map(y)


def test_only_value_and_file_errors_escape_for_tiff(mapdir):
  buf = __import__("io").BytesIO()
  Image.fromarray(GRAY).save(buf, "TIFF")
  (mapdir / "m.pgm").write_bytes(buf.getvalue())
  with pytest.raises(ValueError, match="TIFF file; map images must be PNG, PGM/PPM/PBM or "
                                       "uncompressed BMP"):
    _load_fields(mapdir)


# --------------------------------------------------------------------------- exact save_map


def test_save_tiny_resolution_round_trips(tmp_path):
  # map_saver's 3 decimals wrote "0.000", which load_map (rightly) rejects.
  yml, _ = save_map(_grid(resolution=0.0004), tmp_path / "m")
  assert "resolution: 0.0004\n" in yml.read_text()
  assert load_map(yml).resolution == 0.0004


def test_save_thresholds_past_three_decimals_round_trip(tmp_path):
  # 0.1001 / 0.1004 were both written 0.100: load_map refused free >= occupied.
  yml, _ = save_map(_grid(), tmp_path / "m", mode="scale", free_thresh=0.1001,
                    occupied_thresh=0.1004)
  _, meta = load_map_with_metadata(yml)
  assert (meta.free_thresh, meta.occupied_thresh) == (0.1001, 0.1004)


@settings(max_examples=40, deadline=None)
@given(res=st.floats(F32_TINY, 1e30), xy=st.lists(st.floats(-1e30, 1e30), min_size=3,
                                                    max_size=3),
       free=st.floats(F32_TINY, 0.5), span=st.floats(1e-9, 0.5))
def test_save_numbers_read_back_exactly(tmp_path_factory, res, xy, free, span):
  xy = [0.0 if abs(v) < F32_TINY else v for v in xy]
  d = tmp_path_factory.mktemp("exact")
  grid = _grid(resolution=res, origin=tuple(xy))
  yml, _ = save_map(grid, d / "m", mode="raw", free_thresh=free, occupied_thresh=free + span)
  back, meta = load_map_with_metadata(yml)
  assert back.resolution == res and back.origin == tuple(xy)
  assert (meta.free_thresh, meta.occupied_thresh) == (free, free + span)
  doc = yaml.safe_load(yml.read_text())  # plain YAML 1.1 floats too, not strings
  assert doc["resolution"] == res and doc["origin"] == xy


def test_save_refuses_what_load_would_reject(tmp_path):
  for bad in (dict(resolution=1e-50), dict(resolution=1e39), dict(origin=(1e39, 0.0, 0.0))):
    with pytest.raises(ValueError, match="resolution|origin"):
      save_map(_grid(**bad), tmp_path / "m")
  with pytest.raises(ValueError, match="free_thresh"):
    save_map(_grid(), tmp_path / "m", mode="scale", free_thresh=1e-42)
  assert not list(tmp_path.iterdir())


# --------------------------------------------------------------------------- metadata


def test_metadata_matches_the_yaml(nav2_maps):
  for y in sorted(nav2_maps.glob("*.yaml")):
    if y.stem == "nav2_params":
      continue
    doc = yaml.safe_load(y.read_text())
    grid, meta = load_map_with_metadata(y)
    np.testing.assert_array_equal(grid.data, load_map(y).data)
    assert meta.image == doc["image"] and meta.image_path == str(y.parent / doc["image"])
    assert meta.mode == str(doc.get("mode", "trinary")).lower()
    assert meta.resolution == float(doc["resolution"]) == grid.resolution
    assert meta.origin == tuple(float(v) for v in doc["origin"]) == grid.origin
    assert meta.occupied_thresh == float(doc["occupied_thresh"])
    assert meta.free_thresh == float(doc["free_thresh"])
    assert meta.negate is bool(doc["negate"])


def test_real_maps_round_trip_exactly_with_metadata(nav2_maps, tmp_path):
  for y in sorted(nav2_maps.glob("*.yaml")):
    if y.stem == "nav2_params":
      continue
    grid, meta = load_map_with_metadata(y)
    yml, img = save_map(grid, tmp_path / y.stem, metadata=meta)
    back, meta2 = load_map_with_metadata(yml)
    np.testing.assert_array_equal(back.data, grid.data, err_msg=y.stem)
    assert dataclasses.replace(meta2, image=meta.image, image_path=meta.image_path) == meta
    assert img.suffix == Path(meta.image).suffix  # the format comes back too


REPRESENTABLE = {"trinary": [-1, 0, 100], "raw": list(range(-1, 101)), "scale": None}


@settings(max_examples=50, deadline=None)
@given(mode=st.sampled_from(MAP_MODES), negate=st.booleans(), fmt=st.sampled_from(["png", "pgm"]),
       free=st.one_of(st.just(0.0), st.floats(F32_TINY, 0.9)), span=st.floats(0.05, 1.0),
       data=st.data())
def test_metadata_save_is_exact_or_refuses(tmp_path_factory, mode, negate, fmt, free, span, data):
  occupied = min(1.0, free + span)
  meta = MapMetadata.create(resolution=0.05, origin=(1.0, -2.0, 0.3), mode=mode,
                            occupied_thresh=occupied, free_thresh=free, negate=negate)
  values = data.draw(st.lists(st.integers(-1, 100), min_size=12, max_size=12))
  grid = OccupancyGrid.create(np.array(values, np.int8).reshape(3, 4), 0.05, (1.0, -2.0, 0.3))
  # What a pixel can come back as, from the scalar reference over all 256 grays (+ alpha).
  loadable = {_ref_pixel(g, mode, occupied, free, negate) for g in range(256)}
  if mode == "scale" and fmt == "png":
    loadable.add(-1)
  d = tmp_path_factory.mktemp("meta")
  if set(values) <= loadable:
    yml, _ = save_map(grid, d / "m", metadata=meta, image_format=fmt)
    back, meta2 = load_map_with_metadata(yml)
    np.testing.assert_array_equal(back.data, grid.data)
    assert dataclasses.replace(meta2, image="", image_path="") == meta
  else:
    missing = sorted(set(values) - loadable)
    with pytest.raises(ValueError, match=rf"cannot save (cell value {missing[0]}|unknown)"):
      save_map(grid, d / "m", metadata=meta, image_format=fmt)
    assert not list(d.iterdir())


def test_metadata_save_conflicts(tmp_path):
  grid = _grid(values=np.array([0, 100, -1] * 34, np.int8))
  meta = MapMetadata.create(resolution=grid.resolution, origin=grid.origin, mode="scale",
                            occupied_thresh=1.0, free_thresh=0.0)
  with pytest.raises(ValueError, match="mode 'raw' disagrees with metadata.mode 'scale'"):
    save_map(grid, tmp_path / "m", metadata=meta, mode="raw")
  with pytest.raises(ValueError, match="free_thresh 0.25 disagrees"):
    save_map(grid, tmp_path / "m", metadata=meta, free_thresh=0.25)
  with pytest.raises(ValueError, match="differ from the grid's"):
    save_map(grid, tmp_path / "m", metadata=dataclasses.replace(meta, resolution=0.1))
  with pytest.raises(ValueError, match="unknown .* without transparency"):
    save_map(grid, tmp_path / "m", metadata=meta, image_format="pgm")
  with pytest.raises(ValueError, match="free_thresh"):
    save_map(grid, tmp_path / "m", metadata=dataclasses.replace(meta, free_thresh=1.0))
  with pytest.raises(TypeError, match="MapMetadata"):
    save_map(grid, tmp_path / "m", metadata={"mode": "scale"})
  assert not list(tmp_path.iterdir())
  # Agreeing arguments are fine; free 0.0 stays 0.0 (no map_saver default) with metadata.
  yml, _ = save_map(grid, tmp_path / "m", metadata=meta, mode="SCALE", free_thresh=0.0)
  assert "free_thresh: 0.0\n" in yml.read_text()
  np.testing.assert_array_equal(load_map(yml).data, grid.data)


def test_metadata_create_validates():
  with pytest.raises(ValueError, match="resolution"):
    MapMetadata.create(resolution=1e-50)
  with pytest.raises(ValueError, match="mode"):
    MapMetadata.create(resolution=0.05, mode="ternary")
  with pytest.raises(ValueError, match="free_thresh must be < occupied_thresh"):
    MapMetadata.create(resolution=0.05, occupied_thresh=0.2, free_thresh=0.3)
  with pytest.raises(ValueError, match="negate"):
    MapMetadata.create(resolution=0.05, negate="yes")
  m = MapMetadata.create(resolution=0.05, origin=(1.0, 2.0), negate=1)
  assert m.origin == (1.0, 2.0, 0.0) and m.negate is True and m.mode == "trinary"
  with pytest.raises(dataclasses.FrozenInstanceError):
    m.mode = "raw"


def test_new_names_are_public():
  for name in ("MapMetadata", "load_map_with_metadata", "MAX_MAP_CELLS"):
    assert name in jaxfilters.__all__ and getattr(jaxfilters, name) is not None
