"""Forward kinematics (model/kinematics.py) against inverse kinematics: the cable lengths of
random wrench-feasible poses, given to Newton from a nearby start, give the pose back."""

import numpy as np
import pytest

from cdh_planner.errors import InputError
from cdh_planner.wrench import cable_vectors, wrench_feasibility
from cdh_planner.model.kinematics import (cable_lengths, forward_kinematics, length_jacobian,
                                          rotation_vector_exp)
from cdh_planner.model.pose import rotation_angle_between, rotation_tt
from cdh_planner.model.robot import load_robot
from conftest import CONFIG

ROBOTS = {name: load_robot(CONFIG / f"{name}.yaml") for name in ("robot1", "robot2")}


def _feasible_poses(robot, rng, n):
    """n random wrench-feasible poses (p (n, 3), R (n, 3, 3)) around the base anchors' centre."""
    centre = robot.base_anchors.mean(axis=0)
    spread = np.ptp(robot.base_anchors, axis=0).max()
    ps, Rs = [], []
    for _ in range(200):
        p = centre + rng.uniform(-0.5, 0.5, (4000, 3)) * spread
        tau = rng.uniform([-np.pi, 0.0, -np.pi], [np.pi, 0.8, np.pi], (4000, 3))
        R = rotation_tt(tau)
        ok = wrench_feasibility(robot, p, R=R).feasible
        ps.extend(p[ok])
        Rs.extend(R[ok])
        if len(ps) >= n:
            return np.array(ps[:n]), np.array(Rs[:n])
    raise AssertionError(f"only {len(ps)} feasible poses found")


def test_lengths_are_the_norms_of_the_cable_vectors():
    rng = np.random.default_rng(1)
    robot = ROBOTS["robot2"]
    p, R = _feasible_poses(robot, rng, 5)
    for pk, Rk in zip(p, R):
        np.testing.assert_allclose(cable_lengths(robot, pk, Rk),
                                   np.linalg.norm(cable_vectors(robot, pk[None], Rk[None])[0], axis=1),
                                   rtol=0, atol=1e-15)


def test_length_jacobian_matches_finite_differences_on_se3():
    rng = np.random.default_rng(2)
    robot = ROBOTS["robot2"]
    (p,), (R,) = _feasible_poses(robot, rng, 1)
    J = length_jacobian(robot, p, R)
    h = 1e-6
    for k in range(6):
        d = np.zeros(6)
        d[k] = h
        plus = cable_lengths(robot, p + d[:3], rotation_vector_exp(d[3:]) @ R)
        minus = cable_lengths(robot, p - d[:3], rotation_vector_exp(-d[3:]) @ R)
        np.testing.assert_allclose((plus - minus) / (2 * h), J[:, k], rtol=0, atol=1e-8)


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_forward_kinematics_recovers_random_feasible_poses_from_a_nearby_start(name):
    robot = ROBOTS[name]
    rng = np.random.default_rng(3)
    p, R = _feasible_poses(robot, rng, 30)
    for pk, Rk in zip(p, R):
        L = cable_lengths(robot, pk, Rk)
        # last known pose: up to 2 cm and 0.1 rad away
        p0 = pk + rng.uniform(-0.02, 0.02, 3)
        axis = rng.normal(size=3)
        R0 = rotation_vector_exp(axis / np.linalg.norm(axis) * rng.uniform(0, 0.1)) @ Rk
        fk = forward_kinematics(robot, L, p0, R0)
        assert fk.ok, fk.message
        q, Q, residual = fk
        assert residual <= 1e-12 and fk.message == ""
        assert np.max(np.abs(q - pk)) < 1e-9
        assert rotation_angle_between(Q, Rk) < 1e-9
        np.testing.assert_allclose(Q.T @ Q, np.eye(3), atol=1e-14)
        assert np.linalg.det(Q) > 0


def test_forward_kinematics_from_the_pose_itself_takes_no_step():
    robot = ROBOTS["robot2"]
    (p,), (R,) = _feasible_poses(robot, np.random.default_rng(4), 1)
    fk = forward_kinematics(robot, cable_lengths(robot, p, R), p, R)
    assert fk.ok and fk.iterations == 0
    assert np.max(np.abs(fk.p - p)) == 0.0 and rotation_angle_between(fk.R, R) < 1e-15


def test_unreachable_lengths_are_reported_not_raised():
    robot = ROBOTS["robot2"]
    (p,), (R,) = _feasible_poses(robot, np.random.default_rng(5), 1)
    L = cable_lengths(robot, p, R)
    L[0] += 10.0   # one cable 10 m longer than the others allow
    fk = forward_kinematics(robot, L, p, R)
    assert not fk.ok
    assert fk.message.startswith("forward kinematics: ") and "\n" not in fk.message
    assert fk.residual > 1e-3
    assert np.all(np.isfinite(fk.p)) and np.all(np.isfinite(fk.R))


def test_a_singular_start_is_reported_not_raised():
    """All platform anchors at one point: the Jacobian has no rotational rank anywhere."""
    from dataclasses import replace
    robot = replace(ROBOTS["robot2"], platform_anchors=np.zeros((6, 3)))
    p, R = np.array([0.0, 0.0, 0.3]), np.eye(3)
    L = cable_lengths(robot, p, R) + 0.001
    fk = forward_kinematics(robot, L, p, R)
    assert not fk.ok and "singular" in fk.message


def test_few_iterations_are_a_clear_failure():
    robot = ROBOTS["robot2"]
    (p,), (R,) = _feasible_poses(robot, np.random.default_rng(6), 1)
    fk = forward_kinematics(robot, cable_lengths(robot, p, R), p + 0.02, R, max_iterations=1)
    assert not fk.ok and "no convergence in 1 iterations" in fk.message


@pytest.mark.parametrize("lengths, p0, R0, field", [
    ([0.5] * 5, [0, 0, 0.3], np.eye(3), "lengths"),
    ([0.5] * 5 + [float("nan")], [0, 0, 0.3], np.eye(3), "lengths"),
    ([0.5] * 5 + [0.0], [0, 0, 0.3], np.eye(3), "lengths"),
    ([0.5] * 6, [0, 0], np.eye(3), "p0"),
    ([0.5] * 6, [0, 0, 0.3], 2 * np.eye(3), "R0"),
    ([0.5] * 6, [0, 0, 0.3], "eye", "R0"),
])
def test_bad_input_names_its_field(lengths, p0, R0, field):
    with pytest.raises(InputError) as e:
        forward_kinematics(ROBOTS["robot2"], lengths, p0, R0)
    assert e.value.field == field
