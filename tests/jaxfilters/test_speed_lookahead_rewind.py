"""SpeedFilter path lookahead with Nav2 PR #6522's fixes (docs/nav2_semantics.md §5.7).

The scenarios of Nav2 issue #6511, on a 0.5 m mask (limit = mask value, percent):
- forward-only index: the robot drives along its path, then backs up past a zone without a new
  path; Nav2 main's cached start index stays where the robot turned, so the zone now straight
  ahead is missed; `max_path_rewind` lets the index follow the robot back.
- stale path: after a reset the robot leaves the plan it held; Nav2 main keeps looking ahead
  along that plan, so the limit comes from a zone on a route the robot is not taking and the
  zone it enters is missed; `clear_path_on_reset` drops the plan until a new one arrives.
"""

import dataclasses

import jax
import numpy as np
import pytest

import jaxfilters as jf

RES = 0.5
ORIGIN = (-1.0, -6.0)           # the mask covers x in [-1, 11), y in [-6, 6)
ZONE_AHEAD = 40                 # x in [3, 4) on the path y = 0
ZONE_OFF_PLAN = 20              # x in [9, 10) on the path y = 0
ZONE_SIDE = 60                  # y in [-5, -4) at x in [5, 7.5): the route the robot takes after a reset
NAV2_MAIN = jf.LookaheadConfig(max_decel=-0.2)      # v = 1 m/s -> lookahead 2.5 m
# Both fixes on (one compiled program shared by the tests): the index may move back up to 5 m of
# path per cycle, and a reset drops the held path.
PR6522 = dataclasses.replace(NAV2_MAIN, max_path_rewind=5.0, clear_path_on_reset=True)
N = 24                          # path capacity (poses)


def _mask():
  data = np.zeros((24, 24), np.int8)

  def cols(x0, x1):
    return slice(int((x0 - ORIGIN[0]) / RES), int((x1 - ORIGIN[0]) / RES))

  def rows(y0, y1):
    return slice(int((y0 - ORIGIN[1]) / RES), int((y1 - ORIGIN[1]) / RES))

  data[rows(-2, 2), cols(3, 4)] = ZONE_AHEAD
  data[rows(-2, 2), cols(9, 10)] = ZONE_OFF_PLAN
  data[rows(-5, -4), cols(5, 7.5)] = ZONE_SIDE
  return jf.FilterMask.create(jf.OccupancyGrid.create(data, RES, ORIGIN), jf.FilterInfo.create(1, 0.0, 1.0))


MASK = _mask()
# The plan along y = 0: poses x = 0.25, 0.75, ..., 10.25 (21 poses, 0.5 m apart), padded to N.
PLAN_X = 0.25 + 0.5 * np.arange(21, dtype=np.float32)
PLAN = np.zeros((N, 2), np.float32)
PLAN[:21, 0] = PLAN_X


def _cycle(state, x, y, config, *, new_path=False, reset=False, path=PLAN, length=21):
  """One filter cycle for one robot at (x, y), moving at 1 m/s, holding `path`."""
  return jf.speed_filter_lookahead(MASK, np.float32([[x, y, 0.0]]), state, path[None], np.int32([length]),
                                   np.float32([1.0]), new_path=new_path, reset=np.bool_([reset]), config=config)


def _drive_and_back_up(config):
  """Forward from x = 0.25 to 6.4 (new path on the first cycle), then back up to x = 1.9.

  The robot stands inside segments (not on poses), so each closest segment is unique.
  """
  state = jf.SpeedState.create(1)
  xs = [0.25, 1.4, 2.4, 3.4, 4.4, 5.4, 6.4] + [5.4, 4.4, 3.4, 2.4, 1.9]
  limits = []
  for k, x in enumerate(xs):
    state, out = _cycle(state, x, 0.0, config, new_path=k == 0)
    limits.append(float(out.speed_limit[0]))
  return state, limits


