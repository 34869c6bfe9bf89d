"""`jaxfilters fleet --robot ROBOT.xml`: a bad robot file is one line and exit 2 before anything is
simulated; a good one runs in the fleet with its radius and drive in the summary."""

import json
from pathlib import Path

from jaxfilters import cli

REPO = Path(__file__).resolve().parents[2]
OMNI = REPO / "examples" / "robots" / "omni_base.xml"


def _bad_files(tmp: Path) -> list[tuple[Path, str]]:
  text = OMNI.read_text()
  cases = {
      "radius.xml": (text.replace('data="0.18"', 'data="0"'), "jaxfilters_radius"),
      "include.xml": (text.replace("<worldbody>", '<include file="x.xml"/><worldbody>'), "<include> is refused"),
      "broken.xml": (text[:300], "not well-formed XML"),
      "names.xml": (text.replace('name="vy"', 'name="lateral"'), "actuators must be"),
      "contacts.xml": (text.replace('<flag contact="disable"/>', ""), "contacts must be off"),
      "compile.xml": (text.replace("<worldbody>", "<bogus/><worldbody>"), "MuJoCo cannot compile it"),
  }
  out = []
  for name, (body, words) in cases.items():
    (tmp / name).write_text(body)
    out.append((tmp / name, words))
  big = tmp / "big.xml"
  big.write_bytes(b" " * ((1 << 20) + 1))
  return out + [(big, "at most 1048576 bytes"), (tmp, "not a regular file"), (tmp / "none.xml", "does not exist")]


def test_bad_robot_files_are_one_line_and_exit_2(tmp_path, capsys):
  for path, words in _bad_files(tmp_path):
    rc = cli.main(["fleet", "--robot", str(path), "--robots", "2", "--steps", "1", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == cli.EXIT_USAGE, (path, err)
    assert len(err) == 1, err
    assert "--robot" in err[0] and words in err[0] and "Traceback" not in err[0], err
    assert not (tmp_path / "o").exists(), "nothing is created before every option is checked"


def test_a_robot_the_fleet_cannot_hold_is_exit_2(tmp_path, capsys):
  """A radius within the file's bounds that the fleet's local costmap cannot cover: one line, exit 2."""
  path = tmp_path / "wide.xml"
  path.write_text(OMNI.read_text().replace('data="0.18"', 'data="1.5"'))
  rc = cli.main(["fleet", "--robot", str(path), "--robots", "2", "--steps", "1", "--out", str(tmp_path / "o")])
  err = capsys.readouterr().err.strip().splitlines()
  assert rc == cli.EXIT_USAGE and len(err) == 1 and "local_costmap_size" in err[0], err


def test_the_omni_base_runs_in_the_fleet(tmp_path, capsys):
  out = tmp_path / "o"
  rc = cli.main(["fleet", "--robot", str(OMNI), "--robots", "2", "--steps", "10", "--chunk-seconds", "1",
                 "--out", str(out)])
  captured = capsys.readouterr()
  assert rc == cli.EXIT_OK, captured.err[-2000:]
  summary = json.loads((out / "summary.json").read_text())
  assert summary["config"]["robot_radius_m"] == 0.18
  assert summary["config"]["robot"] == {"file": str(OMNI), "drive": "omni"}
  assert summary["fleet"]["keepout_entries"] == 0 and summary["fleet"]["speed_compliant"]
  assert summary["fleet"]["distance_m"] > 0.5
