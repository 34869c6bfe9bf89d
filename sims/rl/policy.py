"""Trained policies on disk: `save_policy` writes a folder, `load_policy` reads and checks it.

    save_policy("out/pol", algo, train_state, env_config=env.nav_config, fleet_config=env.fleet_config,
                episode_length=150, extra={"seed": 0})
    policy = load_policy("out/pol")
    action = policy.act(obs)                 # jittable; mean action clipped to [-1, 1]

A policy folder holds two files:

* `policy.json`: the format name and version, the actor's architecture
  (`hidden_sizes`, `activation`, `observation_size`, `action_size`), the
  env it was trained on (`env_config`: every `NavEnvConfig` field;
  `robots_per_world`, the K it was trained with (a policy with `env_config.agents` "per_robot"
  drives each robot and runs at any K); `episode_length`), the `trainer`, the `jax` version,
  `extra` (free-form: seed, timesteps, figures) and `weights_sha256`, the
  SHA-256 of `policy.msgpack`'s bytes.
* `policy.msgpack`: `flax.serialization` msgpack of `{"actor": params,
  "obs_mean": float32 [D], "obs_var": float32 [D]}`; `params` is the
  Gaussian actor's tree (`features/Dense_i/{kernel,bias}`,
  `action_mean/{kernel,bias}`, `action_log_std`) and the two vectors are the
  observation-normalisation statistics the actor was trained with.

`Policy.act(obs)` normalises `obs` (float32 [..., D]) with those statistics,
runs the MLP and returns its mean action (float32 [..., A]) clipped to
[-1, 1]: the same numbers as `sims.rl.ppo.mean_policy` on the train state.

Loading treats the folder as untrusted input. Both files must be regular files
(a FIFO, device or directory is refused before a byte is read); the JSON of at
most `MAX_JSON_BYTES` must match the schema exactly (no unknown or missing keys,
the stated types, finite numbers, no duplicate keys) and every field that sizes
work is bounded: at most MAX_LAYERS hidden layers of MAX_HIDDEN units (what
`jaxfilters rl train --hidden` accepts), observations of MAX_OBSERVATION_SIZE,
actions of MAX_ACTION_SIZE, MAX_ROBOTS robots per world, episodes of
MAX_EPISODE_LENGTH steps (`rl train/eval --episode-length`'s bound), a crop of
MAX_CROP_CELLS, and every float of `env_config` a normal float32 (or 0 where
`NavEnvConfig` allows it). The weights file may be no larger than the
architecture's arrays need (`msgpack_size_bound`; at most `MAX_MSGPACK_BYTES`,
the bound of the largest architecture accepted), its SHA-256 must equal
`weights_sha256`, and it must hold float32 arrays of exactly the shapes the
architecture gives, all finite, with variances >= 0. Every problem is a
`PolicyError` (a ValueError) naming the file and what was expected.

Files of format version 2 (written before `NavEnvConfig.agents`) are read as they are, with
agents "world": every policy of that version drives one world. Files of format version 1
(written before the checksum) are refused with a
message saying so; `add_checksum(folder)` re-writes such a folder's
`policy.json` as version 3 (agents "world") with the checksum of the weights it holds (the
weights are checked against the architecture and left unchanged). Run it only
on weights you trust: the checksum proves the file unchanged since, not sound.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import stat
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters.map_decode import read_regular_file

FORMAT = "jaxfilters-policy"
VERSION = 3                # 2: policy.json holds weights_sha256; 3: env_config holds agents
JSON_NAME = "policy.json"
MSGPACK_NAME = "policy.msgpack"
MAX_JSON_BYTES = 2 ** 20
MAX_HIDDEN = 1024          # units per hidden layer (`rl train --hidden`'s bound)
MAX_LAYERS = 4             # hidden layers (`rl train --hidden`'s bound)
MAX_OBSERVATION_SIZE = 4096   # a crop of MAX_CROP_CELLS**2 cells plus the robot's own entries fits
MAX_ACTION_SIZE = 128      # 2 per robot in velocity mode
MAX_ROBOTS = 64            # robots_per_world
MAX_EPISODE_LENGTH = 100_000  # env steps of 0.2 s (`rl train/eval --episode-length`'s bound)
MAX_CROP_CELLS = 63        # NavEnvConfig.crop_cells: the observed crop is crop_cells**2 values per robot
MAX_CONFIG_INT = MAX_CROP_CELLS
_MSGPACK_OVERHEAD = 64 * 2 ** 10   # flax's msgpack framing: names and headers of at most a few dozen arrays
ACTIVATIONS = {"tanh": jnp.tanh, "relu": jax.nn.relu}   # by the __name__ of flax.linen.tanh / relu
_NORM_EPS = 1e-8           # rejax's normalize_obs: (x - mean) / sqrt(var + 1e-8)


class PolicyError(ValueError):
  """A policy folder or file that cannot be loaded; the message names the file and what was expected."""


@dataclasses.dataclass(frozen=True)
class Policy:
  """A loaded policy: its recorded configs and the actor's weights.

  Attributes:
    path: the folder it was loaded from.
    hidden_sizes: units of each hidden layer.
    activation: name of the hidden layers' activation (a key of ACTIVATIONS).
    observation_size: D, the observation length it expects.
    action_size: A, the action length it returns.
    env_config: the NavEnvConfig it was trained with.
    robots_per_world: FleetConfig.robots_per_world it was trained with.
    episode_length: env steps per training episode.
    trainer: the trainer's name and version.
    jax_version: the jax version that trained it.
    extra: free-form training notes (dict).
    params: {"actor": params tree, "obs_mean": float32 [D], "obs_var": float32 [D]} (NumPy).
  """
  path: str
  hidden_sizes: tuple[int, ...]
  activation: str
  observation_size: int
  action_size: int
  env_config: Any
  robots_per_world: int
  episode_length: int
  trainer: str
  jax_version: str
  extra: dict
  params: dict = dataclasses.field(repr=False)

  @property
  def fleet_config(self):
    """The FleetConfig of the env it was trained on (robots_per_world; the rest default)."""
    from sims.fleet.config import FleetConfig
    return FleetConfig(robots_per_world=self.robots_per_world)

  def act(self, obs: jax.Array) -> jax.Array:
    """The mean action for obs float32 [..., D]: float32 [..., A] in [-1, 1] (jittable)."""
    return mean_action(self.params, self.activation, obs)

  def raw_action(self, obs: jax.Array) -> jax.Array:
    """The mean action before the clip to [-1, 1]: float32 [..., A] (jittable); NaN or inf where the
    weights overflow float32 (what `act` would pass on as NaN, or clip from inf to +-1)."""
    return mean_action(self.params, self.activation, obs, clip=False)


def mean_action(params: dict, activation: str, obs: jax.Array, *, clip: bool = True) -> jax.Array:
  """The Gaussian actor's mean action, clipped to [-1, 1] (unless clip=False), with observation normalisation.

  Args:
    params: as `Policy.params`.
    activation: a key of ACTIVATIONS.
    obs: float32 [..., D].
    clip: clip to the action space [-1, 1] (a NaN stays NaN).
  """
  f = ACTIVATIONS[activation]
  x = jnp.asarray(obs, jnp.float32)
  lead = (1,) * (x.ndim - 1)           # vectors broadcast over the batch axes explicitly (rank promotion)
  row = lambda v: jnp.reshape(jnp.asarray(v), lead + (-1,))
  x = (x - row(params["obs_mean"])) / jnp.sqrt(row(params["obs_var"]) + _NORM_EPS)
  p = params["actor"]["params"]
  layers = p["features"]
  for i in range(len(layers)):
    layer = layers[f"Dense_{i}"]
    x = f(x @ layer["kernel"] + row(layer["bias"]))
  mean = x @ p["action_mean"]["kernel"] + row(p["action_mean"]["bias"])
  return jnp.clip(mean, -1.0, 1.0) if clip else mean


def msgpack_size_bound(hidden_sizes, observation_size: int, action_size: int) -> int:
  """Most bytes a `policy.msgpack` of this architecture may have: its float32 arrays plus framing."""
  shapes = param_shapes(hidden_sizes, observation_size, action_size)
  return 4 * sum(math.prod(s) for s in shapes.values()) + _MSGPACK_OVERHEAD


def param_shapes(hidden_sizes, observation_size: int, action_size: int) -> dict[str, tuple[int, ...]]:
  """Every array of `policy.msgpack` by its '/'-joined path, with its shape."""
  shapes = {}
  n_in = observation_size
  for i, h in enumerate(hidden_sizes):
    shapes[f"actor/params/features/Dense_{i}/kernel"] = (n_in, h)
    shapes[f"actor/params/features/Dense_{i}/bias"] = (h,)
    n_in = h
  shapes["actor/params/action_mean/kernel"] = (n_in, action_size)
  shapes["actor/params/action_mean/bias"] = (action_size,)
  shapes["actor/params/action_log_std"] = (action_size,)
  shapes["obs_mean"] = (observation_size,)
  shapes["obs_var"] = (observation_size,)
  return shapes


# The largest weights file any accepted policy.json allows (about 30 MiB).
MAX_MSGPACK_BYTES = msgpack_size_bound((MAX_HIDDEN,) * MAX_LAYERS, MAX_OBSERVATION_SIZE, MAX_ACTION_SIZE)


# ----------------------------------------------------------------------------- save


def save_policy(folder, algo, train_state, *, env_config, fleet_config, episode_length: int,
                extra: dict | None = None) -> Path:
  """Writes `policy.json` and `policy.msgpack` of a rejax PPO train state into `folder`.

  Args:
    folder: the folder (created if missing; the two files are replaced).
    algo: the rejax PPO (`sims.rl.ppo.make_ppo`): its actor's hidden sizes and activation are recorded.
    train_state: its train state (actor params, observation statistics).
    env_config: the NavEnvConfig trained on.
    fleet_config: the FleetConfig trained on (robots_per_world is recorded).
    episode_length: env steps per training episode.
    extra: JSON-serialisable notes (finite numbers only).

  Returns:
    The folder.

  Raises:
    ValueError: a policy `load_policy` would refuse (an architecture or env outside the bounds,
      an activation this format cannot describe, non-finite weights or notes); nothing is written.
  """
  from flax import serialization
  folder = Path(folder)
  actor = algo.actor
  activation = getattr(actor.activation, "__name__", str(actor.activation))
  if activation not in ACTIVATIONS:
    raise ValueError(f"activation {activation!r} cannot be saved; one of {sorted(ACTIVATIONS)} can")
  params = jax.device_get(train_state.actor_ts.params)
  if algo.normalize_observations:
    mean, var = (np.asarray(jax.device_get(v), np.float32) for v in
                 (train_state.obs_rms_state.mean, train_state.obs_rms_state.var))
  else:
    d = np.asarray(params["params"]["features"]["Dense_0"]["kernel"]).shape[0]
    mean, var = np.zeros(d, np.float32), np.full(d, 1.0 - _NORM_EPS, np.float32)
  tree = {"actor": jax.tree.map(lambda a: np.asarray(a, np.float32), params), "obs_mean": mean, "obs_var": var}
  hidden = [int(h) for h in actor.hidden_layer_sizes]
  meta = {"format": FORMAT, "version": VERSION, "hidden_sizes": hidden, "activation": activation,
          "observation_size": int(mean.shape[0]), "action_size": int(actor.action_dim),
          "env_config": dataclasses.asdict(env_config), "robots_per_world": int(fleet_config.robots_per_world),
          "episode_length": int(episode_length), "trainer": "rejax.PPO", "jax": jax.__version__,
          "extra": dict(extra or {})}
  _check_tree(tree, meta, MSGPACK_NAME)
  weights = serialization.msgpack_serialize(tree)
  meta["weights_sha256"] = hashlib.sha256(weights).hexdigest()
  text = json.dumps(meta, indent=2, allow_nan=False)
  check_policy_meta(json.loads(text), JSON_NAME)       # what load_policy will check, before writing
  if len(weights) > msgpack_size_bound(hidden, meta["observation_size"], meta["action_size"]):
    raise ValueError(f"{MSGPACK_NAME} would be {len(weights):,d} bytes, above the loader's bound")
  folder.mkdir(parents=True, exist_ok=True)
  (folder / MSGPACK_NAME).write_bytes(weights)
  (folder / JSON_NAME).write_text(text + "\n")
  return folder


def add_checksum(folder) -> Path:
  """Re-writes a version-1 (or 2) policy folder's `policy.json` as version 3 with the weights' SHA-256.

  The weights are read and checked against the architecture exactly as `load_policy` checks
  them, and are not changed. Use it only on a folder whose weights you trust.

  Raises:
    PolicyError: the folder does not hold a valid version-1, 2 or 3 policy.
  """
  folder = Path(folder)
  path = folder / JSON_NAME
  meta = _parse_json(path)
  if isinstance(meta, dict) and meta.get("version") == 1 and "weights_sha256" not in meta:
    env = meta.get("env_config")
    # Checked as version 3 if its env_config has agents, else as version 2 (before the field).
    meta = {**meta, "version": VERSION if isinstance(env, dict) and "agents" in env else 2,
            "weights_sha256": "0" * 64}
  meta = {**check_policy_meta(meta, path), "version": VERSION}
  raw = _read(folder / MSGPACK_NAME, msgpack_size_bound(meta["hidden_sizes"], meta["observation_size"],
                                                          meta["action_size"]))
  _decode_tree(raw, meta, str(folder / MSGPACK_NAME))
  meta["weights_sha256"] = hashlib.sha256(raw).hexdigest()
  path.write_text(json.dumps(meta, indent=2, allow_nan=False) + "\n")
  load_policy(folder)
  return folder


# ----------------------------------------------------------------------------- load


def load_policy(folder) -> Policy:
  """Reads and checks a policy folder (see the module docstring).

  Raises:
    PolicyError: a missing folder or file, a file that is not a regular file or
      is too large, JSON off the schema, weights of the wrong shape or dtype, or
      non-finite values.
  """
  folder = Path(folder)
  try:
    st = os.stat(folder)
  except FileNotFoundError:
    raise PolicyError(f"policy folder {folder} does not exist") from None
  except OSError as e:
    raise PolicyError(f"policy folder {folder}: cannot read it ({e.strerror or e})") from None
  if not stat.S_ISDIR(st.st_mode):
    raise PolicyError(f"policy folder {folder} is not a directory (expected a folder with {JSON_NAME} and "
                      f"{MSGPACK_NAME})")
  meta = read_policy_json(folder / JSON_NAME)
  tree = read_policy_msgpack(folder / MSGPACK_NAME, meta)
  return Policy(path=str(folder), hidden_sizes=tuple(meta["hidden_sizes"]), activation=meta["activation"],
                observation_size=meta["observation_size"], action_size=meta["action_size"],
                env_config=nav_env_config(meta["env_config"]), robots_per_world=meta["robots_per_world"],
                episode_length=meta["episode_length"], trainer=meta["trainer"], jax_version=meta["jax"],
                extra=meta["extra"], params=tree)


def nav_env_config(fields: dict):
  """NavEnvConfig of `policy.json`'s env_config (lists become tuples); ValueError/TypeError if refused."""
  from sims.rl.env import NavEnvConfig
  return NavEnvConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in fields.items()})


