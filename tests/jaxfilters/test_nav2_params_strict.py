"""jaxfilters.nav2.load_params on hostile params files: read as strictly as a map YAML.

Each case ends in a short `Nav2ParamsError` (a ValueError) naming the file and
the key, within a second or two, where a plain YAML reader recursed, exploded
or blocked. Also: the warnings where Nav2 logs an error about a filter's info
and carries on, from `Nav2Costmap.from_masks` as from the params import.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import jaxfilters as jf
from jaxfilters import nav2

ROOT = Path(__file__).resolve().parents[2]
ASSETS = ROOT / "sims" / "assets"
_BOMB = ('a: &a ["x","x","x","x","x","x","x","x","x"]\nb: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a]\n'
         'c: &c [*b,*b,*b,*b,*b,*b,*b,*b,*b]\nd: &d [*c,*c,*c,*c,*c,*c,*c,*c,*c]\n'
         'e: &e [*d,*d,*d,*d,*d,*d,*d,*d,*d]\nf: &f [*e,*e,*e,*e,*e,*e,*e,*e,*e]\n'
         'g: &g [*f,*f,*f,*f,*f,*f,*f,*f,*f]\n')


@pytest.fixture
def folder(tmp_path):
  """A copy of the shipped params file and its masks (relative yaml_filename)."""
  for name in ("nav2_params.yaml", "default_keepout.yaml", "default_keepout.pgm", "default_speed.yaml",
               "default_speed.pgm"):
    shutil.copy(ASSETS / name, tmp_path / name)
  return tmp_path


def _text(folder) -> str:
  """The shipped params file's text (the copy in `folder` is the one each test rewrites)."""
  return (ASSETS / "nav2_params.yaml").read_text()


def _fails_fast(path, match, **kw):
  start = time.perf_counter()
  with pytest.raises(nav2.Nav2ParamsError, match=match) as e:
    nav2.load_params(path, **kw)
  assert time.perf_counter() - start < 30.0   # a blow-up (alias expansion, deep recursion) takes far longer; not a speed test
  assert str(path) in str(e.value) and len(str(e.value)) <= 600
  return str(e.value)


def test_shipped_file_still_loads(folder):
  g = nav2.load_params(folder / "nav2_params.yaml").global_costmap
  assert [f.name for f in g.filters] == ["keepout_filter", "speed_filter"]


def test_deep_nesting_is_refused(folder):
  path = folder / "nav2_params.yaml"
  path.write_text(_text(folder) + "deep: " + "[" * 2000 + "]" * 2000 + "\n")
  _fails_fast(path, "nested deeper than 32 levels at 'deep")
  path.write_text(_text(folder) + "deep:\n" + "".join(" " * i + f"k{i}:\n" for i in range(1, 200)) + "\n")
  _fails_fast(path, "nested deeper than 32")


@pytest.mark.parametrize("extra", [
    "a: &a {b: *a}\n",                                  # a recursive alias
    _BOMB,                                              # 9**7 leaves in an unrelated key
    "g2:\n  ros__parameters:\n    " + _BOMB.replace("\n", "\n    "),   # and inside ros__parameters
])
def test_aliases_are_refused(folder, extra):
  path = folder / "nav2_params.yaml"
  path.write_text(_text(folder) + extra)
  _fails_fast(path, r"aliases \(\*name\) are not allowed")


def test_alias_bomb_as_base_is_refused_with_a_short_message(folder):
  path = folder / "nav2_params.yaml"
  path.write_text(_BOMB + _text(folder).replace("base: 100.0", "base: *g"))
  _fails_fast(path, "aliases")


def test_duplicate_key_is_refused_with_its_key_path(folder):
  path = folder / "nav2_params.yaml"
  path.write_text(_text(folder).replace("    base: 100.0\n", "    base: 100.0\n    base: 50.0\n"))
  message = _fails_fast(path, "duplicate key 'base'")
  assert "at 'speed_costmap_filter_info_server.ros__parameters.base' (line" in message


def test_fifo_and_devices_are_refused_at_once(tmp_path):
  fifo = tmp_path / "p.yaml"
  os.mkfifo(fifo)
  outcome = []

  def load():
    try:
      nav2.load_params(fifo)
    except Exception as e:  # noqa: BLE001 - the test looks at what came back
      outcome.append(e)

  thread = threading.Thread(target=load, daemon=True)
  thread.start()
  thread.join(5.0)
  if thread.is_alive():  # unblock the reader so the thread can end
    with open(fifo, "w") as f:
      f.write("x: 1\n")
    pytest.fail("load_params blocked on a FIFO")
  assert isinstance(outcome[0], nav2.Nav2ParamsError) and "a FIFO, not a regular file" in str(outcome[0])
  with pytest.raises(nav2.Nav2ParamsError, match="a device, not a regular file"):
    nav2.load_params("/dev/zero")


def test_size_cap(folder):
  path = folder / "nav2_params.yaml"
  path.write_text(_text(folder) + "#" * nav2.MAX_PARAMS_BYTES + "\n")
  _fails_fast(path, f"at most {nav2.MAX_PARAMS_BYTES} are allowed")


def test_deep_substitution_value(folder):
  path = folder / "nav2_params.yaml"
  path.write_text(_text(folder).replace("enabled: true", "enabled: KEEP_ON", 1))
  for value in ("[" * 3000 + "]" * 3000, "&a [*a]", "{a: 1, a: 2}"):
    message = _fails_fast(path, r"'keepout_filter.enabled' must be a bool.*from substitution 'KEEP_ON'",
                          substitutions={"KEEP_ON": value})
    assert len(message) < 400


