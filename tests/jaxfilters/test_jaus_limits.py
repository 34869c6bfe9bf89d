"""JAUS codec held to the map loader's discipline: small maps, size caps, files, lossy runs, tiles.

Each test pins one finding: the library refusing its own message for a small map, a tiny
run-length message declaring a huge grid, message files that are not regular files or are too
large, the run-length variant quantising costs without a word, and a CLI that could not encode
any shipped or Nav2 map (one message holds at most 65535 cells).
"""

from __future__ import annotations

import os
import struct
import threading
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from jaxfilters import cli
from jaxfilters import jaus as J
from jaxfilters.grid import OccupancyGrid
from jaxfilters.map_io import load_map, save_map
from tests.fuzz import fuzz_jaus

ROOT = Path(__file__).resolve().parents[2]
SHIPPED_MAPS = sorted(p for p in (ROOT / "sims" / "assets").glob("*.yaml")
                      if "image:" in p.read_text())


def _cli(args, capsys):
  try:
    code = cli.main(args)
  except SystemExit as e:   # argparse errors exit through ArgumentParser.error
    code = e.code
  out, err = capsys.readouterr()
  return code, out, err


def _round_trip(grid, **options):
  tiles = J.grid_to_reports(grid, **options)
  data = b"".join(J.encode_report(t.report) for t in tiles)
  return J.reports_to_grid(J.decode_all(data))


# --------------------------------------------------------------------------- small maps


@pytest.mark.parametrize("res", [0.05, 0.01, 0.025, 0.03, 0.1, 1.0])
def test_small_design_maps_round_trip_exactly(res):
  rng = np.random.default_rng(int(res * 1000))
  for h in range(1, 7):
    for w in range(1, 7):
      grid = OccupancyGrid.create(rng.integers(-1, 101, size=(h, w)), res, (-2.5, 4.0, 0.0))
      back = J.report_to_grid(J.decode(J.encode_report(J.grid_to_report(grid,
                                                                         profile="design"))))
      assert np.array_equal(back.data, grid.data)
      assert back.resolution == res, (h, w)
      assert back.origin == pytest.approx(grid.origin, abs=1e-9)


def test_iop_map_whose_size_rounds_to_zero_is_refused_by_the_encoder():
  # 1 x 1 cell of 0.05 m: MapWidth 0.05 m is below half a step (0.0763 m) of the uint16 size,
  # so the message would say 0 m and the receiver could not tell the cell size.
  grid = OccupancyGrid.create(np.zeros((1, 1), np.int8), 0.05)
  with pytest.raises(ValueError, match=r"could not tell the cell size; use profile 'design'"):
    J.grid_to_report(grid)
  assert _round_trip(grid, profile="design").resolution == 0.05
  # 2 x 2 cells of 0.05 m: MapWidth 0.1 m goes out as 0.153 m, and the decoder's shortest
  # decimal in [0.038, 0.153] m per cell is 0.1 m; the encoder refuses instead.
  two = OccupancyGrid.create(np.zeros((2, 2), np.int8), 0.05)
  with pytest.raises(ValueError, match=r"would read the cell size .* as 0.1 m, not 0.05 m"):
    J.grid_to_report(two)
  report = J.grid_to_report(two, check_resolution=False)    # the receiver is told 0.05 m
  assert J.report_to_grid(J.decode(J.encode_report(report)), resolution=0.05).resolution == 0.05
  # Every small iop map is either refused at encode or read back with its own resolution.
  kept = 0
  for h in range(1, 9):
    for w in range(1, 9):
      for res in (0.01, 0.05, 0.1, 0.5, 1.0):
        g = OccupancyGrid.create(np.zeros((h, w), np.int8), res)
        try:
          report = J.grid_to_report(g)
        except ValueError as e:
          assert "could not tell the cell size" in str(e) or "would read the cell size" in str(e)
          continue
        assert J.report_to_grid(J.decode(J.encode_report(report))).resolution == res
        kept += 1
  assert kept > 50


