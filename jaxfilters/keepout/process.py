"""`keepout_filter`: Nav2's KeepoutFilter::process over a fleet (docs/nav2_semantics.md §4.3-§4.4).

For each visited master cell the mask is sampled at the cell centre and the cost
raised (`data > old or (old == 255 and data >= 253)`, or with
`KeepoutConfig.unknown_overwrite="any"` `data > old or old == 255`), skipping unknown mask cells; in escape mode the
written value is `lethal_override_cost`. `filter_batch` picks the path: the same-frame
fast path (same_frame.py, other_resolution.py), the other-frame fast path
(other_frame.py), or the exact per-cell path (reference.py) for masks too large for
the fast paths' float32 index arithmetic. Every path gives the exact path's integers.

`keepout_filter` is jitted at the edge: an eager call compiles once per shape, config
and plan, and inside a caller's `jit` it inlines. An eager call decides its
batch-level choices on the host first (plan.py) and compiles only the path it takes. A robot whose traced `mask_index` is
outside [0, M) (an eager call raises instead), or whose mask or costmap geometry is
unusable (a traced NaN, inf, negative, zero or subnormal resolution, a non-finite
origin: `types.mask_geometry_ok`, `types.costmap_geometry_ok`), is left untouched and
gets `KeepoutState.error` True.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters.keepout import host_exact, pallas, plan
from jaxfilters.keepout.common import batched_inputs, check_batched_inputs, fill_error, usable_geometry
from jaxfilters.keepout.config import KeepoutConfig, KeepoutState
from jaxfilters.keepout.other_frame import other_frame_batch
from jaxfilters.keepout.reference import general_batch
from jaxfilters.keepout.same_frame import same_frame_batch
from jaxfilters.types import Costmap, FilterMask


def keepout_filter(costmap: Costmap, mask: FilterMask, poses, state: KeepoutState, *,
                   mask_index=None, enabled=None, window=None, transform=None,
                   config: KeepoutConfig = KeepoutConfig()) -> tuple[Costmap, KeepoutState]:
  """Nav2 KeepoutFilter::process over a fleet (docs/nav2_semantics.md §4.3-§4.4).

  Jitted at the edge (config static); inside a caller's `jit` it inlines.

  Args:
    costmap: Costmap with cost uint8 [B, H, W] (the combined map after layers).
    mask: FilterMask with M masks (M = 1 shared, or a stack with mask_index).
    poses: float [B, 3] robot (x, y, yaw) in the costmap frame (used by the
      escape mode through the state, which `keepout_update_bounds` sets).
    state: KeepoutState [B].
    mask_index: optional int [B], which mask each robot uses. Concrete values
      outside [0, M) raise; traced ones leave that robot's costmap and state
      untouched and set `state.error` (never another mask).
    enabled: optional bool [B] or scalar (Nav2 `enabled` / toggle_filter); a
      disabled robot's costmap and state pass through unchanged.
    window: optional int [B, 4] or [4] (min_i, min_j, max_i, max_j) half-open
      update window, clipped to the map; default the whole map.
    transform: optional float [B, 3] or [3] T_mask_from_global (x, y, yaw)
      when the mask frame differs from the costmap frame; None = same frame.
    config: static KeepoutConfig.

  Returns:
    (Costmap with the new cost, new KeepoutState). `KeepoutState.error` [B] is
    True for a robot the call could not run for: a traced mask_index outside
    [0, M), or a mask or costmap whose traced geometry is unusable (resolution
    NaN, inf, <= 0 or subnormal, origin not finite; `types.mask_geometry_ok`,
    `types.costmap_geometry_ok`). That robot's costmap and the rest of its state
    are returned unchanged; it is False for every robot that ran (a disabled
    robot included).

  Raises:
    TypeError / ValueError: inputs of the wrong type, dtype or shape (e.g. a
      Costmap whose cost is not uint8, a state that is not a KeepoutState), or a
      concrete mask_index out of range.
    ValueError: a KeepoutState, poses, mask_index, enabled, window or transform
      whose batch is not the costmaps' B (the message names the array and both
      sizes), at trace time.
    ValueError: `config.kernel="pallas"` on a backend other than GPU without
      `PallasTuning(interpret=True)`.
  """
  if not isinstance(config, KeepoutConfig):
    raise TypeError(f"config must be a KeepoutConfig; got {type(config).__name__}")
  pallas.use_pallas(config.kernel, config.pallas)   # kernel="pallas" off GPU raises here
  config = _process_config(config)
  _check_index_range(costmap, mask)
  if not plan.is_concrete(costmap, mask, poses, state, mask_index, enabled, window, transform):
    idx, idx_ok, poses, enabled, window, transform = batched_inputs(
        costmap, mask, poses, mask_index, enabled, window, transform, "keepout_filter", state)
    return filter_batch(costmap, mask, idx, idx_ok, fill_error(state, costmap.num_robots), window, enabled,
                        transform, config=config)
  # Eager: the checks in Python, the conversions in the program; the fast path with no exact redo
  # in it, then the robots it reports redone exactly (plan.py).
  inputs = check_batched_inputs(costmap, mask, poses, mask_index, enabled, window, transform, "keepout_filter",
                                state)
  if _exact_only(mask, inputs[3]):
    return _eager_batch(costmap, mask, state, *inputs, config=config, exact=True)
  run_plan = plan.make_plan(costmap, mask, state, *inputs, aligned=config.aligned_fast_path, loop=_loop("auto"))
  out, new_state, needs, batched = _eager_batch(costmap, mask, state, *inputs, config=config, plan=run_plan)
  redo = np.flatnonzero(np.asarray(needs))
  if not redo.size:
    return out, new_state
  cpu = _cpu_backend()
  idx, idx_ok, window, enabled, transform = batched
  if state.error is None:
    state = dataclasses.replace(state, error=np.zeros((costmap.num_robots,), bool))
  size = max(8, 1 << int(redo.size - 1).bit_length())      # a power of two: one compile serves many calls
  sel = np.concatenate([redo, np.full(size - redo.size, redo[0])])
  if redo.size <= EXACT_PATH_REDO_MAX and transform is None:
    # A few robots of the same frame: the exact path in integer arithmetic on the host (host_exact.py),
    # nothing to compile. Only their rows travel: on a CPU through NumPy, elsewhere gathered on the
    # device (one small gather and scatter per B and power of two).
    take = (lambda x: np.asarray(x)[redo]) if cpu else (lambda x: np.asarray(jnp.asarray(x)[sel])[:redo.size])
    sub = jax.tree.map(take, (costmap, idx, idx_ok, state, window, enabled))
    done = host_exact.redo(*sub, None, mask=mask, config=config)
    if done is not None:
      return jax.tree.map(lambda x, v: put_rows(x, v, redo, sel, cpu), (out, new_state), done)
  if not cpu or redo.size > HOST_REDO_MAX_FRACTION * costmap.num_robots:
    # The host redo moves the whole fleet's costmaps through the host: on a GPU that copy costs more
    # than the filter (an H200 at B = 16,384: 91 ms against 0.85 ms jitted), and on a CPU a redo of
    # many robots costs more than the whole program. The fleet then runs once more on the device,
    # the exact reruns inside the program (what a caller's jit runs).
    return _eager_batch(costmap, mask, state, *inputs, config=config)
  # On the host (NumPy): a device gather and scatter would compile once per B.
  sub = jax.tree.map(lambda x: np.asarray(x)[sel], (costmap, idx, idx_ok, state, window, enabled, transform))
  sub_out, sub_state = exact_redo(*sub, mask=mask, config=config, exact=size <= EXACT_PATH_REDO_MAX)
  # The padding slots (robot redo[0] again) are dropped.
  return jax.tree.map(lambda x, v: put_rows(x, v, redo, sel, cpu), (out, new_state), (sub_out, sub_state))


# An eager call redoes on the host at most this fraction of its robots (see keepout_filter).
HOST_REDO_MAX_FRACTION = 0.25
# A host redo of at most this many robots (the power-of-two sub-fleet) runs the exact path: same
# frame in integer arithmetic on the host (host_exact.py: nothing to compile; the first call at
# B = 4,096 of benchmarks/latency.py redoes 6 robots, whose exact program compiled for ~1.5 s of its
# ~2.8 s on this project's 2-core CPU), else (a frame transform) the exact per-cell program (at level
# 1, see _EXACT_JITS: ~1.5-1.7 s to compile against ~8 s for the fast path with its exact reruns;
# 8 / 16 robots of 60 x 60 in 2.3 / 4.7 ms). Larger sub-fleets run the fast path with the exact
# reruns in it, whose run time grows far slower with the robots (20 ms at 256, where the exact path
# compiled at level 0 took 380 ms).
EXACT_PATH_REDO_MAX = 16


@functools.partial(jax.jit, static_argnames=("config", "exact", "plan"))
def _eager_batch(costmap, mask, state, mask_index, enabled, window, transform, *, config, exact=False, plan=None):
  """`batched_inputs` and `filter_batch` in one program (an eager call's)."""
  idx, idx_ok, _, enabled, window, transform = batched_inputs(
      costmap, mask, jnp.zeros((costmap.num_robots, 3), jnp.float32), mask_index, enabled, window, transform,
      "keepout_filter", state)
  out = _filter_batch(costmap, mask, idx, idx_ok, fill_error(state, costmap.num_robots), window, enabled,
                      transform, config=config, exact=exact, plan=plan)
  # With a plan, also the batched inputs, for the exact redo of the robots the fast path reports.
  return out if plan is None else (*out, (idx, idx_ok, window, enabled, transform))


def _cpu_backend() -> bool:
  """Whether the arrays live in host memory (the eager redo's rows then travel through NumPy)."""
  return jax.default_backend() == "cpu"


def put_rows(x, v, rows, sel, cpu):
  """x with rows `rows` set to the first rows of v: on a CPU through NumPy, elsewhere a scatter on the
  device over the padded rows `sel` (the padding repeats rows[0] with its own new value)."""
  v = np.asarray(v)[:rows.size]
  if cpu:
    a = np.array(x)
    a[rows] = v
    return jax.device_put(a)
  v = np.concatenate([v, np.repeat(v[:1], sel.size - rows.size, axis=0)])
  return jnp.asarray(x).at[sel].set(v)


def _loop(loop: str) -> str:
  if loop == "auto":
    return "map" if jax.default_backend() == "cpu" else "vmap"
  return loop


def _exact_only(mask: FilterMask, transform) -> bool:
  """Masks too large for the other-frame fast path's float32 index arithmetic run the exact path."""
  hm, wm = mask.data.shape[1:]
  return transform is not None and (max(hm, wm) > 2 ** 17 or hm * wm >= 2 ** 24)


def _check_index_range(costmap: Costmap, mask: FilterMask) -> None:
  """The kernels address the mask stack, padded by a costmap on each side, with int32 flat indices.

  Raises:
    ValueError: M (Hm + 2H) (Wm + 2W) >= 2^31, where an index would wrap and read
      another cell (a static problem: the shapes alone decide it).
  """
  m, hm, wm = (int(n) for n in mask.data.shape)
  h, w = (int(n) for n in costmap.cost.shape[1:])
  cells = m * (hm + 2 * h) * (wm + 2 * w)
  if cells >= 2 ** 31:
    raise ValueError(f"keepout_filter: the mask stack [M, Hm, Wm] = [{m}, {hm}, {wm}] padded by the costmap "
                     f"[{h}, {w}] on each side has {cells} cells; the keepout kernels index it with int32 and "
                     f"take fewer than 2^31 (split the stack or crop the masks)")


def _process_config(config: KeepoutConfig) -> KeepoutConfig:
  """The options process() uses: the robot-in-zone test lives in updateBounds, so fleets with
  different footprints share one compiled filter."""
  if config.robot_in_zone == "center":
    return config
  # replace() keeps every other option (a new one included) as the caller set it.
  return dataclasses.replace(config, robot_in_zone="center", footprint=None, robot_radius=None,
                             min_mask_resolution=None, escape_clearance=0.0)


@functools.partial(jax.jit, static_argnames=("config", "exact", "loop", "plan"))
def filter_batch(costmap, mask, idx, idx_ok, state, window, enabled, transform, *, config,
                 exact=False, loop="auto", plan=None):
  """The batch behind `keepout_filter`, on inputs `common.batched_inputs` checked.

  Args:
    costmap, mask: as keepout_filter. idx int32 [B], idx_ok bool [B]: each robot's mask
      and whether it is in range (a robot whose mask or costmap geometry is unusable is
      also left out here: `common.usable_geometry`). state: KeepoutState [B] with `error`. window int32
      [B, 4], enabled bool [B], transform float32 [B, 3] or None.
    config: static KeepoutConfig.
    exact: static; run only the exact per-cell path (the reference the tests compare
      the fast paths with).
    loop: static; which kernels the fast paths run: "map" (robot by robot, the CPU
      backend's), "vmap" (vectorised over the fleet, the other backends'), or "auto"
      (the default backend's).
    plan: static `plan.Plan` of an eager call (its batch-level choices, made on the
      host from its concrete inputs), or None (decided in the program). With a plan
      no robot is redone exactly and the fast path also returns needs bool [B]: the
      robots whose cost and state must be redone exactly (plan.py).

  Returns:
    (Costmap with the new cost, new KeepoutState), and needs with a plan.
  """
  return _filter_batch(costmap, mask, idx, idx_ok, state, window, enabled, transform, config=config, exact=exact,
                       loop=loop, plan=plan)


def _exact_sub_fleet(costmap, idx, idx_ok, state, window, enabled, transform, *, config, mask, exact):
  """The redo of an eager call's open robots: with `exact` the exact per-cell path (the reference),
  else the fast path with its exact reruns in the program (what a jitted call runs; the tests hold
  it to the exact path's integers)."""
  return _filter_batch(costmap, mask, idx, idx_ok, state, window, enabled, transform, config=config, exact=exact)


# The redo's programs on a CPU. XLA:CPU's LLVM passes take far longer on the fast path with its
# exact reruns at the default optimisation level than at 0 (26 s vs 6.4 s under load here), so the
# large redos (more than EXACT_PATH_REDO_MAX robots, rare) compile at level 0. The exact per-cell
# path, which the usual redo of a few robots runs, compiles at level 1: at level 0 its program ran
# 6x slower (13 ms against 2.1 ms for an 8-robot redo of 60 x 60 windows, so an eager call with open
# robots took 24 ms instead of 2 ms at B = 64), and level 1 adds ~1 s to the README's first call at
# B = 4,096 (1.8 -> 2.9 s cold). The level changes no float semantics (no fast-math either way): the
# same integers, which tests/jaxfilters/test_keepout_dispatch.py checks against the exact path.
_EXACT_JITS = {
    ("cpu", True): jax.jit(_exact_sub_fleet, static_argnames=("config", "exact"),
                           compiler_options={"xla_backend_optimization_level": 1}),
    ("cpu", False): jax.jit(_exact_sub_fleet, static_argnames=("config", "exact"),
                            compiler_options={"xla_backend_optimization_level": 0}),
    "other": jax.jit(_exact_sub_fleet, static_argnames=("config", "exact")),
}


def exact_redo(*args, exact: bool, **kw):
  """The host redo of an eager call's open robots (a sub-fleet of NumPy inputs): `_exact_sub_fleet`
  jitted for this backend (on a CPU at XLA optimisation level 1 for the exact path, 0 for the fast
  path with its exact reruns)."""
  key = ("cpu", bool(exact)) if jax.default_backend() == "cpu" else "other"
  return _EXACT_JITS[key](*args, exact=exact, **kw)


def _filter_batch(costmap, mask, idx, idx_ok, state, window, enabled, transform, *, config,
                  exact=False, loop="auto", plan=None):
  with jax.named_scope("keepout_filter"):
    out_costmap = costmap
    costmap, mask, idx_ok = usable_geometry(costmap, mask, idx, idx_ok)
    loop = _loop(loop)
    if exact or _exact_only(mask, transform):
      if plan is not None:
        raise ValueError("filter_batch: a plan is for the fast paths (exact=False, masks they take)")
      res = general_batch(costmap, mask, idx, idx_ok, state, window, enabled, transform, config=config)
    elif transform is None:
      res = same_frame_batch(costmap, mask, idx, idx_ok, state, window, enabled, config=config, loop=loop,
                             plan=plan)
    else:
      res = other_frame_batch(costmap, mask, idx, idx_ok, state, window, enabled, transform, config=config,
                              loop=loop, plan=plan)
    return (dataclasses.replace(out_costmap, cost=res[0]), *res[1:])