def test_backing_up_nav2_main_misses_the_zone_ahead_and_rewind_sees_it():
  state, limits = _drive_and_back_up(NAV2_MAIN)
  # At x = 1.9 the zone [3, 4) is 1.1 m ahead, inside the 2.5 m lookahead; Nav2 main still looks
  # ahead from the segment where the robot turned ([6.25, 6.75]), sees x in [6.25, 8.75]: no limit.
  assert limits[-1] == 0.0
  assert int(state.path_start[0]) == 12                 # segment [6.25, 6.75]: never moved back
  state, limits = _drive_and_back_up(PR6522)
  assert limits[-1] == ZONE_AHEAD
  assert int(state.path_start[0]) == 3                  # segment [1.75, 2.25]: the robot's


def test_rewind_is_bounded_per_cycle():
  # One jump back of 4.5 m (a localisation correction): a 2 m bound moves the index only to
  # the segment from x = 4.25, whose window [4.25, 6.75] misses the zone; a 5 m bound reaches the robot.
  for config, expected_start, expected_limit in ((dataclasses.replace(NAV2_MAIN, max_path_rewind=2.0), 8, 0.0),
                                                 (PR6522, 3, ZONE_AHEAD)):
    state = jf.SpeedState.create(1)
    state, _ = _cycle(state, 6.4, 0.0, config, new_path=True)
    state, out = _cycle(state, 1.9, 0.0, config)
    assert int(state.path_start[0]) == expected_start and float(out.speed_limit[0]) == expected_limit


def test_rewind_changes_nothing_while_the_robot_moves_forward():
  xs = [0.25, 0.9, 1.6, 2.2, 2.9, 3.4, 4.1, 5.3, 6.0, 7.7, 8.4, 9.9, 10.25]
  runs = {}
  for name, config in (("main", NAV2_MAIN), ("rewind", PR6522)):
    state, rows = jf.SpeedState.create(1), []
    for k, x in enumerate(xs):
      state, out = _cycle(state, x, 0.05, config, new_path=k == 0)
      rows.append((int(state.path_start[0]), float(state.held_lookahead[0]), float(out.speed_limit[0]),
                   bool(out.changed[0])))
    runs[name] = rows
  assert runs["main"] == runs["rewind"]
  assert {r[2] for r in runs["main"]} >= {ZONE_AHEAD, ZONE_OFF_PLAN}     # both zones were seen ahead


def _leave_the_plan_after_reset(config):
  """Along the plan to x = 6.25, reset, then down the side route x = 7.25 into ZONE_SIDE."""
  state = jf.SpeedState.create(1)
  for k, x in enumerate([0.25, 2.25, 4.25, 6.25]):
    state, _ = _cycle(state, x, 0.0, config, new_path=k == 0)
  seen = []
  for k, y in enumerate([-1.25, -2.75, -4.25]):          # the last pose is inside ZONE_SIDE
    state, out = _cycle(state, 7.25, y, config, reset=k == 0)
    seen.append(float(out.speed_limit[0]))
  return state, seen


def test_stale_plan_nav2_main_applies_the_old_plans_zone_and_clear_path_applies_the_robots():
  state, seen = _leave_the_plan_after_reset(NAV2_MAIN)
  # The held plan still passes ZONE_OFF_PLAN (x in [9, 10)) within 2.5 m of its closest segment:
  # its 20 % is applied while the robot drives away from it, and ZONE_SIDE's 60 % is never published.
  assert seen == [ZONE_OFF_PLAN] * 3
  assert not bool(state.path_dropped[0])
  state, seen = _leave_the_plan_after_reset(PR6522)
  # The plan was dropped at the reset: the plain rule at the robot pose, no limit until the
  # robot is in ZONE_SIDE, whose 60 % is then published.
  assert seen == [0.0, 0.0, ZONE_SIDE] and bool(state.path_dropped[0])
  # A new plan (down the side route, y from -1 to -5.5) is held and looked ahead along again.
  side = np.zeros((N, 2), np.float32)
  side[:10, 0], side[:10, 1] = 7.25, -1.0 - 0.5 * np.arange(10)
  state, out = _cycle(state, 7.25, -2.75, PR6522, new_path=True, path=side, length=10)
  assert not bool(state.path_dropped[0]) and float(out.speed_limit[0]) == ZONE_SIDE   # seen at y = -4.5