def test_peer_message_with_zero_sizes_needs_the_resolution():
  report = J.CostMap2DReport.create(np.zeros((1, 1), np.uint8), map_width=0.0, map_height=0.0,
                                    pose=J.LocalPose(0.0, 0.0, 0.0))
  msg = J.decode(J.encode_report(report))
  with pytest.raises(ValueError, match="sizes are 0 on the wire.*pass resolution="):
    J.report_to_grid(msg)
  assert J.report_to_grid(msg, resolution=0.05).resolution == 0.05


# --------------------------------------------------------------------------- size caps


def _rle_message(rows: int, cols: int) -> bytes:
  """A design run-length report whose runs cover rows x cols cells exactly (4095 a run)."""
  cells, words = rows * cols, []
  while cells:
    n = min(4095, cells)
    words.append(8 | (len(words) % 8) | n << 4)
    cells -= n
  head = struct.pack("<HHHII", 0x4C11, rows, cols, 429497, 429497)
  pose = struct.pack("<BIIH", 1, 1 << 31, 1 << 31, 32768)
  return head + pose + struct.pack("<BH", 2, len(words)) + struct.pack(f"<{len(words)}H", *words)


@pytest.mark.parametrize("side, size_kb", [(9000, 38), (16380, 127)])
def test_declared_size_over_the_cap_is_refused_before_allocating(side, size_kb):
  data = _rle_message(side, side)
  assert len(data) // 1024 == size_kb
  tracemalloc.start()
  try:
    with pytest.raises(J.JausDecodeError, match=f"{side} x {side} = {side * side} cells exceeds "
                       f"max_cells={J.MAX_MAP_CELLS}") as err:
      J.decode(data)
    _, peak = tracemalloc.get_traced_memory()
  finally:
    tracemalloc.stop()
  assert err.value.offset == 2
  assert peak < 2 * len(data) * 8 + (1 << 20)   # the run words, never the cells


def test_cap_is_a_budget_over_all_messages_of_a_file():
  one = _rle_message(100, 100)
  assert len(J.decode_all(one * 3, max_cells=30000)) == 3
  with pytest.raises(J.JausDecodeError, match="exceeds max_cells=9999") as err:
    J.decode_all(one * 3, max_cells=29999)
  assert err.value.offset == 2 * len(one) + 2
  with pytest.raises(J.JausDecodeError, match="no message"):
    J.decode_all(b"")
  empty_query = bytes.fromhex("38d700")
  assert len(J.decode_all(empty_query * J.MAX_MESSAGES)) == J.MAX_MESSAGES
  with pytest.raises(J.JausDecodeError, match="more than MAX_MESSAGES") as err:
    J.decode_all(empty_query * 10**6)     # 3 MB: a million objects without the cap
  assert err.value.offset == 3 * J.MAX_MESSAGES
  with pytest.raises(J.JausDecodeError, match="needs 6 bytes, only 5 left") as err:
    J.decode_all(one + one[:-1])
  assert err.value.offset >= len(one)


# --------------------------------------------------------------------------- files


def _refused_quickly(fn) -> BaseException:
  result = []

  def call():
    try:
      fn()
    except BaseException as e:  # noqa: BLE001 - handed to the test thread
      result.append(e)

  thread = threading.Thread(target=call, daemon=True)
  thread.start()
  thread.join(10)
  assert not thread.is_alive(), "blocked"
  assert result, "not refused"
  return result[0]