def _read(path: Path, max_bytes: int) -> bytes:
  try:
    return read_regular_file(str(path), "policy file", max_bytes=max_bytes)
  except (FileNotFoundError, ValueError) as e:
    raise PolicyError(str(e).splitlines()[0]) from None


def _no_constant(name):
  raise ValueError(f"{name} is not a finite number")


def _unique_keys(pairs):
  out = {}
  for k, v in pairs:
    if k in out:
      raise ValueError(f"key {k!r} appears twice")
    out[k] = v
  return out


def _is_int(v) -> bool:
  return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v) -> bool:
  """An int or float (not a bool) that is a finite float64."""
  if isinstance(v, bool) or not isinstance(v, (int, float)):
    return False
  try:
    return math.isfinite(float(v))
  except OverflowError:         # an int beyond float64
    return False


def _json_value_ok(v, depth: int = 0) -> bool:
  """JSON value with finite numbers only, nested at most 8 deep (for `extra`)."""
  if depth > 8:
    return False
  if isinstance(v, float):
    return math.isfinite(v)
  if v is None or isinstance(v, (str, int, bool)):
    return True
  if isinstance(v, list):
    return all(_json_value_ok(x, depth + 1) for x in v)
  if isinstance(v, dict):
    return all(isinstance(k, str) and _json_value_ok(x, depth + 1) for k, x in v.items())
  return False


