"""Device meshes for the fleet: the world axis sharded over devices, maps and params replicated.

Worlds are independent, so a rollout over W worlds splits into equal blocks of
W / D worlds on D devices with no communication: a 1-D `jax.sharding.Mesh`
with axis "worlds", every per-world array (states, keys, actions, frames)
sharded along its world axis with `NamedSharding(mesh, P("worlds"))`, and the
shared `WorldParams` replicated (`P()`).

    mesh = make_mesh(4)                       # or "all", None (all), or a list of devices
    env = FleetEnv.create(config=FleetConfig(robots_per_world=8))
    keys = put_global(env.world_keys(key, 64), worlds_sharding(mesh))
    params = put_global(env.params, replicated(mesh))
    states = env.reset_fn(mesh=mesh)(params, keys)           # WorldState [64], 16 worlds per device
    states, frames = env.rollout_fn(50, mesh=mesh)(params, states)

Every sharded result equals the unsharded one (the same program per world;
tests/scale/test_sharding.py checks integer outputs exactly with 8 forced CPU
devices). On the command line: `jaxfilters fleet --devices N|all`.

Multi-host (`jax.distributed`): run the same program in every process; each
process sees its local devices and the mesh spans all of them
(`jax.devices()` is global after `initialize`). Inputs are built with
`put_global` (`jax.make_array_from_callback`: each process fills only its own
shards), and each process reads back only its addressable shards (or gathers
with `jax.experimental.multihost_utils.process_allgather`). A worked example on
one machine with two processes of two CPU devices each:

    # process i of 2 (i = 0, 1), e.g. two shells:
    XLA_FLAGS=--xla_force_host_platform_device_count=2 JAX_PLATFORMS=cpu \\
      python -m sims.commands.sharding --coordinator 127.0.0.1:12355 --num-processes 2 \\
        --process-id i --worlds 8 --steps 5 --out out/dist_i.npz

`distributed_rollout` (what that runs) calls `jax.distributed.initialize(
coordinator_address, num_processes=2, process_id=i)`, builds a 4-device mesh,
runs a sharded reset and rollout, and saves this process's shards of the
integer outputs with their world indices; tests/scale/test_sharding.py compares the
union of both files with a single-process run. On a GPU cluster the same code
runs with one process per host (coordinator = host 0's address).
"""

from __future__ import annotations

from collections.abc import Sequence

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P

from sims.fleet.topk import top_k  # noqa: F401  (sharded code's top_k; re-exported)

AXIS = "worlds"


def make_mesh(devices: int | str | Sequence[jax.Device] | None = None) -> Mesh:
  """A 1-D mesh with axis "worlds".

  Args:
    devices: None or "all" (every device, `jax.devices()`: global in a
      multi-process run), an int N (the first N devices), or a sequence of
      jax.Device.

  Returns:
    Mesh of D devices.

  Raises:
    ValueError: N < 1, N more than the devices there are, an unknown string,
      or an empty or repeated device list.
  """
  avail = jax.devices()
  if devices is None or (isinstance(devices, str) and devices == "all"):
    chosen = list(avail)
  elif isinstance(devices, str):
    raise ValueError(f"devices must be 'all', an int or a list of devices; got {devices!r}")
  elif isinstance(devices, (int, np.integer)) and not isinstance(devices, bool):
    n = int(devices)
    if n < 1 or n > len(avail):
      raise ValueError(f"devices must be between 1 and the {len(avail)} available "
                       f"({avail[0].platform}); got {n}")
    chosen = list(avail[:n])
  else:
    chosen = list(devices)
    if not chosen or not all(isinstance(d, jax.Device) for d in chosen):
      raise ValueError(f"devices must be a non-empty sequence of jax.Device; got {devices!r}")
    if len({d.id for d in chosen}) != len(chosen):
      raise ValueError("devices must not repeat a device")
  return Mesh(np.asarray(chosen), (AXIS,))


def worlds_sharding(mesh: Mesh, *, leading: int = 0) -> NamedSharding:
  """Shards the world axis (after `leading` unsharded axes, e.g. 1 for time-major frames)."""
  return NamedSharding(mesh, P(*([None] * leading), mesh.axis_names[0]))


def replicated(mesh: Mesh) -> NamedSharding:
  """Every device holds the whole array (maps, WorldParams)."""
  return NamedSharding(mesh, P())


def check_divisible(num_worlds: int, mesh: Mesh) -> None:
  """ValueError unless the world count splits evenly over the mesh."""
  d = mesh.devices.size
  if num_worlds % d:
    raise ValueError(f"the number of worlds ({num_worlds}) must be a multiple of the number of devices "
                     f"({d}) to shard the world axis evenly")


