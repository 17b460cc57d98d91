"""The robot description (URDF) of a robot file: what ``robot_description`` carries and
``cdh-planner urdf ROBOT.yaml`` prints. No rclpy.

Links and joints (names from the frames' parameters and the robot's winch names):

- ``<fixed_frame>`` (z up) -> ``<base_frame>`` (the paper's frame, z down): fixed joint
  turned by pi about x, the same transform the node puts on /tf_static;
- ``<base_frame>`` -> ``<winch>_base_anchor``: fixed joints at the base anchors A_i (m),
  each drawn as a 1 cm sphere;
- ``<base_frame>`` -> ``<platform_frame>``: a floating joint (the node publishes its pose on
  /tf from the measured cable lengths; robot_state_publisher publishes no floating joint);
  the platform drawn as a thin disc through its anchors, with the load's mass and inertia
  about its load point when the robot file gives them;
- ``<platform_frame>`` -> ``<winch>_platform_anchor``: fixed joints at the platform anchors
  B_i (m).

The cables are not links (their length changes): the node draws them live as markers.
"""

import math
import xml.etree.ElementTree as ET

import numpy as np

ANCHOR_RADIUS_M = 0.005
DISC_THICKNESS_M = 0.004


def _xyz(v):
    return " ".join(repr(float(x)) for x in v)


def _link(robot_el, name, visual=None, inertial=None):
    link = ET.SubElement(robot_el, "link", name=name)
    if inertial is not None:
        link.append(inertial)
    if visual is not None:
        link.append(visual)
    return link


def _joint(robot_el, name, kind, parent, child, xyz=(0, 0, 0), rpy=(0, 0, 0)):
    joint = ET.SubElement(robot_el, "joint", name=name, type=kind)
    ET.SubElement(joint, "parent", link=parent)
    ET.SubElement(joint, "child", link=child)
    ET.SubElement(joint, "origin", xyz=_xyz(xyz), rpy=_xyz(rpy))
    return joint


def _visual(shape, xyz=(0, 0, 0), color=(0.6, 0.6, 0.6, 1.0), **size):
    visual = ET.Element("visual")
    ET.SubElement(visual, "origin", xyz=_xyz(xyz), rpy="0 0 0")
    geometry = ET.SubElement(visual, "geometry")
    ET.SubElement(geometry, shape, **{k: repr(float(v)) for k, v in size.items()})
    material = ET.SubElement(visual, "material", name=f"grey{color[0]:g}")
    ET.SubElement(material, "color", rgba=_xyz(color))
    return visual


def _inertial(robot):
    """<inertial> of the load (mass kg, inertia kg m^2 about the load point), or None."""
    if robot.mass is None:
        return None
    inertial = ET.Element("inertial")
    ET.SubElement(inertial, "origin", xyz=_xyz(robot.load_point), rpy="0 0 0")
    ET.SubElement(inertial, "mass", value=repr(float(robot.mass)))
    I = np.zeros((3, 3)) if robot.inertia is None else np.asarray(robot.inertia, dtype=float)
    ET.SubElement(inertial, "inertia", **{
        k: repr(float(I[i, j])) for k, (i, j) in
        {"ixx": (0, 0), "ixy": (0, 1), "ixz": (0, 2), "iyy": (1, 1), "iyz": (1, 2),
         "izz": (2, 2)}.items()})
    return inertial


def urdf(robot, fixed_frame="world", base_frame="cdh_base", platform_frame="cdh_platform"):
    """The URDF (str, XML) of ``robot`` (model.robot.Robot)."""
    root = ET.Element("robot", name=robot.name or "cdh")
    _link(root, fixed_frame)
    _link(root, base_frame)
    _joint(root, f"{fixed_frame}_to_{base_frame}", "fixed", fixed_frame, base_frame,
           rpy=(math.pi, 0.0, 0.0))
    for name, a in zip(robot.winch_names, robot.base_anchors):
        _link(root, f"{name}_base_anchor", _visual("sphere", radius=ANCHOR_RADIUS_M))
        _joint(root, f"{name}_base_anchor_joint", "fixed", base_frame, f"{name}_base_anchor",
               xyz=a)
    B = np.asarray(robot.platform_anchors, dtype=float)
    centre = B.mean(axis=0)
    radius = max(float(np.max(np.linalg.norm(B[:, :2] - centre[:2], axis=1))), ANCHOR_RADIUS_M)
    _link(root, platform_frame, _visual("cylinder", xyz=centre, color=(0.2, 0.2, 0.2, 1.0),
                                        radius=radius, length=DISC_THICKNESS_M),
          _inertial(robot))
    _joint(root, f"{base_frame}_to_{platform_frame}", "floating", base_frame, platform_frame)
    for name, b in zip(robot.winch_names, B):
        _link(root, f"{name}_platform_anchor", _visual("sphere", radius=ANCHOR_RADIUS_M))
        _joint(root, f"{name}_platform_anchor_joint", "fixed", platform_frame,
               f"{name}_platform_anchor", xyz=b)
    ET.indent(root)
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
