"""benchmarks/ppo_scaling.py: --reset-capacity values are checked before anything is built; one device
times each capacity asked for, several devices compare programs that reset every env (the env, the
PPO build and the timing stubbed: no compile)."""

from __future__ import annotations

import json

import pytest

from benchmarks import ppo_scaling


@pytest.mark.parametrize("value", ["0", "-3", "zero", "²", "4.5", ""])
def test_bad_reset_capacity_exits_2_naming_the_allowed_values(value, capsys):
  with pytest.raises(SystemExit) as e:
    ppo_scaling.main(["--devices", "1", "--num-envs", "64", "--reset-capacity", "auto", value])
  assert e.value.code == 2
  assert "--reset-capacity: each value must be auto, none or an integer >= 1" in capsys.readouterr().err


def _fake_build(monkeypatch, built):
  """training_env, the adapter, make_ppo, the mesh and the timing replaced: no env, no compile."""
  from sims.rl import ppo, randomization
  from sims.scale import sharding
  monkeypatch.setattr(randomization, "training_env", lambda *a, **k: (None, None))
  monkeypatch.setattr(ppo, "GymnaxAdapter", lambda *a, reset_capacity, **k: built.append(reset_capacity) or
                      ("adapter", reset_capacity))
  monkeypatch.setattr(ppo, "make_ppo", lambda adapter, **k: (adapter, k["num_envs"], k["timesteps_per_call"]))
  monkeypatch.setattr(sharding, "make_mesh", lambda d: f"mesh of {d}")

  def timed(algo, mesh, calls):
    (_, cap), envs, steps = algo
    per_s = envs * (3.0 if mesh else 1.0) * (2.0 if cap == "auto" else 1.0)   # resets of ended envs: 2x
    return {"compile_s": 0.0, "call_s": [steps / per_s] * calls, "env_steps_per_call": steps}
  monkeypatch.setattr(ppo_scaling, "_time_program", timed)


def test_a_run_over_devices_compares_programs_that_reset_every_env(monkeypatch, tmp_path):
  """The sharded program resets every env (block_shuffle), so its one-device baselines do too: the
  speedup compares the same program (they took the one-device default, resets of ended envs only)."""
  built = []
  _fake_build(monkeypatch, built)
  out = tmp_path / "r.json"
  assert ppo_scaling.main(["--devices", "4", "--num-envs", "64", "--calls", "1", "--out", str(out)]) == 0
  report = json.loads(out.read_text())
  assert built == [None] and {r["reset_capacity"] for r in report["runs"]} == {None}
  assert [(r["num_envs"], r["devices"]) for r in report["runs"]] == [(64, 4), (64, 1), (16, 1)]
  assert report["speedups"] == [{"num_envs": 64, "speedup": 3.0, "per_device_ceiling": 1.0}]


def test_one_device_times_each_reset_capacity(monkeypatch, tmp_path):
  built = []
  _fake_build(monkeypatch, built)
  out = tmp_path / "r.json"
  assert ppo_scaling.main(["--devices", "1", "--num-envs", "64", "--calls", "1", "--reset-capacity", "auto", "none",
                           "--out", str(out)]) == 0
  report = json.loads(out.read_text())
  assert built == ["auto", None]
  assert [(r["reset_capacity"], r["env_steps_per_s"]) for r in report["runs"]] == [("auto", 128.0), (None, 64.0)]
  assert "speedups" not in report


def test_reset_capacity_over_several_devices_exits_2(capsys):
  with pytest.raises(SystemExit) as e:
    ppo_scaling.main(["--devices", "4", "--num-envs", "64", "--reset-capacity", "auto"])
  assert e.value.code == 2
  assert "--reset-capacity times one-device runs (--devices 1)" in capsys.readouterr().err
