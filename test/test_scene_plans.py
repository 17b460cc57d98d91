"""Plans with obstacles in the way, each path dense-checked by computations that
do not use coal: closed-form distances of spheres (to a cable: point-segment; to the
platform's sphere shape: point-point), point-box and point-cylinder distances of the
platform's centre, and box / cylinder distances sampled along each cable; wrench
feasibility by the closed form (wrench.wrench_feasibility). Robot 2 free flight q2 -> q3
(Table 1), whose direct motion is the answer without a scene."""

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cdh_planner.wrench import wrench_feasibility
from cdh_planner.parsing.problem import load_problem
from cdh_planner.model.pose import Pose, quaternion_from_tau, tau_from_quaternion
from cdh_planner.planner import Planner
from cdh_planner.scene.collision import CollisionModel
from cdh_planner.scene.schema import scene_from_dict
from cdh_planner.status import Status
from cdh_planner.trajectory.path_check import interpolate_segment

from conftest import PROBLEMS
from test_scene_distances import box_signed, cylinder_signed, point_segment

PROBLEM = load_problem(PROBLEMS / "robot2_q2_q3_free_flight.yaml")
ROBOT = PROBLEM.robot
MID = 0.5 * (PROBLEM.start.p + PROBLEM.goal.p)  # the platform's straight path passes here
PLATFORM_R = 0.03  # the platform's shape: a ball about P (a payload)
R_CABLE = 0.001
STEP_M, STEP_RAD = 5e-4, np.deg2rad(0.1)  # the independent check's sampling of the path
AXIS_SAMPLES = 2001  # points along a cable for a box or cylinder
TILT = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_quat().tolist()


def poses_along(p, q):
    """Poses (positions, rotations) every STEP_M / STEP_RAD along waypoints p, q."""
    ps, Rs = [], []
    for k in range(len(p) - 1):
        angle = 2 * np.arccos(min(1.0, abs(float(np.dot(q[k], q[k + 1])))))
        n = int(max(np.linalg.norm(p[k + 1] - p[k]) / STEP_M, angle / STEP_RAD)) + 2
        pp, qq = interpolate_segment(p[k], q[k], p[k + 1], q[k + 1], np.linspace(0, 1, n))
        ps.append(pp)
        Rs.append(Rotation.from_quat(qq).as_matrix())
    return np.concatenate(ps), np.concatenate(Rs)


def least_distance(obstacle, p, R, platform=True):
    """The least distance (m) over the poses of the cables (capsules of R_CABLE) and the
    platform's ball to ``obstacle`` (a scene mapping), without coal; and what attains it."""
    c = np.array(obstacle["position"])
    Ro = Rotation.from_quat(obstacle.get("quaternion", [0, 0, 0, 1])).as_matrix()
    kind = obstacle["type"]
    if kind == "sphere":
        signed = (lambda x: np.linalg.norm(x - c, axis=-1) - obstacle["radius"])
    elif kind == "box":
        signed = (lambda x: box_signed(x.reshape(-1, 3), c, Ro, obstacle["size"]).reshape(x.shape[:-1]))
    else:
        signed = (lambda x: cylinder_signed(x.reshape(-1, 3), c, Ro, obstacle["radius"],
                                            obstacle["height"]).reshape(x.shape[:-1]))
    best, what = np.inf, None
    if platform:
        d = signed(p) - PLATFORM_R
        best, what = float(d.min()), "platform"
    Bw = p[:, None, :] + np.einsum("nij,kj->nki", R, ROBOT.platform_anchors)
    A = ROBOT.base_anchors
    for i in range(len(A)):
        if kind == "sphere":  # closed form
            d = np.array([point_segment(c, A[i], b) for b in Bw[:, i]]) - obstacle["radius"]
            err = 0.0
        else:  # sampled along the cable (within err above the true distance) where the
            # closed-form bound (distance to the centre less the half diagonal) is small
            rho = 0.5 * np.linalg.norm(obstacle.get("size") or [2 * obstacle.get("radius", 0),
                                                                2 * obstacle.get("radius", 0),
                                                                obstacle.get("height", 0)])
            d = np.array([point_segment(c, A[i], b) for b in Bw[:, i]]) - rho
            near = np.flatnonzero(d < 0.01)
            t = np.linspace(0.0, 1.0, AXIS_SAMPLES)[None, :, None]
            if near.size:
                d[near] = np.concatenate([
                    signed(A[i] + t * (Bw[near[a:a + 200], i, None] - A[i])).min(axis=1)
                    for a in range(0, near.size, 200)])
            err = 0.5 * float(np.max(np.linalg.norm(Bw[:, i] - A[i], axis=1))) / (AXIS_SAMPLES - 1)
        d = d - R_CABLE - err
        if d.min() < best:
            best, what = float(d.min()), ROBOT.winch_names[i]
    return best, what


def straight_poses():
    q = quaternion_from_tau(np.array([PROBLEM.start.tau, PROBLEM.goal.tau]))
    return poses_along(np.array([PROBLEM.start.p, PROBLEM.goal.p]), q)


def plan(obstacles, platform=True, **settings):
    d = {"cable_radius": R_CABLE, "obstacles": obstacles}
    if platform:
        d["platform"] = {"type": "sphere", "radius": PLATFORM_R}
    s = dataclasses.replace(PROBLEM.settings, timeout_s=60.0, **settings)
    return Planner(ROBOT, PROBLEM.task, s, scene=scene_from_dict(d)).plan(PROBLEM.start,
                                                                         PROBLEM.goal)


