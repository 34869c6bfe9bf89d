"""Fuzz target for Nav2 params files: mutated `nav2_params.yaml` through `jaxfilters.load_params`.

Registered in `tests.fuzz.fuzz_inputs.TARGETS` as "params", so it runs in the same
sandboxed workers, under the same memory limit and per-input timeout:

    python -m tests.fuzz.fuzz_inputs --targets params --count 2000

Seeds: the shipped `sims/assets/nav2_params.yaml` (masks through relative
`yaml_filename`s) and, when the shared maps folder is beside the checkout
(as for tests/conftest.py's `nav2_maps`), Nav2's bringup `nav2_params.yaml`
(masks and `enabled` given as Nav2's launch file gives them). Masks are the
small shipped ones, so an input costs milliseconds.

Mutations: the map fuzzer's YAML and byte edits, plus params-aware ones: alias
bombs and recursive aliases inside and outside `ros__parameters`, deep
nesting as a parameter value, duplicated keys, huge numbers and wrongly typed
values, wildcard nodes, long names, and substitution values (a line
`#set NAME=VALUE` in the input becomes `substitutions={NAME: VALUE}`, the
CLI's `--set`). Allowed outcomes are the documented ones: the file loads,
`Nav2ParamsError` (a ValueError) or `FileNotFoundError`, each in a short
message.
"""

from __future__ import annotations

import ctypes
import functools
import random
import re
import shutil
import warnings
from pathlib import Path

from jaxfilters import nav2

_ROOT = Path(__file__).resolve().parents[2]
_ASSETS = _ROOT / "sims" / "assets"
_BRINGUP = _ROOT.parent / "shared" / "maps" / "nav2" / "nav2_params.yaml"
_MASK_FILES = ("default_keepout.yaml", "default_keepout.pgm", "default_speed.yaml", "default_speed.pgm")
_ENABLE = {"KEEPOUT_ZONE_ENABLED": "True", "SPEED_ZONE_ENABLED": "True"}

