"""Per-pose geometry of the wrench test, by numpy: cable vectors, the structure matrix J,
the load point, the nominal wrench w0 and the wrench ellipsoid's factor L (L L^T = E^-1),
all in the base frame F1 (paper Sec. 2, App. A). Units: m, N, N m."""

from functools import lru_cache

import numpy as np

from ..model.pose import cross


def skew(v):
    """Cross-product matrices [v]x, shape (..., 3, 3)."""
    v = np.asarray(v, dtype=float)
    S = np.zeros(v.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2] = -v[..., 2], v[..., 1]
    S[..., 1, 0], S[..., 1, 2] = v[..., 2], -v[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -v[..., 1], v[..., 0]
    return S


def cable_vectors(robot, p, R):
    """d_i = p + R b_i - a_i (from base anchor to platform anchor), shape (N, m, 3), m."""
    return p[:, None, :] + np.einsum("nij,kj->nki", R, robot.platform_anchors) - robot.base_anchors


def screw_jacobian(robot, u):
    """J with column i = [u_i; a_i x u_i] (moments about the base origin), shape (N, 6, m)."""
    J = np.empty(u.shape[:-2] + (6, u.shape[-2]))
    J[..., :3, :] = np.swapaxes(u, -1, -2)
    J[..., 3:, :] = np.swapaxes(cross(robot.base_anchors, u), -1, -2)
    return J


def load_point(robot, p, R):
    """c = p + R g, the load point in the base frame, shape (N, 3), m."""
    return p + np.einsum("nij,j->ni", R, robot.load_point)


def wrench_transform(c):
    """e(c) = [[I, 0], [-[c]x, I]]: maps F1 wrench coordinates to the load frame F3."""
    e = np.zeros(c.shape[:-1] + (6, 6))
    e[..., :3, :3] = np.eye(3)
    e[..., 3:, 3:] = np.eye(3)
    e[..., 3:, :3] = -skew(c)
    return e


def nominal_wrench(robot, c):
    """w0 in F1 (force; moment about O), shape (N, 6)."""
    w = np.broadcast_to(robot.wrench_center_local, c.shape[:-1] + (6,)).copy()
    if robot.ellipsoid_frame == "load":
        w[..., 3:] += cross(c, w[..., :3])
    return w


def inverse_ellipsoid_factor(robot, c):
    """L with L L^T = E_F1^-1, shape (N, 6, 6), without inverting E per pose.

    E_F1^-1 = e^-1 E3^-1 e^-T and e(c)^-1 = e(-c), so L = e(-c) chol(E3^-1).
    """
    L3 = inverse_factor(robot)
    if robot.ellipsoid_frame == "base":
        return np.broadcast_to(L3, c.shape[:-1] + (6, 6))
    return wrench_transform(-c) @ L3


@lru_cache(maxsize=64)
def _inverse_factor(E_bytes):
    """L3 with L3 L3^T = E^-1 for the 6 x 6 matrix E given by its bytes (one per robot)."""
    E = np.frombuffer(E_bytes).reshape(6, 6)
    return np.linalg.cholesky(np.linalg.inv(E))


def inverse_factor(robot):
    """L3 (6, 6), L3 L3^T = E^-1 of the robot's ellipsoid matrix, in its own frame."""
    return _inverse_factor(robot.ellipsoid_matrix.tobytes())
