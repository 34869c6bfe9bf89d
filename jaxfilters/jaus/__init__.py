"""JAUS CostMap2D codec: ReportCostMap2D / QueryCostMap2D bytes <-> NumPy, host only.

The wire format and every assumption the codec makes are in docs/jaus.md
(§11 lists them). Two public versions of the message exist and differ on the
wire; both are supported as *profiles*:

  profile   Query / Report     MapWidth, MapHeight        data variants (vtag)
  "iop"     0xD738 / 0xD742    uint16 scaled [0, 10000] m  0 list, 1 confidence, 2 rle
  "design"  0x2C11 / 0x4C11    uint32 scaled [0, 10000] m  + 3 attractiveness (decode only)

The package has four parts:

  jaus.messages  the message types (`CostMap2DReport`, `CostMap2DQuery`, the
                 poses), the profiles and the scaled-integer fields.
  jaus.wire      bytes <-> messages (`encode_report`, `decode`, `decode_all`),
                 hex text, and message files (`load_messages`): regular files
                 of at most `MAX_FILE_BYTES`, grids of at most `MAX_MAP_CELLS`.
  jaus.costs     occupancy <-> Nav2 cost <-> run-length level (`mapping`).
  jaus.grid      messages <-> OccupancyGrid (`grid_to_reports` with tiles,
                 `report_to_grid`, `reports_to_grid`).

Errors: every problem with message bytes or a message file raises
`JausDecodeError`, a ValueError carrying the byte offset (None for the file
itself) and the reason; building or encoding a message from bad values raises
ValueError (TypeError for a wrong type). The run-length variant is lossy (3-bit
costs): `grid_to_reports` needs `lossy=True` for costs it would change, and a
decoded run-length report has `quantised` True.
"""

from jaxfilters.jaus.costs import (MAPPINGS, cost_to_occupancy, cost_to_rle_level,
                                   occupancy_to_cost, rle_level_to_cost)
from jaxfilters.jaus.grid import (AXES, JausTile, grid_to_report, grid_to_reports, report_to_grid,
                                  reports_to_grid)
from jaxfilters.jaus.messages import (PROFILES, RLE_LEVEL_COST, VARIANTS, CostMap2DQuery,
                                      CostMap2DReport, GlobalPose, JausProfile, LocalPose)
from jaxfilters.jaus.wire import (MAX_FILE_BYTES, MAX_MESSAGES, JausDecodeError, decode,
                                  decode_all, decode_query, decode_report, encode_query,
                                  encode_report, from_hex, fuzz_target, load_messages,
                                  read_message_file, to_hex)
from jaxfilters.map_decode import MAX_MAP_CELLS

__all__ = [
    "AXES", "MAPPINGS", "MAX_FILE_BYTES", "MAX_MAP_CELLS", "MAX_MESSAGES", "PROFILES",
    "RLE_LEVEL_COST", "VARIANTS", "CostMap2DQuery", "CostMap2DReport", "GlobalPose", "JausDecodeError",
    "JausProfile", "JausTile", "LocalPose", "cost_to_occupancy", "cost_to_rle_level", "decode",
    "decode_all", "decode_query", "decode_report", "encode_query", "encode_report", "from_hex",
    "fuzz_target", "grid_to_report", "grid_to_reports", "load_messages", "occupancy_to_cost",
    "read_message_file", "report_to_grid", "reports_to_grid", "rle_level_to_cost", "to_hex",
]
