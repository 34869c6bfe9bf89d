"""Internal: four uint8 cells per uint32 word, per-byte arithmetic without carries between bytes.

The SWAR forms follow Hacker's Delight 2-18. XLA:GPU moves uint8 elementwise data one
byte at a time, well below the memory rate it reaches with 4-byte words, so the
accelerator kernels pack the costmap and the mask bytes into words and apply the write
rule there (`write_rule`, the word form of `common.m1_rule_u8`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxfilters import constants
from jaxfilters.keepout.config import KeepoutConfig

_HI = 0x80808080
_LO = 0x7F7F7F7F
_ONES = 0x01010101


def _u32(v):
  return jnp.uint32(v)


def bytes_plus_one(x):
  """Each byte of uint32 words plus one, wrapping 255 to 0."""
  return ((x & _u32(_LO)) + _u32(_ONES)) ^ (x & _u32(_HI))


def bytes_minus_one(x):
  """Each byte of uint32 words minus one, wrapping 0 to 255."""
  return ((x | _u32(_HI)) - _u32(_ONES)) ^ (~x & _u32(_HI))


def zero_bytes(x):
  """0x80 in each byte of uint32 words that is zero, else 0x00 (Hacker's Delight 6-2, exact)."""
  y = (x & _u32(_LO)) + _u32(_LO)
  return ~(y | x | _u32(_LO))


def bytes_less_than(a, b):
  """0xFF in each byte where a < b (unsigned), else 0x00."""
  d = ((a | _u32(_HI)) - (b & _u32(_LO))) ^ ((a ^ ~b) & _u32(_HI))
  borrow = ((~a & b) | (~(a ^ b) & d)) & _u32(_HI)
  return (borrow >> _u32(7)) * _u32(0xFF)


def pack(x):
  """uint8 [..., 4n] -> uint32 [..., n] (little-endian bytes)."""
  return jax.lax.bitcast_convert_type(x.reshape(*x.shape[:-1], x.shape[-1] // 4, 4), jnp.uint32)


def unpack(x):
  """uint32 [..., n] -> uint8 [..., 4n]."""
  y = jax.lax.bitcast_convert_type(x, jnp.uint8)
  return y.reshape(*x.shape[:-1], x.shape[-1] * 4)


def shifted_words(table):
  """uint8 [M, R, C] -> uint32 [4, M, R, Q]: entry [s, m, r, q] packs bytes 4q+s .. 4q+s+3.

  Any 4-aligned run of words starts a window at byte offset 4q + s.
  """
  m, r, c = table.shape
  q = -(-c // 4)
  table = jnp.pad(table, ((0, 0), (0, 0), (0, 4 * q + 4 - c)))
  return jnp.stack([pack(table[:, :, s:s + 4 * q]) for s in range(4)])


def word(byte_planes):
  """uint32 word from four uint8 arrays (byte s of the word from plane s), by shifts."""
  out = byte_planes[0].astype(jnp.uint32)
  for s in range(1, 4):
    out = out | (byte_planes[s].astype(jnp.uint32) << _u32(8 * s))
  return out


def write_rule(c, m1, state, config: KeepoutConfig):
  """`common.m1_rule_u8` on uint32 words of four cells: new words of c.

  c: uint32 costs; m1: uint32 (mask cost + 1) bytes, 0 where unknown or not visited.
  """
  c1 = bytes_plus_one(c)
  if config.unknown_overwrite == "inscribed":   # common.old_plus_one_u8: unknown (c1 = 0) compares as 253 (as old 252)
    c1 = c1 | ((zero_bytes(c1) >> _u32(7)) * _u32(constants.INSCRIBED_INFLATED_OBSTACLE))
  write = bytes_less_than(c1, m1)
  if config.override_lethal_cost:
    value = jnp.where(state.is_pose_lethal, _u32(config.lethal_override_cost * _ONES), bytes_minus_one(m1))
  else:
    value = bytes_minus_one(m1)
  return (c & ~write) | (value & write)
