"""Fuzz the command line's option values and the bag folder check, in process, against oracles.

    python -m tests.fuzz.fuzz_cli_values --values 100000 --folders 100000 --seed 0

values: random texts (plain, signed, huge and out-of-range numbers; underscores, spaces, '+',
non-ASCII digits, exponents, hex, letters, empty) go through the `type` of every integer option
of `jaxfilters fleet`, `rl train`, `rl eval` and `jaus encode` (the parser's own function,
`jaxfilters.cli.int_type`) and of every path option (`path_type`), and are compared with an oracle
written from the rule: an integer is ASCII digits with an optional leading '-', at most 30
digits, within the option's bound; a path is any text that is not blank and has no NUL. One value
in ten also goes through a whole `parse_args` of its command, which must end in exit 2 with one
line or give the oracle's value. No integer option may use Python's `int` (it reads '6_4').

folders: a random walk over the states of one folder, each step adding, replacing or removing
one entry (the marker with good or spoiled text, metadata.yaml, .mcap files, the user's files
and folders, symbolic links, FIFOs), then `sims.record.bag.check_bag_dir(..., overwrite=True)` against
an oracle of the rule (accepted: empty, or the marker with this module's first line listing
metadata.yaml / .mcap names, and nothing but the marker and listed names, all regular files).
Every check must leave the folder as it was; at some accepted states `remove_bag` runs and must
remove exactly the folder, at some refused ones it must raise and touch nothing.

Prints the counts; exits 1 on the first disagreement (with the input).
"""

from __future__ import annotations

import argparse
import os
import random
import shutil
import stat
import sys
import tempfile
import time
from pathlib import Path

DIGITS = "0123456789"
ODD = ["_", " ", "\t", "\n", "+", "-", ".", "e", "E", "x", "\u00a0", "\uff10", "\uff15", "\u0663", "\u09e7",
       "\u07c0", "\u2070", "\u00b2", "a", "\x00", "/"]


def _int_oracle(text: str, low, high):
  body = text[1:] if text.startswith("-") else text
  if not body or any(c not in DIGITS for c in body) or len(body) > 30:
    return None
  value = int(text)
  if (low is not None and value < low) or (high is not None and value > high):
    return None
  return value


def random_value(rng: random.Random) -> str:
  kind = rng.randrange(8)
  if kind == 0:                                   # a plain integer of any size
    return str(rng.randrange(-10 ** rng.randrange(1, 40), 10 ** rng.randrange(1, 40)))
  if kind == 1:                                   # around a power of two (the bounds)
    return str(2 ** rng.randrange(0, 64) + rng.randrange(-2, 3))
  if kind == 2:                                   # digits with odd characters mixed in
    s = list(str(rng.randrange(10 ** 6)))
    for _ in range(rng.randrange(1, 3)):
      s.insert(rng.randrange(len(s) + 1), rng.choice(ODD))
    return "".join(s)
  if kind == 3:                                   # non-ASCII digits only
    return "".join(rng.choice("\uff10\uff11\uff12\u0660\u0661\u0966\u09e6\u0e51") for _ in range(rng.randrange(1, 4)))
  if kind == 4:                                   # leading zeros, signs
    return rng.choice(["", "-", "+", "--"]) + "0" * rng.randrange(5) + str(rng.randrange(1000))
  if kind == 5:
    return rng.choice(["", " ", "-", "0", "-0", "00", "1e3", "0x10", "2.0", "inf", "nan", "1_000", " 2 ", "1" * 31,
                       "1" * 30, "9" * 5000])
  if kind == 6:                                   # random printable / unicode text
    return "".join(chr(rng.randrange(32, 0x3000)) for _ in range(rng.randrange(0, 8)))
  return "".join(rng.choice(DIGITS + "".join(ODD)) for _ in range(rng.randrange(0, 12)))


def option_types(parser):
  """(command words, option, action) of every option of every (sub)command."""
  out = []

  def walk(p, words):
    for a in p._actions:                              # noqa: SLF001 - argparse keeps its actions there
      if isinstance(a, argparse._SubParsersAction):   # noqa: SLF001
        for name, sub in a.choices.items():
          walk(sub, words + [name])
      elif a.option_strings:
        out.append((words, a.option_strings[-1], a))
  walk(parser, [])
  return out


