"""Elastic cables (numpy; the equilibrium's Newton compiled in ``elastic_kernel``): a cable
of unstretched length L0 (m) under tension t (N) is L0 (1 + t / EA) long, EA its axial
stiffness (N, ``robot.cable_stiffness``). A robot without a stiffness has rigid cables:
every function here then gives the rigid answer.
"""

from dataclasses import dataclass

import numpy as np

from ..parallel import blocks
from .pose import cross


def is_elastic(robot):
    """Does the robot file give its cables a stiffness?"""
    return robot.cable_stiffness is not None


def unstretched_lengths(robot, L, t):
    """L0 (N, m) m: the unstretched lengths that are L (N, m) m long under tensions t (N, m) N,
    L0 = L / (1 + t / EA); L itself for rigid cables."""
    L = np.asarray(L, dtype=float)
    if not is_elastic(robot):
        return L.copy()
    return L / (1.0 + np.asarray(t, dtype=float) / robot.cable_stiffness)


def stretched_lengths(robot, L0, t):
    """L (N, m) m: the lengths of cables of unstretched length L0 (N, m) m under tensions
    t (N, m) N, L0 (1 + t / EA); L0 itself for rigid cables."""
    L0 = np.asarray(L0, dtype=float)
    if not is_elastic(robot):
        return L0.copy()
    return L0 * (1.0 + np.asarray(t, dtype=float) / robot.cable_stiffness)


def stretched_tensions(robot, L, L0):
    """Tensions (N, m) N of cables of unstretched length L0 pulled to length L (both m):
    EA (L - L0) / L0, zero where slack (a cable cannot push)."""
    return np.maximum(0.0, robot.cable_stiffness * (np.asarray(L) - L0) / L0)


def axial_stiffness(robot, L0):
    """k_i = EA_i / L0_i (N/m) of cables of unstretched lengths L0 (N, m) m."""
    return robot.cable_stiffness / np.asarray(L0, dtype=float)


EQUILIBRIUM_ITERATIONS = 25
LINE_SEARCH_HALVINGS = 12
EQUILIBRIUM_TOL = 1e-12  # N (and N m) per N of the load's force: converged


@dataclass(frozen=True)
class Equilibria:
    """Poses p (M, 3) m, R (M, 3, 3) where elastic cables balance a load, their tensions
    (M, m) N, the largest force or moment residual (M,) N and ``ok`` (M,) where Newton
    converged."""

    p: np.ndarray
    R: np.ndarray
    tensions: np.ndarray
    residual: np.ndarray
    ok: np.ndarray


