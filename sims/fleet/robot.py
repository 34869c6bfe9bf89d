"""Your own robot: an MJCF base for the fleet, checked against a documented interface.

    robot = load_robot("examples/robots/diff_drive.xml")     # RobotModel, or RobotModelError
    env = FleetEnv.create(scenario, config, robot=robot)      # the file's radius everywhere

The interface (docs/guides/robots.md says the same, with examples):

* a body named `base`, a child of the world body at x = y = 0 with no rotation,
  carrying exactly three joints, in this order: a slide along (1, 0, 0), a slide
  along (0, 1, 0) and a hinge about (0, 0, 1) through the body origin (qpos =
  x, y, yaw of the robot centre), no limits, springs, damping or friction loss,
  and no other joint in the model (nq = nv = 3);
* a site named `base_link` on `base` at its origin with no rotation: the frame
  the commands are given in (Nav2's `cmd_vel` frame);
* `velocity` actuators (kv in (0, `MAX_KV`], no ctrlrange or forcerange: the fleet's speed
  caps are the limits) on the `base_link` site, one per gear axis, named by the
  drive type:
  - differential drive: `v` (gear 1 0 0 0 0 0, forward speed), `wz` (gear
    0 0 0 0 0 1, yaw rate) and `no_slip` (gear 0 1 0 0 0 0, the wheels' lateral
    grip: a servo the controller holds at 0, so the base does not slide sideways);
  - holonomic (omni): `vx`, `vy`, `wz` (gears x, y and yaw). The fleet's planner
    commands (v, w), so an omni base is driven with vx = v, vy = 0, wz = w;
  each actuator must follow its command within `MAX_TIME_CONSTANT` s (the base's
  mass, or yaw inertia, over kv);
* the costmap footprint: `<custom><numeric name="jaxfilters_radius" data="R"/>`, a
  disc of radius R metres about `base_link`, R in [`MIN_RADIUS`, `MAX_RADIUS`] and
  at least the map's resolution; every geom of the robot lies inside it;
* contacts off (`<flag contact="disable"/>`, or contype = conaffinity = 0 on every
  geom): robots keep apart through their costmaps, as the built-in robot does;
* everything in one file: no `<include>`, no `file=` attribute (meshes,
  textures, height fields), no asset folders, no DOCTYPE or entities, no
  plugins, no generated bodies (`replicate`, `composite`, flexes), no `<size>`
  (the fleet sizes the memory); at most `MAX_BYTES` bytes, nesting at most
  `MAX_DEPTH` elements deep, at most `MAX_BODIES` bodies and `MAX_GEOMS` geoms,
  and no geom on the world body (the warehouse is the map).

The fleet sets the physics options it runs every robot with: the timestep
(`FleetConfig.physics_dt`), the implicitfast integrator and the sparse
Jacobian. The file's radius replaces `FleetConfig.robot.radius` (`configure`), so
the costmap footprint, inflation, the keepout footprint test, spawn spacing and
the contact metric all use it; speed and acceleration limits stay the
FleetConfig's. Every problem raises `RobotModelError` (a ValueError) with one
line saying what was wrong and what is expected.
"""

from __future__ import annotations

import dataclasses
import math
import os
import stat
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np

ROBOT_XML = Path(__file__).resolve().parents[1] / "assets" / "planar_robot.xml"
DRIVES = {"diff_drive": ("v", "no_slip", "wz"), "omni": ("vx", "vy", "wz")}
MAX_BYTES = 1 << 20          # bytes of an MJCF file
MAX_DEPTH = 32               # XML element nesting
MAX_BODIES = 64              # bodies, world included
MAX_GEOMS = 256
MIN_RADIUS, MAX_RADIUS = 0.05, 2.0     # m, the footprint disc
MAX_TIME_CONSTANT = 0.02     # s, mass / kv (yaw inertia / kv) of each actuator
MAX_KV = 1e6                 # N s/m (N m s/rad), an actuator's kv: far inside float32 with the masses above
RADIUS_NAME = "jaxfilters_radius"
# Elements that read other files, load code, generate bodies or size memory: refused.
FORBIDDEN_ELEMENTS = ("include", "model", "plugin", "extension", "instance", "replicate", "composite",
                      "flexcomp", "flex", "deformable", "skin", "hfield", "size", "attach")