def put_global(tree, sharding: NamedSharding):
  """Host values -> global jax.Arrays with `sharding` (works across processes).

  Each process passes the same full host values; only the shards it can
  address are copied to its devices (`jax.make_array_from_callback`).

  Raises:
    ValueError: a leaf whose sharded axis does not split evenly.
  """
  mesh = sharding.mesh
  spec = sharding.spec

  def put(x):
    host = np.asarray(x)
    for axis, name in enumerate(spec):
      if name is not None and host.shape[axis] % mesh.shape[name]:
        raise ValueError(f"axis {axis} of a {host.shape} array must be a multiple of the {mesh.shape[name]} "
                         f"devices on mesh axis {name!r}")
    return jax.make_array_from_callback(host.shape, sharding, lambda idx: host[idx])

  return jax.tree.map(put, tree)


def local_shards(tree) -> list:
  """[(index tuple, host numpy array)] of this process's addressable shards, for each leaf."""
  return [[(s.index, np.asarray(s.data)) for s in leaf.addressable_shards] for leaf in jax.tree.leaves(tree)]


def rl_batch_fns(env, mesh: Mesh | None = None, *, devices=None):
  """jit(vmap(reset)) and jit(vmap(step)) of a Playground-contract env, the env axis sharded.

  Args:
    env: `sims.rl.env.NavEnv` (or any env with reset(rng) / step(state, action)).
    mesh: None (default device placement) or a mesh from `make_mesh`; then
      keys [N, 2], states and actions are sharded along N over the devices.
    devices: instead of mesh, what `make_mesh` takes (an int, "all" or devices).

  Returns:
    (reset(keys [N, 2]) -> State [N], step(State [N], actions [N, A]) -> State [N]).
  """
  if devices is not None:
    if mesh is not None:
      raise ValueError("give mesh or devices, not both")
    mesh = make_mesh(devices)
  reset, step = jax.vmap(env.reset), jax.vmap(env.step)
  if mesh is None:
    return jax.jit(reset), jax.jit(step)
  w = worlds_sharding(mesh)
  return (jax.jit(reset, in_shardings=w, out_shardings=w),
          jax.jit(step, in_shardings=(w, w), out_shardings=w))


INT_OUTPUTS = ("goal", "goals_reached", "keepout_entries", "stuck_events")


def integer_outputs(states, frames) -> dict:
  """The integer outputs compared between sharded and unsharded runs (each [..., W, K])."""
  return {"goal": states.goal, "goals_reached": states.metrics.goals_reached,
          "keepout_entries": states.metrics.keepout_entries, "stuck_events": states.metrics.stuck_events,
          "frame_goal": frames.goal}


def distributed_rollout(coordinator: str, num_processes: int, process_id: int, *, num_worlds: int,
                        num_steps: int, robots_per_world: int = 2, seed: int = 0) -> dict:
  """Multi-process sharded fleet rollout (see the module docstring).

  Returns:
    {name: (world indices int [n], this process's values [..., n, K])} for the
    `integer_outputs`, gathered from its addressable shards.
  """
  jax.distributed.initialize(coordinator, num_processes=num_processes, process_id=process_id)
  from sims.fleet.config import FleetConfig
  from sims.fleet.env import FleetEnv
  env = FleetEnv.create(config=FleetConfig(robots_per_world=robots_per_world))
  mesh = make_mesh("all")
  check_divisible(num_worlds, mesh)
  keys = put_global(env.world_keys(jax.random.PRNGKey(seed), num_worlds), worlds_sharding(mesh))
  params = put_global(env.params, replicated(mesh))
  states = env.reset_fn(mesh=mesh)(params, keys)
  # Every input global: a process-local array (e.g. the default idle actions) would make JAX
  # check or broadcast it across processes.
  idle = put_global(np.full((num_steps, num_worlds, robots_per_world), -1, np.int32),
                    worlds_sharding(mesh, leading=1))
  states, frames = env.rollout_fn(num_steps, mesh=mesh)(params, states, idle)
  out = {}
  for name, arr in integer_outputs(states, frames).items():
    world_axis = arr.ndim - 2
    idx, vals = [], []
    for s in arr.addressable_shards:
      sl = s.index[world_axis]
      idx.append(np.arange(num_worlds)[sl])
      vals.append(np.asarray(s.data))
    order = np.argsort(np.concatenate(idx), kind="stable")
    allidx = np.concatenate(idx)[order]
    allvals = np.concatenate(vals, axis=world_axis).take(order, axis=world_axis)
    uniq, first = np.unique(allidx, return_index=True)     # replicated shards repeat worlds
    out[name] = (uniq, allvals.take(first, axis=world_axis))
  jax.distributed.shutdown()
  return out
