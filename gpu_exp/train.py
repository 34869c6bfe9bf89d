"""Experiment (not committed): PPO on randomised layouts, timing and eval. argv: out num_envs num_steps lr hidden iters_per_eval evals layouts"""
import json, os, sys, time
T0 = time.time()
import jax, jax.numpy as jnp, numpy as np
from flax import serialization
from sims.randomization import training_env
from sims.adapter import GymnaxAdapter
from sims.ppo import make_ppo, evaluate_policy, mean_policy

out, num_envs, num_steps, lr, hidden, per_eval, evals, layouts, ent = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4]), tuple(int(h) for h in sys.argv[5].split("x")), int(sys.argv[6]), int(sys.argv[7]), int(sys.argv[8]), float(sys.argv[9])
os.makedirs(out, exist_ok=True)
env, fn = training_env(randomize=True, seed=0, layouts=layouts)
T_env = time.time() - T0
ad = GymnaxAdapter(env, 300, fn, full_reset=True)
ev_env, ev_fn = training_env(randomize=True, seed=1001, layouts=16)
ev_ad = GymnaxAdapter(ev_env, 300, ev_fn, full_reset=True)
algo = make_ppo(ad, timesteps_per_call=num_envs * num_steps * per_eval, num_envs=num_envs, num_steps=num_steps,
                learning_rate=lr, hidden=hidden, ent_coef=ent)
with jax.numpy_rank_promotion("allow"):
  train = jax.jit(lambda ts: algo.train(train_state=ts)[0])
  ts = jax.jit(algo.init_state)(jax.random.PRNGKey(0))
  evaluate = jax.jit(lambda ts, k: {n: jnp.mean(v) for n, v in evaluate_policy(ev_ad, mean_policy(algo, ts), k, 1024).items()})
  t = time.time(); train_c = train.lower(ts).compile(); tc = time.time() - t
  t = time.time(); eval_c = evaluate.lower(ts, jax.random.PRNGKey(5)).compile(); te = time.time() - t
  print(f"env build {T_env:.1f}s compile train {tc:.1f}s eval {te:.1f}s", flush=True)
  train_s = 0.0
  for i in range(evals):
    t = time.time(); ts = train_c(ts); jax.block_until_ready(ts); train_s += time.time() - t
    r = {k: float(v) for k, v in eval_c(ts, jax.random.PRNGKey(100 + i)).items()}
    print(f"[{time.time()-T0:6.1f}s] steps {int(ts.global_step):>10d} train {train_s:6.1f}s {int(ts.global_step)/train_s/1e6:5.2f}M/s "
          f"success {r['success']:.3f} goals {r['goals_reached']:.2f} keepout {r['keepout_entries']:.4f} coll {r['collisions']:.4f} "
          f"over {r['speed_violation_s']:.4f} late {r.get('speed_violation_after_clip_s', -1):.4f} ret {r['return']:.2f}", flush=True)
    blob = serialization.msgpack_serialize({"actor": serialization.to_state_dict(ts.actor_ts.params),
                                            "obs_rms": serialization.to_state_dict(ts.obs_rms_state)})
    open(f"{out}/policy_{i}.msgpack", "wb").write(blob)
    json.dump({"i": i, "steps": int(ts.global_step), "wall": time.time() - T0, "train_s": train_s, **r,
               "hidden": hidden, "lr": lr}, open(f"{out}/eval_{i}.json", "w"))
