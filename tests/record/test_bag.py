"""A fleet run as a rosbag2 (MCAP) folder, read back with the `mcap` readers (not this project's code)."""

from __future__ import annotations

import json
from pathlib import Path

import jax
import numpy as np
import pytest

pytest.importorskip("rosbags")
mcap_reader = pytest.importorskip("mcap.reader")
mcap_ros2 = pytest.importorskip("mcap_ros2.decoder")

from jaxfilters.map_io import load_map  # noqa: E402
from sims.record import bag as bag_lib  # noqa: E402
from sims.fleet.config import FleetConfig  # noqa: E402
from sims.fleet.env import FleetEnv  # noqa: E402
from sims.fleet.scenario import ASSETS, Scenario  # noqa: E402

ROBOTS_PER_WORLD = 3
WORLDS = 2
STEPS = 15          # 3 s at 5 Hz, 60 controller ticks
CHUNKS = 2
COSTMAP_ROBOTS = 2


@pytest.fixture(scope="module")
def run(tmp_path_factory):
  scenario = Scenario.default()
  config = FleetConfig(robots_per_world=ROBOTS_PER_WORLD)
  env = FleetEnv.create(scenario, config, seed=3)
  states = env.reset_fn()(env.params, env.world_keys(jax.random.PRNGKey(3), WORLDS))
  rollout = env.rollout_fn(STEPS, record_ticks=True, record_costmaps=COSTMAP_ROBOTS)
  chunks = []
  for _ in range(CHUNKS):
    states, rec = rollout(env.params, states)
    chunks.append(rec)
  robots = ROBOTS_PER_WORLD * WORLDS
  rec = bag_lib.host_recording(chunks, robots=robots, step_seconds=config.step_seconds)
  path = tmp_path_factory.mktemp("bag") / "run"
  bag_lib.write_fleet_bag(path, scenario, rec, max_speed=config.robot.max_speed,
                          summary={"robots": robots}, overwrite=False)
  return scenario, config, chunks, rec, path


def _messages(path):
  files = sorted(path.glob("*.mcap"))
  assert len(files) == 1, files
  out = {}
  with open(files[0], "rb") as f:
    reader = mcap_reader.make_reader(f, decoder_factories=[mcap_ros2.DecoderFactory()])
    for schema, channel, message, ros_msg in reader.iter_decoded_messages():
      out.setdefault(channel.topic, []).append((schema.name, message.log_time, ros_msg))
  return out


def _grid(msg):
  info = msg.info
  return np.asarray(msg.data, np.int8).reshape(info.height, info.width), info


def test_every_topic_is_present_with_its_type(run):
  *_, path = run
  msgs = _messages(path)
  want = {"/map": "nav_msgs/msg/OccupancyGrid", "/keepout_filter_mask": "nav_msgs/msg/OccupancyGrid",
          "/speed_filter_mask": "nav_msgs/msg/OccupancyGrid",
          "/keepout_costmap_filter_info": "nav2_msgs/msg/CostmapFilterInfo",
          "/speed_costmap_filter_info": "nav2_msgs/msg/CostmapFilterInfo",
          "/tf": "tf2_msgs/msg/TFMessage", "/fleet/summary": "std_msgs/msg/String"}
  for i in range(ROBOTS_PER_WORLD * WORLDS):
    want[f"/robot_{i}/cmd_vel"] = "geometry_msgs/msg/Twist"
    want[f"/robot_{i}/speed_limit"] = "nav2_msgs/msg/SpeedLimit"
    want[f"/robot_{i}/speed_cap"] = "std_msgs/msg/Float64"
  for i in range(COSTMAP_ROBOTS):
    want[f"/robot_{i}/local_costmap/costmap"] = "nav_msgs/msg/OccupancyGrid"
  assert set(msgs) == set(want)
  for topic, typ in want.items():
    assert {name for name, _, _ in msgs[topic]} == {typ}, topic
  assert json.loads(msgs["/fleet/summary"][0][2].data) == {"robots": ROBOTS_PER_WORLD * WORLDS}