FORBIDDEN_ATTRIBUTES = ("file", "meshdir", "texturedir", "assetdir", "fileright", "fileleft", "fileup",
                        "filedown", "filefront", "fileback", "content_type", "plugin")
_GEARS = {"x": (1, 0, 0, 0, 0, 0), "y": (0, 1, 0, 0, 0, 0), "yaw": (0, 0, 0, 0, 0, 1)}
_AXIS_OF = {"v": "x", "vx": "x", "no_slip": "y", "vy": "y", "wz": "yaw"}


class RobotModelError(ValueError):
  """A robot MJCF that does not meet the interface of `sims.fleet.robot` (one line: what and what is expected)."""


@dataclasses.dataclass(frozen=True)
class RobotModel:
  """A checked robot MJCF (build with `load_robot` or `robot_from_xml`, never by hand).

  Attributes:
    name: where it came from (the file path, or "<string>").
    xml: the MJCF text.
    drive: "diff_drive" or "omni".
    radius: m, the footprint disc (`jaxfilters_radius`).
    num_ctrl: actuators (3).
    forward: index of the forward-speed actuator (`v` or `vx`).
    yaw: index of the yaw-rate actuator (`wz`).
  """
  name: str
  xml: str
  drive: str
  radius: float
  num_ctrl: int
  forward: int
  yaw: int

  def mj_model(self, timestep: float) -> mujoco.MjModel:
    """The MjModel with the fleet's physics options: `timestep` s, implicitfast, sparse Jacobian.

    Args:
      timestep: s, the physics step (`FleetConfig.physics_dt`).

    Returns:
      A mujoco.MjModel of one robot.
    """
    m = mujoco.MjModel.from_xml_string(self.xml)
    m.opt.timestep = timestep
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    m.opt.jacobian = mujoco.mjtJacobian.mjJAC_SPARSE
    return m

  def configure(self, config):
    """`config` with the file's radius as `robot.radius` (what FleetEnv.create runs with).

    Args:
      config: a FleetConfig.

    Returns:
      The FleetConfig with robot.radius = self.radius; its other fields unchanged.

    Raises:
      ValueError: the FleetConfig refuses the radius (e.g. a local costmap too small for it).
    """
    return dataclasses.replace(config, robot=dataclasses.replace(config.robot, radius=self.radius))

  def check_resolution(self, resolution: float) -> None:
    """Refuses a map whose cells are larger than the robot's radius (the footprint would be one cell).

    Raises:
      RobotModelError: radius < resolution.
    """
    if self.radius < resolution:
      raise RobotModelError(f"{self.name}: radius {self.radius:g} m is below the map resolution {resolution:g} m; "
                            "the footprint must span at least one cell each side of the centre")

  def ctrl_vectors(self) -> tuple[np.ndarray, np.ndarray]:
    """(forward, yaw) float32 [num_ctrl] one-hot vectors: ctrl = v * forward + w * yaw."""
    e = np.eye(self.num_ctrl, dtype=np.float32)
    return e[self.forward], e[self.yaw]


def planar_ctrl(robot: RobotModel | None, v, w, yaw):
  """Actuator targets of K robots for the body-frame command (v, w).

  Args:
    robot: the RobotModel, or None for the built-in robot (sims/assets/planar_robot.xml,
      whose actuators act in the world frame: the command is rotated by the yaw).
    v: float32 [K] m/s; w: float32 [K] rad/s; yaw: float32 [K] rad.

  Returns:
    float32 [K, num_ctrl] ctrl (an omni base's vy and a differential drive's no_slip are 0).
  """
  import jax.numpy as jnp  # noqa: PLC0415 - the loader above runs without jax (the CLI's checks)
  if robot is None:
    return jnp.stack([v * jnp.cos(yaw), v * jnp.sin(yaw), w], axis=1)
  fwd, rot = robot.ctrl_vectors()
  return v[:, None] * jnp.asarray(fwd)[None, :] + w[:, None] * jnp.asarray(rot)[None, :]


