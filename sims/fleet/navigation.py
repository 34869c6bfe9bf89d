"""Global navigation: a distance-to-goal field per goal station, computed with JAX.

The field is a navigation function on a grid graph (8-connected, edge cost =
step length x mean cell weight of its two ends): every reachable cell other
than the goal has a neighbour with a strictly smaller value, so descending it
reaches the goal, and blocked cells (lethal, inscribed or unknown in the global
costmap, which has the keepout zones inflated) are never crossed.

It is solved by fast sweeping: Gauss-Seidel passes as `lax.scan` over rows
(down, up) and over columns (right, left), each propagating through the three
forward neighbours, repeated in a `lax.while_loop` until nothing changes. Each
pass is O(H W S); paths with k turns converge in about k passes, instead of
the O(path length) iterations of a Jacobi relaxation.

The field is computed once per scenario on a grid coarser than the map (a whole
multiple of it, `pool_costmap`) and shared by every robot of every world; a
robot samples it with `nav_value` (bilinear over the finite corners).
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from jaxfilters.types import pytree_dataclass

_F32 = jnp.float32
_SQRT2 = math.sqrt(2.0)
UNREACHABLE = 1e6  # nav_value where every corner is blocked or unreachable (m)


@pytree_dataclass
class NavField:
  """Distance-to-goal fields of S stations on the navigation grid.

  Attributes:
    dist: float32 [S, Hn, Wn], metres (weighted) to station s; +inf if blocked or
      unreachable. With keepout escape (FleetConfig.keepout_escape) one more
      entry, dist[S], is the exit field (`exit_field`): metres to the nearest
      cell outside the keepout zones and their inscribed band.
    origin: float32 [2], world (x, y) of the lower-left corner of cell (0, 0).
    resolution: float32 [], metres per navigation cell.
    stations: float32 [S, 2], world (x, y) of each station (a cell centre).
  """
  dist: jax.Array
  origin: jax.Array
  resolution: jax.Array
  stations: jax.Array

  @property
  def num_stations(self) -> int:
    """S, the number of goal stations."""
    return self.stations.shape[0]


def pool_costmap(cost: np.ndarray, factor: int, *, cost_weight: float = 2.0
                 ) -> tuple[np.ndarray, np.ndarray]:
  """Coarsens a global costmap by `factor` for navigation (host, NumPy).

  A coarse cell is blocked if any of its fine cells is inscribed, lethal or
  unknown (>= 253), so keepout and obstacle cells stay blocked; its weight is
  `1 + cost_weight * max_cost / 252` (higher near obstacles, like navfn's
  cost-aware planning).

  Args:
    cost: uint8 [H, W] global costmap (static + keepout + inflation).
    factor: int >= 1, fine cells per coarse cell along each axis.
    cost_weight: extra weight at cost 252.

  Returns:
    (blocked bool [Hn, Wn], weight float32 [Hn, Wn]) with Hn = ceil(H / factor);
    the padding beyond the map is blocked.
  """
  h, w = cost.shape
  hn, wn = -(-h // factor), -(-w // factor)
  padded = np.full((hn * factor, wn * factor), constants.NO_INFORMATION, np.uint8)
  padded[:h, :w] = cost
  blocks = padded.reshape(hn, factor, wn, factor).max(axis=(1, 3))
  blocked = blocks >= constants.INSCRIBED_INFLATED_OBSTACLE
  weight = (1.0 + cost_weight * np.minimum(blocks, 252).astype(np.float32) / 252.0).astype(np.float32)
  return blocked, weight


def _sweep(d: jax.Array, w: jax.Array) -> jax.Array:
  """One Gauss-Seidel pass along axis 0 (increasing), through the 3 forward neighbours.

  Args:
    d: float32 [H, S, W] distances.
    w: float32 [H, W] cell weights in metres per cell step (+inf blocked).
  """
  inf = jnp.asarray(jnp.inf, _F32)

  def shift(x, by):  # x[..., c - by] along the last axis, inf-filled
    pad = [(0, 0)] * (x.ndim - 1)
    if by > 0:
      return jnp.pad(x, pad + [(by, 0)], constant_values=inf)[..., :-by]
    return jnp.pad(x, pad + [(0, -by)], constant_values=inf)[..., -by:]

  def body(prev, cur):
    d_prev, w_prev = prev
    d_cur, w_cur = cur
    best = jnp.minimum(d_cur, d_prev + 0.5 * (w_prev + w_cur)[None, :])
    for by in (1, -1):
      best = jnp.minimum(best, shift(d_prev, by) + (_SQRT2 * 0.5) * (shift(w_prev, by) + w_cur)[None, :])
    best = jnp.where(jnp.isinf(w_cur)[None, :], d_cur, best)
    return (best, w_cur), best

  _, rest = jax.lax.scan(body, (d[0], w[0]), (d[1:], w[1:]))
  return jnp.concatenate([d[:1], rest], axis=0)


def _four_sweeps(d: jax.Array, w: jax.Array, wt: jax.Array) -> jax.Array:
  """Down, up, right, left passes. d: [H, S, W]; w: [H, W]; wt = w.T."""
  d = _sweep(d, w)
  d = _sweep(d[::-1], w[::-1])[::-1]
  dt = jnp.transpose(d, (2, 1, 0))             # [W, S, H]
  dt = _sweep(dt, wt)
  dt = _sweep(dt[::-1], wt[::-1])[::-1]
  return jnp.transpose(dt, (2, 1, 0))


@functools.partial(jax.jit, static_argnames=("max_passes",))
def distance_field(weight: jax.Array, goal_rows: jax.Array, goal_cols: jax.Array, *,
                   max_passes: int = 200) -> jax.Array:
  """Weighted 8-connected distance from each goal cell to every cell.

  Args:
    weight: float32 [Hn, Wn], metres per unit step through a cell (+inf = blocked).
    goal_rows, goal_cols: int32 [S], the goal cells (must not be blocked).
    max_passes: cap on rounds of four sweeps (converged fields stop early).

  Returns:
    float32 [S, Hn, Wn]: distances in metres; +inf where blocked or unreachable.
  """
  h, w = weight.shape
  s = goal_rows.shape[0]
  d = jnp.full((h, s, w), jnp.inf, _F32)
  d = d.at[goal_rows, jnp.arange(s), goal_cols].set(0.0)
  return _solve(d, weight, max_passes)


@functools.partial(jax.jit, static_argnames=("max_passes",))
def exit_field(weight: jax.Array, sources: jax.Array, *, max_passes: int = 200) -> jax.Array:
  """Weighted 8-connected distance from every cell to the nearest source cell (one multi-source field).

  The keepout escape's "shortest way out": sources are the cells outside the
  keepout zones and their inscribed band, and the weights let a path cross
  zones (not walls), so descending the field leaves a zone the shortest way.

  Args:
    weight: float32 [Hn, Wn], metres per unit step through a cell (+inf = blocked).
    sources: bool [Hn, Wn], cells at distance 0 (blocked ones are ignored).
    max_passes: cap on rounds of four sweeps.

  Returns:
    float32 [1, Hn, Wn]: metres; +inf where blocked or no source is reachable.
  """
  d = jnp.where(sources & jnp.isfinite(weight), 0.0, jnp.inf).astype(_F32)[:, None, :]
  return _solve(d, weight, max_passes)


def _solve(d: jax.Array, weight: jax.Array, max_passes: int) -> jax.Array:
  """Fast sweeping from the initial distances d [H, S, W] to convergence; returns [S, H, W]."""
  wt = weight.T

  def cond(carry):
    _, changed, i = carry
    return changed & (i < max_passes)

  def body(carry):
    d, _, i = carry
    new = _four_sweeps(d, weight, wt)
    return new, jnp.any(new < d), i + 1

  d, _, _ = jax.lax.while_loop(cond, body, (d, jnp.asarray(True), jnp.asarray(0)))
  return jnp.transpose(d, (1, 0, 2))


def nav_value(field: NavField, goal: jax.Array, xy: jax.Array) -> jax.Array:
  """Bilinear distance-to-goal at one point, over the corners that are finite.

  Args:
    field: the shared NavField.
    goal: int32 [], station index.
    xy: float32 [2], world point.

  Returns:
    float32 [] metres; UNREACHABLE where no corner is finite.
  """
  _, hn, wn = field.dist.shape
  g = (xy - field.origin) / field.resolution - 0.5      # continuous cell-centre coordinates
  c0 = jnp.floor(g)
  f = g - c0
  c0 = c0.astype(jnp.int32)
  vals, wts = [], []
  for dy in (0, 1):
    for dx in (0, 1):
      cx, cy = c0[0] + dx, c0[1] + dy
      inside = (cx >= 0) & (cx < wn) & (cy >= 0) & (cy < hn)
      v = field.dist[goal, jnp.clip(cy, 0, hn - 1), jnp.clip(cx, 0, wn - 1)]
      ok = inside & jnp.isfinite(v)
      wgt = (f[0] if dx else 1.0 - f[0]) * (f[1] if dy else 1.0 - f[1])
      vals.append(jnp.where(ok, v, 0.0))
      wts.append(jnp.where(ok, wgt + 1e-6, 0.0))
  vals, wts = jnp.stack(vals), jnp.stack(wts)
  total = jnp.sum(wts)
  return jnp.where(total > 0, jnp.sum(vals * wts) / jnp.where(total > 0, total, 1.0), UNREACHABLE)


def descent_direction(field: NavField, goal: jax.Array, xy: jax.Array) -> jax.Array:
  """Unit vector of steepest descent of the field at xy.

  Differences are one cell wide and one-sided where the other side is
  unreachable (next to a wall), so walls do not dominate the direction.

  Args:
    field: the shared NavField.
    goal: int32 [] station index.
    xy: float32 [2] point (m).

  Returns:
    float32 [2]; zero where the field is flat or unreachable.
  """
  h = field.resolution
  v0 = nav_value(field, goal, xy)

  def slope(e):
    vp, vm = nav_value(field, goal, xy + e), nav_value(field, goal, xy - e)
    okp, okm = vp < UNREACHABLE, vm < UNREACHABLE
    n = okp.astype(_F32) + okm.astype(_F32)
    total = jnp.where(okp, vp - v0, 0.0) + jnp.where(okm, v0 - vm, 0.0)
    return jnp.where(n > 0, total / jnp.maximum(n, 1.0), 0.0)

  g = -jnp.stack([slope(jnp.asarray([1.0, 0.0], _F32) * h), slope(jnp.asarray([0.0, 1.0], _F32) * h)])
  g = jnp.where(v0 < UNREACHABLE, g, 0.0)
  n = jnp.sqrt(jnp.sum(g * g))
  return jnp.where(n > 1e-9, g / jnp.where(n > 1e-9, n, 1.0), 0.0)


def value_and_direction(field: NavField, goal: jax.Array, xy: jax.Array) -> tuple[jax.Array, jax.Array]:
  """`nav_value` and `descent_direction` at one point, with one gather for both.

  The five points the pair reads (xy and xy +- one navigation cell along x and
  y) are evaluated together: their 20 bilinear corners are one flat gather from
  the field instead of 20 separate ones, then the same float32 arithmetic as
  `nav_value` and `descent_direction`. Results agree with them to float rounding
  (XLA may contract a multiply-add differently; the direction, a difference of
  nearby values, within 1e-4; tests/fleet/test_planner_reference.py).

  Args:
    field: the shared NavField.
    goal: int32 [] station index.
    xy: float32 [2] point (m).

  Returns:
    (float32 [] value as `nav_value(field, goal, xy)`, float32 [2] unit vector
    as `descent_direction(field, goal, xy)`).
  """
  s, hn, wn = field.dist.shape
  if s * hn * wn >= 2 ** 31:
    raise ValueError(f"value_and_direction indexes the field as one int32 array; got {s} x {hn} x {wn} "
                     f"cells (must be < 2**31)")
  h = field.resolution
  ex = jnp.asarray([1.0, 0.0], _F32) * h
  ey = jnp.asarray([0.0, 1.0], _F32) * h
  pts = jnp.stack([xy, xy + ex, xy - ex, xy + ey, xy - ey])        # [5, 2]
  g = (pts - field.origin[None, :]) / field.resolution - 0.5
  c0 = jnp.floor(g)
  f = g - c0
  c0 = c0.astype(jnp.int32)
  flat, inside, wgts = [], [], []
  for dy in (0, 1):
    for dx in (0, 1):
      cx, cy = c0[:, 0] + dx, c0[:, 1] + dy
      inside.append((cx >= 0) & (cx < wn) & (cy >= 0) & (cy < hn))
      flat.append((goal * hn + jnp.clip(cy, 0, hn - 1)) * wn + jnp.clip(cx, 0, wn - 1))
      wgts.append((f[:, 0] if dx else 1.0 - f[:, 0]) * (f[:, 1] if dy else 1.0 - f[:, 1]))
  v = field.dist.reshape(-1)[jnp.stack(flat)]                   # [4 corners, 5 points]: one gather
  ok = jnp.stack(inside) & jnp.isfinite(v)
  vals = jnp.where(ok, v, 0.0)
  wts = jnp.where(ok, jnp.stack(wgts) + 1e-6, 0.0)
  total = jnp.sum(wts, axis=0)
  value = jnp.where(total > 0, jnp.sum(vals * wts, axis=0) / jnp.where(total > 0, total, 1.0), UNREACHABLE)
  v0, vxp, vxm, vyp, vym = value[0], value[1], value[2], value[3], value[4]

  def slope(vp, vm):
    okp, okm = vp < UNREACHABLE, vm < UNREACHABLE
    n = okp.astype(_F32) + okm.astype(_F32)
    total = jnp.where(okp, vp - v0, 0.0) + jnp.where(okm, v0 - vm, 0.0)
    return jnp.where(n > 0, total / jnp.maximum(n, 1.0), 0.0)

  grad = -jnp.stack([slope(vxp, vxm), slope(vyp, vym)])
  grad = jnp.where(v0 < UNREACHABLE, grad, 0.0)
  n = jnp.sqrt(jnp.sum(grad * grad))
  return v0, jnp.where(n > 1e-9, grad / jnp.where(n > 1e-9, n, 1.0), 0.0)


def value_and_direction_xy(field: NavField, goal: jax.Array, x: jax.Array, y: jax.Array
                           ) -> tuple[jax.Array, jax.Array, jax.Array]:
  """`value_and_direction` at many points of one goal, elementwise (no stacked arrays).

  The same five points, 20 bilinear corners and float32 arithmetic as
  `value_and_direction`, written as separate gathers and elementwise operations
  on arrays of x's shape, so a GPU computes everything inside the kernel that
  produced x and y (the one-pass planner, `planner.one_pass_terms`) instead of
  writing [corners, points, ...] arrays out. Sums run in a fixed order (results
  agree with `value_and_direction` to float rounding; tests/fleet/test_planner_reference.py).

  Args:
    field: the shared NavField. goal: int32 [] station index.
    x, y: float32 [...] points (m), the same shape.

  Returns:
    (value float32 [...] as `nav_value`, direction unit vector components dx, dy float32 [...]).
  """
  s, hn, wn = field.dist.shape
  if s * hn * wn >= 2 ** 31:
    raise ValueError(f"value_and_direction_xy indexes the field as one int32 array; got {s} x {hn} x {wn} "
                     f"cells (must be < 2**31)")
  h = field.resolution
  dist = field.dist.reshape(-1)

  def value(px, py):
    gx = (px - field.origin[0]) / field.resolution - 0.5
    gy = (py - field.origin[1]) / field.resolution - 0.5
    fx0, fy0 = jnp.floor(gx), jnp.floor(gy)
    fx, fy = gx - fx0, gy - fy0
    cx0, cy0 = fx0.astype(jnp.int32), fy0.astype(jnp.int32)
    num = total = None
    for dy in (0, 1):
      for dx in (0, 1):
        cx, cy = cx0 + dx, cy0 + dy
        inside = (cx >= 0) & (cx < wn) & (cy >= 0) & (cy < hn)
        v = dist[(goal * hn + jnp.clip(cy, 0, hn - 1)) * wn + jnp.clip(cx, 0, wn - 1)]
        ok = inside & jnp.isfinite(v)
        wgt = jnp.where(ok, (fx if dx else 1.0 - fx) * (fy if dy else 1.0 - fy) + 1e-6, 0.0)
        term = jnp.where(ok, v, 0.0) * wgt
        num, total = (term, wgt) if num is None else (num + term, total + wgt)
    return jnp.where(total > 0, num / jnp.where(total > 0, total, 1.0), UNREACHABLE)

  v0 = value(x, y)

  def slope(vp, vm):
    okp, okm = vp < UNREACHABLE, vm < UNREACHABLE
    n = okp.astype(_F32) + okm.astype(_F32)
    total = jnp.where(okp, vp - v0, 0.0) + jnp.where(okm, v0 - vm, 0.0)
    return jnp.where(n > 0, total / jnp.maximum(n, 1.0), 0.0)

  gx = jnp.where(v0 < UNREACHABLE, -slope(value(x + h, y), value(x - h, y)), 0.0)
  gy = jnp.where(v0 < UNREACHABLE, -slope(value(x, y + h), value(x, y - h)), 0.0)
  n = jnp.sqrt(gx * gx + gy * gy)
  safe = jnp.where(n > 1e-9, n, 1.0)
  return v0, jnp.where(n > 1e-9, gx / safe, 0.0), jnp.where(n > 1e-9, gy / safe, 0.0)


def trace_plan(field: NavField, goal: jax.Array, xy: jax.Array, *, num_points: int,
               step: float) -> tuple[jax.Array, jax.Array]:
  """One robot's global plan: the descent of its goal's field from xy, as a polyline.

  The fleet has no path planner of its own: a robot descends the navigation
  function (`value_and_direction`), whose descent is the shortest weighted path
  to the goal. This traces it the way Nav2's planner publishes a plan (world
  metres, first point the robot's position): from xy, one `step` along the
  descent direction per point, until the goal is within one step (the station
  is then the last point), the field gives no direction (flat or unreachable),
  or `num_points` points are used. A longer path is cut there: its last point
  stands in for the goal (AsymmetricInflationLayer's `goal_distance_threshold`
  reads the last point).

  Args:
    field: the shared NavField.
    goal: int32 [], station index (< S).
    xy: float32 [2], the robot position (m).
    num_points: P >= 1, the most points (static).
    step: metres between points (static, > 0).

  Returns:
    (float32 [P, 2] points in world metres, int32 [] points in use in [1, P]);
    points past the length repeat the last one.
  """
  if num_points < 1 or not step > 0:
    raise ValueError(f"trace_plan needs num_points >= 1 and step > 0; got {num_points}, {step}")
  xy = jnp.asarray(xy, _F32)
  station = field.stations[goal]

  def body(carry, _):
    p, n, done = carry
    v, d = value_and_direction(field, goal, p)
    moves = (v < UNREACHABLE) & jnp.any(d != 0.0)
    arrive = v <= step
    go = ~done & (moves | arrive)
    nxt = jnp.where(arrive, station, p + jnp.float32(step) * d)
    p = jnp.where(go, nxt, p)
    return (p, n + go.astype(jnp.int32), done | ~go | arrive), p

  init = (xy, jnp.ones((), jnp.int32), jnp.zeros((), bool))
  (_, n, _), rest = jax.lax.scan(body, init, None, length=num_points - 1)
  return jnp.concatenate([xy[None], rest], axis=0), n
