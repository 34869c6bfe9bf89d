"""The zones a rasteriser draws: Nav2 Vector Objects (polygons, circles) as fixed device slots.

`Polygon` and `Circle` are host descriptions (nav2_msgs PolygonObject with
`closed: true`, CircleObject with `fill: true`); `Shapes` holds a fixed number of
them as traced arrays, so zones can be added, moved or removed between steps
without a recompile. `jaxfilters.shapes` draws them into OccupancyGrid masks and
`jaxfilters.soft` turns them into smooth costs; the rules they follow are
written in `jaxfilters.shapes`' docstring.

Exactness domain: every non-zero coordinate and radius has magnitude in
[2**-32, 2**32] (`COORD_MIN`, `COORD_MAX`); `Shapes.create` refuses others.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from jaxfilters.types import pytree_dataclass
from jaxfilters.validate import float32_values, short_repr

OVERLAY_SEQ = 0
OVERLAY_MAX = 1
OVERLAY_MIN = 2
OVERLAY_TYPES = (OVERLAY_SEQ, OVERLAY_MAX, OVERLAY_MIN)
COORD_MIN = 2.0 ** -32          # smallest non-zero magnitude of the exactness domain
COORD_MAX = 2.0 ** 32           # largest magnitude of the exactness domain


@dataclasses.dataclass(frozen=True, eq=False)
class Polygon:
  """A filled polygon zone (nav2_msgs/PolygonObject with `closed: true`).

  Attributes:
    points: float [N, 2] vertices (x, y) in metres, N >= 3, in the map frame.
    value: OccupancyGrid value written inside, -1..100 (Vector Object
      server default 100). For keepout 100 is lethal, 1..99 graded; for
      speed it is the raw mask value `d` that base/multiplier map to a
      limit; for binary and zone filters the value or zone id.
  """
  points: Any
  value: int = constants.OCC_GRID_OCCUPIED


@dataclasses.dataclass(frozen=True, eq=False)
class Circle:
  """A filled circle zone (nav2_msgs/CircleObject with `fill: true`).

  Attributes:
    center: float [2] (x, y) in metres.
    radius: metres, >= 0 (0 marks only a cell whose centre is the centre).
    value: OccupancyGrid value, -1..100 (default 100), as for Polygon.
  """
  center: Any
  radius: float
  value: int = constants.OCC_GRID_OCCUPIED


def _domain(value, name: str, owner: str) -> np.ndarray:
  v = float32_values(value, name, owner=owner)
  a = np.abs(v.astype(np.float64))
  bad = (a != 0) & ((a < COORD_MIN) | (a > COORD_MAX))
  if np.any(bad):
    raise ValueError(f"{owner}: {name} must be 0 or have magnitude in [2**-32, 2**32] "
                     f"(the exact rasteriser's domain); got {short_repr(value)}")
  return v


def _value(value, owner: str) -> int:
  if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
    raise ValueError(f"{owner}: value must be an integer OccupancyGrid value in -1..100; "
                     f"got {short_repr(value)}")
  if not -1 <= int(value) <= 100:
    raise ValueError(f"{owner}: value must lie in -1..100 (OccupancyGrid: -1 unknown, "
                     f"0..100); got {int(value)}")
  return int(value)


def _polygon_arrays(poly: Polygon, max_vertices: int, owner: str):
  pts = np.asarray(poly.points) if not isinstance(poly.points, np.ndarray) else poly.points
  if pts.ndim != 2 or pts.shape[1] != 2:
    raise ValueError(f"{owner}: points must be [N, 2] (x, y) vertices; got shape {pts.shape}")
  n = pts.shape[0]
  if n < 3:
    raise ValueError(f"{owner}: a polygon needs at least 3 vertices (Vector Object server "
                     f"rule); got {n}")
  if n > max_vertices:
    raise ValueError(f"{owner}: at most max_vertices = {max_vertices} vertices; got {n}")
  pts = _domain(pts, "points", owner)
  padded = np.zeros((max_vertices, 2), np.float32)
  padded[:n] = pts
  return padded, n, _value(poly.value, owner)


def _circle_arrays(circle: Circle, owner: str):
  c = np.asarray(circle.center)
  if c.shape != (2,):
    raise ValueError(f"{owner}: center must be (x, y); got shape {c.shape}")
  c = _domain(c, "center", owner)
  r = _domain(circle.radius, "radius", owner)
  if r.shape != ():
    raise ValueError(f"{owner}: radius must be a scalar; got shape {r.shape}")
  if r < 0:
    raise ValueError(f"{owner}: radius must be >= 0 (Vector Object server rule); got {circle.radius!r}")
  return c, np.float32(r), _value(circle.value, owner)


@pytree_dataclass
class Shapes:
  """A fixed number of polygon and circle slots (add, move, remove: no recompile).

  Leaves may carry a leading [M] (one set of shapes per mask of a stack).
  P polygon slots of up to V vertices, C circle slots. A slot is drawn when
  `*_active`; `*_order` is the overlay order (arrival order in the Vector
  Object server: larger is later, so with OVERLAY_SEQ it wins). Equal orders
  are broken by slot, polygons before circles.

  Attributes:
    vertices: float32 [P, V, 2] metres; slots past `num_vertices` are ignored.
    num_vertices: int32 [P], vertices used, 3..V.
    polygon_value: int8 [P], OccupancyGrid value -1..100.
    polygon_active: bool [P].
    polygon_order: int32 [P].
    center: float32 [C, 2] metres.
    radius: float32 [C] metres, >= 0.
    circle_value: int8 [C].
    circle_active: bool [C].
    circle_order: int32 [C].
  """
  vertices: jax.Array
  num_vertices: jax.Array
  polygon_value: jax.Array
  polygon_active: jax.Array
  polygon_order: jax.Array
  center: jax.Array
  radius: jax.Array
  circle_value: jax.Array
  circle_active: jax.Array
  circle_order: jax.Array

  @property
  def max_polygons(self) -> int:
    return self.vertices.shape[-3]

  @property
  def max_vertices(self) -> int:
    return self.vertices.shape[-2]

  @property
  def max_circles(self) -> int:
    return self.center.shape[-2]

  @classmethod
  def create(cls, shapes: Sequence[Polygon | Circle] = (), *, max_polygons: int | None = None,
             max_vertices: int | None = None, max_circles: int | None = None) -> "Shapes":
    """Builds the slots from shapes listed in arrival (overlay) order.

    Args:
      shapes: Polygon and Circle objects; their position is their overlay
        order, as in the Vector Object server's `shapes` parameter.
      max_polygons, max_vertices, max_circles: slot counts (static shapes of
        the arrays); default the counts given (max_vertices at least 3).
        Leave room to add zones later without a recompile.

    Raises:
      ValueError: a shape that is not a Polygon or Circle, fewer than 3 or
        more than max_vertices vertices, a value outside -1..100 or not an
        integer, a negative radius, coordinates that are not finite float32
        values in the exactness domain, or more shapes than slots.
    """
    shapes = list(shapes)
    polys = [s for s in shapes if isinstance(s, Polygon)]
    circles = [s for s in shapes if isinstance(s, Circle)]
    for i, s in enumerate(shapes):
      if not isinstance(s, (Polygon, Circle)):
        raise ValueError(f"Shapes.create: shape {i} must be a jaxfilters.shapes.Polygon or Circle; "
                         f"got {type(s).__name__}")
    p = len(polys) if max_polygons is None else _count("max_polygons", max_polygons)
    c = len(circles) if max_circles is None else _count("max_circles", max_circles)
    longest = max([3] + [int(np.shape(s.points)[0]) if np.ndim(s.points) == 2 else 3 for s in polys])
    v = longest if max_vertices is None else _count("max_vertices", max_vertices)
    if v < 3:
      raise ValueError(f"Shapes.create: max_vertices must be >= 3; got {v}")
    if len(polys) > p:
      raise ValueError(f"Shapes.create: {len(polys)} polygons given; max_polygons = {p}")
    if len(circles) > c:
      raise ValueError(f"Shapes.create: {len(circles)} circles given; max_circles = {c}")
    out = _empty_arrays(p, v, c)
    pi = ci = 0
    for order, s in enumerate(shapes):
      if isinstance(s, Polygon):
        verts, n, val = _polygon_arrays(s, v, f"Shapes.create: shape {order} (polygon)")
        out["vertices"][pi], out["num_vertices"][pi], out["polygon_value"][pi] = verts, n, val
        out["polygon_active"][pi], out["polygon_order"][pi] = True, order
        pi += 1
      else:
        cen, r, val = _circle_arrays(s, f"Shapes.create: shape {order} (circle)")
        out["center"][ci], out["radius"][ci], out["circle_value"][ci] = cen, r, val
        out["circle_active"][ci], out["circle_order"][ci] = True, order
        ci += 1
    return cls(**{k: jnp.asarray(a) for k, a in out.items()})

  @classmethod
  def empty(cls, max_polygons: int, max_vertices: int, max_circles: int) -> "Shapes":
    """Slots with nothing active (fill them with `set_polygon` / `set_circle`)."""
    return cls.create((), max_polygons=max_polygons, max_vertices=max_vertices, max_circles=max_circles)

  def _host(self) -> dict:
    if self.vertices.ndim != 3:
      raise ValueError("host edits work on one set of shapes (no leading [M]); "
                       f"got vertices of shape {tuple(self.vertices.shape)}")
    return {f.name: np.array(getattr(self, f.name)) for f in dataclasses.fields(self)}

  def _next_order(self, a) -> int:
    orders = [a["polygon_order"][a["polygon_active"]], a["circle_order"][a["circle_active"]]]
    orders = np.concatenate(orders)
    return int(orders.max()) + 1 if orders.size else 0

  def set_polygon(self, slot: int, polygon: Polygon) -> "Shapes":
    """Adds (inactive slot: drawn last) or modifies (active: keeps its order) a polygon.

    Same array shapes, so jitted users of the result do not recompile.

    Raises:
      ValueError: slot out of range, or an invalid polygon (see `create`).
    """
    a = self._host()
    i = _slot("polygon", slot, self.max_polygons)
    verts, n, val = _polygon_arrays(polygon, self.max_vertices, f"Shapes.set_polygon({slot})")
    if not a["polygon_active"][i]:
      a["polygon_order"][i] = self._next_order(a)
    a["vertices"][i], a["num_vertices"][i], a["polygon_value"][i] = verts, n, val
    a["polygon_active"][i] = True
    return Shapes(**{k: jnp.asarray(v) for k, v in a.items()})

  def set_circle(self, slot: int, circle: Circle) -> "Shapes":
    """Adds (inactive slot: drawn last) or modifies (active: keeps its order) a circle.

    Raises:
      ValueError: slot out of range, or an invalid circle (see `create`).
    """
    a = self._host()
    i = _slot("circle", slot, self.max_circles)
    cen, r, val = _circle_arrays(circle, f"Shapes.set_circle({slot})")
    if not a["circle_active"][i]:
      a["circle_order"][i] = self._next_order(a)
    a["center"][i], a["radius"][i], a["circle_value"][i] = cen, r, val
    a["circle_active"][i] = True
    return Shapes(**{k: jnp.asarray(v) for k, v in a.items()})

  def remove_polygon(self, slot: int) -> "Shapes":
    """Deactivates a polygon slot (RemoveShapes). Raises ValueError for a bad slot."""
    i = _slot("polygon", slot, self.max_polygons)
    return dataclasses.replace(self, polygon_active=self.polygon_active.at[i].set(False))

  def remove_circle(self, slot: int) -> "Shapes":
    """Deactivates a circle slot (RemoveShapes). Raises ValueError for a bad slot."""
    i = _slot("circle", slot, self.max_circles)
    return dataclasses.replace(self, circle_active=self.circle_active.at[i].set(False))


def _count(name: str, v) -> int:
  if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or v < 0:
    raise ValueError(f"Shapes.create: {name} must be an integer >= 0; got {short_repr(v)}")
  return int(v)


def _slot(kind: str, slot, size: int) -> int:
  if isinstance(slot, (bool, np.bool_)) or not isinstance(slot, (int, np.integer)) or not 0 <= slot < size:
    raise ValueError(f"{kind} slot must be an integer in [0, {size}); got {short_repr(slot)}")
  return int(slot)


def _empty_arrays(p: int, v: int, c: int) -> dict:
  return dict(
      vertices=np.zeros((p, v, 2), np.float32), num_vertices=np.full((p,), 3, np.int32),
      polygon_value=np.zeros((p,), np.int8), polygon_active=np.zeros((p,), bool),
      polygon_order=np.zeros((p,), np.int32),
      center=np.zeros((c, 2), np.float32), radius=np.zeros((c,), np.float32),
      circle_value=np.zeros((c,), np.int8), circle_active=np.zeros((c,), bool),
      circle_order=np.zeros((c,), np.int32))


def check_overlay_params(default_value, overlay_type) -> None:
  """Host check of the Vector Object server's `default_value` and `overlay_type`.

  Raises:
    ValueError: default_value not an integer in -1..100, or overlay_type not
      0 (sequential), 1 (max) or 2 (min).
  """
  _value(default_value, "default_value")
  if (isinstance(overlay_type, (bool, np.bool_)) or not isinstance(overlay_type, (int, np.integer))
      or int(overlay_type) not in OVERLAY_TYPES):
    raise ValueError(f"overlay_type must be one of {OVERLAY_TYPES} (0 sequential, 1 max, 2 min); "
                     f"got {short_repr(overlay_type)}")


def check_shapes(shapes: Shapes, batch: int | None) -> None:
  """Static checks of a Shapes pytree that reaches a public function (works under jit).

  Args:
    shapes: the slots; batch: None for one set, else the leading [M] expected.

  Raises:
    TypeError: not a Shapes. ValueError: a leaf of the wrong shape or dtype.
  """
  if not isinstance(shapes, Shapes):
    raise TypeError(f"shapes must be a jaxfilters.shapes.Shapes (see Shapes.create); got {type(shapes).__name__}")
  lead = () if batch is None else (batch,)
  p, v = shapes.vertices.shape[-3:-1]
  c = shapes.center.shape[-2]
  want = dict(vertices=(*lead, p, v, 2), num_vertices=(*lead, p), polygon_value=(*lead, p),
              polygon_active=(*lead, p), polygon_order=(*lead, p), center=(*lead, c, 2),
              radius=(*lead, c), circle_value=(*lead, c), circle_active=(*lead, c), circle_order=(*lead, c))
  kinds = dict(vertices="f", center="f", radius="f", polygon_active="b", circle_active="b")
  for name, shp in want.items():
    leaf = getattr(shapes, name)
    if tuple(leaf.shape) != shp:
      raise ValueError(f"Shapes.{name} must have shape {shp}; got {tuple(leaf.shape)}")
    kind = kinds.get(name, "i")
    dt = jnp.dtype(leaf.dtype)
    if (kind == "f" and dt != jnp.float32) or (kind == "b" and dt != jnp.bool_) or (
        kind == "i" and not jnp.issubdtype(dt, jnp.integer)):
      raise ValueError(f"Shapes.{name} has dtype {dt}; expected "
                       f"{ {'f': 'float32', 'b': 'bool', 'i': 'an integer type'}[kind] }")
