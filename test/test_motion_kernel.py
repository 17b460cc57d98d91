"""The dynamic timing's per-sample geometry compiled (trajectory/motion_kernel.py) against
its numpy transcription (the einsums ``dynamics._terms`` used before): the inertial wrench
coefficients A, B and the lengths' s-rates to rounding, on a planned path's samples and on
random poses and rates; and L_s, L_ss the s-derivatives of L (finite differences along the
path)."""

import dataclasses

import numpy as np
import pytest

from conftest import PROBLEMS
from cdh_planner.model.robot import load_robot
from cdh_planner.parsing.problem import load_problem
from cdh_planner.ports import Rotation
from cdh_planner.trajectory.dynamics import _Geometry
from cdh_planner.trajectory.motion_kernel import motion_terms, turns
from cdh_planner.wrench import cable_vectors


def reference(robot, p, p_s, p_ss, R, w, w_s, mass, inertia):
    """A, B, L, L_s, L_ss by numpy (the module docstring of trajectory.dynamics)."""
    g = robot.load_point
    c = p + np.einsum("nij,j->ni", R, g)
    wxg = np.cross(w, g)
    c_s = p_s + np.einsum("nij,nj->ni", R, wxg)
    c_ss = p_ss + np.einsum("nij,nj->ni", R, np.cross(w_s, g) + np.cross(w, wxg))
    Iw, Iws = w @ inertia.T, w_s @ inertia.T
    A = np.concatenate([mass * c_s, np.cross(c, mass * c_s) + np.einsum("nij,nj->ni", R, Iw)], axis=1)
    B = np.concatenate([mass * c_ss, np.cross(c, mass * c_ss)
                        + np.einsum("nij,nj->ni", R, Iws + np.cross(w, Iw))], axis=1)
    d = cable_vectors(robot, p, R)
    L = np.linalg.norm(d, axis=-1)
    u = d / L[..., None]
    b = robot.platform_anchors[None]
    wxb = np.cross(w[:, None, :], b)
    q_s = p_s[:, None, :] + np.einsum("nij,nkj->nki", R, wxb)
    q_ss = p_ss[:, None, :] + np.einsum("nij,nkj->nki", R, np.cross(w_s[:, None, :], b)
                                        + np.cross(w[:, None, :], wxb))
    L_s = np.einsum("nki,nki->nk", u, q_s)
    L_ss = (np.einsum("nki,nki->nk", q_s, q_s) - L_s ** 2) / L + np.einsum("nki,nki->nk", u, q_ss)
    return A, B, L, L_s, L_ss


def _agree(got, expected):
    for a, b in zip(got, expected):
        assert np.all(np.abs(a - b) <= 1e-12 * max(1.0, np.max(np.abs(b))))


@pytest.fixture(scope="module")
def geometry():
    problem = load_problem(PROBLEMS / "robot2_q2_q3.yaml")
    from cdh_planner.planner import Planner
    result = Planner(problem.robot, problem.task, problem.settings).plan(problem.start, problem.goal)
    assert result.success
    return problem.robot, _Geometry(problem.robot, result.path)


def test_the_kernel_is_the_numpy_algebra_on_a_path(geometry):
    robot, geo = geometry
    s = np.linspace(0.0, geo.length, 700)
    args = (*geo.at(s), robot.mass, robot.inertia)
    _agree(motion_terms(robot, *args), reference(robot, *args))


@pytest.mark.parametrize("name", ["robot2.yaml", "robot1.yaml", "robot2_8.yaml"])
def test_the_kernel_is_the_numpy_algebra_at_random_states(name):
    """Any pose, rates, load point, mass and full inertia (off-diagonal terms too)."""
    robot = load_robot(PROBLEMS.parent / name)
    rng = np.random.default_rng(4)
    n = 300
    p = np.mean(robot.base_anchors, axis=0) + rng.normal(scale=0.1, size=(n, 3))
    R = Rotation.from_rotvec(rng.normal(scale=0.5, size=(n, 3))).as_matrix()
    rates = [rng.normal(size=(n, 3)) for _ in range(4)]
    M = rng.normal(size=(3, 3))
    inertia = M @ M.T + np.eye(3)
    robot = dataclasses.replace(robot, load_point=rng.normal(scale=0.05, size=3))
    args = (p, rates[0], rates[1], R, rates[2], rates[3], 1.7, inertia)
    _agree(motion_terms(robot, *args), reference(robot, *args))


def test_the_length_rates_are_the_derivatives_along_the_path(geometry):
    """L_s and L_ss against central differences of L along s (the spline's own pose)."""
    robot, geo = geometry
    s = np.linspace(0.05, 0.95, 50) * geo.length
    h = 1e-5 * geo.length

    def lengths(x):
        return motion_terms(robot, *geo.at(x), robot.mass, robot.inertia)[2]
    _, _, L, L_s, L_ss = motion_terms(robot, *geo.at(s), robot.mass, robot.inertia)
    assert np.allclose(L_s, (lengths(s + h) - lengths(s - h)) / (2 * h), atol=1e-6)
    assert np.allclose(L_ss, (lengths(s + h) - 2 * L + lengths(s - h)) / h ** 2, atol=1e-3)


def test_the_turns_are_the_ports_rotation_vectors():
    """``turns`` against Rotation.from_matrix(R[a]^T R[b]).as_rotvec(): random rotations and
    turns of 0, 1e-9, 1e-4, 1e-3 (the series' edge), pi / 2 and near pi about each axis (each
    quaternion branch); a product off orthogonal (a matrix scaled by 1 + 1e-9) goes to the
    port, which projects it; a reflection is refused as the port refuses it."""
    rng = np.random.default_rng(12)
    base = Rotation.from_rotvec(rng.normal(size=(40, 3))).as_matrix()
    special = [Rotation.from_rotvec(angle * axis).as_matrix()
               for axis in np.eye(3) for angle in (0.0, 1e-9, 1e-4, 1e-3, 1.1e-3, np.pi / 2, np.pi - 1e-6)]
    R = np.concatenate([base, base[:len(special)] @ np.array(special)])
    a = np.concatenate([rng.integers(0, 40, 60), np.arange(len(special))])
    b = np.concatenate([rng.integers(0, 40, 60), 40 + np.arange(len(special))])
    R[3] *= 1.0 + 1e-9  # off orthogonal
    a[0] = 3
    got = turns(R, a, b)
    ref = Rotation.from_matrix(np.swapaxes(R[a], 1, 2) @ R[b]).as_rotvec()
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-15)
    R[5] = -R[5]  # left-handed
    with pytest.raises(ValueError):
        turns(R, np.array([5]), np.array([6]))
