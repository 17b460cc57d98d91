"""One pose, one plan: a start or goal written as task coordinates, as a
pose (a quaternion), or as that pose with the noise forward kinematics of measured cable
lengths leaves (1e-7 rad, 2e-7 m) plans the same path, to 1 % in length, on every task,
including at the singular set of tilt-and-torsion (theta = 0 or pi: the sphere task's
poles, Robot 1's q'_s and q''_s), where the rotation does not determine phi.

The maths first (model/pose.tau_from_rotation, model/task.end_taus), then plans."""
import dataclasses
from datetime import timedelta

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from cdh_planner.parsing.problem import load_problem
from cdh_planner.model.kinematics import cable_lengths, forward_kinematics, rotation_vector_exp
from cdh_planner.model.pose import (Pose, on_singular_set, quaternion_from_tau, rotation_angle_between,
                                    rotation_tt, tau_from_quaternion, tau_from_rotation, wrap_angle)
from cdh_planner.model.task import FreeTask, PivotTask, SliceTask, SphereTask, end_taus
from cdh_planner.planner import TASK_TOL, Planner, PlannerSettings

from conftest import PROBLEMS

NOISE_RAD, NOISE_M = 1e-7, 2e-7   # what forward kinematics of measured lengths leaves
SEEDS = (0, 1, 2)
SIGMA1 = 0.593411945678072        # Robot 1's slice: sigma = 34 deg
TASKS = [FreeTask(), SphereTask(center=(0.0, 0.0, 0.306), radius=0.13),
         SphereTask(center=(0.0, 0.0, 0.306), radius=0.13, free_torsion=True),
         SliceTask(fixed={"x": 0.0, "y": 0.0, "z": 0.35, "sigma": SIGMA1}),
         SliceTask(fixed={"x": 0.0, "y": 0.0, "z": 0.35, "phi": 1.7}),
         PivotTask(tool=(0.0, 0.0, 0.1), center=(0.0, 0.0, 0.35))]
PROPERTY = settings(max_examples=60, deadline=timedelta(seconds=5), derandomize=True, database=None)


def angle_gap(a, b):
    return np.abs(wrap_angle(np.asarray(a) - np.asarray(b)))


def noisy(pose, seed, rad=NOISE_RAD, m=NOISE_M):
    """The pose turned by ``rad`` about a random axis and moved by ``m`` in a random
    direction, read back as a quaternion (phi wherever the noise puts it)."""
    rng = np.random.default_rng(seed)
    w, d = rng.normal(size=3), rng.normal(size=3)
    R = rotation_vector_exp(w * rad / np.linalg.norm(w)) @ rotation_tt(pose.tau)
    tau = tau_from_quaternion(Rotation.from_matrix(R).as_quat())
    return Pose(pose.p + d * m / np.linalg.norm(d), tau)


def as_quaternion(pose):
    """The same pose written as a quaternion (phi = 0 where theta = 0)."""
    return Pose(pose.p, tau_from_quaternion(quaternion_from_tau(pose.tau)))


def measured(robot, pose):
    """Forward kinematics of the pose's cable lengths rounded to 0.1 um (an encoder)."""
    R = rotation_tt(pose.tau)
    fk = forward_kinematics(robot, np.round(cable_lengths(robot, pose.p, R), 7), pose.p + 1e-4, R)
    assert fk.ok
    return Pose(fk.p, tau_from_quaternion(Rotation.from_matrix(fk.R).as_quat()))


def writings(robot, pose):
    """(label, pose): the pose as given, as a quaternion, with noise, from measured lengths."""
    return ([("given", pose), ("quaternion", as_quaternion(pose)), ("measured", measured(robot, pose))]
            + [(f"noise {s}", noisy(pose, s)) for s in SEEDS])


def assert_one_plan(results):
    """Every plan succeeded, and costs and platform path lengths agree to 1 %."""
    for label, res in results:
        assert res.success, (label, res.message)
    cost = np.array([res.cost for _, res in results])
    length = np.array([res.path.length_m() for _, res in results])
    assert cost.max() <= 1.01 * cost.min(), list(zip([lb for lb, _ in results], cost))
    assert length.max() <= 1.01 * length.min() + 1e-9, list(zip([lb for lb, _ in results], length))


# ----- the maths ------------------------------------------------------------------------------
angles = st.floats(-np.pi, np.pi)
tilts = st.floats(0.0, 0.999)   # of tol (at tol itself rounding decides)


@PROPERTY
@given(phi=angles, sigma=angles, hint=angles, frac=tilts, south=st.booleans(),
       tol=st.sampled_from([1e-9, 1e-6, 1e-3, 0.1]))
