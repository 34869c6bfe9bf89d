"""ZoneParameterFilter (docs/nav2_semantics.md §7): mask value -> zone id -> a row of per-zone parameters.

Nav2 sets ROS parameters on other nodes; here each zone is a row of a table of
P float parameters, and the filter yields, per robot, the parameter values in
force after Nav2's rules:

* entering zone M != 0 from N: parameters M sets take M's values; parameters N
  touched that M does not set go back to their nominal default if they have
  one, else keep N's value; state 0 restores every nominal default;
* leaving the mask applies state 0 with no state event; an unknown cell changes
  nothing; the first in-mask cycle always applies a state (an event 0 too);
* a zone id with no configured row is an error in Nav2 (it throws): here the
  robot's state is left untouched and `error` is set (under `jit` a value
  problem is masked and flagged, never raised);
* a mask whose info type is not 4 (zone parameter) is refused by Nav2: the
  filter is inert for that robot (state kept, no event, no error);
* a traced `mask_index` outside [0, M), or a mask whose traced geometry is
  unusable (`types.mask_geometry_ok`), keeps the robot's state and sets `error`.

`zone_filter` is jitted at the edge (inlines inside a caller's `jit`).
"""

from __future__ import annotations

from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from jaxfilters import validate
from jaxfilters.mask_lookup import mask_cell, mask_leaves, transform_point
from jaxfilters.types import FilterMask, check_robot_inputs, mask_geometry_ok, pytree_dataclass, robot_inputs

NUM_ZONES = 128  # int8 mask values 0..127


@pytree_dataclass
class ZoneTable:
  """Per-zone parameter rows.

  Attributes:
    values: float32 [Z, P], zone z's value for each parameter (Z = 128).
    sets: bool [Z, P], zone z sets parameter p.
    configured: bool [Z], zone z is configured (zone 0 always is).
    nominal: float32 [P], nominal default per parameter.
    has_nominal: bool [P].
  """
  values: jax.Array
  sets: jax.Array
  configured: jax.Array
  nominal: jax.Array
  has_nominal: jax.Array

  @classmethod
  def create(cls, parameters: list[str], nominal_defaults: Mapping[str, float],
             states: Mapping[int, Mapping[str, float]]) -> "ZoneTable":
    """Builds the table from Nav2-style configuration.

    Args:
      parameters: the P parameter names (columns).
      nominal_defaults: name -> value restored in state 0.
      states: zone id (1..127 reachable from int8 masks) -> {name: value}.

    Raises:
      ValueError: an id outside 1..127, a parameter name not in `parameters`,
        or a value that is not a finite float32 (NaN, beyond 3.4e38, subnormal).
    """
    cols = {n: k for k, n in enumerate(parameters)}
    if len(cols) != len(parameters):
      raise ValueError(f"parameter names must be unique; got {parameters}")
    p = len(parameters)
    values = np.zeros((NUM_ZONES, p), np.float32)
    sets = np.zeros((NUM_ZONES, p), bool)
    configured = np.zeros((NUM_ZONES,), bool)
    configured[0] = True
    nominal = np.zeros((p,), np.float32)
    has_nominal = np.zeros((p,), bool)
    for name, v in nominal_defaults.items():
      if name not in cols:
        raise ValueError(f"nominal default {name!r} is not one of the parameters {parameters}")
      nominal[cols[name]] = validate.float32_values(v, f"nominal default {name!r}", owner="ZoneTable.create")
      has_nominal[cols[name]] = True
    for zid, setpoints in states.items():
      if int(zid) != zid or not 1 <= zid < NUM_ZONES:
        raise ValueError(f"zone id must be an integer in 1..{NUM_ZONES - 1} (int8 mask values); got {zid!r}")
      configured[zid] = True
      for name, v in setpoints.items():
        if name not in cols:
          raise ValueError(f"zone {zid} sets {name!r}, which is not one of the parameters {parameters}")
        values[zid, cols[name]] = validate.float32_values(v, f"zone {zid} value of {name!r}",
                                                          owner="ZoneTable.create")
        sets[zid, cols[name]] = True
    return cls(*(jnp.asarray(a) for a in (values, sets, configured, nominal, has_nominal)))


@pytree_dataclass
class ZoneState:
  """Per-robot zone state.

  Attributes:
    current: int32 [B], current zone id (0 = nominal).
    initialized: bool [B], a state has been applied since reset.
    params: float32 [B, P], parameter values in force.
  """
  current: jax.Array
  initialized: jax.Array
  params: jax.Array

  @classmethod
  def create(cls, table: ZoneTable, num_robots: int) -> "ZoneState":
    """Starts every robot uninitialised with the nominal defaults in force."""
    return cls(jnp.zeros((num_robots,), jnp.int32), jnp.zeros((num_robots,), bool),
               jnp.tile(table.nominal, (num_robots, 1)))


