"""`jaxfilters bench`: runs the benchmark harness (benchmarks/run.py) of a source checkout.

    jaxfilters bench --quick
    jaxfilters bench --help          # the harness's options
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import io
import sys
from pathlib import Path

from jaxfilters.cli import EXIT_INTERNAL, EXIT_OK, EXIT_USAGE, CliError

_HELP_HEADER = """\
jaxfilters bench: the throughput harness of a source checkout (benchmarks/run.py; the same as
`python -m benchmarks` there). Every option below passes through to it.

examples:
  jaxfilters bench --quick
  jaxfilters bench --quick --only speed,baseline_speed --json

exit codes: 0 ok, 1 the harness could not be imported or failed, 2 bad option or no checkout
"""


def harness_root() -> Path | None:
  """The checkout holding benchmarks/run.py beside the sims package, or None (a wheel install)."""
  import sims
  root = Path(sims.__file__).resolve().parent.parent
  return root if (root / "benchmarks" / "run.py").is_file() else None


def run_bench(args) -> int:
  """Runs benchmarks/run.py's main with the passed-through options.

  The harness is not installed with the package (pyproject.toml installs only
  jaxfilters and sims): it is found beside the sims package of a source
  checkout (an editable install or PYTHONPATH), else a one-line usage error.

  Args:
    args: the argparse namespace; `args.bench_args` holds the options passed through.

  Returns:
    The harness's exit code, or 1 if benchmarks/run.py cannot be imported.

  Raises:
    CliError: no benchmarks/ beside the sims package and none importable.
  """
  argv = list(getattr(args, "bench_args", []) or [])
  root = harness_root()
  if root is None and importlib.util.find_spec("benchmarks") is None:
    raise CliError("the benchmark harness (benchmarks/run.py) ships with the source checkout, not with "
                   "the installed package; run `jaxfilters bench` from an editable install of a checkout "
                   "(pip install -e .) or `python -m benchmarks` in one")
  if root is not None and str(root) not in sys.path:
    sys.path.insert(0, str(root))     # benchmarks is a checkout folder, not an installed package
  try:
    from benchmarks import run as bench_run
  except ImportError as e:
    print(f"jaxfilters bench: the benchmark harness benchmarks/run.py could not be imported ({e}); "
          "run from a checkout that has benchmarks/run.py", file=sys.stderr)
    return EXIT_INTERNAL
  if not hasattr(bench_run, "main"):
    print("jaxfilters bench: benchmarks/run.py has no main(argv)", file=sys.stderr)
    return EXIT_INTERNAL
  if "-h" in argv or "--help" in argv:
    # The harness's parser names itself `python -m benchmarks`: show its options under this command's name.
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.suppress(SystemExit):
      bench_run.main(["--help"])
    sys.stdout.write(_HELP_HEADER + "\n" + buf.getvalue().replace("python -m benchmarks", "jaxfilters bench"))
    return EXIT_OK
  try:
    return bench_run.main(argv) or 0
  except SystemExit as e:            # the harness's own argparse errors (exit 2)
    return e.code if isinstance(e.code, int) else EXIT_USAGE


def register_bench(sub) -> argparse.ArgumentParser:
  """Adds `jaxfilters bench` (options pass through to benchmarks/run.py).

  Args:
    sub: argparse's subparsers object.

  Returns:
    The `bench` parser (no --help of its own: `jaxfilters bench --help` shows the harness's options
    under the name `jaxfilters bench`, with examples and exit codes).
  """
  p = sub.add_parser("bench", help="run the benchmark harness (benchmarks/run.py); options pass through",
                     add_help=False)
  p.set_defaults(func=run_bench, passthrough="bench_args")
  return p


