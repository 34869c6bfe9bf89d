"""AsymmetricInflationLayer full updates at 800 x 800, one robot and many, beside the plain layer.

    python -m benchmarks.asymmetric                   # B = 1, 8 (CPU) or 1, 16, 256 (GPU)
    python -m benchmarks.asymmetric --sizes 1,64 --poses 400

The scene of Nav2 PR #6109's benchmark: an 800 x 800 costmap of 0.05 m (40 m x 40 m), a
local inflation radius of 0.55 m, and a plan with a pose every 0.05 m (Nav2's planners space
poses about one cell apart) of `--poses` poses across the map. Every robot of a batch gets its
own obstacles (rectangles, a seeded warehouse-like scatter) and its own plan (a sine of its own
phase), so nothing is shared between robots. Per batch size the median milliseconds per call
of:

* plain: `jaxfilters.inflate` with max(left, right), Nav2's InflationLayer (pass 1 alone);
* asymmetric: `jaxfilters.asymmetric_inflate`, both passes (pass 2 from the disfavoured side);

each inside the caller's `jax.jit` (inputs as arguments), after two warm-ups, and the cold
first-call seconds of each. One robot's result is checked cell for cell against
reference/asymmetric_inflation.py (the float64 transcription of Nav2's C++) when `--check` is
given (slow: the reference is a Python loop). #6109 reports Nav2's own C++ at 1.1 ms (plain) and
3.3 ms (asymmetric) per full update at 800 x 800 for one robot on its author's CPU.
"""

from __future__ import annotations

import os
import time

import numpy as np

import jaxfilters  # noqa: F401  (first: importing it sets the XLA:CPU flags, jaxfilters/xla_flags.py)

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import jaxfilters as jf  # noqa: E402
from benchmarks.latency import time_calls  # noqa: E402
from jaxfilters.cli import ArgumentParser  # noqa: E402

N = 800
RES = 0.05
NAV2_6109_MS = {"plain": 1.1, "asymmetric": 3.3}


def config() -> jf.AsymmetricInflationConfig:
  return jf.AsymmetricInflationConfig(inflation_radius=0.55, cost_scaling_factor_left=3.0,
                                      cost_scaling_factor_right=10.0, goal_distance_threshold=1.5,
                                      inscribed_radius=0.22, resolution=RES)


def scene(b: int, poses: int, seed: int = 0):
  """uint8 [B, N, N] maps, float32 [B, poses, 2] plans (a pose every RES), int32 [B], float32 [B, 2]."""
  rng = np.random.default_rng(seed)
  costs = np.zeros((b, N, N), np.uint8)
  for k in range(b):
    for _ in range(80):
      y, x = rng.integers(0, N - 40, 2)
      costs[k, y:y + rng.integers(2, 40), x:x + rng.integers(2, 40)] = 254
  s = np.arange(poses, dtype=np.float64) * RES            # arc length along x, one cell per pose
  phase = rng.uniform(0, 2 * np.pi, (b, 1))
  x = 2.0 + np.broadcast_to(s, (b, poses))
  y = 20.0 + 4.0 * np.sin(s / 6.0 + phase)
  paths = np.stack([x, y], -1).astype(np.float32)
  return costs, paths, np.full((b,), poses, np.int32), paths[:, 0].copy()


