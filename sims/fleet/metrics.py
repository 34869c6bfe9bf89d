"""Fleet metrics, accumulated inside the jitted step, and their host summary.

Per robot (leading axis K inside one world, [W, K] over worlds):

* distance travelled and goals reached;
* time in each speed zone and the highest speed seen there (compliance: the
  zone's limit in m/s plus `FleetConfig.speed_tolerance`), sampled every
  physics step at the robot centre's speed-mask cell;
* keepout: physics steps with the robot centre on a lethal keepout-mask cell,
  and entries into one (both must stay 0 for robots started outside zones);
  with keepout escape (FleetConfig.keepout_escape) also over the footprint
  (the robot's disc, jaxfilters.footprint's rule): steps, entries, the last
  time it was on a zone, whether it is on one now, and which robots started
  on one (they must leave; the entries count only comes-back and new ones);
* robot-robot proximity at the controller rate: contacts (centres closer than
  2 * radius) and near misses (closer than 2 * radius + near_miss_margin),
  counted as events (rising edges) per robot, and the smallest separation;
* stuck events: the progress checker (0.5 m in 10 s) failed;
* emergency stops: ticks where every planner candidate was rejected;
* with a direction mask (one-way lanes, Scenario.direction): physics steps
  driven the wrong way along a lane (the robot centre's mask cell holds a
  direction and the velocity direction is outside its sector,
  `jaxfilters.direction`; slower than `WRONG_WAY_MIN_SPEED` is not driving)
  and wrong-way traversals (rising edges of that).

The per-step kernels are written for one world ([K] leaves); `summarize`
turns the final [W, K] metrics into plain Python for summary.json.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import geometry
from jaxfilters.direction import DirectionConfig, wrong_way_cells
from jaxfilters.footprint import footprint_in_zone_one
from jaxfilters.keepout import pose_in_lethal_zone_one
from jaxfilters.mask_lookup import mask_cell, mask_leaves
from jaxfilters.types import FilterMask, pytree_dataclass

_F32 = jnp.float32
WRONG_WAY_MIN_SPEED = 0.05   # m/s: slower is turning or standing, not driving along a lane


@pytree_dataclass
class Metrics:
  """Accumulated metrics of the K robots of one world.

  Attributes:
    distance: float32 [K], metres travelled.
    goals_reached: int32 [K].
    zone_time: float32 [K, Z], seconds in each speed zone (zone 0 = no limit).
    zone_max_speed: float32 [K, Z], highest linear speed (m/s) seen in each zone.
    keepout_steps: int32 [K], physics steps with the centre on a keepout cell.
    keepout_entries: int32 [K], entries into a keepout cell.
    contacts: int32 [K], contact events with another robot.
    near_misses: int32 [K], near-miss events.
    min_separation: float32 [K], smallest centre distance to another robot (m).
    stuck_events: int32 [K], progress-checker failures.
    emergency_stops: int32 [K], ticks with no admissible candidate.
    footprint_steps: int32 [K], physics steps with the footprint on a lethal keepout cell.
    footprint_entries: int32 [K], footprint entries into a zone (rising edges; a
      robot started in one enters only by coming back).
    footprint_last_time: float32 [K], simulated seconds when the footprint was last
      on a zone (-1 never).
    footprint_now: bool [K], the footprint is on a zone at the last physics step.
    started_in_keepout: bool [K], the footprint was on a zone at reset.
    wrong_way_steps: int32 [K], physics steps driven against a one-way lane.
    wrong_way_entries: int32 [K], wrong-way traversals (rising edges of a wrong-way step).
    wrong_way_now: bool [K], the last physics step was a wrong-way step.
    (The footprint fields stay at their initial values without keepout escape,
    the wrong-way ones without a direction mask.)
  """
  distance: jax.Array
  goals_reached: jax.Array
  zone_time: jax.Array
  zone_max_speed: jax.Array
  keepout_steps: jax.Array
  keepout_entries: jax.Array
  contacts: jax.Array
  near_misses: jax.Array
  min_separation: jax.Array
  stuck_events: jax.Array
  emergency_stops: jax.Array
  footprint_steps: jax.Array
  footprint_entries: jax.Array
  footprint_last_time: jax.Array
  footprint_now: jax.Array
  started_in_keepout: jax.Array
  wrong_way_steps: jax.Array
  wrong_way_entries: jax.Array
  wrong_way_now: jax.Array

  @classmethod
  def zeros(cls, num_robots: int, num_zones: int) -> "Metrics":
    """Metrics of K robots over Z zones before the first step.

    Counters and times are 0 and min_separation is +inf (no other robot seen yet).

    Args:
      num_robots: K.
      num_zones: Z, including zone 0 (no limit).

    Returns:
      Metrics with leaves [K] or [K, Z].
    """
    k, z = num_robots, num_zones
    i = jnp.zeros((k,), jnp.int32)
    return cls(distance=jnp.zeros((k,), _F32), goals_reached=i, zone_time=jnp.zeros((k, z), _F32),
               zone_max_speed=jnp.zeros((k, z), _F32), keepout_steps=i, keepout_entries=i,
               contacts=i, near_misses=i, min_separation=jnp.full((k,), jnp.inf, _F32),
               stuck_events=i, emergency_stops=i, footprint_steps=i, footprint_entries=i,
               footprint_last_time=jnp.full((k,), -1.0, _F32), footprint_now=jnp.zeros((k,), bool),
               started_in_keepout=jnp.zeros((k,), bool), wrong_way_steps=i, wrong_way_entries=i,
               wrong_way_now=jnp.zeros((k,), bool))


def zone_at(speed_mask: FilterMask, zone_table: jax.Array, xy: jax.Array) -> jax.Array:
  """Speed zone id at one point: the robot centre's mask cell; 0 off the mask.

  Args:
    speed_mask: FilterMask (M = 1) of the speed filter.
    zone_table: int32 [256] zone id by mask byte (WorldParams.zone_table).
    xy: float32 [2] point (m) in the mask frame.

  Returns:
    int32 [] zone id (0 = no limit, or off the mask).
  """
  _, h, w = speed_mask.data.shape
  mx, my, valid = geometry.world_to_cell(xy[0], xy[1], speed_mask.origin[0], speed_mask.resolution[0], w, h,
                                         None if speed_mask.origin_lo is None else speed_mask.origin_lo[0])
  byte = jax.lax.bitcast_convert_type(speed_mask.data[0, my, mx], jnp.uint8).astype(jnp.int32)
  return jnp.where(valid, zone_table[byte], 0)


def in_keepout(keepout_mask: FilterMask, xy: jax.Array) -> jax.Array:
  """Whether the point's keepout-mask cell is lethal (Nav2's "pose in keepout", docs/nav2_semantics.md §4.2).

  Args:
    keepout_mask: FilterMask (M = 1) of the keepout filter.
    xy: float32 [2] point (m) in the mask frame.

  Returns:
    bool []; False off the mask.
  """
  lo = None if keepout_mask.origin_lo is None else keepout_mask.origin_lo[0]
  return pose_in_lethal_zone_one(keepout_mask.data[0], keepout_mask.origin[0], keepout_mask.resolution[0], xy,
                                 lo)


def footprint_in_keepout(keepout_mask: FilterMask, xy: jax.Array, *, radius: float, window: int) -> jax.Array:
  """Whether a robot's footprint (a disc) covers a lethal keepout cell (jaxfilters.footprint's rule).

  Args:
    keepout_mask: FilterMask (M = 1) of the keepout filter.
    xy: float32 [2] robot centre (m) in the mask frame.
    radius: static, the robot radius (m).
    window: static window half-size in mask cells (`jaxfilters.footprint.window_cells`
      at the mask's resolution).

  Returns:
    bool []; cells off the mask never count.
  """
  lo = None if keepout_mask.origin_lo is None else keepout_mask.origin_lo[0]
  return footprint_in_zone_one(keepout_mask.data[0], keepout_mask.origin[0], keepout_mask.resolution[0],
                               jnp.stack([xy[0], xy[1], jnp.float32(0.0)]), radius=radius, window=window,
                               mask_origin_lo=lo)


def wrong_way(direction_mask: FilterMask, xy: jax.Array, velocity: jax.Array) -> jax.Array:
  """Whether a robot is driving against its cell's lane (`jaxfilters.direction`'s rule, default sector).

  Args:
    direction_mask: FilterMask (M = 1) of type 5.
    xy: float32 [2] robot centre (m) in the mask frame; velocity: float32 [2] (m/s).

  Returns:
    bool []; False off the mask, on a cell without a direction, or slower than
    WRONG_WAY_MIN_SPEED.
  """
  data, origin, res, info = mask_leaves(direction_mask, 0)
  d, inside = mask_cell(data, origin, res, xy)
  heading = jnp.arctan2(velocity[1], velocity[0])
  wrong, _, _ = wrong_way_cells(d, info, heading, jnp.asarray(DirectionConfig().half_width, _F32))
  return inside & wrong & (jnp.hypot(velocity[0], velocity[1]) > WRONG_WAY_MIN_SPEED)


def wrong_way_update(m: Metrics, now: jax.Array) -> Metrics:
  """Accumulates one physics step of the wrong-way metrics for K robots (now bool [K])."""
  return dataclasses.replace(
      m, wrong_way_steps=m.wrong_way_steps + now.astype(jnp.int32),
      wrong_way_entries=m.wrong_way_entries + (now & ~m.wrong_way_now).astype(jnp.int32), wrong_way_now=now)


def footprint_update(m: Metrics, now: jax.Array, t: jax.Array) -> Metrics:
  """Accumulates one physics step of the footprint keepout metrics for K robots.

  Args:
    m: Metrics [K]; `m.footprint_now` holds the last step's flags.
    now: bool [K] footprint on a zone at this step.
    t: float32 [] simulated seconds at this step.

  Returns:
    The new Metrics.
  """
  return dataclasses.replace(
      m, footprint_steps=m.footprint_steps + now.astype(jnp.int32),
      footprint_entries=m.footprint_entries + (now & ~m.footprint_now).astype(jnp.int32),
      footprint_last_time=jnp.where(now, t, m.footprint_last_time), footprint_now=now)


def physics_update(m: Metrics, prev_in_keepout: jax.Array, xy: jax.Array, step_len: jax.Array,
                   speed: jax.Array, zone: jax.Array, keepout: jax.Array, dt: float
                   ) -> tuple[Metrics, jax.Array]:
  """Accumulates one physics step for K robots.

  Args:
    m: Metrics [K]; prev_in_keepout: bool [K].
    xy: float32 [K, 2] (unused beyond shape checks); step_len: float32 [K] metres moved.
    speed: float32 [K] linear speed (m/s); zone: int32 [K]; keepout: bool [K].
    dt: physics timestep (s).

  Returns:
    (new Metrics, new in_keepout flags).
  """
  del xy
  z = m.zone_time.shape[1]
  onehot = jax.nn.one_hot(zone, z, dtype=_F32)                          # [K, Z]
  return dataclasses.replace(
      m,
      distance=m.distance + step_len,
      zone_time=m.zone_time + dt * onehot,
      zone_max_speed=jnp.maximum(m.zone_max_speed, jnp.where(onehot > 0, speed[:, None], 0.0)),
      keepout_steps=m.keepout_steps + keepout.astype(jnp.int32),
      keepout_entries=m.keepout_entries + (keepout & ~prev_in_keepout).astype(jnp.int32),
  ), keepout


def proximity_update(m: Metrics, prev_contact: jax.Array, prev_near: jax.Array, xy: jax.Array,
                     radius: float, near_margin: float):
  """Accumulates robot-robot proximity for K robots at one instant.

  Args:
    m: Metrics [K]; prev_contact, prev_near: bool [K] flags of the last check.
    xy: float32 [K, 2] robot positions.
    radius: robot radius (m); near_margin: m.

  Returns:
    (new Metrics, contact flags bool [K], near flags bool [K]).
  """
  k = xy.shape[0]
  d = jnp.linalg.norm(xy[:, None, :] - xy[None, :, :], axis=-1)
  d = jnp.where(jnp.eye(k, dtype=bool), jnp.inf, d)
  nearest = jnp.min(d, axis=1)
  contact = nearest < 2.0 * radius
  near = nearest < 2.0 * radius + near_margin
  return dataclasses.replace(
      m,
      contacts=m.contacts + (contact & ~prev_contact).astype(jnp.int32),
      near_misses=m.near_misses + (near & ~prev_near).astype(jnp.int32),
      min_separation=jnp.minimum(m.min_separation, nearest),
  ), contact, near


def summarize(metrics: Metrics, *, zone_labels, zone_limits, zone_speed, speed_tolerance: float,
              seconds: float, footprint: bool = False, escape_within: float | None = None) -> dict:
  """Host summary of final metrics.

  Args:
    metrics: Metrics with leaves [W, K, ...] (worlds, robots per world).
    zone_labels, zone_limits, zone_speed: per zone (World fields).
    speed_tolerance: m/s allowed above a zone's limit (physics lag).
    seconds: simulated time.
    footprint: the footprint keepout metrics were recorded (keepout escape);
      False reports them as None.
    escape_within: s, a robot started in a zone must be out (footprint clear)
      by then and stay out; None: by the end of the run.

  Returns:
    A JSON-ready dict: 'fleet' totals and compliance per zone, and 'robots'
    (one dict per robot, world-major order). Contacts and near misses are
    robot-events (a pair coming into contact counts once for each robot).
    `fleet['keepout_ok']`: no centre entry and no centre step for robots
    started outside zones, and with footprint metrics no footprint entry and
    every robot started in a zone escaped in time.
  """
  m = jax.tree.map(lambda a: np.asarray(a).reshape((-1,) + np.shape(a)[2:]), metrics)
  b = m.distance.shape[0]
  zones = []
  for z, label in enumerate(zone_labels):
    limit = float(zone_speed[z])
    top = float(m.zone_max_speed[:, z].max()) if b else 0.0
    zones.append({
        "zone": label, "limit": float(zone_limits[z]),
        "limit_mps": None if not np.isfinite(limit) else limit,
        "time_s": float(m.zone_time[:, z].sum()),
        "max_speed_mps": top,
        "compliant": bool(not np.isfinite(limit) or top <= limit + speed_tolerance),
    })
  sep = m.min_separation[np.isfinite(m.min_separation)]
  fleet = {
      "robots": int(b), "seconds": float(seconds),
      "distance_m": float(m.distance.sum()),
      "goals_reached": int(m.goals_reached.sum()),
      "keepout_steps": int(m.keepout_steps.sum()),
      "keepout_entries": int(m.keepout_entries.sum()),
      "contacts": int(m.contacts.sum()),
      "near_misses": int(m.near_misses.sum()),
      "min_separation_m": float(sep.min()) if sep.size else None,
      "stuck_events": int(m.stuck_events.sum()),
      "robots_stuck": int((m.stuck_events > 0).sum()),
      "emergency_stops": int(m.emergency_stops.sum()),
      "wrong_way_steps": int(m.wrong_way_steps.sum()),
      "wrong_way_entries": int(m.wrong_way_entries.sum()),
      "speed_tolerance_mps": float(speed_tolerance),
      "speed_compliant": all(zn["compliant"] for zn in zones),
      "zones": zones,
  }
  started = m.started_in_keepout.astype(bool)
  outside_steps = int(m.keepout_steps[~started].sum())
  outside_entries = int(m.keepout_entries[~started].sum())
  fleet["keepout_steps_started_outside"] = outside_steps
  fleet["keepout_entries_started_outside"] = outside_entries
  # A robot started in a zone may move its centre onto a zone cell while it escapes (its
  # footprint is in the zone already); entering from outside shows as a footprint entry.
  ok = outside_entries == 0 and outside_steps == 0
  limit = seconds if escape_within is None else escape_within
  escaped = started & ~m.footprint_now.astype(bool) & (m.footprint_last_time <= limit)
  if footprint:
    fleet.update({
        "keepout_metric": "footprint (robot disc) and centre",
        "footprint_steps": int(m.footprint_steps.sum()),
        "footprint_entries": int(m.footprint_entries.sum()),
        "robots_started_in_keepout": int(started.sum()),
        "robots_escaped": int(escaped.sum()),
        "escape_within_s": float(limit),
        "escape_time_max_s": float(m.footprint_last_time[escaped].max()) if escaped.any() else None,
        "robots_in_keepout_at_end": int(m.footprint_now.astype(bool).sum()),
    })
    ok = ok and fleet["footprint_entries"] == 0 and bool(np.all(escaped[started]))
  else:
    fleet.update({"keepout_metric": "centre", "footprint_steps": None, "footprint_entries": None,
                  "robots_started_in_keepout": int(started.sum())})
  fleet["keepout_ok"] = bool(ok)
  robots = []
  for i in range(b):
    robots.append({
        "robot": i,
        "distance_m": float(m.distance[i]),
        "goals_reached": int(m.goals_reached[i]),
        "zone_time_s": {label: float(m.zone_time[i, z]) for z, label in enumerate(zone_labels)},
        "zone_max_speed_mps": {label: float(m.zone_max_speed[i, z]) for z, label in enumerate(zone_labels)},
        "keepout_entries": int(m.keepout_entries[i]),
        "contacts": int(m.contacts[i]),
        "near_misses": int(m.near_misses[i]),
        "min_separation_m": float(m.min_separation[i]) if np.isfinite(m.min_separation[i]) else None,
        "stuck_events": int(m.stuck_events[i]),
        "emergency_stops": int(m.emergency_stops[i]),
        "wrong_way_entries": int(m.wrong_way_entries[i]),
        "started_in_keepout": bool(started[i]),
        "footprint_entries": int(m.footprint_entries[i]) if footprint else None,
        "escape_time_s": float(m.footprint_last_time[i]) if footprint and escaped[i] else None,
    })
  return {"fleet": fleet, "robots": robots}
