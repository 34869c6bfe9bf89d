"""sims/scale/sharding.py: sharded rollouts equal unsharded ones; `jaxfilters fleet --devices`; two processes.

The test process has already started JAX with one CPU device, so every check
runs in a fresh subprocess with XLA_FLAGS=--xla_force_host_platform_device_count=4:
one process for the sharded rollouts, the mesh errors and the command line, and
2 x 4 devices for the jax.distributed run. All of them use the same XLA flags, so
the later processes load the world-building programs the first one compiled from
the session's compilation cache (tests/conftest.py). Integer outputs (goals, goal
counts, keepout entries, stuck events, the recorded goals of every step) must be
equal exactly.
"""

import json
import os
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
WORLDS, STEPS, K = 8, 4, 2
DEVICES = 4                  # CPU devices of every subprocess


def _env() -> dict:
  env = dict(os.environ)
  env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "") + f" --xla_force_host_platform_device_count={DEVICES}").strip()
  env["JAX_PLATFORMS"] = "cpu"
  env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
  return env


SINGLE = f"""
import jaxfilters  # noqa: F401  (first: importing it sets the XLA:CPU flags, jaxfilters/xla_flags.py)
import contextlib, io, json, sys
import jax, jax.numpy as jnp, numpy as np
from sims.scale import sharding
from sims.fleet.config import FleetConfig
from sims.fleet.env import FleetEnv

assert len(jax.devices()) == {DEVICES}, jax.devices()
out = {{}}
env = FleetEnv.create(config=FleetConfig(robots_per_world={K}))
keys = env.world_keys(jax.random.PRNGKey(0), {WORLDS})
plain = env.rollout_fn({STEPS})(env.params, env.reset_fn()(env.params, keys))
ref = {{k: np.asarray(v) for k, v in sharding.integer_outputs(*plain).items()}}
np.savez(sys.argv[1], **ref)

mesh = sharding.make_mesh({DEVICES})
s0 = env.reset_fn(mesh=mesh)(sharding.put_global(env.params, sharding.replicated(mesh)),
                              sharding.put_global(keys, sharding.worlds_sharding(mesh)))
roll = env.rollout_fn({STEPS}, mesh=mesh)
states, frames = roll(env.params, s0)
# Communication: worlds and envs are independent, so a sharded step moves no per-world data between
# devices. Collective ops in the compiled programs: an all-gather or all-to-all would copy the batch.
import re
def collectives(compiled):
  found = re.findall(r"= (.+?) (all-gather|all-to-all|collective-permute|reduce-scatter|all-reduce)(?:-start)?\\(",
                     compiled.as_text())
  return sorted({{f"{{kind}} {{shape[:40]}}" for shape, kind in found}})
# Lowered right after the call, from the same traced rollout: the call's executable, not a second compile.
out["fleet_collectives"] = collectives(roll.lower(env.params, s0).compile())
got = sharding.integer_outputs(states, frames)
out["equal"] = {{k: bool(np.array_equal(np.asarray(v), ref[k])) for k, v in got.items()}}
out["pose_max_diff"] = float(np.max(np.abs(np.asarray(frames.pose) - np.asarray(plain[1].pose))))
out["state_devices"] = len(states.goal.sharding.device_set)
out["state_spec"] = list(states.goal.sharding.spec)
out["frame_spec"] = list(frames.goal.sharding.spec)
out["shard_shape"] = list(states.goal.addressable_shards[0].data.shape)
out["nonzero_goals"] = int(ref["goals_reached"].sum() + (ref["frame_goal"] != ref["frame_goal"][:1]).sum())

# The RL env: reset and 3 steps of vmap(step), sharded over 4 devices vs unsharded.
from sims.rl.env import NavEnv
rl = NavEnv.create()
rkeys = jax.random.split(jax.random.PRNGKey(1), 8)
acts = jnp.tile(jnp.asarray([[1.0, 0.3]]), (8, 1))
res = {{}}
for name, devices in (("plain", None), ("sharded", 4)):
  reset, step = sharding.rl_batch_fns(rl, devices=devices)
  s = start = reset(rkeys)
  for _ in range(3):
    s = step(s, acts)
  res[name] = s
out["rl_devices"] = len(res["sharded"].obs.sharding.device_set)
out["rl_goal_equal"] = bool(np.array_equal(np.asarray(res["plain"].info["goal"]), np.asarray(res["sharded"].info["goal"])))
out["rl_done_equal"] = bool(np.array_equal(np.asarray(res["plain"].done), np.asarray(res["sharded"].done)))
out["rl_obs_max_diff"] = float(np.max(np.abs(np.asarray(res["plain"].obs) - np.asarray(res["sharded"].obs))))
out["rl_moved"] = float(np.min(np.linalg.norm(np.asarray(s.data.qpos[:, 0, :2])
                                              - np.asarray(start.data.qpos[:, 0, :2]), axis=-1)))

# The RL env's reset in its randomised training layouts (drawn spawn points), run at every auto-reset.
from sims.rl.randomization import training_env
from sims.rl.env import NavEnvConfig
renv, _ = training_env(None, randomize=True, seed=0, layouts=1, config=NavEnvConfig())
w = sharding.worlds_sharding(mesh)
rk = jax.device_put(jax.random.split(jax.random.PRNGKey(2), 8), w)
out["rl_reset_collectives"] = collectives(jax.jit(jax.vmap(renv.reset), in_shardings=w, out_shardings=w)
                                          .lower(rk).compile())
# The same reset with jax.lax.top_k for the spawn draw: the check sees the gather it adds.
from sims.fleet import topk
real_top_k = topk.top_k
topk.top_k = jax.lax.top_k
try:
  out["rl_reset_collectives_lax_top_k"] = collectives(jax.jit(jax.vmap(renv.reset), in_shardings=w, out_shardings=w)
                                                      .lower(rk).compile())
finally:
  topk.top_k = real_top_k

# Mesh errors.
errs = []
for bad in (0, {DEVICES + 1}, "most"):
  try:
    sharding.make_mesh(bad)
  except ValueError as e:
    errs.append(str(e))
try:
  sharding.check_divisible(6, sharding.make_mesh(4))
except ValueError as e:
  errs.append(str(e))
out["errors"] = errs

# The command line, in this process: three bad --devices (exit 2) and one run over all devices.
from jaxfilters import cli
codes, err = [], io.StringIO()
with contextlib.redirect_stderr(err):
  for argv in (["fleet", "--devices", "3", "--robots", "8", "--robots-per-world", "2", "--steps", "1"],
               ["fleet", "--devices", "{DEVICES + 1}", "--robots", "8", "--robots-per-world", "2", "--steps", "1"],
               ["fleet", "--devices", "two", "--robots", "8", "--steps", "1"]):
    codes.append(cli.main(argv))
  # The rollout's shapes above (8 worlds x {K} robots, {STEPS} steps): the sharded programs come from the cache.
  codes.append(cli.main(["fleet", "--devices", "all", "--robots", "{WORLDS * K}", "--robots-per-world", "{K}",
                         "--steps", "{STEPS}", "--out", sys.argv[2], "--no-cache", "--record-robots", "2"]))
out["cli_codes"] = codes
out["cli_stderr"] = err.getvalue()
print("RESULT " + json.dumps(out))
"""


