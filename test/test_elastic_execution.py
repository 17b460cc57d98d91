"""Elastic cables end to end: the commanded (unstretched) lengths executed by a platform on
elastic, tension-only cables in an independent simulation (test/elastic_plant.py: an ODE of
the rigid body, scipy's solve_ivp, damping on the stretch rate), the planner's elastic
equilibrium and its Jacobian, the band of length control for m > 6, the executed check
on an under-tensioned command, forward kinematics with measured tensions, and the refusal
of length-only execution of m > 6 rigid cables."""

from dataclasses import replace

import numpy as np
import pytest

from conftest import PROBLEMS, REPO
from elastic_plant import Plant, envelope_at, planned_at
from cdh_planner.wrench import band_feasibility
from cdh_planner.wrench import inverse_ellipsoid_factor, load_point, screw_jacobian
from cdh_planner.model import elastic as E
from cdh_planner.model.forward_kinematics import current_pose, measured_cable_lengths
from cdh_planner.model.kinematics import cable_lengths
from cdh_planner.model.robot import load_robot
from cdh_planner.ports.rotation import Rotation
from cdh_planner.parsing.problem import load_problem
from cdh_planner.planner import Planner
from cdh_planner.trajectory import executed as X
from cdh_planner.trajectory.path import command_tensions

TENSION_TOL = 0.01     # of the tension range: tensions against limits and envelope
POSE_TOL_M = 1e-3      # m, plus 0.05 % of the longest cable
POSE_TOL_RAD = 5e-3


@pytest.fixture(scope="module", params=["robot2_q2_q3", "robot2_8_q2_q3"])
def plan(request):
    problem = load_problem(PROBLEMS / f"{request.param}.yaml")
    result = Planner(problem.robot, problem.task, problem.settings).plan(problem.start,
                                                                         problem.goal)
    assert result.success, result.message
    return problem.robot, result.path, result


def simulate(robot, path, lengths, velocities, accelerations):
    """The plant driven by these points from rest to rest: per 1 ms sample the tensions'
    excess over the limits and over the published envelope (fractions of the tension
    range), and at the waypoints the position (m) and rotation (rad) error."""
    plant = Plant(robot, robot.cable_stiffness, path.t, lengths, velocities, accelerations)
    R0 = Rotation.from_quat(path.quaternion[:1]).as_matrix()[0]
    t, p, R, f = plant.run(path.p[0], R0)
    span = robot.tension_max - robot.tension_min
    limits = np.max(np.maximum(robot.tension_min - f, f - robot.tension_max) / span)
    moving = (t >= path.t[1]) & (t <= path.t[-2])   # at rest: the static tensions (below)
    lo, hi = envelope_at(path.t, path.tension_min, path.tension_max, t[moving])
    envelope = np.max(np.maximum(lo - f[moving], f[moving] - hi) / span)
    at = np.clip(np.round(path.t / 1e-3).astype(int), 0, len(t) - 1)
    p_plan, R_plan = planned_at(path.t, path.p, path.quaternion, t[at])
    position = np.max(np.linalg.norm(p[at] - p_plan, axis=1))
    rotation = np.max(Rotation.from_matrix(np.swapaxes(R_plan, 1, 2) @ R[at]).magnitude())
    return limits, envelope, position, rotation, f


def test_commanded_lengths_execute_the_plan_on_elastic_cables(plan):
    robot, path, _ = plan
    limits, envelope, position, rotation, f = simulate(robot, path, *path.commanded())
    assert limits <= TENSION_TOL and np.min(f) > 0, (limits, np.min(f))
    assert envelope <= TENSION_TOL, envelope
    assert position <= POSE_TOL_M + 5e-4 * np.max(robot.length_max), position
    assert rotation <= POSE_TOL_RAD, rotation


