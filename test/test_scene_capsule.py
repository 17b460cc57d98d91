"""The capsule shape (model.shapes.Capsule) and the shape registry: a capsule's file keys
and their errors, its bounding radius, its distances (as an obstacle: the compiled
kernel's, exact, against the closed form segment-segment less both radii; as the platform's shape: the compiled
kernel's segment-segment, against coal) at random poses, over ROS (Obstacle.CAPSULE, both
ways) and as markers (a cylinder with two sphere caps); the robot's platform choices read
from the registry; docs/scenes.md lists every registered shape."""

import math
import re

import coal
import numpy as np
import pytest

from cdh_planner.errors import InputError
from cdh_planner.model.robot import PLATFORM_SHAPES
from cdh_planner.model.shapes import SHAPES
from cdh_planner.scene.schema import scene_from_dict, shape_from_dict

from conftest import CONFIG
from test_scene_distances import (R_CABLE, ROBOT2, lower_bounds, model, near_cable_point,
                                  platform_anchors, random_pose, random_quaternion,
                                  segment_segment)

DOCS = CONFIG.parent / "docs" / "scenes.md"
TOL_M = 1e-6


def capsule_axis(shape):
    """The capsule's segment ends (base frame) of a Shape."""
    h = 0.5 * shape.length * shape.rotation[:, 2]
    return shape.position - h, shape.position + h


# ----------------------------------------------------------------- the file

def test_a_capsule_is_read_with_its_radius_and_length_and_bounded_by_half_length_plus_radius():
    s = shape_from_dict({"type": "capsule", "radius": 0.01, "length": 0.2,
                         "position": [0.1, 0, 0.3]}, "scene.obstacles[0]", "rod")
    assert (s.kind, s.radius, s.length) == ("capsule", 0.01, 0.2)
    assert s.bounding_radius() == pytest.approx(0.11, abs=1e-15)


@pytest.mark.parametrize("fields, where, value", [
    ({"radius": 0.01}, "length", "None"),
    ({"length": 0.2}, "radius", "None"),
    ({"radius": -0.01, "length": 0.2}, "radius", "-0.01"),
    ({"radius": 0.01, "length": 0.0}, "length", "0.0"),
    ({"radius": 0.01, "length": "long"}, "length", "long"),
    ({"radius": 0.01, "length": 0.2, "height": 0.2}, "height", ""),
])
def test_capsule_file_errors_name_the_field_and_value(fields, where, value):
    with pytest.raises(InputError) as e:
        shape_from_dict({"type": "capsule", **fields}, "scene.obstacles[0]", "rod")
    msg = str(e.value)
    assert "\n" not in msg and f"scene.obstacles[0].{where}" in msg and value in msg


def test_an_unknown_type_lists_the_registered_ones():
    with pytest.raises(InputError, match="expected one of sphere, box, cylinder, mesh, capsule"):
        shape_from_dict({"type": "cone"}, "scene.obstacles[0]", "c")


def test_the_robots_platform_shapes_are_the_registrys_platform_classes():
    assert PLATFORM_SHAPES == ("none", "box", "cylinder", "sphere")
    assert {t for t, c in SHAPES.items() if c.platform_extents} == set(PLATFORM_SHAPES[1:])


def test_docs_list_every_registered_shape_with_its_keys():
    rows = {m.group(1): m.group(2) for m in
            re.finditer(r"^\| (\w+) \| ([^|]*) \|", DOCS.read_text(), re.M)}
    for t, c in SHAPES.items():
        assert rows.get(t) == ", ".join(c.required) + ("; " + ", ".join(c.optional)
                                                       if c.optional else ""), t


# ----------------------------------------------------------------- distances

