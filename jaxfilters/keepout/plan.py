"""Internal: an eager keepout call's batch-level choices, made on the host before tracing.

XLA compiles both branches of a `lax.cond`, and on a GPU a batch-level predicate travels
to the host and back. Each fast path brackets its float32 arithmetic
and redoes exactly the few robots a bracket leaves open (an update window or a cell
centre exactly on a mask-cell edge). Inside a caller's `jit` that redo is part of the
program. An eager call (concrete inputs: a notebook cell, a Python control loop) instead
runs the fast path with a static `Plan` and no redo in it: the program returns which
robots need the exact arithmetic, and the host redoes only those (`process.py`): a few
robots of the same frame in integer arithmetic on the host (`host_exact.py`, nothing to
compile), else a jitted exact program on a small sub-fleet whose size is a power of two
(compiled once per power, whatever the fleet's B), so a call where no robot needs it
compiles and runs none of the exact arithmetic.

On the vectorised loop (GPU) the slice kernel serves only a fleet whose robots are all
sliced: `make_plan` reads that from one small program first.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp

from jaxfilters.keepout import prologue
from jaxfilters.keepout.common import batched_inputs, usable_geometry


@dataclasses.dataclass(frozen=True)
class Plan:
  """An eager call's static choices (see the module docstring).

  Attributes:
    all_sliced: the vectorised loop's fleet reads its mask cells as slices, every
      robot (robots whose brackets are open are redone anyway), so the slice kernel
      serves it; False: the gather. The CPU's loop ("map") has one kernel for both.
  """
  all_sliced: bool = False


def is_concrete(*trees) -> bool:
  """No leaf of `trees` is a tracer (the call is eager, its values can be read on the host)."""
  return not any(isinstance(x, jax.core.Tracer) for x in jax.tree.leaves(trees))


@functools.partial(jax.jit, static_argnames=("aligned",))
def _all_sliced(costmap, mask, state, mask_index, enabled, window, *, aligned):
  idx, idx_ok, _, enabled, window, _ = batched_inputs(costmap, mask, jnp.zeros((costmap.num_robots, 3)), mask_index,
                                                      enabled, window, None, "keepout_filter", state)
  costmap, mask, idx_ok = usable_geometry(costmap, mask, idx, idx_ok)
  _, _, _, _, sliced, box_known, decided = prologue.same_frame_prologue(costmap, mask, idx, idx_ok, window,
                                                                          enabled, flags=True)
  return jnp.asarray(aligned) & jnp.all(sliced | ~box_known | ~decided)


def make_plan(costmap, mask, state, mask_index, enabled, window, transform, *, aligned: bool, loop: str) -> Plan:
  """The `Plan` of an eager call's checked inputs (`common.check_batched_inputs`): on the vectorised
  same-frame loop, one small program and one flag read on the host; nothing elsewhere."""
  if transform is not None or loop == "map":
    return Plan()
  return Plan(all_sliced=bool(_all_sliced(costmap, mask, state, mask_index, enabled, window, aligned=aligned)))
