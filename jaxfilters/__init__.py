"""jaxfilters: Nav2-faithful costmap filters as batched, jittable JAX functions.

Layers, types -> geometry -> filters -> pipelines: imports run one way. Each
filter is written for one robot (`*_one`) and vmapped once at the public edge;
public functions take an explicit leading robot axis B.

Importing the package picks XLA:CPU's classic fusion emitters on jaxlib 0.10 (`xla_flags`), the
setting the test suite and the commands run with, unless XLA_FLAGS already names them; it takes
effect where no JAX backend has started yet in the process.
"""

from jaxfilters import xla_flags

xla_flags.use_fast_cpu_compile()   # first: before anything below can start a JAX backend

from jaxfilters import constants, jaus, ros
from jaxfilters._version import __version__
from jaxfilters.asymmetric_inflation import (AsymmetricInflationConfig, asymmetric_inflate,
                                             asymmetric_inflate_zones)
from jaxfilters.binary import BinaryResult, BinaryState, binary_filter
from jaxfilters.direction import DirectionConfig, DirectionResult, direction_filter
from jaxfilters.geometry import world_to_cell
from jaxfilters.grid import OccupancyGrid
from jaxfilters.inflation import InflationConfig, footprint_radii, inflate
from jaxfilters.keepout import (KeepoutConfig, KeepoutState, keepout_filter, keepout_update_bounds,
                                occ_to_cost)
from jaxfilters.map_io import (MAX_MAP_CELLS, MapMetadata, load_map, load_map_image,
                               load_map_with_metadata, save_map)
from jaxfilters.pipeline import LayersConfig, costmap_pipeline
from jaxfilters.nav2 import (Nav2BinaryFilter, Nav2Costmap, Nav2Filter, Nav2InflationLayer, Nav2KeepoutFilter, Nav2Params,
                             Nav2ParamsError, Nav2ParamsWarning, Nav2Readout, Nav2SpeedFilter, Nav2ZoneFilter,
                             ZoneSetpoint, ZoneStateConfig, load_params)
from jaxfilters.query import binary_at, keepout_cost_at, speed_limit_at, zone_at
from jaxfilters.shapes import (OVERLAY_MAX, OVERLAY_MIN, OVERLAY_SEQ, Circle, Polygon, RasterResult, Shapes,
                               rasterize, rasterize_mask)
from jaxfilters.soft import (signed_distance, soft_keepout_cost, soft_speed_limit,
                             zone_speed_limits)
from jaxfilters.speed import (LookaheadConfig, SpeedResult, SpeedState, speed_filter,
                              speed_filter_lookahead)
from jaxfilters.static_layer import StaticLayerConfig, static_layer
from jaxfilters.types import Costmap, FilterInfo, FilterMask
from jaxfilters.zone import ZoneResult, ZoneState, ZoneTable, zone_filter

__all__ = [
    "__version__", "AsymmetricInflationConfig", "BinaryResult", "BinaryState", "Circle", "Costmap", "DirectionConfig",
    "DirectionResult", "FilterInfo", "FilterMask",
    "InflationConfig", "KeepoutConfig", "KeepoutState", "LayersConfig", "LookaheadConfig",
    "MAX_MAP_CELLS", "MapMetadata", "Nav2BinaryFilter", "Nav2Costmap", "Nav2Filter",
    "Nav2InflationLayer", "Nav2KeepoutFilter", "Nav2Params", "Nav2ParamsError", "Nav2ParamsWarning", "Nav2Readout",
    "Nav2SpeedFilter", "Nav2ZoneFilter", "OVERLAY_MAX", "OVERLAY_MIN", "OVERLAY_SEQ", "OccupancyGrid", "Polygon",
    "RasterResult", "Shapes", "SpeedResult", "SpeedState", "StaticLayerConfig", "ZoneResult",
    "ZoneSetpoint", "ZoneState", "ZoneStateConfig", "ZoneTable", "asymmetric_inflate", "asymmetric_inflate_zones",
    "binary_at", "binary_filter",
    "constants", "costmap_pipeline", "direction_filter", "footprint_radii", "inflate", "jaus", "keepout_cost_at",
    "keepout_filter", "keepout_update_bounds", "load_map", "load_map_image",
    "load_map_with_metadata", "load_params", "occ_to_cost", "rasterize", "rasterize_mask", "ros",
    "save_map", "signed_distance", "soft_keepout_cost", "soft_speed_limit", "speed_filter",
    "speed_filter_lookahead", "speed_limit_at", "static_layer", "world_to_cell", "zone_at",
    "zone_filter", "zone_speed_limits",
]