def fuzz_values(count: int, seed: int) -> dict:
  import contextlib
  import io
  from jaxfilters import cli
  parser = cli.build_parser()
  actions = option_types(parser)
  commands = {("fleet",), ("rl", "train"), ("rl", "eval"), ("jaus", "encode")}
  ints = [(w, o, a) for w, o, a in actions if getattr(a.type, "__name__", "") == "int" and tuple(w) in commands]
  paths = [(w, o, a) for w, o, a in actions if a.type is cli.path_type]
  plain = [(w, o) for w, o, a in actions if a.type is int]
  if plain:
    raise AssertionError(f"integer options that use Python's int (which reads '6_4'): {plain}")
  if len(ints) < 20 or len(paths) < 6:
    raise AssertionError(f"expected every size option to use int_type and every path path_type; got "
                         f"{[o for _, o, _ in ints]} and {[o for _, o, _ in paths]}")
  required = {("rl", "train"): ["--out", "o"], ("rl", "eval"): ["--policy", "p"], ("fleet",): [],
              ("jaus", "encode"): []}
  rng = random.Random(seed)
  n = parsed = accepted = 0
  for i in range(count):
    text = random_value(rng)
    for words, option, action in ints:
      want = _int_oracle(text, action.type.low, action.type.high)
      try:
        got = action.type(text)
      except argparse.ArgumentTypeError as e:
        got = None
        if "\n" in str(e):
          raise AssertionError(f"{option} {text!r}: a message of more than one line: {e}") from None
      if got != want or (got is not None and type(got) is not int):
        raise AssertionError(f"{' '.join(words)} {option} {text!r}: got {got!r}, the rule says {want!r}")
      n += 1
      accepted += got is not None
    for words, option, action in paths:
      want = bool(text.strip()) and "\x00" not in text
      try:
        got = action.type(text) is not None
      except argparse.ArgumentTypeError:
        got = False
      if got != want:
        raise AssertionError(f"{' '.join(words)} {option} {text!r}: accepted {got}, the rule says {want}")
      n += 1
    if i % 10 == 0 and not text.startswith("-"):      # a whole parse of one command with this value
      words, option, action = ints[rng.randrange(len(ints))]
      if action.nargs not in (None,):
        continue
      argv = [*words, *required[tuple(words)], option, text]
      err = io.StringIO()
      with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
          ns = parser.parse_args(argv)
          code = 0
        except SystemExit as e:
          code = e.code
      want = _int_oracle(text, action.type.low, action.type.high)
      if want is None:
        lines = err.getvalue().strip().splitlines()
        if code != 2 or len(lines) != 1:
          raise AssertionError(f"{argv!r}: exit {code}, stderr {err.getvalue()!r}; the rule says exit 2, one line")
      elif code != 0 or getattr(ns, action.dest) != want:
        raise AssertionError(f"{argv!r}: exit {code}; the rule says {want}")
      parsed += 1
  return {"values": count, "type_checks": n, "values_accepted": accepted, "whole_parses": parsed,
          "int_options": len(ints), "path_options": len(paths)}


# ----------------------------------------------------------------------------- bag folders

NAMES = ["marker", "metadata.yaml", "bag.mcap", "other.mcap", "notes.txt", "thesis.mcap", ".hidden", "run.db3"]
KINDS = ["absent", "regular", "regular", "regular", "symlink", "fifo", "dir"]


def _marker_text(rng: random.Random, header: str, present: list[str]) -> bytes:
  kind = rng.randrange(10)
  listed = [n for n in present if n in ("metadata.yaml", "bag.mcap", "other.mcap")] or ["metadata.yaml"]
  if kind < 5:                                       # what write_fleet_bag writes
    return ("\n".join([header, *listed]) + "\n").encode()
  return rng.choice([
      ("\n".join([header, *listed, "notes.txt"]) + "\n").encode(),        # lists a name it never writes
      ("\n".join([header, "../x.mcap"]) + "\n").encode(),
      ("\n".join([header + " ", *listed]) + "\n").encode(),
      ("\n".join(["not ours", *listed]) + "\n").encode(),
      (header + "\n").encode(),
      b"",
      b"\xff\xfe" + header.encode(),
      ("\n".join([header, *listed]) + "\n" + "x" * 5000).encode(),
      ("\n".join([header, "thesis.mcap", *listed]) + "\n").encode(),
      ("\n".join([header, ".mcap"]) + "\n").encode(),
  ])


def _bag_oracle(folder: Path, marker: str, header: str) -> bool:
  entries = os.listdir(folder)
  if not entries:
    return True
  m = folder / marker
  if marker not in entries or not stat.S_ISREG(os.lstat(m).st_mode):
    return False
  raw = m.read_bytes()
  if len(raw) > 4096:
    return False
  try:
    lines = raw.decode("utf-8").split("\n")
  except UnicodeDecodeError:
    return False
  if lines[0] != header:
    return False
  listed = {x for x in lines[1:] if x}
  if not listed or any(not (x == "metadata.yaml" or (x.endswith(".mcap") and x != ".mcap" and "/" not in x))
                       for x in listed):
    return False
  return all((e == marker or e in listed) and stat.S_ISREG(os.lstat(folder / e).st_mode) for e in entries)