def test_huge_numbers_and_long_names(folder):
  path = folder / "nav2_params.yaml"
  path.write_text(_text(folder).replace("base: 100.0", "base: 1" + "0" * 400))
  _fails_fast(path, "parameter 'base' must fit float32; got an integer of 1329 bits")
  path.write_text(_text(folder).replace("lethal_override_cost: 200", "lethal_override_cost: 1" + "0" * 400, 1))
  with pytest.warns(nav2.Nav2ParamsWarning, match="is clamped to"):
    k = nav2.load_params(path).global_costmap.keepout
  assert k.config.lethal_override_cost == 252
  path.write_text(_text(folder).replace("      global_frame: map\n", "      " + "x" * 300 + ": 1\n", 1))
  _fails_fast(path, "has 300 characters; at most 256")


def test_many_wildcards_stay_fast(folder):
  path = folder / "nav2_params.yaml"
  path.write_text(_text(folder) + "/" + "**/" * 60 + "global_costmap:\n  ros__parameters:\n    resolution: 0.1\n")
  start = time.perf_counter()
  nav2.load_params(path)
  assert time.perf_counter() - start < 30.0   # a blow-up (alias expansion, deep recursion) takes far longer; not a speed test


def test_bad_arguments(folder):
  path = folder / "nav2_params.yaml"
  with pytest.raises(nav2.Nav2ParamsError, match=r"masks\['keepout_filter_mask_server'\] must be a path"):
    nav2.load_params(path, masks={"keepout_filter_mask_server": 5})
  huge = [[0] * 1000] * 1000
  start = time.perf_counter()
  with pytest.raises(nav2.Nav2ParamsError, match="costmaps must name") as e:
    nav2.load_params(path, costmaps=huge)
  assert time.perf_counter() - start < 30.0 and len(str(e.value)) < 400   # a blow-up takes far longer
  assert issubclass(nav2.Nav2ParamsError, ValueError)


def test_cli_turns_a_params_error_into_one_line(folder, tmp_path):
  path = folder / "nav2_params.yaml"
  path.write_text(_text(folder) + "a: &a {b: *a}\n")
  poses = tmp_path / "poses.csv"
  poses.write_text("0,0,0\n")
  run = subprocess.run([sys.executable, "-m", "jaxfilters", "query", "--params", str(path), "--poses", str(poses)],
                       cwd=ROOT, capture_output=True, text=True, timeout=120)
  assert run.returncode == 2, run.stderr
  lines = run.stderr.strip().splitlines()
  assert len(lines) == 1 and "aliases" in lines[0] and str(path) in lines[0]


def test_readme_example_paths_load_from_the_repository_root(monkeypatch):
  monkeypatch.chdir(ROOT)
  params = jf.load_params("sims/assets/nav2_params.yaml",
                          masks={"keepout_filter_mask_server": "sims/assets/default_keepout.yaml"})
  assert params.global_costmap.keepout.mask_yaml == "sims/assets/default_keepout.yaml"


# --------------------------------------------------------------------------- Nav2's logged errors


def _grid():
  return jf.OccupancyGrid.create(np.array([[0, 30], [100, -1]]), 1.0, (0.0, 0.0))


@pytest.mark.parametrize("kind, info, match", [
    ("keepout", (0, 2.5, 1.0), "keepout mask's info sets base 2.5 / multiplier 1.0; KeepoutFilter ignores them"),
    ("keepout", (0, 0.0, 2.0), "KeepoutFilter ignores them .Nav2 logs an error"),
    ("speed", (0, 0.0, 1.0), "has type 0, not 1 .percent. or 2 .m/s.; SpeedFilter logs an error"),
    ("binary", (1, 0.0, 1.0), "has type 1, not 3; BinaryFilter logs an error"),
    ("zone", (4, 1.0, 1.0), "ZoneParameterFilter warns and ignores them"),
])
def test_from_masks_warns_where_nav2_logs_and_carries_on(kind, info, match):
  mask = jf.FilterMask.create(_grid(), jf.FilterInfo.create(*info))
  with pytest.warns(nav2.Nav2ParamsWarning, match=match):
    c = nav2.Nav2Costmap.from_masks(**{kind: mask})
  assert getattr(c, kind).mask is mask


def test_from_masks_says_nothing_for_usable_infos():
  import warnings
  with warnings.catch_warnings():
    warnings.simplefilter("error")
    nav2.Nav2Costmap.from_masks(keepout=jf.FilterMask.create(_grid(), jf.FilterInfo.create(0)),
                                speed=jf.FilterMask.create(_grid(), jf.FilterInfo.create(1, 100.0, -1.0)),
                                binary=jf.FilterMask.create(_grid(), jf.FilterInfo.create(3, 0.0, 2.0)),
                                zone=jf.FilterMask.create(_grid(), jf.FilterInfo.create(4)))


def test_params_binary_type_and_zone_base_warn(folder):
  path = folder / "nav2_params.yaml"
  path.write_text(_text(folder).replace("    type: 0\n", "    type: 0\n", 1).replace(
      "    base: 0.0\n    multiplier: 1.0\n", "    base: 0.0\n    multiplier: 3.0\n"))
  with pytest.warns(nav2.Nav2ParamsWarning, match="sets base 0.0 / multiplier 3.0; KeepoutFilter ignores them"):
    nav2.load_params(path)
