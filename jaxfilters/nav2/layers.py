"""Internal: a costmap's inflation layers from a Nav2 params file (docs/nav2_semantics.md §9).

`load_params` (`jaxfilters.nav2.params`) calls `inflation_layers` for every costmap: each
`nav2_costmap_2d::InflationLayer` and `nav2_costmap_2d::AsymmetricInflationLayer` listed
under `plugins:` becomes a `Nav2InflationLayer` whose config holds the layer's parameters
(Nav2's defaults where absent), the costmap's resolution and the inscribed radius of its
padded footprint, read the way `Costmap2DROS` does (`getParameters`, `setRobotFootprint`):

* `footprint` (a string such as "[[0.3, 0.2], [0.3, -0.2], [-0.3, -0.2], [-0.3, 0.2]]",
  default "[]") when it parses as at least three (x, y) pairs, its numbers float32 as
  `makeFootprintFromString` keeps them; otherwise (with Nav2's error logged as a
  warning when it was set but invalid) the 16-gon of `robot_radius` (default 0.1);
* padded by `footprint_padding` (default 0.01), a float member in Nav2, so float32;
* the InflationLayer's `custom_inscribed_radius` (Nav2 PR #6223, default -1) replaces
  the inscribed radius when >= 0, with Nav2's "POTENTIAL SAFETY ISSUE" warning; the
  AsymmetricInflationLayer does not read it.
"""

from __future__ import annotations

import re
import warnings

import numpy as np

from jaxfilters.asymmetric_inflation import AsymmetricInflationConfig
from jaxfilters.inflation import InflationConfig, footprint_radii
from jaxfilters.nav2.document import Nav2ParamsError, Node, Reader, parent_namespace, resolve_topic, show
from jaxfilters.nav2.runtime import (ASYMMETRIC_INFLATION_PLUGIN, INFLATION_PLUGIN, Nav2InflationLayer,
                                     Nav2ParamsWarning)

__all__ = ["LAYER_PLUGINS", "RESOLUTION_DEFAULT", "footprint_inscribed_radius", "inflation_layers",
           "parse_footprint"]

LAYER_PLUGINS = (INFLATION_PLUGIN, ASYMMETRIC_INFLATION_PLUGIN)
RESOLUTION_DEFAULT = 0.1          # Costmap2DROS's `resolution` default
_NUMBER = r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*"
_PAIR = re.compile(r"\s*\[" + _NUMBER + "," + _NUMBER + r"\]\s*")


def _warn(message: str) -> None:
  warnings.warn(message, Nav2ParamsWarning, stacklevel=4)


def parse_footprint(text: str) -> list[tuple[float, float]] | None:
  """Nav2's `makeFootprintFromString`: "[[x, y], ...]" -> float32 vertices, or None if it is not
  at least three (x, y) number pairs."""
  s = text.strip()
  if not (s.startswith("[") and s.endswith("]")):
    return None
  inner = s[1:-1].strip()
  pts, pos = [], 0
  while pos < len(inner):
    m = _PAIR.match(inner, pos)
    if m is None:
      return None
    pts.append((float(np.float32(m.group(1))), float(np.float32(m.group(2)))))
    pos = m.end()
    if pos < len(inner):
      if inner[pos] != ",":
        return None
      pos += 1
  if len(pts) < 3 or not all(np.isfinite(v) for p in pts for v in p):
    return None
  return pts


def footprint_inscribed_radius(r: Reader) -> float:
  """The inscribed radius of the costmap's padded footprint (module docstring), in metres."""
  pad = r.get("footprint_padding", "float", 0.01)
  pad32 = np.float32(pad)
  if not np.isfinite(pad32):
    raise Nav2ParamsError(f"{r.where}: parameter 'footprint_padding' must be a finite float32; got {show(pad)}")
  radius = r.get("robot_radius", "float", 0.1)
  text = r.get("footprint", "str", "[]")
  pts = None
  if text not in ("", "[]"):
    pts = parse_footprint(text)
    if pts is None:
      _warn(f"{r.where}: the footprint parameter is invalid: {show(text)}, using radius ({radius}) instead "
            "(Nav2 logs this error and does the same)")
  try:
    if pts is not None:
      return footprint_radii(footprint=pts, footprint_padding=float(pad32))[0]
    return footprint_radii(robot_radius=radius, footprint_padding=float(pad32))[0]
  except ValueError as e:
    raise Nav2ParamsError(f"{r.where}: footprint: {e}") from None


