"""Where the fleet step's time goes: the step with each part removed, scaled or replaced, one figure each.

    python benchmarks/fleet_breakdown.py 65536            # GPU, full size (B = 8192 worlds x 8)
    python benchmarks/fleet_breakdown.py 512 --repeats 3  # CPU, a few minutes
    python benchmarks/fleet_breakdown.py 512 --only full,physics
    python benchmarks/fleet_breakdown.py 65536 --time-budget 500   # under a 10-minute limit

Every variant is the real fleet rollout (`FleetEnv.rollout_fn`, 100 physics steps
of 0.01 s by default, record=False) with one thing changed, so the time of a part
is a difference of two measured figures:

| variant | what runs per robot |
| --- | --- |
| bare_mjx | `sims.scale.bench.bare_mjx_rollout`: vmapped mjx.step only (the baseline) |
| physics | the fleet loop (20 Hz ticks of 5 physics steps) at a constant twist; no filters, no metrics |
| metrics | + the per-physics-step metrics (zone, keepout, distance) and the per-tick proximity check |
| speed_clip | + speed filter, goals, progress checker, recovery and the clip; the planner's command is a constant twist |
| costmap | + the 5 Hz local costmap (static window, robots, inflation, keepout filter, planner table) |
| full | + the 20 Hz planner: the default fleet step |
| reference_planner | full with the straightforward reference planner (reference/planner.py) |
| candidates_3 / candidates_half / candidates_double | full with 3, about half or twice the planner's candidates |
| const_costmap_lookups / const_speed_lookups / const_nav_lookups / const_lookups | full with the planner's local-costmap, speed-cap or navigation-field lookups (or all three) replaced by constants |
| controller_10hz | full with the controller at 10 Hz (same costmap rate) |
| rollout_cumsum / rollout_chain / rollout_fused | full with the planner forced to one mode (`planner.rollout_mode`: the rollout sums as one cumsum or a chain of adds, then each rule over the points; or every rule folded into one pass over the steps; the default is cumsum on CPU, fused elsewhere) |

Each variant is compiled and timed in its own try block; a failure is reported
as a string and the others still run. Progress goes to stderr; stdout gets one
JSON line: per variant robot_steps_per_s, robot_seconds_per_s (simulated
robot-seconds per wall second), ns_per_robot_step and compile_s, plus `parts_ns`
(ns per robot-step of each part, from the differences of wall times; on CPU also
`parts_cpu_ns` from host CPU times) and the device.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import json
import sys
import time
from pathlib import Path

if __package__ in (None, ""):
  sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import jaxfilters  # noqa: F401  (first: importing it sets the XLA:CPU flags, jaxfilters/xla_flags.py)

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

from reference import planner as planner_reference  # noqa: E402
from sims.scale import bench
from sims.fleet import navigation, planner  # noqa: E402
from sims.fleet.config import FleetConfig  # noqa: E402
from sims.fleet.env import FleetEnv, WorldState, mjx_step  # noqa: E402
from jaxfilters.cli import ArgumentParser  # noqa: E402

_F32 = jnp.float32
_TWIST = (0.4, 0.3)   # m/s, rad/s: the constant command of the variants without a planner (as bare_mjx)


@dataclasses.dataclass(frozen=True, eq=False)
class VariantEnv(FleetEnv):
  """FleetEnv with parts of the step switched off (benchmark only).

  Attributes:
    costmap: rebuild the local costmaps every env step.
    control: 'planner' (the full controller), 'clip' (everything but the planner,
      whose command is the constant twist) or 'none' (the constant twist only).
    metrics: accumulate the per-physics-step and proximity metrics.
    extra_speeds: offer the planner the zone speeds as extra candidates.
    reference: plan with the straightforward reference planner (reference/planner.py:
      one robot's costmap and its hard cells looked up separately, 81 full rollouts),
      to compare the optimised planner with it in one run.
  """
  costmap: bool = True
  control: str = "planner"
  metrics: bool = True
  extra_speeds: bool = True
  reference: bool = False

  @property
  def zone_speeds(self) -> tuple[float, ...]:
    """The env's extra planner speeds, or none."""
    return super().zone_speeds if self.extra_speeds else ()

  def _update_costmaps(self, state: WorldState) -> WorldState:
    if not self.costmap:
      return state
    state = super()._update_costmaps(state)
    if self.reference:   # the reference planner reads hard_cells beside the costmap; plan_lut carries it here
      state = dataclasses.replace(
          state, plan_lut=jax.vmap(planner.hard_cells)(state.local.cost).astype(state.plan_lut.dtype))
    return state

  def _control(self, s: WorldState):
    if self.control != "none":
      return super()._control(s)
    k = self.num_robots
    return s, jnp.full((k,), _TWIST[0], _F32), jnp.full((k,), _TWIST[1], _F32)

  def _plan(self, s, poses, goal, cap, recovering):
    if self.control == "planner" and self.reference:
      p, k = self.params, self.num_robots
      plan = functools.partial(planner_reference.plan_one, nav=p.nav, speed_mask=p.speed,
                               speed_cap=p.speed_cap, config=self.config, extra_speeds=self.zone_speeds)
      cmd, info = jax.vmap(plan, in_axes=(0, 0, 0, 0, 0, 0, 0, 0, 0, None, 0))(
          poses, s.cmd, goal, cap, recovering, s.local.cost, s.plan_lut.astype(jnp.uint8), s.local.origin,
          s.local.resolution, poses[:, :2], ~jnp.eye(k, dtype=bool))
      return cmd, info["stopped"]
    if self.control == "planner":
      return super()._plan(s, poses, goal, cap, recovering)
    k = self.num_robots
    return jnp.broadcast_to(jnp.asarray(_TWIST, _F32), (k, 2)), jnp.zeros((k,), bool)

  def _physics(self, s: WorldState, v, w, t0) -> WorldState:
    if self.metrics:
      return super()._physics(s, v, w, t0)

    def substep(data, _):
      th = data.qpos[:, 2]
      ctrl = jnp.stack([v * jnp.cos(th), v * jnp.sin(th), w], axis=1)
      return jax.vmap(lambda d, u: mjx_step(self.mjx_model, d, u))(data, ctrl), None

    data, _ = jax.lax.scan(substep, s.data, None, length=self.config.substeps_per_tick)
    return dataclasses.replace(s, data=data)


def _const_lut(lut, origin, res, x, y):
  del lut, origin, res, x
  return jnp.zeros(jnp.shape(y), jnp.uint16)


def _const_speed_xy(speed_cap, origin, res, x, y):
  del speed_cap, origin, res, x
  return jnp.full(jnp.shape(y), jnp.inf, _F32)


def _const_nav_value(field, goal, xy):
  del field, goal
  return 0.1 * xy[0]


def _const_descent(field, goal, xy):
  del field, goal
  return jnp.asarray([1.0, 0.0], _F32) + 0.0 * xy


def _const_value_and_direction(field, goal, xy):
  return _const_nav_value(field, goal, xy), _const_descent(field, goal, xy)


# Planner lookups a variant replaces by constants: (module, attribute, replacement). Attributes that a
# version of sims/fleet/planner.py lacks are skipped (and listed in the variant's result).
_LOOKUPS = {
    "costmap": [(planner, "lut_at", _const_lut)],
    "speed": [(planner, "speed_cap_xy", _const_speed_xy)],
    "nav": [(navigation, "nav_value", _const_nav_value), (navigation, "descent_direction", _const_descent),
            (navigation, "value_and_direction", _const_value_and_direction)],
    # Not lookups: the ways sims/fleet/planner.py can run the candidates (its default depends on the backend).
    "rollout_cumsum": [(planner, "rollout_mode", lambda: "cumsum")],
    "rollout_chain": [(planner, "rollout_mode", lambda: "chain")],
    "rollout_fused": [(planner, "rollout_mode", lambda: "fused")],
}


@contextlib.contextmanager
def patched_lookups(kinds):
  """Replaces the planner lookups of `kinds` (keys of the lookup table above) while the block runs.

  Yields the dotted names this version of sims lacks (skipped); restores every replaced
  attribute on exit, also when the block raises.
  """
  saved, missing = [], []
  try:
    for kind in kinds:
      for module, name, fn in _LOOKUPS[kind]:
        if hasattr(module, name):
          saved.append((module, name, getattr(module, name)))
          setattr(module, name, fn)
        else:
          missing.append(f"{module.__name__}.{name}")
    yield missing
  finally:
    for module, name, fn in reversed(saved):
      setattr(module, name, fn)


def _planner(base: FleetConfig, **kw) -> FleetConfig:
  return dataclasses.replace(base, planner=dataclasses.replace(base.planner, **kw))


def variants(base: FleetConfig) -> dict:
  """name -> (FleetConfig, VariantEnv fields, lookups replaced by constants)."""
  p = base.planner
  return {
      "physics": (base, dict(costmap=False, control="none", metrics=False), ()),
      "metrics": (base, dict(costmap=False, control="none"), ()),
      "speed_clip": (base, dict(costmap=False, control="clip"), ()),
      "costmap": (base, dict(control="clip"), ()),
      "full": (base, {}, ()),
      "reference_planner": (base, dict(reference=True), ()),
      "candidates_3": (_planner(base, num_speeds=2, num_yaw_rates=1), dict(extra_speeds=False), ()),
      "candidates_half": (_planner(base, num_yaw_rates=max(1, (p.num_yaw_rates + 1) // 2)), {}, ()),
      "candidates_double": (_planner(base, num_yaw_rates=2 * p.num_yaw_rates), {}, ()),
      "const_costmap_lookups": (base, {}, ("costmap",)),
      "const_speed_lookups": (base, {}, ("speed",)),
      "const_nav_lookups": (base, {}, ("nav",)),
      "const_lookups": (base, {}, ("costmap", "speed", "nav")),
      "controller_10hz": (dataclasses.replace(base, controller_hz=10.0), {}, ()),
      "rollout_cumsum": (base, {}, ("rollout_cumsum",)),
      "rollout_chain": (base, {}, ("rollout_chain",)),
      "rollout_fused": (base, {}, ("rollout_fused",)),
  }


def _num_candidates(env: FleetEnv) -> int:
  return int(planner.candidates(env.config, env.zone_speeds).shape[0])


def run_variant(name: str, spec, num_robots: int, num_steps: int, repeats: int) -> dict:
  """Compiles and times one variant; returns its figures."""
  config, fields, lookups = spec
  k = config.robots_per_world
  if num_robots % k:
    raise ValueError(f"num_robots ({num_robots}) must be a multiple of robots_per_world ({k})")
  num_worlds = num_robots // k
  per_env_step = config.ticks_per_step * config.substeps_per_tick
  env_steps = -(-num_steps // per_env_step)
  physics_steps = env_steps * per_env_step
  env = dataclasses.replace(VariantEnv.create(config=config), **fields)
  with patched_lookups(lookups) as missing:
    timed = bench.time_rollout(env, num_worlds, env_steps, repeats=repeats)
  rate = num_robots * physics_steps / timed["run_s"]
  out = {"robot_steps_per_s": rate, "robot_seconds_per_s": rate * config.physics_dt,
         "ns_per_robot_step": 1e9 / rate, "compile_s": timed["compile_s"], "run_s": timed["run_s"],
         "cpu_ns_per_robot_step": 1e9 * timed["cpu_s"] / (num_robots * physics_steps)}
  if env.control == "planner":
    out["candidates"] = _num_candidates(env)
  if missing:
    out["not_patched"] = missing
  return out


def _bare(num_robots: int, num_steps: int, repeats: int) -> dict:
  r = bench.fleet_throughput(num_robots, num_steps, filters=False, repeats=repeats)
  rate = r["robot_steps_per_s"]
  return {"robot_steps_per_s": rate, "robot_seconds_per_s": r["robot_seconds_per_s"],
          "ns_per_robot_step": 1e9 / rate, "compile_s": r["compile_s"], "run_s": r["run_s"]}


def parts(results: dict, key: str = "ns_per_robot_step") -> dict:
  """ns per robot-step of each part, as differences of the measured variants (absent where one failed).

  `key` picks the figure: wall time (default) or 'cpu_ns_per_robot_step' (host CPU time, steadier
  than the wall time on a shared CPU machine; meaningless on a GPU).
  """
  ns = {k: v[key] for k, v in results.items() if isinstance(v, dict) and key in v}
  out = {}

  def diff(name, a, b, scale=1.0):
    if a in ns and b in ns:
      out[name] = (ns[a] - ns[b]) * scale

  if "physics" in ns:
    out["physics"] = ns["physics"]
  diff("fleet_loop_over_bare_mjx", "physics", "bare_mjx")
  diff("metrics", "metrics", "physics")
  diff("speed_filter_goals_clip", "speed_clip", "metrics")
  diff("local_costmap", "costmap", "speed_clip")
  diff("planner", "full", "costmap")
  diff("reference_planner", "reference_planner", "costmap")
  diff("costmap_lookups", "full", "const_costmap_lookups")
  diff("speed_cap_lookups", "full", "const_speed_lookups")
  diff("nav_lookups", "full", "const_nav_lookups")
  diff("all_lookups", "full", "const_lookups")
  diff("controller_half_rate_saves", "full", "controller_10hz")
  full, half = results.get("full"), results.get("candidates_half")
  if isinstance(full, dict) and isinstance(half, dict) and full.get("candidates") != half.get("candidates"):
    out["per_candidate"] = (ns["full"] - ns["candidates_half"]) / (full["candidates"] - half["candidates"])
    out["planner_fixed_part"] = ns["full"] - ns["costmap"] - out["per_candidate"] * full["candidates"]
  if "bare_mjx" in ns and "full" in ns:
    out["full_fraction_of_bare"] = ns["bare_mjx"] / ns["full"]
  return out


def main(argv=None) -> int:
  ap = ArgumentParser(description=__doc__.split("\n")[0])
  ap.add_argument("num_robots", nargs="?", type=int, default=512, help="B, robots in all (default 512)")
  ap.add_argument("--steps", type=int, default=100, help="physics steps per timed call (default 100)")
  ap.add_argument("--repeats", type=int, default=3, help="timed calls per variant, best kept (default 3)")
  ap.add_argument("--only", default="", help="comma-separated variant names (default: all)")
  ap.add_argument("--time-budget", type=float, default=None, metavar="S",
                  help="start no further variant after S seconds (the first always runs; the rest "
                       "are reported as skipped), so a run under a time limit still prints its JSON line")
  args = ap.parse_args(sys.argv[1:] if argv is None else argv)
  base = FleetConfig()
  table = variants(base)
  names = ["bare_mjx", *table]
  if args.only:
    wanted = [n.strip() for n in args.only.split(",") if n.strip()]
    unknown = sorted(set(wanted) - set(names))
    if unknown:
      ap.error(f"unknown variant(s) {unknown}; choose from {names}")
    names = [n for n in names if n in wanted]
  if args.num_robots < 1 or args.steps < 1 or args.repeats < 1:
    ap.error(f"num_robots, --steps and --repeats must be >= 1; got {args.num_robots}, {args.steps}, "
             f"{args.repeats}")
  if args.num_robots % base.robots_per_world:
    ap.error(f"num_robots must be a multiple of robots_per_world = {base.robots_per_world} "
             f"(worlds of {base.robots_per_world} robots); got {args.num_robots}")
  if args.time_budget is not None and not args.time_budget > 0:
    ap.error(f"--time-budget must be > 0 seconds; got {args.time_budget}")
  results = {}
  t0 = time.perf_counter()
  for name in names:
    if results and args.time_budget is not None and time.perf_counter() - t0 > args.time_budget:
      results[name] = f"skipped: --time-budget {args.time_budget:g} s spent"
      print(f"{name:24s} {results[name]}", file=sys.stderr, flush=True)
      continue
    try:
      if name == "bare_mjx":
        results[name] = _bare(args.num_robots, args.steps, args.repeats)
      else:
        results[name] = run_variant(name, table[name], args.num_robots, args.steps, args.repeats)
      r = results[name]
      cpu = f"  cpu {r['cpu_ns_per_robot_step']:9.1f} ns" if "cpu_ns_per_robot_step" in r else ""
      print(f"{name:24s} {r['robot_steps_per_s'] / 1e6:9.3f} M robot-steps/s  {r['ns_per_robot_step']:9.1f} ns"
            f"{cpu}  compile {r['compile_s']:.1f} s", file=sys.stderr, flush=True)
    except Exception as e:  # noqa: BLE001 - report and go on with the other variants
      results[name] = f"{type(e).__name__}: {e}"[:300]
      print(f"{name:24s} FAILED {results[name]}", file=sys.stderr, flush=True)
  report = {"num_robots": args.num_robots, "robots_per_world": base.robots_per_world,
            "physics_steps": args.steps, "physics_dt_s": base.physics_dt,
            "device": str(jax.devices()[0].device_kind), "platform": jax.devices()[0].platform,
            "jax": jax.__version__, "wall_s": time.perf_counter() - t0,
            "variants": results, "parts_ns": parts(results)}
  if jax.devices()[0].platform == "cpu":
    report["parts_cpu_ns"] = parts(results, "cpu_ns_per_robot_step")
  print(json.dumps(report))
  return 0


if __name__ == "__main__":
  sys.exit(main())