def check_dense(result, obstacle, platform=True):
    """The planned path, sampled densely: wrench-feasible and clear of the obstacle."""
    assert result.success, result.message
    p, R = poses_along(result.path.p, result.path.quaternion)
    assert wrench_feasibility(ROBOT, p, R=R).margin.min() > 0.0
    d, _ = least_distance(obstacle, p, R, platform)
    assert d > 0.0, d
    return d


@pytest.mark.parametrize("obstacle", [
    {"id": "ball", "type": "sphere", "radius": 0.01, "position": MID.tolist()},
    {"id": "block", "type": "box", "size": [0.02, 0.02, 0.02], "position": MID.tolist(),
     "quaternion": TILT},
    {"id": "pipe", "type": "cylinder", "radius": 0.008, "height": 0.04, "position": MID.tolist(),
     "quaternion": TILT},
], ids=["sphere", "box", "cylinder"])
def test_an_obstacle_on_the_platforms_straight_path_is_avoided(obstacle):
    hit, what = least_distance(obstacle, *straight_poses())
    assert hit < 0 and what == "platform"  # the direct motion (the plan without it) hits it
    result = plan([obstacle])
    assert not result.stats["direct"]
    d = check_dense(result, obstacle)
    assert result.stats["least_clearance_m"] >= d - 1e-3  # waypoints: at least the dense least


def test_a_small_obstacle_hit_by_one_cable_is_avoided():
    p, R = straight_poses()
    k = len(p) // 2
    a, b = ROBOT.base_anchors[2], p[k] + R[k] @ ROBOT.platform_anchors[2]
    ball = {"id": "bead", "type": "sphere", "radius": 0.003, "position": (0.5 * (a + b)).tolist()}
    hit, what = least_distance(ball, p, R, platform=False)
    assert hit < 0 and what == "winch_3"
    # only that cable: every other one stays clear of the bead along the straight path
    Bw = p[:, None] + np.einsum("nij,kj->nki", R, ROBOT.platform_anchors)
    others = [min(point_segment(np.array(ball["position"]), ROBOT.base_anchors[i], B[i])
                  for B in Bw) for i in range(6) if i != 2]
    assert min(others) > 0.003 + R_CABLE
    result = plan([ball], platform=False)
    check_dense(result, ball, platform=False)


def test_a_start_in_collision_is_refused_naming_the_obstacle():
    a = ROBOT.base_anchors[0]
    b = PROBLEM.start.p + Rotation.from_quat(quaternion_from_tau(PROBLEM.start.tau)).as_matrix() \
        @ ROBOT.platform_anchors[0]
    ball = {"id": "snag", "type": "sphere", "radius": 0.005, "position": (0.5 * (a + b)).tolist()}
    result = plan([ball], platform=False)
    assert result.reason is Status.START_IN_COLLISION and not result.success
    assert "snag" in result.message and "winch_1" in result.message
    flipped = Planner(ROBOT, PROBLEM.task, PROBLEM.settings,
                      scene=scene_from_dict({"cable_radius": R_CABLE, "obstacles": [ball]}))
    back = flipped.plan(PROBLEM.goal, PROBLEM.start)
    assert back.reason is Status.GOAL_IN_COLLISION and "snag" in back.message


def test_cables_that_would_cross_are_never_planned_through():
    """A Robot 2 whose third base anchor is moved 3 cm from the second: between these two
    poses the direct motion (wrench-feasible: the plan without a scene) passes cable 3
    through cable 2. With the scene, no path crosses: the search ends at its chart limit
    or a path that is clear all along."""
    A = ROBOT.base_anchors.copy()
    A[2] = A[1] + [0.0, -0.03, 0.0]
    robot = dataclasses.replace(ROBOT, base_anchors=A)
    qs = [-0.22265681, 0.14771098, 0.13825059, 0.95367300]
    qg = [-0.00709487, 0.13857075, -0.10871001, 0.98434239]
    start = Pose(np.array([-0.0474279, 0.0677013, 0.2308872]), tau_from_quaternion(np.array(qs)))
    goal = Pose(np.array([0.0015239, 0.0716442, 0.1825931]), tau_from_quaternion(np.array(qg)))
    free = Planner(robot, PROBLEM.task, PROBLEM.settings).plan(start, goal)
    assert free.success and free.stats["direct"]
    scene = scene_from_dict({"cable_radius": R_CABLE})
    cm = CollisionModel(robot, scene)
    p, R = poses_along(free.path.p, free.path.quaternion)
    crossing = min((cm.clearance(a, b) for a, b in zip(p, R)), key=lambda c: c.distance)
    assert crossing.distance < 0 and crossing.binding == "winch_2 / winch_3"
    s = dataclasses.replace(PROBLEM.settings, max_charts=60)
    result = Planner(robot, PROBLEM.task, s, scene=scene).plan(start, goal)
    if result.success:
        p, R = poses_along(result.path.p, result.path.quaternion)
        assert min(cm.clearance(a, b).distance for a, b in zip(p, R)) > 0
    else:
        assert result.reason in (Status.CHART_LIMIT, Status.NO_PATH)
