"""Counting XLA compilations in tests, through JAX's public monitoring events.

A test that a second call with new values of the same shapes compiles nothing:

    with count_compiles() as compiles:
      f(x1)
      f(x2)
    assert compiles() == 1

Every backend compilation in the process is counted while the block runs, so the
block should contain only the calls under test (warm other code up first).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator

import jax

BACKEND_COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"
_count = [0]


def _listener(event: str, duration_secs: float, **kwargs) -> None:
  del duration_secs, kwargs
  if event == BACKEND_COMPILE_EVENT:
    _count[0] += 1


jax.monitoring.register_event_duration_secs_listener(_listener)


@contextlib.contextmanager
def count_compiles() -> Iterator[Callable[[], int]]:
  """Yields a function that returns the compilations since the block started."""
  start = _count[0]
  yield lambda: _count[0] - start


CACHE_MISS_EVENT = "/jax/compilation_cache/cache_misses"
_misses = [0]


def _event_listener(event: str, **kwargs) -> None:
  del kwargs
  if event == CACHE_MISS_EVENT:
    _misses[0] += 1


jax.monitoring.register_event_listener(_event_listener)


@contextlib.contextmanager
def count_cache_misses() -> Iterator[Callable[[], int]]:
  """Yields a function that returns the persistent compilation cache's misses since the block started
  (a program looked up in the cache folder and not found there; programs JAX finds in its in-memory
  caches are not looked up at all)."""
  start = _misses[0]
  yield lambda: _misses[0] - start
