"""Map I/O, the public face: Nav2 map_server loading and map_saver writing (docs/nav2_semantics.md §10).

`load_map` reads a map YAML and its image into an `OccupancyGrid` exactly as
Nav2's current (Eigen) `nav2_map_server::loadMapFromYaml` does: inclusive
float32 thresholds, free applied last, alpha < 255 meaning unknown in trinary
and scale, raw bytes wrapped to int8, and the image rows flipped so grid row 0
is the bottom image row. `load_map_with_metadata` also returns the YAML's
settings as a `MapMetadata`. `load_map_image` is the pure NumPy pixel
conversion they use. `save_map` writes `<name>.yaml` + image the way
`map_saver` does, or, given a `MapMetadata`, so that the map loads back exactly.

Deliberate deviations from Nav2 (bad input fails loudly instead of loading a plausible wrong map):
  - Bad input raises instead of returning a load status: `FileNotFoundError`
    for a missing YAML or image, `ValueError` (naming the file and the key)
    for everything else, whatever the files contain.
  - Nav2 does not check `resolution` or the thresholds when loading; we
    require resolution and origin to be finite and normal in float32 (the
    device's precision; resolution > 0), thresholds in [0, 1] and
    `free_thresh < occupied_thresh` (so Nav2's "free wins" order is only
    visible when both thresholds round to the same float32).
  - Files are read strictly (`jaxfilters.map_decode`): regular files only;
    YAML at most `MAX_YAML_BYTES`, without aliases, merge keys or duplicate
    keys; images PNG, Netpbm (P1-P6) or uncompressed BMP only, at most
    `MAX_MAP_CELLS` cells, complete and uncorrupted (PNG CRCs and zlib stream,
    exact Netpbm raster sizes, samples <= maxval, palette indices inside the
    palette). Nav2 reads any format GraphicsMagick knows.
  - Colour images are reduced to gray with Pillow's ITU-R 601 luma
    (`(19595 R + 38470 G + 7471 B + 2**15) >> 16`, i.e. `convert("L")`).
    GraphicsMagick's fixed-point luma may differ from it by 1 on some colours;
    gray images and colour pixels with R = G = B are exact.
  - 16-bit gray images (PGM with maxval > 255, 16-bit gray PNG) are scaled to
    8 bits with `round(v / 257)` as a 16-bit-quantum GraphicsMagick build does;
    Pillow has already stretched PGM maxvals below 65535 to the full 16-bit
    range. 16-bit colour PNGs are reduced by Pillow to the high byte of each
    sample (GraphicsMagick rounds; they may differ by 1 before the luma).
  - Saving supports only the formats Nav2 recommends (png, pgm, bmp); Nav2
    would warn and try any format GraphicsMagick can write. Numbers are written
    with the shortest repr that reads back as the same float64 (Nav2 writes
    resolution, origin x/y and scale thresholds to 3 decimals, so 0.0004 m
    became 0.000), and the origin yaw as given (Nav2 normalises it to
    (-pi, pi] through a quaternion).
"""

from jaxfilters.map_load import (MAP_MODES, MAX_MAP_CELLS, MAX_YAML_BYTES, MapMetadata, load_map, load_map_image,
                                 load_map_with_metadata)
from jaxfilters.map_save import save_map

__all__ = ["MAP_MODES", "MAX_MAP_CELLS", "MAX_YAML_BYTES", "MapMetadata", "load_map",
           "load_map_image", "load_map_with_metadata", "save_map"]
