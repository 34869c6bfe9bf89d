"""Soak: many fleet env steps in jitted chunks, checking the rules and the memory after each chunk.

    python -m sims.commands.soak --worlds 64 --robots-per-world 8 --chunk-steps 50 --chunks 200 [--devices all]

After every chunk (one compiled `FleetEnv.rollout_fn`, states carried) it checks:

* no NaN or inf in any robot's pose, velocity or command;
* no keepout entry and no physics step inside a keepout cell (Metrics);
* speed compliance: the highest speed seen in each zone is within the zone's
  limit + `FleetConfig.speed_tolerance`;
* flat device memory: `device.memory_stats()["bytes_in_use"]` where the
  backend reports it (GPU), else the number of live jax.Arrays (CPU); after the
  first chunk (warm-up) the peak of the later half of the chunks may not exceed
  the peak of the earlier half (the allocator makes the figure oscillate).

It prints one line per chunk and a JSON report; the exit code is 0 when every
check passed, 3 (the CLI's "a robot broke a rule") otherwise.
"""

from __future__ import annotations

import json
import sys
import time

import jaxfilters  # noqa: F401  (first: importing it sets the XLA:CPU flags, jaxfilters/xla_flags.py)

import jax  # noqa: E402
import numpy as np  # noqa: E402
from jaxfilters.cli import ArgumentParser  # noqa: E402


def _memory(device) -> tuple[str, int]:
  stats = None
  try:
    stats = device.memory_stats()
  except Exception:  # noqa: BLE001 - backends without memory stats raise or return None
    stats = None
  if stats and "bytes_in_use" in stats:
    return "bytes_in_use", int(stats["bytes_in_use"])
  return "live_arrays", len(jax.live_arrays())