def test_message_files_are_regular_and_capped(tmp_path):
  fifo = tmp_path / "pipe"
  os.mkfifo(fifo)
  big = tmp_path / "big.bin"
  with open(big, "wb") as f:
    f.truncate(J.MAX_FILE_BYTES + 1)            # sparse: nothing is written
  cases = [(tmp_path / "nope.bin", "does not exist"), (tmp_path, "is a directory"),
           (fifo, "is a FIFO"), (Path("/dev/zero"), "is a device"),
           (big, f"at most {J.MAX_FILE_BYTES} are allowed")]
  for path, match in cases:
    err = _refused_quickly(lambda: J.load_messages(path))
    assert isinstance(err, J.JausDecodeError) and isinstance(err, ValueError), err
    assert err.offset is None and match in str(err), err
  hexed = tmp_path / "m.hex"
  hexed.write_text("42 d7 zz")
  with pytest.raises(J.JausDecodeError, match="not hex text"):
    J.load_messages(hexed, hex=True)
  grid = OccupancyGrid.create(np.zeros((4, 5), np.int8), 0.5)
  data = J.encode_report(J.grid_to_report(grid))
  hexed.write_text(J.to_hex(data))
  with pytest.raises(J.JausDecodeError, match="looks like hex text"):
    J.load_messages(hexed)
  assert len(J.load_messages(hexed, hex=True)) == 1
  assert J.read_message_file(hexed, hex=True) == data


# --------------------------------------------------------------------------- lossy run-length


def test_lossy_run_length_needs_the_flag_and_the_decoded_report_says_quantised(nav2_maps):
  speed = load_map(nav2_maps / "warehouse_speed.yaml")
  assert 20 in np.unique(speed.data)
  with pytest.raises(ValueError, match=r"keeps 3 bits .* occupancy .*20 \(cost 51 -> 73\).*"
                     r"lossy=True"):
    J.grid_to_reports(speed, variant="rle", tiles=True)
  tiles = J.grid_to_reports(speed, variant="rle", tiles=True, lossy=True)
  msgs = J.decode_all(b"".join(J.encode_report(t.report) for t in tiles))
  assert all(m.quantised for m in msgs)
  back = J.reports_to_grid(msgs)
  assert np.all(back.data[speed.data == 20] == 29)    # an 80 % limit would become 71 %
  # Costs the levels carry exactly need no flag and come back unchanged.
  exact = OccupancyGrid.create(np.array([[0, 100, -1], [14, 100, 0]]), 0.1)
  msg = J.decode(J.encode_report(J.grid_to_report(exact, variant="rle", profile="design")))
  assert msg.quantised and np.array_equal(J.report_to_grid(msg).data, exact.data)
  lossless = J.decode(J.encode_report(J.grid_to_report(exact, profile="design")))
  assert not lossless.quantised
  with pytest.raises(ValueError, match="lossy must be True or False"):
    J.grid_to_report(exact, variant="rle", lossy="yes")


# --------------------------------------------------------------------------- tiles


def test_tiles_put_together_in_any_order_with_gaps_unknown():
  rng = np.random.default_rng(4)
  grid = OccupancyGrid.create(rng.integers(-1, 101, size=(300, 260)), 0.05, (-3.2, 1.45, 0.7))
  tiles = J.grid_to_reports(grid, tiles=lambda rows, cols: (100, 90))
  msgs = [J.decode(J.encode_report(t.report)) for t in tiles]
  back = J.reports_to_grid(msgs[::-1])
  assert np.array_equal(back.data, grid.data)
  assert back.resolution == 0.05 and back.origin == pytest.approx(grid.origin, abs=1e-9)
  gap = J.reports_to_grid(msgs[1:])         # tile 0 (lower-left) missing: unknown there
  assert np.all(gap.data[:100, :90] == -1) and np.array_equal(gap.data[100:], grid.data[100:])
  with pytest.raises(ValueError, match="overlaps an earlier tile"):
    J.reports_to_grid([msgs[0], msgs[0]])
  far = J.grid_to_report(OccupancyGrid.create(np.zeros((10, 10), np.int8), 0.05,
                                              (90000.0, 0.0, 0.7)), profile="iop")
  tracemalloc.start()
  try:
    with pytest.raises(ValueError, match="more than max_cells"):
      J.reports_to_grid([msgs[0], J.decode(J.encode_report(far))])
    _, peak = tracemalloc.get_traced_memory()
  finally:
    tracemalloc.stop()
  assert peak < 16 << 20
  other = J.grid_to_report(OccupancyGrid.create(np.zeros((10, 10), np.int8), 0.05,
                                                (-3.2, 1.45, 0.2)))
  with pytest.raises(ValueError, match="share one rotation"):
    J.reports_to_grid([msgs[0], other])
  shifted = J.grid_to_report(OccupancyGrid.create(np.zeros((10, 10), np.int8), 0.05,
                                                  (-3.2 + 0.02, 1.45, 0.7)))
  with pytest.raises(ValueError, match="not on a cell corner"):
    J.reports_to_grid([msgs[0], shifted])


