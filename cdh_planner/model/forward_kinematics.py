"""Forward kinematics of many cable-length vectors at once (numpy, vectorised).

    fk = forward_kinematics_many(robot, lengths, p0, R0)   # (M, 6); seeds (M, 3), (M, 3, 3)
    fk.p, fk.R, fk.residual, fk.ok                          # (M, 3), (M, 3, 3), (M,), (M,)

The same Newton on SE(3) as ``model.kinematics.forward_kinematics`` (one pose, with
backtracking and reasons), run on M poses together: p <- p + dp, R <- exp([w]x) R with
J [dp; w] = lengths - l(p, R), J the length Jacobian. Each pose starts from its own seed
(the planned pose at that instant), where Newton converges quadratically; a pose that
does not reach ``tol`` in ``max_iterations`` is reported with ``ok`` False (the caller
decides), never raised.
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from .kinematics import TOL_M

MAX_ITERATIONS = 20


@dataclass(frozen=True)
class ManyPoses:
    """Poses p (M, 3) m, R (M, 3, 3), the largest cable length error ``residual`` (M,) m
    and ``ok`` (M,) where it is within the tolerance."""

    p: np.ndarray
    R: np.ndarray
    residual: np.ndarray
    ok: np.ndarray


def forward_kinematics_many(robot, lengths, p0, R0, tol=TOL_M, max_iterations=MAX_ITERATIONS):
    """The poses whose cable lengths are ``lengths`` (M, 6) m, by Newton from the seeds
    (``p0`` (M, 3) m, ``R0`` (M, 3, 3)), to ``tol`` m per m of the longest cable."""
    L = np.asarray(lengths, dtype=float)
    p = np.array(p0, dtype=float)
    R = np.array(R0, dtype=float)
    tol = tol * np.maximum(1.0, np.max(L, axis=1))
    idx = np.arange(len(L))    # the poses still iterating
    for _ in range(max_iterations):
        Rb = R[idx] @ robot.platform_anchors.T               # (m, 3, 6): R b_i as columns
        d = p[idx, :, None] + Rb - robot.base_anchors.T       # (m, 3, 6)
        length = np.sqrt(np.einsum("nik,nik->nk", d, d))
        error = length - L[idx]
        active = np.max(np.abs(error), axis=1) > tol[idx]
        if not active.any():
            break
        idx, d, Rb, error = idx[active], d[active], Rb[active], error[active]
        u = d / length[active][:, None, :]
        J = np.swapaxes(np.concatenate([u, np.cross(Rb, u, axis=1)], axis=1), 1, 2)  # (m, 6, 6)
        try:
            step = np.linalg.solve(J, -error[..., None])[..., 0]
        except np.linalg.LinAlgError:  # a singular Jacobian: the least-squares step
            step = (np.linalg.pinv(J) @ -error[..., None])[..., 0]
        p[idx] += step[:, :3]
        R[idx] = Rotation.from_rotvec(step[:, 3:]).as_matrix() @ R[idx]
    d = p[:, :, None] + R @ robot.platform_anchors.T - robot.base_anchors.T
    residual = np.max(np.abs(np.sqrt(np.einsum("nik,nik->nk", d, d)) - L), axis=1)
    return ManyPoses(p=p, R=R, residual=residual, ok=residual <= tol)
