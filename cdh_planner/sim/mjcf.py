"""The robot of a robot file as MJCF (MuJoCo's XML): what ``cdh-planner mjcf`` prints and the
plant (``sim.plant``) loads. Every value comes from the robot file (and a scene file).

- The world is the robot's base frame (the paper's is z down): base anchors A_i are world
  sites, gravity is the load force over the load mass (m/s^2, in the base frame).
- The platform is a free body (``platform``, free joint ``platform``) with the load's mass
  (kg) and inertia (kg m^2, about its centre of mass) at ``load.point`` (platform frame);
  platform anchors B_i are its sites; its shape (``robot.platform_shape``, or the scene's
  platform) is a geom that collides with the obstacles (none: a thin disc through the
  anchors, drawn only).
- Cable i is a spatial tendon (its winch's name) from B_i to A_i, driven by a ``general``
  actuator (the winch's name too) with gear -1, gain -k, affine bias (0, -k, -kv):
  its force is k (L - ctrl) + kv L' with L the tendon length, clamped to [0, FORCE_CAP]: the
  actuator force is the cable's tension and a cable only pulls. k = EA / L0 (N/m) is the
  axial stiffness of a cable of unstretched length L0 (``model.elastic``), kv =
  DAMPING_TIME_S k (N s/m); the plant sets both for the commanded L0 at every step and
  ctrl = L0 + DAMPING_TIME_S L0' so that the damping acts on the stretch rate. In the file
  k is that of the keyframe ``home`` (``home_pose``).
- Obstacles of the scene are static geoms (sphere, box, cylinder, capsule, mesh: its convex
  hull).
- Camera ``workspace`` looks at the base anchors' centre from the side, the picture's up
  against gravity (the base frame may be z down).

A robot file without ``cable_stiffness`` (rigid cables) gets DEFAULT_STRETCH: EA =
tension_max / DEFAULT_STRETCH, a cable stretching 0.1 % at its greatest tension: stiff for a
rigid-cable plan (its sag is 0.1 % of a cable length at most), soft enough for 1 kHz steps
(the plant substeps where the stiffness needs it, ``plant.substeps``). A robot file without
``load.mass`` gets the load's weight as mass, |force| / GRAVITY; without ``load.inertia``,
or with a zero one, that of a uniform disc through the platform anchors (MuJoCo's free bodies
need a positive inertia). A load moment or ellipsoid offset is not gravity: the plant applies
it as an external wrench (``plant``); the file notes it in a comment.
"""

import math
import xml.etree.ElementTree as ET

import numpy as np

from ..errors import InputError
from ..model.robot import GRAVITY

TIMESTEP_S = 1e-3          # s: the plant's control period (1 kHz)
DAMPING_TIME_S = 0.02      # s: cable damping kv = DAMPING_TIME_S x k (on the stretch rate)
DEFAULT_STRETCH = 1e-3     # rigid cables: EA = tension_max / DEFAULT_STRETCH
FORCE_CAP_N = 1e10         # N: the actuators' upper force range ("unlimited": a cable
                           # overloads in the plant, it is not clipped at its limit)
MIN_INERTIA_FRACTION = 1e-9   # an inertia below this x m r^2 counts as none


def cable_stiffness(robot):
    """EA (m,) N of each cable: ``robot.cable_stiffness``, or DEFAULT_STRETCH's."""
    if robot.cable_stiffness is not None:
        return np.broadcast_to(np.asarray(robot.cable_stiffness, float), (len(robot.base_anchors),)).copy()
    return np.asarray(robot.tension_max, dtype=float) / DEFAULT_STRETCH


def load_mass(robot):
    """The load's mass (kg): ``load.mass``, or its weight |force| / GRAVITY."""
    if robot.mass is not None:
        return float(robot.mass)
    weight = float(np.linalg.norm(robot.force))
    if weight <= 0.0:
        raise InputError("load.mass", None, "the plant needs a mass: give load.mass, or a "
                                            "load.force that is the load's weight")
    return weight / GRAVITY


def gravity(robot):
    """Gravity (3,) m/s^2 in the base frame: the load force over the load mass."""
    return np.asarray(robot.force, dtype=float) / load_mass(robot)


def platform_radius(robot):
    """The platform anchors' largest distance (m) from their centre (at least 1 cm)."""
    B = np.asarray(robot.platform_anchors, dtype=float)
    return max(float(np.max(np.linalg.norm(B - B.mean(axis=0), axis=1))), 0.01)