# --------------------------------------------------------------------------- CLI


@pytest.mark.parametrize("yaml_path", SHIPPED_MAPS, ids=lambda p: p.name)
def test_readme_commands_run_on_the_shipped_maps(yaml_path, tmp_path, capsys, monkeypatch):
  monkeypatch.chdir(tmp_path)
  rel = os.path.relpath(yaml_path, tmp_path)
  code, out, err = _cli(["jaus", "encode", rel, "--out", "map.bin"], capsys)
  assert code == 0 and err == "", err
  assert "messages (tiles" in out
  code, out, err = _cli(["jaus", "decode", "map.bin", "--out", "decoded.yaml"], capsys)
  assert code == 0 and err == "", err
  grid, back = load_map(yaml_path), load_map(tmp_path / "decoded.yaml")
  assert np.array_equal(back.data, grid.data)
  assert back.resolution == grid.resolution and back.origin == pytest.approx(grid.origin)


@pytest.mark.parametrize("name", ["warehouse.yaml", "warehouse_keepout.yaml", "tb3_sandbox.yaml",
                                  "speed_mask.yaml"])
def test_cli_round_trips_whole_nav2_maps(nav2_maps, name, tmp_path, capsys):
  extra = ["--profile", "design", "--hex"] if name == "tb3_sandbox.yaml" else []
  out_bin, out_yaml = tmp_path / "m.bin", tmp_path / "m.yaml"
  code, _, err = _cli(["jaus", "encode", str(nav2_maps / name), "--out", str(out_bin), *extra],
                      capsys)
  assert code == 0, err
  code, out, err = _cli(["jaus", "decode", str(out_bin), "--out", str(out_yaml),
                         *[e for e in extra if e == "--hex"]], capsys)
  assert code == 0, err
  grid, back = load_map(nav2_maps / name), load_map(out_yaml)
  assert np.array_equal(back.data, grid.data)
  assert back.resolution == grid.resolution and back.origin == pytest.approx(grid.origin)


def test_cli_lossy_run_length(nav2_maps, tmp_path, capsys):
  speed, out_bin = nav2_maps / "warehouse_speed.yaml", tmp_path / "s.bin"
  code, _, err = _cli(["jaus", "encode", str(speed), "--out", str(out_bin), "--variant", "rle"],
                      capsys)
  assert code == 2 and "pass --lossy" in err and len(err.strip().splitlines()) == 1, err
  assert not out_bin.exists()
  code, out, err = _cli(["jaus", "encode", str(speed), "--out", str(out_bin), "--variant", "rle",
                         "--lossy"], capsys)
  assert code == 0 and "quantised" in out, err
  code, out, err = _cli(["jaus", "decode", str(out_bin), "--out", str(tmp_path / "s.yaml")],
                        capsys)
  assert code == 0 and "quantised" in out, err