def test_cables_against_a_capsule_obstacle_match_segment_segment_less_both_radii():
    rng = np.random.default_rng(30)
    hits = 0
    for _ in range(12):
        p, R = random_pose(rng)
        obstacle = {"id": "rod", "type": "capsule", "radius": float(rng.uniform(0.003, 0.02)),
                    "length": float(rng.uniform(0.01, 0.2)), "quaternion": random_quaternion(rng),
                    "position": near_cable_point(rng, ROBOT2, p, R, 0.03)}
        cm = model([obstacle])
        s = cm.obstacles[0]
        q0, q1 = capsule_axis(s)
        Bw = platform_anchors(ROBOT2, p, R)
        lb = lower_bounds(cm, p, R)
        assert np.all(lb[:-1, 0] == math.inf)  # exact in the kernel: nothing left for coal
        for kind, _, cables, d in cm.distances(p, R):
            if kind != "cable-obstacle":
                continue
            i = cables[0]
            exact = segment_segment(ROBOT2.base_anchors[i], Bw[i], q0, q1) - R_CABLE - s.radius
            assert d == pytest.approx(exact, abs=1e-9)  # in contact too: the axes' distance
            hits += exact < 0.0
        assert cm.clearance(p, R).distance == pytest.approx(
            min(d for *_, d in cm.distances(p, R)), abs=1e-12)
    assert hits  # some poses touch the capsule


def test_cables_against_a_capsule_platform_match_coal_at_random_poses():
    """The kernel's exact cable-platform distance of a capsule platform (segment against
    segment) against coal's capsule-capsule distance, the cable cut by the exemption."""
    rng = np.random.default_rng(31)
    for _ in range(10):
        length, radius = float(rng.uniform(0.02, 0.2)), float(rng.uniform(0.01, 0.06))
        platform = {"type": "capsule", "radius": radius, "length": length,
                    "position": rng.uniform(-0.02, 0.02, 3).tolist(),
                    "quaternion": random_quaternion(rng)}
        cm = model([], platform=platform)
        assert cm.static[-13] == 4.0  # CAPSULE_FORM: exact in the kernel, no coal call
        geometry = coal.Capsule(radius, length)
        for _ in range(5):
            p, R = random_pose(rng)
            got = {c[0]: d for k, _, c, d in cm.distances(p, R) if k == "cable-platform"}
            assert not (cm.lb[:6, -1] < np.inf).any()
            s = cm.platform
            Bw = platform_anchors(ROBOT2, p, R)
            for i, d in got.items():
                a, b = ROBOT2.base_anchors[i], Bw[i]
                u = (b - a) / np.linalg.norm(b - a)
                cut = b - u * cm.scene.shared_anchor_exemption
                half = 0.5 * np.linalg.norm(cut - a)
                cable = coal.Capsule(R_CABLE, 2.0 * half)
                T_cable = coal.Transform3s(_z_to(u), 0.5 * (a + cut))
                T_plat = coal.Transform3s(R @ s.rotation, p + R @ s.position)
                req, res = coal.DistanceRequest(), coal.DistanceResult()
                req.gjk_tolerance = 1e-9
                want = coal.distance(cable, T_cable, geometry, T_plat, req, res)
                if want >= 0.0:
                    assert d == pytest.approx(want, abs=TOL_M)


def test_a_capsule_platform_against_spheres_matches_the_closed_form():
    rng = np.random.default_rng(32)
    spheres = [{"id": f"s{k}", "type": "sphere", "radius": 0.01,
                "position": (np.array([0, 0, 0.4]) + rng.uniform(-0.12, 0.12, 3)).tolist()}
               for k in range(8)]
    cm = model(spheres, platform={"type": "capsule", "radius": 0.02, "length": 0.1,
                                  "quaternion": random_quaternion(rng)})
    for _ in range(5):
        p, R = random_pose(rng)
        s = cm.platform
        axis = 0.5 * s.length * (R @ s.rotation[:, 2])
        centre = p + R @ s.position
        for kind, oid, _, d in cm.distances(p, R):
            if kind == "platform-obstacle":
                c = np.asarray(cm.scene.obstacle(oid).position)
                exact = segment_segment(centre - axis, centre + axis, c, c) - 0.03
                if exact >= 0.0:
                    assert d == pytest.approx(exact, abs=TOL_M)


