"""The `jaxfilters` command line.

    jaxfilters --version
    jaxfilters COMMAND --help

Commands come from two places: the library's own (`query`, `jaus`, listed in
`_BUILTIN`) and any installed package that registers a function under the
entry-point group `jaxfilters.commands` (the simulator registers `fleet` and
`bench` from `sims.cli`; the library never imports the simulator). Each
registered function receives argparse's subparsers object, adds its parser
and sets `func` (a callable `args -> int`) as a default; a command that passes
unknown options through to another program also sets `passthrough` to the name
of the attribute that receives them.

Exit codes, the same for every command:

  0  success
  1  internal error (a bug: one line on stderr; JAXFILTERS_DEBUG=1 shows the traceback)
  2  usage error: a bad option value, or an input file that is missing or invalid
  3  the run finished but a robot broke a rule (keepout entry or speed violation)
"""

from __future__ import annotations

import argparse
import importlib
import importlib.metadata
import os
import sys
import traceback

from jaxfilters import _xla_flags
from jaxfilters._version import __version__

ENTRY_POINT_GROUP = "jaxfilters.commands"
EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_USAGE = 2
EXIT_VIOLATION = 3

# name -> "module:function" of the library's own commands (registered in this order).
_BUILTIN: dict[str, str] = {}


class CliError(Exception):
  """A usage error: a bad option value or input file. Printed as one line, exit code 2."""


class ArgumentParser(argparse.ArgumentParser):
  """argparse with one-line errors (no usage dump) and exit code 2."""

  def error(self, message: str):
    self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _registrars():
  """Yields (name, register function) for the built-in and the entry-point commands."""
  seen = set()
  for name, target in _BUILTIN.items():
    module, _, attr = target.partition(":")
    seen.add(name)
    yield name, getattr(importlib.import_module(module), attr)
  try:
    eps = importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)
  except Exception:  # noqa: BLE001 - broken metadata of another package must not break the CLI
    eps = ()
  for ep in sorted(eps, key=lambda e: e.name):
    if ep.name in seen:
      continue
    seen.add(ep.name)
    try:
      yield ep.name, ep.load()
    except Exception as e:  # noqa: BLE001
      print(f"jaxfilters: warning: command {ep.name!r} from {ep.value} could not be loaded "
            f"({type(e).__name__}: {e})", file=sys.stderr)


def build_parser() -> ArgumentParser:
  """The top-level parser with every registered command."""
  parser = ArgumentParser(prog="jaxfilters",
                          description="Nav2 costmap filters as batched JAX functions.",
                          epilog="exit codes: 0 ok, 1 internal error, 2 usage error (bad option or "
                          "input file), 3 a robot broke a rule")
  parser.add_argument("--version", action="version", version=f"jaxfilters {__version__}")
  sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND",
                              parser_class=ArgumentParser)
  for _, register in _registrars():
    register(sub)
  return parser


def main(argv=None) -> int:
  """Entry point of the `jaxfilters` console script; returns the exit code."""
  argv = list(sys.argv[1:] if argv is None else argv)
  _xla_flags.use_fast_cpu_compile()   # before any JAX backend starts
  parser = build_parser()
  try:
    args, extra = parser.parse_known_args(argv)
    if extra:
      if not getattr(args, "passthrough", None):
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
      setattr(args, args.passthrough, list(getattr(args, args.passthrough, None) or []) + extra)
  except SystemExit as e:          # --help, --version (0) and argparse usage errors (2)
    return int(e.code or 0) if not isinstance(e.code, str) else EXIT_USAGE
  try:
    return int(args.func(args) or 0)
  except CliError as e:
    text = "; ".join(line.strip() for line in str(e).splitlines() if line.strip())
    print(f"jaxfilters {args.command}: error: {text[:500]}", file=sys.stderr)
    return EXIT_USAGE
  except KeyboardInterrupt:
    print(f"jaxfilters {args.command}: interrupted", file=sys.stderr)
    return 130
  except Exception as e:  # noqa: BLE001 - one line, not a traceback; the bug is still reported
    if os.environ.get("JAXFILTERS_DEBUG"):
      traceback.print_exc()
    msg = str(e).splitlines()[0] if str(e) else ""
    print(f"jaxfilters {args.command}: internal error: {type(e).__name__}: {msg[:300]} "
          "(set JAXFILTERS_DEBUG=1 for the traceback)", file=sys.stderr)
    return EXIT_INTERNAL


if __name__ == "__main__":
  # Run the imported module's main, not this __main__ copy: commands raise
  # jaxfilters.cli.CliError, which must be the class main() catches.
  from jaxfilters.cli import main as _main
  sys.exit(_main())