def load_builtin_model(config) -> mujoco.MjModel:
  """The built-in planar robot (sims/assets/planar_robot.xml) with the config's timestep and radius.

  Args:
    config: FleetConfig (physics_dt in s, robot.radius in m).

  Returns:
    A mujoco.MjModel of one robot (contacts off).
  """
  m = mujoco.MjModel.from_xml_path(str(ROBOT_XML))
  m.opt.timestep = config.physics_dt
  gid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "chassis")
  m.geom_size[gid, 0] = config.robot.radius          # visual only: contacts are off
  return m


# ----------------------------------------------------------------------------- loading


def load_robot(path) -> RobotModel:
  """Reads and checks a robot MJCF file (a regular UTF-8 file of at most MAX_BYTES).

  Args:
    path: the file.

  Returns:
    The RobotModel.

  Raises:
    RobotModelError: the file cannot be read, or the model breaks the interface (module docstring).
  """
  name = str(path)
  try:
    fd = os.open(name, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
  except FileNotFoundError:
    raise RobotModelError(f"{name}: file does not exist") from None
  except (OSError, ValueError) as e:
    raise RobotModelError(f"{name}: cannot read it ({getattr(e, 'strerror', None) or e})") from None
  try:
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode):
      raise RobotModelError(f"{name}: not a regular file (a FIFO, device or directory is refused)")
    if st.st_size > MAX_BYTES:
      raise RobotModelError(f"{name}: {st.st_size} bytes; a robot MJCF is at most {MAX_BYTES} bytes")
    data = os.read(fd, MAX_BYTES + 1)
  except OSError as e:
    raise RobotModelError(f"{name}: cannot read it ({e.strerror or e})") from None
  finally:
    os.close(fd)
  if len(data) > MAX_BYTES:
    raise RobotModelError(f"{name}: more than {MAX_BYTES} bytes; a robot MJCF is at most {MAX_BYTES} bytes")
  return robot_from_xml(data, name=name)


def robot_from_xml(xml: str | bytes, *, name: str = "<string>") -> RobotModel:
  """Checks robot MJCF text against the interface and returns it as a RobotModel.

  Args:
    xml: the MJCF (str, or UTF-8 bytes), at most MAX_BYTES bytes.
    name: how errors name it.

  Returns:
    The RobotModel.

  Raises:
    RobotModelError: anything that breaks the interface (module docstring), one line.
  """
  if isinstance(xml, str):
    try:
      data = xml.encode("utf-8")
    except UnicodeEncodeError as e:
      raise RobotModelError(f"{name}: not encodable as UTF-8 (character {e.start})") from None
  elif isinstance(xml, bytes):
    data = xml
  else:
    raise RobotModelError(f"{name}: MJCF must be str or bytes; got {type(xml).__name__}")
  if len(data) > MAX_BYTES:
    raise RobotModelError(f"{name}: {len(data)} bytes; a robot MJCF is at most {MAX_BYTES} bytes")
  try:
    text = data.decode("utf-8")
  except UnicodeDecodeError as e:
    raise RobotModelError(f"{name}: not UTF-8 text (byte {e.start})") from None
  _check_text(text, name)
  said: list[str] = []
  previous = mujoco.get_mju_user_warning()
  mujoco.set_mju_user_warning(said.append)       # MuJoCo's warnings become the refusal, not stray lines
  try:
    model = _compile(text, name)
    _check_numbers(model, name)
    drive, forward, yaw = _check_model(model, name)
    radius = _check_radius(model, name)
  finally:
    mujoco.set_mju_user_warning(previous)
  if said:
    raise RobotModelError(f"{name}: MuJoCo warns about it ({_one_line(said[0])})")
  return RobotModel(name=name, xml=text, drive=drive, radius=radius, num_ctrl=model.nu, forward=forward, yaw=yaw)