def test_batch_margins_with_a_capsule_platform_and_obstacle_equal_the_clearance():
    rng = np.random.default_rng(33)
    p0, R0 = random_pose(rng)
    obstacles = [{"id": "rod", "type": "capsule", "radius": 0.008, "length": 0.05,
                  "quaternion": random_quaternion(rng),
                  "position": near_cable_point(rng, ROBOT2, p0, R0, 0.03)}]
    cm = model(obstacles, platform={"type": "capsule", "radius": 0.03, "length": 0.08},
               clearance=0.0001)
    p = p0 + rng.uniform(-0.05, 0.05, (40, 3))
    R = np.repeat(R0[None], 40, axis=0)
    margins, _ = cm.margins(p, R)
    for n in range(40):
        assert margins[n] == cm.clearance(p[n], R[n]).margin


# ----------------------------------------------------------------- ROS and markers

def test_a_capsule_goes_over_ros_as_obstacle_capsule_and_back():
    from cdh_planner.ros.msgs.scene_msgs import obstacle_msg, shape_of_obstacle
    from cdh_planner_interfaces.msg import Obstacle

    s = shape_from_dict({"type": "capsule", "radius": 0.01, "length": 0.2,
                         "position": [0.1, 0, 0.3], "quaternion": [0, 0, 0.6, 0.8]}, "x", "rod")
    msg = obstacle_msg(s)
    assert msg.primitive.type == Obstacle.CAPSULE == 100
    assert list(msg.primitive.dimensions) == [0.2, 0.01]
    back = shape_of_obstacle(msg, "obstacles[0]")
    assert back.same_geometry(s)
    msg.primitive.dimensions = [0.2]
    with pytest.raises(InputError, match=r"obstacles\[0\]\.primitive\.dimensions = \[0\.2\]: "
                                         "a capsule has 2"):
        shape_of_obstacle(msg, "obstacles[0]")
    msg.primitive.dimensions = [0.2, -0.01]
    with pytest.raises(InputError, match=r"obstacles\[0\]\.primitive\.radius = -0\.01"):
        shape_of_obstacle(msg, "obstacles[0]")
    msg.primitive.type = 7
    with pytest.raises(InputError, match=r"expected SPHERE \(2\), BOX \(1\), CYLINDER \(3\) or "
                                         r"CAPSULE \(100\)"):
        shape_of_obstacle(msg, "obstacles[0]")


def test_a_capsule_is_drawn_as_a_cylinder_with_two_sphere_caps():
    from visualization_msgs.msg import Marker

    from cdh_planner.ros.msgs.markers import obstacle_markers

    q = [0.0, 0.7071067811865476, 0.0, 0.7071067811865476]  # z turned onto x
    scene = scene_from_dict({"obstacles": [
        {"id": "ball", "type": "sphere", "radius": 0.02},
        {"id": "rod", "type": "capsule", "radius": 0.01, "length": 0.2,
         "position": [0.1, 0.0, 0.3], "quaternion": q}]})
    ms = obstacle_markers(scene, "cdh_base", None)
    assert [(m.ns, m.id, m.type) for m in ms] == [
        ("obstacles", 0, Marker.SPHERE), ("obstacles", 1, Marker.CYLINDER),
        ("obstacles/1", 1, Marker.SPHERE), ("obstacles/2", 1, Marker.SPHERE)]
    body, cap1, cap2 = ms[1:]
    assert (body.scale.x, body.scale.y, body.scale.z) == pytest.approx((0.02, 0.02, 0.2))
    assert (cap1.scale.x, cap1.scale.y, cap1.scale.z) == pytest.approx((0.02, 0.02, 0.02))
    ends = sorted([(c.pose.position.x, c.pose.position.y, c.pose.position.z) for c in (cap1, cap2)])
    assert np.allclose(ends, [(0.0, 0.0, 0.3), (0.2, 0.0, 0.3)], atol=1e-12)
    assert all(m.pose.orientation.y == q[1] and m.pose.orientation.w == q[3] for m in ms[1:])


def _z_to(u):
    """A rotation taking z to the unit vector u."""
    z = np.array([0.0, 0.0, 1.0])
    v, c = np.cross(z, u), float(np.dot(z, u))
    if c < -1.0 + 1e-12:
        return np.diag([1.0, -1.0, -1.0])
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + K @ K / (1.0 + c)