def test_geometric_lengths_do_not_execute_the_plan(plan):
    """The same test with the geometric lengths commanded fails: for m > 6 the stiffness
    shares the load (least-norm tensions, not the published rule); for six cables the
    tensions are the statics of a sagged pose, off the plan by more than the tolerance."""
    robot, path, _ = plan
    limits, envelope, position, rotation, _ = simulate(robot, path, path.lengths,
                                                       path.velocities, path.accelerations)
    if len(robot.base_anchors) == 6:
        assert rotation > POSE_TOL_RAD, rotation
    else:
        assert limits > TENSION_TOL and envelope > TENSION_TOL, (limits, envelope)


# ----------------------------------------------------------------------------- equilibrium

ROBOTS = ["robot2", "robot2_8", "cogiro"]


def _feasible_poses(robot, n, rng):
    """n wrench-feasible poses near the middle of the robot's workspace."""
    centre = np.mean(robot.base_anchors, axis=0) * np.array([1.0, 1.0, 0.0])
    centre[2] = 0.306 if robot.tension_max.max() < 100 else 0.0
    p, R = [], []
    while len(p) < n:
        q = centre + rng.normal(scale=0.02, size=3)
        Q = Rotation.from_rotvec(rng.normal(scale=0.05, size=3)).as_matrix()
        if band_feasibility(robot, q[None], R=Q[None]).margin[0] > 0:
            p.append(q), R.append(Q)
    return np.array(p), np.array(R)


def _load(robot, n):
    w = np.broadcast_to(robot.wrench_center_local, (n, 6))
    arm = w[:, :3] if robot.ellipsoid_frame == "load" else np.zeros((n, 3))
    return w[:, :3].copy(), w[:, 3:].copy(), arm.copy()


@pytest.mark.parametrize("name", ROBOTS)
def test_wrench_balance_jacobian_by_finite_differences(name):
    robot = load_robot(REPO / "config" / f"{name}.yaml")
    rng = np.random.default_rng(3)
    p, R = _feasible_poses(robot, 4, rng)
    L = np.array([cable_lengths(robot, a, b) for a, b in zip(p, R)])
    L0 = L * 0.995                                          # every cable taut
    force, moment, arm = _load(robot, len(p))
    _, jac, t = E.wrench_balance(robot, L0, p, R, force, moment, arm)
    assert np.all(t > 0)
    h = 1e-7
    for j in range(6):
        dx = np.zeros(6)
        dx[j] = h
        ends = []
        for s in (1, -1):
            Rs = Rotation.from_rotvec(np.broadcast_to(s * dx[3:], (len(p), 3))).as_matrix() @ R
            ends.append(E.wrench_balance(robot, L0, p + s * dx[:3], Rs, force, moment, arm)[0])
        np.testing.assert_allclose((ends[0] - ends[1]) / (2 * h), jac[:, :, j],
                                   atol=1e-6 * np.abs(jac).max())


@pytest.mark.parametrize("name", ROBOTS)
def test_equilibrium_of_the_commanded_lengths_is_the_planned_pose(name):
    """L0 from the nominal tensions: the equilibrium from a pose 1 mm and 10 mrad away is
    the pose itself, its tensions the nominal ones."""
    robot = load_robot(REPO / "config" / f"{name}.yaml")
    p, R = _feasible_poses(robot, 5, np.random.default_rng(4))
    f = band_feasibility(robot, p, R=R)
    L0 = E.unstretched_lengths(robot, f.lengths, f.tension_nominal)
    rng = np.random.default_rng(5)
    start_R = Rotation.from_rotvec(rng.normal(scale=0.01, size=(len(p), 3))).as_matrix() @ R
    eq = E.equilibrium_poses(robot, L0, p + rng.normal(scale=1e-3, size=p.shape), start_R,
                             *_load(robot, len(p)))
    assert np.all(eq.ok)
    np.testing.assert_allclose(eq.p, p, atol=1e-9)
    np.testing.assert_allclose(eq.R, R, atol=1e-9)
    np.testing.assert_allclose(eq.tensions, f.tension_nominal, atol=1e-7 * robot.tension_max.max())


