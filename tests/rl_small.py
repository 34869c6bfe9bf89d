"""The one small PPO configuration the suite trains with, wherever a test only needs *a* training run.

`jaxfilters rl train` (tests/commands/test_rl.py, tests/rl/test_training_counts.py), the library's
`train_with_curve` (tests/rl/test_env.py) and notebook 04's quick run (the kernel gets
JAXFILTERS_NOTEBOOK_QUICK=1 from tests/project/test_notebooks.py) all train on the same env (the
built-in warehouse, randomised zones and goals from 4 layouts drawn with seed 0) with the same PPO
sizes. Their training and evaluation programs are then the same programs, byte for byte, so the
session's compilation cache (tests/conftest.py) compiles each once for the whole run, whichever
process (xdist worker, notebook kernel) gets there first; the number of PPO iterations is traced
and the number of evaluations is a Python loop, so neither makes a new program.

Notebook 04 spells the same values out in its first cell (QUICK); tests/project/test_notebooks.py
checks that they agree with the ones here.
"""

NUM_ENVS = 4
NUM_STEPS = 8
MINIBATCHES = 8           # the command's default: 4 envs x 8 steps in minibatches of 4
EPISODE_LENGTH = 6
HIDDEN = (16,)
NUM_EVAL = 2
LAYOUTS = 4
SEED = 0

# `rl eval` options for a policy of this run's network (add --policy). A policy of these hidden
# sizes and EPISODE_LENGTH, evaluated with these options, runs the same evaluation program as the
# trained one (the weights are arguments), so the suite compiles it once. The seed is part of the
# program: it draws the layouts.
EVAL_EPISODES = 3
EVAL_SEED = 5
EVAL_ARGS = ["--episodes", str(EVAL_EPISODES), "--seed", str(EVAL_SEED), "--randomize", "--layouts", str(LAYOUTS),
             "--json"]

# `rl train` options for that run (add --timesteps, --evals and --out).
TRAIN_ARGS = ["--num-envs", str(NUM_ENVS), "--num-steps", str(NUM_STEPS), "--minibatches", str(MINIBATCHES),
              "--episode-length", str(EPISODE_LENGTH), "--hidden", ",".join(map(str, HIDDEN)),
              "--num-eval", str(NUM_EVAL), "--randomize", "--layouts", str(LAYOUTS), "--seed", str(SEED)]


def fresh_trace_caches():
  """Empties JAX's in-process caches (`jax.clear_caches()`) before tracing this run's programs.

  The compilation cache's key is the lowered program's text, and that text depends on the
  process's tracing history: JAX lowers a repeated inner jitted call (`jnp.where`, `clip`,
  `dynamic_update_index_in_dim`) once per program only while its traced jaxpr is still in the
  tracing caches (LRU, 2,048 entries). In a worker that has traced hundreds of programs
  before, entries are evicted in the middle of this run's trace, the program gets copies of
  those functions, and its key misses the entry another process wrote for the same run (the
  `rl train` of tests/rl/test_training_counts.py compiled the 44 s again after
  tests/commands/test_rl.py in the same session). From empty caches every process traces the
  same text. Call it first in a test that trains this run in the test process, or evaluates a
  policy with EVAL_ARGS.
  """
  import jax
  jax.clear_caches()


def training_run():
  """(env, adapter, algo) as `rl train TRAIN_ARGS` builds them (sims/commands/rl.py `run_train`)."""
  from sims.rl.env import NavEnvConfig
  from sims.rl.ppo import GymnaxAdapter, make_ppo
  from sims.rl.randomization import training_env
  env, fn = training_env(None, randomize=True, seed=SEED, layouts=LAYOUTS, config=NavEnvConfig())
  adapter = GymnaxAdapter(env, EPISODE_LENGTH, fn, full_reset=True)
  algo = make_ppo(adapter, timesteps_per_call=NUM_ENVS * NUM_STEPS, num_envs=NUM_ENVS, num_steps=NUM_STEPS,
                  num_minibatches=MINIBATCHES, hidden=HIDDEN)
  return env, adapter, algo
