"""Collisions as the atlas's domain (pipeline.validity.CollisionFreeDomain): no chart is
centred in collision, charts reaching an obstacle are cut there, and a path threads the gap
between two obstacles. Distances checked without coal (a sphere against a cable: the
point-segment distance less both radii)."""

import dataclasses

import numpy as np
import pytest

from cdh_planner.model.pose import rotation_tt
from cdh_planner.parsing.problem import load_problem
from cdh_planner.planner import Planner
from cdh_planner.scene.schema import scene_from_dict

from conftest import PROBLEMS
from test_scene_distances import point_segment
from test_scene_plans import poses_along

PROBLEM = load_problem(PROBLEMS / "robot2_q2_q3_ball.yaml")
ROBOT = PROBLEM.robot
BALL = PROBLEM.scene.obstacles[0]
R_CABLE = PROBLEM.scene.cable_radius


def sphere_distances(centre, radius, p, R):
    """Least distance (m) of each pose's cables (capsules of R_CABLE) to a sphere; the
    cable and the closest point on its axis."""
    out = []
    for pk, Rk in zip(p, R):
        B = pk + ROBOT.platform_anchors @ Rk.T
        d = [point_segment(centre, a, b) for a, b in zip(ROBOT.base_anchors, B)]
        out.append(min(d) - radius - R_CABLE)
    return np.array(out)


def planned(scene):
    s = dataclasses.replace(PROBLEM.settings, timeout_s=60.0)
    planner = Planner(ROBOT, PROBLEM.task, s, scene=scene)
    return planner, planner.plan(PROBLEM.start, PROBLEM.goal)


def test_no_chart_is_centred_in_collision_and_charts_are_cut_at_the_obstacle():
    planner, result = planned(PROBLEM.scene)
    assert result.success, result.message
    poses = [planner.constraint.pose(ch.x) for ch in planner.atlas.charts]
    p = np.array([a for a, _ in poses])
    R = rotation_tt(np.array([b for _, b in poses]))
    d = sphere_distances(BALL.position, BALL.radius, p, R)
    assert d.min() >= planner.settings.margin_floor * 0.1 - 1e-9  # the floor, in metres
    assert planner.validity.clear_of_collision(p, R).all()
    # some chart was cut at the domain's boundary (the ball's, or the box's)
    assert any(ch.frontier for ch in planner.atlas.charts)


def test_the_domain_cut_is_the_collision_margin_to_the_exact_distance():
    """The domain's predicate is the exact clearance: a pose just outside the ball by
    1e-6 m more than the floor is inside, one 1e-6 m less is not."""
    planner, _ = planned(PROBLEM.scene)
    domain = planner.atlas.c
    floor_m = planner.settings.margin_floor * 0.1
    x0 = planner.constraint.lift(PROBLEM.start.p, PROBLEM.start.tau)
    p, tau = planner.constraint.pose(x0)
    R = rotation_tt(tau[None])[0]
    d = sphere_distances(BALL.position, BALL.radius, p[None], R[None])[0]
    # move the ball along its line to the nearest cable so that the gap is floor -/+ 1e-6
    B = p + ROBOT.platform_anchors @ R.T
    i = int(np.argmin([point_segment(BALL.position, a, b) for a, b in zip(ROBOT.base_anchors, B)]))
    a, b = ROBOT.base_anchors[i], B[i]
    t = np.clip(np.dot(BALL.position - a, b - a) / np.dot(b - a, b - a), 0, 1)
    foot = a + t * (b - a)
    u = (np.asarray(BALL.position) - foot) / np.linalg.norm(np.asarray(BALL.position) - foot)
    assert d > floor_m
    for extra, inside in ((1e-6, True), (-1e-6, False)):
        centre = foot + u * (BALL.radius + R_CABLE + floor_m + extra)
        scene = scene_from_dict({"cable_radius": R_CABLE, "obstacles": [
            {"id": "ball", "type": "sphere", "radius": BALL.radius, "position": centre.tolist()}]})
        planner_k = Planner(ROBOT, PROBLEM.task, planner.settings, scene=scene)
        gap = sphere_distances(centre, BALL.radius, p[None], R[None])[0]
        if abs(gap - floor_m - extra) > 1e-9:  # another cable is nearer: not this test's case
            pytest.skip("another cable is nearer the moved ball")
        assert planner_k.atlas.c.inside(x0) == inside
    assert domain.inside(x0)


def test_a_path_threads_the_gap_between_two_obstacles():
    """The ball of robot2_ball.yaml and a second ball on the other side of the cable that
    passes the first one closest on the one-ball path, 6 mm of room between them."""
    _, result = planned(PROBLEM.scene)
    assert result.success
    p, R = result.path.p, rotation_tt(result.path.tau)
    k = int(np.argmin(sphere_distances(BALL.position, BALL.radius, p, R)))
    B = p[k] + ROBOT.platform_anchors @ R[k].T
    c = np.asarray(BALL.position)
    i = int(np.argmin([point_segment(c, a, b) for a, b in zip(ROBOT.base_anchors, B)]))
    a, b = ROBOT.base_anchors[i], B[i]
    foot = a + np.clip(np.dot(c - a, b - a) / np.dot(b - a, b - a), 0, 1) * (b - a)
    u = (foot - c) / np.linalg.norm(foot - c)
    gap = 0.006  # m between the two balls' surfaces, through which the cable passes
    second = c + u * (2 * BALL.radius + gap)
    obstacles = [{"id": "ball", "type": "sphere", "radius": BALL.radius, "position": c.tolist()},
                 {"id": "ball2", "type": "sphere", "radius": BALL.radius, "position": second.tolist()}]
    planner, two = planned(scene_from_dict({"cable_radius": R_CABLE, "obstacles": obstacles}))
    assert two.success, two.message
    pp, RR = poses_along(two.path.p, two.path.quaternion)
    for o in obstacles:
        assert sphere_distances(np.array(o["position"]), BALL.radius, pp, RR).min() > 0.0
