"""Per-env randomisation of the RL env (`sims.rl.env.NavEnv`) and the env the `jaxfilters rl` commands use.

`randomize_zones_and_goals` is a Playground/Brax `randomization_fn`: each env
draws a zone layout from the env's bank (`NavEnv.create(layouts=L)`, see
`sims.fleet.layouts`), a scale of every speed limit, a shift of the speed zones and
its goal stations. `training_env` builds the env and picks that function for
the command line's `--randomize`.
"""

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from sims.fleet.config import FleetConfig
from sims.fleet.layouts import LayoutConfig
from sims.rl.env import NavEnv, NavEnvConfig, NavModel
from sims.fleet.scenario import Scenario

_F32 = jnp.float32


def randomize_zones_and_goals(model: NavModel, rng: jax.Array, *, limit_scale: tuple[float, float] = (0.75, 1.0),
                              zone_shift: float = 0.5, goal_keep: float = 0.5) -> tuple[NavModel, Any]:
  """Playground/Brax `randomization_fn`: per-env zone layout, zone limits, zone positions and goals.

  For env i (velocity mode): a layout l_i ~ U{0..L-1} of the env's bank (`NavEnv.create(layouts=L)`:
  keepout and speed zones at random places and sizes, the speed zones with random limits); every
  speed mask's base and multiplier scaled by u_i ~ U(limit_scale) (each zone's limit scales by u_i;
  Nav2 keeps a mask value of 0 as "no limit"); the speed masks' origins moved by
  U(-zone_shift, zone_shift) m in x and y (the speed zones move; keepout zones stay where the
  layout's navigation field expects them); and each goal station of layout l_i stays in the goal
  distribution with probability goal_keep (at least two always do; other layouts' stations never
  are goals). In navigation mode (one layout, the fleet's planner) the scale and shift apply to
  the world's speed mask and the planner's per-cell caps instead.

  Args:
    model: the env's NavModel (`env.mjx_model`).
    rng: uint32 [N, 2], one key per env (Brax's PPO passes `rng=`).
    limit_scale: (low, high) with 0 < low <= high <= 1 (a scale above 1 could
      lift a percent limit over 100, which Nav2 turns into "no limit").
    zone_shift: m, >= 0.
    goal_keep: probability in (0, 1].

  Returns:
    (NavModel with leading axis N on the randomised leaves, in_axes pytree).

  Raises:
    ValueError: bad ranges or rng shape.
  """
  lo, hi = (float(v) for v in limit_scale)
  if not 0 < lo <= hi <= 1:
    raise ValueError(f"limit_scale must satisfy 0 < low <= high <= 1; got {limit_scale!r}")
  if not np.isfinite(zone_shift) or zone_shift < 0:
    raise ValueError(f"zone_shift must be a finite number >= 0 (m); got {zone_shift!r}")
  if not 0 < goal_keep <= 1:
    raise ValueError(f"goal_keep must lie in (0, 1]; got {goal_keep!r}")
  rng = jnp.asarray(rng)
  if rng.ndim != 2 or rng.shape[1] != 2:
    raise ValueError(f"rng must be uint32 [N, 2], one key per env; got shape {tuple(rng.shape)}")
  task = model.task
  bank = task.bank
  nav_mode = task.navigation_mode
  speed = task.world.speed if nav_mode else bank.speed
  num_layouts, per = bank.num_layouts, bank.stations_per_layout

  def one(key):
    k_layout, k_scale, k_shift, k_keep, k_perm = jax.random.split(key, 5)
    layout = jax.random.randint(k_layout, (), 0, num_layouts, jnp.int32)
    u = jax.random.uniform(k_scale, (), _F32, lo, hi)
    shift = jax.random.uniform(k_shift, (2,), _F32, -zone_shift, zone_shift)
    keep = jax.random.bernoulli(k_keep, goal_keep, (per,))
    first_two = jnp.zeros((per,), bool).at[jax.random.permutation(k_perm, per)[:2]].set(True)
    own = jnp.where(keep | first_two, 0.0, -jnp.inf).astype(_F32)
    logits = jnp.full((num_layouts, per), -jnp.inf, _F32).at[layout].set(own).reshape(-1)
    info = dataclasses.replace(speed.info, base=speed.info.base * u, multiplier=speed.info.multiplier * u)
    out = {"layout": layout, "info": info, "origin": speed.origin + shift[None, :], "logits": logits}
    if nav_mode:
      out.update(cap=task.world.speed_cap * u, zone_speed=task.world.zone_speed * u)
    return out

  v = jax.vmap(one)(rng)
  new_speed = dataclasses.replace(speed, info=v["info"], origin=v["origin"])
  speed_axes = dataclasses.replace(jax.tree.map(lambda _: None, speed), info=jax.tree.map(lambda _: 0, speed.info),
                                   origin=0)
  changes = {"task.goal_logits": v["logits"], "task.layout": v["layout"]}
  axes = {"task.goal_logits": 0, "task.layout": 0}
  if nav_mode:
    changes["task.world"] = dataclasses.replace(task.world, speed=new_speed, speed_cap=v["cap"],
                                                zone_speed=v["zone_speed"])
    axes["task.world"] = dataclasses.replace(jax.tree.map(lambda _: None, task.world), speed=speed_axes,
                                             speed_cap=0, zone_speed=0)
  else:
    changes["task.bank"] = dataclasses.replace(bank, speed=new_speed)
    axes["task.bank"] = dataclasses.replace(jax.tree.map(lambda _: None, bank), speed=speed_axes)
  v_model = model.tree_replace(changes)
  in_axes = jax.tree.map(lambda _: None, model).tree_replace(axes)
  return v_model, in_axes


def training_env(scenario: Scenario | None = None, *, randomize: bool, seed: int,
                 config: NavEnvConfig = NavEnvConfig(), layouts: int = 16,
                 layout_config: LayoutConfig = LayoutConfig(), evaluation: bool = False,
                 robots_per_world: int = 1):
  """The env and randomization_fn the `jaxfilters rl` commands train and evaluate on.

  Args:
    scenario: maps (default: the built-in warehouse).
    randomize: draw zone layouts, limits and goals per episode (`randomize_zones_and_goals`) from
      a bank of `layouts` layouts (the scenario's own first); False: the scenario's zones only.
    seed: seed of the random layouts. Training uses layout seed 2 * seed and evaluation
      2 * seed + 1, so an evaluation never draws the random layouts a training run drew.
    config: NavEnvConfig (velocity mode).
    layouts: L >= 1, bank size when randomize.
    layout_config: how random layouts are drawn.
    evaluation: the env is for evaluation (see seed).
    robots_per_world: K robots per world (`FleetConfig.robots_per_world`; more than one is
      what `NavEnvConfig(agents="per_robot")` is for).

  Returns:
    (NavEnv, randomization_fn or None).

  Raises:
    ValueError: layouts < 1, a negative seed, a bad robots_per_world, or a scenario the env cannot
      be built on.
  """
  if isinstance(seed, bool) or int(seed) != seed or seed < 0:
    raise ValueError(f"seed must be an integer >= 0; got {seed!r}")
  fleet_config = FleetConfig(robots_per_world=robots_per_world)
  if not randomize:
    return NavEnv.create(scenario, fleet_config, config=config), None
  env = NavEnv.create(scenario, fleet_config, config=config, layouts=layouts, layout_seed=2 * int(seed) + int(bool(evaluation)),
                      layout_config=layout_config)
  return env, randomize_zones_and_goals


__all__ = ["randomize_zones_and_goals", "training_env"]