def test_cli_bad_inputs_are_one_line_exit_2(tmp_path, capsys):
  grid = OccupancyGrid.create(np.zeros((30, 40), np.int8), 0.05)
  yaml_path, _ = save_map(grid, tmp_path / "m", mode="trinary")
  good = tmp_path / "ok.bin"
  assert _cli(["jaus", "encode", str(yaml_path), "--out", str(good)], capsys)[0] == 0
  fifo = tmp_path / "pipe"
  os.mkfifo(fifo)
  (tmp_path / "empty.bin").write_bytes(b"")
  out = str(tmp_path / "x.bin")
  enc = ["jaus", "encode", str(yaml_path), "--out", out]
  dec_out = ["--out", str(tmp_path / "x.yaml")]
  cases = [
      (["jaus", "encode", str(tmp_path / "nope.yaml"), "--out", out], "does not exist"),
      (["jaus", "encode", str(tmp_path), "--out", out], "directory"),
      (["jaus", "encode", str(fifo), "--out", out], "FIFO"),
      (["jaus", "encode", "/dev/zero", "--out", out], "device"),
      (["jaus", "encode", str(yaml_path), "--out", str(tmp_path)], "is a directory"),
      (["jaus", "encode", str(yaml_path), "--out", str(fifo)], "not a regular file"),
      (enc + ["--window", "-1", "0", "4", "4"], "--window"),
      (enc + ["--window", "0", "0", "0", "4"], "--window"),
      (enc + ["--window", "38", "0", "4", "4"], "--window"),
      (enc + ["--window", "0", "0", "1e3", "4"], "invalid int value"),
      (enc + ["--window", "0", "0", "4"], "expected 4 arguments"),
      (enc + ["--window", "0", "0", "1", "1"], "could not tell the cell size"),
      (enc + ["--profile", "jaus"], "invalid choice"),
      (enc + ["--variant", "attractiveness"], "invalid choice"),
      (enc + ["--mapping", "linear"], "invalid choice"),
      (enc + ["--axes", "enu"], "invalid choice"),
      (["jaus", "decode", str(tmp_path / "nope.bin"), *dec_out], "does not exist"),
      (["jaus", "decode", str(tmp_path), *dec_out], "directory"),
      (["jaus", "decode", str(fifo), *dec_out], "FIFO"),
      (["jaus", "decode", "/dev/zero", *dec_out], "device"),
      (["jaus", "decode", str(tmp_path / "empty.bin"), *dec_out], "no message"),
      (["jaus", "decode", str(good), "--out", str(fifo)], "not a regular file"),
      (["jaus", "decode", str(good), *dec_out, "--resolution", "nan"], "resolution"),
      (["jaus", "decode", str(good), *dec_out, "--mode", "png"], "invalid choice"),
      (["jaus", "frobnicate"], "invalid choice"),
  ]
  for args, match in cases:
    code, _, err = _refused_quickly_cli(args, capsys)
    assert code == 2, (args, err)
    assert match in err, (args, err)
    assert len(err.strip().splitlines()) == 1, (args, err)
  assert not Path(out).exists() and not (tmp_path / "x.yaml").exists()


def _refused_quickly_cli(args, capsys):
  result = []
  thread = threading.Thread(target=lambda: result.append(_cli(args, capsys)), daemon=True)
  thread.start()
  thread.join(20)
  assert not thread.is_alive(), f"blocked: {args}"
  return result[0]


# --------------------------------------------------------------------------- fuzz seeds


def test_fuzz_targets_accept_their_seeds():
  for seed in fuzz_jaus.file_seeds():
    grid = fuzz_jaus.run_file(seed.data)
    if seed.expected is not None:
      assert np.array_equal(grid.data, seed.expected())
  for seed in fuzz_jaus.seeds():
    fuzz_jaus.run_bytes(seed.data)


def test_package_is_host_only():
  import re
  for path in Path(J.__file__).parent.glob("*.py"):
    source = path.read_text(encoding="utf-8")
    assert not re.search(r"^\s*(import|from)\s+jax(\.|\s|$)", source, re.M), path