@pytest.fixture(scope="module")
def single(tmp_path_factory):
  """One 4-device process: (its RESULT dict, the unsharded reference npz, the CLI run's out folder)."""
  folder = tmp_path_factory.mktemp("shard")
  ref, fleet_out = folder / "ref.npz", folder / "fleet"
  r = subprocess.run([sys.executable, "-c", textwrap.dedent(SINGLE), str(ref), str(fleet_out)], env=_env(), cwd=ROOT,
                     capture_output=True, text=True, timeout=900)
  assert r.returncode == 0, r.stderr[-3000:]
  line = [l for l in r.stdout.splitlines() if l.startswith("RESULT ")][-1]
  return json.loads(line[len("RESULT "):]), ref, fleet_out


def test_sharded_fleet_rollout_equals_unsharded(single):
  out, _, _ = single
  assert out["equal"] == {k: True for k in ("goal", "goals_reached", "keepout_entries", "stuck_events",
                                            "frame_goal")}
  assert out["state_devices"] == DEVICES and out["shard_shape"] == [WORLDS // DEVICES, K]
  assert out["state_spec"] == ["worlds"]
  assert out["frame_spec"] == [None, "worlds"]
  assert out["pose_max_diff"] < 1e-5          # same program per world; floats agree too


def test_sharded_rl_env_equals_unsharded(single):
  out, _, _ = single
  assert out["rl_devices"] == 4
  assert out["rl_goal_equal"] and out["rl_done_equal"]
  assert out["rl_obs_max_diff"] < 1e-5
  assert out["rl_moved"] > 0.05                # the robots really drove (0.6 s at up to 0.5 m/s)


def test_sharded_steps_move_no_batch_between_devices(single):
  """No all-gather / all-to-all in the sharded fleet rollout or RL reset: XLA's TopK gathered the whole batch
  onto every device (the RL env's spawn draw at each auto-reset, the collision monitor's nearest robots)."""
  out, _, _ = single
  moved = [c for c in out["fleet_collectives"] + out["rl_reset_collectives"] if not c.startswith("all-reduce pred[]")]
  assert moved == [], moved
  # The only all-reduces left: the keepout filter's batch-level decisions (one bool each).
  assert all(c == "all-reduce pred[]" for c in out["fleet_collectives"]), out["fleet_collectives"]
  assert any(c.startswith("all-gather") for c in out["rl_reset_collectives_lax_top_k"]), \
      out["rl_reset_collectives_lax_top_k"]


def test_top_k_equals_lax_top_k_with_ties_and_infinities():
  import jax
  import jax.numpy as jnp
  from sims.scale import sharding
  rng = np.random.default_rng(0)
  for trial in range(60):
    n = int(rng.integers(1, 10))
    k = int(rng.integers(1, n + 1))
    x = rng.integers(-2, 3, size=(4, n)).astype(np.float32)     # many ties
    x[rng.random((4, n)) < 0.3] = -np.inf
    x[rng.random((4, n)) < 0.1] = np.inf
    got, want = sharding.top_k(jnp.asarray(x), k), jax.lax.top_k(jnp.asarray(x), k)
    np.testing.assert_array_equal(np.asarray(got[1]), np.asarray(want[1]), err_msg=f"{x} k={k}")
    np.testing.assert_array_equal(np.asarray(got[0]), np.asarray(want[0]))
    assert got[1].dtype == jnp.int32
  with pytest.raises(ValueError, match="k must be between 1 and the last axis \\(3\\); got 4"):
    sharding.top_k(jnp.zeros(3), 4)


def test_mesh_errors_name_expected_and_got(single):
  out, _, _ = single
  e = out["errors"]
  assert f"between 1 and the {DEVICES} available" in e[0] and "got 0" in e[0]
  assert f"got {DEVICES + 1}" in e[1]
  assert "'all', an int or a list" in e[2]
  assert "worlds (6) must be a multiple of the number of devices (4)" in e[3]


def test_cli_devices(single):
  out, _, fleet_out = single
  codes, stderr = out["cli_codes"], out["cli_stderr"]
  assert codes == [2, 2, 2, 0], stderr[-3000:]
  assert "worlds (4) must be a multiple of the number of devices (3)" in stderr
  assert f"between 1 and the {DEVICES} available" in stderr and f"got {DEVICES + 1}" in stderr
  assert "--devices must be a positive integer or 'all'; got 'two'" in stderr
  summary = json.loads((fleet_out / "summary.json").read_text())
  assert summary["config"]["devices"] == DEVICES and summary["config"]["worlds"] == 8


def _free_port() -> int:
  with socket.socket() as s:
    s.bind(("127.0.0.1", 0))
    return s.getsockname()[1]


def test_two_processes_jax_distributed(single, tmp_path):
  _, ref_path, _ = single
  port = _free_port()
  procs = []
  for i in range(2):
    cmd = [sys.executable, "-m", "sims.commands.sharding", "--coordinator", f"127.0.0.1:{port}", "--num-processes", "2",
           "--process-id", str(i), "--worlds", str(WORLDS), "--steps", str(STEPS), "--robots-per-world", str(K),
           "--out", str(tmp_path / f"p{i}.npz")]
    procs.append(subprocess.Popen(cmd, env=_env(), cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                  text=True))
  outs = []
  try:
    for p in procs:
      outs.append(p.communicate(timeout=900))
  finally:
    for p in procs:
      if p.poll() is None:
        p.kill()
  for p, (so, se) in zip(procs, outs):
    assert p.returncode == 0, se[-3000:]
  ref = np.load(ref_path)
  parts = [np.load(tmp_path / f"p{i}.npz") for i in range(2)]
  seen = sorted(set(parts[0]["goal_index"].tolist()) | set(parts[1]["goal_index"].tolist()))
  assert seen == list(range(WORLDS))
  assert not set(parts[0]["goal_index"].tolist()) & set(parts[1]["goal_index"].tolist())  # split, not copied
  for name in ("goal", "goals_reached", "keepout_entries", "stuck_events", "frame_goal"):
    axis = ref[name].ndim - 2
    for part in parts:
      np.testing.assert_array_equal(part[name], ref[name].take(part[f"{name}_index"], axis=axis), err_msg=name)
