#!/usr/bin/env bash
# Run on the GPU machine from the repo root:  bash benchmarks/device_run.sh
# One call installs the carried wheels, checks the exact arithmetic on the GPU, and
# measures every figure (filters, pipeline, fleet with filters and bare MJX, baselines,
# the C++ peer, copy bandwidth) into $OUT/bench.json, soaks the fleet (SOAK=0 skips it),
# and with RL=1 also runs benchmarks/rl_bench.py (needs the `rl` extra's wheels in .whl);
# PPO_SCALING=1 adds PPO over all the host's GPUs vs one (benchmarks/ppo_scaling.py, needs the rl wheels;
# PPO_SCALING_ENVS sets --num-envs, PPO_SCALING_EXTRA adds options, e.g. "--devices 1 --reset-capacity auto none");
# RECIPE=1 retrains the shipped policy's recipe (examples/ppo_nav/README.md) cold, --no-cache, timed from the
# interpreter's start, into $OUT/recipe (its results.json beside examples/ppo_nav/results.json; the
# policy weights are not kept); RECIPE_TIMEOUT (default 200 s) bounds it;
# LATENCY=1 runs benchmarks/latency.py (LATENCY_EXTRA adds options, LATENCY_TIMEOUT bounds it, default 240 s);
# PROBES=1 adds the fleet breakdown (benchmarks/fleet_breakdown.py) to $OUT/fleet_breakdown.json;
# TESTS=0 / BENCH=0 skip those parts; BENCH_EXTRA adds options to the benchmarks (e.g. "--only
# keepout_aligned"). A summary table is printed last.
# Fits the device tool's 10-minute call with RL=0 and PROBES=0.
set -u
OUT="${OUT:-/tmp/out}"
mkdir -p "$OUT"