@pytree_dataclass
class ZoneResult:
  """One ZoneParameterFilter cycle per robot.

  Attributes:
    zone: int32 [B], the zone id in force.
    params: float32 [B, P], the parameter values in force.
    event: bool [B], Nav2 would publish a UInt8 state event (value `zone`).
    error: bool [B], the mask named a zone with no configuration (Nav2 throws),
      the robot's traced mask_index was outside [0, M), or its mask's traced
      geometry is unusable (`types.mask_geometry_ok`).
  """
  zone: jax.Array
  params: jax.Array
  event: jax.Array
  error: jax.Array


def _apply(table, prev_zone, prev_params, new_zone):
  """Parameter values after switching prev_zone -> new_zone."""
  restore = table.has_nominal & (table.sets[prev_zone] | (new_zone == 0))
  restored = jnp.where(restore, table.nominal, prev_params)
  return jnp.where(table.sets[new_zone] & (new_zone != 0), table.values[new_zone], restored)


def zone_cell(d):
  """Nav2's ZoneParameterFilter rule for one mask value: (zone id int32 [] in 0..127, known bool []).

  The zone id is the mask value (docs/nav2_semantics.md §7); a negative (unknown)
  value is not a zone and changes nothing.
  """
  return jnp.clip(d, 0, NUM_ZONES - 1).astype(jnp.int32), d >= 0


def zone_filter_one(state, table, data, mask_origin, mask_res, info, pose, enabled, transform):
  """ZoneParameterFilter::process for one robot (scalar leaves; see module docstring)."""
  # Nav2 only WARNs on non-default base/multiplier and ignores them; a type other
  # than 4 is refused, so such a mask drives nothing.
  enabled = enabled & (info.type == constants.ZONE_PARAMETER_FILTER)
  xy = pose[:2] if transform is None else transform_point(transform, pose[:2])
  d, inside = mask_cell(data, mask_origin, mask_res, xy)
  zid, known = zone_cell(d)
  # Outside: back to state 0 without an event (only if initialised and not already 0).
  leave = ~inside & state.initialized & (state.current != 0)
  # Inside a known cell: apply when uninitialised or different.
  switch = inside & known & (~state.initialized | (zid != state.current))
  error = switch & ~table.configured[zid]
  apply_in = switch & ~error
  new_zone = jnp.where(leave, 0, jnp.where(apply_in, zid, state.current))
  new_params = jnp.where(leave | apply_in, _apply(table, state.current, state.params, new_zone), state.params)
  new_init = state.initialized | apply_in
  new_state = ZoneState(new_zone, new_init, new_params)
  new_state = jax.tree.map(lambda a, b: jnp.where(enabled, a, b), new_state, state)
  return new_state, ZoneResult(new_state.current, new_state.params, enabled & apply_in, enabled & error)


def zone_filter(mask: FilterMask, poses, state: ZoneState, table: ZoneTable, *, mask_index=None,
                enabled=None, transform=None) -> tuple[ZoneState, ZoneResult]:
  """Nav2 ZoneParameterFilter over a fleet. Jitted at the edge.

  Args:
    mask: FilterMask of type 4 (other types make the filter inert, as Nav2
      refuses them; base/multiplier are ignored like Nav2 does).
    poses: float [B, 3].
    state: ZoneState [B].
    table: ZoneTable shared by the fleet.
    mask_index, enabled, transform: as jaxfilters.speed.speed_filter.

  Returns:
    (new ZoneState, ZoneResult [B]).
  """
  if not isinstance(state, ZoneState):
    raise TypeError(f"state must be a ZoneState (ZoneState.create); got {type(state).__name__}")
  if not isinstance(table, ZoneTable):
    raise TypeError(f"table must be a ZoneTable (ZoneTable.create); got {type(table).__name__}")
  b = state.current.shape[0]
  # The checks here, in Python; the conversions in the program (no eager device operation).
  poses, mask_index, enabled, transform = check_robot_inputs(mask, poses, b, mask_index, enabled, transform,
                                                             state=state)
  if state.params.shape[1:] != table.nominal.shape:
    raise ValueError(f"ZoneState has {state.params.shape[1:]} parameters but the table has "
                     f"{table.nominal.shape}; build the state with ZoneState.create(table, B)")
  return _zone_jit(mask, state, table, poses, mask_index, enabled, transform)


@jax.jit
def _zone_jit(mask, state, table, poses, mask_index, enabled, transform):
  idx, idx_ok, poses, enabled, transform = robot_inputs(mask, poses, state.current.shape[0], mask_index, enabled,
                                                        transform, state=state)
  with jax.named_scope("zone_filter"):
    idx_ok = idx_ok & mask_geometry_ok(mask)[idx]

    def one(st, i, ok, pose, en, tf):
      new, out = zone_filter_one(st, table, *mask_leaves(mask, i), pose, en & ok, tf)
      return new, ZoneResult(out.zone, out.params, out.event, out.error | ~ok)

    return jax.vmap(one, in_axes=(0, 0, 0, 0, 0, None if transform is None else 0))(
        state, idx, idx_ok, poses, enabled, transform)