def _layer(r: Reader, costmap: Node, name: str, plugin: str, resolution: float,
           inscribed: float) -> Nav2InflationLayer:
  lw = f"{r.where}: layer '{name}'"
  get = lambda key, kind, default: r.get(f"{name}.{key}", kind, default)
  common = dict(enabled=get("enabled", "bool", True), inflate_unknown=get("inflate_unknown", "bool", False),
                inflate_around_unknown=get("inflate_around_unknown", "bool", False), resolution=resolution)
  threads = get("num_threads", "int", -1)
  plan_topic = None
  if plugin == INFLATION_PLUGIN:
    custom = get("custom_inscribed_radius", "float", -1.0)
    if custom >= 0.0:
      _warn(f"{lw}: POTENTIAL SAFETY ISSUE!!! custom_inscribed_radius {custom} m replaces the footprint's "
            f"inscribed radius {inscribed} m (Nav2 logs this warning and does the same)")
      inscribed = custom
    radius = get("inflation_radius", "float", 0.55)
    try:
      config = InflationConfig(inflation_radius=radius,
                               cost_scaling_factor=get("cost_scaling_factor", "float", 10.0),
                               inscribed_radius=inscribed, **common)
    except ValueError as e:
      raise Nav2ParamsError(f"{lw}: {e}") from None
  else:
    if r.has(f"{name}.custom_inscribed_radius"):
      _warn(f"{lw}: the AsymmetricInflationLayer does not read custom_inscribed_radius; it uses the "
            f"footprint's inscribed radius {inscribed} m")
    if threads < -1:
      raise Nav2ParamsError(f"{lw}: parameter '{name}.num_threads' must be -1 (auto) or > 0 (Nav2's "
                            f"AsymmetricInflationLayer throws); got {threads}")
    tolerance = r.get("transform_tolerance", "float", 0.3)
    if tolerance < 0:
      raise Nav2ParamsError(f"{r.where}: parameter 'transform_tolerance' must be >= 0 (Nav2's "
                            f"AsymmetricInflationLayer throws); got {tolerance}")
    radius = get("inflation_radius", "float", 2.0)
    try:
      config = AsymmetricInflationConfig(
          inflation_radius=radius, cost_scaling_factor_left=get("cost_scaling_factor_left", "float", 4.0),
          cost_scaling_factor_right=get("cost_scaling_factor_right", "float", 4.0),
          goal_distance_threshold=get("goal_distance_threshold", "float", 1.5), inscribed_radius=inscribed,
          **common)
    except ValueError as e:
      raise Nav2ParamsError(f"{lw}: {e}") from None
    plan_topic = resolve_topic(get("plan_topic", "str", "plan"), parent_namespace(costmap.namespace), r.where,
                               f"{name}.plan_topic")
  if radius < inscribed:
    _warn(f"{lw}: the configured inflation radius ({radius}) is smaller than the computed/custom inscribed "
          f"radius ({inscribed}) of your footprint (Nav2 logs this warning)")
  return Nav2InflationLayer(name=name, plugin=plugin, config=config, plan_topic=plan_topic)


def inflation_layers(r: Reader, costmap: Node, names: list[str]) -> tuple[Nav2InflationLayer, ...]:
  """The inflation layers among the `plugins:` entries `names` (others are skipped), in order.

  Raises:
    Nav2ParamsError: a parameter of the wrong type, or one Nav2's layer rejects
      (a negative radius, factor or threshold; num_threads < -1), naming the layer and key.
  """
  chosen = [n for n in names if r.has(f"{n}.plugin") and r.get(f"{n}.plugin", "str") in LAYER_PLUGINS]
  if not chosen:
    return ()
  resolution = RESOLUTION_DEFAULT
  if r.has("resolution"):
    resolution = r.get("resolution", "float")
  inscribed = footprint_inscribed_radius(r)
  return tuple(_layer(r, costmap, n, r.get(f"{n}.plugin", "str"), resolution, inscribed) for n in chosen)
