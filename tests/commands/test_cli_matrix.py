"""The CLI matrix: (command, input, exit code, message) for the inputs users and fuzzers tripped on.

Every bad input exits 2 with one line on stderr (after any warning lines) before anything is
simulated; options are applied or refused, never ignored. The last tests run one short simulation
(twice, the second from the compilation cache) to check that `--seconds` is honoured, that `fleet
--params` applies the params file and that a broken rule exits 3.
"""

import json
import os
import threading
from pathlib import Path

import pytest

from jaxfilters import cli

REPO = Path(__file__).resolve().parents[2]
ASSETS = REPO / "sims" / "assets"


def _files(tmp_path: Path) -> dict:
  """Inputs named in the matrix: {name: path}."""
  ok = tmp_path / "ok.csv"
  ok.write_text("x,y\n0.5,0.5\n")
  big = tmp_path / "big_field.csv"
  big.write_text("x,y\n1," + "1" * 140_000 + "\n")
  huge = tmp_path / "huge.csv"
  with open(huge, "wb") as f:            # sparse: over the 4 MiB cap without writing 5 MiB
    f.truncate(5 * 2 ** 20)
  binary = tmp_path / "binary.csv"
  binary.write_bytes(b"\x00\xff\xfe1,2\n")
  nul = tmp_path / "nul.csv"
  nul.write_text("1,2\x00\n")
  params = tmp_path / "p.yaml"
  params.write_text((ASSETS / "nav2_params.yaml").read_text())
  return {"ok": ok, "big_field": big, "huge": huge, "binary": binary, "nul": nul, "dir": tmp_path,
          "dev_zero": "/dev/zero", "keepout": ASSETS / "default_keepout.yaml", "speed": ASSETS / "default_speed.yaml",
          "map": ASSETS / "default_map.yaml", "params": ASSETS / "nav2_params.yaml", "out": tmp_path / "out"}


# (command and arguments with {name} placeholders, exit code, a fragment of the one error line)
MATRIX = [
    # query: pose files
    ("query --keepout {keepout} --poses {big_field}", 2, "big_field.csv line 2: not CSV (field larger"),
    ("query --keepout {keepout} --poses {dev_zero}", 2, "--poses /dev/zero: not a regular file"),
    ("query --keepout {keepout} --poses {dir}", 2, "not a regular file"),
    ("query --keepout {keepout} --poses {huge}", 2, "at most 4194304 are read"),
    ("query --keepout {keepout} --poses {binary}", 2, "not UTF-8 text"),
    ("query --keepout {keepout} --poses {nul}", 2, "nul.csv line 1: '2\\x00' is not a number"),
    # query: speed info
    ("query --speed {speed} --speed-multiplier 3e38 --poses {ok}", 2, "--speed-base/--speed-multiplier: "),
    ("query --speed {speed} --speed-base=-3e38 --speed-multiplier 1e38 --poses {ok}", 2, "must stay finite"),
    ("query --speed {speed} --speed-type 2.5 --poses {ok}", 2, "--speed-type must be 1 (percent) or 2"),
    # fleet: options that the built-in warehouse would ignore
    ("fleet --speed-type 2 --speed-base 0.2 --speed-multiplier 0 --out {out}", 2, "--speed-type needs --speed M.yaml"),
    ("fleet --speed-multiplier 0 --out {out}", 2, "--speed-multiplier needs --speed M.yaml"),
    ("fleet --mask a=b.yaml --out {out}", 2, "--mask needs --params"),
    ("fleet --set A=1 --out {out}", 2, "--set needs --params"),
    ("fleet --costmap local_costmap --out {out}", 2, "--costmap needs --params"),
    # fleet: values found wrong only after simulating
    ("fleet --record-robots 0 --out {out}", 2, "argument --record-robots: must lie in [1, 1,024]; got 0"),
    ("fleet --map {map} --keepout {keepout} --speed {speed} --speed-multiplier 3e38 --out {out}", 2,
     "--speed-base/--speed-multiplier: "),
    ("fleet --map {map} --keepout {keepout} --speed {speed} --speed-type 3 --out {out}", 2, "--speed-type must be 1"),
    # fleet --params
    ("fleet --params {params} --out {out}", 2, "--params needs --map M.yaml"),
    ("fleet --map {map} --params {params} --keepout {keepout} --out {out}", 2, "--keepout cannot be combined with --params"),
    ("fleet --map {map} --params {params} --speed-base 1 --out {out}", 2, "--speed-base cannot be combined with --params"),
    ("fleet --map {map} --params {params} --costmap local_costmap --out {out}", 2, "local_costmap"),
    ("fleet --map {map} --params {params} --mask nosuch=x.yaml --out {out}", 2, "nosuch"),
    ("fleet --map {map} --params {nosuch} --out {out}", 2, "--params"),
]


