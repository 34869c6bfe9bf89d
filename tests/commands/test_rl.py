"""`jaxfilters rl train` / `rl eval` through the command line, the policy files, and PPO over 4 devices.

The randomised training smoke test runs in this process through `jaxfilters.cli.main` (sharing
the JAX process, as the fleet CLI tests do); a 4-device run of the same command starts first in a
subprocess (`--xla_force_host_platform_device_count=4`), so the two compile side by side, and is
compared with it at the end: the same env steps, the same learning curve per sample, the same
weights up to float rounding. Networks are tiny (one hidden layer of 16) and every run is 2 PPO
iterations of 4 envs x 8 steps, so the cost is the env's compile; the run is tests/rl_small.py's, whose
programs the other small training runs of the suite share through the session's compilation cache.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import importlib.metadata
import io
import json
import math
import os
import subprocess
import sys
import types
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfilters import cli
from sims.rl import policy as P
from tests import rl_small
from tests.compile_count import count_cache_misses

REPO = Path(__file__).resolve().parents[2]
ASSETS = REPO / "sims" / "assets"
# The suite's one small training run (tests/rl_small.py): 2 PPO iterations, one evaluation after them.
TRAIN_ARGS = ["--timesteps", "64", "--evals", "1", *rl_small.TRAIN_ARGS]
EVAL_KEYS = ("episodes", "success", "goals_per_episode", "keepout_entries", "collisions", "speed_excess_s", "speed_excess_after_clip_s",
             "speed_excess_outside_entry_s",
             "mean_return", "clipped_per_episode", "steps_per_episode", "seed", "map", "randomize", "device",
             "wall_s")


@pytest.fixture(scope="module")
def rl_entry_point(tmp_path_factory) -> str:
  """Makes `jaxfilters rl` available; returns a PYTHONPATH entry for subprocesses ('' if not needed).

  pyproject.toml registers the command; an editable install made before that lacks the entry
  point until `pip install -e .` runs again, so a throwaway distribution naming it is put on
  sys.path instead.
  """
  if any(ep.name == "rl" for ep in importlib.metadata.entry_points(group=cli.ENTRY_POINT_GROUP)):
    yield ""
    return
  root = tmp_path_factory.mktemp("entry_point")
  info = root / "jaxfilters_rl_checkout-0.dist-info"
  info.mkdir()
  (info / "METADATA").write_text("Metadata-Version: 2.1\nName: jaxfilters-rl-checkout\nVersion: 0\n")
  (info / "entry_points.txt").write_text(f"[{cli.ENTRY_POINT_GROUP}]\nrl = sims.commands.rl:register_rl\n")
  sys.path.insert(0, str(root))
  importlib.invalidate_caches()
  yield str(root)
  sys.path.remove(str(root))


def run_cli(argv) -> tuple[int, str, str]:
  out, err = io.StringIO(), io.StringIO()
  with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
    rc = cli.main(argv)
  return rc, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def four_devices(rl_entry_point, tmp_path_factory):
  """`rl train ... --devices 4` started in a subprocess with 4 CPU devices; yields (Popen, out dir)."""
  out = tmp_path_factory.mktemp("dev4") / "pol"
  env = dict(os.environ, JAX_PLATFORMS="cpu", XLA_FLAGS="--xla_force_host_platform_device_count=4",
             PYTHONPATH=os.pathsep.join(p for p in (str(REPO), rl_entry_point) if p))
  proc = subprocess.Popen([sys.executable, "-m", "jaxfilters", "rl", "train", *TRAIN_ARGS, "--devices", "4",
                           "--out", str(out)], cwd=REPO, env=env, stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, text=True)
  yield proc, out
  if proc.poll() is None:
    proc.kill()
    proc.communicate()


@pytest.fixture(scope="module")
def trained(four_devices, tmp_path_factory):
  """The randomised smoke run through the command line: (out dir, stdout, stderr)."""
  out = tmp_path_factory.mktemp("train") / "pol"
  rl_small.fresh_trace_caches()
  rc, stdout, stderr = run_cli(["rl", "train", *TRAIN_ARGS, "--out", str(out)])
  assert rc == 0, stderr
  return out, stdout, stderr


# ----------------------------------------------------------------------------- the smoke test


def test_train_writes_policy_results_and_curve(trained):
  out, stdout, stderr = trained
  assert sorted(p.name for p in out.iterdir()) == sorted(
      ("policy.json", "policy.msgpack", "results.json", "learning_curve.png"))
  progress = [line for line in stderr.splitlines() if "env steps " in line and "steps/s" in line]
  assert len(progress) == 2, stderr                       # before training and after the one call
  for word in ("return", "success", "goals/episode", "keepout entries", "collisions", "speed-excess"):
    assert word in progress[-1]
  res = json.loads((out / "results.json").read_text())
  assert res["env_steps"] == 64 and res["curve"]["env_steps"] == [0.0, 64.0]
  assert res["device"]["count"] == 1 and res["device"]["kind"]
  for key in ("compile_s", "train_s", "wall_s", "env_steps_per_s"):
    assert res["timing"][key] > 0, key
  assert res["config"]["randomize"] is True and res["config"]["hidden"] == [16]
  pol = P.load_policy(out)
  assert pol.hidden_sizes == (16,) and pol.episode_length == 6 and pol.extra["randomize"] is True
  assert "wrote" in stdout


def test_eval_json_has_the_figures(trained, capsys):
  out, _, _ = trained
  rl_small.fresh_trace_caches()          # the text every process lowers for this evaluation
  rc, stdout, stderr = run_cli(["rl", "eval", "--policy", str(out), *rl_small.EVAL_ARGS])
  assert rc == 0, stderr
  lines = stdout.strip().splitlines()
  assert len(lines) == 1
  res = json.loads(lines[0])
  assert set(EVAL_KEYS) <= set(res), sorted(set(EVAL_KEYS) - set(res))
  assert res["episodes"] == rl_small.EVAL_EPISODES and res["seed"] == rl_small.EVAL_SEED and res["randomize"] is True
  assert 0.0 <= res["success"] <= 1.0
  assert res["keepout_entries"] >= 0 and res["collisions"] >= 0 and res["speed_excess_s"] >= 0 and res["speed_excess_after_clip_s"] >= 0
  assert 0 <= res["speed_excess_outside_entry_s"] <= res["speed_excess_s"] * res["episodes"] + 1e-9
  assert isinstance(res["keepout_entries"], int) and isinstance(res["collisions"], int)
  assert 1 <= res["steps_per_episode"] <= 6
  assert all(math.isfinite(res[k]) for k in ("mean_return", "goals_per_episode", "clipped_per_episode"))


def test_eval_of_another_checkpoint_of_the_same_network_compiles_nothing(tmp_path, rl_entry_point):
  # `rl eval` passes the weights to its programs as arguments, not as constants: a second policy of
  # the same architecture on the same env finds every program in the compilation cache. (The small
  # run's network and evaluation: test_eval_json_has_the_figures may have compiled it already.)
  argv = lambda p: ["rl", "eval", "--policy", str(p), *rl_small.EVAL_ARGS]
  first, second = (write_policy(tmp_path / n, seed=s, hidden=rl_small.HIDDEN) for n, s in (("a", 1), ("b", 2)))
  old = jax.config.jax_persistent_cache_min_compile_time_secs
  jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)     # keep every program, however quick
  try:
    rl_small.fresh_trace_caches()
    rc, out_a, stderr = run_cli(argv(first))
    assert rc == 0, stderr
    with count_cache_misses() as misses:
      rc, out_b, stderr = run_cli(argv(second))
    assert rc == 0, stderr
  finally:
    jax.config.update("jax_persistent_cache_min_compile_time_secs", old)
  assert misses() == 0
  assert json.loads(out_a)["mean_return"] != json.loads(out_b)["mean_return"]     # other weights, other actions


def test_four_devices_shard_the_env_batch_and_learn_the_same(trained, four_devices):
  proc, out4 = four_devices
  try:
    stdout, stderr = proc.communicate(timeout=900)
  except subprocess.TimeoutExpired:
    proc.kill()
    pytest.fail("the 4-device training did not finish in 900 s")
  assert proc.returncode == 0, stderr[-2000:]
  out1 = trained[0]
  r1, r4 = (json.loads((o / "results.json").read_text()) for o in (out1, out4))
  assert r4["device"]["count"] == 4
  assert r4["device"]["env_batch"] == ["worlds"] and r4["device"]["envs_per_device"] == 1
  assert r4["device"]["replicas_identical"] is True
  assert r1["device"]["env_batch"] is None and r1["device"]["envs_per_device"] == 4
  assert r4["env_steps"] == r1["env_steps"] == 64
  assert r4["curve"]["env_steps"] == r1["curve"]["env_steps"]
  # The same initial networks and evaluation keys: the evaluation before training agrees up to the
  # order of float sums; after it, each device drew its own minibatches and action noise.
  for key in ("return", "goals_reached", "length"):
    np.testing.assert_allclose(r4["curve"][key][0], r1["curve"][key][0], rtol=1e-5, atol=1e-5, err_msg=key)
  p1, p4 = P.load_policy(out1), P.load_policy(out4)
  flat1, flat4 = jax.tree.leaves(p1.params), jax.tree.leaves(p4.params)
  assert all(np.isfinite(a).all() for a in flat4)
  assert len(flat1) == len(flat4) and all(a.shape == b.shape for a, b in zip(flat1, flat4))
  assert not all(np.array_equal(a, b) for a, b in zip(flat1, flat4))     # trained, on other minibatches


# ----------------------------------------------------------------------------- bad arguments


def write_policy(folder: Path, *, hidden=(4,), obs=98, act=2, meta_edit=None, tree_edit=None, seed=0) -> Path:
  """A valid policy folder with random weights (no training), optionally edited."""
  from flax import serialization

  from sims.rl.env import NavEnvConfig
  from tests.fuzz.fuzz_policy import random_tree
  tree = random_tree(hidden, obs, act, seed, var_floor=0.5)
  meta = {"format": P.FORMAT, "version": P.VERSION, "hidden_sizes": list(hidden), "activation": "tanh",
          "observation_size": obs, "action_size": act, "env_config": dataclasses.asdict(NavEnvConfig()),
          "robots_per_world": 1, "episode_length": 6, "trainer": "rejax.PPO", "jax": jax.__version__,
          "extra": {}}
  if meta_edit:
    meta_edit(meta)
  if tree_edit:
    tree_edit(tree)
  weights = serialization.msgpack_serialize(tree)
  meta.setdefault("weights_sha256", hashlib.sha256(weights).hexdigest())    # a meta_edit may set its own
  folder.mkdir(parents=True, exist_ok=True)
  (folder / P.JSON_NAME).write_text(json.dumps(meta))
  (folder / P.MSGPACK_NAME).write_bytes(weights)
  return folder


def _bad_inputs(tmp: Path) -> dict:
  fifo_dir = tmp / "fifo_pol"
  fifo_dir.mkdir()
  os.mkfifo(fifo_dir / "policy.json")
  os.mkfifo(tmp / "fifo")
  (tmp / "empty_pol").mkdir()
  corrupt = write_policy(tmp / "corrupt")
  (corrupt / "policy.json").write_text('{"format": "jaxfilters-policy", ')
  full = tmp / "full"
  full.mkdir()
  (full / "notes.txt").write_text("mine")
  return {"tmp": tmp, "fifo_pol": fifo_dir, "fifo": tmp / "fifo", "empty_pol": tmp / "empty_pol",
          "corrupt": corrupt, "full": full, "obs50": write_policy(tmp / "obs50", obs=50),
          "ok": write_policy(tmp / "ok")}


TRAIN = "rl train --timesteps 64 --num-envs 4 --num-steps 8 --evals 1"
BAD = [
    ("rl eval --policy {ok} --episodes 0", "argument --episodes: must lie in [1, 262,144]; got 0"),
    (TRAIN + " --num-envs 0 --out {tmp}/o", "argument --num-envs: must lie in [1, 2,097,152]; got 0"),
    (TRAIN + " --timesteps -1 --out {tmp}/o", "argument --timesteps: must lie in [1, 1,073,741,824]; got -1"),
    (TRAIN + " --devices 3 --out {tmp}/o", "--num-envs (4) must be a multiple of --devices (3)"),
    (TRAIN + " --devices 0 --out {tmp}/o", "--devices must be >= 1"),
    (TRAIN + " --devices many --out {tmp}/o", "--devices must be a positive integer or 'all'"),
    (TRAIN + " --hidden 16,x --out {tmp}/o", "--hidden must be comma-separated integers"),
    (TRAIN + " --minibatches 5 --out {tmp}/o", "--minibatches (5) must divide"),
    (TRAIN + " --num-steps 2 --minibatches 8 --devices 4 --out {tmp}/o",
     "--minibatches (8) must divide each device's batch, --num-envs / --devices x --num-steps (1 x 2)"),
    (TRAIN + " --out {full}", "not empty and not an earlier policy folder"),
    (TRAIN + " --seed x --out {tmp}/o", "argument --seed: invalid int value"),
    ("rl eval --policy {ok} --seed -1", "argument --seed: must lie in [0, 4,294,967,295]; got -1"),
    ("rl eval --policy {tmp}/missing", "does not exist"),
    ("rl eval --policy {fifo}", "is not a directory"),
    ("rl eval --policy {fifo_pol}", "is a FIFO, not a regular file"),
    ("rl eval --policy {empty_pol}", "policy.json does not exist"),
    ("rl eval --policy {corrupt}", "not valid JSON"),
    ("rl eval --policy {obs50}", "the policy expects observations of 50 values"),
    ("rl eval --policy {ok} --map " + str(ASSETS / "default_map.yaml"), "give all three of --map, --keepout and"),
    ("rl eval --policy {ok} --mask a=b.yaml", "--mask needs --params"),
    ("rl eval", "the following arguments are required: --policy"),
]


@pytest.fixture(scope="module")
def bad_inputs(tmp_path_factory, rl_entry_point):
  return _bad_inputs(tmp_path_factory.mktemp("bad"))


@pytest.mark.parametrize("argv, message", BAD, ids=[b[1][:40] for b in BAD])
def test_bad_arguments_exit_2_with_one_line(argv, message, bad_inputs):
  rc, stdout, stderr = run_cli(argv.format(**bad_inputs).split())
  lines = [line for line in stderr.splitlines() if line.strip()]
  assert rc == 2, (argv, stderr)
  assert len(lines) == 1 and message in lines[0], (argv, stderr)
  assert "Traceback" not in stderr and not (bad_inputs["tmp"] / "o").exists()


def test_help_texts_have_examples_exit_codes_and_every_option_explained(rl_entry_point):
  parser = cli.build_parser()
  for sub in ("train", "eval"):
    rc, stdout, _ = run_cli(["rl", sub, "--help"])
    assert rc == 0 and f"usage: jaxfilters rl {sub}" in stdout
    assert "examples:" in stdout and "exit codes:" in stdout and f"jaxfilters rl {sub} --" in stdout
  rl = next(a for a in parser._actions if a.dest == "command").choices["rl"]       # noqa: SLF001 - argparse's
  for sub, p in next(a for a in rl._actions if a.dest == "rl_command").choices.items():  # noqa: SLF001
    missing = [a.option_strings for a in p._actions if not a.help]               # noqa: SLF001
    assert not missing, (sub, missing)


def test_out_folder_of_an_earlier_run_is_accepted(tmp_path):
  from sims.commands.rl import check_out_dir
  write_policy(tmp_path / "pol")
  (tmp_path / "pol" / "results.json").write_text("{}")
  check_out_dir(tmp_path / "pol", overwrite=False)               # an earlier run's files only
  (tmp_path / "pol" / "mine.txt").write_text("x")
  with pytest.raises(cli.CliError, match="not empty"):
    check_out_dir(tmp_path / "pol", overwrite=False)
  check_out_dir(tmp_path / "pol", overwrite=True)


# ----------------------------------------------------------------------------- policy files


def test_save_load_round_trip_acts_like_the_train_state(tmp_path):
  from sims.rl.ppo import GymnaxAdapter, make_ppo, mean_policy
  from sims.rl.randomization import training_env
  env, _ = training_env(None, randomize=False, seed=0)
  adapter = GymnaxAdapter(env, 6)
  algo = make_ppo(adapter, timesteps_per_call=32, num_envs=4, num_steps=8, hidden=(16, 8))
  d = env.observation_size
  key = jax.random.PRNGKey(1)
  params = algo.actor.init(key, jnp.zeros((1, d)), key)
  params = jax.tree.map(lambda a: a + 0.3 * jax.random.normal(key, a.shape), params)   # no zero biases
  k1, k2, k3 = jax.random.split(key, 3)
  rms = types.SimpleNamespace(mean=jax.random.normal(k1, (d,)), var=jax.random.uniform(k2, (d,), minval=0.1))
  ts = types.SimpleNamespace(actor_ts=types.SimpleNamespace(params=params), obs_rms_state=rms)
  P.save_policy(tmp_path / "p", algo, ts, env_config=env.nav_config, fleet_config=env.fleet_config,
                episode_length=6, extra={"seed": 1, "note": "round trip"})
  pol = P.load_policy(tmp_path / "p")
  assert (pol.hidden_sizes, pol.activation, pol.observation_size, pol.action_size) == ((16, 8), "tanh", d, 2)
  assert pol.env_config == env.nav_config and pol.robots_per_world == 1 and pol.extra["note"] == "round trip"
  obs = 3.0 * jax.random.normal(k3, (64, d))
  want = jnp.stack([mean_policy(algo, ts)(o) for o in obs])
  got = jax.jit(pol.act)(obs)
  np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=1e-5, atol=1e-6)
  assert np.abs(np.asarray(got)).max() <= 1.0 and np.ptp(np.asarray(got)) > 0.1   # clipped, not constant


def _set(path, value):
  def edit(d):
    *parents, leaf = path.split("/")
    for k in parents:
      d = d[k]
    if value is KeyError:
      del d[leaf]
    else:
      d[leaf] = value
  return edit


POLICY_ERRORS = [
    ({"meta_edit": _set("version", 4)}, "'version' must be 3 (this reader's format version) or 2"),
    ({"meta_edit": _set("version", 2)}, "'env_config' has field 'agents', which format version 2 does not have"),
    ({"meta_edit": _set("env_config/agents", KeyError)}, "'env_config' has missing field 'agents'"),
    ({"meta_edit": _set("env_config/agents", "robot")}, "env_config: NavEnvConfig.agents must be one of"),
    ({"meta_edit": _set("env_config/agents", 1)}, "env_config.agents must be a string"),
    ({"meta_edit": _set("hidden_sizes", [4, 0])}, "'hidden_sizes' must be"),
    ({"meta_edit": _set("observation_size", True)}, "'observation_size' must be an integer"),
    ({"meta_edit": _set("activation", "softsign")}, "'activation' must be one of"),
    ({"meta_edit": _set("surprise", 1)}, "unknown key 'surprise'"),
    ({"meta_edit": _set("trainer", KeyError)}, "missing key 'trainer'"),
    ({"meta_edit": _set("env_config/new_field", 1.0)}, "'env_config' has unknown field 'new_field'"),
    ({"meta_edit": _set("env_config/goal_bonus", KeyError)}, "'env_config' has missing field 'goal_bonus'"),
    ({"meta_edit": _set("env_config/goal_bonus", "5")}, "env_config.goal_bonus must be a finite number"),
    ({"meta_edit": _set("env_config/crop_cells", 10)}, "env_config: NavEnvConfig.crop_cells must be an odd"),
    ({"meta_edit": _set("env_config/crop_cells", 10 ** 6 + 1)}, "env_config.crop_cells must be an integer in"),
    ({"meta_edit": _set("hidden_sizes", [5])}, "has shape (98, 4); the architecture"),
    ({"tree_edit": _set("obs_var", KeyError)}, "missing array 'obs_var'"),
    ({"tree_edit": _set("actor/params/extra", np.zeros(2, np.float32))}, "unexpected array 'actor/params/extra'"),
    ({"tree_edit": _set("obs_mean", np.full(98, np.nan, np.float32))}, "obs_mean has non-finite values"),
    ({"tree_edit": _set("obs_var", -np.ones(98, np.float32))}, "obs_var has negative variances"),
    ({"tree_edit": _set("obs_mean", np.zeros(98, np.float64))}, "must be a float32 array of shape (98,)"),
    ({"tree_edit": _set("obs_mean", 1.5)}, "must be a float32 array"),
]


@pytest.mark.parametrize("edits, message", POLICY_ERRORS, ids=[e[1][:40] for e in POLICY_ERRORS])
def test_policy_errors_name_the_file_and_the_expectation(tmp_path, edits, message):
  folder = write_policy(tmp_path / "p", **edits)
  with pytest.raises(P.PolicyError) as info:
    P.load_policy(folder)
  text = str(info.value)
  assert message in text and str(folder) in text and len(text) < 600, text


def test_policy_files_are_checked_before_reading(tmp_path):
  folder = write_policy(tmp_path / "p")
  P.load_policy(folder)                                          # the valid one loads
  with open(folder / "policy.msgpack", "r+b") as f:              # sparse: over the cap without writing it
    f.truncate(P.MAX_MSGPACK_BYTES + 1)
  with pytest.raises(P.PolicyError, match="policy.msgpack"):
    P.load_policy(folder)
  write_policy(folder)
  (folder / "policy.msgpack").write_bytes(b"\xc1garbage")
  with pytest.raises(P.PolicyError, match="changed or damaged"):        # the checksum in policy.json
    P.load_policy(folder)
  write_policy(folder, meta_edit=_set("weights_sha256", hashlib.sha256(b"\xc1garbage").hexdigest()))
  (folder / "policy.msgpack").write_bytes(b"\xc1garbage")
  with pytest.raises(P.PolicyError, match="not a flax msgpack file"):
    P.load_policy(folder)
  write_policy(folder)
  (folder / "policy.json").write_text((folder / "policy.json").read_text().replace(f'"version": {P.VERSION}', '"version": NaN'))
  with pytest.raises(P.PolicyError, match="not valid JSON"):
    P.load_policy(folder)
  (folder / "policy.json").write_text('{"format": "a", "format": "b"}')
  with pytest.raises(P.PolicyError, match="appears twice"):
    P.load_policy(folder)
  with pytest.raises(P.PolicyError, match="is not a directory"):
    P.load_policy(folder / "policy.json")
  assert issubclass(P.PolicyError, ValueError)


def test_fuzz_targets_accept_their_seeds():
  from tests.fuzz import fuzz_policy
  for data in fuzz_policy.json_seeds():
    fuzz_policy.run_json(data)
  for data in fuzz_policy.msgpack_seeds():
    fuzz_policy.run_msgpack(data)
