"""`NavTask`: the task data every RL env step reads (map, inflated static layer, goal weights, zone layouts).

Its own room so that the env (sims.rl.env) and its per-step kernels (sims.rl.kernels) both import it
without importing each other.

No `from __future__ import annotations` here: `NavModel` (an `mjx.Model`) makes its `task` field
a pytree node only if NavTask's field annotations are real types (mjx reads `field.type` to find
arrays); as strings they would turn the task into static metadata, and per-env randomisation of
goals and zones would silently do nothing.
"""

import dataclasses

import jax

from sims.fleet.layouts import LayoutBank
from sims.fleet.world import WorldParams


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class NavTask:
  """The task data every step reads (all traced leaves; randomisable per env).

  Attributes:
    world: WorldParams of the scenario (navigation mode drives the fleet on it).
    static_inflated: uint8 [H, W], the static layer inflated (no keepout), on the map grid.
    goal_logits: float32 [L * S], log-weights of drawing each station of the bank as a goal
      (-inf never); an env draws among its own layout's stations only.
    bank: LayoutBank of L zone layouts (L = 1: the scenario's own zones); velocity mode reads
      its masks, navigation fields, stations and spawns.
    layout: int32 [], the bank layout this env drives in (randomised per env).
    navigation_mode: static; True when the env runs in navigation mode (it reads `world`'s
      zones, velocity mode reads `bank`'s).
  """
  world: WorldParams
  static_inflated: jax.Array
  goal_logits: jax.Array
  bank: LayoutBank
  layout: jax.Array
  navigation_mode: bool = dataclasses.field(default=False, metadata={"static": True})

  def replace(self, **changes) -> "NavTask":
    """dataclasses.replace (what `mjx.Model.tree_replace` calls on nested fields)."""
    return dataclasses.replace(self, **changes)
