"""Same frame, mask cells that are not one slice (another mask resolution): a gather.

Each robot reads its mask cells through its two exact index vectors
(`prologue.index_vectors`): the mask column of each costmap column and the mask row of
each costmap row. On the CPU backend one byte is gathered per cell
(`gather_write_one`, robot by robot); vectorised over a fleet, four cells are packed
per uint32 word when W % 4 == 0 (four byte gathers from the (cost + 1) table, the write
rule in word arithmetic, whole-word loads and stores of the costs).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxfilters.keepout.common import m1_table, write_u8
from jaxfilters.keepout.config import KeepoutConfig
from jaxfilters.keepout.packed import pack, unpack, word, write_rule


def gather_write_one(cost, flat, i, mshape, mx, vx, my, vy, col_ok, row_ok, state, *, config: KeepoutConfig):
  """The write rule on mask cells gathered through the two index vectors: new cost uint8 [H, W].

  Args:
    cost: uint8 [H, W]. flat: int8 [M * Hm * Wm] the mask stack, flat; i: int32 [] the
      mask; mshape: (Hm, Wm). mx, vx: int32 / bool [W] each column's mask column and
      whether it lies on the mask; my, vy: [H] the same for rows. col_ok [W], row_ok [H]:
      the update window as flags. state, config: as `reference.keepout_one`.
  """
  hm, wm = mshape
  d = flat[i * (hm * wm) + my[:, None] * wm + mx[None, :]]
  return write_u8(cost, d, (col_ok & vx)[None, :] & (row_ok & vy)[:, None], state, config)


def _gather_packed_one(cost, m1flat, i, mshape, mx, colv, my, rowv, state, *, config: KeepoutConfig):
  """The gather on four cells per uint32 word (W % 4 == 0): new cost uint8 [H, W].

  m1flat: the masks' (cost + 1) bytes, flat (`common.m1_table`). colv [W] / rowv [H]:
  the column / row is in the window and its mask cell on the mask.
  """
  h, w = cost.shape
  hm, wm = mshape
  base = i * (hm * wm) + my * wm
  mx4, cv4 = mx.reshape(w // 4, 4), colv.reshape(w // 4, 4)
  planes = [jnp.where(cv4[None, :, s] & rowv[:, None], m1flat[base[:, None] + mx4[None, :, s]], jnp.uint8(0))
            for s in range(4)]
  return unpack(write_rule(pack(cost), word(planes), state, config))


def other_resolution_batch(cells, mask, *, config: KeepoutConfig):
  """The same-frame cells of a fleet through the exact index vectors, vectorised over robots.

  Args:
    cells: (cost uint8 [B, H, W], mask index int32 [B], mx int32 [B, W], vx bool [B, W],
      my int32 [B, H], vy bool [B, H], col_ok bool [B, W], row_ok bool [B, H], state).
    mask: the FilterMask stack. config: static KeepoutConfig.

  Returns:
    new cost uint8 [B, H, W].
  """
  cost, idx, mx, vx, my, vy, col_ok, row_ok, state = cells
  w = cost.shape[2]
  _, hm, wm = mask.data.shape
  if w % 4:
    flat = mask.data.reshape(-1)
    one = lambda c, i, mx, vx, my, vy, co, ro, st: gather_write_one(c, flat, i, (hm, wm), mx, vx, my, vy, co, ro,
                                                                    st, config=config)
    return jax.vmap(one)(*cells)
  m1flat = m1_table(mask.data).reshape(-1)
  one = lambda c, i, mx, cv, my, rv, st: _gather_packed_one(c, m1flat, i, (hm, wm), mx, cv, my, rv, st,
                                                            config=config)
  return jax.vmap(one)(cost, idx, mx, col_ok & vx, my, row_ok & vy, state)
