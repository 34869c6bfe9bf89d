"""Fuzz targets for policy folders: mutated `policy.json` and `policy.msgpack` through `sims.rl.policy.load_policy`.

Registered in tests/fuzz/fuzz_inputs.py as "policy-json" (the JSON mutated beside a valid msgpack) and
"policy-msgpack" (the msgpack mutated beside a valid JSON), so they run in the same sandboxed
workers, under the same memory limit and per-input timeout:

    python -m tests.fuzz.fuzz_inputs --targets policy-json,policy-msgpack --count 2000

Seeds are small valid policies (hidden layers (4,) and (3, 5), random float32 weights, the
default NavEnvConfig) built here, so no training is needed. Mutations: the generic byte edits,
plus format-aware ones: for the JSON, a key dropped, an unknown key, a value of another type,
NaN / Infinity / huge or negative numbers, deep nesting, duplicate keys, sizes that no longer
match the weights, env_config fields changed; for the msgpack, an array dropped or added, another
shape or dtype, NaN / inf weights, negative variances, a scalar or a string in place of an array,
deep nesting; float edge cases in env_config (subnormal, 0 or inf in float32, -0.0, above the
bound), sizes at and past their bounds (episode_length, robots, observation and action sizes,
hidden sizes, crop_cells), and weights_sha256 dropped, changed, upper-cased or shortened, and the
version set back to 1. Every input must either load or raise `PolicyError` (a ValueError) with a
short message; a policy that loads must hold float32 weights of the recorded shapes, all finite,
whose SHA-256 is the recorded one, sizes within the bounds of `sims.rl.policy`, and every env_config
float 0 or a normal float32 of at most `sims.rl.env.MAX_CONFIG_VALUE`.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import hashlib
import json
import random
import tempfile
from pathlib import Path

import numpy as np
from flax import serialization

from sims.rl import policy as P
from sims.rl.env import MAX_CONFIG_VALUE, NavEnvConfig   # imported before the fuzz workers' memory limit is set

_ARCHS = (((4,), 98, 2), ((3, 5), 98, 2))


def _meta(hidden, obs, act, weights: bytes = b"") -> dict:
  return {"format": P.FORMAT, "version": P.VERSION, "hidden_sizes": list(hidden), "activation": "tanh",
          "observation_size": obs, "action_size": act, "env_config": dataclasses.asdict(NavEnvConfig()),
          "robots_per_world": 1, "episode_length": 150, "trainer": "rejax.PPO", "jax": "0.10.2",
          "extra": {"seed": 0, "note": "fuzz seed"}, "weights_sha256": hashlib.sha256(weights).hexdigest()}


def with_checksum(json_bytes: bytes, msgpack_bytes: bytes) -> bytes:
  """`json_bytes` with weights_sha256 set to the checksum of `msgpack_bytes` (unchanged if not a JSON
  object: the loader refuses it for that)."""
  try:
    meta = json.loads(json_bytes)
  except (ValueError, RecursionError):
    return json_bytes
  if not isinstance(meta, dict):
    return json_bytes
  meta["weights_sha256"] = hashlib.sha256(msgpack_bytes).hexdigest()
  return json.dumps(meta).encode()


def random_tree(hidden, obs, act, seed: int, *, var_floor: float = 0.1) -> dict:
  """A valid policy.msgpack tree with random weights (obs_var >= var_floor), shaped as
  `sims.rl.policy.param_shapes` says; also the CLI tests' policy folders."""
  rng = np.random.default_rng(seed)
  tree: dict = {}
  for path, shape in P.param_shapes(hidden, obs, act).items():
    node = tree
    *parents, leaf = path.split("/")
    for k in parents:
      node = node.setdefault(k, {})
    value = rng.normal(size=shape).astype(np.float32)
    node[leaf] = np.abs(value) + var_floor if leaf == "obs_var" else value
  return tree


def _pack(tree) -> bytes:
  return serialization.msgpack_serialize(tree)