def test_length_control_shares_a_wrench_change_by_stiffness():
    """Eight cables held at their lengths: a small change dw of the load moves the tensions
    by P_K dw, P_K = K A^T (A K A^T)^-1 (the band ``wrench.stiffness_band`` publishes),
    not by the rule's P; the band is |rows of P_K L|."""
    from cdh_planner.wrench import rule_tensions, stiffness_band
    robot = load_robot(REPO / "config" / "robot2_8.yaml")
    p, R = _feasible_poses(robot, 3, np.random.default_rng(6))
    f = band_feasibility(robot, p, R=R)
    L0 = E.unstretched_lengths(robot, f.lengths, f.tension_nominal)
    force, moment, arm = _load(robot, len(p))
    dw = 1e-4 * np.array([1.0, -0.5, 0.7, 0.0, 0.0, 0.0])
    eq = E.equilibrium_poses(robot, L0, p, R, force + dw[:3], moment, arm + dw[:3] *
                             (robot.ellipsoid_frame == "load"))
    J = screw_jacobian(robot, f.unit_vectors)
    K = (robot.cable_stiffness + f.tension_nominal) / f.lengths
    JK = J * K[:, None]
    P_K = np.swapaxes(np.linalg.solve(JK @ np.swapaxes(J, 1, 2), JK), 1, 2)
    c = load_point(robot, p, R)
    moves = robot.ellipsoid_frame == "load"          # the load's moment moves with c
    dw_o = np.concatenate([dw[:3] + 0 * c, np.cross(c, dw[:3]) * moves], axis=1)
    measured = (eq.tensions - f.tension_nominal) / 1e-4
    np.testing.assert_allclose(measured, np.einsum("nij,nj->ni", P_K, dw_o) / 1e-4, rtol=2e-2,
                               atol=2e-2 * np.abs(measured).max())
    np.testing.assert_allclose(np.einsum("nij,njk->nik", J, P_K),
                               np.broadcast_to(np.eye(6), (3, 6, 6)), atol=1e-9)
    v = np.linalg.norm(P_K @ inverse_ellipsoid_factor(robot, c), axis=-1)
    np.testing.assert_allclose(rule_tensions(robot, p, R)[1], v, rtol=1e-9)
    np.testing.assert_allclose(f.tension_spread, v, rtol=1e-9)
    rigid = replace(robot, cable_stiffness=None)
    t0, v_rule = rule_tensions(rigid, p, R)
    assert np.array_equal(stiffness_band(rigid, J, c, t0, f.lengths, v_rule), v_rule)


# ----------------------------------------------------------------------------- the commands

