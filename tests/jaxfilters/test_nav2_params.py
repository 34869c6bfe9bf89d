"""jaxfilters.nav2.load_params: real Nav2 bringup params, and params files written here.

Expected values come from docs/nav2_semantics.md and hand-written tables; the speed, binary
and zone results are checked against reference/nav2.py (float64 loops) and,
for the warehouse masks, against the raw PGM pixels.
"""

import math
import warnings

import jax
import numpy as np
import pytest
import yaml
from PIL import Image

from tests.compile_count import count_compiles
import jaxfilters as jf
from jaxfilters import nav2
from reference import nav2 as reference

_ENABLE = {"KEEPOUT_ZONE_ENABLED": "True", "SPEED_ZONE_ENABLED": "True"}


def _warehouse_masks(maps):
  return {"keepout_filter_mask_server": maps / "warehouse_keepout.yaml",
          "speed_filter_mask_server": maps / "warehouse_speed.yaml"}


@pytest.fixture(scope="module")
def bringup(nav2_maps):
  with warnings.catch_warnings():
    warnings.simplefilter("error")  # the bringup file loads without a single warning
    return nav2.load_params(nav2_maps / "nav2_params.yaml", masks=_warehouse_masks(nav2_maps),
                            substitutions=_ENABLE)


def test_bringup_file_wiring(bringup, nav2_maps):
  g, loc = bringup.global_costmap, bringup.local_costmap
  assert (g.node, g.global_frame, g.resolution) == ("/global_costmap/global_costmap", "map", 0.05)
  assert (loc.node, loc.global_frame) == ("/local_costmap/local_costmap", "odom")
  assert [f.name for f in g.filters] == ["keepout_filter", "speed_filter"]
  assert [f.name for f in loc.filters] == ["keepout_filter"] and loc.speed is None
  k, s = g.keepout, g.speed
  assert (k.plugin, k.enabled, k.as_layer) == ("nav2_costmap_2d::KeepoutFilter", True, False)
  assert (k.filter_info_topic, k.info_server) == ("/keepout_costmap_filter_info",
                                                  "/keepout_costmap_filter_info_server")
  assert (k.mask_topic, k.mask_server, k.mask_frame) == ("/keepout_filter_mask", "/keepout_filter_mask_server",
                                                         "map")
  assert k.config == jf.KeepoutConfig(override_lethal_cost=True, lethal_override_cost=200)
  assert (s.filter_info_topic, s.mask_topic, s.speed_limit_topic) == (
      "/speed_costmap_filter_info", "/speed_filter_mask", "/speed_limit")
  assert s.percentage is True and s.lookahead is None
  assert s.mask_yaml == str(nav2_maps / "warehouse_speed.yaml")
  info = s.mask.info
  assert (int(info.type[0]), float(info.base[0]), float(info.multiplier[0])) == (1, 100.0, -1.0)
  assert int(k.mask.info.type[0]) == 0
  assert s.mask.shape == (1674, 1006) and float(s.mask.resolution[0]) == np.float32(0.03)
  np.testing.assert_array_equal(np.asarray(s.mask.origin[0]), np.float32([-15.1, -25.0]))
  assert loc.foreign_frames() == ("map",)


def _pgm_occupancy(path, mx, my):
  """Scale-mode 1.0/0.0 occupancy of grid cell (mx, my), read from the raw PGM (docs/nav2_semantics.md §10.2)."""
  img = np.asarray(Image.open(path).convert("L"))
  g = img[img.shape[0] - 1 - my, mx]
  occ = 1.0 - np.float32(g) / np.float32(255.0)
  return int(math.floor(float(occ) * 100.0 + 0.5))  # (occ - 0) / (1 - 0) * 100, round half away


