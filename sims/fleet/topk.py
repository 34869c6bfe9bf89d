"""`top_k` for code that runs vmapped over a sharded batch (the planner's nearest robots, the RL env's spawn draw).

It lives here, below its users (sims.fleet.planner, sims.rl.env) and beside nothing they import
back, so the fleet, the RL env and sims.scale.sharding all take it from one place.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def top_k(x: jax.Array, k: int) -> tuple[jax.Array, jax.Array]:
  """`jax.lax.top_k(x, k)` as k rounds of argmax, for code that runs vmapped over a sharded batch.

  XLA's SPMD partitioner does not split the TopK op along batch axes: under a
  mesh it all-gathers the whole batch onto every device, runs TopK on all of it
  there and keeps the device's slice (one all-gather per call, and D times the
  work). A reduction (argmax) partitions along batch axes with no communication.

  Args:
    x: float [..., n], no NaN (-inf allowed).
    k: static, 1 <= k <= n.

  Returns:
    (values [..., k], int32 indices [..., k]), equal to `jax.lax.top_k`'s: largest
    first, ties (-inf included) to the lower index.
  """
  n = x.shape[-1]
  if not 1 <= k <= n:
    raise ValueError(f"top_k: k must be between 1 and the last axis ({n}); got {k}")
  taken = jnp.zeros(x.shape, bool)
  first = jax.lax.broadcasted_iota(jnp.int32, x.shape, x.ndim - 1)
  vals, idxs = [], []
  for _ in range(k):
    cand = jnp.where(taken, -jnp.inf, x)
    i = jnp.argmax(cand, axis=-1)
    # All that is left is -inf: argmax may land on a taken -inf; take the first untaken index.
    i_taken = jnp.take_along_axis(taken, i[..., None], axis=-1)[..., 0]
    i = jnp.where(i_taken, jnp.argmax(~taken, axis=-1), i).astype(jnp.int32)
    taken = taken | (first == i[..., None])
    vals.append(jnp.take_along_axis(x, i[..., None], axis=-1)[..., 0])
    idxs.append(i)
  return jnp.stack(vals, axis=-1), jnp.stack(idxs, axis=-1)