def test_command_tensions_average_and_rates():
    """The tent average against a quadrature, its rates against finite differences."""
    rng = np.random.default_rng(8)
    t = np.concatenate([[0.0], np.cumsum(rng.uniform(0.001, 0.03, 39))])
    f = rng.uniform(0.0, 5.0, (40, 3))
    w = 0.02
    at = np.array([0.0, 0.1, 0.33, t[-1], t[-1] + 0.01])
    avg, rate, second = command_tensions(t, f, w, at)
    s = np.linspace(-w, w, 200001)
    weight = (w - np.abs(s)) / w ** 2 * (s[1] - s[0])
    for k, x in enumerate(at):
        held = np.stack([np.interp(x + s, t, c) for c in f.T], axis=1)
        np.testing.assert_allclose(avg[k], weight @ held, atol=1e-8)
    h = 1e-6
    up, down = command_tensions(t, f, w, at + h), command_tensions(t, f, w, at - h)
    np.testing.assert_allclose((up[0] - down[0]) / (2 * h), rate, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose((up[1] - down[1]) / (2 * h), second, rtol=1e-3, atol=1e-2)


def test_the_commands_carry_the_tensions_at_the_planned_poses(plan):
    """At waypoints the commanded lengths are L / (1 + t / EA) with t within the window's
    reach of the nominal tension, their rates those of the tent-averaged stretch, zero at
    both ends; the JSON's commanded_lengths are these."""
    from cdh_planner.commands.plan import result_dict
    robot, path, result = plan
    L0, V0, A0 = path.commanded()
    t = robot.cable_stiffness * (path.lengths / L0 - 1.0)
    span = robot.tension_max - robot.tension_min
    assert np.max(np.abs(t - path.tension_nominal) / span) < 0.01
    assert not V0[[0, -1]].any()
    doc = result_dict(result)
    assert [w["commanded_lengths"] for w in doc["path"]] == L0.tolist()
    assert [w["velocities"] for w in doc["path"]] == V0.tolist()


# ----------------------------------------------------------------------------- the check

def test_the_elastic_check_fails_an_under_tensioned_command(plan):
    """Commands that leave cable 1 0.2 % too long at the planned poses (eight cables: the
    others take the load, cable 1 goes slack) or slack (an 11 %
    longer cable: the platform is lost or a tension leaves its band): the executed check
    (elastic equilibrium of the commanded quintic) fails; the planned commands pass. Six
    cables under-tensioned only move the platform (its statics are unique)."""
    robot, path, _ = plan
    # no winch limits (the tensions are checked), over a second of the motion
    load = dict(mass=robot.mass, inertia=robot.inertia, within=[[1.0, 2.0]])
    assert X.check_path(robot, path, **load).ok
    low = path.tension_nominal.copy()
    low[:, 0] = -0.002 * robot.cable_stiffness[0]            # L0 = L / 0.998: slack
    check = X.check_path(robot, replace(path, tension_nominal=low), **load)
    if len(robot.base_anchors) > 6:
        assert not check.ok and "tension margin" in check.reason, check.reason
    low[:, 0] = -0.1 * robot.cable_stiffness[0]             # L0 = L / 0.9: slack
    check = X.check_path(robot, replace(path, tension_nominal=low), **load)
    assert not check.ok and ("tension margin" in check.reason or "lost" in check.reason)


# ----------------------------------------------------------------------------- measured pose

@pytest.mark.parametrize("name", ROBOTS)
def test_forward_kinematics_with_measured_tensions_recovers_the_pose(name):
    robot = load_robot(REPO / "config" / f"{name}.yaml")
    p, R = _feasible_poses(robot, 3, np.random.default_rng(9))
    f = band_feasibility(robot, p, R=R)
    for k in range(len(p)):
        L0 = E.unstretched_lengths(robot, f.lengths[k], f.tension_nominal[k])  # the winches'
        guess = (p[k] + 1e-3, R[k])
        q, Q = current_pose(robot, measured_cable_lengths(robot, L0, f.tension_nominal[k]), guess)
        assert np.max(np.abs(q - p[k])) < 1e-9 and np.max(np.abs(Q - R[k])) < 1e-9
        q, _ = current_pose(robot, measured_cable_lengths(robot, L0, None), guess)  # rigid
        assert np.max(np.abs(q - p[k])) > 1e-6


# ----------------------------------------------------------------------------- refusal

def test_length_only_modes_refuse_more_than_six_rigid_cables():
    outlets = pytest.importorskip("cdh_planner.ros.execution.command_outlets")
    eight = load_robot(REPO / "config" / "robot2_8.yaml")
    six = load_robot(REPO / "config" / "robot2.yaml")
    for mode, cls in outlets.OUTLETS.items():
        assert cls.refusal(eight) == ""
        assert cls.refusal(replace(six, cable_stiffness=None)) == ""
        line = cls.refusal(replace(eight, cable_stiffness=None))
        if mode in ("follow_joint_trajectory", "forward_command"):
            assert "robot.cable_stiffness" in line and "\n" not in line
        else:
            assert line == ""