def test_map_and_masks_decode_to_the_grids_load_map_gives(run):
  *_, path = run
  msgs = _messages(path)
  for topic, name in (("/map", "default_map"), ("/keepout_filter_mask", "default_keepout"),
                      ("/speed_filter_mask", "default_speed")):
    (_, stamp, msg), = msgs[topic]
    data, info = _grid(msg)
    want = load_map(ASSETS / f"{name}.yaml")
    np.testing.assert_array_equal(data, np.asarray(want.data))
    assert info.resolution == pytest.approx(float(np.float32(want.resolution)))
    assert (info.origin.position.x, info.origin.position.y) == pytest.approx(tuple(want.origin[:2]))
    assert stamp == 0
  info = msgs["/speed_costmap_filter_info"][0][2]
  assert (info.type, info.filter_mask_topic) == (1, "/speed_filter_mask")
  assert (info.base, info.multiplier) == (100.0, -1.0)


def test_tf_poses_equal_the_recorded_frames(run):
  _, config, chunks, rec, path = run
  tf = _messages(path)["/tf"]
  ticks = config.ticks_per_step
  assert len(tf) == len(rec.time) + 1                  # one per tick and the end pose
  frames = np.concatenate([np.asarray(c.frame.pose).reshape(STEPS, -1, 3) for c in chunks])
  for j, (_, stamp, msg) in enumerate(tf):
    assert [t.child_frame_id for t in msg.transforms] == [f"robot_{i}/base_link" for i in range(6)]
    assert {t.header.frame_id for t in msg.transforms} == {"map"}
    got = np.array([[t.transform.translation.x, t.transform.translation.y,
                     2 * np.arctan2(t.transform.rotation.z, t.transform.rotation.w)] for t in msg.transforms])
    assert stamp == round(j * config.control_dt * 1e9)
    if j % ticks == 0 and j > 0:     # the start of env step k is the end of step k-1: Frame k-1
      np.testing.assert_allclose(got[:, :2], frames[j // ticks - 1, :, :2], rtol=0, atol=1e-6)
      dyaw = (got[:, 2] - frames[j // ticks - 1, :, 2] + np.pi) % (2 * np.pi) - np.pi
      np.testing.assert_allclose(dyaw, 0, atol=1e-5)
  assert len(tf) // ticks >= 10 * 0 and 1 / config.control_dt >= 10          # 10 Hz or more


def test_cmd_vel_stays_within_the_speed_limit_in_force(run):
  scenario, config, _, rec, path = run
  msgs = _messages(path)
  percent = scenario.speed_type == 1
  moved = 0
  for i in range(ROBOTS_PER_WORLD * WORLDS):
    limits = [(stamp, m.speed_limit, m.percentage) for _, stamp, m in msgs[f"/robot_{i}/speed_limit"]]
    assert limits[0][0] == 0 and all(p == percent for *_, p in limits)
    cmds = msgs[f"/robot_{i}/cmd_vel"]
    assert len(cmds) == len(rec.time)
    k = 0
    for _, stamp, m in cmds:
      while k + 1 < len(limits) and limits[k + 1][0] <= stamp:
        k += 1
      limit = limits[k][1]
      cap = config.robot.max_speed * limit / 100 if percent else limit
      v = abs(m.linear.x)
      moved += v > 0
      if limit > 0:
        assert v <= cap * (1 + 1e-6), (i, stamp, v, cap)
      assert v <= config.robot.max_speed * (1 + 1e-6)
  assert moved > 0


def test_speed_limit_is_published_when_it_changes(run):
  _, _, _, rec, path = run
  msgs = _messages(path)
  for i in range(ROBOTS_PER_WORLD * WORLDS):
    series = rec.speed_limit[:, i]
    changes = 1 + int(np.count_nonzero(series[1:] != series[:-1]))
    assert len(msgs[f"/robot_{i}/speed_limit"]) == changes


def test_local_costmaps_follow_nav2s_publisher_values(run):
  _, config, chunks, rec, path = run
  msgs = _messages(path)
  for i in range(COSTMAP_ROBOTS):
    grids = msgs[f"/robot_{i}/local_costmap/costmap"]
    assert len(grids) == STEPS * CHUNKS
    _, stamp, msg = grids[-1]
    data, info = _grid(msg)
    cost = np.asarray(chunks[-1].costmaps.cost)[-1, i]
    table = {0: 0, 253: 99, 254: 100, 255: -1}
    want = np.array([table.get(int(c), 1 + (97 * (int(c) - 1)) // 251) for c in cost.ravel()]).reshape(cost.shape)
    np.testing.assert_array_equal(data, want)
    assert stamp == round((STEPS * CHUNKS - 1) * config.step_seconds * 1e9)


def test_bag_folder_checks(tmp_path):
  (tmp_path / "file").write_text("x")
  with pytest.raises(bag_lib.BagError, match="not a folder"):
    bag_lib.check_bag_dir(tmp_path / "file")
  (tmp_path / "full").mkdir()
  (tmp_path / "full" / "x").write_text("x")
  with pytest.raises(bag_lib.BagError, match="not empty"):
    bag_lib.check_bag_dir(tmp_path / "full")
  with pytest.raises(bag_lib.BagError, match="other than a bag this tool wrote"):
    bag_lib.check_bag_dir(tmp_path / "full", overwrite=True)       # never deletes a folder that is not a bag
  (tmp_path / "full" / "x").unlink()
  (tmp_path / "full" / "metadata.yaml").write_text("rosbag2_bagfile_information: {}")
  (tmp_path / "full" / "run_0.mcap").write_bytes(b"")
  with pytest.raises(bag_lib.BagError, match="no .jaxfilters_fleet_bag file"):    # a bag's names, not ours
    bag_lib.check_bag_dir(tmp_path / "full", overwrite=True)
  (tmp_path / "full" / bag_lib.MARKER_NAME).write_text(f"{bag_lib.MARKER_HEADER}\nmetadata.yaml\nrun_0.mcap\n")
  assert bag_lib.check_bag_dir(tmp_path / "full", overwrite=True) == tmp_path / "full"
  assert bag_lib.check_bag_dir(tmp_path / "missing" / "bag") == tmp_path / "missing" / "bag"
  with pytest.raises(bag_lib.BagError, match="is not a folder"):
    bag_lib.check_bag_dir(tmp_path / "file" / "bag")
  (tmp_path / "empty").mkdir()
  assert bag_lib.check_bag_dir(tmp_path / "empty") == tmp_path / "empty"


def test_foxglove_layout_names_only_topics_the_bag_has(run):
  *_, path = run
  topics = set(_messages(path))
  layout = json.loads((Path(__file__).resolve().parents[2] / "examples" / "foxglove" / "fleet_layout.json").read_text())
  named = set(layout["configById"]["3D!fleet"]["topics"])
  for panel in layout["configById"].values():
    for p in panel.get("paths", []):
      named.add(p["value"].split(".")[0])
    if "topicPath" in panel:
      named.add(panel["topicPath"].split(".")[0])
  assert named and named <= topics, named - topics


def test_bag_picture_reads_the_bag(run, tmp_path):
  from sims.record import bag_view
  *_, path = run
  out = bag_view.render_bag_png(path, tmp_path / "bag.png")
  assert out.stat().st_size > 10_000
  with pytest.raises(ValueError, match="robot 99 is not in the bag"):
    bag_view.bag_figure(path, robot=99)


@pytest.mark.parametrize("extra, message", [
    (["--bag-robots", "2"], "--bag-robots needs --bag"),
    (["--bag-costmaps", "1"], "--bag-costmaps needs --bag"),
    (["--overwrite"], "--overwrite needs --bag"),
    (["--bag", "{tmp}/b", "--bag-robots", "0"], "argument --bag-robots: must lie in [1, 1,048,576]; got 0"),
    (["--bag", "{tmp}/b", "--bag-robots", "5"], "--bag-robots must lie in [1, --robots = 4]"),
    (["--bag", "{tmp}/b", "--bag-robots", "2", "--bag-costmaps", "3"], "--bag-costmaps must lie in [0, bag robots = 2]"),
    (["--bag", "{tmp}/full"], "folder is not empty"),
    (["--bag", "{tmp}/full", "--overwrite"], "other than a bag this tool wrote"),
    (["--bag", "{tmp}/file"], "not a folder"),
    (["--bag", "{tmp}/file/b"], "is not a folder"),
    (["--bag", "{tmp}/b", "--devices", "1"], "--bag records on one device"),
])
def test_fleet_bag_arguments_are_checked_before_simulating(tmp_path, capsys, extra, message):
  from jaxfilters import cli
  (tmp_path / "full").mkdir()
  (tmp_path / "full" / "notes.txt").write_text("keep me")
  (tmp_path / "file").write_text("x")
  args = ["fleet", "--robots", "4", "--steps", "1", "--out", str(tmp_path / "out")]
  rc = cli.main(args + [a.replace("{tmp}", str(tmp_path)) for a in extra])
  err = capsys.readouterr().err
  assert rc == 2 and message in err and len(err.strip().splitlines()) == 1, err
  assert (tmp_path / "full" / "notes.txt").read_text() == "keep me"
  assert not (tmp_path / "out" / "summary.json").exists()