def load_inertia(robot):
    """The load's inertia (3, 3) kg m^2 about its centre of mass, platform frame: the robot
    file's, or a uniform disc's (axis z, radius ``platform_radius``) where it gives none."""
    m, r = load_mass(robot), platform_radius(robot)
    if robot.inertia is not None:
        I = np.asarray(robot.inertia, dtype=float).reshape(3, 3)
        if np.min(np.linalg.eigvalsh(I)) > MIN_INERTIA_FRACTION * m * r * r:
            return I
    return np.diag([m * r * r / 4, m * r * r / 4, m * r * r / 2])


def home_pose(robot):
    """The keyframe pose (p (3,) m, quaternion (x, y, z, w)): no rotation, the platform below
    the base anchors' centre along gravity, the mean cable length mid-range."""
    A = np.asarray(robot.base_anchors, dtype=float)
    B = np.asarray(robot.platform_anchors, dtype=float)
    down = gravity(robot) / max(np.linalg.norm(gravity(robot)), 1e-300)
    centre = A.mean(axis=0)
    spread = float(np.mean(np.linalg.norm((A - centre) - (B - B.mean(axis=0)), axis=1)))
    length = 0.5 * float(np.mean(robot.length_min) + np.mean(robot.length_max))
    drop = math.sqrt(max(length * length - spread * spread, 0.0)) or length
    return centre + drop * down - B.mean(axis=0), np.array([0.0, 0.0, 0.0, 1.0])


def _num(v):
    return " ".join(f"{float(x):.12g}" for x in np.ravel(v))


def _wxyz(q):
    q = np.asarray(q, dtype=float)
    return _num([q[3], q[0], q[1], q[2]])


def _shape_geom(parent, shape, name, assets, **attrs):
    """A geom of a scene Shape placed by its pose (its class's MuJoCo type and size; a mesh
    its hull's vertices as an asset)."""
    geom = ET.SubElement(parent, "geom", name=name, pos=_num(shape.position),
                         quat=_wxyz(shape.quaternion), **attrs)
    kind, size = shape.type.mjcf(shape)
    geom.set("type", kind)
    if kind != "mesh":
        geom.set("size", _num(size))
    else:
        ET.SubElement(assets, "mesh", name=f"{name}_mesh", vertex=_num(shape.vertices))
        geom.set("mesh", f"{name}_mesh")
    return geom