def run_soak(*, num_worlds: int = 16, robots_per_world: int = 4, chunk_steps: int = 25, num_chunks: int = 10,
             seed: int = 0, devices=None, log=None) -> dict:
  """Runs the soak and returns its report (see the module docstring).

  Args:
    num_worlds, robots_per_world: fleet size (W x K robots).
    chunk_steps: env steps (0.2 s) per jitted chunk; num_chunks: chunks.
    seed: PRNG seed.
    devices: None, an int or "all": shard the worlds (sims/scale/sharding.py).
    log: optional callable receiving one text line per chunk.

  Returns:
    dict: ok, env_steps, seconds, keepout_entries, keepout_steps, nan, speed_compliant,
    worst_zone_excess_mps, memory_kind, memory (one figure per chunk), memory_growth.

  Raises:
    ValueError: counts below 1, or worlds that do not split over the devices.
  """
  from sims.fleet.config import FleetConfig
  from sims.fleet.env import FleetEnv
  for name, v in (("num_worlds", num_worlds), ("robots_per_world", robots_per_world),
                  ("chunk_steps", chunk_steps), ("num_chunks", num_chunks)):
    if isinstance(v, bool) or int(v) != v or v < 1:
      raise ValueError(f"{name} must be an integer >= 1; got {v!r}")
  mesh = None
  if devices is not None:
    from sims.scale import sharding
    mesh = sharding.make_mesh(devices)
    sharding.check_divisible(num_worlds, mesh)
  env = FleetEnv.create(config=FleetConfig(robots_per_world=robots_per_world), seed=seed)
  world = env.world
  limits = np.asarray(world.zone_speed, np.float64)
  tol = env.config.speed_tolerance
  states = env.reset_fn(mesh=mesh)(env.params, env.world_keys(jax.random.PRNGKey(seed), num_worlds))
  run = env.rollout_fn(chunk_steps, mesh=mesh, record=True)
  device = jax.devices()[0]
  memory, nan_total, kind = [], 0, None
  t0 = time.perf_counter()
  worst = -np.inf
  for c in range(num_chunks):
    states, frames = run(env.params, states)
    jax.block_until_ready(states)
    pose, cmd, speed = (np.asarray(a) for a in (frames.pose, frames.cmd, frames.speed))
    qvel = np.asarray(states.data.qvel)
    nan = int((~np.isfinite(pose)).sum() + (~np.isfinite(cmd)).sum() + (~np.isfinite(speed)).sum()
              + (~np.isfinite(qvel)).sum())
    nan_total += nan
    zmax = np.asarray(states.metrics.zone_max_speed).reshape(-1, len(limits))
    excess = zmax - limits[None, :]
    worst = max(worst, float(np.max(np.where(np.isfinite(limits)[None, :], excess, -np.inf))))
    entries = int(np.asarray(states.metrics.keepout_entries).sum())
    ksteps = int(np.asarray(states.metrics.keepout_steps).sum())
    del frames, pose, cmd, speed, qvel
    kind, mem = _memory(device)
    memory.append(mem)
    if log:
      log(f"chunk {c + 1}/{num_chunks}: {(c + 1) * chunk_steps * num_worlds} world-steps, nan {nan}, "
          f"keepout entries {entries}, worst zone excess {worst:+.4f} m/s, {kind} {mem}")
  seconds = time.perf_counter() - t0
  # bytes_in_use oscillates as the allocator reuses blocks, so "flat" means no upward trend:
  # after the warm-up chunk, the later half's peak does not exceed the earlier half's peak.
  steady = memory[1:]
  if len(steady) >= 2:
    half = len(steady) // 2
    growth = int(max(steady[half:]) - max(steady[:half]))
  else:
    growth = 0
  entries = int(np.asarray(states.metrics.keepout_entries).sum())
  ksteps = int(np.asarray(states.metrics.keepout_steps).sum())
  compliant = bool(worst <= tol) if np.isfinite(worst) else True
  report = {"env_steps": num_worlds * chunk_steps * num_chunks, "robots": num_worlds * robots_per_world,
            "seconds": seconds, "keepout_entries": entries, "keepout_steps": ksteps, "nan": nan_total,
            "speed_compliant": compliant, "worst_zone_excess_mps": None if not np.isfinite(worst) else worst,
            "speed_tolerance_mps": tol, "memory_kind": kind, "memory": memory, "memory_growth": growth,
            "device": device.device_kind, "devices": 1 if mesh is None else int(mesh.devices.size)}
  report["ok"] = bool(nan_total == 0 and entries == 0 and ksteps == 0 and compliant and growth <= 0)
  return report


def main(argv=None) -> int:
  ap = ArgumentParser(prog="python -m sims.commands.soak", description=__doc__.splitlines()[0],
                               epilog="exit codes: 0 every check passed, 2 bad option, 3 a check failed")
  ap.add_argument("--worlds", type=int, default=16, help="independent worlds (default 16)")
  ap.add_argument("--robots-per-world", type=int, default=4, help="robots per world (default 4)")
  ap.add_argument("--chunk-steps", type=int, default=25, help="env steps per jitted chunk (default 25)")
  ap.add_argument("--chunks", type=int, default=10, help="chunks to run, checked after each (default 10)")
  ap.add_argument("--seed", type=int, default=0, help="PRNG seed (default 0)")
  ap.add_argument("--devices", default=None, help="N or 'all': shard the worlds over devices")
  args = ap.parse_args(argv)
  devices = args.devices
  if devices is not None and devices != "all":
    try:
      devices = int(devices)
    except ValueError:
      ap.error(f"--devices must be an integer or 'all'; got {devices!r}")
  try:
    report = run_soak(num_worlds=args.worlds, robots_per_world=args.robots_per_world,
                      chunk_steps=args.chunk_steps, num_chunks=args.chunks, seed=args.seed, devices=devices,
                      log=lambda line: print(line, file=sys.stderr, flush=True))
  except ValueError as e:
    ap.error(str(e))
  print(json.dumps(report, indent=2))
  return 0 if report["ok"] else 3


if __name__ == "__main__":
  sys.exit(main())
