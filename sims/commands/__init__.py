"""The simulator's entry points; the library (sims.*) holds no `__main__` code.

Registered as `jaxfilters` commands (entry-point group `jaxfilters.commands` in
pyproject.toml):

* `jaxfilters fleet` (`sims.commands.fleet`): simulate a fleet, write pictures and a summary.
* `jaxfilters bench` (`sims.commands.bench`): the benchmark harness of a checkout.
* `jaxfilters rl` (`sims.commands.rl`): `train` a PPO policy on the RL env, `eval` a saved one on any map
  (the `rl` extra).

Run as `python -m sims.commands.NAME`:

* `soak`: many chunks of fleet steps with the rules and memory checked after each.
* `make_default_scenario`: regenerates the built-in warehouse in sims/assets.
* `soft_tuning`: a speed-zone limit tuned with jax.grad, re-checked with the real filters.
* `sharding`: one process of a multi-process sharded rollout.
* `readme_picture`: copies the `make demo` picture to docs/demo.png (`make readme-picture`).
"""
