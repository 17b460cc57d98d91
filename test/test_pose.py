"""Tilt-and-torsion angles, rotation matrices and quaternions (model/pose.py)."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cdh_planner.errors import InputError
from cdh_planner.model.pose import (check_quaternion, quaternion_from_tau, rotation_from_quaternion,
                                    rotation_tt, rotation_tt_derivatives, tau_from_quaternion,
                                    tau_from_rotation, wrap_angle)

RNG = np.random.default_rng(12)


def random_tau(n, theta=None):
    tau = np.column_stack([RNG.uniform(-np.pi, np.pi, n), RNG.uniform(0.05, np.pi - 0.05, n),
                           RNG.uniform(-np.pi, np.pi, n)])
    if theta is not None:
        tau[:, 1] = theta
    return tau


def angle_diff(a, b):
    return np.abs(wrap_angle(np.asarray(a) - np.asarray(b)))


def test_rotation_tt_is_the_documented_product():
    tau = random_tau(20)
    for (phi, theta, sigma), R in zip(tau, rotation_tt(tau)):
        expected = Rotation.from_euler("ZYZ", [phi, theta, sigma - phi]).as_matrix()
        np.testing.assert_allclose(R, expected, atol=1e-12)


def test_rotation_tt_is_orthonormal_and_vectorised():
    tau = random_tau(24).reshape(2, 3, 4, 3)
    R = rotation_tt(tau)
    assert R.shape == (2, 3, 4, 3, 3)
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)


def test_tau_rotation_round_trip_regular():
    tau = random_tau(200)
    back = tau_from_rotation(rotation_tt(tau))
    assert np.all(angle_diff(back[:, 0], tau[:, 0]) < 1e-9)
    np.testing.assert_allclose(back[:, 1], tau[:, 1], atol=1e-9)
    assert np.all(angle_diff(back[:, 2], tau[:, 2]) < 1e-9)


@pytest.mark.parametrize("theta", [0.0, np.pi])
def test_tau_rotation_round_trip_on_the_singular_set_with_phi_hint(theta):
    tau = random_tau(50, theta=theta)
    back = tau_from_rotation(rotation_tt(tau), phi_hint=tau[:, 0])
    assert np.all(angle_diff(back[:, 0], tau[:, 0]) < 1e-9)
    np.testing.assert_allclose(back[:, 1], theta, atol=1e-9)
    assert np.all(angle_diff(back[:, 2], tau[:, 2]) < 1e-9)
    # Whatever phi is chosen there, the recovered angles give the same rotation.
    np.testing.assert_allclose(rotation_tt(tau_from_rotation(rotation_tt(tau))), rotation_tt(tau), atol=1e-9)


@pytest.mark.parametrize("theta", [0.0, 1e-7, 0.7, np.pi - 1e-7, np.pi])
def test_quaternion_round_trip(theta):
    tau = random_tau(50, theta=theta)
    q = quaternion_from_tau(tau)
    assert q.shape == (50, 4)
    assert np.all(q[:, 3] >= 0)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(rotation_from_quaternion(q), rotation_tt(tau), atol=1e-9)
    back = tau_from_quaternion(q, phi_hint=tau[:, 0])
    np.testing.assert_allclose(rotation_tt(back), rotation_tt(tau), atol=1e-7)
    if theta in (0.0, np.pi):
        assert np.all(angle_diff(back[:, 0], tau[:, 0]) < 1e-9)


def test_quaternion_from_tau_is_the_checked_conversion_bit_for_bit():
    """quaternion_from_tau assumes rotation_tt's matrices valid (no orthogonality test): the
    same quaternions as the checked conversion, over wide and singular angles."""
    from cdh_planner.ports.rotation import Rotation as Port
    rng = np.random.default_rng(5)
    tau = np.concatenate([rng.uniform([-10, -1, -10], [10, 4, 10], (20_000, 3)),
                          random_tau(200, theta=0.0), random_tau(200, theta=np.pi),
                          [[0.0, 0.0, 0.0], [np.pi, np.pi, -np.pi], [1e-300, 1e-300, 0.0]]])
    checked = Port.from_matrix(rotation_tt(tau)).as_quat()
    checked = np.where(checked[:, 3:4] < 0, -checked, checked)
    assert np.array_equal(quaternion_from_tau(tau), checked)


def test_identity_quaternion_is_theta_zero():
    tau = tau_from_quaternion(np.array([0.0, 0.0, 0.0, 1.0]), phi_hint=0.4)
    np.testing.assert_allclose(tau, [0.4, 0.0, 0.0], atol=1e-12)  # theta = 0: R = Rz(sigma)


def test_derivatives_match_finite_differences():
    tau = random_tau(30)
    D = rotation_tt_derivatives(tau)
    assert D.shape == (30, 3, 3, 3)
    h = 1e-6
    for k in range(3):
        dt = np.zeros(3)
        dt[k] = h
        fd = (rotation_tt(tau + dt) - rotation_tt(tau - dt)) / (2 * h)
        np.testing.assert_allclose(D[..., k], fd, atol=1e-8)


def test_derivatives_at_theta_zero():
    tau = random_tau(10, theta=0.0)
    D = rotation_tt_derivatives(tau)
    h = 1e-6
    for k in range(3):
        dt = np.zeros(3)
        dt[k] = h
        fd = (rotation_tt(tau + dt) - rotation_tt(tau - dt)) / (2 * h)
        np.testing.assert_allclose(D[..., k], fd, atol=1e-8)
    # At theta = 0 phi does not change the rotation.
    np.testing.assert_allclose(D[..., 0], 0.0, atol=1e-12)


def test_wrap_angle_range():
    a = wrap_angle(np.array([-np.pi, np.pi, 3 * np.pi, -7.0, 0.0]))
    assert np.all(a >= -np.pi) and np.all(a < np.pi)
    np.testing.assert_allclose(a[[0, 1, 2, 4]], [-np.pi, -np.pi, -np.pi, 0.0])


def test_check_quaternion_accepts_and_normalises_within_tolerance():
    q = check_quaternion([0.0, 0.0, 0.0, 1.0005])
    np.testing.assert_allclose(np.linalg.norm(q), 1.0)


@pytest.mark.parametrize("q, reason", [
    ([0.0, 0.0, 0.0, 0.0], "zero"),
    ([0.0, 0.0, 0.0, 2.0], "not normalised"),
    ([0.0, 0.0, float("nan"), 1.0], "finite"),
    ([0.0, 0.0, float("inf"), 1.0], "finite"),
    ([0.0, 0.0, 1.0], "4 numbers"),
    ([0.0, 0.0, 0.0, 1.0, 0.0], "4 numbers"),
])
def test_check_quaternion_errors_name_the_field(q, reason):
    with pytest.raises(InputError) as exc:
        check_quaternion(q, field="poses[3].quaternion")
    assert exc.value.field == "poses[3].quaternion"
    assert reason in str(exc.value)


def test_cross_is_numpys_cross_to_the_bit():
    from cdh_planner.model.pose import cross
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(5, 3)), rng.normal(size=(7, 5, 3))
    assert np.array_equal(cross(a, b), np.cross(a, b))
    assert np.array_equal(cross(b[0], a), np.cross(b[0], a))
    g, h = rng.normal(size=(4, 3, 6)), rng.normal(size=(4, 3, 6))   # over a middle axis
    for axis in (1, -2):
        assert np.array_equal(cross(g, h, axis=axis), np.cross(g, h, axis=1))
