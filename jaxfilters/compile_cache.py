"""JAX's persistent compilation cache for the `jaxfilters` commands and for notebooks.

A program compiled once is written to a folder and read back by the next process, so a second
`jaxfilters fleet` or `rl eval`, or a notebook kernel restarted, skips XLA's compile (the keepout
filter's first call on a CPU compiles for seconds). The commands turn it on by default; in a
notebook, one line does:

    import jaxfilters.compile_cache; jaxfilters.compile_cache.enable()

Where the folder is, first match wins:

1. off: `--no-cache` on the command line, or the environment variable `JAXFILTERS_NO_CACHE`
   set to anything but "" or "0";
2. `JAX_COMPILATION_CACHE_DIR` already set (the user's or a test run's own choice): JAX's, left as is;
3. `JAXFILTERS_CACHE_DIR`;
4. `$XDG_CACHE_HOME/jaxfilters/xla`, else `~/.cache/jaxfilters/xla`.

A folder that cannot be made or written (read-only, a file in its place) turns the cache off for
the process without an error; entries that cannot be written later (a full disk) or read back
(a damaged file) only cost the compile they would have saved: JAX's warnings for them are kept
off the screen. The cache key is the program with its compile options, XLA flags and jaxlib
version, so an entry read back is the executable a compile would give.
"""

from __future__ import annotations

import os
import tempfile
import warnings
from pathlib import Path

NO_CACHE_ENV = "JAXFILTERS_NO_CACHE"
CACHE_DIR_ENV = "JAXFILTERS_CACHE_DIR"
# Programs that compile in less than this are not written: they cost more to store than to redo.
MIN_COMPILE_SECONDS = 0.5


def default_dir() -> Path:
  """The folder `enable()` uses without arguments (rules 3 and 4 above)."""
  if os.environ.get(CACHE_DIR_ENV):
    return Path(os.environ[CACHE_DIR_ENV]).expanduser()
  base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
  return Path(base) / "jaxfilters" / "xla"


def disabled_by_env() -> bool:
  """True when `JAXFILTERS_NO_CACHE` asks for no cache."""
  return os.environ.get(NO_CACHE_ENV, "").strip() not in ("", "0")


def _writable(folder: Path) -> bool:
  try:
    folder.mkdir(parents=True, exist_ok=True)
    if not folder.is_dir():
      return False
    with tempfile.NamedTemporaryFile(dir=folder, prefix=".probe-"):
      pass
    return True
  except OSError:
    return False


def enable(path: str | os.PathLike | None = None, *, disable: bool = False) -> Path | None:
  """Turns JAX's persistent compilation cache on for this process; returns the folder, or None if off.

  Call it before the first compile (JAX opens the cache at its first compile and keeps that folder).

  Args:
    path: the cache folder; None picks it by the rules in the module docstring.
    disable: True (a command's `--no-cache`) leaves the cache off.

  Returns:
    The folder in use, or None when the cache stays off (asked for, or the folder is not writable).
  """
  import jax  # noqa: PLC0415 - callers set XLA options before JAX starts

  if disable or disabled_by_env():
    return None
  if path is None and os.environ.get("JAX_COMPILATION_CACHE_DIR"):
    return Path(os.environ["JAX_COMPILATION_CACHE_DIR"])
  folder = Path(path).expanduser() if path is not None else default_dir()
  if not _writable(folder):
    return None
  jax.config.update("jax_compilation_cache_dir", str(folder))
  if not os.environ.get("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"):      # JAX's own setting wins
    jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_SECONDS)
  # A full disk or a damaged entry: the compile happens as without a cache; no warning per program.
  warnings.filterwarnings("ignore", message=r"Error (writing|reading) persistent compilation cache entry")
  return folder