def row(b: int, poses: int, reps: int, check: bool) -> dict:
  cfg = config()
  costs, paths, lengths, xy = scene(b, poses)
  args = tuple(jnp.asarray(a) for a in (costs, paths, lengths, xy))
  plain = jax.jit(lambda c, p, n, r: jf.inflate(c, config=cfg.symmetric))
  asym = jax.jit(lambda c, p, n, r: jf.asymmetric_inflate(c, paths=p, path_lengths=n, robot_xy=r, config=cfg))
  out = {"B": b, "poses": poses}
  for name, fn in (("plain", plain), ("asymmetric", asym)):
    t = time.perf_counter()
    res = jax.block_until_ready(fn(*args))
    out[f"{name}_first_s"] = time.perf_counter() - t
    out[f"{name}_ms"] = 1e3 * time_calls(fn, [args], min_s=0.0, min_n=reps, max_n=reps)[0]
    out[f"{name}_raised_cells"] = int(np.sum(np.asarray(res) != costs))
  if check:
    from reference import asymmetric_inflation as ref
    want = ref.asymmetric_inflate(costs[0], paths[0], xy[0], origin=(0.0, 0.0), resolution=RES,
                                  inflation_radius=cfg.inflation_radius,
                                  cost_scaling_factor_left=cfg.cost_scaling_factor_left,
                                  cost_scaling_factor_right=cfg.cost_scaling_factor_right,
                                  goal_distance_threshold=cfg.goal_distance_threshold,
                                  inscribed_radius=cfg.inscribed_radius)
    got = np.asarray(asym(*args))[0]
    if not np.array_equal(got, want):
      raise AssertionError(f"B={b}: robot 0 differs from the reference in {int(np.sum(got != want))} cells")
    out["checked"] = True
  return out


def table(rows) -> str:
  lines = ["| B | poses | plain ms/call | asymmetric ms/call | asym per robot ms | asym / plain | first call s (plain / asym) |",
           "| ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
  for r in rows:
    lines.append(f"| {r['B']:,} | {r['poses']} | {r['plain_ms']:.2f} | {r['asymmetric_ms']:.2f} | "
                 f"{r['asymmetric_ms'] / r['B']:.3f} | {r['asymmetric_ms'] / r['plain_ms']:.2f} | "
                 f"{r['plain_first_s']:.1f} / {r['asymmetric_first_s']:.1f} |")
  return "\n".join(lines)


def main(argv=None):
  p = ArgumentParser(prog="python -m benchmarks.asymmetric", description=__doc__.split("\n")[0])
  p.add_argument("--sizes", help="comma-separated batch sizes (default 1,8 on a CPU, 1,16,256 on a GPU)")
  p.add_argument("--poses", type=int, default=400, help="poses per plan, one every 0.05 m (default 400: 20 m)")
  p.add_argument("--reps", type=int, default=7, help="timed calls per row (median)")
  p.add_argument("--check", action="store_true", help="check robot 0 against the float64 reference (slow)")
  args = p.parse_args(argv)
  gpu = jax.default_backend() != "cpu"
  try:
    sizes = [int(s) for s in args.sizes.split(",")] if args.sizes else ([1, 16, 256] if gpu else [1, 8])
  except ValueError:
    p.error(f"--sizes must be comma-separated integers; got {args.sizes!r}")
  if any(b < 1 or b > 4096 for b in sizes):
    p.error(f"--sizes must be in [1, 4096]; got {args.sizes!r}")
  if not 2 <= args.poses <= 100_000:
    p.error(f"--poses must be in [2, 100000]; got {args.poses}")
  if not 1 <= args.reps <= 1000:
    p.error(f"--reps must be in [1, 1000]; got {args.reps}")
  dev = jax.devices()[0]
  print(f"# {jax.default_backend()} {dev.device_kind}, jax {jax.__version__}, {os.cpu_count()} host cores, "
        f"{N}x{N} cells of {RES} m, radius {config().inflation_radius} m", flush=True)
  rows = []
  for b in sizes:
    rows.append(row(b, args.poses, args.reps, args.check))
    r = rows[-1]
    print(f"B={b:5d} plain {r['plain_ms']:9.2f} ms  asymmetric {r['asymmetric_ms']:9.2f} ms", flush=True)
  print()
  print(table(rows))
  print(f"\nNav2 C++ (#6109, one robot, its author's CPU): plain {NAV2_6109_MS['plain']} ms, "
        f"asymmetric {NAV2_6109_MS['asymmetric']} ms")


if __name__ == "__main__":
  main()
