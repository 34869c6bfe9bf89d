"""The command line: one-line errors naming the option or file, distinct exit codes, no traceback."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from jaxfilters import cli
from jaxfilters._version import __version__

REPO = Path(__file__).resolve().parents[2]


BAD_FLEET = [
    (["--seconds", "nan"], "--seconds"), (["--seconds", "0"], "--seconds"), (["--seconds", "-5"], "--seconds"),
    (["--seconds", "0.01"], "--seconds"), (["--steps", "0"], "--steps"), (["--seed", "-1"], "--seed"),
    (["--seed", str(2 ** 32)], "--seed"), (["--robots", "0"], "--robots"),
    (["--robots-per-world", "0"], "--robots-per-world"), (["--robots", "5", "--robots-per-world", "2"],
                                                         "--robots-per-world"),
    (["--chunk-seconds", "inf"], "--chunk-seconds"), (["--speed-base", "nan"], "--speed-base"),
    (["--record-robots", "-1"], "--record-robots"), (["--robots", "x"], "--robots"),
    (["--speed-type", "3"], "--speed-type"), (["--impl", "foo"], "--impl"), (["--map", "x.yaml"], "--map"),
    (["--map", "no.yaml", "--keepout", "no.yaml", "--speed", "no.yaml"], "no.yaml"),
]


@pytest.mark.parametrize("argv, names", BAD_FLEET, ids=lambda v: " ".join(v) if isinstance(v, list) else None)
def test_bad_fleet_arguments_are_usage_errors(argv, names, capsys, tmp_path):
  rc = cli.main(["fleet", "--out", str(tmp_path / "o"), *argv])
  err = capsys.readouterr().err.strip().splitlines()
  assert rc == cli.EXIT_USAGE
  assert len(err) == 1 and names in err[0] and "Traceback" not in err[0], err


def test_unwritable_out_fails_before_simulating(capsys, tmp_path):
  blocker = tmp_path / "file"
  blocker.write_text("x")
  rc = cli.main(["fleet", "--out", str(blocker / "sub"), "--seconds", "1"])
  err = capsys.readouterr().err
  assert rc == cli.EXIT_USAGE and "--out" in err and "simulated" not in err


def test_bad_map_file_is_a_usage_error(capsys, tmp_path, nav2_maps):
  bad = tmp_path / "bad.yaml"
  bad.write_text("image: [\n")
  rc = cli.main(["fleet", "--out", str(tmp_path / "o"), "--map", str(bad), "--keepout",
                 str(nav2_maps / "keepout_mask.yaml"), "--speed", str(nav2_maps / "speed_mask.yaml")])
  err = capsys.readouterr().err.strip().splitlines()
  assert rc == cli.EXIT_USAGE and len(err) == 1 and "bad.yaml" in err[0]


def test_mismatched_mask_resolution_is_a_usage_error(capsys, tmp_path, nav2_maps):
  rc = cli.main(["fleet", "--out", str(tmp_path / "o"), "--map", str(nav2_maps / "warehouse.yaml"), "--keepout",
                 str(nav2_maps / "keepout_mask.yaml"), "--speed", str(nav2_maps / "speed_mask.yaml")])
  err = capsys.readouterr().err
  assert rc == cli.EXIT_USAGE and "resolution" in err and "Traceback" not in err


def test_version_and_unknown_command(capsys):
  assert cli.main(["--version"]) == 0 and capsys.readouterr().out.strip() == f"jaxfilters {__version__}"
  assert cli.main(["nosuch"]) == cli.EXIT_USAGE
  assert "invalid choice: 'nosuch'" in capsys.readouterr().err


def test_internal_error_is_one_line_with_code_1(monkeypatch, capsys, tmp_path):
  from sims.fleet import env
  def boom(*a, **k):
    raise RuntimeError("simulated bug\nsecond line")
  monkeypatch.setattr(env.FleetEnv, "create", classmethod(lambda cls, *a, **k: boom()))
  rc = cli.main(["fleet", "--out", str(tmp_path / "o"), "--seconds", "1"])
  err = capsys.readouterr().err.strip().splitlines()
  assert rc == cli.EXIT_INTERNAL and "internal error: RuntimeError: simulated bug" in err[-1]
  assert "second line" not in err[-1] and not any("Traceback" in e for e in err)


def test_tb3_sandbox_with_nav2_filter_masks_runs(tmp_path, nav2_maps, capsys):
  """Nav2's own filter demo: sandbox map, keepout mask (mostly unknown) and speed mask."""
  out = tmp_path / "tb3"
  rc = cli.main(["fleet", "--robots", "4", "--seconds", "2", "--chunk-seconds", "2", "--out", str(out),
                 "--no-cache", "--map", str(nav2_maps / "tb3_sandbox.yaml"), "--keepout",
                 str(nav2_maps / "keepout_mask.yaml"), "--speed", str(nav2_maps / "speed_mask.yaml")])
  summary = json.loads((out / "summary.json").read_text())
  assert rc == cli.EXIT_OK
  assert summary["fleet"]["keepout_entries"] == 0 and summary["fleet"]["keepout_steps"] == 0


def test_console_script_exit_code_in_a_subprocess(tmp_path):
  proc = subprocess.run([sys.executable, "-m", "jaxfilters.cli", "fleet", "--seconds", "nan"],
                        capture_output=True, text=True, cwd=REPO, timeout=120)
  assert proc.returncode == 2
  lines = [l for l in proc.stderr.splitlines() if l.strip()]
  assert lines == ["jaxfilters fleet: error: --seconds must be a finite number > 0; got nan"], lines
