"""sims/record/render.py: zones land at their world place, labels name every zone, files stay small.

Pixel checks render the figure to an array (Agg canvas) and read the colour at
the map axes' data -> pixel transform of a world point, against the colour
worked out by hand (the zone colour alpha-blended over the white free cell).
"""

import dataclasses

import numpy as np
import pytest
from matplotlib import colormaps
from matplotlib.colors import to_rgb
from PIL import Image

from jaxfilters.grid import OccupancyGrid
from sims.record import render
from sims.fleet.config import FleetConfig
from sims.fleet.scenario import Scenario
from sims.fleet.world import build_world


@pytest.fixture(scope="module")
def world():
  w = build_world(Scenario.default(), FleetConfig(robots_per_world=2))
  # One station far from every probe point, so nothing but the zones is drawn there.
  return dataclasses.replace(w, stations=np.array([[-14.0, 8.5]], np.float32))


def _rollout(t=2):
  pose = np.zeros((t, 1, 3))
  pose[:, 0, 0] = np.linspace(-13.0, -11.0, t)
  pose[:, 0, 1] = 8.0
  return pose, np.full((t, 1), 0.25)


def _with_masks(world, **masks):
  return dataclasses.replace(world, scenario=dataclasses.replace(world.scenario, **masks))


def _draw(world, pose=None, speed=None, **kw):
  if pose is None:
    pose, speed = _rollout()
  fig = render.fleet_figure(world, pose, speed, **kw)
  fig.canvas.draw()
  return fig, np.asarray(fig.canvas.buffer_rgba())[..., :3].astype(float)


def _pixel(fig, rgb, x, y):
  u, v = fig.axes[0].transData.transform((x, y))
  return rgb[int(round(rgb.shape[0] - v)), int(round(u))]


def _blend(colour, alpha):
  return 255 * (alpha * np.asarray(to_rgb(colour)) + (1 - alpha))


