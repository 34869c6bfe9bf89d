"""Tests for jaxfilters.map_io against spec §10 (Nav2 map_server / map_saver)."""

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
from jaxfilters.map_io import MAP_MODES, load_map, load_map_image, save_map

MAPS = Path(__file__).resolve().parents[1].parent / "shared" / "maps" / "nav2"


def _maps_dir() -> Path:
  if not MAPS.is_dir():
    pytest.skip(f"real Nav2 maps not found at {MAPS} (they live in ../shared/maps/nav2 next to "
                f"the repo; a fresh clone does not have them)")
  return MAPS


# --------------------------------------------------------------------------- reference


def _ref_pixel(g: int, mode: str, occupied: float, free: float, negate: bool,
               alpha: int = 255) -> int:
  """One pixel, written out scalar by scalar from spec §10.2."""
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
# Spec §10.2 worked table, one column each: (mode, occupied, free) -> values for TABLE_G.
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
       free=st.floats(0.0, 0.999), span=st.floats(1e-3, 1.0))
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


def test_save_origin_precision(tmp_path):
  yml, _ = save_map(_grid(origin=(1.23456, -7.89012, 4.0)), tmp_path / "o")
  text = yml.read_text()
  assert "resolution: 0.050\n" in text
  back = load_map(yml)
  assert back.origin[:2] == (1.235, -7.89)
  assert back.origin[2] == pytest.approx(4.0 - 2 * math.pi)  # yaw through a quaternion


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
  assert "occupied_thresh: 0.650\nfree_thresh: 0.250\n" in yml.read_text()


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