_BOMB = ['a0: &a0 ["x","x","x","x","x","x","x","x","x"]'] + [
    f"a{i}: &a{i} [{','.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 7)]
_VALUES = ("1" + "0" * 400, "-1" + "0" * 40, "1e39", "-1e39", "1e-50", ".nan", ".inf", "-.inf", "0", "-1", "300",
           "256", "2147483648", "true", "false", "~", "''", "'x'", "[1, 2]", "[]", "{a: 1}", "{}", "[a, b]",
           "&x [1]", "*x", "!!binary aGVsbG8=", "2001-02-30", "2001-01-01", "0x10", "1_000", "'/'", "'~/x'",
           "/dev/zero", "/dev/null", "missing.yaml", "../../../../etc/hostname", "a" * 3000, "KEEPOUT_ZONE_ENABLED",
           '"\\x00"', "!!python/object:os.system x", "? complex", "[" * 3000, "[" * 40 + "]" * 40)


@functools.cache
def _folder() -> Path:
  """This process's folder: the shipped masks, beside which each input is written as p.yaml."""
  from tests.fuzz.fuzz_inputs import workdir
  folder = workdir() / "params"
  folder.mkdir(exist_ok=True)
  for name in _MASK_FILES:
    shutil.copy(_ASSETS / name, folder / name)
  return folder


def run(data: bytes) -> nav2.Nav2Params:
  """Loads one input; `#set NAME=VALUE` lines become substitutions (the CLI's --set)."""
  folder = _folder()
  path = folder / "p.yaml"
  path.write_bytes(data)
  subs = dict(_ENABLE)
  for m in re.finditer(rb"^#set ([^=\n]+)=([^\n]*)$", data, re.M):
    subs[m.group(1).decode("utf-8", "replace")] = m.group(2).decode("utf-8", "replace")
  masks = {}
  if not re.search(rb"^\s*yaml_filename:", data, re.M):  # Nav2's bringup: the launch file names the masks
    masks = {"keepout_filter_mask_server": str(folder / "default_keepout.yaml"),
             "speed_filter_mask_server": str(folder / "default_speed.yaml")}
  with warnings.catch_warnings():
    warnings.simplefilter("ignore", nav2.Nav2ParamsWarning)
    return nav2.load_params(path, masks=masks, substitutions=subs)


def _one_malloc_arena() -> None:
  """Caps glibc's malloc at one arena: JAX's CPU backend threads otherwise reserve ~1 GiB of address space.

  Each thread that allocates gets its own 64 MiB arena reservation; the
  worker's address-space limit (1 GiB by default) would then be spent before
  the first input. Set before the backend starts its threads.
  """
  try:
    ctypes.CDLL(None).mallopt(-8, 1)  # M_ARENA_MAX
  except (OSError, AttributeError):
    pass  # not glibc: nothing to cap


def seeds() -> list:
  """The valid params files (each must load unmutated); the first load also starts JAX's backend."""
  from tests.fuzz.fuzz_inputs import Seed
  _one_malloc_arena()
  found = [Seed(p.read_bytes()) for p in (_ASSETS / "nav2_params.yaml", _BRINGUP) if p.is_file()]
  for s in found:  # before the worker's memory limit: imports, the backend, the first arrays
    run(s.data)
  return found


def _indented(lines: list[str], rng: random.Random) -> tuple[int, str]:
  """A line index inside some node's parameters, and its indentation."""
  inside = [i for i, line in enumerate(lines) if line.startswith("      ") and ":" in line] or [0]
  i = rng.choice(inside)
  return i, re.match(r"\s*", lines[i]).group(0)


def edit(data: bytes, rng: random.Random) -> bytes:
  """One params-aware mutation (half the time the map fuzzer's YAML edit)."""
  from tests.fuzz.fuzz_inputs import yaml_edit
  if rng.random() < 0.3:
    return yaml_edit(data, rng)
  text = data.decode("utf-8", "replace")
  lines = text.splitlines(keepends=True) or ["\n"]
  op = rng.randrange(10)
  i, pad = _indented(lines, rng)
  if op == 0:  # replace a parameter's value
    key = lines[i].split(":", 1)[0]
    lines[i] = f"{key}: {rng.choice(_VALUES)}\n"
  elif op == 1:  # replace one number anywhere
    nums = list(re.finditer(r"-?\d+(\.\d+)?", text))
    if nums:
      m = rng.choice(nums)
      return (text[:m.start()] + rng.choice(_VALUES) + text[m.end():]).encode()
  elif op == 2:  # an alias bomb inside a node's parameters, or used as a value
    block = "".join(f"{pad}{b}\n" for b in _BOMB)
    lines.insert(i, block if rng.random() < 0.5 else block + f"{pad}base: *a6\n")
  elif op == 3:  # a recursive alias
    lines.insert(i, rng.choice((f"{pad}r: &r {{b: *r}}\n", "r: &r [*r]\n", f"{pad}m: &m {{<<: *m}}\n")))
  elif op == 4:  # deep nesting as a value, flow or block
    n = rng.choice((20, 40, 2000))
    if rng.random() < 0.5:
      lines.insert(i, f"{pad}deep: " + "[" * n + "]" * n + "\n")
    else:
      lines.insert(i, "".join(f"{pad}{' ' * k}k{k}:\n" for k in range(min(n, 300))) + f"{pad}{' ' * 300}v: 1\n")
  elif op == 5:  # a duplicated key
    lines.insert(i, lines[i])
  elif op == 6:  # a substitution value (--set)
    name = rng.choice(("KEEPOUT_ZONE_ENABLED", "SPEED_ZONE_ENABLED", "UNUSED"))
    lines.append(f"#set {name}={rng.choice(_VALUES)}\n")
  elif op == 7:  # wildcard nodes
    pattern = rng.choice(("/**", "/**/" * rng.choice((2, 60)) + "global_costmap", "/*/*", "**/x/**"))
    lines.append(f"{pattern}:\n  ros__parameters:\n    {rng.choice(('resolution', 'global_frame', 'filters'))}:"
                 f" {rng.choice(_VALUES)}\n")
  elif op == 8:  # a long name
    lines.insert(i, f"{pad}{'k' * rng.choice((200, 300, 5000))}: 1\n")
  else:  # another filter's plugin, or a filter list naming something else
    lines.insert(i, f"{pad}{rng.choice(('plugin', 'filters', 'filter_info_topic', 'mask_topic', 'type'))}: "
                    f"{rng.choice(('nav2_costmap_2d::BinaryFilter', '[keepout_filter, keepout_filter]', '4', '[]'))}\n")
  return "".join(lines).encode("utf-8", "surrogateescape")