def _check_text(text: str, name: str) -> None:
  """Well-formed XML, one file, bounded nesting, none of the refused elements and attributes."""
  if "\x00" in text:
    raise RobotModelError(f"{name}: contains a NUL character")
  if "<!" in text.replace("<!--", ""):
    raise RobotModelError(f"{name}: DOCTYPE, ENTITY and CDATA declarations are refused (a robot is plain MJCF)")
  try:
    root = ET.fromstring(text)
  except ET.ParseError as e:
    raise RobotModelError(f"{name}: not well-formed XML ({_one_line(str(e))})") from None
  if root.tag != "mujoco":
    raise RobotModelError(f"{name}: the root element must be <mujoco>; got <{_short(root.tag)}>")
  stack = [(root, 1)]
  while stack:
    el, depth = stack.pop()
    if depth > MAX_DEPTH:
      raise RobotModelError(f"{name}: elements nested more than {MAX_DEPTH} deep")
    if not isinstance(el.tag, str):
      continue
    if el.tag in FORBIDDEN_ELEMENTS:
      raise RobotModelError(f"{name}: <{el.tag}> is refused: a robot is one file of plain MJCF (no includes, "
                            "plugins, generated bodies or <size>)")
    for attr in el.attrib:
      if attr in FORBIDDEN_ATTRIBUTES:
        raise RobotModelError(f"{name}: attribute {_short(attr)}= on <{el.tag}> is refused: a robot reads no other "
                              "file (meshes inline as vertex data, textures builtin)")
    stack.extend((child, depth + 1) for child in el)


def _compile(text: str, name: str) -> mujoco.MjModel:
  try:
    return mujoco.MjModel.from_xml_string(text)
  except Exception as e:  # noqa: BLE001 - MuJoCo's compiler raises ValueError; anything else is a refusal too
    raise RobotModelError(f"{name}: MuJoCo cannot compile it ({_one_line(str(e))})") from None


def _check_numbers(m: mujoco.MjModel, name: str) -> None:
  """Every number of the compiled model finite in float32 (MJX runs it in float32); the fleet's physics options."""
  limit = float(np.finfo(np.float32).max)
  for field in dir(m):
    if field.startswith("_"):
      continue
    value = getattr(m, field, None)
    if isinstance(value, np.ndarray) and value.dtype.kind == "f" and value.size \
        and not np.all(np.abs(value) <= limit):
      raise RobotModelError(f"{name}: a number in {field} is NaN, infinite or beyond float32's range "
                            f"(+-{limit:.4g}); MJX runs the model in float32")
  o = m.opt
  if np.any(o.gravity[:2] != 0) or o.density != 0 or o.viscosity != 0 or np.any(o.wind != 0):
    raise RobotModelError(f"{name}: <option> gravity along x or y, density, viscosity and wind must be 0 (the "
                          "actuators alone move the base)")
  if o.disableflags & mujoco.mjtDisableBit.mjDSBL_ACTUATION or o.disableactuator:
    raise RobotModelError(f"{name}: actuation is disabled in <option>; the fleet drives the base through its actuators")