def _assert_map_free(world, points):
  grid = world.scenario.map
  for x, y in points:
    col = int((x - grid.origin[0]) // grid.resolution)
    row = int((y - grid.origin[1]) // grid.resolution)
    assert grid.data[row, col] == 0, f"probe ({x}, {y}) is not on a free map cell"


def test_shifted_masks_are_drawn_at_their_own_origin_and_resolution(world):
  # Speed mask: 0.1 m cells (the map has 0.05), origin (4.5, -4.5), 30 x 25 cells; one 50 % block
  # at rows 5..14, cols 8..21 -> x 5.3..6.7, y -4.0..-3.0.
  speed = np.zeros((25, 30), np.int8)
  speed[5:15, 8:22] = 50
  # Keepout mask: 0.1 m cells, origin (-8.5, -2.0), 50 x 40 cells; lethal block x -7.5..-5.5, y -1..1.
  keep = np.zeros((40, 50), np.int8)
  keep[10:30, 10:30] = 100
  w = _with_masks(world, speed=OccupancyGrid.create(speed, 0.1, (4.5, -4.5)),
                  keepout=OccupancyGrid.create(keep, 0.1, (-8.5, -2.0)))
  inside_speed, inside_keep = [(6.0, -3.5), (5.5, -3.2), (6.5, -3.8)], [(-6.5, 0.0), (-7.3, 0.8)]
  outside = [(5.1, -3.5), (6.9, -3.5), (6.0, -2.8), (6.0, -4.2), (-7.7, 0.0), (-5.3, 0.0), (-6.5, 1.2),
             (-6.5, -1.2)]
  _assert_map_free(w, inside_speed + inside_keep + outside)
  fig, rgb = _draw(w)
  zone = _blend(render.zone_colour(0), render.ZONE_ALPHA)
  red = _blend(render.KEEPOUT_COLOUR, render.KEEPOUT_ALPHA)
  for p in inside_speed:
    np.testing.assert_allclose(_pixel(fig, rgb, *p), zone, atol=4, err_msg=str(p))
  for p in inside_keep:
    np.testing.assert_allclose(_pixel(fig, rgb, *p), red, atol=4, err_msg=str(p))
  for p in outside:
    np.testing.assert_allclose(_pixel(fig, rgb, *p), [255, 255, 255], atol=1, err_msg=str(p))
  # Drawn by array index on the map's grid, the speed block would sit at x -14.6..-13.9, y -9.75..-9.25.
  assert np.abs(_pixel(fig, rgb, -14.25, -9.5) - zone).max() > 20


def test_masks_of_another_size_are_drawn(world):
  # 80 x 60 cells at the map's resolution and origin (the map is 600 x 400): two zones.
  speed = np.zeros((60, 80), np.int8)
  speed[20:40, 30:60] = 70                 # 30 %: x -13.5..-12.0, y -9.0..-8.0
  speed[20:40, 62:78] = 50                 # 50 %: x -11.9..-11.1
  keep = np.zeros((30, 40), np.int8)
  keep[5:25, 5:35] = 100                   # x -14.75..-13.25, y -9.75..-8.75 (overlaps the 30 % zone)
  w = _with_masks(world, speed=OccupancyGrid.create(speed, 0.05, (-15.0, -10.0)),
                  keepout=OccupancyGrid.create(keep, 0.05, (-15.0, -10.0)))
  z30, z50, off = (-12.75, -8.3), (-11.5, -8.5), (-10.5, -8.5)
  _assert_map_free(w, [z30, z50, off])
  fig, rgb = _draw(w)
  zones = render.speed_zones(w.scenario, w.config.robot.max_speed)
  assert [z["label"] for z in zones] == ["50 %", "30 %"]
  c50, c30 = _pixel(fig, rgb, *z50), _pixel(fig, rgb, *z30)
  np.testing.assert_allclose(c50, _blend(render.zone_colour(0), render.ZONE_ALPHA), atol=4)
  np.testing.assert_allclose(c30, _blend(render.zone_colour(1), render.ZONE_ALPHA), atol=4)
  np.testing.assert_allclose(_pixel(fig, rgb, *off), [255, 255, 255], atol=1)
  # Keepout drawn over the zone it overlaps: red alpha over the 30 % blend.
  want = 255 * render.KEEPOUT_ALPHA * np.asarray(to_rgb(render.KEEPOUT_COLOUR)) + (1 - render.KEEPOUT_ALPHA) * c30
  np.testing.assert_allclose(_pixel(fig, rgb, -13.4, -8.9), want, atol=4)
  assert np.linalg.norm(c50 - c30) > 60                         # the two zones are told apart


def test_legend_names_every_zone_with_its_limit_and_every_marker(world):
  fig, _ = _draw(world, summary={"fleet": {"robots": 1, "speed_compliant": True, "keepout_entries": 0,
                                           "keepout_steps": 0, "goals_reached": 3}})
  labels = [t.get_text() for t in fig.legends[0].get_texts()]
  for want in ("keepout zone (no entry)", "speed zone 50 % (0.25 m/s)", "speed zone 30 % (0.15 m/s)",
               "goal station (1)", "robot start", "robot end (points along heading)", "obstacle (map)",
               "unknown (map)"):
    assert want in labels, (want, labels)
  title = fig._suptitle.get_text()
  assert "default_warehouse" in title and "speed compliance PASS" in title
  assert "keepout entries 0 (PASS)" in title and "goals reached 3" in title


def test_absolute_speed_mask_labels_in_metres_per_second(world):
  speed = np.zeros((20, 20), np.int8)
  speed[5:10, 5:10] = 30                   # type 2, base 0, multiplier 0.01: 0.3 m/s
  sc = dataclasses.replace(world.scenario, speed=OccupancyGrid.create(speed, 0.05, (0.0, 0.0)),
                           speed_type=2, speed_base=0.0, speed_multiplier=0.01)
  fig, _ = _draw(dataclasses.replace(world, scenario=sc))
  labels = [t.get_text() for t in fig.legends[0].get_texts()]
  assert "speed zone 0.3 m/s" in labels, labels


def test_failing_result_in_title(world):
  fig, _ = _draw(world, summary={"robots": 4, "speed_compliant": False, "keepout_entries": 2,
                                 "keepout_steps": 5, "goals_reached": 0})
  title = fig._suptitle.get_text()
  assert "4 robots (1 drawn)" in title and "speed compliance FAIL" in title and "keepout entries 2 (FAIL)" in title


def test_colour_bar_and_legend_sit_outside_the_map(world):
  fig, _ = _draw(world)
  r = fig.canvas.get_renderer()
  m = fig.axes[0].get_window_extent(r)
  cbar = fig.axes[1].get_window_extent(r)
  legend = fig.legends[0].get_window_extent(r)
  assert cbar.x0 >= m.x1 and legend.y1 <= m.y0
  assert fig.axes[1].get_ylabel() == "robot speed (m/s)"
  assert fig.axes[0].get_xlabel() == "x (m)" and fig.axes[0].get_ylabel() == "y (m)"


def test_keepout_red_is_not_a_trajectory_colour():
  speeds = colormaps[render.SPEED_CMAP](np.linspace(0, 1, 256))[:, :3]
  red = np.asarray(to_rgb(render.KEEPOUT_COLOUR))
  assert np.linalg.norm(speeds - red, axis=1).min() > 0.35
  zone_rgb = [np.asarray(to_rgb(render.zone_colour(i))) for i in range(12)]
  for i, a in enumerate(zone_rgb):
    assert np.linalg.norm(a - red) > 0.3
    for b in zone_rgb[:i]:
      assert np.linalg.norm(a - b) > 0.05


def test_trajectory_is_coloured_by_speed(world):
  t = 40
  pose = np.zeros((t, 2, 3))
  pose[:, :, 0] = np.linspace(-7.0, -4.0, t)[:, None]
  pose[:, 0, 1], pose[:, 1, 1] = 0.0, 1.0
  speed = np.stack([np.full(t, 0.5), np.full(t, 0.1)], axis=1)
  _assert_map_free(world, [(-5.5, 0.0), (-5.5, 1.0)])
  fig, rgb = _draw(world, pose, speed)
  cmap = colormaps[render.SPEED_CMAP]
  np.testing.assert_allclose(_pixel(fig, rgb, -5.5, 0.0), 255 * np.asarray(cmap(1.0)[:3]), atol=30)
  np.testing.assert_allclose(_pixel(fig, rgb, -5.5, 1.0), 255 * np.asarray(cmap(0.2)[:3]), atol=30)


def test_png_and_gif_files(world, tmp_path):
  pose, speed = _rollout(t=23)
  png = render.render_png(world, pose, speed, tmp_path / "t.png")
  assert png.stat().st_size < 200_000
  with Image.open(png) as im:
    assert im.format == "PNG" and im.size[0] >= 900
  gif = render.render_gif(world, pose, speed, tmp_path / "f.gif", max_frames=10, seconds_per_frame=0.2)
  with Image.open(gif) as im:
    assert im.n_frames == 8                            # ceil(23 / 3): every 3rd recorded step
    assert im.info["duration"] == 300                  # 3 steps x 0.2 s at 2x speed


def test_gif_frames_use_the_same_scene(world, tmp_path):
  keep = np.zeros((40, 50), np.int8)
  keep[10:30, 10:30] = 100
  w = _with_masks(world, keepout=OccupancyGrid.create(keep, 0.1, (-8.5, -2.0)))
  pose, speed = _rollout(t=4)
  fig, frames, stride = render.animation_frames(w, pose, speed, max_frames=2)
  assert stride == 2 and len(frames) == 2
  red = _blend(render.KEEPOUT_COLOUR, render.KEEPOUT_ALPHA)
  for p in [(-6.5, 0.0), (-7.3, 0.8)]:
    np.testing.assert_allclose(_pixel(fig, frames[-1].astype(float), *p), red, atol=4)
  # The robot disc (true radius, filled with its speed colour) sits at its last kept pose.
  cmap = colormaps[render.SPEED_CMAP]
  np.testing.assert_allclose(_pixel(fig, frames[-1].astype(float), *pose[2, 0, :2] + [0, -0.12]),
                             255 * np.asarray(cmap(0.5)[:3]), atol=30)
  gif = render.render_gif(w, pose, speed, tmp_path / "f.gif", max_frames=2)
  with Image.open(gif) as im:
    im.seek(1)
    written = np.asarray(im.convert("RGB"), float)
  assert written.shape == frames[1].shape
  assert np.abs(written - frames[1]).mean() < 3          # the shared 256-colour palette loses little


@pytest.mark.parametrize("pose,speed,match", [
    (np.zeros((5, 2)), np.zeros((5, 2)), "pose must be"),
    (np.zeros((5, 2, 3)), np.zeros((5, 3)), "speed must be"),
    (np.full((5, 2, 3), np.nan), np.zeros((5, 2)), "non-finite"),
])
def test_bad_rollouts_raise(world, pose, speed, match, tmp_path):
  with pytest.raises(ValueError, match=match):
    render.render_png(world, pose, speed, tmp_path / "x.png")
  with pytest.raises(ValueError, match=match):
    render.render_gif(world, pose, speed, tmp_path / "x.gif")
