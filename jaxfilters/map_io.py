"""Map I/O, the public face: Nav2 map_server loading and map_saver writing (docs/nav2_semantics.md §10).

Loading (`load_map`, `load_map_with_metadata`, `load_map_image`, `MapMetadata`) is
`jaxfilters.map_load`, which documents Nav2's rules; writing (`save_map`) is `jaxfilters.map_save`.
This module re-exports both so `jaxfilters.map_io.X` keeps working.
"""

from jaxfilters.map_load import (MAP_MODES, MAX_MAP_CELLS, MAX_YAML_BYTES, MapMetadata, load_map, load_map_image,
                                 load_map_with_metadata)
from jaxfilters.map_save import save_map

__all__ = ["MAP_MODES", "MAX_MAP_CELLS", "MAX_YAML_BYTES", "MapMetadata", "load_map",
           "load_map_image", "load_map_with_metadata", "save_map"]
