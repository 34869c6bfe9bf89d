"""KeepoutFilter (docs/nav2_semantics.md §4): write no-go zones from a mask into each robot's costmap.

Nav2's filter runs in two phases per costmap cycle, and so does this package:

* `keepout_update_bounds` is `KeepoutFilter::updateBounds` (docs/nav2_semantics.md §4.2, bounds.py): it grows
  the update window when a new mask arrives and runs the robot-in-zone test of the
  escape mode (`override_lethal_cost`).
* `keepout_filter` is `KeepoutFilter::process` (docs/nav2_semantics.md §4.3-§4.4, process.py): for each
  visited master cell, sample the mask at the cell centre and raise the cost.

Lanes (docs/nav2_semantics.md §4) are keepout masks with graded values 1..99, which
give intermediate costs round(2.54 * d).

Both are written for one robot (`keepout_one`, `keepout_update_bounds_one`) and
vmapped once at the public edge. The package holds one module per path, each giving
the integers of the exact per-cell path (reference.py):

* same_frame.py: the mask in the costmap's frame; a robot whose mask cells are one
  slice of the mask reads them as one (prologue.py decides which);
* other_resolution.py: the same frame, mask cells gathered through exact index vectors;
* other_frame.py: a frame transform (SE2), floors decided with a proof or by edge tables;
* packed.py: the word arithmetic of the vectorised kernels; pallas.py: the Pallas kernel
  of `KeepoutConfig(kernel="pallas")`; common.py: what the path modules share;
* plan.py: an eager call's choices, made on the host before tracing; host_exact.py: the
  exact same-frame path in integer arithmetic on the host, for the few robots an eager
  call redoes (no program to compile).
"""

from jaxfilters.keepout.bounds import keepout_update_bounds, keepout_update_bounds_one, pose_in_lethal_zone_one
from jaxfilters.keepout.config import KeepoutConfig, KeepoutState, mask_cost_plus_one_table, occ_to_cost
from jaxfilters.keepout.pallas import PallasTuning
from jaxfilters.keepout.process import keepout_filter
from jaxfilters.keepout.reference import keepout_one

__all__ = [
    "KeepoutConfig",
    "KeepoutState",
    "PallasTuning",
    "keepout_filter",
    "keepout_one",
    "keepout_update_bounds",
    "keepout_update_bounds_one",
    "mask_cost_plus_one_table",
    "occ_to_cost",
    "pose_in_lethal_zone_one",
]
