"""The bag picture (`python -m sims.commands.bag_picture BAG OUT`) on hostile bag folders: a FIFO where a
file should be never blocks, a malformed metadata.yaml is one line, exit 2 for both.

The bags are written from a two-tick recording made by hand (no simulation), then spoiled.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sims.record import bag as bag_lib

pytest.importorskip("rosbags")
REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> Path:
  from sims.fleet.scenario import Scenario
  t, r = 2, 1
  rec = bag_lib.FleetRecording(
      time=np.arange(t) * 0.05, pose=np.zeros((t, r, 3), np.float32), cmd=np.zeros((t, r, 2), np.float32),
      speed_limit=np.zeros((t, r), np.float32), speed_cap=np.full((t, r), np.inf, np.float32), end_time=t * 0.05,
      end_pose=np.zeros((r, 3), np.float32), costmap_time=np.zeros((0,)), costmap=np.zeros((0, 0, 1, 1), np.uint8),
      costmap_origin=np.zeros((0, 0, 2), np.float32), costmap_resolution=np.zeros((0, 0), np.float32))
  path = tmp_path_factory.mktemp("bags") / "bag"
  bag_lib.write_fleet_bag(path, Scenario.default(), rec, max_speed=1.0)
  return path


def _copy(src: Path, dst: Path) -> Path:
  dst.mkdir()
  for p in src.iterdir():
    (dst / p.name).write_bytes(p.read_bytes())
  return dst


def _picture(argv, timeout=120):
  """The script in a subprocess (a blocking open would hang this process; the timeout catches it)."""
  env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
  return subprocess.run([sys.executable, "-m", "sims.commands.bag_picture", *map(str, argv)], capture_output=True,
                        text=True, timeout=timeout, env=env, cwd=REPO)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
def test_a_fifo_mcap_is_refused_without_blocking(written, tmp_path):
  bag = _copy(written, tmp_path / "fifo_bag")
  (bag / "bag.mcap").unlink()
  os.mkfifo(bag / "bag.mcap")
  try:
    done = _picture([bag, tmp_path / "out.png"], timeout=60)
  except subprocess.TimeoutExpired:
    pytest.fail("bag_picture blocked on a FIFO .mcap")
  lines = done.stderr.strip().splitlines()
  assert done.returncode == 2 and len(lines) == 1 and "is not a regular file" in lines[0], done.stderr


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
def test_fifo_metadata_and_fifo_output_are_refused(written, tmp_path):
  from sims.record import bag_view
  from sims.commands import bag_picture
  bag = _copy(written, tmp_path / "fifo_meta")
  (bag / "metadata.yaml").unlink()
  os.mkfifo(bag / "metadata.yaml")
  with pytest.raises(ValueError, match="metadata.yaml is not a regular file"):
    bag_view.check_bag_files(bag)
  os.mkfifo(tmp_path / "out.png")
  assert bag_picture.main([str(written), str(tmp_path / "out.png")]) == 2     # would block writing the PNG


@pytest.mark.parametrize("text, message", [
    ("rosbag2_bagfile_information:\n  version: [8\n  x: }\n", "is not valid YAML at line 3"),
    ("\tbad: [", "is not valid YAML"),
    ("- a\n- b\n", "is not rosbag2 metadata"),
    ("rosbag2_bagfile_information:\n  relative_file_paths: 7\n", "is not rosbag2 metadata"),
    ("rosbag2_bagfile_information:\n  relative_file_paths: [gone.mcap]\n", "gone.mcap does not exist"),
])
def test_malformed_metadata_is_one_line(written, tmp_path, capsys, text, message):
  from sims.commands import bag_picture
  bag = _copy(written, tmp_path / "bad")
  (bag / "metadata.yaml").write_text(text)
  assert bag_picture.main([str(bag), str(tmp_path / "out.png")]) == 2
  err = capsys.readouterr().err
  assert len(err.strip().splitlines()) == 1 and message in err, err
  assert not (tmp_path / "out.png").exists()


def test_the_unspoiled_bag_passes_the_checks(written):
  from sims.record import bag_view
  bag_view.check_bag_files(written)     # the files of a bag write_fleet_bag made
