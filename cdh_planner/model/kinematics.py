"""Cable lengths of a pose (inverse kinematics) and the pose of measured cable lengths
(forward kinematics). SI units: m, rad. numpy only.

    lengths = cable_lengths(robot, p, R)                      # (m,) m
    fk = forward_kinematics(robot, lengths, p0, R0)           # Newton from (p0, R0)
    if fk.ok:
        p, R, residual = fk                                   # residual: max |l_i - L_i|, m
    else:
        print(fk.message)                                     # why: singular, no convergence

Cable i runs from base anchor a_i to platform anchor b_i: l_i = |p + R b_i - a_i|. A
hexapod's forward kinematics has several solutions; Newton from the last known pose finds
the one the platform is on, as long as it moved little since. The step is taken on SE(3):
p <- p + dp and R <- exp([w]x) R (w a rotation vector in the base frame), with the length
Jacobian d l_i = u_i . dp + ((R b_i) x u_i) . w (u_i the unit cable vector).

With m > 6 cables the lengths over-determine the pose: the step is Gauss-Newton (least
squares on the m lengths), converged when it no longer moves the pose, and the residual
(the largest |l_i - L_i| left, m) says how consistent the measured lengths are.
"""

from dataclasses import dataclass

import numpy as np

from ..errors import MAX_POSITION_M, InputError

TOL_M = 1e-12          # converged when every cable length is within this of its target
                       # (m, per m of the longest cable: rounding allows ~1e-15 of it)
MAX_ITERATIONS = 50
LSQ_RTOL = 1e-6  # m > 6: |J^T e| / (|J| |e|) at which the least-squares pose is reached
                 # (the pose then within ~1e-6 of the residual of it, times cond J)
# 1 / condition number of the length Jacobian below this: the pose is not determined by
# the lengths (a singular configuration)
MIN_RCOND = 1e-12
MIN_STEP = 1.0 / 1024  # smallest step fraction the backtracking tries before giving up


@dataclass(frozen=True)
class ForwardKinematics:
    """A forward kinematics solution: position ``p`` (3,) m, rotation ``R`` (3, 3), the
    largest cable length error ``residual`` (m), Newton ``iterations``, ``ok`` when
    converged, and otherwise ``message``, one line naming why (the pose and residual are
    then the last iterate). Unpacks as ``p, R, residual``."""

    p: np.ndarray
    R: np.ndarray
    residual: float
    iterations: int
    ok: bool
    message: str = ""

    def __iter__(self):
        return iter((self.p, self.R, self.residual))


def cable_lengths(robot, p, R):
    """Inverse kinematics: the m cable lengths (m) of pose (p (3,), R (3, 3))."""
    return np.linalg.norm(_cable_vectors(robot, np.asarray(p, float), np.asarray(R, float)), axis=1)


def length_jacobian(robot, p, R):
    """d lengths / d(p, w), shape (m, 6): row i = [u_i, (R b_i) x u_i], w the rotation
    vector of R <- exp([w]x) R (base frame)."""
    d = _cable_vectors(robot, p, R)
    u = d / np.linalg.norm(d, axis=1)[:, None]
    return np.hstack([u, np.cross(robot.platform_anchors @ R.T, u)])


def rotation_vector_exp(w):
    """exp([w]x): the rotation by |w| rad about w (Rodrigues)."""
    w = np.asarray(w, dtype=float)
    angle = float(np.linalg.norm(w))
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if angle < 1e-8:   # series to second order: exact to rounding at this size
        return np.eye(3) + K + 0.5 * K @ K
    return (np.eye(3) + np.sin(angle) / angle * K
            + (1.0 - np.cos(angle)) / angle ** 2 * K @ K)