def wrench_balance(robot, L0, p, R, force, moment, arm, bilateral=False, jacobian=True):
    """Residual (M, 6) and its Jacobian (M, 6, 6) of the balance of cables of unstretched
    lengths L0 (M, m) m at poses (p (M, 3) m, R (M, 3, 3)) against the load wrench about
    the origin [force; moment + c x arm] (each (M, 3), N and N m; c = p + R g the load
    point): sum_i t_i [u_i; a_i x u_i] - w, t_i = max(0, EA_i (L_i - L0_i) / L0_i), u_i the
    unit vector from base anchor a_i to platform anchor. Also the tensions (M, m) N. The
    Jacobian is with respect to [dp; dtheta], p <- p + dp, R <- exp([dtheta]x) R (base
    frame), the geometric stiffness of the tensions included. ``bilateral``: cables that
    push as well (t_i = EA_i (L_i - L0_i) / L0_i of either sign), a smooth system whose
    solution is the tension-only one where every tension comes out positive. ``jacobian``
    False: the Jacobian is None (a line search needs the residual only)."""
    a, b = robot.base_anchors, robot.platform_anchors
    r = b @ R.transpose(0, 2, 1)                                        # R b_i (M, m, 3)
    d = p[:, None, :] + r - a
    L = np.linalg.norm(d, axis=-1)
    u = d / L[..., None]
    k = axial_stiffness(robot, L0)
    t = k * (L - L0)
    if not bilateral:
        t = np.maximum(t, 0.0)
        k = np.where(t > 0, k, 0.0)
    c = p + R @ robot.load_point
    w = np.concatenate([force, moment + cross(c, arm)], axis=1)
    au = cross(a, u)                                                 # a_i x u_i (M, m, 3)
    res = np.concatenate([(t[:, None, :] @ u)[:, 0], (t[:, None, :] @ au)[:, 0]], axis=1) - w
    if not jacobian:
        return res, None, t
    # dq_i = dp + dtheta x r_i; dL_i = [u_i; r_i x u_i] . [dp; dtheta];
    # d(t_i u_i) = k_i u_i dL_i + (t_i / L_i) (dq_i - u_i dL_i), summed over the cables with
    # matrix products (M, 3, m) @ (M, m, 6), the [a]x [r]x terms as r a^T - (a . r) I
    dL = np.concatenate([u, cross(r, u)], axis=-1)                   # (M, m, 6)
    tl = t / L                                                          # (M, m) N/m
    cu = (k - tl)[..., None] * dL                                        # (M, m, 6)
    wr = tl[..., None] * r                                               # (t_i / L_i) r_i (M, m, 3)
    eye = np.eye(3)
    top = u.transpose(0, 2, 1) @ cu
    top[:, :, :3] += tl.sum(axis=1)[:, None, None] * eye
    top[:, :, 3:] -= _skew(wr.sum(axis=1))
    bottom = au.transpose(0, 2, 1) @ cu
    bottom[:, :, :3] += _skew(tl @ a)
    bottom[:, :, 3:] -= (wr.transpose(0, 2, 1) @ a                     # sum (t_i / L_i) r_i a_i^T
                         - (wr * a).sum(axis=(1, 2))[:, None, None] * eye)
    arm_x = _skew(arm)
    bottom[:, :, :3] += arm_x                                          # d(c x arm) = -arm x dc
    bottom[:, :, 3:] -= arm_x @ _skew(c - p)
    jac = np.concatenate([top, bottom], axis=1)
    return res, jac, t


def static_load(robot, n):
    """(force, moment, arm), each (n, 3), N and N m: the load wrench of ``wrench_balance``
    at rest, ``robot.wrench_center_local`` (its force at the load point when the ellipsoid's
    frame is "load", else at the origin)."""
    w = np.broadcast_to(robot.wrench_center_local, (n, 6))
    force, moment = w[:, :3], w[:, 3:]
    arm = force if robot.ellipsoid_frame == "load" else np.zeros_like(force)
    return force, moment, arm


def platform_stiffness(robot, p, R, t):
    """K (M, 6, 6): the stiffness of the platform on elastic cables that carry tensions t
    (M, m) N at poses (p (M, 3) m, R (M, 3, 3)) under the load at rest (``static_load``),
    cables held at their unstretched lengths L0 = L / (1 + t / EA): the change of the
    wrench the platform must resist, about p (rows: N, N m), per [dp; dtheta] (m, rad;
    ``wrench_balance``'s Jacobian, its moment rows moved from the origin to p). Elastic and
    geometric stiffness (tensions, load) both; symmetrised (symmetric where t balances the
    load, a conservative system). Affine in t. The equilibrium is stable iff K is positive
    definite; a small wrench dw about p moves it by K^-1 dw."""
    p, R, t = (np.asarray(x, dtype=float) for x in (p, R, t))
    d = p[:, None, :] + robot.platform_anchors @ R.transpose(0, 2, 1) - robot.base_anchors
    L0 = unstretched_lengths(robot, np.linalg.norm(d, axis=-1), t)
    _, jac, _ = wrench_balance(robot, L0, p, R, *static_load(robot, len(p)), bilateral=True)
    jac[:, 3:, :] -= _skew(p) @ jac[:, :3, :]   # moments about p: M_p = M_o - p x F
    return 0.5 * (jac + jac.transpose(0, 2, 1))


