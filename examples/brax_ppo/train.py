"""Brax's own PPO (`brax.training.agents.ppo.train`) on the fleet RL env, the shipped recipe's env.

    python examples/brax_ppo/train.py --out out/brax_ppo          # one H200; writes results.json, curve.png

The env is the one `jaxfilters rl train --randomize --costmap-stop` trains on (the built-in
warehouse, 16 zone layouts, per-episode limits and goals: `sims.rl.randomization.training_env`),
wrapped as every MuJoCo Playground env is for Brax (`wrapper.wrap_for_brax_training` with the env's
domain randomizer). Brax 0.14.2 runs on this jax through `sims.rl.brax_compat.install()`. The
budget and PPO settings follow examples/ppo_nav's recipe where Brax has the same knob (8,192 envs,
32-step unrolls, 4 epochs of 8 minibatches, lr 3e-4, gamma 0.99, lambda 0.95, clip 0.2, 2 x 64
tanh MLPs, observation normalisation, 300-step episodes). The policy is then evaluated with its
deterministic action on layouts of an evaluation seed that training never draws, with the same
function `jaxfilters rl eval` uses (`sims.rl.ppo.evaluate_policy`): success = a goal reached.
"""

from __future__ import annotations

import time

T_START = time.perf_counter()

import argparse  # noqa: E402
import functools  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import jax  # noqa: E402
import numpy as np  # noqa: E402
from brax.training.agents.ppo import networks as ppo_networks  # noqa: E402
from brax.training.agents.ppo import train as ppo  # noqa: E402
from mujoco_playground import wrapper  # noqa: E402

from jaxfilters import cli as jcli  # noqa: E402
from sims.rl import brax_compat  # noqa: E402
from sims.rl.adapter import GymnaxAdapter  # noqa: E402
from sims.rl.env import NavEnvConfig  # noqa: E402
from sims.rl.ppo import EVAL_KEYS, evaluate_policy  # noqa: E402
from sims.rl.randomization import training_env  # noqa: E402


def main(argv=None) -> int:
  p = jcli.ArgumentParser(prog="examples/brax_ppo/train.py", description=__doc__.split("\n")[0])
  p.add_argument("--out", type=jcli.path_type, required=True, help="output folder (results.json, curve.png)")
  p.add_argument("--timesteps", type=jcli.int_type(262_144, 2 ** 30), default=20_000_000,
                 help="env steps of training (default 20,000,000)")
  p.add_argument("--num-envs", type=jcli.int_type(8, 2 ** 18), default=8192, help="parallel envs (default 8192)")
  p.add_argument("--evals", type=jcli.int_type(2, 50), default=5, help="Brax's evaluation points (default 5)")
  p.add_argument("--seed", type=jcli.int_type(0, 2 ** 31 - 1), default=0, help="training seed (default 0)")
  p.add_argument("--eval-seed", type=jcli.int_type(0, 2 ** 31 - 1), default=1,
                 help="seed of the evaluation layouts and episodes (default 1)")
  p.add_argument("--eval-episodes", type=jcli.int_type(1, 65_536), default=1024, help="(default 1024)")
  args = p.parse_args(argv)
  if args.num_envs % 8:
    p.error(f"argument --num-envs: must be a multiple of 8 (8 minibatches); got {args.num_envs}")
  if args.out.exists() and not args.out.is_dir():
    p.error(f"argument --out: {args.out} exists and is not a folder")
  args.out.mkdir(parents=True, exist_ok=True)

  brax_compat.install()
  episode_length = 300
  config = NavEnvConfig(costmap_stop=True)
  env, randomizer = training_env(randomize=True, seed=args.seed, config=config, layouts=16)
  curve = []

  def progress(step, metrics):
    row = {"env_steps": int(step), "wall_s": round(time.perf_counter() - T_START, 2)}
    row.update({k: float(v) for k, v in metrics.items() if np.ndim(v) == 0})
    curve.append(row)
    print(f"step {int(step):>11,d}  {row['wall_s']:7.1f} s  reward {row.get('eval/episode_reward', float('nan')):8.3f}"
          f"  goals {row.get('eval/episode_goals_reached', float('nan')):6.3f}", file=sys.stderr, flush=True)

  network = functools.partial(ppo_networks.make_ppo_networks, policy_hidden_layer_sizes=(64, 64),
                              value_hidden_layer_sizes=(64, 64), activation=jax.nn.tanh)
  t_train = time.perf_counter()
  make_policy, params, _ = ppo.train(
      environment=env, num_timesteps=args.timesteps, episode_length=episode_length, num_envs=args.num_envs,
      batch_size=args.num_envs // 8, num_minibatches=8, unroll_length=32, num_updates_per_batch=4,
      learning_rate=3e-4, entropy_cost=1e-3, discounting=0.99, gae_lambda=0.95, clipping_epsilon=0.2,
      max_grad_norm=0.5, normalize_observations=True, reward_scaling=1.0, num_evals=args.evals,
      num_eval_envs=256, seed=args.seed, network_factory=network, wrap_env_fn=wrapper.wrap_for_brax_training,
      randomization_fn=randomizer, progress_fn=progress)
  train_s = time.perf_counter() - t_train

  eval_env, eval_fn = training_env(randomize=True, seed=args.eval_seed, config=config, layouts=16, evaluation=True)
  adapter = GymnaxAdapter(eval_env, episode_length, eval_fn, full_reset=True)
  policy = make_policy(params, deterministic=True)
  act = lambda obs: policy(obs, jax.random.PRNGKey(0))[0]
  t_eval = time.perf_counter()
  per_episode = jax.jit(lambda k: evaluate_policy(adapter, act, k, args.eval_episodes))(
      jax.random.PRNGKey(args.eval_seed))
  per_episode = {k: np.asarray(v) for k, v in per_episode.items()}
  eval_s = time.perf_counter() - t_eval
  figures = {k: float(per_episode[k].mean()) for k in EVAL_KEYS}
  results = {
      "command": "python examples/brax_ppo/train.py " + " ".join(sys.argv[1:] if argv is None else argv),
      "device": jax.devices()[0].device_kind, "jax": jax.__version__,
      "brax": __import__("brax").__version__, "config": {k: v for k, v in vars(args).items() if k != "out"},
      "episode_length": episode_length, "train_s": round(train_s, 1), "eval_s": round(eval_s, 1),
      "wall_s": round(time.perf_counter() - T_START, 1), "evaluation": figures, "curve": curve}
  (args.out / "results.json").write_text(json.dumps(results, indent=1))
  import matplotlib
  matplotlib.use("Agg")
  import matplotlib.pyplot as plt
  fig, ax = plt.subplots(1, 2, figsize=(9, 3.4), layout="constrained")
  x = [r["env_steps"] / 1e6 for r in curve]
  ax[0].plot(x, [r.get("eval/episode_reward", np.nan) for r in curve], marker="o")
  ax[0].set_xlabel("env steps (M)"); ax[0].set_ylabel("episode return (Brax eval)")
  ax[1].plot(x, [r.get("eval/episode_goals_reached", np.nan) for r in curve], marker="o", color="tab:green")
  ax[1].set_xlabel("env steps (M)"); ax[1].set_ylabel("goals per episode (Brax eval)")
  fig.suptitle(f"Brax PPO on the fleet env: {figures['success']:.1%} success on evaluation layouts", fontsize=10)
  fig.savefig(args.out / "curve.png", dpi=80)
  print(json.dumps({k: results[k] for k in ("device", "train_s", "eval_s", "wall_s", "evaluation")}, indent=1))
  return 0


if __name__ == "__main__":
  sys.exit(main())
