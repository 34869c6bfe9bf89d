"""Where a command's time goes in JAX: trace, lowering and XLA compile seconds per test file and per program.

    python -m benchmarks.compile_profile --log /tmp/complog -- python -m pytest -q -n 2 --dist loadfile tests
    python -m benchmarks.compile_profile --log /tmp/complog            # only sum an existing log

Runs the command with benchmarks/compile_log/ first on PYTHONPATH and JAXFILTERS_COMPILE_LOG set
(its sitecustomize.py logs every event of every process the command starts, with the pytest test
that ran it), then prints, per test file (or per command line outside pytest), the seconds of XLA
backend compile, tracing and lowering, and the programs that compiled longest with their count.
The figures are wall seconds inside each event: with two pytest workers on two cores they include
waiting for the other worker. The log folder must be empty or absent (the logs are summed).
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import subprocess
import sys
from pathlib import Path

LOG_TOOL = Path(__file__).resolve().parent / "compile_log"
COMPILE, TRACE, LOWER = "backend_compile_duration", "jaxpr_trace_duration", "jaxpr_to_mlir_module_duration"


FIELDS = {"test": str, "event": str, "fun": str, "s": (int, float)}


def read_log(folder: Path) -> list[dict]:
  """Every event line of the folder's *.jsonl files. Skipped: a line cut short by a killed process, and
  a line that is not one of the logger's events (another tool's .jsonl left in the folder)."""
  rows = []
  for path in sorted(folder.glob("*.jsonl")):
    for line in path.read_text(errors="replace").splitlines():
      try:
        row = json.loads(line)
      except json.JSONDecodeError:
        continue
      if isinstance(row, dict) and all(isinstance(row.get(k), t) for k, t in FIELDS.items()):
        rows.append(row)
  return rows


def test_file(test: str) -> str:
  """'tests/x.py::test_y[a] (call)' -> 'tests/x.py'; a command line is kept whole."""
  return test.split("::", 1)[0] if "::" in test else test


def summarise(rows: list[dict], top: int = 20) -> dict:
  """Per file: {compile, trace, lower} seconds; per program name: [count, seconds, longest]."""
  files = collections.defaultdict(lambda: {"compile": 0.0, "trace": 0.0, "lower": 0.0})
  programs = collections.defaultdict(lambda: [0, 0.0, 0.0])
  for r in rows:
    key = {COMPILE: "compile", TRACE: "trace", LOWER: "lower"}.get(r["event"])
    if key is None:
      continue
    files[test_file(r["test"])][key] += r["s"]
    if key == "compile":
      p = programs[r["fun"]]
      p[0] += 1
      p[1] += r["s"]
      p[2] = max(p[2], r["s"])
  by_file = dict(sorted(files.items(), key=lambda kv: -kv[1]["compile"]))
  by_program = dict(sorted(programs.items(), key=lambda kv: -kv[1][1])[:top])
  totals = {k: sum(f[k] for f in files.values()) for k in ("compile", "trace", "lower")}
  return {"files": by_file, "programs": by_program, "totals": totals}


def print_summary(s: dict, out=None) -> None:
  out = sys.stdout if out is None else out
  t = s["totals"]
  print(f"all: compile {t['compile']:.1f} s, trace {t['trace']:.1f} s, lower {t['lower']:.1f} s", file=out)
  print(f"{'compile s':>10} {'trace s':>8} {'lower s':>8}  file", file=out)
  for name, f in s["files"].items():
    print(f"{f['compile']:10.1f} {f['trace']:8.1f} {f['lower']:8.1f}  {name}", file=out)
  print(f"\n{'compiles':>8} {'seconds':>8} {'longest':>8}  program", file=out)
  for name, (n, sec, longest) in s["programs"].items():
    print(f"{n:8d} {sec:8.1f} {longest:8.1f}  {name}", file=out)


def main(argv=None) -> int:
  ap = argparse.ArgumentParser(prog="python -m benchmarks.compile_profile", description=__doc__.splitlines()[0])
  ap.add_argument("--log", type=Path, required=True, help="folder for the event logs (empty or absent)")
  ap.add_argument("--top", type=int, default=20, help="programs to list (default 20)")
  ap.add_argument("command", nargs=argparse.REMAINDER, help="-- then the command to profile")
  args = ap.parse_args(argv)
  command = args.command[1:] if args.command[:1] == ["--"] else args.command
  if command:
    if args.log.exists() and (not args.log.is_dir() or any(args.log.iterdir())):
      print(f"compile_profile: --log {args.log} must be an empty folder or absent", file=sys.stderr)
      return 2
    args.log.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, JAXFILTERS_COMPILE_LOG=str(args.log.resolve()),
               PYTHONPATH=os.pathsep.join([str(LOG_TOOL)] + [p for p in [os.environ.get("PYTHONPATH")] if p]))
    rc = subprocess.call(command, env=env)
    if rc:
      print(f"compile_profile: the command exited with {rc}; the summary covers what it logged", file=sys.stderr)
  elif not args.log.is_dir():
    print(f"compile_profile: --log {args.log} is not a folder (and no command was given)", file=sys.stderr)
    return 2
  print_summary(summarise(read_log(args.log), args.top))
  return 0


if __name__ == "__main__":
  sys.exit(main())
