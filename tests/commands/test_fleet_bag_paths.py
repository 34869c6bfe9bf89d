"""`jaxfilters fleet --bag DIR [--overwrite]`: only a bag this tool wrote is ever replaced, and every
--bag / --out path problem is refused (exit 2, one line) before anything is simulated.

The refusals run in this process through `jaxfilters.cli.main` and stop before the simulator is
imported, so no case compiles anything. The library half writes a bag from a two-tick recording
made by hand (no simulation) and replaces it.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from jaxfilters import cli
from sims.record import bag as bag_lib

pytest.importorskip("rosbags")


def _tree(root: Path) -> dict[str, bytes | str]:
  """Every entry under root: file bytes, 'dir', or 'link -> target' (what a refusal must leave as it was)."""
  out = {}
  for dirpath, dirnames, filenames in os.walk(root):
    for name in dirnames + filenames:
      p = Path(dirpath) / name
      rel = str(p.relative_to(root))
      if p.is_symlink():
        out[rel] = f"link -> {os.readlink(p)}"
      elif p.is_dir():
        out[rel] = "dir"
      else:
        out[rel] = p.read_bytes()
  return out


@pytest.fixture
def places(tmp_path, monkeypatch):
  """The user's folders a careless --bag could name; the test runs in tmp_path/work."""
  thesis = tmp_path / "thesis"
  (thesis / "thesis.mcap").mkdir(parents=True)             # a folder named like a bag file, with the user's work
  (thesis / "thesis.mcap" / "chapter1.tex").write_text("years of work")
  (thesis / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
  meta = tmp_path / "meta"                                  # only the user's own metadata.yaml
  meta.mkdir()
  (meta / "metadata.yaml").write_text("author: me\n")
  (tmp_path / "empty").mkdir()
  (tmp_path / "link").symlink_to(tmp_path / "empty", target_is_directory=True)
  (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
  fake = tmp_path / "fake"                                  # a bag's file names, and a marker we did not write
  fake.mkdir()
  (fake / "metadata.yaml").write_text("x")
  (fake / "fake.mcap").write_text("x")
  (fake / bag_lib.MARKER_NAME).write_text("not ours\nmetadata.yaml\nfake.mcap\n")
  ours_plus = tmp_path / "ours_plus"                        # our marker, plus a file the user added
  ours_plus.mkdir()
  (ours_plus / "metadata.yaml").write_text("x")
  (ours_plus / "ours_plus.mcap").write_text("x")
  (ours_plus / bag_lib.MARKER_NAME).write_text(f"{bag_lib.MARKER_HEADER}\nmetadata.yaml\nours_plus.mcap\n")
  (ours_plus / "notes.txt").write_text("mine")
  ours_link = tmp_path / "ours_link"                        # our marker, but the .mcap is a link to the user's file
  ours_link.mkdir()
  (ours_link / "metadata.yaml").write_text("x")
  (ours_link / "ours_link.mcap").symlink_to(tmp_path / "thesis" / "thesis.mcap" / "chapter1.tex")
  (ours_link / bag_lib.MARKER_NAME).write_text(f"{bag_lib.MARKER_HEADER}\nmetadata.yaml\nours_link.mcap\n")
  work = tmp_path / "work"
  work.mkdir()
  monkeypatch.chdir(work)
  return tmp_path


CASES = [
    # --overwrite never removes what this tool did not write
    (["--bag", "{tmp}/thesis", "--overwrite"], "no .jaxfilters_fleet_bag file"),
    (["--bag", "{tmp}/meta", "--overwrite"], "no .jaxfilters_fleet_bag file"),
    (["--bag", "{tmp}/fake", "--overwrite"], "is not one this tool writes"),
    (["--bag", "{tmp}/ours_plus", "--overwrite"], "it holds 'notes.txt'"),
    (["--bag", "{tmp}/ours_link", "--overwrite"], "'ours_link.mcap' is not a regular file"),
    (["--bag", "{tmp}/thesis"], "folder is not empty"),
    # paths that were found wrong only after the whole simulation
    (["--bag", "{tmp}/link"], "is a symbolic link"),
    (["--bag", "{tmp}/dangling"], "is a symbolic link"),
    (["--bag", "{tmp}/X", "--out", "{tmp}/X"], "must be separate folders"),
    (["--bag", "{tmp}/X", "--out", "{tmp}/X/run"], "must be separate folders"),
    (["--bag", "{tmp}/X/run", "--out", "{tmp}/X"], "must be separate folders"),
    (["--bag", "{tmp}/X", "--out", "{tmp}/sub/../X"], "must be separate folders"),
    (["--bag", ""], "argument --bag: must name a path"),
    (["--bag", "."], "is the current folder or holds it"),
    (["--bag", ".."], "is the current folder or holds it"),
    (["--bag", "/"], "is the current folder or holds it"),
    (["--out", ""], "argument --out: must name a path"),
]


@pytest.mark.parametrize("extra, message", CASES, ids=[" ".join(c[0]) for c in CASES])
def test_bag_paths_are_refused_before_simulating_and_nothing_is_touched(places, capsys, extra, message):
  before = _tree(places)
  argv = ["fleet", "--robots", "2", "--steps", "1", "--out", str(places / "out")]
  rc = cli.main(argv + [a.replace("{tmp}", str(places)) for a in extra])
  err = capsys.readouterr().err
  assert rc == 2 and len(err.strip().splitlines()) == 1 and message in err, err
  assert _tree(places) == before                  # nothing created, removed or changed (no --out either)


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs Linux /proc")
def test_bag_where_no_folder_can_be_made_is_refused(places, capsys):
  rc = cli.main(["fleet", "--robots", "2", "--steps", "1", "--out", str(places / "out"), "--bag", "/proc/x"])
  err = capsys.readouterr().err
  assert rc == 2 and "--bag /proc/x: cannot create a folder in /proc" in err and len(err.splitlines()) == 1, err
  assert not (places / "out").exists()


@pytest.mark.parametrize("option, value", [("--robots", "6_4"), ("--robots", " 2 "), ("--robots", "\uff12"),
                                           ("--steps", "1_0"), ("--seed", "+1"), ("--bag-robots", "٣")])
def test_fleet_integer_options_take_plain_ascii_digits_only(tmp_path, capsys, option, value):
  rc = cli.main(["fleet", "--out", str(tmp_path / "out"), option, value])
  err = capsys.readouterr().err
  assert rc == 2 and f"argument {option}: invalid int value" in err and len(err.splitlines()) == 1, err


@pytest.mark.parametrize("option, value, bound", [("--robots", "1048577", "[1, 1,048,576]"),
                                                  ("--steps", "1000001", "[1, 1,000,000]"),
                                                  ("--robots-per-world", "1025", "[1, 1,024]")])
def test_fleet_sizes_are_bounded_in_the_parser_and_the_help_says_so(tmp_path, capsys, option, value, bound):
  rc = cli.main(["fleet", "--out", str(tmp_path / "out"), option, value])
  err = capsys.readouterr().err
  assert rc == 2 and f"argument {option}: must lie in {bound}" in err, err
  assert cli.main(["fleet", "--help"]) == 0
  assert bound.split(", ")[1].rstrip("]") in capsys.readouterr().out


def test_fleet_seconds_beyond_the_step_bound_are_refused(tmp_path, capsys):
  rc = cli.main(["fleet", "--out", str(tmp_path / "out"), "--seconds", "1e15"])
  err = capsys.readouterr().err
  assert rc == 2 and "--seconds must be at most 200,000" in err, err
  assert not (tmp_path / "out").exists()


# ----------------------------------------------------------------------------- the library: write, replace


def _recording(steps: int = 2, robots: int = 1) -> bag_lib.FleetRecording:
  """A two-tick recording made by hand (the bag writer's input; no simulation)."""
  t = steps
  return bag_lib.FleetRecording(
      time=np.arange(t) * 0.05, pose=np.zeros((t, robots, 3), np.float32), cmd=np.zeros((t, robots, 2), np.float32),
      speed_limit=np.zeros((t, robots), np.float32), speed_cap=np.full((t, robots), np.inf, np.float32),
      end_time=t * 0.05, end_pose=np.zeros((robots, 3), np.float32), costmap_time=np.zeros((0,)),
      costmap=np.zeros((0, 0, 1, 1), np.uint8), costmap_origin=np.zeros((0, 0, 2), np.float32),
      costmap_resolution=np.zeros((0, 0), np.float32))


@pytest.fixture(scope="module")
def scenario():
  from sims.fleet.scenario import Scenario
  return Scenario.default()


def test_a_written_bag_carries_the_marker_and_is_replaced_only_as_written(tmp_path, scenario):
  path = tmp_path / "bag"
  bag_lib.write_fleet_bag(path, scenario, _recording(), max_speed=1.0)
  names = sorted(os.listdir(path))
  assert names == sorted([bag_lib.MARKER_NAME, "metadata.yaml", "bag.mcap"])
  assert bag_lib.bag_files(path) == names
  lines = (path / bag_lib.MARKER_NAME).read_text().splitlines()
  assert lines[0] == bag_lib.MARKER_HEADER and sorted(lines[1:]) == ["bag.mcap", "metadata.yaml"]
  with pytest.raises(bag_lib.BagError, match="not empty"):
    bag_lib.write_fleet_bag(path, scenario, _recording(), max_speed=1.0)
  bag_lib.write_fleet_bag(path, scenario, _recording(3), max_speed=1.0, overwrite=True)   # ours: replaced
  from jaxfilters import ros
  assert len([m for m in ros.read_bag(path) if m.topic == "/robot_0/cmd_vel"]) == 3
  (path / "notes.txt").write_text("mine")                  # the user adds a file: never replaced again
  with pytest.raises(bag_lib.BagError, match="it holds 'notes.txt'"):
    bag_lib.write_fleet_bag(path, scenario, _recording(), max_speed=1.0, overwrite=True)
  assert (path / "notes.txt").read_text() == "mine" and (path / "bag.mcap").exists()


def test_remove_bag_removes_only_the_listed_files(tmp_path, scenario):
  path = tmp_path / "bag"
  bag_lib.write_fleet_bag(path, scenario, _recording(), max_speed=1.0)
  bag_lib.remove_bag(path)
  assert not path.exists()
  user = tmp_path / "user"
  user.mkdir()
  (user / "metadata.yaml").write_text("mine")
  with pytest.raises(bag_lib.BagError):
    bag_lib.remove_bag(user)
  assert (user / "metadata.yaml").read_text() == "mine"