def _check_model(m: mujoco.MjModel, name: str) -> tuple[str, int, int]:
  """The structure of the interface; returns (drive, forward index, yaw index)."""
  if m.nbody > MAX_BODIES or m.ngeom > MAX_GEOMS:
    raise RobotModelError(f"{name}: {m.nbody} bodies and {m.ngeom} geoms; at most {MAX_BODIES} and {MAX_GEOMS}")
  base = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "base")
  if base < 0:
    raise RobotModelError(f"{name}: no body named 'base' (the robot's base, carrying the planar joints)")
  if m.body_parentid[base] != 0:
    raise RobotModelError(f"{name}: body 'base' must be a child of the world body")
  if not (np.all(m.body_pos[base, :2] == 0) and np.allclose(m.body_quat[base], (1, 0, 0, 0), atol=1e-9)):
    raise RobotModelError(f"{name}: body 'base' must sit at x = y = 0 with no rotation (its joints give the pose); "
                          f"got pos {_vec(m.body_pos[base])}, quat {_vec(m.body_quat[base])}")
  if m.njnt != 3 or m.nq != 3 or m.nv != 3:
    raise RobotModelError(f"{name}: the model must have exactly 3 joints (slide x, slide y, hinge yaw on 'base'); "
                          f"got {m.njnt} joints, nq = {m.nq}, nv = {m.nv}")
  want = ((mujoco.mjtJoint.mjJNT_SLIDE, (1, 0, 0)), (mujoco.mjtJoint.mjJNT_SLIDE, (0, 1, 0)),
          (mujoco.mjtJoint.mjJNT_HINGE, (0, 0, 1)))
  for j, (kind, axis) in enumerate(want):
    label = ("slide along (1, 0, 0)", "slide along (0, 1, 0)", "hinge about (0, 0, 1)")[j]
    if (m.jnt_bodyid[j] != base or m.jnt_type[j] != kind or not np.allclose(m.jnt_axis[j], axis, atol=1e-9)
        or m.jnt_qposadr[j] != j):
      raise RobotModelError(f"{name}: joint {j} must be a {label} on body 'base' (joints in the order x, y, yaw)")
    if m.jnt_limited[j] or m.jnt_stiffness[j] != 0 or m.qpos0[j] != 0:
      raise RobotModelError(f"{name}: joint {j} ({label}) must have no limits, no stiffness and ref 0")
    if m.dof_damping[j] != 0 or m.dof_frictionloss[j] != 0:
      raise RobotModelError(f"{name}: joint {j} ({label}) must have no damping or friction loss (the actuators "
                            "alone set the speed)")
  if np.any(m.jnt_pos[2] != 0):
    raise RobotModelError(f"{name}: the yaw hinge must pass through the origin of 'base'; got pos {_vec(m.jnt_pos[2])}")
  if m.neq or m.ntendon:
    raise RobotModelError(f"{name}: equality constraints and tendons are refused ({m.neq} and {m.ntendon})")
  contacts_off = bool(m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT)
  if not contacts_off and (np.any(m.geom_contype != 0) or np.any(m.geom_conaffinity != 0)):
    raise RobotModelError(f"{name}: contacts must be off: <flag contact=\"disable\"/> in <option>, or contype = "
                          "conaffinity = 0 on every geom (robots keep apart through their costmaps)")
  if np.any(m.geom_bodyid == 0):
    raise RobotModelError(f"{name}: a geom on the world body; the file holds the robot only (the warehouse is the map)")
  site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "base_link")
  if site < 0 or m.site_bodyid[site] != base:
    raise RobotModelError(f"{name}: no site 'base_link' on body 'base' (the frame of the velocity commands)")
  if np.any(m.site_pos[site] != 0) or not np.allclose(m.site_quat[site], (1, 0, 0, 0), atol=1e-9):
    raise RobotModelError(f"{name}: site 'base_link' must sit at the origin of 'base' with no rotation")
  names = tuple(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, i) or "" for i in range(m.nu))
  drive = next((d for d, want_names in DRIVES.items() if sorted(names) == sorted(want_names)), None)
  if drive is None:
    raise RobotModelError(f"{name}: actuators must be {DRIVES['diff_drive']} (differential drive) or "
                          f"{DRIVES['omni']} (omni); got {tuple(_short(n) for n in names)}")
  data = mujoco.MjData(m)
  mujoco.mj_forward(m, data)
  inertia = np.zeros((3, 3))
  mujoco.mj_fullM(m, data, inertia)
  for i, act in enumerate(names):
    axis = _AXIS_OF[act]
    kv = float(m.actuator_gainprm[i, 0])
    velocity = (m.actuator_dyntype[i] == mujoco.mjtDyn.mjDYN_NONE
                and m.actuator_gaintype[i] == mujoco.mjtGain.mjGAIN_FIXED
                and m.actuator_biastype[i] == mujoco.mjtBias.mjBIAS_AFFINE and m.actuator_biasprm[i, 0] == 0
                and m.actuator_biasprm[i, 1] == 0 and m.actuator_biasprm[i, 2] == -kv)
    if not velocity or not 0 < kv <= MAX_KV:
      raise RobotModelError(f"{name}: actuator '{act}' must be a <velocity> actuator with kv in (0, {MAX_KV:g}]")
    if m.actuator_trntype[i] != mujoco.mjtTrn.mjTRN_SITE or m.actuator_trnid[i, 0] != site \
        or m.actuator_trnid[i, 1] != -1 or tuple(m.actuator_gear[i]) != _GEARS[axis]:
      raise RobotModelError(f"{name}: actuator '{act}' must act on site 'base_link' with gear "
                            f"\"{' '.join(map(str, _GEARS[axis]))}\"")
    if m.actuator_ctrllimited[i] or m.actuator_forcelimited[i]:
      raise RobotModelError(f"{name}: actuator '{act}' must have no ctrlrange or forcerange (the fleet's speed caps "
                            "are the limits; a range would clip commands the planner counts on)")
    tau = inertia[2, 2] / kv if axis == "yaw" else inertia[0, 0] / kv
    if not tau <= MAX_TIME_CONSTANT:
      raise RobotModelError(f"{name}: actuator '{act}' follows its command too slowly: "
                            f"{'yaw inertia' if axis == 'yaw' else 'mass'} / kv = {tau:.3g} s; at most "
                            f"{MAX_TIME_CONSTANT} s (raise kv)")
  forward = names.index("v" if drive == "diff_drive" else "vx")
  return drive, forward, names.index("wz")