def test_warehouse_speed_limit_is_100_minus_value(bringup, nav2_maps):
  s = bringup.global_costmap.speed
  data = np.asarray(s.mask.data[0])
  rng = np.random.default_rng(0)
  ox, oy, res = -15.1, -25.0, 0.03
  cells = []
  for value in (0, 20, 100):
    ys, xs = np.nonzero(data == value)
    pick = rng.choice(len(xs), 6, replace=False)
    cells += [(int(xs[i]), int(ys[i])) for i in pick]
  # Cell centres (all three speed classes) plus random points, some off the mask.
  xy = [(ox + (mx + 0.5) * res, oy + (my + 0.5) * res) for mx, my in cells]
  xy += list(zip(rng.uniform(-17, 17, 12), rng.uniform(-27, 27, 12)))
  poses = np.float32([[x, y, 0.0] for x, y in xy])
  out = bringup.global_costmap.readout(poses)
  o32, r32 = np.float32([ox, oy]), np.float32(res)
  seen = set()
  for b, (x, y, _) in enumerate(poses):
    cell = reference.world_to_map(x, y, o32[0], o32[1], r32, 1006, 1674)
    got = float(out.speed.speed_limit[b]) if bool(out.speed.valid[b]) else None
    if cell is None:
      assert got is None
      continue
    d = int(data[cell[1], cell[0]])
    if b < len(cells):
      assert cell == cells[b]
      assert d == _pgm_occupancy(nav2_maps / "warehouse_speed.pgm", *cell)
    seen.add(d)
    want = None if d in (0, 100) else 100.0 - d          # 0 and 100 % both mean "no limit"
    assert (got or None) == want, (x, y, d)
    lim, valid = reference.speed_limit_at(data, o32, r32, 1, np.float32(100), np.float32(-1), x, y)
    assert valid and lim == (want or 0.0)
  assert seen >= {0, 20, 100}
  assert bool(np.all(np.asarray(out.speed.percentage)))


def test_warehouse_keepout_cost_and_local_costmap_transform(bringup):
  k = bringup.global_costmap.keepout
  data = np.asarray(k.mask.data[0])
  rng = np.random.default_rng(1)
  poses = np.float32(np.stack([rng.uniform(-16, 16, 24), rng.uniform(-26, 26, 24), np.zeros(24)], 1))
  o, r = np.asarray(k.mask.origin[0]), np.asarray(k.mask.resolution[0])

  def want(x, y):
    cell = reference.world_to_map(x, y, o[0], o[1], r, data.shape[1], data.shape[0])
    return 255 if cell is None else reference.mask_cost(data[cell[1], cell[0]])

  got = np.asarray(bringup.global_costmap.readout(poses).keepout_cost)
  assert got.tolist() == [want(x, y) for x, y, _ in poses]
  assert {0, 254, 255} <= set(got.tolist())
  local = bringup.local_costmap
  with pytest.raises(ValueError, match="frame 'map' differ.*global_frame 'odom'.*transform"):
    local.readout(poses)
  tf = np.float32([1.5, -2.0, 0.3])  # T_map_from_odom
  got = np.asarray(local.readout(poses, transform=tf).keepout_cost)
  c, s = np.cos(tf[2]), np.sin(tf[2])
  mapped = [(np.float32(c * x - s * y + tf[0]), np.float32(s * x + c * y + tf[1])) for x, y, _ in poses]
  assert got.tolist() == [want(x, y) for x, y in mapped]
  with pytest.raises(ValueError, match="only for masks in another frame"):
    bringup.global_costmap.readout(poses, transform=tf)


def test_bringup_placeholders_and_launch_masks(nav2_maps):
  params = nav2_maps / "nav2_params.yaml"
  masks = _warehouse_masks(nav2_maps)
  with pytest.raises(ValueError, match=r"node '/global_costmap/global_costmap'.*'keepout_filter.enabled'.*"
                     r"'KEEPOUT_ZONE_ENABLED'.*--set KEEPOUT_ZONE_ENABLED=VALUE"):
    nav2.load_params(params, masks=masks, costmaps=("global_costmap",))
  with pytest.raises(ValueError, match=r"node '/keepout_filter_mask_server': missing parameter 'yaml_filename'"
                     r".*masks=\{'keepout_filter_mask_server'"):
    nav2.load_params(params, substitutions=_ENABLE)
  keepout_only = {"keepout_filter_mask_server": masks["keepout_filter_mask_server"]}
  off = nav2.load_params(params, masks=keepout_only, costmaps=("local_costmap",),
                         substitutions={"KEEPOUT_ZONE_ENABLED": "false"})
  assert off.global_costmap is None and off.local_costmap.keepout.enabled is False
  assert off.local_costmap.readout(np.zeros((2, 3), np.float32), transform=None).keepout_cost is None
  with pytest.warns(nav2.Nav2ParamsWarning) as record:
    p = nav2.load_params(params, masks=masks, costmaps=("local_costmap",), substitutions=_ENABLE)
  assert sorted(str(w.message).split(": ", 1)[1] for w in record) == [
      "masks['speed_filter_mask_server'] names a mask server no loaded filter uses",
      "substitution 'SPEED_ZONE_ENABLED' replaced no parameter the costmap filters read"]
  assert p.unused_substitutions == ("SPEED_ZONE_ENABLED",)
  with pytest.raises(ValueError, match="'speed_mask_server', which is not a filter mask server"):
    nav2.load_params(params, masks={"speed_mask_server": "x.yaml"}, substitutions=_ENABLE)
  with pytest.raises(FileNotFoundError, match="node '/speed_filter_mask_server'.*nope.yaml.*masks"):
    nav2.load_params(params, masks={**masks, "speed_filter_mask_server": "nope.yaml"}, substitutions=_ENABLE)


