"""Host-side validation of values where they enter the library, in the terms the device sees.

Every geometry value (resolution, origin, base, multiplier, speed caps) lives on
the device as float32. A float64 that is finite on the host can become inf,
0 or a subnormal in float32 (XLA flushes subnormals to zero), which would turn
"resolution 1e-50" into a division by zero and every pose into "inside the
mask". So values are checked *after* the float32 rounding, in the terms the
device sees: finite, not subnormal, and for resolutions > 0 and not rounded to 0.

Errors are `ValueError` with the owner, the name, what was expected and a
shortened repr of what was given (long values are cut, so a hostile input
cannot build a huge message).
"""

from __future__ import annotations

import reprlib

from typing import Any

import numpy as np

F32_TINY = float(np.finfo(np.float32).tiny)   # smallest normal float32, 1.18e-38
F32_MAX = float(np.finfo(np.float32).max)
_REPR_LIMIT = 80


def short_repr(value: Any, limit: int = _REPR_LIMIT) -> str:
  """repr(value) cut to `limit` characters (error messages stay short and cheap for any input).

  Containers are abbreviated while the text is built (`reprlib`: a few items per level, a few
  levels deep), so a huge or deeply nested value costs no more than a small one.
  """
  try:
    text = _REPR.repr(value)
  except Exception:  # noqa: BLE001 - a hostile __repr__ must not hide the real error
    text = f"<{type(value).__name__}>"
  return text if len(text) <= limit else text[:limit - 3] + "..."


def _bounded_repr() -> reprlib.Repr:
  r = reprlib.Repr()
  r.maxlevel, r.maxlist, r.maxtuple, r.maxdict, r.maxset, r.maxfrozenset = 4, 8, 8, 8, 8, 8
  r.maxstring, r.maxother, r.maxlong = _REPR_LIMIT, _REPR_LIMIT, _REPR_LIMIT
  return r


_REPR = _bounded_repr()


def _where(owner: str, name: str) -> str:
  return f"{owner}: {name}" if owner else name


def _as_float64(value: Any, owner: str, name: str) -> np.ndarray:
  try:
    arr = np.asarray(value)
  except Exception as e:  # noqa: BLE001
    raise ValueError(f"{_where(owner, name)} must be a number or an array of numbers; "
                     f"got {short_repr(value)} ({type(e).__name__})") from None
  if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
    raise ValueError(f"{_where(owner, name)} must be real numbers; got {short_repr(value)}")
  if np.issubdtype(arr.dtype, np.complexfloating):
    raise ValueError(f"{_where(owner, name)} must be real numbers; got complex {short_repr(value)}")
  with np.errstate(over="ignore", invalid="ignore"):
    return arr.astype(np.float64)


def float32_values(value: Any, name: str, *, owner: str = "", positive: bool = False,
                   nonnegative: bool = False) -> np.ndarray:
  """Rounds to float32 and checks each element is usable on the device.

  Args:
    value: a number or array (float64, int, or float32).
    name: what the value is ("resolution", "origin", ...), for the message.
    owner: who checks it ("FilterMask.create", the YAML file path, ...).
    positive: require > 0 (a resolution).
    nonnegative: require >= 0.

  Returns:
    The float32 array (same shape as the input).

  Raises:
    ValueError: an element that is NaN, becomes inf in float32 (|v| > 3.4e38),
      becomes a subnormal or 0 in float32 while non-zero in float64
      (0 < |v| < 1.18e-38), or breaks the sign requirement.
  """
  v64 = _as_float64(value, owner, name)
  where = _where(owner, name)
  if not np.all(np.isfinite(v64)):
    raise ValueError(f"{where} must be finite; got {short_repr(value)}")
  with np.errstate(over="ignore", under="ignore"):
    v32 = v64.astype(np.float32)
  if not np.all(np.isfinite(v32)):
    raise ValueError(f"{where} must fit float32 (|value| <= {F32_MAX:.4g}, the device's "
                     f"precision); got {short_repr(value)}, which becomes inf")
  tiny = (v64 != 0) & (np.abs(v64) < F32_TINY)
  if np.any(tiny):
    raise ValueError(f"{where} must be 0 or at least {F32_TINY:.4g} in magnitude in float32 "
                     f"(smaller values become 0 or subnormal on the device); got {short_repr(value)}")
  if positive and np.any(v32 <= 0):
    raise ValueError(f"{where} must be > 0; got {short_repr(value)}")
  if nonnegative and np.any(v32 < 0):
    raise ValueError(f"{where} must be >= 0; got {short_repr(value)}")
  return v32


def resolution_value(value: Any, *, owner: str = "", name: str = "resolution") -> np.ndarray:
  """A grid resolution (metres per cell): finite, > 0 and a normal float32."""
  return float32_values(value, name, owner=owner, positive=True)


def int_values(value: Any, name: str, *, lo: int, hi: int, owner: str = "") -> np.ndarray:
  """Integer array with every element in [lo, hi]; floats are refused, never truncated.

  Raises:
    ValueError: a non-integer dtype (floats such as 99.9 or NaN are not
      silently truncated) or an element outside [lo, hi].
  """
  arr = np.asarray(value)
  where = _where(owner, name)
  if arr.dtype == bool or not np.issubdtype(arr.dtype, np.integer):
    raise ValueError(f"{where} must be integers in [{lo}, {hi}]; got dtype {arr.dtype}")
  if arr.size and (arr.min() < lo or arr.max() > hi):
    raise ValueError(f"{where} must lie in [{lo}, {hi}]; got min {arr.min()} max {arr.max()}")
  return arr


def split_float64(x) -> "np.ndarray":
  """Host float64 -> float32 [..., 3] parts (hi, mid, lo) whose exact sum is x.

  Raises:
    ValueError: x not finite in float32 terms, or so small that a part would be
      subnormal on the device (the sum would no longer be x).
  """
  x = np.asarray(x, np.float64)
  with np.errstate(over="ignore", under="ignore"):
    hi = x.astype(np.float32)
    r1 = x - hi.astype(np.float64)
    mid = r1.astype(np.float32)
    lo = (r1 - mid.astype(np.float64)).astype(np.float32)
  tiny = np.finfo(np.float32).tiny
  parts = np.stack([hi, mid, lo], axis=-1)
  exact = (hi.astype(np.float64) + mid.astype(np.float64) + lo.astype(np.float64)) == x
  normal = np.all((parts == 0) | (np.abs(parts) >= tiny), axis=-1)
  if not (np.all(np.isfinite(hi)) and np.all(exact) and np.all(normal)):
    bad = x[~(exact & normal & np.isfinite(hi))] if x.ndim else x
    raise ValueError(f"value {np.ravel(bad)[:3].tolist()} cannot be carried exactly on the device as "
                     "three normal float32 parts (|x| must lie in [1e-31, 3.4e38] or be 0)")
  return parts
