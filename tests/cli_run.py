"""Runs a `jaxfilters` command in this process and returns (exit code, stdout, stderr).

`cli.main` may add to XLA_FLAGS (jaxfilters/xla_flags.py); the variable is put back afterwards so
that later subprocesses of the suite see the suite's own value.
"""

import contextlib
import io
import os

from jaxfilters import cli


def run_cli(argv) -> tuple[int, str, str]:
  out, err = io.StringIO(), io.StringIO()
  saved = os.environ.get("XLA_FLAGS")
  try:
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
      rc = cli.main(argv)
  finally:
    if saved is None:
      os.environ.pop("XLA_FLAGS", None)
    else:
      os.environ["XLA_FLAGS"] = saved
  return rc, out.getvalue(), err.getvalue()
