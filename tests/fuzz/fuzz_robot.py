"""Fuzz target for robot MJCF files: mutated robots through `sims.fleet.robot.robot_from_xml`.

Registered in `tests.fuzz.fuzz_inputs.TARGETS` as "robot", so it runs in the same sandboxed
workers, under the same memory limit and per-input timeout:

    python -m tests.fuzz.fuzz_inputs --targets robot --count 100000

Seeds: the two example bases (examples/robots/) and a minimal omni base written here.
Mutations: the generic byte edits, plus MJCF-aware ones: a number attribute set to an odd
value (NaN, inf, 0, negative, float32 overflow and subnormals, several numbers, text), a name
changed to another of the interface's names, an element dropped, duplicated or moved, a tag
changed (velocity to position, motor, general; slide to hinge), and constructs the interface
refuses or bounds inserted (include, file= and *dir= attributes, DOCTYPE and entities,
<size>, <replicate>, deep nesting, a world geom or plane, a free joint, an extra jointed body,
ctrlrange and forcerange, tendons, equalities, inline meshes, sensors, keyframes, lights).
The only outcomes allowed: a RobotModel whose radius lies in the bounds and whose MjModel
compiles with three actuators, or `RobotModelError` with a one-line message; any other
exception (another ValueError included) is a failure.
"""

from __future__ import annotations

import random
import re
from pathlib import Path

from sims.fleet import robot as R

_ROOT = Path(__file__).resolve().parents[2]

MINIMAL = """<mujoco model="m">
  <option><flag contact="disable"/></option>
  <custom><numeric name="jaxfilters_radius" data="0.2"/></custom>
  <worldbody>
    <body name="base">
      <joint type="slide" axis="1 0 0"/><joint type="slide" axis="0 1 0"/><joint type="hinge" axis="0 0 1"/>
      <site name="base_link"/>
      <geom type="sphere" size="0.2" mass="10"/>
    </body>
  </worldbody>
  <actuator>
    <velocity name="wz" site="base_link" gear="0 0 0 0 0 1" kv="20"/>
    <velocity name="vx" site="base_link" gear="1 0 0 0 0 0" kv="1000"/>
    <velocity name="vy" site="base_link" gear="0 1 0 0 0 0" kv="1000"/>
  </actuator>
</mujoco>
"""


def seeds() -> list[bytes]:
  """The example bases and the minimal one (each loads)."""
  return [(_ROOT / "examples" / "robots" / n).read_bytes() for n in ("diff_drive.xml", "omni_base.xml")] + [
      MINIMAL.encode()]


def run(data: bytes):
  """Loads `data`; a RobotModel must meet the oracles, any refusal must be a one-line RobotModelError."""
  try:
    robot = R.robot_from_xml(data, name="robot.xml")
  except R.RobotModelError as e:
    if "\n" in str(e):
      raise RuntimeError(f"a RobotModelError over several lines: {str(e)[:300]!r}") from None
    raise
  except ValueError as e:
    raise RuntimeError(f"a ValueError that is not RobotModelError: {type(e).__name__}: {str(e)[:300]}") from None
  if not R.MIN_RADIUS <= robot.radius <= R.MAX_RADIUS or robot.drive not in R.DRIVES:
    raise RuntimeError(f"loaded out of bounds: radius {robot.radius!r}, drive {robot.drive!r}")
  m = robot.mj_model(0.01)
  if (m.nu, m.nq, m.nv) != (3, 3, 3) or not 0 <= robot.forward < 3 or not 0 <= robot.yaw < 3:
    raise RuntimeError(f"loaded a model of nu {m.nu}, nq {m.nq}, nv {m.nv}")
  return robot


_ODD = ("nan", "inf", "-inf", "0", "-1", "1e39", "1e-45", "1e-50", "-0", "", "1 2", "0.1 0.2 0.3 0.4 0.5 0.6 0.7",
        "abc", "9" * 400, "0x10", "1e308", "0.05", "2", "2.0000001", "0.049999")
_NAMES = ("base", "base_link", "v", "vx", "vy", "wz", "no_slip", "jaxfilters_radius", "x", "world", "")
_TAGS = (("velocity", "position"), ("velocity", "motor"), ("velocity", "general"), ("slide", "hinge"),
         ("hinge", "slide"), ("numeric", "text"), ("site", "geom"), ("body", "frame"))