def forward_kinematics(robot, lengths, p0, R0, tol=TOL_M, max_iterations=MAX_ITERATIONS):
    """The pose whose cable lengths are ``lengths`` (m,) m, by damped Newton from the pose
    (``p0`` (3,) m, ``R0`` (3, 3)) the platform was last known at, to ``tol`` m (per m of
    the longest cable) on every cable; with m > 6, the least-squares pose (Gauss-Newton,
    converged when the length errors are orthogonal to J's columns to LSQ_RTOL), its
    residual the largest length error left. A ForwardKinematics:
    never raises for a pose it cannot find (``ok`` False and ``message``: the Jacobian is
    singular, or the lengths are not reached in ``max_iterations``); InputError for
    lengths, p0 or R0 that are not finite numbers of the right shape (or R0 not a
    rotation)."""
    m = len(robot.base_anchors)
    L = _checked("lengths", lengths, (m,))
    if np.any(L <= 0):
        raise InputError("lengths", L.tolist(), "cable lengths must be > 0 m")
    p = _checked("p0", p0, (3,))
    R = _checked("R0", R0, (3, 3))
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) <= 0:
        raise InputError("R0", R.tolist(), "not a rotation matrix")
    R = _orthonormal(R)

    tol = tol * max(1.0, float(np.max(L)))
    error = cable_lengths(robot, p, R) - L
    residual = float(np.max(np.abs(error)))
    for it in range(max_iterations + 1):
        if residual <= tol:
            return ForwardKinematics(p, R, residual, it, True)
        if it == max_iterations:
            break
        J = length_jacobian(robot, p, R)
        rcond = 1.0 / np.linalg.cond(J)
        if not rcond > MIN_RCOND:
            return ForwardKinematics(p, R, residual, it, False,
                                     f"forward kinematics: singular cable Jacobian at "
                                     f"iteration {it} (1/cond {rcond:.2g}); cable length "
                                     f"error {residual:.3g} m")
        if m > 6 and _stationary(J, error):
            return ForwardKinematics(p, R, residual, it, True)  # the least-squares pose
        step = np.linalg.solve(J, -error) if m == 6 else np.linalg.lstsq(J, -error, rcond=None)[0]
        # backtracking: the largest fraction of the Newton step that lowers the error
        t = 1.0
        while True:
            p_new = p + t * step[:3]
            R_new = _orthonormal(rotation_vector_exp(t * step[3:]) @ R)
            e_new = cable_lengths(robot, p_new, R_new) - L
            if np.linalg.norm(e_new) < np.linalg.norm(error) or t <= MIN_STEP:
                break
            t *= 0.5
        if not np.linalg.norm(e_new) < np.linalg.norm(error):
            return ForwardKinematics(p, R, residual, it, False,
                                     f"forward kinematics: no step lowers the cable length "
                                     f"error {residual:.3g} m (iteration {it}): the lengths "
                                     f"may be unreachable from the start pose")
        p, R, error = p_new, R_new, e_new
        residual = float(np.max(np.abs(error)))
    return ForwardKinematics(p, R, residual, max_iterations, False,
                             f"forward kinematics: no convergence in {max_iterations} "
                             f"iterations; cable length error {residual:.3g} m")


def _stationary(J, error):
    """True at a least-squares minimum: the length errors (m,) orthogonal to the columns of
    the length Jacobian J (m, 6), relative to LSQ_RTOL."""
    return np.linalg.norm(J.T @ error) <= LSQ_RTOL * np.linalg.norm(J) * np.linalg.norm(error)


def _cable_vectors(robot, p, R):
    """d_i = p + R b_i - a_i, shape (m, 3)."""
    return p + robot.platform_anchors @ R.T - robot.base_anchors


def _orthonormal(R):
    """The rotation nearest R (polar factor): keeps rounding from accumulating."""
    U, _, Vt = np.linalg.svd(R)
    return U @ Vt


def _checked(field, value, shape):
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(field, value, f"expected numbers of shape {shape}") from None
    if a.shape != shape:
        raise InputError(field, value, f"expected shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)) or np.any(np.abs(a) > MAX_POSITION_M):
        raise InputError(field, a.tolist(), f"values must be finite and within "
                                            f"+-{MAX_POSITION_M:g}")
    return a