def _camera(robot):
    """pos (3,) and xyaxes (6,) of a camera that sees every base anchor, upright."""
    A = np.asarray(robot.base_anchors, dtype=float)
    p, _ = home_pose(robot)
    points = np.vstack([A, p + np.asarray(robot.platform_anchors, dtype=float)])
    centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
    up = -gravity(robot) / max(np.linalg.norm(gravity(robot)), 1e-300)
    radius = max(float(np.max(np.linalg.norm(points - centre, axis=1))), platform_radius(robot))
    side = np.cross(up, [1.0, 0.0, 0.0])
    if np.linalg.norm(side) < 0.5:
        side = np.cross(up, [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    view = side - 0.35 * up                       # looking slightly down
    view /= np.linalg.norm(view)
    pos = centre - view * radius / math.tan(math.radians(22.5)) * 1.05
    z = -view                                     # a camera looks along its -z
    y = up - np.dot(up, z) * z
    y /= np.linalg.norm(y)
    x = np.cross(y, z)
    return pos, np.concatenate([x, y])


def mjcf(robot, scene=None):
    """The MJCF text (str) of ``robot`` (model.robot.Robot) and ``scene``'s obstacles and
    platform (scene.schema.Scene, or None)."""
    EA = cable_stiffness(robot)
    root = ET.Element("mujoco", model=robot.name or "cdh")
    ET.SubElement(root, "compiler", angle="radian", autolimits="true")
    ET.SubElement(root, "option", timestep=_num([TIMESTEP_S]), integrator="implicitfast",
                  gravity=_num(gravity(robot)))
    vis = ET.SubElement(root, "visual")
    ET.SubElement(vis, "global", offwidth="960", offheight="720")
    ET.SubElement(vis, "headlight", ambient="0.5 0.5 0.5", diffuse="0.6 0.6 0.6")
    scale = max(float(np.max(np.abs(robot.base_anchors))), 0.05)
    ET.SubElement(vis, "map", znear="0.01", zfar="50")
    ET.SubElement(vis, "scale", framelength=_num([0.2]), framewidth=_num([0.02]))
    assets = ET.SubElement(root, "asset")
    ET.SubElement(assets, "texture", type="skybox", builtin="gradient", rgb1="0.95 0.95 0.97",
                  rgb2="0.75 0.78 0.82", width="64", height="64")
    world = ET.SubElement(root, "worldbody")
    up = -gravity(robot) / max(np.linalg.norm(gravity(robot)), 1e-300)
    ET.SubElement(world, "light", name="top", directional="true", dir=_num(-up),
                  pos=_num(np.mean(robot.base_anchors, axis=0) + 3 * scale * up))
    cam_pos, xyaxes = _camera(robot)
    ET.SubElement(world, "camera", name="workspace", mode="fixed", pos=_num(cam_pos),
                  xyaxes=_num(xyaxes), fovy="45")
    site = 0.01 * scale
    for name, a in zip(robot.winch_names, robot.base_anchors):
        ET.SubElement(world, "site", name=f"{name}_base", pos=_num(a), size=_num([site]),
                      rgba="0.9 0.6 0.1 1")
    for o in (scene.obstacles if scene is not None else ()):
        _shape_geom(world, o, f"obstacle_{o.id}", assets, contype="2", conaffinity="1",
                    rgba="0.8 0.2 0.2 0.6")
    _platform(world, robot, scene, assets, site)
    tendons = ET.SubElement(root, "tendon")
    width = (scene.cable_radius if scene is not None else robot.cable_radius) or 0.002 * scale
    for name in robot.winch_names:
        t = ET.SubElement(tendons, "spatial", name=name, width=_num([width]), rgba="0.1 0.3 0.9 1")
        ET.SubElement(t, "site", site=f"{name}_platform")
        ET.SubElement(t, "site", site=f"{name}_base")
    p, q = home_pose(robot)
    L = np.linalg.norm(p + np.asarray(robot.platform_anchors) - robot.base_anchors, axis=1)
    actuators = ET.SubElement(root, "actuator")
    for name, ea, length in zip(robot.winch_names, EA, L):
        k = ea / length
        ET.SubElement(actuators, "general", name=name, tendon=name, gear="-1",
                      gainprm=_num([-k]), biastype="affine",
                      biasprm=_num([0.0, -k, -DAMPING_TIME_S * k]), forcelimited="true",
                      forcerange=_num([0.0, FORCE_CAP_N]))
    custom = ET.SubElement(root, "custom")
    ET.SubElement(custom, "numeric", name="cable_stiffness_EA", data=_num(EA))
    ET.SubElement(custom, "numeric", name="damping_time_s", data=_num([DAMPING_TIME_S]))
    keys = ET.SubElement(root, "keyframe")
    ET.SubElement(keys, "key", name="home", qpos=_num(p) + " " + _wxyz(q), ctrl=_num(L))
    ET.indent(root)
    return _header(robot) + ET.tostring(root, encoding="unicode") + "\n"


def _platform(world, robot, scene, assets, site):
    p, q = home_pose(robot)
    body = ET.SubElement(world, "body", name="platform", pos=_num(p), quat=_wxyz(q))
    ET.SubElement(body, "freejoint", name="platform")
    I = load_inertia(robot)
    ET.SubElement(body, "inertial", pos=_num(robot.load_point), mass=_num([load_mass(robot)]),
                  fullinertia=_num([I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]]))
    shape = scene.platform if scene is not None else None
    if shape is None and robot.platform_shape != "none":
        from ..scene.schema import robot_platform
        shape = robot_platform(robot)
    if shape is not None:
        _shape_geom(body, shape, "platform", assets, contype="1", conaffinity="2",
                    rgba="0.25 0.25 0.25 1", mass="0")
    else:
        B = np.asarray(robot.platform_anchors, dtype=float)
        ET.SubElement(body, "geom", name="platform", type="cylinder", pos=_num(B.mean(axis=0)),
                      size=_num([platform_radius(robot), 0.5 * 0.02 * platform_radius(robot)]),
                      contype="0", conaffinity="0", mass="0", rgba="0.25 0.25 0.25 1")
    for name, b in zip(robot.winch_names, robot.platform_anchors):
        ET.SubElement(body, "site", name=f"{name}_platform", pos=_num(b), size=_num([site]),
                      rgba="0.9 0.6 0.1 1")


def _header(robot):
    notes = [f"robot {robot.name} ({robot.source or 'no file'}), written by cdh-planner mjcf",
             "world = the robot's base frame; actuator force = cable tension (N), ctrl = "
             "unstretched length (m) + damping_time_s x its rate"]
    if robot.cable_stiffness is None:
        notes.append(f"robot.cable_stiffness absent: EA = tension_max / {DEFAULT_STRETCH:g}")
    if robot.mass is None:
        notes.append("load.mass absent: the load's weight / g")
    extra = np.concatenate([robot.moment, robot.ellipsoid_offset[3:]])
    if np.any(robot.ellipsoid_offset[:3]) or np.any(extra):
        notes.append("load moment / ellipsoid offset: applied by cdh_planner.sim.plant as "
                     "an external wrench, not in this file")
    return "".join(f"<!-- {n.replace('--', '-')} -->\n" for n in notes)