_INSERTS = (
    '<include file="other.xml"/>', '<asset><mesh name="q" file="/etc/passwd"/></asset>',
    '<compiler meshdir="/"/>', '<size memory="100G"/>', '<asset><texture name="t" type="2d" builtin="checker" '
    'width="8" height="8"/></asset>', '<asset><mesh name="q" vertex="0 0 0 1 0 0 0 1 0 0 0 1"/></asset>',
    '<replicate count="1000000"><body/></replicate>', '<worldbody><geom type="plane" size="1 1 1"/></worldbody>',
    '<worldbody><body><freejoint/><geom size="0.1"/></body></worldbody>', '<tendon><fixed name="t"><joint joint="x" '
    'coef="1"/></fixed></tendon>', '<equality><weld body1="base"/></equality>', '<sensor><framepos objtype="site" '
    'objname="base_link"/></sensor>', '<keyframe><key qpos="1 2 3"/></keyframe>',
    '<worldbody><light dir="0 0 -1"/></worldbody>', '<extension><plugin plugin="mujoco.pid"/></extension>',
    '<custom><numeric name="jaxfilters_radius" data="0.5"/></custom>', "<!-- -- -->", "<![CDATA[x]]>",
    '<default><velocity ctrlrange="-1 1"/></default>', '<default><joint damping="1"/></default>',
    '<option integrator="RK4" timestep="1e-9"/>', '<option><flag contact="enable"/></option>',
    "<worldbody>" + "<body>" * 40 + "</body>" * 40 + "</worldbody>", '<statistic meansize="1e30"/>',
    '<visual><global offwidth="100000000" offheight="100000000"/></visual>')


def edit(data: bytes, rng: random.Random) -> bytes:
  """One MJCF-aware mutation."""
  text = data.decode("utf-8", "replace")
  op = rng.randrange(8)
  if op == 0:                                           # a number attribute set to an odd value
    spots = [m for m in re.finditer(r'(\w+)="([-+0-9.e ]+)"', text)]
    if spots:
      m = rng.choice(spots)
      text = text[:m.start(2)] + rng.choice(_ODD) + text[m.end(2):]
  elif op == 1:                                         # a name changed
    spots = list(re.finditer(r'name="([^"]*)"', text))
    if spots:
      m = rng.choice(spots)
      text = text[:m.start(1)] + rng.choice(_NAMES) + text[m.end(1):]
  elif op in (2, 3):                                    # an element dropped, duplicated or moved
    spots = list(re.finditer(r"<[a-z][^<>]*/>", text))
    if spots:
      m = rng.choice(spots)
      piece = m.group(0)
      text = text[:m.start()] + (piece * 2 if op == 2 and rng.random() < 0.5 else "") + text[m.end():]
      if op == 3:
        others = list(re.finditer(r"<[a-z][^<>]*/>", text)) or [m]
        at = rng.choice(others).end()
        text = text[:at] + piece + text[at:]
  elif op == 4:                                         # a tag changed
    old, new = rng.choice(_TAGS)
    text = text.replace(f"<{old} " if old != "hinge" and old != "slide" else f'"{old}"',
                        f"<{new} " if old != "hinge" and old != "slide" else f'"{new}"', 1)
  elif op == 5:                                         # a refused or bounded construct inserted
    piece = rng.choice(_INSERTS)
    at = text.find("<worldbody>") if rng.random() < 0.7 else text.find("</mujoco>")
    text = (text[:at] + piece + text[at:]) if at >= 0 else piece + text
  elif op == 6:                                         # an attribute added to a random element
    spots = list(re.finditer(r"<([a-z]+) ", text))
    if spots:
      m = rng.choice(spots)
      attr = rng.choice(('ctrlrange="-1 1"', 'forcerange="-5 5"', 'range="-1 1"', 'pos="0.5 0 0"',
                         'euler="0 0 1"', 'contype="1"', 'file="x.stl"', 'mass="0"', 'mass="-1"', 'kv="1e30"',
                         'damping="5"', 'stiffness="3"', 'ref="1"', 'gear="1 1 0 0 0 0"', 'refsite="base_link"'))
      text = text[:m.end()] + attr + " " + text[m.end():]
  else:                                                 # the declared radius moved about its bound
    text = re.sub(r'(name="jaxfilters_radius" data=")[^"]*"',
                  lambda m: m.group(1) + rng.choice(("0.05", "0.0499", "2", "2.01", "0.19", "0.25", "1e-40",
                                                     "0.3 0.1", "-0.2")) + '"', text, count=1)
  return text.encode("utf-8", "surrogatepass")