def soft_poses(robot, p, R, t, where, kappa):
    """Soft (M,) bool: where ``where`` (M,) and the platform's stiffness K
    (``platform_stiffness``) at tensions t (M, m) N and poses (p (M, 3) m, R (M, 3, 3)) is
    finite with its least eigenvalue below kappa (N/m, N m/rad). Compiled, one pose at a
    time (``elastic_kernel``: the same K, decided by a Cholesky factor of K - kappa I
    rather than an eigenvalue solver; a pose within rounding of kappa may fall either
    way; a large batch in blocks on threads)."""
    from .elastic_kernel import soft_kernel  # machine code: loaded only for elastic robots
    m = len(robot.base_anchors)
    f64 = [np.ascontiguousarray(x, dtype=float) for x in
           (robot.base_anchors, robot.platform_anchors, robot.load_point,
            np.broadcast_to(np.asarray(robot.cable_stiffness, dtype=float), (m,)), p, R, t)]
    force, moment, arm = (np.ascontiguousarray(x[0], dtype=float) for x in static_load(robot, 1))
    a, b, g, EA, p, R, t = f64
    where = np.ascontiguousarray(where, dtype=bool)
    return blocks(lambda i, j: soft_kernel(a, b, g, EA, p[i:j], R[i:j], t[i:j], force, moment, arm,
                                           where[i:j], float(kappa)), len(p))


def equilibrium_poses(robot, L0, p0, R0, force, moment, arm,
                      max_iterations=EQUILIBRIUM_ITERATIONS):
    """Equilibria of the platform on elastic cables of unstretched lengths L0 (M, m) m under
    the load wrench [force; moment + c x arm] (``wrench_balance``), by Newton with the exact
    Jacobian from the poses (p0 (M, 3) m, R0 (M, 3, 3)): first with cables that could push
    (smooth: no cable slackens on the way), then tension-only from there, which changes
    nothing where every tension is positive. Each step is halved (up to
    LINE_SEARCH_HALVINGS times) while the largest residual does not fall: far from the
    equilibrium a stiff cable's slack or the geometric stiffness can make the full step
    overshoot; a pose no step improves is stuck. Converged when the residual is below
    EQUILIBRIUM_TOL times the largest of the force's norm and 1 N; a slack cable is allowed
    (its tension is zero), a singular Jacobian is not converged. Compiled, one pose at a
    time (``elastic_kernel``, the same algebra as ``wrench_balance``)."""
    from .elastic_kernel import equilibrium_kernel  # machine code: loaded only for elastic robots
    m = len(robot.base_anchors)
    force, moment, arm = (np.ascontiguousarray(x, dtype=float) for x in (force, moment, arm))
    tol = EQUILIBRIUM_TOL * np.maximum(1.0, np.linalg.norm(force, axis=1))
    p, R, t, residual, ok = equilibrium_kernel(
        np.ascontiguousarray(robot.base_anchors, dtype=float),
        np.ascontiguousarray(robot.platform_anchors, dtype=float),
        np.ascontiguousarray(robot.load_point, dtype=float),
        np.broadcast_to(np.asarray(robot.cable_stiffness, dtype=float), (m,)).copy(),
        np.ascontiguousarray(L0, dtype=float), np.ascontiguousarray(p0, dtype=float),
        np.ascontiguousarray(R0, dtype=float), force, moment, arm, tol, max_iterations,
        LINE_SEARCH_HALVINGS)
    return Equilibria(p=p, R=R, tensions=t, residual=residual, ok=ok)


def _skew(v):
    """[v]x (..., 3, 3) of vectors v (..., 3)."""
    z = np.zeros(v.shape[:-1])
    return np.stack([np.stack([z, -v[..., 2], v[..., 1]], -1),
                     np.stack([v[..., 2], z, -v[..., 0]], -1),
                     np.stack([-v[..., 1], v[..., 0], z], -1)], -2)