def _check_radius(m: mujoco.MjModel, name: str) -> float:
  """The declared footprint radius, bounded, with every geom inside it."""
  nid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_NUMERIC, RADIUS_NAME)
  if nid < 0 or m.numeric_size[nid] != 1:
    raise RobotModelError(f"{name}: no footprint radius: add <custom><numeric name=\"{RADIUS_NAME}\" "
                          "data=\"R\"/></custom> "
                          "(one number, metres)")
  r = float(m.numeric_data[m.numeric_adr[nid]])
  if not (math.isfinite(r) and MIN_RADIUS <= r <= MAX_RADIUS):
    raise RobotModelError(f"{name}: {RADIUS_NAME} must be a number of metres in [{MIN_RADIUS}, {MAX_RADIUS}]; "
                          f"got {r!r}")
  data = mujoco.MjData(m)
  mujoco.mj_forward(m, data)
  base = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "base")
  upright_round = (mujoco.mjtGeom.mjGEOM_SPHERE, mujoco.mjtGeom.mjGEOM_CYLINDER, mujoco.mjtGeom.mjGEOM_CAPSULE)
  for g in range(m.ngeom):
    if m.geom_type[g] in (mujoco.mjtGeom.mjGEOM_PLANE, mujoco.mjtGeom.mjGEOM_HFIELD):
      raise RobotModelError(f"{name}: geom {g} is a plane or height field; a robot's geoms are bounded")
    centre = float(np.hypot(*(data.geom_xpos[g, :2] - data.xpos[base, :2])))
    z_up = abs(float(data.geom_xmat[g].reshape(3, 3)[2, 2])) > 1 - 1e-9
    half = float(m.geom_size[g, 0]) if (m.geom_type[g] in upright_round and z_up) else float(m.geom_rbound[g])
    if not centre + half <= r + 1e-6:
      label = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) or f"#{g}"
      raise RobotModelError(f"{name}: geom '{_short(label)}' reaches {centre + half:.4g} m from base_link, outside "
                            f"the footprint {RADIUS_NAME} = {r:g} m (the costmap would not cover it)")
  return r


def _one_line(text: str, limit: int = 300) -> str:
  flat = "; ".join(x.strip() for x in text.splitlines() if x.strip())
  return flat if len(flat) <= limit else flat[:limit] + "..."


def _short(text: str, limit: int = 60) -> str:
  text = _one_line(str(text), limit)
  return text if len(text) <= limit else text[:limit] + "..."


def _vec(a) -> str:
  return "(" + ", ".join(f"{float(x):g}" for x in a) + ")"


__all__ = ["DRIVES", "MAX_BODIES", "MAX_BYTES", "MAX_DEPTH", "MAX_GEOMS", "MAX_KV", "MAX_RADIUS", "MAX_TIME_CONSTANT",
           "MIN_RADIUS", "RADIUS_NAME", "ROBOT_XML", "RobotModel", "RobotModelError", "load_builtin_model",
           "load_robot", "planar_ctrl", "robot_from_xml"]