def test_a_rotation_within_tol_of_the_singular_set_is_snapped_onto_it(phi, sigma, hint, frac, south, tol):
    """Within tol of theta = 0 (pi): theta becomes 0 (pi), phi the hint, and the rotation
    moves by exactly its tilt to the set (theta, or pi - theta), keeping R's rotation about
    z (sigma) at 0 and 2 phi - sigma at pi."""
    tilt = frac * tol
    theta = np.pi - tilt if south else tilt
    R = rotation_tt([phi, theta, sigma])
    out = tau_from_rotation(R, hint, tol)
    assert out[1] == (np.pi if south else 0.0) and on_singular_set(out)
    assert angle_gap(out[0], hint) < 1e-12
    assert abs(rotation_angle_between(R, rotation_tt(out)) - tilt) < 1e-9
    kept = (2 * out[0] - out[2], 2 * phi - sigma) if south else (out[2], sigma)
    assert angle_gap(*kept) < 1e-9


@PROPERTY
@given(phi=angles, sigma=angles, hint=angles, theta=st.floats(1e-5, np.pi - 1e-5))
def test_a_rotation_off_the_singular_set_keeps_its_angles(phi, sigma, hint, theta):
    out = tau_from_rotation(rotation_tt([phi, theta, sigma]), hint, 1e-6)
    assert abs(out[1] - theta) < 1e-9
    assert angle_gap(out[0], phi) < 1e-9 / np.sin(theta) + 1e-12
    assert angle_gap(out[2], sigma) < 1e-9 / np.sin(theta) + 1e-12


@PROPERTY
@given(task=st.sampled_from(TASKS), phi=angles, sigma=angles, end=st.sampled_from([0, 1]),
       theta=st.sampled_from([0.0, np.pi, 0.3, 1.2, 2.5]), other_phi=angles,
       other_theta=st.sampled_from([0.0, 0.8, np.pi - 0.4]), seed=st.integers(0, 2 ** 16))
def test_end_angles_depend_on_the_pose_only(task, phi, sigma, end, theta, other_phi, other_theta, seed):
    """end_taus with one end (the start or the goal) rewritten with another phi (on the
    singular set) and turned by 1e-7 rad of noise: the same angles for both ends, within
    the noise; each end's rotation within the tolerance of the one given."""
    exact = np.array([phi, theta, sigma])
    other = np.array([other_phi, other_theta, 0.2])
    rewritten = tau_from_rotation(rotation_tt(exact), phi + 1.0)        # the same rotation
    turned = noisy(Pose(np.zeros(3), rewritten), seed).tau

    def ends(tau):
        return end_taus(task, [tau, other] if end == 0 else [other, tau], TASK_TOL)
    a, b = ends(exact), ends(turned)
    assert np.all(angle_gap(a[:, [0, 2]], b[:, [0, 2]]) < 1e-5)
    assert np.all(np.abs(a[:, 1] - b[:, 1]) < 1e-5)
    assert rotation_angle_between(rotation_tt(a[end]), rotation_tt(exact)) < 1e-9
    assert rotation_angle_between(rotation_tt(b[end]), rotation_tt(turned)) <= TASK_TOL


@pytest.mark.parametrize("task", [t for t in TASKS if t.fixed_angle("phi") is None
                                  and t.fixed_angle("sigma") is None], ids=lambda t: t.type)
def test_a_singular_end_takes_the_other_ends_azimuth(task):
    """So the straight line in task coordinates tilts straight toward the other end (the
    sphere task's pole: the other end's meridian). Both ends singular: phi = 0."""
    out = end_taus(task, [[-2.0, 0.0, 0.4], [1.1, 0.7, 0.2]], TASK_TOL)
    np.testing.assert_allclose(out, [[1.1, 0.0, 0.4], [1.1, 0.7, 0.2]], atol=1e-12)
    out = end_taus(task, [[0.5, 0.9, 0.0], [2.0, np.pi, 0.3]], TASK_TOL)
    np.testing.assert_allclose(out[1, :2], [0.5, np.pi], atol=1e-12)
    assert angle_gap(2 * out[1, 0] - out[1, 2], 4.0 - 0.3) < 1e-12      # the same rotation
    out = end_taus(task, [[-2.0, 0.0, 0.4], [1.0, np.pi, 0.3]], TASK_TOL)
    assert out[0, 0] == 0.0 and out[1, 0] == 0.0