def _parse_json(path: Path):
  raw = _read(path, MAX_JSON_BYTES)
  try:
    return json.loads(raw.decode("utf-8"), parse_constant=_no_constant, object_pairs_hook=_unique_keys)
  except (ValueError, RecursionError) as e:        # UnicodeDecodeError and JSONDecodeError are ValueErrors
    raise PolicyError(f"{path}: not valid JSON ({str(e).splitlines()[0][:200]})") from None


def read_policy_json(path: Path) -> dict:
  """`policy.json` read and checked against the schema; returns the dict.

  Raises:
    PolicyError: see `load_policy`.
  """
  return check_policy_meta(_parse_json(path), path)


# Fields of policy.json that size work, with their bounds.
_SIZE_BOUNDS = {"observation_size": MAX_OBSERVATION_SIZE, "action_size": MAX_ACTION_SIZE,
                "robots_per_world": MAX_ROBOTS, "episode_length": MAX_EPISODE_LENGTH}


def check_policy_meta(meta, path) -> dict:
  """A parsed `policy.json` checked against the schema and the bounds (module docstring); returns it.

  Raises:
    PolicyError: naming `path` and the key.
  """
  if not isinstance(meta, dict):
    raise PolicyError(f"{path}: expected a JSON object; got {type(meta).__name__}")
  from sims.rl.env import NavEnvConfig
  defaults = {f.name: f.default for f in dataclasses.fields(NavEnvConfig)}
  if meta.get("version") == 1 and "weights_sha256" not in meta:
    raise PolicyError(f"{path}: format version 1 (written before the weights checksum); this reader needs "
                      f"version {VERSION} with 'weights_sha256': if you trust the weights, "
                      "sims.rl.policy.add_checksum(folder) adds it")
  keys = {"format", "version", "hidden_sizes", "activation", "observation_size", "action_size", "env_config",
          "robots_per_world", "episode_length", "trainer", "jax", "extra", "weights_sha256"}
  unknown, missing = sorted(set(meta) - keys), sorted(keys - set(meta))
  if unknown:
    raise PolicyError(f"{path}: unknown key {unknown[0]!r}; expected exactly {sorted(keys)}")
  if missing:
    raise PolicyError(f"{path}: missing key {missing[0]!r}; expected exactly {sorted(keys)}")

  def bad(key, want):
    return PolicyError(f"{path}: {key!r} must be {want}; got {_short(meta[key])}")

  if meta["format"] != FORMAT:
    raise bad("format", repr(FORMAT))
  if not _is_int(meta["version"]) or meta["version"] not in (2, VERSION):
    raise bad("version", f"{VERSION} (this reader's format version) or 2")
  h = meta["hidden_sizes"]
  if not isinstance(h, list) or not 1 <= len(h) <= MAX_LAYERS or \
      not all(_is_int(x) and 1 <= x <= MAX_HIDDEN for x in h):
    raise bad("hidden_sizes", f"a list of 1 to {MAX_LAYERS} integers in [1, {MAX_HIDDEN}]")
  if not isinstance(meta["activation"], str) or meta["activation"] not in ACTIVATIONS:
    raise bad("activation", f"one of {sorted(ACTIVATIONS)}")
  for key, most in _SIZE_BOUNDS.items():
    if not _is_int(meta[key]) or not 1 <= meta[key] <= most:
      raise bad(key, f"an integer in [1, {most:,d}]")
  sha = meta["weights_sha256"]
  if not isinstance(sha, str) or len(sha) != 64 or any(c not in "0123456789abcdef" for c in sha):
    raise bad("weights_sha256", f"the SHA-256 of {MSGPACK_NAME} as 64 lowercase hex digits")
  for key in ("trainer", "jax"):
    if not isinstance(meta[key], str) or len(meta[key]) > 200:
      raise bad(key, "a string of at most 200 characters")
  if not isinstance(meta["extra"], dict) or not _json_value_ok(meta["extra"]):
    raise bad("extra", "an object of JSON values with finite numbers, nested at most 8 deep")
  env = meta["env_config"]
  if not isinstance(env, dict):
    raise bad("env_config", "an object of NavEnvConfig fields")
  if meta["version"] == 2:      # written before NavEnvConfig.agents: every version-2 policy drives one world
    if "agents" in env:
      raise PolicyError(f"{path}: 'env_config' has field 'agents', which format version 2 does not have "
                        f"(version {VERSION} does)")
    env = {**env, "agents": "world"}
    meta = {**meta, "env_config": env}
  unknown, missing = sorted(set(env) - set(defaults)), sorted(set(defaults) - set(env))
  if unknown or missing:
    which = f"unknown field {unknown[0]!r}" if unknown else f"missing field {missing[0]!r}"
    raise PolicyError(f"{path}: 'env_config' has {which}; expected the NavEnvConfig fields {sorted(defaults)}")
  for name, default in defaults.items():
    v = env[name]
    if isinstance(default, bool):
      ok, want = isinstance(v, bool), "true or false"
    elif isinstance(default, str):
      ok, want = isinstance(v, str), "a string"
    elif _is_int(default):     # counts such as crop_cells: bounded so the env stays buildable
      ok, want = _is_int(v) and 0 <= v <= MAX_CONFIG_INT, f"an integer in [0, {MAX_CONFIG_INT}]"
    elif isinstance(default, float):     # float32 terms are NavEnvConfig's check, below
      ok, want = _is_number(v), "a finite number"
    else:                      # a list field (a tuple in NavEnvConfig): JSON values, checked by NavEnvConfig
      ok, want = isinstance(v, list) and _json_value_ok(v), "a list of finite numbers"
    if not ok:
      raise PolicyError(f"{path}: env_config.{name} must be {want}; got {_short(v)}")
  try:
    nav_env_config(env)
  except (TypeError, ValueError) as e:
    raise PolicyError(f"{path}: env_config: {str(e).splitlines()[0]}") from None
  return meta


