"""Policy files: what `rl train` can write, `rl eval` loads; every policy.json field that sizes work
is bounded; env_config floats are checked in float32; a checksum guards the weights; evaluation
reports NaN actions and refuses a policy whose actions are not finite.

Policies are written with `save_policy` from random weights (no training); the two command-line
cases compile the RL env's reset and one short evaluation.
"""

from __future__ import annotations

import json
import types
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfilters import cli
from sims.rl import policy as P
from sims.rl.env import NavEnvConfig
from tests.fuzz.fuzz_policy import random_tree
from tests import rl_small
from tests.cli_run import run_cli

REPO = Path(__file__).resolve().parents[2]


def fake_run(hidden, obs, act, *, activation=jax.nn.tanh, seed=0, tree_edit=None):
  """(algo, train state) as save_policy reads them, with random weights of the architecture."""
  tree = random_tree(tuple(hidden), obs, act, seed, var_floor=0.5)
  if tree_edit:
    tree_edit(tree)
  actor = types.SimpleNamespace(activation=activation, hidden_layer_sizes=tuple(hidden), action_dim=act)
  algo = types.SimpleNamespace(actor=actor, normalize_observations=True)
  ts = types.SimpleNamespace(actor_ts=types.SimpleNamespace(params=tree["actor"]),
                             obs_rms_state=types.SimpleNamespace(mean=tree["obs_mean"], var=tree["obs_var"]))
  return algo, ts


def save(folder, hidden=(4,), obs=98, act=2, *, episode_length=6, env_config=None, robots=1, **kw):
  algo, ts = fake_run(hidden, obs, act, **kw)
  return P.save_policy(folder, algo, ts, env_config=env_config or NavEnvConfig(),
                       fleet_config=types.SimpleNamespace(robots_per_world=robots), episode_length=episode_length)


def edit_json(folder, **changes):
  meta = json.loads((folder / P.JSON_NAME).read_text())
  for key, value in changes.items():
    target = meta
    *parents, leaf = key.split("__")
    for k in parents:
      target = target[k]
    target[leaf] = value
  (folder / P.JSON_NAME).write_text(json.dumps(meta))


def refused(folder, *words):
  with pytest.raises(P.PolicyError) as info:
    P.load_policy(folder)
  text = str(info.value)
  assert str(folder) in text and all(w in text for w in words) and len(text) < 600, text
  return text


# ----------------------------------------------------------------------------- what train writes, eval loads


@pytest.mark.parametrize("hidden, obs, act", [
    ((P.MAX_HIDDEN,) * P.MAX_LAYERS, 98, 2),                                      # rl train --hidden's corner
    ((P.MAX_HIDDEN,) * P.MAX_LAYERS, P.MAX_OBSERVATION_SIZE, P.MAX_ACTION_SIZE),  # the loader's corner
    ((1,), 1, 1),
    ((P.MAX_HIDDEN,), P.MAX_OBSERVATION_SIZE, 2),
])
def test_save_at_the_accepted_corners_loads(tmp_path, hidden, obs, act):
  folder = save(tmp_path / "p", hidden, obs, act, episode_length=P.MAX_EPISODE_LENGTH)
  size = (folder / P.MSGPACK_NAME).stat().st_size
  assert size <= P.msgpack_size_bound(hidden, obs, act) <= P.MAX_MSGPACK_BYTES
  pol = P.load_policy(folder)
  assert pol.hidden_sizes == tuple(hidden) and (pol.observation_size, pol.action_size) == (obs, act)
  assert pol.episode_length == P.MAX_EPISODE_LENGTH


def test_rl_train_hidden_range_is_the_loaders():
  from sims.commands.rl import parse_hidden
  biggest = ",".join([str(P.MAX_HIDDEN)] * P.MAX_LAYERS)
  assert parse_hidden(biggest) == (P.MAX_HIDDEN,) * P.MAX_LAYERS
  for text in ("2048,2048", f"{P.MAX_HIDDEN + 1}", ",".join(["8"] * (P.MAX_LAYERS + 1))):
    with pytest.raises(cli.CliError, match="--hidden must give 1 to"):
      parse_hidden(text)