@functools.cache
def valid_pairs() -> list[tuple[bytes, bytes]]:
  """(policy.json, policy.msgpack) bytes of each seed policy."""
  out = []
  for i, a in enumerate(_ARCHS):
    weights = _pack(random_tree(*a, seed=i))
    out.append((json.dumps(_meta(*a, weights), indent=2).encode(), weights))
  return out


def json_seeds() -> list[bytes]:
  """The seed policies' policy.json files."""
  return [j for j, _ in valid_pairs()]


def msgpack_seeds() -> list[bytes]:
  """Weights of the first seed's architecture (the JSON beside them): two draws."""
  return [valid_pairs()[0][1], _pack(random_tree(*_ARCHS[0], seed=7))]


_ODD_VALUES = (None, True, False, 0, -1, 1.5, 2 ** 31, 10 ** 30, -(10 ** 400), "", "x" * 300, [], {}, [1, 2],
               {"a": 1}, "tanh", "relu", "NaN")
# float32 edge cases: subnormal, 0 and inf in float32, the smallest normal, the bound and past it.
_FLOAT_EDGES = (1e-45, 1e-40, 1e-50, 1e-320, 1.1754943508222875e-38, 1.1754942e-38, 3.4028235e38, 3.5e38,
                1e39, 1e308, -0.0, 0.0, 1e6, 1e6 + 1, 5e-324, -1e-45, 0.5, 2.0)
_SIZE_KEYS = {"episode_length": P.MAX_EPISODE_LENGTH, "robots_per_world": P.MAX_ROBOTS,
              "observation_size": P.MAX_OBSERVATION_SIZE, "action_size": P.MAX_ACTION_SIZE}


def _bound_edit(meta: dict, rng: random.Random) -> None:
  """A size at or past its bound, a float32 edge case in env_config, or a changed checksum/version."""
  op = rng.randrange(4)
  if op == 0:
    key = rng.choice(sorted(_SIZE_KEYS))
    most = _SIZE_KEYS[key]
    meta[key] = rng.choice((most, most + 1, 2 * most, 2 ** 20, 2 ** 31, 2 ** 63, 0))
    if rng.random() < 0.3:
      meta["hidden_sizes"] = rng.choice(([P.MAX_HIDDEN] * P.MAX_LAYERS, [P.MAX_HIDDEN + 1],
                                         [4] * (P.MAX_LAYERS + 1), [2048, 2048]))
  elif op == 1 and isinstance(meta.get("env_config"), dict):
    env = meta["env_config"]
    names = [k for k, v in env.items() if isinstance(v, float)] or list(env) or ["x"]
    env[rng.choice(names)] = rng.choice(_FLOAT_EDGES)
    if rng.random() < 0.3:
      env["crop_cells"] = rng.choice((P.MAX_CROP_CELLS, P.MAX_CROP_CELLS + 2, 1001, 3, 1))
  elif op == 2:
    sha = meta.get("weights_sha256")
    meta["weights_sha256"] = rng.choice((None, "0" * 64, "g" * 64, "", 12,
                                         sha.upper() if isinstance(sha, str) else "A" * 64,
                                         sha[:63] if isinstance(sha, str) else "a",
                                         (sha[:-1] + ("0" if sha[-1:] != "0" else "1")) if isinstance(sha, str)
                                         else "b" * 64))
    if rng.random() < 0.2:
      meta.pop("weights_sha256", None)
  else:
    meta["version"] = rng.choice((1, 0, 2, 4, str(P.VERSION), float(P.VERSION), True))
    if rng.random() < 0.5:
      meta.pop("weights_sha256", None)


def _json_text_edit(text: str, rng: random.Random) -> str:
  op = rng.randrange(5)
  if op == 0:
    return text.replace(rng.choice((f'"version": {P.VERSION}', '"observation_size": 98', '"crop_cells": 9')),
                        rng.choice(("NaN", "Infinity", "-Infinity", "1e400", "-0", "1" * 5000)), 1)
  if op == 1:                                       # a duplicate key
    return text.replace("{", '{"format": "jaxfilters-policy", ', 1)
  if op == 2:                                       # deep nesting in extra
    depth = rng.choice((9, 50, 5000))
    return text.replace('"extra": {', '"extra": {"deep": ' + "[" * depth + "]" * depth + ", ", 1)
  if op == 3:
    return text[:rng.randrange(len(text))] if text else "{"
  return text.replace('"', "'", rng.randint(1, 3))


