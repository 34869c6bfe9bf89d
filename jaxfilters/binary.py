"""BinaryFilter (docs/nav2_semantics.md §6): flip a per-robot boolean when the robot enters a zone.

State in, new state plus `published` out. Nav2's publish rules:
* outside the mask: state = default_state, published on **every** cycle;
* unknown cell (d == -1): nothing;
* `base + d * multiplier > flip_threshold` (strict, decided exactly): state =
  !default_state, published only when it was default_state; otherwise state =
  default_state, published only when it differed.
`BinaryState.create` starts at False whatever `default_state` is, as Nav2's
construction does (its first publish is false even with default_state true).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxfilters import constants
from jaxfilters import geometry
from jaxfilters import validate
from jaxfilters.mask_lookup import mask_cell, mask_leaves, transform_point
from jaxfilters.types import FilterMask, mask_geometry_ok, pytree_dataclass, robot_inputs

_F32 = jnp.float32


@pytree_dataclass
class BinaryState:
  """Per-robot BinaryFilter state: `binary_state` bool [B]."""
  binary_state: jax.Array

  @classmethod
  def create(cls, num_robots: int) -> "BinaryState":
    """Every robot's state False, as Nav2 constructs the filter (whatever `default_state` is)."""
    return cls(jnp.zeros((num_robots,), bool))


@pytree_dataclass
class BinaryResult:
  """One BinaryFilter cycle per robot.

  Attributes:
    binary_state: bool [B], the state after this cycle.
    published: bool [B], Nav2 would publish std_msgs/Bool(binary_state).
    in_mask: bool [B], the robot was on a known mask cell.
    error: bool [B], the robot's traced mask_index was outside [0, M) or its
      mask's traced geometry is unusable (`types.mask_geometry_ok`): its
      state was kept and nothing published.
  """
  binary_state: jax.Array
  published: jax.Array
  in_mask: jax.Array
  error: jax.Array | None = None


def binary_cell(d, info, default_state, flip_threshold):
  """Nav2's BinaryFilter rule for one mask value (docs/nav2_semantics.md §6).

  Args:
    d: int32 [] raw mask value. info: FilterInfo with scalar leaves.
    default_state: bool []. flip_threshold: float32 [].

  Returns:
    (state bool [], `not default_state` where `base + d * multiplier >
    flip_threshold` (strict, decided exactly), else `default_state`; known
    bool [], False on an unknown cell (-1), where Nav2 changes nothing).
  """
  above = geometry.exact_sign_affine(d, info.multiplier, info.base, flip_threshold) > 0
  return jnp.where(above, ~default_state, default_state), d != constants.OCC_GRID_UNKNOWN


def binary_filter_one(state, data, mask_origin, mask_res, info, pose, default_state,
                      flip_threshold, enabled, transform):
  """BinaryFilter::process for one robot (scalar leaves; see module docstring)."""
  xy = pose[:2] if transform is None else transform_point(transform, pose[:2])
  d, inside = mask_cell(data, mask_origin, mask_res, xy)
  # A mask of another type is never subscribed in Nav2: the filter does nothing.
  active = enabled & (info.type == constants.BINARY_FILTER)
  target, known = binary_cell(d, info, default_state, flip_threshold)
  known = inside & known
  s = state.binary_state
  new = jnp.where(inside, jnp.where(known, target, s), default_state)
  published = jnp.where(inside, known & (new != s), True)
  new = jnp.where(active, new, s)
  return BinaryState(new), BinaryResult(new, active & published, active & known, jnp.asarray(False))


def _per_robot(name, value, dtype, b):
  v = jnp.asarray(value, dtype)
  if v.shape not in ((), (b,)):
    raise ValueError(f"{name} must be a scalar or [B] = ({b},); got shape {tuple(v.shape)}")
  return jnp.broadcast_to(v, (b,))


def binary_filter(mask: FilterMask, poses, state: BinaryState, *, default_state=False,
                  flip_threshold=50.0, mask_index=None, enabled=None,
                  transform=None) -> tuple[BinaryState, BinaryResult]:
  """Nav2 BinaryFilter over a fleet. Jitted at the edge (inlines inside `jit`).

  Args:
    mask: FilterMask of type 3 (other types make the filter inert, as in Nav2).
    poses: float [B, 3].
    state: BinaryState [B].
    default_state: bool [B] or scalar (Nav2 `default_state`).
    flip_threshold: float [B] or scalar (Nav2 `flip_threshold`, default 50.0),
      compared as float32 (must be finite in float32).
    mask_index, enabled, transform: as jaxfilters.speed.speed_filter (a traced
      out-of-range mask_index keeps the state, publishes nothing, sets `error`).

  Returns:
    (new BinaryState, BinaryResult [B]).
  """
  if not isinstance(state, BinaryState):
    raise TypeError(f"state must be a BinaryState (BinaryState.create); got {type(state).__name__}")
  b = state.binary_state.shape[0]
  idx, idx_ok, poses, enabled, transform = robot_inputs(mask, poses, b, mask_index, enabled, transform,
                                                        state=state)
  if not isinstance(flip_threshold, jax.core.Tracer):
    validate.float32_values(flip_threshold, "flip_threshold", owner="binary_filter")
  ds = jnp.asarray(default_state)
  if ds.dtype != jnp.bool_:
    raise ValueError(f"default_state must be bool (scalar or [B]); got {ds.dtype}")
  default_state = _per_robot("default_state", ds, bool, b)
  flip_threshold = _per_robot("flip_threshold", flip_threshold, _F32, b)
  return _binary_jit(mask, poses, state, default_state, flip_threshold, idx, idx_ok, enabled, transform)


@jax.jit
def _binary_jit(mask, poses, state, default_state, flip_threshold, idx, idx_ok, enabled, transform):
  with jax.named_scope("binary_filter"):
    idx_ok = idx_ok & mask_geometry_ok(mask)[idx]

    def one(st, i, ok, pose, ds, thr, en, tf):
      new, out = binary_filter_one(st, *mask_leaves(mask, i), pose, ds, thr, en, tf)
      kept = jax.tree.map(lambda a, b: jnp.where(ok, a, b), new, st)
      out = BinaryResult(kept.binary_state, out.published & ok, out.in_mask & ok, ~ok)
      return kept, out

    return jax.vmap(one, in_axes=(0, 0, 0, 0, 0, 0, 0, None if transform is None else 0))(
        state, idx, idx_ok, poses, default_state, flip_threshold, enabled, transform)
