"""Platform orientation in tilt-and-torsion angles (the paper's tau) and quaternions.

R(tau) = Rz(phi) Ry(theta) Rz(sigma - phi), tau = (phi, theta, sigma) in radians,
theta in [0, pi]; phi and sigma are 2 pi periodic. Quaternions are (x, y, z, w), as in
ROS (geometry_msgs/Quaternion) and scipy (whose formulas ports/rotation.py follows).

Everything is vectorised over leading axes: tau has shape (..., 3), R (..., 3, 3).
"""

from dataclasses import dataclass

import numpy as np
from ..ports import Rotation

from ..errors import InputError

TWO_PI = 2.0 * np.pi


def wrap_angle(a):
    """Wrap angles to [-pi, pi) (radians)."""
    return (np.asarray(a, dtype=float) + np.pi) % TWO_PI - np.pi


def cross(a, b, axis=-1):
    """a x b over ``axis`` (of length 3) of broadcasting arrays: the same numbers as
    np.cross (the same products and differences) at a fifth of its cost on (N, m, 3) arrays
    (np.cross moves axes and copies; the elastic equilibria take millions of these)."""
    def part(x, k):
        return x[(Ellipsis, k) + (slice(None),) * (-axis - 1)] if axis < 0 else \
            x[(slice(None),) * axis + (k,)]
    a0, a1, a2 = (part(a, k) for k in range(3))
    b0, b1, b2 = (part(b, k) for k in range(3))
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=axis)


def rotation_tt(tau):
    """Rotation matrix R = Rz(phi) Ry(theta) Rz(sigma - phi), shape (..., 3, 3)."""
    tau = np.asarray(tau, dtype=float)
    phi, theta, sigma = tau[..., 0], tau[..., 1], tau[..., 2]
    psi = sigma - phi
    cf, sf = np.cos(phi), np.sin(phi)
    ct, st = np.cos(theta), np.sin(theta)
    cp, sp = np.cos(psi), np.sin(psi)
    R = np.empty(tau.shape[:-1] + (3, 3))
    R[..., 0, 0] = cf * ct * cp - sf * sp
    R[..., 0, 1] = -cf * ct * sp - sf * cp
    R[..., 0, 2] = cf * st
    R[..., 1, 0] = sf * ct * cp + cf * sp
    R[..., 1, 1] = -sf * ct * sp + cf * cp
    R[..., 1, 2] = sf * st
    R[..., 2, 0] = -st * cp
    R[..., 2, 1] = st * sp
    R[..., 2, 2] = ct
    return R


def rotation_tt_derivatives(tau):
    """dR/dphi, dR/dtheta, dR/dsigma stacked as shape (..., 3, 3, 3) (last index = angle)."""
    tau = np.asarray(tau, dtype=float)
    phi, theta, sigma = tau[..., 0], tau[..., 1], tau[..., 2]
    psi = sigma - phi
    Rz_phi, dRz_phi = _rz(phi)
    Ry_t, dRy_t = _ry(theta)
    Rz_psi, dRz_psi = _rz(psi)
    d_phi = dRz_phi @ Ry_t @ Rz_psi - Rz_phi @ Ry_t @ dRz_psi
    d_theta = Rz_phi @ dRy_t @ Rz_psi
    d_sigma = Rz_phi @ Ry_t @ dRz_psi
    return np.stack([d_phi, d_theta, d_sigma], axis=-1)


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(a), np.ones_like(a)
    R = np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)
    dR = np.stack([np.stack([-s, -c, z], -1), np.stack([c, -s, z], -1), np.stack([z, z, z], -1)], -2)
    return R, dR


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(a), np.ones_like(a)
    R = np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)
    dR = np.stack([np.stack([-s, z, c], -1), np.stack([z, z, z], -1), np.stack([-c, z, -s], -1)], -2)
    return R, dR


SINGULAR_TOL = 1e-9  # rad: tau_from_rotation's default distance for snapping to theta = 0 or pi