def test_reset_in_nav2_main_mode_returns_index_and_held_distance_to_zero():
  state, _ = _drive_and_back_up(NAV2_MAIN)
  assert float(state.held_lookahead[0]) > 0.0 or int(state.path_start[0]) > 0
  # initializeFilter puts the index at 0, so the search starts from the path's start again and
  # finds the robot; the path is kept (not dropped) in this mode.
  state, out = _cycle(state, 1.9, 0.0, NAV2_MAIN, reset=True)
  assert int(state.path_start[0]) == 3 and float(out.speed_limit[0]) == ZONE_AHEAD
  assert not bool(state.path_dropped[0])


def _fleet_inputs():
  """Three robots, each with its own path and state: the back-up scenario, a plan along y, no path."""
  rng = np.random.default_rng(7)
  paths = np.zeros((3, N, 2), np.float32)
  paths[0] = PLAN
  paths[1, :12, 0], paths[1, :12, 1] = 7.0, -5.75 + 0.75 * np.arange(12)
  paths[2] = rng.uniform(-1, 10, (N, 2)).astype(np.float32)
  lengths = np.int32([21, 12, 0])
  state = jf.SpeedState(np.float32([40.0, 0.0, 60.0]), np.int32([12, 2, 5]), np.float32([2.5, 0.0, 0.3]),
                        np.bool_([False, False, True]))
  poses = np.float32([[1.9, 0.0, 3.1], [7.1, -3.0, 1.5], [5.0, -4.5, 0.0]])
  vel = np.float32([1.0, 0.6, 0.2])
  return poses, state, paths, lengths, vel


@pytest.mark.parametrize("config", [NAV2_MAIN, PR6522],
                         ids=["nav2_main", "pr6522"])
def test_fleet_matches_robot_by_robot_and_jit_matches_eager(config):
  poses, state, paths, lengths, vel = _fleet_inputs()
  reset = np.bool_([False, True, False])
  new_path = np.bool_([False, False, True])
  new, out = jf.speed_filter_lookahead(MASK, poses, state, paths, lengths, vel, new_path=new_path, reset=reset,
                                       config=config)
  jitted = jax.jit(lambda p, s, pa, n, v, npth, rs: jf.speed_filter_lookahead(
      MASK, p, s, pa, n, v, new_path=npth, reset=rs, config=config))(poses, state, paths, lengths, vel,
                                                                        new_path, reset)
  for a, b in zip(jax.tree.leaves((new, out)), jax.tree.leaves(jitted)):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
  for i in range(3):
    one = jax.tree.map(lambda a, i=i: a[i:i + 1], state)
    new_i, out_i = jf.speed_filter_lookahead(MASK, poses[i:i + 1], one, paths[i:i + 1], lengths[i:i + 1],
                                             vel[i:i + 1], new_path=new_path[i:i + 1], reset=reset[i:i + 1],
                                             config=config)
    for a, b in zip(jax.tree.leaves((new, out)), jax.tree.leaves((new_i, out_i))):
      np.testing.assert_array_equal(np.asarray(a)[i:i + 1], np.asarray(b))
  if config.max_path_rewind > 0:
    assert int(new.path_start[0]) == 3 and float(out.speed_limit[0]) == ZONE_AHEAD
  else:
    assert int(new.path_start[0]) == 12 and float(out.speed_limit[0]) == 0.0
  # Robot 1 was reset: with clear_path_on_reset its plan is dropped (plain rule at its pose).
  assert bool(new.path_dropped[1]) == config.clear_path_on_reset
  assert not bool(new.path_dropped[2])          # a new path clears a drop


@pytest.mark.parametrize("bad, err", [
    ({"max_path_rewind": -0.5}, "max_path_rewind must be 0"),
    ({"max_path_rewind": float("inf")}, "max_path_rewind must be finite"),
    ({"max_path_rewind": 1e-45}, "normal float32"),
    ({"max_path_rewind": 1e39}, "normal float32"),
    ({"clear_path_on_reset": 1}, "clear_path_on_reset must be a bool"),
])
def test_bad_lookahead_config_raises(bad, err):
  with pytest.raises((ValueError, TypeError), match=err):
    jf.LookaheadConfig(**bad)


def test_bad_reset_flag_raises():
  with pytest.raises(ValueError, match="reset must be a bool"):
    _cycle(jf.SpeedState.create(1), 1.0, 0.0, NAV2_MAIN, reset=np.int32([1]))