# --------------------------------------------------------------------------- files written here


def _write_mask(folder, name, data, res=0.5, origin=(-1.0, -2.0)):
  """A raw-mode mask: int data [H, W] in -1..100, row 0 = lowest y."""
  data = np.asarray(data)
  Image.fromarray(np.where(data < 0, 255, data).astype(np.uint8)[::-1], mode="L").save(folder / f"{name}.png")
  (folder / f"{name}.yaml").write_text(
      f"image: {name}.png\nmode: raw\nresolution: {res}\norigin: [{origin[0]}, {origin[1]}, 0.0]\n"
      "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
  return folder / f"{name}.yaml"


def _servers(name, ftype, base=0.0, mult=1.0, info_topic=None, mask_topic=None, yaml_filename=None, frame=None):
  info = {"type": ftype, "filter_info_topic": info_topic or f"{name}_info", "mask_topic": mask_topic or f"{name}_mask",
          "base": base, "multiplier": mult}
  mask = {"topic_name": mask_topic or f"{name}_mask"}
  if yaml_filename is not None:
    mask["yaml_filename"] = yaml_filename
  if frame is not None:
    mask["frame_id"] = frame
  return {f"{name}_info_server": {"ros__parameters": info}, f"{name}_mask_server": {"ros__parameters": mask}}


def _write_params(folder, costmap_params, *servers, name="global_costmap", extra=None):
  doc = {name: {name: {"ros__parameters": {"global_frame": "map", **costmap_params}}}}
  for s in servers:
    doc.update(s)
  doc.update(extra or {})
  path = folder / "params.yaml"
  path.write_text(yaml.safe_dump(doc, sort_keys=False))
  return path


_ZONE_DATA = np.array([[0, 1, 1, 2], [2, 3, -1, 7], [0, 0, 3, 1]])  # 7: an unconfigured id


def _zone_params(folder):
  _write_mask(folder, "zones", _ZONE_DATA)
  zone = {
      "plugin": "nav2_costmap_2d::ZoneParameterFilter", "filter_info_topic": "zone_info",
      "states": ["slow", "fast", "lamp_on", "bad", "huge"],
      "slow": {"id": 1, "setpoints": ["vel", "infl", "mode"],
               "vel": {"node": "controller_server", "parameter": "FollowPath.vx_max", "value": 0.25},
               "infl": {"node": "local_costmap", "parameter": "inflation_layer.inflation_radius", "value": 0.9},
               "mode": {"node": "controller_server", "parameter": "goal_checker", "value": "precise"}},
      "fast": {"id": 2, "setpoints": ["vel", "empty"],
               "vel": {"node": "controller_server", "parameter": "FollowPath.vx_max", "value": 1},
               "empty": {"node": "", "parameter": "x", "value": 1.0}},
      "lamp_on": {"id": 3, "setpoints": ["lamp"],
                  "lamp": {"node": "lamp_driver", "parameter": "on", "value": True}},
      "bad": {"id": 0, "setpoints": []},
      "huge": {"id": 200, "setpoints": []},
      "nominal_defaults": ["n_vel", "n_infl", "n_mode"],
      # Nav2 names these 'nominal_defaults.N.*' beside the list: dotted keys, as ROS allows.
      "nominal_defaults.n_vel.node": "controller_server",
      "nominal_defaults.n_vel.parameter": "FollowPath.vx_max",
      "nominal_defaults.n_vel.value": 0.5,
      "nominal_defaults.n_infl.node": "local_costmap",
      "nominal_defaults.n_infl.parameter": "inflation_layer.inflation_radius",
      "nominal_defaults.n_infl.value": 0.55,
      "nominal_defaults.n_mode.node": "controller_server",
      "nominal_defaults.n_mode.parameter": "goal_checker",
      "nominal_defaults.n_mode.value": "general",
  }
  return _write_params(folder, {"filters": ["zone_filter"], "zone_filter": zone},
                       _servers("zone", 4, yaml_filename="zones.yaml"))


def test_zone_filter_states_in_nav2_shape(tmp_path):
  path = _zone_params(tmp_path)
  with pytest.warns(nav2.Nav2ParamsWarning) as record:
    z = nav2.load_params(path).global_costmap.zone
  messages = "\n".join(str(w.message) for w in record)
  assert "'bad' has id 0" in messages and "skips the state" in messages
  assert "'huge' has id 200" in messages
  assert "setpoint of state 'fast' 'empty' has no node" in messages
  assert "sets lamp_driver:on, which has no nominal default" in messages
  assert "controller_server:goal_checker" in messages and "cannot hold" in messages
  assert (z.plugin, z.state_event_topic, z.mask_topic) == ("nav2_costmap_2d::ZoneParameterFilter",
                                                           "/zone_filter_state", "/zone_mask")
  assert [(s.name, s.id) for s in z.states] == [("slow", 1), ("fast", 2), ("lamp_on", 3), ("huge", 200)]
  assert z.states[0].setpoints[2] == nav2.ZoneSetpoint("mode", "controller_server", "goal_checker", "precise")
  assert [p.value for p in z.nominal_defaults] == [0.5, 0.55, "general"]
  cols = [f"{n}:{p}" for n, p in z.parameters]
  assert cols == ["controller_server:FollowPath.vx_max", "local_costmap:inflation_layer.inflation_radius",
                  "lamp_driver:on"]
  t = z.table
  assert np.flatnonzero(np.asarray(t.configured)).tolist() == [0, 1, 2, 3]
  np.testing.assert_array_equal(np.asarray(t.nominal), np.float32([0.5, 0.55, 0.0]))
  np.testing.assert_array_equal(np.asarray(t.has_nominal), [True, True, False])
  np.testing.assert_array_equal(np.asarray(t.values[1:4]), np.float32([[0.25, 0.9, 0], [1, 0, 0], [0, 0, 1]]))
  np.testing.assert_array_equal(np.asarray(t.sets[1:4]), [[1, 1, 0], [1, 0, 0], [0, 0, 1]])

  # The loaded table drives zone_filter like the reference Nav2 model built from the file by hand.
  nominal = {"vel": 0.5, "infl": 0.55}
  states = {1: {"vel": 0.25, "infl": 0.9}, 2: {"vel": 1.0}, 3: {"lamp": 1.0}}
  rng = np.random.default_rng(2)
  b, steps = 6, 8
  data = np.asarray(z.mask.data[0])
  o, r = np.asarray(z.mask.origin[0]), np.asarray(z.mask.resolution[0])
  refs = [reference.ZoneRef(nominal, states) for _ in range(b)]
  state = jf.ZoneState.create(z.table, b)
  step = jax.jit(jf.zone_filter)
  for _ in range(steps):
    xy = np.float32(np.stack([rng.uniform(-1.5, 1.5, b), rng.uniform(-2.5, -0.2, b)], 1))
    state, out = step(z.mask, np.concatenate([xy, np.zeros((b, 1), np.float32)], 1), state, z.table)
    for i in range(b):
      event, error = refs[i].process(data, o, r, xy[i, 0], xy[i, 1])
      assert (bool(out.event[i]), bool(out.error[i])) == (event, error)
      assert int(out.zone[i]) == refs[i].current
      want = [refs[i].params.get(k, 0.0) for k in ("vel", "infl", "lamp")]
      np.testing.assert_allclose(np.asarray(out.params[i]), want, rtol=1e-6)


def test_zone_state_without_id_names_the_key(tmp_path):
  path = _zone_params(tmp_path)
  doc = yaml.safe_load(path.read_text())
  del doc["global_costmap"]["global_costmap"]["ros__parameters"]["zone_filter"]["lamp_on"]["id"]
  path.write_text(yaml.safe_dump(doc))
  with pytest.raises(ValueError, match=r"node '/global_costmap/global_costmap': missing required parameter "
                     r"'zone_filter.lamp_on.id'"):
    with warnings.catch_warnings():
      warnings.simplefilter("ignore", nav2.Nav2ParamsWarning)
      nav2.load_params(path)
  p = nav2.load_params(_keepout_file(tmp_path))
  assert p.local_costmap is None and p.costmap("global_costmap") is p.global_costmap
  with pytest.raises(ValueError, match="has no local_costmap node"):
    p.costmap("local_costmap")


def test_zone_readout_flags_unconfigured_ids(tmp_path):
  with pytest.warns(nav2.Nav2ParamsWarning):
    z = nav2.load_params(_zone_params(tmp_path)).global_costmap
  # Cell centres of (0,0) id 0, (1,0) id 1, (3,1) id 7, (2,1) unknown, one point off the mask.
  poses = np.float32([[-0.75, -1.75, 0], [-0.25, -1.75, 0], [0.75, -1.25, 0], [0.25, -1.25, 0], [9, 9, 0]])
  out = z.readout(poses).zone
  assert np.asarray(out.zone).tolist() == [0, 1, 0, 0, 0]
  assert np.asarray(out.error).tolist() == [False, False, True, False, False]


def test_binary_filter_topics_threshold_and_first_cycle(tmp_path):
  data = np.array([[0, 10, 64, 65], [66, 100, -1, 40]])
  _write_mask(tmp_path, "bin", data, res=1.0, origin=(0.0, 0.0))
  binary = {"plugin": "nav2_costmap_2d::BinaryFilter", "filter_info_topic": "/binary_info",
            "default_state": True, "flip_threshold": 35.0}
  path = _write_params(tmp_path, {"filters": ["binary_filter"], "binary_filter": binary},
                       _servers("binary", 3, base=100.0, mult=-1.0, info_topic="/binary_info",
                                mask_topic="/binary_mask", yaml_filename="bin.yaml"))
  f = nav2.load_params(path).global_costmap.binary
  assert (f.default_state, f.flip_threshold, f.binary_state_topic) == (True, 35.0, "/global_costmap/binary_state")
  poses = np.float32([[x + 0.5, y + 0.5, 0] for y in range(2) for x in range(4)] + [[-1, 0, 0]])
  out = nav2.Nav2Costmap.readout(nav2.load_params(path).global_costmap, poses).binary
  for i, (x, y, _) in enumerate(poses):
    ref = reference.BinaryRef(default_state=True, threshold=35.0)
    published = ref.process(data, (0.0, 0.0), 1.0, 100.0, -1.0, x, y)
    assert (bool(out.binary_state[i]), bool(out.published[i])) == (ref.state, published), (x, y)
  # Relative binary topics resolve in the costmap's own namespace (Nav2 does not join them).
  binary["filter_info_topic"] = "binary_info"
  path = _write_params(tmp_path, {"filters": ["binary_filter"], "binary_filter": binary},
                       _servers("binary", 3, info_topic="binary_info", yaml_filename="bin.yaml"))
  with pytest.raises(ValueError, match=r"publishes '/global_costmap/binary_info' \(found: \['/binary_info'\]\)"
                     r".*BinaryFilter does not join"):
    nav2.load_params(path)


def test_speed_absolute_namespaces_wildcards_lookahead_and_type_checks(tmp_path):
  _write_mask(tmp_path, "spd", [[0, 20, 50, -1]], res=0.25, origin=(0.0, 0.0))
  speed = {"plugin": "nav2_costmap_2d::SpeedFilter", "enabled": True, "filter_info_topic": "speed_info",
           "speed_limit_topic": "limit", "enable_path_lookahead": True, "max_decel": 0.2, "min_lookahead": -1.0}
  costmap = {"global_costmap": {"global_costmap": {"ros__parameters": {
      "filters": ["speed_filter"], "speed_filter": speed, "resolution": 0.1}}}}
  doc = {"tb4": {**costmap, **_servers("speed", 2, base=0.0, mult=0.01, yaml_filename="spd.yaml")},
         "/**/global_costmap": {"ros__parameters": {"resolution": 9.0, "global_frame": "tb4/map"}}}
  path = tmp_path / "ns.yaml"
  path.write_text(yaml.safe_dump(doc))
  with pytest.warns(nav2.Nav2ParamsWarning) as record:
    g = nav2.load_params(path).global_costmap
  messages = " ".join(str(w.message) for w in record)
  assert "max_decel 0.2 is not negative" in messages and "min_lookahead -1.0 < 0 is clamped" in messages
  assert (g.node, g.resolution, g.global_frame) == ("/tb4/global_costmap/global_costmap", 0.1, "tb4/map")
  s = g.speed
  assert (s.filter_info_topic, s.mask_topic, s.speed_limit_topic, s.path_topic) == (
      "/tb4/speed_info", "/tb4/speed_mask", "/tb4/limit", "/tb4/plan")
  assert s.percentage is False and s.lookahead == jf.LookaheadConfig(0.2, 0.0, 5.0)
  assert s.mask_frame == "map" and g.foreign_frames() == ("map",)
  out = g.readout(np.float32([[0.1, 0.1, 0], [0.3, 0.1, 0], [0.6, 0.1, 0], [0.9, 0.1, 0]]),
                  transform=[0.0, 0.0, 0.0]).speed
  np.testing.assert_allclose(np.asarray(out.speed_limit), [0.0, np.float32(0.2), np.float32(0.5), 0.0])
  assert np.asarray(out.valid).tolist() == [True, True, True, False]
  assert not bool(np.any(np.asarray(out.percentage)))


def _lookahead_params(tmp_path, extra):
  """A params file with a lookahead SpeedFilter whose parameters are `extra` on top of the defaults."""
  _write_mask(tmp_path, "spd", [[0, 20]])
  speed = {"plugin": "nav2_costmap_2d::SpeedFilter", "filter_info_topic": "speed_info",
           "enable_path_lookahead": True, **extra}
  path = _write_params(tmp_path, {"filters": ["speed_filter"], "speed_filter": speed},
                       _servers("speed", 1, yaml_filename="spd.yaml"))
  return path


@pytest.mark.parametrize("extra, expected", [
    ({}, (0.0, False)),                                       # absent: Nav2 main's behaviour
    ({"max_path_rewind": 1.5, "clear_path_on_reset": True}, (1.5, True)),
])
def test_speed_lookahead_rewind_and_clear_path_parameters(tmp_path, extra, expected):
  la = nav2.load_params(_lookahead_params(tmp_path, extra)).global_costmap.speed.lookahead
  assert (la.max_path_rewind, la.clear_path_on_reset) == expected
  assert la == jf.LookaheadConfig(max_path_rewind=expected[0], clear_path_on_reset=expected[1])


@pytest.mark.parametrize("extra, match", [
    ({"max_path_rewind": -1.0}, r"max_path_rewind -1.0 is negative"),
    ({"max_path_rewind": 1e39}, r"max_path_rewind. must fit float32"),
    ({"clear_path_on_reset": 1}, r"clear_path_on_reset"),
])
def test_speed_lookahead_rewind_parameters_bad_values(tmp_path, extra, match):
  with pytest.raises(ValueError, match=match):        # Nav2ParamsError, or the float32 check's ValueError
    nav2.load_params(_lookahead_params(tmp_path, extra))


def _keepout_file(tmp_path, keepout=None, info=None, extra=None, filters=("keepout_filter",)):
  _write_mask(tmp_path, "keep", [[0, 100], [50, -1]])
  k = {"plugin": "nav2_costmap_2d::KeepoutFilter", "filter_info_topic": "keepout_info"}
  k.update(keepout or {})
  servers = _servers("keepout", 0, yaml_filename="keep.yaml")
  servers["keepout_info_server"]["ros__parameters"].update(info or {})
  return _write_params(tmp_path, {"filters": list(filters), "keepout_filter": k, **(extra or {})}, servers)


@pytest.mark.parametrize("keepout,info,error,match", [
    ({"plugin": None}, {}, ValueError, r"node '/global_costmap/global_costmap'.*missing required parameter "
                                       r"'keepout_filter.plugin'"),
    ({"plugin": "nav2_costmap_2d::KeepOutFilter"}, {}, ValueError, r"unknown plugin 'nav2_costmap_2d::KeepOutFilter'"
                                                                  r".*'keepout_filter.plugin'"),
    ({"filter_info_topic": None}, {}, ValueError, r"missing required parameter 'keepout_filter.filter_info_topic'"),
    ({"filter_info_topic": "other_info"}, {}, ValueError, r"no costmap_filter_info_server .* publishes "
                                                         r"'/other_info' \(found: \['/keepout_info'\]\)"),
    ({"enabled": "maybe"}, {}, ValueError, r"'keepout_filter.enabled' must be a bool.*'maybe'.*--set maybe=VALUE"),
    ({"lethal_override_cost": 1.5}, {}, ValueError, r"'keepout_filter.lethal_override_cost' must be an integer"),
    ({"override_lethal_cost": 1}, {}, ValueError, r"'keepout_filter.override_lethal_cost' must be a bool .*; got 1$"),
    ({}, {"type": 9}, ValueError, r"node '/keepout_info_server': parameter 'type'.*got 9"),
    ({}, {"type": "0"}, ValueError, r"node '/keepout_info_server': parameter 'type' must be an integer"),
    ({}, {"base": 1e39}, ValueError, r"node '/keepout_info_server': parameter 'base' must fit float32"),
    ({}, {"multiplier": float("nan")}, ValueError, r"parameter 'multiplier' must be finite"),
    ({}, {"mask_topic": "elsewhere"}, ValueError, r"no filter mask server .* publishes '/elsewhere'"),
])
def test_bad_filter_parameters_name_node_and_key(tmp_path, keepout, info, error, match):
  path = _keepout_file(tmp_path, {k: v for k, v in keepout.items()}, info)
  doc = yaml.safe_load(path.read_text())
  params = doc["global_costmap"]["global_costmap"]["ros__parameters"]["keepout_filter"]
  for key in [k for k, v in keepout.items() if v is None]:
    del params[key]
  path.write_text(yaml.safe_dump(doc))
  with pytest.raises(error, match=match):
    nav2.load_params(path)


def test_files_and_yaml_errors(tmp_path):
  with pytest.raises(FileNotFoundError, match="params file .*missing.yaml does not exist"):
    nav2.load_params(tmp_path / "missing.yaml")
  bad = tmp_path / "bad.yaml"
  bad.write_text("a: [1, 2\n")
  with pytest.raises(ValueError, match="bad.yaml: invalid params YAML"):
    nav2.load_params(bad)
  bad.write_text("- 1\n- 2\n")
  with pytest.raises(ValueError, match="must be a mapping of node names"):
    nav2.load_params(bad)
  bad.write_text("amcl:\n  ros__parameters:\n    x: 1\n")
  with pytest.raises(ValueError, match="no global_costmap or local_costmap node"):
    nav2.load_params(bad)
  path = _keepout_file(tmp_path)
  (tmp_path / "keep.png").unlink()
  with pytest.raises(FileNotFoundError, match=r"node '/keepout_mask_server' \(parameter 'yaml_filename'\).*keep.png"):
    nav2.load_params(path)
  (tmp_path / "keep.yaml").unlink()
  with pytest.raises(FileNotFoundError, match=r"node '/keepout_mask_server': mask file .*keep.yaml \(parameter "
                     r"'yaml_filename'\) does not exist"):
    nav2.load_params(path)
  with pytest.raises(ValueError, match="costmaps must name some of"):
    nav2.load_params(path, costmaps=("controller_server",))


def test_keepout_options_placeholders_and_warnings(tmp_path):
  path = _keepout_file(tmp_path, {"enabled": "KEEP_ON", "lethal_override_cost": 300, "override_lethal_cost": True},
                       {"base": "KEEP_BASE"})
  with pytest.raises(ValueError, match=r"'keepout_filter.enabled' must be a bool.*'KEEP_ON'"):
    nav2.load_params(path)
  with pytest.raises(ValueError, match=r"node '/keepout_info_server': parameter 'base' must be a number.*'KEEP_BASE'"):
    nav2.load_params(path, substitutions={"KEEP_ON": "yes"})
  with pytest.raises(ValueError, match=r"'keepout_filter.enabled' must be a bool .*; got 'maybe' from "
                     r"substitution 'KEEP_ON'$"):
    nav2.load_params(path, substitutions={"KEEP_ON": "maybe", "KEEP_BASE": "2.5"})
  with pytest.warns(nav2.Nav2ParamsWarning) as record:
    k = nav2.load_params(path, substitutions={"KEEP_ON": "false", "KEEP_BASE": "2.5"}).global_costmap.keepout
  messages = " ".join(str(w.message) for w in record)
  assert "lethal_override_cost 300 is clamped to [0, 252]" in messages
  assert "base 2.5 / multiplier 1.0; KeepoutFilter ignores them" in messages
  assert k.enabled is False and k.config.lethal_override_cost == 252 and k.config.override_lethal_cost
  assert float(k.mask.info.base[0]) == 2.5
  # A Python value substitutes as is; a keepout under `plugins:` runs as a layer.
  path = _keepout_file(tmp_path, {"enabled": "KEEP_ON"}, extra={
      "plugins": ["static_layer", "keepout_filter", "inflation_layer"],
      "static_layer": {"plugin": "nav2_costmap_2d::StaticLayer"}}, filters=())
  k = nav2.load_params(path, substitutions={"KEEP_ON": True}).global_costmap.keepout
  assert k.as_layer and k.enabled


def test_speed_info_type_mismatch_warns_and_limits_nothing(tmp_path):
  _write_mask(tmp_path, "spd", [[30, 40]])
  speed = {"plugin": "nav2_costmap_2d::SpeedFilter", "filter_info_topic": "speed_info"}
  path = _write_params(tmp_path, {"filters": ["speed_filter"], "speed_filter": speed},
                       _servers("speed", 0, yaml_filename="spd.yaml"))
  with pytest.warns(nav2.Nav2ParamsWarning, match="type 0, not 1 .percent. or 2 .m/s.; SpeedFilter logs an error"):
    g = nav2.load_params(path).global_costmap
  assert g.speed.percentage is None
  out = g.readout(np.float32([[-0.75, -1.75, 0]])).speed
  assert not bool(out.valid[0]) and float(out.speed_limit[0]) == 0.0


def test_two_filters_of_one_kind_and_from_masks(tmp_path):
  path = _keepout_file(tmp_path, extra={"keepout_b": {"plugin": "nav2_costmap_2d::KeepoutFilter",
                                                      "filter_info_topic": "keepout_info"}},
                       filters=("keepout_filter", "keepout_b"))
  g = nav2.load_params(path).global_costmap
  assert [f.name for f in g.filters] == ["keepout_filter", "keepout_b"]
  assert g.filters[0].mask_yaml == g.filters[1].mask_yaml == str(tmp_path / "keep.yaml")
  with pytest.raises(ValueError, match="2 KeepoutFilters .keepout_filter, keepout_b."):
    g.keepout  # noqa: B018
  grid = jf.OccupancyGrid.create(np.array([[0, 3], [100, -1]]), 1.0, (0.0, 0.0))
  c = nav2.Nav2Costmap.from_masks(keepout=jf.FilterMask.create(grid, jf.FilterInfo.create(0)),
                                  zone=jf.FilterMask.create(grid, jf.FilterInfo.create(4)))
  poses = np.float32([[0.5, 0.5, 0], [1.5, 0.5, 0], [0.5, 1.5, 0], [1.5, 1.5, 0], [2.5, 0.5, 0]])
  out = c.readout(poses)
  assert np.asarray(out.keepout_cost).tolist() == [0, 8, 254, 255, 255]
  assert np.asarray(out.zone.zone).tolist() == [0, 3, 100, 0, 0] and not bool(np.any(out.zone.error))
  assert out.speed is None and out.binary is None
  out = c.readout(poses + np.float32(0.25))
  with count_compiles() as compiles:
    c.readout(poses - np.float32(0.25))  # new values, same shapes: nothing compiles
  assert compiles() == 0
  with pytest.raises(ValueError, match="poses must be"):
    c.readout(np.float32([[0.5, 0.5]]))