def test_the_tasks_own_phi_comes_first():
    """A slice that fixes phi: a theta = 0 end gets that phi (on the task, residual 0)
    whatever the quaternion's phi; one that fixes sigma, at theta = pi where the rotation
    fixes 2 phi - sigma: the one of the two phi (pi apart) that gives the fixed sigma,
    nearest the other end's."""
    fixed_phi = SliceTask(fixed={"x": 0.0, "y": 0.0, "z": 0.35, "phi": 1.7})
    start = tau_from_quaternion(quaternion_from_tau([1.7, 0.0, 0.3]))
    assert start[0] == 0.0 and fixed_phi.residual([[0, 0, 0.35]], [start])[0] > 1.0
    out = end_taus(fixed_phi, [start, [1.7, 0.5, 0.0]], TASK_TOL)
    np.testing.assert_allclose(out[0], [1.7, 0.0, 0.3], atol=1e-12)
    assert fixed_phi.residual([[0, 0, 0.35]], out[:1])[0] == 0.0

    fixed_sigma = SliceTask(fixed={"x": 0.0, "y": 0.0, "z": 0.35, "sigma": SIGMA1})
    for goal_phi in (-2.0, -0.5, 1.0, 2.9):
        south = np.array([0.4, np.pi, SIGMA1])
        written = tau_from_rotation(rotation_tt(south), 2.2)     # sigma no longer SIGMA1
        out = end_taus(fixed_sigma, [written, [goal_phi, 1.0, SIGMA1]], TASK_TOL)[0]
        assert out[1] == np.pi and angle_gap(out[2], SIGMA1) < 1e-12
        assert rotation_angle_between(rotation_tt(out), rotation_tt(south)) < 1e-12
        assert min(angle_gap(out[0], 0.4), angle_gap(out[0], 0.4 + np.pi)) < 1e-12
        assert angle_gap(out[0], goal_phi) <= np.pi / 2 + 1e-12


# ----- plans --------------------------------------------------------------------------------
def plan_all(pr, pairs, task=None, planner_settings=None):
    task = task or pr.task
    return [(label, Planner(pr.robot, task, planner_settings or pr.settings).plan(a, b))
            for label, a, b in pairs]


@pytest.mark.parametrize("end", ["start", "goal"])
def test_robot2_q1_q2_from_the_pole_plans_one_path(end):
    """q1 is the sphere task's pole. Given as task coordinates (lambda), as the exact pose,
    from measured lengths and with noise (3 seeds), as the start or as the goal: one
    path, the meridian of q2 (0.13 m x (pi/2 - 0.75) = 0.1067 m). Before: 0.107, 0.161,
    0.121, 0.162 m."""
    pr = load_problem(PROBLEMS / "robot2_q1_q2.yaml")
    pairs = [(label, q, pr.goal) if end == "start" else (label, pr.goal, q)
             for label, q in writings(pr.robot, pr.start)]
    results = plan_all(pr, pairs)
    assert_one_plan(results)
    assert results[0][1].cost == pytest.approx(0.13 * (np.pi / 2 - 0.75), rel=1e-6)


@pytest.mark.parametrize("end", ["start", "goal"])
def test_robot1_q_s_prime_and_second_on_theta_zero_plan_one_path(end):
    """q'_s = (-2.3, 0) and q''_s = (1.7, 0) are one pose (theta = 0: R = Rz(sigma)): both
    files, the quaternion, measured lengths and noise plan one path, as start or goal."""
    pr = load_problem(PROBLEMS / "robot1_qs1_qg.yaml")
    other = load_problem(PROBLEMS / "robot1_qs2_qg.yaml").start
    found = [("q's", pr.start), ("q''s", other)] + writings(pr.robot, pr.start)[1:]
    pairs = [(label, q, pr.goal) if end == "start" else (label, pr.goal, q) for label, q in found]
    results = plan_all(pr, pairs)
    assert_one_plan(results)
    assert results[0][1].stats["chart_path"] > 0      # a search, not a direct motion


@pytest.mark.parametrize("kind", ["free", "orientation"])
def test_robot1_from_theta_zero_in_free_flight_and_free_orientation(kind):
    """The 6-D free task (chart radius 0.5) and the orientation slice (position fixed,
    n = 3) from q'_s on theta = 0: searches, one path however the start is written."""
    pr = load_problem(PROBLEMS / "robot1_qs1_qg.yaml")
    task = FreeTask() if kind == "free" else SliceTask(fixed={"x": 0.0, "y": 0.0, "z": 0.35})
    s = dataclasses.replace(pr.settings, radius=0.5 if kind == "free" else pr.settings.radius)
    found = writings(pr.robot, pr.start)
    results = plan_all(pr, [(label, q, pr.goal) for label, q in found], task, s)
    assert_one_plan(results)
    assert results[0][1].stats["chart_path"] > 0


