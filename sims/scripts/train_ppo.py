"""Trains PPO (rejax) on the fleet RL env and plots its learning curve (needs the `rl` extra).

    python -m sims.scripts.train_ppo --timesteps 400000 --out out/ppo

Writes OUT/results.json (timings, the evaluation curve, first and last values)
and OUT/learning_curve.png; the library part is `sims.ppo`.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from jaxfilters import xla_flags

_EPILOG = """\
examples:
  python -m sims.scripts.train_ppo --timesteps 400000 --out out/ppo
  python -m sims.scripts.train_ppo --timesteps 3000000 --num-envs 64 --num-steps 64 --randomize --out out/ppo3m

exit codes: 0 ok, 2 bad option"""


def build_parser() -> argparse.ArgumentParser:
  """The script's options, each with its default."""
  ap = argparse.ArgumentParser(prog="python -m sims.scripts.train_ppo",
                               description="Train PPO (rejax) on the fleet RL env and plot its learning curve.",
                               epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
  ap.add_argument("--timesteps", type=int, default=400_000,
                  help="env steps to train, rounded up to whole updates (default 400000)")
  ap.add_argument("--num-envs", type=int, default=32, help="parallel envs (default 32)")
  ap.add_argument("--num-steps", type=int, default=64, help="rollout length per update (default 64)")
  ap.add_argument("--episode-length", type=int, default=150, help="env steps of 0.2 s per episode (default 150)")
  ap.add_argument("--evals", type=int, default=20, help="evaluation points on the curve (default 20)")
  ap.add_argument("--num-eval", type=int, default=32, help="episodes per evaluation (default 32)")
  ap.add_argument("--keepout", choices=("terminate", "penalty"), default="terminate",
                  help="what a keepout entry does: end the episode (terminate) or "
                  "only cost reward (penalty) (default terminate)")
  ap.add_argument("--randomize", action="store_true", help="randomise zones and goals per episode")
  ap.add_argument("--seed", type=int, default=0, help="PRNG seed (default 0)")
  ap.add_argument("--out", type=Path, default=Path("out/ppo"), help="output folder (default out/ppo)")
  return ap


def main(argv=None) -> int:
  """Parses the options, trains, writes OUT/results.json and OUT/learning_curve.png; returns the exit code."""
  ap = build_parser()
  args = ap.parse_args(argv)
  for name in ("timesteps", "num_envs", "num_steps", "episode_length", "evals", "num_eval"):
    if getattr(args, name) < 1:
      ap.error(f"--{name.replace('_', '-')} must be >= 1; got {getattr(args, name)}")

  xla_flags.use_fast_cpu_compile()   # before the JAX backend starts
  import jax

  from sims.ppo import EVAL_KEYS, GymnaxAdapter, make_ppo, plot_curve, train_with_curve
  from sims.randomization import randomize_zones_and_goals
  from sims.rl import NavEnv, NavEnvConfig
  env = NavEnv.create(config=NavEnvConfig(keepout=args.keepout))
  adapter = GymnaxAdapter(env, args.episode_length, randomize_zones_and_goals if args.randomize else None)
  per_iter = args.num_envs * args.num_steps
  iters = max(1, -(-args.timesteps // per_iter))
  per_call = max(1, iters // args.evals)
  num_calls = -(-iters // per_call)
  algo = make_ppo(adapter, timesteps_per_call=per_call * per_iter, num_envs=args.num_envs,
                  num_steps=args.num_steps)
  steps = num_calls * per_call * per_iter
  device = jax.devices()[0].device_kind
  print(f"PPO (rejax 0.1.3) on NavEnv: {steps} env steps, {args.num_envs} envs, device {device}",
        file=sys.stderr)
  _, evals, timing = train_with_curve(adapter, algo, jax.random.PRNGKey(args.seed), num_calls=num_calls,
                                      num_eval=args.num_eval)
  result = {"trainer": "rejax.PPO 0.1.3", "jax": jax.__version__, "device": device, "env_steps": steps,
            **timing, "env_steps_per_s": steps / timing["train_s"],
            "config": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
            "curve": evals, "final": {k: v[-1] for k, v in evals.items()},
            "initial": {k: v[0] for k, v in evals.items()}}
  args.out.mkdir(parents=True, exist_ok=True)
  (args.out / "results.json").write_text(json.dumps(result, indent=2))
  png = plot_curve(evals, args.out / "learning_curve.png",
                   f"PPO (rejax) on NavEnv, {device}: {steps / 1e3:.0f}k env steps in "
                   f"{timing['train_s']:.0f} s")
  print(f"compile {timing['compile_train_s']:.1f} s (train) + {timing['compile_eval_s']:.1f} s (eval), "
        f"train {timing['train_s']:.1f} s ({steps / timing['train_s']:.0f} env steps/s)")
  f, i = result["final"], result["initial"]
  for name in EVAL_KEYS:
    print(f"  {name:<18} start {i[name]:8.3f}   end {f[name]:8.3f}")
  print(f"wrote {args.out / 'results.json'}, {png}")
  return 0


if __name__ == "__main__":
  sys.exit(main())