def _snapshot(root: Path) -> list:
  """(path, type, size, mtime, inode) of every entry under root, two levels deep (all the walk makes)."""
  out = []
  stack = [(root, 0)]
  while stack:
    d, depth = stack.pop()
    with os.scandir(d) as it:
      for e in it:
        st = e.stat(follow_symlinks=False)
        out.append((e.path, stat.S_IFMT(st.st_mode), st.st_size, st.st_mtime_ns, st.st_ino))
        if depth < 2 and stat.S_ISDIR(st.st_mode):
          stack.append((e.path, depth + 1))
  return sorted(out)


def _remove(p: Path) -> None:
  if p.is_symlink() or (p.exists() and not p.is_dir()):
    p.unlink()
  elif p.is_dir():
    shutil.rmtree(p)


def fuzz_folders(count: int, seed: int) -> dict:
  from sims.record import bag as bag_lib
  rng = random.Random(seed)
  marker, header = bag_lib.MARKER_NAME, bag_lib.MARKER_HEADER
  root = Path(tempfile.mkdtemp(prefix="fuzz_bag_"))
  outside = root / "outside"
  outside.mkdir()
  (outside / "user.txt").write_text("the user's file")
  folder = root / "bag"
  folder.mkdir()
  cwd = os.getcwd()
  os.chdir(outside)
  checks = accepted = removed = refused_removals = 0
  try:
    for _ in range(count):
      if not folder.exists():
        folder.mkdir()
      r = rng.random()
      if r < 0.1:                                    # a bag as write_fleet_bag leaves it
        for e in os.listdir(folder):
          _remove(folder / e)
        (folder / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
        (folder / "bag.mcap").write_bytes(b"\x89MCAP0\r\n")
        (folder / marker).write_text(f"{header}\nbag.mcap\nmetadata.yaml\n")
      elif r < 0.12:                                 # an empty folder
        for e in os.listdir(folder):
          _remove(folder / e)
      name = rng.choice(NAMES)
      real = marker if name == "marker" else name
      p = folder / real
      kind = rng.choice(KINDS)
      _remove(p)
      if kind == "regular":
        if name == "marker":
          p.write_bytes(_marker_text(rng, header, os.listdir(folder)))
        else:
          p.write_bytes(b"x" * rng.randrange(3))
      elif kind == "symlink":
        p.symlink_to(outside / "user.txt")
      elif kind == "fifo":
        os.mkfifo(p)
      elif kind == "dir":
        p.mkdir()
        (p / "chapter.tex").write_text("work")
      before = _snapshot(root)
      want = _bag_oracle(folder, marker, header)
      try:
        bag_lib.check_bag_dir(folder, overwrite=True)
        got = True
      except bag_lib.BagError as e:
        got = False
        if "\n" in str(e):
          raise AssertionError(f"a message of more than one line: {e}") from None
      checks += 1
      if got != want:
        raise AssertionError(f"check_bag_dir accepted={got}, the rule says {want}, for {_snapshot(folder)}")
      if _snapshot(root) != before:
        raise AssertionError("check_bag_dir changed the folder tree")
      accepted += got
      if rng.random() < 0.03:
        if got and os.listdir(folder):
          bag_lib.remove_bag(folder)
          if folder.exists() or (outside / "user.txt").read_text() != "the user's file":
            raise AssertionError("remove_bag left the folder or touched a file outside")
          removed += 1
        elif not got:
          try:
            bag_lib.remove_bag(folder)
            raise AssertionError("remove_bag removed a folder check_bag_dir refused")
          except bag_lib.BagError:
            pass
          if _snapshot(root) != before:
            raise AssertionError("a refused remove_bag changed the folder tree")
          refused_removals += 1
  finally:
    os.chdir(cwd)
    shutil.rmtree(root)
  return {"folder_checks": checks, "folders_accepted": accepted, "removed": removed, "refused_removals": refused_removals}


def main(argv=None) -> int:
  ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
  ap.add_argument("--values", type=int, default=100_000, help="random option values (default 100000)")
  ap.add_argument("--folders", type=int, default=100_000, help="folder states checked (default 100000)")
  ap.add_argument("--seed", type=int, default=0)
  args = ap.parse_args(argv)
  t0 = time.perf_counter()
  try:
    counts = {**fuzz_values(args.values, args.seed), **fuzz_folders(args.folders, args.seed)}
  except AssertionError as e:
    print(f"fuzz_cli_values: FAILED: {e}", file=sys.stderr)
    return 1
  print(f"fuzz_cli_values: ok in {time.perf_counter() - t0:.1f} s: " + ", ".join(f"{k} {v:,d}" for k, v in counts.items()))
  return 0


if __name__ == "__main__":
  sys.exit(main())
