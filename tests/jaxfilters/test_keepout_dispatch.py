"""An eager keepout call picks its path on the host; a jitted one decides in the program.

Eager (concrete inputs): the fast path runs with no exact redo in it and reports the
robots whose float32 brackets were left open; only those are redone in a sub-fleet whose size is
a power of two (plan.py): up to `process.EXACT_PATH_REDO_MAX` robots in integer arithmetic on the
host (keepout/host_exact.py, same frame; nothing to compile) or, where that declines (a frame
transform), by the exact per-cell path's program; more by the jitted program with its exact
reruns. The results are
the exact path's integers, also on fleets built to put cell centres exactly on
mask-cell edges. The CPU loop's programs hold no conditional: eager, nothing but the
robot loop (none at all for one robot); jitted, the exact redo as loops of
data-dependent trip count.
"""

from __future__ import annotations

import dataclasses
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfilters as jf
from jaxfilters.keepout import common, host_exact, process
from jaxfilters.keepout.plan import Plan
from tests.compile_count import count_compiles
from tests.keepout_fleets import B, W, WM, fleet

PLAIN = jf.KeepoutConfig()
ESCAPE = jf.KeepoutConfig(override_lethal_cost=True, lethal_override_cost=100)


def _edges():
  """Master centres exactly on mask-cell edges (brackets left open), windows partly off the masks."""
  rng = np.random.default_rng(7)
  k = rng.integers(-W - 3, WM + 3, (B, 2))
  return fleet(rng, 0.25, 0.25, (k + 0.5) * 0.25, [(0.0, 0.0), (0.1, 0.3)])


def _plain(seed=8):
  """Cell centres on the masks' cell centres: every bracket decided."""
  rng = np.random.default_rng(seed)
  k = rng.integers(-4, 8, (B, 2))
  return fleet(rng, 0.1, 0.1, 0.3 + k * 0.1, [(0.3, 0.3), (0.1, 0.2)])


def _exact(case, config, transform=None):
  cm, mask, state, window, mask_index, enabled = case
  idx, ok, _, en, win, tf = common.batched_inputs(cm, mask, jnp.zeros((cm.num_robots, 3)), mask_index, enabled,
                                                  window, transform, "test")
  return process.filter_batch(cm, mask, idx, ok, common.fill_error(state, cm.num_robots), win, en, tf,
                              config=config, exact=True)


def _eager(case, config, transform=None):
  cm, mask, state, window, mask_index, enabled = case
  return jf.keepout_filter(cm, mask, np.zeros((cm.num_robots, 3), np.float32), state, mask_index=mask_index, enabled=enabled,
                           window=window, transform=transform, config=config)


def _needs(case, config, transform=None):
  """The robots the eager fast path reports open (`filter_batch` with a plan)."""
  cm, mask, state, window, mask_index, enabled = case
  idx, ok, _, en, win, tf = common.batched_inputs(cm, mask, jnp.zeros((cm.num_robots, 3)), mask_index, enabled,
                                                  window, transform, "test")
  return np.asarray(process.filter_batch(cm, mask, idx, ok, common.fill_error(state, cm.num_robots), win, en, tf,
                                         config=config, plan=Plan())[2])


def _assert_equal(got, want):
  np.testing.assert_array_equal(np.asarray(got[0].cost), np.asarray(want[0].cost))
  for a, b in zip(jax.tree.leaves(got[1]), jax.tree.leaves(want[1])):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.parametrize("config", [PLAIN, ESCAPE], ids=["plain", "escape"])
def test_eager_call_redoes_the_open_robots_exactly(config):
  case = _edges()
  assert _needs(case, config).any()            # the fleet exercises the redo
  _assert_equal(_eager(case, config), _exact(case, config))


def _host_redo_programs(config, monkeypatch) -> list[bool]:
  """The edge fleet's eager call with its open robots redone on the host: asserts the exact path's
  integers and returns `exact` of each `process.exact_redo` call (True: the exact per-cell path)."""
  case = _edges()
  monkeypatch.setattr(process, "HOST_REDO_MAX_FRACTION", 1.0)
  ran = []
  real = process.exact_redo
  monkeypatch.setattr(process, "exact_redo", lambda *a, **k: ran.append(k["exact"]) or real(*a, **k))
  _assert_equal(_eager(case, config), _exact(case, config))
  return ran


@pytest.mark.parametrize("config", [PLAIN, ESCAPE], ids=["plain", "escape"])
def test_a_larger_host_redo_runs_the_fast_path_with_its_exact_reruns(config, monkeypatch):
  """Past EXACT_PATH_REDO_MAX open robots the host redo runs the jitted program (exact reruns in
  it), not the exact path; the integers are the exact path's either way."""
  if jax.default_backend() != "cpu":
    pytest.skip("off a CPU the open robots are redone on the device, never on the host")
  monkeypatch.setattr(process, "EXACT_PATH_REDO_MAX", 0)
  assert _host_redo_programs(config, monkeypatch) == [False]