def read_policy_msgpack(path: Path, meta: dict) -> dict:
  """`policy.msgpack` read and checked against the architecture in `meta` (from `read_policy_json`).

  Returns:
    {"actor": params tree, "obs_mean": ..., "obs_var": ...} of float32 NumPy arrays.

  Raises:
    PolicyError: see `load_policy`.
  """
  raw = _read(path, msgpack_size_bound(meta["hidden_sizes"], meta["observation_size"], meta["action_size"]))
  digest = hashlib.sha256(raw).hexdigest()
  if digest != meta["weights_sha256"]:
    raise PolicyError(f"{path}: SHA-256 {digest[:16]}... differs from weights_sha256 {meta['weights_sha256'][:16]}... "
                      f"in {JSON_NAME}: the weights were changed or damaged after they were saved")
  return _decode_tree(raw, meta, str(path))


def _decode_tree(raw: bytes, meta: dict, path: str) -> dict:
  from flax import serialization
  try:
    tree = serialization.msgpack_restore(raw)
  except Exception as e:  # noqa: BLE001 - the msgpack decoder raises many types on damaged bytes
    raise PolicyError(f"{path}: not a flax msgpack file ({type(e).__name__}: "
                      f"{str(e).splitlines()[0][:150] if str(e) else ''})") from None
  _check_tree(tree, meta, path)
  return tree