@pytest.mark.parametrize("task, coords", [
    (SphereTask(center=(0.0, 0.0, 0.306), radius=0.13, free_torsion=True), [0.55, np.pi / 2, 0.3]),
    (PivotTask(tool=(0.0, 0.0, 0.1), center=(0.0, 0.0, 0.35)), [1.0, 0.0, 0.65]),
], ids=["sphere_sigma_free", "pivot"])
def test_the_other_tasks_at_theta_zero(task, coords):
    pr = load_problem(PROBLEMS / "robot2_q1_q2.yaml")
    p, tau = task.pose([coords])
    start = Pose(p[0], tau[0])
    gp, gt = task.pose([[2.63, 0.75, 0.0] if task.type == "sphere" else [-0.27, 0.76, 0.37]])
    goal = Pose(gp[0], gt[0])
    assert_one_plan(plan_all(pr, [(label, q, goal) for label, q in writings(pr.robot, start)], task))


@pytest.mark.parametrize("name", ["robot2_q2_q3", "robot2_pivot"])
def test_searched_queries_between_regular_poses_plan_one_path(name):
    """Off the singular set, both ends measured or turned by noise: the same search (GBF),
    the same path."""
    pr = load_problem(PROBLEMS / f"{name}.yaml")
    pr.settings = dataclasses.replace(pr.settings, strategy="gbf")
    ends = [("given", pr.start, pr.goal), ("measured", measured(pr.robot, pr.start),
                                           measured(pr.robot, pr.goal)),
            ("noise", noisy(pr.start, 7), noisy(pr.goal, 8))]
    results = plan_all(pr, ends)
    assert_one_plan(results)
    assert results[0][1].stats["chart_path"] > 0


def test_a_slice_that_fixes_phi_plans_from_a_quaternion_on_theta_zero():
    """Before, the quaternion's phi (0) made the pose 1.7 rad off the slice: refused."""
    pr = load_problem(PROBLEMS / "robot1_qs2_qg.yaml")
    task = SliceTask(fixed={"x": 0.0, "y": 0.0, "z": 0.35, "phi": 1.7})
    results = plan_all(pr, [(label, q, pr.goal) for label, q in writings(pr.robot, pr.start)], task)
    assert_one_plan(results)


def test_the_snap_is_bounded_by_the_tolerance():
    """Robot 2 from 0.5 mrad off the pole: within the default tolerance (1 mrad) it plans
    from the pole itself (the meridian, moved by the 0.5 mrad); with tolerance 0.1 mrad
    from where it is."""
    pr = load_problem(PROBLEMS / "robot2_q1_q2.yaml")
    p, tau = pr.task.pose([[-1.0, np.pi / 2 - 5e-4]])
    start = Pose(p[0], tau[0])
    snapped = Planner(pr.robot, pr.task, pr.settings).plan(start, pr.goal)
    assert snapped.success and snapped.path.tau[0, 1] == 0.0
    assert rotation_angle_between(rotation_tt(snapped.path.tau[0]), rotation_tt(tau[0])) == \
        pytest.approx(5e-4, rel=1e-6)
    assert snapped.cost == pytest.approx(0.13 * (np.pi / 2 - 0.75), rel=1e-6)
    kept = Planner(pr.robot, pr.task, pr.settings).plan(start, pr.goal, tolerance=1e-4)
    assert kept.success and kept.path.tau[0, 1] == pytest.approx(5e-4, rel=1e-9)
    assert angle_gap(kept.path.tau[0, 0], -1.0 - np.pi) < 1e-9


def test_a_measured_start_through_the_nodes_messages_plans_the_pole_path():
    """use_current_start: forward kinematics of q1's lengths, measured (rounded to 0.1 um)
    or with noise, becomes a PoseStamped, then the node's request poses: the plan is the
    one from q1's task coordinates (before: 13 % longer over the node)."""
    pytest.importorskip("rclpy")
    from nav_msgs.srv import GetPlan
    from cdh_planner.ros.msgs import messages as M
    from cdh_planner.ros.core.plan_requests import request_poses
    pr = load_problem(PROBLEMS / "robot2_q1_q2.yaml")
    goal = M.pose_stamped_msg(pr.goal.p, rotation_tt(pr.goal.tau), "base")
    results = [("lambda", Planner(pr.robot, pr.task, pr.settings).plan(pr.start, pr.goal))]
    for label, pose in writings(pr.robot, pr.start)[1:]:
        request = GetPlan.Request(start=M.pose_stamped_msg(pose.p, rotation_tt(pose.tau), "base"),
                                  goal=goal)
        start, end = request_poses(request, "base")
        results.append((label, Planner(pr.robot, pr.task, pr.settings).plan(start, end)))
    assert_one_plan(results)