def test_save_refuses_what_load_would_refuse(tmp_path):
  with pytest.raises(ValueError, match="hidden_sizes"):
    save(tmp_path / "big", (2048, 2048))
  with pytest.raises(ValueError, match="episode_length"):
    save(tmp_path / "long", episode_length=P.MAX_EPISODE_LENGTH + 1)
  assert not (tmp_path / "big").exists() and not (tmp_path / "long").exists()


# ----------------------------------------------------------------------------- bounds of policy.json


@pytest.mark.parametrize("key, value", [
    ("episode_length", 1_048_576), ("episode_length", P.MAX_EPISODE_LENGTH + 1),
    ("robots_per_world", P.MAX_ROBOTS + 1), ("observation_size", P.MAX_OBSERVATION_SIZE + 1),
    ("action_size", P.MAX_ACTION_SIZE + 1), ("hidden_sizes", [4, 4, 4, 4, 4]), ("hidden_sizes", [1025]),
])
def test_fields_that_size_work_are_bounded(tmp_path, key, value):
  folder = save(tmp_path / "p")
  edit_json(folder, **{key: value})
  refused(folder, repr(key), "must be")


def test_crop_cells_is_bounded(tmp_path):
  folder = save(tmp_path / "p")
  edit_json(folder, env_config__crop_cells=P.MAX_CROP_CELLS + 2)
  refused(folder, "env_config.crop_cells must be an integer in [0, 63]")


@pytest.mark.parametrize("key, value", [
    ("goal_bonus", 1e-45),            # subnormal in float32
    ("crop_spacing", 1e-50),          # 0 in float32, where > 0 is needed
    ("speed_penalty", 1e39),          # inf in float32
    ("time_penalty", 3e38),           # finite, but rewards summed over an episode overflow
])
def test_env_config_floats_are_checked_in_float32(tmp_path, key, value):
  folder = save(tmp_path / "p")
  edit_json(folder, **{f"env_config__{key}": value})
  refused(folder, f"NavEnvConfig.{key} must be 0 or a normal float32")
  with pytest.raises(ValueError, match=key):
    NavEnvConfig(**{key: value})
  NavEnvConfig(**{key: 0.0 if key != "crop_spacing" else 0.5})


# ----------------------------------------------------------------------------- checksum


