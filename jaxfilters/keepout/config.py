"""Keepout options, per-robot state and the mask-value-to-cost rule (docs/nav2_semantics.md §1.4, §4)."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from jaxfilters import constants
from jaxfilters import footprint as footprint_lib
from jaxfilters.keepout import pallas
from jaxfilters.keepout.pallas import PallasTuning
from jaxfilters.types import pytree_dataclass

_F32 = jnp.float32
UNKNOWN_OVERWRITES = pallas.UNKNOWN_OVERWRITES
"""The values of `KeepoutConfig.unknown_overwrite`."""
EMPTY_BOX = (np.inf, np.inf, -np.inf, -np.inf)
"""The empty world box (min_x, min_y, max_x, max_y) of `KeepoutState.acc_box`."""


def occ_to_cost(data: jax.Array) -> jax.Array:
  """Mask value -> cost (docs/nav2_semantics.md §1.4): round-half-away(2.54 * d), -1 -> 255.

  Values outside -1..100 (never produced by map_server; undefined behaviour in
  Nav2) are treated as unknown (255), as docs/nav2_semantics.md §1.4 recommends. Uses integer
  arithmetic: floor((254 d + 50) / 100) == floor(2.54 d + 0.5) exactly.

  Args:
    data: int8 (or any integer) array of OccupancyGrid values.

  Returns:
    uint8 array of the same shape.
  """
  d = jnp.asarray(data).astype(jnp.int32)
  cost = (d * 254 + 50) // 100
  return jnp.where((d >= 0) & (d <= 100), cost, constants.NO_INFORMATION).astype(jnp.uint8)


@dataclasses.dataclass(frozen=True)
class KeepoutConfig:
  """Static keepout options (Nav2 parameters `<filter>.override_lethal_cost` etc.).

  Attributes:
    override_lethal_cost: escape mode; while the robot's centre (or, with
      robot_in_zone "footprint", its footprint) is in a lethal keepout cell,
      every cell the filter writes gets `lethal_override_cost`.
    lethal_override_cost: clamped to [0, 252] like Nav2 (MAX_NON_OBSTACLE).
    aligned_fast_path: let `keepout_filter` read a robot's mask cells as one
      slice (same integers) when, at run time, its exact per-column and
      per-row mask indices are consecutive (same frame, equal
      resolutions up to the float32 rounding of the mask's); False always
      gathers them through the two index vectors. An eager call makes the
      choice on the host (keepout/plan.py); inside a caller's `jit` the
      vectorised loop makes it at run time (`lax.cond`, both compiled).
    kernel: what runs the aligned path's cells: "xla" (one fused XLA loop, every
      backend), "pallas" (the Triton kernel of `jaxfilters.keepout.pallas`, same
      integers; needs a GPU backend, or `pallas.interpret=True`, else
      `keepout_filter` raises) or "auto" (Pallas on a GPU backend, XLA
      elsewhere). The gather path is XLA either way.
    frame_kernel: what runs the vectorised other-frame (SE2) cells: "auto"
      (default: the Triton kernel `pallas.other_frame_write` on a GPU backend,
      the XLA edge-table loop elsewhere), "xla" or "pallas" (as `kernel`: a GPU
      backend or `pallas.interpret=True`). The same integers either way.
    pallas: static `jaxfilters.keepout.pallas.PallasTuning` of the kernels (layout, blocks,
      warps, interpreter).
    robot_in_zone: the escape mode's robot-in-zone test: "center" (Nav2: the
      robot centre's mask cell) or "footprint" (beyond Nav2, Nav2 issue #6505 / PR
      #6526: any lethal mask cell whose centre the footprint covers, or the
      centre test; exact rule and hysteresis in jaxfilters/footprint.py). Needs
      override_lethal_cost.
    footprint: "footprint" mode: polygon ((x, y), ...) in the robot frame
      (metres, >= 3 vertices, float32 values), or None.
    robot_radius: "footprint" mode: disc radius (m) instead of a polygon.
    min_mask_resolution: "footprint" mode: the finest mask resolution (m) it
      meets; sizes the static window of mask cells the test reads (a finer
      mask raises eagerly and sets `KeepoutState.error` under jit).
    escape_clearance: "footprint" mode, m >= 0: escape, once on, stays on until
      the footprint grown by this distance is clear of lethal cells
      (`footprint.band_clearance` gives the value that leaves the robot's
      centre cell outside the zone's inscribed band).
    unknown_overwrite: which known mask costs overwrite a master cell that is
      unknown (NO_INFORMATION, 255) (docs/nav2_semantics.md §4.4). "inscribed"
      (default, Nav2 main since PR #6329, `KeepoutFilter::process`): only a mask
      cost >= 253 (INSCRIBED_INFLATED_OBSTACLE or LETHAL_OBSTACLE), so free and
      low-cost mask cells leave unknown space unknown; the rule is
      `data > old || (old == NO_INFORMATION && data >= 253)`. "any" (Nav2
      before #6329): every known mask cost, `data > old || old == NO_INFORMATION`.
      Known master cells are raised the same way under both.
  """
  override_lethal_cost: bool = False
  lethal_override_cost: int = constants.MAX_NON_OBSTACLE
  aligned_fast_path: bool = True
  kernel: str = "xla"
  frame_kernel: str = "auto"
  pallas: PallasTuning = PallasTuning()
  robot_in_zone: str = "center"
  footprint: tuple | None = None
  robot_radius: float | None = None
  min_mask_resolution: float | None = None
  escape_clearance: float = 0.0
  unknown_overwrite: str = "inscribed"

  @property
  def footprint_window(self) -> int:
    """n: the footprint test reads (2n + 1) x (2n + 1) mask cells per robot (0 in "center" mode)."""
    if self.robot_in_zone != "footprint":
      return 0
    return footprint_lib.window_cells(self.footprint, self.robot_radius, self.escape_clearance,
                                      self.min_mask_resolution)

  def __post_init__(self):
    pallas.check_unknown_overwrite(self.unknown_overwrite)
    pallas.check_kernel(self.kernel)
    pallas.check_kernel(self.frame_kernel)
    if not isinstance(self.pallas, PallasTuning):
      raise ValueError(f"pallas must be a keepout.pallas.PallasTuning; got {type(self.pallas).__name__}")
    if not isinstance(self.aligned_fast_path, (bool, np.bool_)):
      raise ValueError(f"aligned_fast_path must be a bool; got {self.aligned_fast_path!r}")
    object.__setattr__(self, "aligned_fast_path", bool(self.aligned_fast_path))
    if not isinstance(self.override_lethal_cost, (bool, np.bool_)):
      raise ValueError(f"override_lethal_cost must be a bool; got {self.override_lethal_cost!r}")
    if int(self.lethal_override_cost) != self.lethal_override_cost:
      raise ValueError(f"lethal_override_cost must be an integer cost; got {self.lethal_override_cost!r}")
    # Nav2 clamps rather than rejects.
    object.__setattr__(self, "lethal_override_cost",
                       int(min(max(int(self.lethal_override_cost), 0), constants.MAX_NON_OBSTACLE)))
    opts = footprint_lib.check_options(self.robot_in_zone, self.footprint, self.robot_radius,
                                       self.min_mask_resolution, self.escape_clearance,
                                       self.override_lethal_cost)
    for name, value in opts.items():
      object.__setattr__(self, name, value)


@pytree_dataclass
class KeepoutState:
  """Per-robot state KeepoutFilter carries between cycles.

  Attributes:
    is_pose_lethal: bool [B], robot centre in a lethal keepout cell (escape mode).
    last_pose_lethal: bool [B], the value at the end of the last process().
    acc_box: float32 [B, 4] world (min_x, min_y, max_x, max_y) accumulated while
      the robot is in a zone; (+inf, +inf, -inf, -inf) when empty.
    error: bool [B], the last call could not run for this robot because its
      traced `mask_index` was outside [0, M) or its mask's or costmap's traced
      geometry was unusable (`types.mask_geometry_ok`,
      `types.costmap_geometry_ok`): nothing was written and the rest of its
      state was kept. After `keepout_update_bounds` with a
      "footprint" KeepoutConfig it is also True where the mask is finer than
      `min_mask_resolution` (the footprint test saw only its window).
      None in a hand-built state.
  """
  is_pose_lethal: jax.Array
  last_pose_lethal: jax.Array
  acc_box: jax.Array
  error: jax.Array | None = None

  @classmethod
  def create(cls, num_robots: int) -> "KeepoutState":
    """The state before the first cycle: not in a zone, empty box, no error."""
    return cls(jnp.zeros((num_robots,), bool), jnp.zeros((num_robots,), bool),
               jnp.tile(jnp.asarray(EMPTY_BOX, _F32), (num_robots, 1)),
               jnp.zeros((num_robots,), bool))


def mask_cost_plus_one_table() -> np.ndarray:
  """uint8 [256]: entry v is (occ_to_cost(int8 v) + 1) mod 256, so unknown (255) -> 0."""
  d = np.arange(256, dtype=np.uint8).view(np.int8).astype(np.int32)
  cost = np.where((d >= 0) & (d <= 100), (d * 254 + 50) // 100, constants.NO_INFORMATION)
  return ((cost + 1) % 256).astype(np.uint8)
