"""`jaxfilters query`: JSON lines at poses, from a Nav2 params file or from mask files; one-line errors."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from jaxfilters import cli
from reference import nav2 as reference

_KEYS = ["x", "y", "speed_limit", "speed_limit_type", "keepout_cost", "binary_state", "zone"]
_ROOT = Path(__file__).resolve().parents[2]


def _query(capsys, *argv):
  rc = cli.main(["query", *map(str, argv)])
  out, err = capsys.readouterr()
  return rc, [json.loads(line) for line in out.splitlines()], err


def _usage_error(capsys, *argv):
  """Runs a query that must fail: exit 2, nothing on stdout, one error line (after any warning lines)."""
  try:
    rc = cli.main(["query", *map(str, argv)])
  except SystemExit as e:  # argparse's own errors
    rc = e.code
  out, err = capsys.readouterr()
  assert rc == 2 and out == "", (rc, out, err)
  lines = err.splitlines()
  assert "Traceback" not in err and lines and ": error: " in lines[-1], err
  assert all(line.startswith("jaxfilters query: warning: ") for line in lines[:-1]), err
  return lines[-1]


def _bringup_args(maps):
  return ["--params", maps / "nav2_params.yaml",
          "--mask", f"keepout_filter_mask_server={maps / 'warehouse_keepout.yaml'}",
          "--mask", f"speed_filter_mask_server={maps / 'warehouse_speed.yaml'}"]


_ENABLE = ["--set", "KEEPOUT_ZONE_ENABLED=True", "--set", "SPEED_ZONE_ENABLED=True"]


def _warehouse_cells(maps, per_value=4, seed=0):
  """Cell centres (x, y) of the warehouse speed mask in each of its values 0, 20, 100, and those values."""
  from jaxfilters import load_map
  data = load_map(maps / "warehouse_speed.yaml").data
  rng = np.random.default_rng(seed)
  xy, values = [], []
  for value in (0, 20, 100):
    ys, xs = np.nonzero(data == value)
    for i in rng.choice(len(xs), per_value, replace=False):
      xy.append((round(-15.1 + (xs[i] + 0.5) * 0.03, 4), round(-25.0 + (ys[i] + 0.5) * 0.03, 4)))
      values.append(value)
  return xy, values


def test_done_when_check_warehouse_speed_limits(nav2_maps, tmp_path, capsys):
  xy, values = _warehouse_cells(nav2_maps)
  poses = tmp_path / "F.csv"
  poses.write_text("x,y,yaw\n" + "".join(f"{x},{y},0.5\n" for x, y in xy) + "40.0,40.0\n")
  rc, rows, err = _query(capsys, *_bringup_args(nav2_maps), *_ENABLE, "--poses", poses)
  assert rc == 0 and err == ""
  assert len(rows) == len(xy) + 1 and all(list(r) == _KEYS for r in rows)
  keep = np.asarray(Image.open(nav2_maps / "warehouse_keepout.pgm").convert("L"))[::-1]
  for row, (x, y), d in zip(rows, xy, values):
    assert (row["x"], row["y"]) == (x, y)
    assert row["speed_limit"] == (None if d in (0, 100) else 100.0 - d)
    assert row["speed_limit_type"] == "percent"
    # Trinary 0.65/0.1 keepout (docs/nav2_semantics.md §10.2): pixel <= 89 occupied (254), >= 230 free (0), else unknown.
    mx, my = int((x + 15.1) // 0.03), int((y + 25.0) // 0.03)
    g = int(keep[my, mx])
    assert row["keepout_cost"] == (254 if g <= 89 else 0 if g >= 230 else 255)
    assert row["binary_state"] is None and row["zone"] is None
  assert {r["speed_limit"] for r in rows} == {None, 80.0}
  assert rows[-1] == {"x": 40.0, "y": 40.0, "speed_limit": None, "speed_limit_type": "percent",
                      "keepout_cost": 255, "binary_state": None, "zone": None}


def test_params_mode_costmaps_placeholders_and_transform(nav2_maps, tmp_path, capsys):
  poses = tmp_path / "F.csv"
  poses.write_text("-7.675,-0.115\n")
  err = _usage_error(capsys, *_bringup_args(nav2_maps), "--poses", poses)
  assert "'KEEPOUT_ZONE_ENABLED'" in err and "--set KEEPOUT_ZONE_ENABLED=VALUE" in err
  err = _usage_error(capsys, "--params", nav2_maps / "nav2_params.yaml", *_ENABLE, "--poses", poses)
  assert "keepout_filter_mask_server" in err and "--mask keepout_filter_mask_server=MASK.yaml" in err
  err = _usage_error(capsys, *_bringup_args(nav2_maps), *_ENABLE, "--costmap", "local_costmap", "--poses", poses)
  assert "global_frame is 'odom' but masks are in 'map'" in err and "--transform X,Y,YAW" in err
  err = _usage_error(capsys, *_bringup_args(nav2_maps), *_ENABLE, "--transform", "0,0,0", "--poses", poses)
  assert "--transform: every enabled mask of global_costmap is in its global_frame 'map'" in err
  rc, rows, err = _query(capsys, *_bringup_args(nav2_maps), *_ENABLE, "--costmap", "local_costmap",
                         "--transform", "0,0,0", "--poses", poses)
  assert rc == 0 and rows[0]["keepout_cost"] == 254 and rows[0]["speed_limit_type"] is None
  assert "warning:" in err and "speed_filter_mask_server" in err and "SPEED_ZONE_ENABLED" in err
  # A disabled filter: warned on stderr, its columns null.
  rc, rows, err = _query(capsys, *_bringup_args(nav2_maps), "--set", "KEEPOUT_ZONE_ENABLED=False",
                         "--set", "SPEED_ZONE_ENABLED=True", "--poses", poses)
  assert rc == 0 and rows[0]["keepout_cost"] is None and rows[0]["speed_limit"] == 80.0
  assert "filter 'keepout_filter' is disabled" in err
  err = _usage_error(capsys, *_bringup_args(nav2_maps), *_ENABLE, "--keepout", "k.yaml", "--poses", poses)
  assert "--keepout cannot be combined with --params" in err
  assert "--mask must be NAME=VALUE" in _usage_error(capsys, *_bringup_args(nav2_maps), "--mask", "x",
                                                     "--poses", poses)
  assert "--set gives 'A' twice" in _usage_error(capsys, *_bringup_args(nav2_maps), "--set", "A=1", "--set",
                                                 "A=2", "--poses", poses)
  assert "invalid choice" in _usage_error(capsys, *_bringup_args(nav2_maps), "--costmap", "controller",
                                          "--poses", poses)


def _raw_mask(folder, name, data, res=1.0, origin=(0.0, 0.0)):
  data = np.asarray(data)
  Image.fromarray(np.where(data < 0, 255, data).astype(np.uint8)[::-1], mode="L").save(folder / f"{name}.png")
  (folder / f"{name}.yaml").write_text(
      f"image: {name}.png\nmode: raw\nresolution: {res}\norigin: [{origin[0]}, {origin[1]}, 0.0]\n"
      "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
  return folder / f"{name}.yaml"


_DATA = np.array([[0, 25, 75, -1], [100, 50, 120 - 120, 30]])  # row 0 = lowest y


def test_mask_files_mode_against_reference(tmp_path, capsys):
  m = _raw_mask(tmp_path, "m", _DATA)
  rng = np.random.default_rng(5)
  xy = np.round(np.stack([rng.uniform(-0.5, 4.5, 30), rng.uniform(-0.5, 2.5, 30)], 1), 3)
  xy[:8] = [(i % 4 + 0.5, i // 4 + 0.5) for i in range(8)]   # every cell centre
  poses = tmp_path / "F.csv"
  poses.write_text("\n".join(f"{x},{y}" for x, y in xy) + "\n\n")
  rc, rows, err = _query(capsys, "--keepout", m, "--speed", m, "--speed-base", "100", "--speed-multiplier", "-1",
                         "--binary", m, "--zone", m, "--poses", poses)
  assert rc == 0 and err == "" and len(rows) == len(xy)
  for row, (x, y) in zip(rows, xy):
    x32, y32 = np.float32(x), np.float32(y)
    cell = reference.world_to_map(x32, y32, 0.0, 0.0, 1.0, 4, 2)
    d = None if cell is None else int(_DATA[cell[1], cell[0]])
    lim, valid = reference.speed_limit_at(_DATA, (0.0, 0.0), 1.0, 1, 100.0, -1.0, x32, y32)
    assert row["speed_limit"] == (lim if valid and lim != 0 else None), (x, y)
    assert row["speed_limit_type"] == "percent"
    assert row["keepout_cost"] == (255 if d is None else reference.mask_cost(d))
    b = reference.BinaryRef()
    b.process(_DATA, (0.0, 0.0), 1.0, 0.0, 1.0, x32, y32)
    assert row["binary_state"] == b.state
    assert row["zone"] == (d if d is not None and d > 0 else 0)
  assert [r["keepout_cost"] for r in rows[:4]] == [0, 64, 191, 255]   # round half away: 25 -> 64, 75 -> 191
  assert [r["speed_limit"] for r in rows[:8]] == [None, 75.0, 25.0, None, None, 50.0, None, 70.0]
  rc, rows, _ = _query(capsys, "--speed", m, "--speed-type", "2", "--speed-base", "0", "--speed-multiplier", "0.01",
                         "--poses", poses)
  assert rows[1]["speed_limit_type"] == "absolute" and rows[1]["speed_limit"] == 0.25
  assert rows[0]["keepout_cost"] is None and rows[0]["speed_limit"] is None


def test_zone_id_without_a_state_is_an_error(tmp_path, capsys, nav2_maps):
  m = _raw_mask(tmp_path, "zones", [[0, 1, 7]])
  params = tmp_path / "p.yaml"
  params.write_text(
      "global_costmap:\n  global_costmap:\n    ros__parameters:\n      filters: [zone_filter]\n"
      "      zone_filter:\n        plugin: nav2_costmap_2d::ZoneParameterFilter\n"
      "        filter_info_topic: zone_info\n        states: [slow]\n        slow:\n          id: 1\n"
      "zone_info_server:\n  ros__parameters:\n    type: 4\n    filter_info_topic: zone_info\n"
      "    mask_topic: zone_mask\n"
      "zone_mask_server:\n  ros__parameters:\n    topic_name: zone_mask\n    yaml_filename: zones.yaml\n")
  poses = tmp_path / "F.csv"
  poses.write_text("0.5,0.5\n1.5,0.5\n")
  rc, rows, err = _query(capsys, "--params", params, "--poses", poses)
  assert rc == 0 and [r["zone"] for r in rows] == [0, 1] and rows[0]["keepout_cost"] is None
  poses.write_text("0.5,0.5\n1.5,0.5\n2.5,0.5\n")
  err = _usage_error(capsys, "--params", params, "--poses", poses)
  assert "F.csv line 3: the zone mask gives zone id 7 there, which 'zone_filter' does not configure" in err
  assert "configured ids: [1]" in err


@pytest.mark.parametrize("text,match", [
    ("x,y\n1,2\n1,b\n", "line 3: 'b' is not a number"),
    ("1,2,3,4\n", "line 1: expected x,y or x,y,yaw (2 or 3 numbers); got 4 fields"),
    ("1\n", "line 1: expected x,y or x,y,yaw (2 or 3 numbers); got 1 field"),
    ("1,2\nx,y\n", "line 2: 'x' is not a number"),
    ("1,nan\n", "line 1: x,y,yaw must be finite"),
    ("1e39,0\n", "line 1: x,y,yaw must fit float32"),
    ("0,1e-45\n", "line 1: x,y,yaw must be 0 or at least"),
    ("x,y\n\n", "no poses"),
])
def test_bad_pose_rows(tmp_path, capsys, text, match):
  m = _raw_mask(tmp_path, "m", _DATA)
  poses = tmp_path / "F.csv"
  poses.write_text(text)
  err = _usage_error(capsys, "--keepout", m, "--poses", poses)
  assert match in err and ("F.csv" in err)


@pytest.mark.parametrize("argv,match", [
    (["--poses", "F.csv"], "give --params P.yaml, or mask files"),
    (["--keepout", "{m}", "--costmap", "global_costmap", "--poses", "F.csv"], "--costmap needs --params"),
    (["--keepout", "{m}", "--set", "A=1", "--poses", "F.csv"], "--set needs --params"),
    (["--keepout", "{m}", "--speed-base", "1", "--poses", "F.csv"], "--speed-base needs --speed M.yaml"),
    (["--speed", "{m}", "--speed-type", "3", "--poses", "F.csv"], "--speed-type must be 1 (percent) or 2"),
    (["--speed", "{m}", "--speed-base", "fast", "--poses", "F.csv"], "--speed-base must be a number; got 'fast'"),
    (["--speed", "{m}", "--speed-multiplier", "inf", "--poses", "F.csv"], "--speed-multiplier must be finite"),
    (["--keepout", "{m}", "--poses", "missing.csv"], "--poses missing.csv: file does not exist"),
    (["--keepout", "nope.yaml", "--poses", "F.csv"], "--keepout: map YAML file nope.yaml does not exist"),
    (["--params", "nope.yaml", "--poses", "F.csv"], "params file nope.yaml does not exist"),
    (["--params", "{m}", "--poses", "F.csv"], "no global_costmap node"),
    (["--keepout", "{m}"], "the following arguments are required: --poses"),
])
def test_bad_options(tmp_path, capsys, monkeypatch, argv, match):
  monkeypatch.chdir(tmp_path)
  m = _raw_mask(tmp_path, "m", _DATA)
  (tmp_path / "F.csv").write_text("0.5,0.5\n")
  err = _usage_error(capsys, *[a.format(m=m) for a in argv])
  assert match in err, err


def test_python_m_entry_point_exit_codes(tmp_path):
  """`python -m jaxfilters.cli query`: results on stdout; a usage error is one line and exit 2."""
  m = _raw_mask(tmp_path, "m", _DATA)
  (tmp_path / "F.csv").write_text("1.5,0.5\n")
  env = {**os.environ, "PYTHONPATH": str(_ROOT)}
  ok = subprocess.run([sys.executable, "-m", "jaxfilters.cli", "query", "--keepout", str(m), "--poses",
                       str(tmp_path / "F.csv")], capture_output=True, text=True, env=env, timeout=120)
  assert ok.returncode == 0 and json.loads(ok.stdout)["keepout_cost"] == 64
  bad = subprocess.run([sys.executable, "-m", "jaxfilters.cli", "query", "--keepout", str(m), "--poses",
                        str(tmp_path / "missing.csv")], capture_output=True, text=True, env=env, timeout=120)
  assert bad.returncode == 2 and bad.stdout == ""
  assert bad.stderr.strip().splitlines()[-1].startswith("jaxfilters query: error: --poses")
  assert "Traceback" not in bad.stderr