def test_flipped_weight_bytes_are_refused(tmp_path):
  folder = save(tmp_path / "p", (16,))
  P.load_policy(folder)
  raw = bytearray((folder / P.MSGPACK_NAME).read_bytes())
  rng = np.random.default_rng(0)
  for i in rng.choice(np.arange(len(raw) // 2, len(raw)), 20, replace=False):   # inside the weights
    raw[i] ^= 0x5A
  (folder / P.MSGPACK_NAME).write_bytes(bytes(raw))
  refused(folder, str(folder / P.MSGPACK_NAME), "SHA-256", "changed or damaged")


def test_version_1_files_are_refused_until_a_checksum_is_added(tmp_path):
  folder = save(tmp_path / "p")
  meta = json.loads((folder / P.JSON_NAME).read_text())
  del meta["weights_sha256"]
  meta["version"] = 1
  (folder / P.JSON_NAME).write_text(json.dumps(meta))
  weights = (folder / P.MSGPACK_NAME).read_bytes()
  refused(folder, "version 1", "add_checksum")
  P.add_checksum(folder)
  assert P.load_policy(folder).hidden_sizes == (4,)
  assert (folder / P.MSGPACK_NAME).read_bytes() == weights
  edit_json(folder, weights_sha256="ab" * 32)
  refused(folder, "SHA-256")
  edit_json(folder, weights_sha256="not hex")
  refused(folder, "'weights_sha256' must be the SHA-256")


def test_shipped_example_policy_has_its_checksum():
  pol = P.load_policy(REPO / "examples" / "ppo_nav")
  assert pol.hidden_sizes == (64, 64) and pol.observation_size == 98
  # A version-2 file (written before NavEnvConfig.agents) drives one world.
  assert json.loads((REPO / "examples" / "ppo_nav" / P.JSON_NAME).read_text())["version"] == 2
  assert pol.env_config.agents == "world" and pol.robots_per_world == 1


def test_per_robot_policies_load_with_their_mode(tmp_path):
  folder = save(tmp_path / "p", env_config=NavEnvConfig(agents="per_robot"), robots=8)
  assert json.loads((folder / P.JSON_NAME).read_text())["env_config"]["agents"] == "per_robot"
  pol = P.load_policy(folder)
  assert pol.env_config.agents == "per_robot" and pol.robots_per_world == 8


# ----------------------------------------------------------------------------- NaN actions


def nan_weights(tree):
  """relu(bias 3e38) @ (+-3e38) overflows float32 (inf, or inf - inf = NaN, by the order of the sum)
  for every observation, from finite weights."""
  layer = tree["actor"]["params"]["features"]["Dense_0"]
  layer["kernel"][:] = 0.0
  layer["bias"][:] = 3e38
  head = tree["actor"]["params"]["action_mean"]
  head["kernel"][:] = np.array([[3e38], [-3e38]], np.float32)
  head["bias"][:] = 0.0


def test_raw_action_shows_the_nan_the_clip_hides(tmp_path):
  folder = save(tmp_path / "p", (2,), activation=jax.nn.relu, tree_edit=nan_weights)
  pol = P.load_policy(folder)
  obs = np.random.default_rng(1).uniform(-1, 1, (5, 98)).astype(np.float32)
  assert not np.isfinite(np.asarray(pol.raw_action(obs))).any()
  assert np.isfinite(np.asarray(pol.act(obs))).all()        # the clip turns inf into +-1: it hides the fault
  ok = P.load_policy(save(tmp_path / "q", (2,)))
  np.testing.assert_array_equal(np.clip(np.asarray(ok.raw_action(obs)), -1, 1), np.asarray(ok.act(obs)))


def test_evaluation_counts_nan_action_steps():
  from sims.rl.ppo import GymnaxAdapter, evaluate_policy
  from sims.rl.env import NavEnv
  adapter = GymnaxAdapter(NavEnv.create(), 3)
  nan_always = lambda obs: jnp.full((2,), jnp.nan, jnp.float32)
  with jax.numpy_rank_promotion("allow"):
    out = jax.jit(lambda k: evaluate_policy(adapter, nan_always, k, 2))(jax.random.PRNGKey(0))
  np.testing.assert_array_equal(np.asarray(out["bad_action"]), np.asarray(out["length"]))
  assert np.all(np.asarray(out["length"]) >= 1)


def inf_weights(tree):
  """tanh(bias 3e38) = 1 in every hidden unit, two of them weighted +-3e38 into each action: +inf and
  -inf for every observation (float32 overflow), from finite weights."""
  layer = tree["actor"]["params"]["features"]["Dense_0"]
  layer["kernel"][:] = 0.0
  layer["bias"][:] = 3e38
  head = tree["actor"]["params"]["action_mean"]
  head["kernel"][:] = 0.0
  head["kernel"][:2] = np.array([3e38, -3e38], np.float32)
  head["bias"][:] = 0.0


def test_rl_eval_refuses_non_finite_actions_and_reports_bad_action_steps(tmp_path):
  # The suite's small run's network and evaluation (tests/rl_small.py): both policies run the program
  # `rl eval` of the trained policy compiles (tests/commands/test_rl.py), from the session's cache.
  bad = save(tmp_path / "bad", rl_small.HIDDEN, tree_edit=inf_weights, episode_length=rl_small.EPISODE_LENGTH)
  rl_small.fresh_trace_caches()          # this worker's tracing history would change the program's text
  rc, stdout, stderr = run_cli(["rl", "eval", "--policy", str(bad), *rl_small.EVAL_ARGS])
  lines = stderr.strip().splitlines()
  n = rl_small.EVAL_EPISODES
  assert rc == 2 and len(lines) == 1 and f"actions are not finite (NaN or inf) on {n} of the {n}" in lines[0], stderr
  assert stdout == ""
  good = save(tmp_path / "good", rl_small.HIDDEN, episode_length=rl_small.EPISODE_LENGTH)
  rc, stdout, stderr = run_cli(["rl", "eval", "--policy", str(good), *rl_small.EVAL_ARGS])
  assert rc == 0, stderr
  assert json.loads(stdout)["bad_action_steps"] == 0