@pytest.mark.parametrize("argv, code, fragment", MATRIX, ids=[m[0] for m in MATRIX])
def test_cli_matrix(argv, code, fragment, tmp_path, capsys):
  files = _files(tmp_path)
  files["nosuch"] = tmp_path / "nosuch.yaml"
  args = [a.format(**files) for a in argv.split()]
  rc = cli.main(args)
  out, err = capsys.readouterr()
  lines = [line for line in err.splitlines() if line.strip()]
  errors = [line for line in lines if ": warning: " not in line]
  assert rc == code, (rc, err)
  assert len(errors) == 1 and fragment in errors[0], err
  assert "Traceback" not in err and "simulated" not in err and out == "", err


def test_query_poses_fifo_is_refused_without_blocking(tmp_path, capsys):
  fifo = tmp_path / "poses.fifo"
  os.mkfifo(fifo)
  result = {}
  worker = threading.Thread(target=lambda: result.setdefault(
      "rc", cli.main(["query", "--keepout", str(ASSETS / "default_keepout.yaml"), "--poses", str(fifo)])),
      daemon=True)
  worker.start()
  worker.join(60)
  if worker.is_alive():                  # release the blocked reader before failing
    fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
    os.close(fd)
    worker.join(10)
  assert result.get("rc") == 2, "query --poses FIFO blocked or did not exit 2"
  assert "not a regular file" in capsys.readouterr().err


def test_help_texts_have_examples_and_exit_codes(capsys):
  for command in ("fleet", "query"):
    assert cli.main([command, "--help"]) == 0
    text = capsys.readouterr().out
    assert "examples:" in text and "exit codes:" in text and f"jaxfilters {command} --" in text, command
  assert cli.main(["bench", "--help"]) == 0
  text = capsys.readouterr().out
  assert "usage: jaxfilters bench" in text and "python -m benchmarks [" not in text
  assert "examples:" in text and "exit codes:" in text


def test_query_and_fleet_share_speed_defaults(tmp_path, capsys):
  """`query --speed M.yaml` and `fleet --speed M.yaml` read the same mask with the same info."""
  poses = tmp_path / "F.csv"
  poses.write_text("0.5,0.5\n")
  assert cli.main(["query", "--speed", str(ASSETS / "default_speed.yaml"), "--poses", str(poses)]) == 0
  row = json.loads(capsys.readouterr().out)
  from sims.fleet.scenario import Scenario
  sc = Scenario.load(ASSETS / "default_map.yaml", ASSETS / "default_keepout.yaml", ASSETS / "default_speed.yaml",
                     speed_type=cli.SPEED_TYPE_DEFAULT, speed_base=cli.SPEED_BASE_DEFAULT,
                     speed_multiplier=cli.SPEED_MULTIPLIER_DEFAULT)
  default = Scenario.default()
  assert (sc.speed_type, sc.speed_base, sc.speed_multiplier) == (
      default.speed_type, default.speed_base, default.speed_multiplier) == (1, 100.0, -1.0)
  assert row["speed_limit"] == 50.0 and row["speed_limit_type"] == "percent"


# The short simulations below all run this fleet, so they compile its two chunk programs once (the
# session's compilation cache, tests/conftest.py, serves the later runs).
SHORT_FLEET = ["fleet", "--robots", "2", "--seconds", "0.65", "--chunk-seconds", "0.4", "--no-cache",
               "--map", str(ASSETS / "default_map.yaml"), "--params", str(ASSETS / "nav2_params.yaml")]


@pytest.mark.slow
def test_fleet_params_and_exact_seconds(tmp_path, capsys):
  """`fleet --params` applies the params file; --seconds 0.65 is 3 steps (said), in chunks of 2 + 1."""
  out = tmp_path / "o"
  rc = cli.main([*SHORT_FLEET, "--out", str(out)])
  err = capsys.readouterr().err
  assert rc == 0, err
  assert "note: --seconds 0.65 is not a whole number of 0.2 s env steps; simulating 3 steps (0.6 s)" in err
  summary = json.loads((out / "summary.json").read_text())
  assert summary["fleet"]["seconds"] == pytest.approx(0.6)
  assert summary["scenario"]["params"] == str(ASSETS / "nav2_params.yaml")
  assert summary["scenario"]["speed_filter"] == {"type": 1, "base": 100.0, "multiplier": -1.0}


def test_rule_violation_exit_code_is_3(monkeypatch, tmp_path):
  from sims.fleet import metrics
  real = metrics.summarize
  def violated(*a, **k):
    s = real(*a, **k)
    s["fleet"]["keepout_entries"] = 1
    return s
  monkeypatch.setattr(metrics, "summarize", violated)
  rc = cli.main([*SHORT_FLEET, "--out", str(tmp_path / "v")])
  assert rc == cli.EXIT_VIOLATION