def json_edit(data: bytes, rng: random.Random) -> bytes:
  """One policy.json-aware mutation."""
  try:
    meta = json.loads(data)
  except (ValueError, RecursionError):
    meta = None
  if not isinstance(meta, dict) or rng.random() < 0.25:
    return _json_text_edit(data.decode("utf-8", "replace"), rng).encode()
  if rng.random() < 0.35:
    _bound_edit(meta, rng)
    try:
      return json.dumps(meta, allow_nan=True).encode()
    except (ValueError, RecursionError):
      return data
  target = meta["env_config"] if isinstance(meta.get("env_config"), dict) and rng.random() < 0.3 else meta
  keys = list(target) or ["x"]
  op = rng.randrange(5)
  if op == 0:
    target.pop(rng.choice(keys), None)
  elif op == 1:
    target[rng.choice(("unknown", "Version", "hidden", " format"))] = rng.choice(_ODD_VALUES)
  elif op == 2:
    target[rng.choice(keys)] = copy.deepcopy(rng.choice(_ODD_VALUES))
  elif op == 3:                                     # sizes that no longer match the weights
    meta[rng.choice(("observation_size", "action_size"))] = rng.choice((1, 2, 3, 97, 99, 2 ** 20, 2 ** 20 + 1))
    if rng.random() < 0.5:
      meta["hidden_sizes"] = rng.choice(([4], [5], [3, 5], [5, 3], [4096] * 9, [0], [-4], [4.0], []))
  try:
    text = json.dumps(meta, allow_nan=True)
  except (ValueError, RecursionError):   # an earlier mutation nested it too deep to write again
    return data
  if op == 4:
    text = text.replace("0.01", rng.choice(("NaN", "1e999", "-5")), 1)
  return text.encode()


def msgpack_edit(data: bytes, rng: random.Random) -> bytes:
  """One policy.msgpack-aware mutation (decoded, changed, encoded again)."""
  try:
    tree = serialization.msgpack_restore(data)
  except Exception:  # noqa: BLE001 - an earlier mutation broke it: edit the bytes
    return data[:rng.randrange(len(data) + 1)] + bytes(rng.randrange(256) for _ in range(rng.randint(0, 8)))
  flat = []

  def walk(node, path):
    if isinstance(node, dict):
      for k, v in node.items():
        if isinstance(v, dict):
          walk(v, path + [k])
        else:
          flat.append((node, k))
  walk(tree, [])
  if not flat:
    return _pack({"x": np.zeros(1, np.float32)})
  node, key = rng.choice(flat)
  a = node[key]
  op = rng.randrange(8)
  if op == 0:
    del node[key]
  elif op == 1:
    node[str(key) + rng.choice(("_extra", "", "x"))] = np.zeros(3, np.float32)
    node["extra_array"] = np.ones((2, 2), np.float32)
  elif op == 2 and isinstance(a, np.ndarray):       # another shape
    node[key] = np.resize(a, rng.choice(((1,), (a.size + 1,), (2, 2), (0,), a.shape[::-1] + (1,))))
  elif op == 3 and isinstance(a, np.ndarray):       # another dtype
    node[key] = a.astype(rng.choice((np.float64, np.float16, np.int32, np.uint8, np.bool_, np.complex64)))
  elif op == 4 and isinstance(a, np.ndarray) and a.size:
    b = a.copy()
    bad = (np.nan, np.inf, -np.inf, -1.0, 3.4e38) if np.issubdtype(b.dtype, np.inexact) else (-1, 0, 1, 255)
    b.reshape(-1)[rng.randrange(b.size)] = rng.choice(bad)
    node[key] = b
  elif op == 5:
    node[key] = rng.choice((1, 1.5, "x", b"\x00" * 4, None, [1.0, 2.0], True))
  elif op == 6:                                     # deep nesting
    deep: dict = {}
    cur = deep
    for _ in range(rng.choice((5, 20, 200))):
      cur["d"] = {}
      cur = cur["d"]
    node[key] = deep
  else:
    tree = rng.choice(([1, 2, 3], "policy", 3, {1: np.zeros(2, np.float32)}))
  try:
    return _pack(tree)
  except Exception:  # noqa: BLE001 - a tree flax cannot encode: keep the input unchanged
    return data


