"""jaxfilters/compile_cache.py: the commands' persistent compilation cache, where it lives, how it is turned
off, and what happens when its folder cannot be written or its entries are damaged."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from jaxfilters import compile_cache

ROOT = Path(__file__).resolve().parents[2]


def test_folder_rules(monkeypatch, tmp_path):
  for var in (compile_cache.CACHE_DIR_ENV, "XDG_CACHE_HOME"):
    monkeypatch.delenv(var, raising=False)
  assert compile_cache.default_dir() == Path.home() / ".cache" / "jaxfilters" / "xla"
  monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
  assert compile_cache.default_dir() == tmp_path / "xdg" / "jaxfilters" / "xla"
  monkeypatch.setenv(compile_cache.CACHE_DIR_ENV, str(tmp_path / "mine"))
  assert compile_cache.default_dir() == tmp_path / "mine"


@pytest.mark.parametrize("value, off", [("1", True), ("yes", True), ("0", False), ("", False)])
def test_environment_switch(monkeypatch, value, off):
  monkeypatch.setenv(compile_cache.NO_CACHE_ENV, value)
  assert compile_cache.disabled_by_env() is off


def test_off_and_unwritable_folders_leave_the_cache_off_without_an_error(monkeypatch, tmp_path):
  monkeypatch.delenv("JAX_COMPILATION_CACHE_DIR", raising=False)
  assert compile_cache.enable(tmp_path / "c", disable=True) is None
  monkeypatch.setenv(compile_cache.NO_CACHE_ENV, "1")
  assert compile_cache.enable(tmp_path / "c") is None
  monkeypatch.delenv(compile_cache.NO_CACHE_ENV)
  blocker = tmp_path / "file"
  blocker.write_text("not a folder")
  assert compile_cache.enable(blocker) is None                 # a file where the folder should be
  assert compile_cache.enable(blocker / "below") is None       # a folder that cannot be made
  assert not (tmp_path / "c").exists()


def _query(tmp_path, env_extra, *flags):
  mask = tmp_path / "keepout.yaml"
  if not mask.exists():
    (tmp_path / "keepout.pgm").write_bytes(b"P5\n4 4\n255\n" + bytes([0, 0, 254, 254] * 4))
    mask.write_text("image: keepout.pgm\nresolution: 0.5\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n"
                    "occupied_thresh: 0.65\nfree_thresh: 0.196\nmode: trinary\n")
    (tmp_path / "poses.csv").write_text("0.2,0.2,0\n1.7,0.2,0\n")
  env = {k: v for k, v in os.environ.items() if k not in ("JAX_COMPILATION_CACHE_DIR", compile_cache.NO_CACHE_ENV)}
  env.update(PYTHONPATH=str(ROOT), JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0", **env_extra)
  return subprocess.run([sys.executable, "-m", "jaxfilters.cli", "query", "--keepout", str(mask),
                         "--poses", str(tmp_path / "poses.csv"), *flags],
                        capture_output=True, text=True, timeout=300, env=env, cwd=tmp_path)


def test_commands_write_the_cache_by_default_and_not_with_no_cache(tmp_path):
  cache = tmp_path / "cache"
  off = _query(tmp_path, {compile_cache.CACHE_DIR_ENV: str(cache)}, "--no-cache")
  assert off.returncode == 0, off.stderr
  assert not cache.exists() or not any(cache.iterdir())
  on = _query(tmp_path, {compile_cache.CACHE_DIR_ENV: str(cache)})
  assert on.returncode == 0, on.stderr
  entries = [p for p in cache.iterdir() if not p.name.startswith(".")]
  assert entries, "the first run wrote no cache entry"
  assert on.stdout == off.stdout
  # Damaged entries: the next run compiles again, answers the same and prints no cache warning.
  for p in entries:
    if p.is_file():
      p.write_bytes(b"\0garbage")
  again = _query(tmp_path, {compile_cache.CACHE_DIR_ENV: str(cache)})
  assert again.returncode == 0 and again.stdout == on.stdout, again.stderr
  assert "persistent compilation cache" not in again.stderr