if [ -d .whl ] && ls .whl/*.whl >/dev/null 2>&1; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
  export PYTHONPATH=/tmp/site:$PWD
else
  export PYTHONPATH=$PWD
fi
# The checkout is on PYTHONPATH, not installed: the `jaxfilters` command finds `fleet`, `bench` and
# `rl` through the entry points pyproject.toml declares, so they are written as package metadata.
mkdir -p /tmp/site
python3 - <<'PY'
import pathlib, tomllib
eps = tomllib.loads(pathlib.Path("pyproject.toml").read_text())["project"]["entry-points"]
d = pathlib.Path("/tmp/site/jaxfilters_checkout-0.dist-info")
d.mkdir(exist_ok=True)
(d / "METADATA").write_text("Metadata-Version: 2.1\nName: jaxfilters-checkout\nVersion: 0\n")
(d / "entry_points.txt").write_text("".join(f"[{g}]\n" + "".join(f"{k} = {v}\n" for k, v in e.items()) for g, e in eps.items()))
PY
export PYTHONPATH=/tmp/site:$PWD
export PYTHONUNBUFFERED=1

echo "== devices"
nvidia-smi -L || true
echo "C++ peer compiler: $(command -v "${CXX:-g++}" || echo "none (the keepout figures say the peer was skipped)")"
python3 -c 'import sys, jax, mujoco; print("python", sys.version.split()[0], "jax", jax.__version__, "mujoco", mujoco.__version__); print(jax.devices())'

if [ "${TESTS:-1}" = 1 ]; then
echo "== exact-arithmetic tests on the GPU (FMA contraction) -> $OUT/gpu_tests.log"
# test_keepout_paths: the fast paths' error bounds (2-ulp division, FMA, flush-to-zero) on this device;
# test_trust: costmaps with double (float64) geometry beside float32 masks.
# TEST_FILES overrides the list (e.g. the files a change touched, to fit the call's time limit).
timeout "${TEST_TIMEOUT:-300}" python3 -m pytest -q ${TEST_FILES:-tests/jaxfilters/test_geometry.py tests/jaxfilters/test_keepout_paths_random.py \
  tests/jaxfilters/test_keepout_paths.py tests/jaxfilters/test_float32_inputs.py \
  tests/jaxfilters/test_keepout_unknown_cells.py tests/jaxfilters/test_mask_index.py tests/jaxfilters/test_nav2_doubles.py \
  tests/jaxfilters/test_state_filter_gates.py} -k "not eager_speed_filter_compiles_once" \
  -p no:cacheprovider > "$OUT/gpu_tests.log" 2>&1
echo "pytest rc=$? ; tail:"; tail -n 3 "$OUT/gpu_tests.log"
fi

if [ "${BENCH:-1}" = 1 ]; then
echo "== benchmarks (full sizes) -> $OUT/bench.json"
timeout "${BENCH_TIMEOUT:-330}" python3 -m benchmarks --json ${BENCH_EXTRA:-} --out "$OUT/bench.json" > /dev/null 2> "$OUT/bench.stderr"
echo "bench rc=$?"
fi

if [ "${PROBES:-0}" = 1 ]; then
  echo "== the fleet breakdown -> $OUT/fleet_breakdown.json"
  timeout 300 python3 benchmarks/fleet_breakdown.py 65536 --time-budget "${BREAKDOWN_BUDGET:-240}" > "$OUT/fleet_breakdown.json" 2>> "$OUT/probes.stderr"
  echo "fleet_breakdown rc=$?"
fi

if [ "${SOAK:-1}" = 1 ]; then
  echo "== soak: fleet env steps in chunks (NaN, keepout, speed, device memory) -> $OUT/soak.log"
  timeout "${SOAK_TIMEOUT:-150}" python3 -m sims.commands.soak --worlds "${SOAK_WORLDS:-1024}" --robots-per-world 8 \
    --chunk-steps 50 --chunks "${SOAK_CHUNKS:-10}" > "$OUT/soak.log" 2>&1
  echo "soak rc=$?"; grep -v '^ ' "$OUT/soak.log" | tail -n 6
fi

if [ "${RL:-0}" = 1 ]; then
  echo "== RL env, policy loop, PPO end to end, scaling over the devices -> $OUT/rl_bench.json"
  timeout "${RL_TIMEOUT:-400}" python3 -m benchmarks.rl_bench --json --out "$OUT/rl_bench.json" > "$OUT/rl_bench.log" 2>&1
  echo "rl_bench rc=$?"; grep -v '^ \|^{\|^}' "$OUT/rl_bench.log" | tail -n 15
fi

if [ "${PPO_SCALING:-0}" = 1 ]; then
  # PPO training calls over all the host's GPUs against one at the same batch (benchmarks/ppo_scaling.py).
  echo "== PPO over the devices vs one -> $OUT/ppo_scaling.json"
  timeout "${PPO_SCALING_TIMEOUT:-300}" python3 -m benchmarks.ppo_scaling --num-envs ${PPO_SCALING_ENVS:-1048576} \
    --calls 2 ${PPO_SCALING_EXTRA:-} --out "$OUT/ppo_scaling.json" > "$OUT/ppo_scaling.log" 2>&1
  echo "ppo_scaling rc=$?"; grep "^N=" "$OUT/ppo_scaling.log"
fi

if [ "${LATENCY:-0}" = 1 ]; then
  # Microseconds per call at small and large batches beside the lean C++ loop and the dispatch floor,
  # then the cold compiles (benchmarks/latency.py); LATENCY_EXTRA adds options (e.g. --no-compile).
  echo "== latency -> $OUT/latency.json"
  timeout "${LATENCY_TIMEOUT:-240}" python3 -m benchmarks.latency ${LATENCY_EXTRA:-} --json "$OUT/latency.json" \
    > "$OUT/latency.log" 2>&1
  echo "latency rc=$?"; grep '^|' "$OUT/latency.log"
fi

if [ "${RECIPE:-0}" = 1 ]; then
  # The shipped PPO recipe from a cold interpreter with no compilation cache: wall, compile, train, curve.
  echo "== the examples/ppo_nav recipe, cold -> $OUT/recipe"
  start=$(date +%s.%N)
  timeout "${RECIPE_TIMEOUT:-200}" python3 -m jaxfilters rl train --randomize --costmap-stop --timesteps 20000000 \
    --num-envs 8192 --num-steps 32 --evals 4 --num-eval 256 --seed 0 --no-cache --out "$OUT/recipe" \
    > "$OUT/recipe.log" 2>&1
  rc=$?
  echo "recipe rc=$rc wall_s=$(python3 -c "import sys, time; print(round(time.time() - float(sys.argv[1]), 1))" "$start")"
  rm -f "$OUT/recipe/policy.msgpack"
  [ -s "$OUT/recipe/results.json" ] && python3 - "$OUT/recipe/results.json" examples/ppo_nav/results.json <<'PY'
import json, sys
new, old = (json.load(open(p)) for p in sys.argv[1:3])
for name, r in (("this run", new), ("shipped", old)):
  t, f = r["timing"], r["final"]
  print(f"{name}: {r['device']['kind']} compile {t['compile_s']:.1f} s, train {t['train_s']:.1f} s, "
        f"{t['env_steps_per_s'] / 1e6:.2f} M env-steps/s, success {f['success']:.3f}, goals {f['goals_reached']:.2f}, "
        f"keepout {f['keepout_entries']:.0f}; success curve " + " ".join(f"{x:.2f}" for x in r["curve"]["success"]))
PY
fi

echo "== summary"
if [ -s "$OUT/bench.json" ]; then
  python3 - "$OUT/bench.json" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
from benchmarks.run import table
print(table(r))
PY
else
  echo "no bench.json; stderr tail:"; tail -n 30 "$OUT/bench.stderr"
fi