def _flatten(tree, prefix: str, out: dict, path: str, depth: int = 0) -> None:
  if depth > MAX_LAYERS + 4:
    raise PolicyError(f"{path}: nested deeper than a policy's parameter tree")
  for k, v in tree.items():
    if not isinstance(k, str):
      raise PolicyError(f"{path}: a key that is not a string ({_short(k)})")
    name = f"{prefix}{k}"
    if isinstance(v, dict):
      _flatten(v, name + "/", out, path, depth + 1)
    else:
      out[name] = v


def _check_tree(tree, meta: dict, path: str) -> None:
  """Exactly the arrays of the architecture: float32, recorded shapes, finite, variances >= 0."""
  if not isinstance(tree, dict):
    raise PolicyError(f"{path}: expected a map of parameter arrays; got {type(tree).__name__}")
  flat: dict = {}
  _flatten(tree, "", flat, path)
  want = param_shapes(meta["hidden_sizes"], meta["observation_size"], meta["action_size"])
  unknown, missing = sorted(set(flat) - set(want)), sorted(set(want) - set(flat))
  arch = (f"hidden {meta['hidden_sizes']}, observation {meta['observation_size']}, "
          f"action {meta['action_size']} in {JSON_NAME}")
  if unknown:
    raise PolicyError(f"{path}: unexpected array {unknown[0]!r} for the architecture ({arch})")
  if missing:
    raise PolicyError(f"{path}: missing array {missing[0]!r} for the architecture ({arch})")
  for name, shape in want.items():
    a = flat[name]
    if not isinstance(a, np.ndarray) or a.dtype != np.float32:
      kind = f"{a.dtype} array" if isinstance(a, np.ndarray) else type(a).__name__
      raise PolicyError(f"{path}: {name} must be a float32 array of shape {shape}; got a {kind}")
    if a.shape != shape:
      raise PolicyError(f"{path}: {name} has shape {a.shape}; the architecture ({arch}) gives {shape}")
    if not np.isfinite(a).all():
      raise PolicyError(f"{path}: {name} has non-finite values (NaN or inf)")
  if (flat["obs_var"] < 0).any():
    raise PolicyError(f"{path}: obs_var has negative variances")


def _short(v) -> str:
  text = repr(v)
  return text if len(text) <= 80 else text[:77] + "..."


__all__ = ["ACTIVATIONS", "FORMAT", "JSON_NAME", "MAX_ACTION_SIZE", "MAX_CROP_CELLS", "MAX_EPISODE_LENGTH",
           "MAX_HIDDEN", "MAX_JSON_BYTES", "MAX_LAYERS", "MAX_MSGPACK_BYTES", "MAX_OBSERVATION_SIZE", "MAX_ROBOTS",
           "MSGPACK_NAME", "Policy", "PolicyError", "VERSION", "add_checksum", "check_policy_meta", "load_policy",
           "mean_action", "msgpack_size_bound", "nav_env_config", "param_shapes", "read_policy_json",
           "read_policy_msgpack", "save_policy"]