@functools.cache
def _folder() -> Path:
  return Path(tempfile.mkdtemp(prefix="jaxfilters-fuzz-policy-"))


def _load_and_check(json_bytes: bytes, msgpack_bytes: bytes):
  folder = _folder()
  (folder / P.JSON_NAME).write_bytes(json_bytes)
  (folder / P.MSGPACK_NAME).write_bytes(msgpack_bytes)
  pol = P.load_policy(folder)
  shapes = P.param_shapes(pol.hidden_sizes, pol.observation_size, pol.action_size)
  flat = {}

  def walk(node, prefix):
    for k, v in node.items():
      if isinstance(v, dict):
        walk(v, prefix + k + "/")
      else:
        flat[prefix + k] = v
  walk(pol.params, "")
  if set(flat) != set(shapes):
    raise AssertionError(f"loaded arrays {sorted(flat)} differ from the architecture's {sorted(shapes)}")
  for name, shape in shapes.items():
    a = flat[name]
    if a.dtype != np.float32 or a.shape != shape or not np.isfinite(a).all():
      raise AssertionError(f"loaded {name}: {a.dtype} {a.shape} (want float32 {shape}, finite)")
  meta = json.loads(json_bytes)
  if meta.get("weights_sha256") != hashlib.sha256(msgpack_bytes).hexdigest():
    raise AssertionError("loaded a policy whose weights_sha256 is not the SHA-256 of its weights")
  sizes = {"episode_length": pol.episode_length, "robots_per_world": pol.robots_per_world,
           "observation_size": pol.observation_size, "action_size": pol.action_size}
  for key, most in _SIZE_KEYS.items():
    if not 1 <= sizes[key] <= most:
      raise AssertionError(f"loaded {key} = {sizes[key]}, outside [1, {most}]")
  if len(pol.hidden_sizes) > P.MAX_LAYERS or max(pol.hidden_sizes) > P.MAX_HIDDEN:
    raise AssertionError(f"loaded hidden sizes {pol.hidden_sizes} past the bounds")
  tiny = float(np.finfo(np.float32).tiny)
  for f in dataclasses.fields(pol.env_config):
    v = getattr(pol.env_config, f.name)
    if isinstance(v, float) and not (v == 0 or tiny <= v <= MAX_CONFIG_VALUE):
      raise AssertionError(f"loaded env_config.{f.name} = {v!r}: not 0 or a normal float32 within the bound")
  if pol.env_config.crop_cells > P.MAX_CROP_CELLS:
    raise AssertionError(f"loaded crop_cells = {pol.env_config.crop_cells}")
  return pol


def run_json(data: bytes):
  """Loads a policy whose policy.json is `data`, beside the seed msgpack of its hidden sizes."""
  try:
    three_five = json.loads(data).get("hidden_sizes") == [3, 5]
  except Exception:  # noqa: BLE001 - not JSON, or not an object: the loader says what is wrong
    three_five = False
  return _load_and_check(data, valid_pairs()[1 if three_five else 0][1])


def run_msgpack(data: bytes):
  """Loads a policy whose policy.msgpack is `data` (beside the first seed's policy.json with the checksum
  of `data`, as a writer that recomputes it would leave: the decoder and the array checks are fuzzed,
  not only the checksum)."""
  return _load_and_check(with_checksum(valid_pairs()[0][0], data), data)