@pytest.mark.parametrize("config", [PLAIN, ESCAPE], ids=["plain", "escape"])
def test_a_small_host_redo_runs_in_integers_on_the_host(config, monkeypatch):
  """Up to EXACT_PATH_REDO_MAX open robots of a same-frame call: host_exact, no device program (on
  every backend: off a CPU only their rows travel)."""
  assert _host_redo_programs(config, monkeypatch) == []


@pytest.mark.parametrize("config", [PLAIN, ESCAPE], ids=["plain", "escape"])
def test_a_small_host_redo_that_host_exact_declines_runs_the_exact_path(config, monkeypatch):
  if jax.default_backend() != "cpu":
    pytest.skip("off a CPU the open robots are redone on the device, never on the host")
  monkeypatch.setattr(host_exact, "redo", lambda *a, **k: None)
  assert _host_redo_programs(config, monkeypatch) == [True]


@pytest.mark.parametrize("config", [PLAIN, ESCAPE], ids=["plain", "escape"])
def test_an_eager_call_with_many_open_robots_runs_the_fleet_on_the_device(config, monkeypatch):
  """Past EXACT_PATH_REDO_MAX open robots and HOST_REDO_MAX_FRACTION (and always on a GPU, where the
  host copy of the fleet cost 100x the filter) the eager call runs the whole fleet once more with the
  exact reruns in the program."""
  from jaxfilters.keepout import process
  case = _edges()
  monkeypatch.setattr(process, "HOST_REDO_MAX_FRACTION", 0.0)
  monkeypatch.setattr(process, "EXACT_PATH_REDO_MAX", 0)
  ran = []
  monkeypatch.setattr(host_exact, "redo", lambda *a, **k: ran.append(1))
  _assert_equal(_eager(case, config), _exact(case, config))
  assert ran == []


def test_eager_other_frame_call_equals_the_exact_path():
  case = _plain(9)
  tf = jnp.asarray(np.float32(np.random.default_rng(9).uniform(-1, 1, (B, 3))))
  _assert_equal(_eager(case, PLAIN, tf), _exact(case, PLAIN, tf))


def test_eager_call_with_no_open_robot_equals_the_exact_path():
  case = _plain()
  assert not _needs(case, PLAIN).any()
  _assert_equal(_eager(case, PLAIN), _exact(case, PLAIN))


def test_the_exact_redo_compiles_once_per_power_of_two(monkeypatch):
  """A fleet of another B whose open robots fit the same sub-fleet compiles only its fast path."""
  from jaxfilters.keepout import process
  if jax.default_backend() != "cpu":
    pytest.skip("off a CPU the open robots are redone on the device, never on the host")
  monkeypatch.setattr(process, "HOST_REDO_MAX_FRACTION", 1.0)      # this fleet's open robots on the host
  case = _edges()
  _eager(case, PLAIN)
  smaller = _first(case, B - 1)
  assert _needs(smaller, PLAIN).any()
  with count_compiles() as compiles:
    got = _eager(smaller, PLAIN)
  assert compiles() == 1
  _assert_equal(got, _exact(smaller, PLAIN))


def test_a_second_eager_call_compiles_nothing():
  case = _plain()
  _eager(case, PLAIN)
  cm = case[0]
  other = (dataclasses.replace(cm, cost=jnp.asarray(255 - np.asarray(cm.cost))), *case[1:])
  with count_compiles() as compiles:
    got = _eager(other, PLAIN)
  assert compiles() == 0
  _assert_equal(got, _exact(other, PLAIN))


def _first(case, b):
  """The first b robots of a fleet (the masks kept)."""
  cm, mask, *rest = case
  cut = lambda t: jax.tree.map(lambda x: x[:b], t)
  return (cut(cm), mask, *cut(rest))


def _ops(hlo: str, op: str) -> int:
  return len(re.findall(rf"[\s)]{op}\(", hlo))


def _compiled(case, b, **kw):
  cm, mask, state, window, mask_index, enabled = _first(case, b)
  idx, ok, _, en, win, tf = common.batched_inputs(cm, mask, jnp.zeros((b, 3)), mask_index, enabled, window, None,
                                                  "test")
  return process.filter_batch.lower(cm, mask, idx, ok, common.fill_error(state, b), win, en, tf, config=PLAIN,
                                    loop="map", **kw).compile().as_text()


def test_cpu_loop_programs_hold_no_conditional():
  case = _plain()
  eager = _compiled(case, B, plan=Plan())
  assert _ops(eager, "conditional") == 0
  assert _ops(eager, "while") == 1                      # the robot loop, nothing else
  one = _compiled(case, 1, plan=Plan())
  assert _ops(one, "conditional") == 0 and _ops(one, "while") == 0
  traced = _compiled(case, B)
  assert _ops(traced, "conditional") == 0
