"""Runs a `jaxfilters` command in this process and returns (exit code, stdout, stderr)."""

import contextlib
import io

from jaxfilters import cli


def run_cli(argv) -> tuple[int, str, str]:
  out, err = io.StringIO(), io.StringIO()
  with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
    rc = cli.main(argv)
  return rc, out.getvalue(), err.getvalue()