def tau_from_rotation(R, phi_hint=0.0, tol=SINGULAR_TOL):
    """Tilt-and-torsion angles of rotation matrices, theta in [0, pi], phi and sigma wrapped
    to [-pi, pi). Shape (..., 3).

    theta = 0 and theta = pi are the representation's singular set: there R = Rz(sigma)
    fixes only sigma, and R = Rz(2 phi - sigma) Ry(pi) only 2 phi - sigma, so phi is free.
    A rotation within ``tol`` (rad, < pi/2) of that set -- its tilt theta, or pi - theta,
    is its angle to the nearest rotation on the set -- is snapped onto it: theta becomes
    exactly 0 (pi), phi is ``phi_hint`` (rad), and sigma keeps R's rotation about z (0) or
    2 phi - sigma (pi). Elsewhere phi is R's own azimuth (ill-conditioned as 1 / theta
    near the set, which is why noise there needs the snap).

    sigma = phi + psi and 2 phi - sigma = phi - psi (psi = sigma - phi) come from the upper
    2x2 block, scaled by 1 + cos theta and 1 - cos theta: each is used on the half of the
    sphere where it is well-conditioned, so sigma is continuous up to the singular set.
    """
    R = np.asarray(R, dtype=float)
    cos_t = np.clip(R[..., 2, 2], -1.0, 1.0)
    sin_t = np.hypot(R[..., 0, 2], R[..., 1, 2])
    theta = np.arctan2(sin_t, cos_t)
    hint = np.broadcast_to(np.asarray(phi_hint, dtype=float), theta.shape)
    north, south = theta <= tol, np.arctan2(sin_t, -cos_t) <= tol   # (pi - theta, exact)
    phi = np.where(north | south, hint, np.arctan2(R[..., 1, 2], R[..., 0, 2]))
    sum_ = np.arctan2(R[..., 1, 0] - R[..., 0, 1], R[..., 0, 0] + R[..., 1, 1])   # phi + psi
    diff = np.arctan2(-(R[..., 1, 0] + R[..., 0, 1]), R[..., 1, 1] - R[..., 0, 0])  # phi - psi
    sigma = np.where(cos_t >= 0.0, sum_, 2.0 * phi - diff)
    theta = np.where(north, 0.0, np.where(south, np.pi, theta))
    return np.stack([wrap_angle(phi), theta, wrap_angle(sigma)], axis=-1)


def on_singular_set(tau):
    """Is theta exactly 0 or pi (where phi is not determined by the rotation)? Shape (...)."""
    theta = np.asarray(tau, dtype=float)[..., 1]
    return (theta == 0.0) | (theta == np.pi)


def quaternion_from_tau(tau):
    """Quaternion (x, y, z, w) of tilt-and-torsion angles, shape (..., 4), w >= 0."""
    tau = np.asarray(tau, dtype=float)
    # rotation_tt's products of sines and cosines are rotations to rounding
    q = Rotation.from_matrix(rotation_tt(tau).reshape(-1, 3, 3), assume_valid=True).as_quat()
    q = np.where(q[:, 3:4] < 0, -q, q)
    return q.reshape(tau.shape[:-1] + (4,))


def check_quaternion(q, field="quaternion", tol=1e-3):
    """Validate a quaternion (x, y, z, w): finite, non-zero and unit length within ``tol``.

    A non-normalised quaternion is an error, not silently normalised: it usually means the
    fields were given in the wrong order or in degrees.
    """
    q = np.asarray(q, dtype=float)
    if q.shape != (4,):
        raise InputError(field, q.tolist(), "expected 4 numbers (x, y, z, w)")
    if not np.all(np.isfinite(q)):
        raise InputError(field, q.tolist(), "must be finite numbers")
    norm = float(np.linalg.norm(q))
    if norm < 1e-9:
        raise InputError(field, q.tolist(), "zero quaternion is not a rotation")
    if abs(norm - 1.0) > tol:
        raise InputError(field, q.tolist(), f"not normalised (norm {norm:.6g}, expected 1)")
    return q / norm


def tau_from_quaternion(q, phi_hint=0.0, tol=SINGULAR_TOL):
    """Tilt-and-torsion angles (radians) of unit quaternions (x, y, z, w), shape (..., 3);
    ``phi_hint`` and ``tol`` as in ``tau_from_rotation``."""
    q = np.asarray(q, dtype=float)
    R = Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape(q.shape[:-1] + (3, 3))
    return tau_from_rotation(R, phi_hint, tol)


def rotation_from_quaternion(q):
    """Rotation matrices of quaternions (x, y, z, w), shape (..., 3, 3)."""
    q = np.asarray(q, dtype=float)
    return Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape(q.shape[:-1] + (3, 3))


def rotation_angle_between(Ra, Rb):
    """SO(3) geodesic distance: the angle (radians) of D = Ra^T Rb, shape (...). From
    atan2(sin, cos) with 2 sin = |axial vector of D - D^T|: exact to rounding near 0 and
    pi, where arccos of the trace loses half the digits."""
    D = np.einsum("...ki,...kj->...ij", Ra, Rb)
    tr = D[..., 0, 0] + D[..., 1, 1] + D[..., 2, 2]
    axial = np.stack([D[..., 2, 1] - D[..., 1, 2], D[..., 0, 2] - D[..., 2, 0],
                      D[..., 1, 0] - D[..., 0, 1]], axis=-1)
    return np.arctan2(0.5 * np.linalg.norm(axial, axis=-1), 0.5 * (tr - 1.0))


@dataclass(frozen=True)
class Pose:
    """Platform pose: position ``p`` (3,) m in the base frame, ``tau`` = (phi, theta, sigma) rad."""

    p: np.ndarray
    tau: np.ndarray
