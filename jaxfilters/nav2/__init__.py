"""Nav2 params import and ready filter bundles: a `nav2_params.yaml` -> filter objects per costmap.

    params = load_params("sims/assets/nav2_params.yaml")
    g = params.global_costmap
    out = g.readout(poses)          # every enabled filter's first cycle at B poses

Three parts, each an internal module (use the names listed here):
`jaxfilters.nav2.document` reads the YAML strictly into nodes, typed
parameters and topic names; `jaxfilters.nav2.params` wires the filters the
way Nav2 does (filter -> info server -> mask server) and builds the bundles;
`jaxfilters.nav2.runtime` holds the bundles (`Nav2Costmap` and one
`Nav2*Filter` per filter kind) and their jitted readout.
"""

from jaxfilters.nav2.document import MAX_NAME_CHARS, MAX_PARAMS_BYTES, MAX_PARAMS_DEPTH, Nav2ParamsError
from jaxfilters.nav2.params import Nav2Params, load_params
from jaxfilters.nav2.runtime import (ASYMMETRIC_INFLATION_PLUGIN, BINARY_PLUGIN, COSTMAPS, INFLATION_PLUGIN,
                                     KEEPOUT_PLUGIN, SPEED_PLUGIN, ZONE_PLUGIN, Nav2BinaryFilter, Nav2Costmap,
                                     Nav2Filter, Nav2InflationLayer, Nav2KeepoutFilter,
                                     Nav2ParamsWarning, Nav2Readout, Nav2SpeedFilter, Nav2ZoneFilter,
                                     ZoneSetpoint, ZoneStateConfig)

__all__ = [
    "ASYMMETRIC_INFLATION_PLUGIN", "BINARY_PLUGIN", "COSTMAPS", "INFLATION_PLUGIN", "KEEPOUT_PLUGIN", "MAX_NAME_CHARS", "MAX_PARAMS_BYTES", "MAX_PARAMS_DEPTH",
    "SPEED_PLUGIN", "ZONE_PLUGIN", "Nav2BinaryFilter", "Nav2Costmap", "Nav2Filter", "Nav2InflationLayer",
    "Nav2KeepoutFilter", "Nav2Params", "Nav2ParamsError", "Nav2ParamsWarning", "Nav2Readout", "Nav2SpeedFilter", "Nav2ZoneFilter",
    "ZoneSetpoint", "ZoneStateConfig", "load_params",
]
