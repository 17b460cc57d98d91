"""Forward kinematics of many cable-length vectors at once (numpy, vectorised).

    fk = forward_kinematics_many(robot, lengths, p0, R0)   # (M, 6); seeds (M, 3), (M, 3, 3)
    fk.p, fk.R, fk.residual, fk.ok                          # (M, 3), (M, 3, 3), (M,), (M,)
    p, R = current_pose(robot, lengths, guess=(p, R))       # one pose from measured lengths

The same Newton on SE(3) as ``model.kinematics.forward_kinematics`` (one pose, with
backtracking and reasons), run on M poses together: p <- p + dp, R <- exp([w]x) R with
J [dp; w] = lengths - l(p, R), J the length Jacobian. Each pose starts from its own seed
(the planned pose at that instant), where Newton converges quadratically; a pose that
does not reach ``tol`` in ``max_iterations`` is reported with ``ok`` False (the caller
decides), never raised.
"""

from dataclasses import dataclass

import numpy as np
from ..ports import Rotation

from ..errors import InputError
from .elastic import stretched_lengths
from .kinematics import LSQ_RTOL, TOL_M, cable_lengths, forward_kinematics, rotation_vector_exp
from .pose import rotation_angle_between

MAX_ITERATIONS = 20
# rad: a pose found from the last known one but turned further than this from it is not
# taken on trust (a platform does not turn so far between two readings; Newton does, to a
# twin or, with more than six cables, a least-squares local minimum): the seeds decide
GUESS_TURN_RAD = 0.5
LSQ_FLOOR_M = 1e-9  # m > 6 cables: a length error this small (per m of cable) is converged


@dataclass(frozen=True)
class ManyPoses:
    """Poses p (M, 3) m, R (M, 3, 3), the largest cable length error ``residual`` (M,) m
    and ``ok`` (M,) where it is within the tolerance (with m > 6 cables: where the
    least-squares pose is reached, the residual telling how consistent the lengths are)."""

    p: np.ndarray
    R: np.ndarray
    residual: np.ndarray
    ok: np.ndarray


def forward_kinematics_many(robot, lengths, p0, R0, tol=TOL_M, max_iterations=MAX_ITERATIONS):
    """The poses whose cable lengths are ``lengths`` (M, m) m, by Newton from the seeds
    (``p0`` (M, 3) m, ``R0`` (M, 3, 3)), to ``tol`` m per m of the longest cable; with
    m > 6 the least-squares poses (Gauss-Newton, as ``kinematics.forward_kinematics``:
    converged when the length errors are orthogonal to the Jacobian's columns to LSQ_RTOL)."""
    L = np.asarray(lengths, dtype=float)
    square = L.shape[1] == 6
    stationary = np.zeros(len(L), dtype=bool)
    p = np.array(p0, dtype=float)
    R = np.array(R0, dtype=float)
    # m > 6: rounding keeps |J^T e| from the stationarity test near e = 0: a nanometre is exact
    tol = (tol if square else max(tol, LSQ_FLOOR_M)) * np.maximum(1.0, np.max(L, axis=1))
    idx = np.arange(len(L))    # the poses still iterating
    for _ in range(max_iterations):
        Rb = R[idx] @ robot.platform_anchors.T               # (m, 3, 6): R b_i as columns
        d = p[idx, :, None] + Rb - robot.base_anchors.T       # (m, 3, 6)
        length = np.sqrt(np.einsum("nik,nik->nk", d, d))
        error = length - L[idx]
        active = np.max(np.abs(error), axis=1) > tol[idx]
        u = d / length[:, None, :]
        J = np.swapaxes(np.concatenate([u, np.cross(Rb, u, axis=1)], axis=1), 1, 2)  # (k, m, 6)
        if not square:  # the least-squares pose is reached: |J^T e| small against |J| |e|
            g = np.einsum("nij,ni->nj", J, error)
            done = np.linalg.norm(g, axis=1) <= LSQ_RTOL * np.linalg.norm(J, axis=(1, 2)) * \
                np.linalg.norm(error, axis=1)
            stationary[idx[done]] = True
            active &= ~done
        if not active.any():
            break
        idx, J, error = idx[active], J[active], error[active]
        try:
            step = np.linalg.solve(J, -error[..., None])[..., 0] if square else \
                np.linalg.solve(np.swapaxes(J, 1, 2) @ J, -g[active][..., None])[..., 0]
        except np.linalg.LinAlgError:  # a singular Jacobian: the least-squares step
            step = (np.linalg.pinv(J) @ -error[..., None])[..., 0]
        p[idx] += step[:, :3]
        R[idx] = Rotation.from_rotvec(step[:, 3:]).as_matrix() @ R[idx]
    d = p[:, :, None] + R @ robot.platform_anchors.T - robot.base_anchors.T
    residual = np.max(np.abs(np.sqrt(np.einsum("nik,nik->nk", d, d)) - L), axis=1)
    return ManyPoses(p=p, R=R, residual=residual, ok=(residual <= tol) | stationary)


# Seeds of a pose search without a guess: the platform level (R = I) first, then turned
# about the base z axis and tilted, each with p from the lengths (``_position_seeds``).
_SEED_TURNS = (0.0, np.pi / 2, -np.pi / 2, np.pi)
_SEED_TILTS = (np.zeros(3), np.array([0.4, 0.0, 0.0]), np.array([-0.4, 0.0, 0.0]),
               np.array([0.0, 0.4, 0.0]), np.array([0.0, -0.4, 0.0]))


def nearest_waypoint(robot, lengths, p, R):
    """Of poses (a path's waypoints: p (N, 3) m, R (N, 3, 3)), the pose (p_k, R_k) whose
    cable lengths are nearest ``lengths`` (m, largest difference), all at once: a start for
    ``current_pose``'s Newton, since a hexapod has several poses for the same lengths.
    None for no poses."""
    if not len(p):
        return None
    d = p[:, None, :] + np.einsum("nij,kj->nki", R, robot.platform_anchors) - robot.base_anchors
    k = int(np.argmin(np.max(np.abs(np.linalg.norm(d, axis=2) - np.asarray(lengths)), axis=1)))
    return p[k], R[k]


def _mismatch(robot, lengths, pose):
    """The largest difference (m) between the cable lengths of ``pose`` (p, R) and ``lengths``."""
    return float(np.max(np.abs(cable_lengths(robot, *pose) - np.asarray(lengths, dtype=float))))


def measured_cable_lengths(robot, lengths, tensions):
    """The cable lengths (m,) m of the winches' measured ``lengths`` (m,) m: with elastic
    cables (``robot.cable_stiffness``) and measured ``tensions`` (m,) N, the winches pay
    out unstretched cable, which is L0 (1 + t / EA) long (``elastic.stretched_lengths``;
    a negative measured tension counts as slack); rigid cables or no tensions (None): the
    lengths themselves. InputError (``joint_states.effort``) for tensions that are not
    one finite number per winch."""
    L = np.asarray(lengths, dtype=float)
    if tensions is None:
        return L
    t = np.asarray(tensions, dtype=float)
    if t.shape != L.shape or not np.all(np.isfinite(t)):
        raise InputError("joint_states.effort", t.tolist(),
                         "expected one finite tension (N) per winch")
    return stretched_lengths(robot, L, np.maximum(t, 0.0))


def current_pose(robot, lengths, guess=None, feasible=None, known=()):
    """The platform pose (p (3,) m, R (3, 3)) whose cable lengths are ``lengths`` (m,) m,
    by Newton (``forward_kinematics``) from ``guess`` = (p, R), the last known pose.

    A hexapod's forward kinematics has several solutions (for planar anchor sets, at
    least the mirror image through the base plane); Newton from the last known pose finds
    the one the platform is on as long as it moved little since. Without a guess, Newton
    runs from 20 orientations (level, turned about z, tilted by 0.4 rad), each with one or
    two positions fitted to the lengths (``_position_seeds``), ~30 ms; of the solutions
    that explain the lengths best (``likeliest_pose``: with more than six cables a
    least-squares point may be a worse local minimum) a wrench-feasible one is preferred
    (the platform hangs in taut cables), then the least tilted (z axis nearest the
    base's). Lengths alone cannot tell feasible solutions apart:
    Robot 2's free-flight goal (config/problems) has a feasible twin with the same lengths
    tilted 3.06 rad, nearly upside down, and its pose p (0.02, -0.01, 0.30) m, tau (0.3,
    0.4, 0.1) rad one 9 cm higher and less tilted, which is what the search returns. Pass a
    guess whenever a pose is known; when Newton fails from it (the platform moved far
    since) or ends turned more than GUESS_TURN_RAD from it, the seeds are searched as
    without one (that end one of the solutions). ``known``: more poses the platform may be
    near (a plan's ends), Newton from each as from the guess; of the ends that explain the
    lengths alike (``likeliest_pose``'s band: with more than six cables a wrong last pose
    can be a least-squares local minimum, which Newton from it keeps), the one from the
    start nearest in cable lengths (a twin is told apart by where it was last).

    InputError (field ``joint_states``) naming why when no pose is found (singular cable
    Jacobian, no convergence) or the lengths are not numbers > 0. ``feasible(p, R) -> bool``
    tells the poses the platform can hang in (the caller's wrench check: model/ knows no
    wrenches, ``ros.winches.current_pose`` passes ``wrench.wrench_feasibility``); None: all.
    """
    L = np.asarray(lengths, dtype=float)
    if L.shape != (len(robot.winch_names),) or not np.all(np.isfinite(L)) or np.any(L <= 0):
        raise InputError("joint_states", np.asarray(lengths).tolist(),
                         "expected one finite cable length > 0 (m) per winch")
    near, found, trusted = None, [], []
    for p0, R0 in ([guess] if guess is not None else []) + list(known):
        fk = forward_kinematics(robot, L, p0, R0)
        turned = rotation_angle_between(fk.R, np.asarray(R0, dtype=float))
        if fk.ok and turned <= GUESS_TURN_RAD:
            trusted.append((_mismatch(robot, L, (p0, R0)), fk))
            continue
        # the platform is far from that pose (moved while not watched, a stale guess), or
        # Newton wandered off to another solution or a least-squares local minimum: search
        # as without a guess rather than refuse, that solution a candidate
        near = near or (fk.message if not fk.ok else f"Newton from a known pose turned {turned:.2f} rad")
        found += [fk] if fk.ok else []
    if trusted:
        band = _residual_band([fk for _, fk in trusted], np.max(L))
        best = min((t for t in trusted if t[1].residual <= band), key=lambda t: t[0])[1]
        return best.p, best.R
    reasons = []
    for R0 in _rotation_seeds():
        for p0 in _position_seeds(robot, L, R0):
            try:
                fk = forward_kinematics(robot, L, p0, R0)
            except InputError as exc:   # a seed beyond the position limits
                reasons.append(str(exc))
                continue
            if not fk.ok:
                reasons.append(fk.message)
                continue
            found.append(fk)
    if not found:
        not_near = "near the last known one nor " if near else ""
        raise InputError("joint_states", L.tolist(), f"no pose {not_near}from "
                                                     f"{len(reasons)} seeds: {near or reasons[0]}")
    best = likeliest_pose(found, np.max(L), feasible)
    return best.p, best.R


def likeliest_pose(solutions, longest_m, feasible=None):
    """Of converged forward kinematics ``solutions`` (ForwardKinematics) of one set of
    lengths, the pose the platform most likely is in. With more than six cables a
    solution may be a least-squares point that explains the lengths worse than another
    (a local minimum of the length error): only those within ``_residual_band`` of the
    least residual (twice it, and LSQ_FLOOR_M per m of the longest cable ``longest_m`` m
    for exact lengths) are candidates. Their residuals are alike (six cables: rounding;
    measured lengths: their noise), so they cannot choose: feasibility (``feasible(p, R)``,
    None: all) does, then the tilt (the platform's z axis from the base's), since a
    platform hanging in cables is seldom upside down."""
    band = _residual_band(solutions, longest_m)

    def key(fk):
        hangs = feasible is None or bool(feasible(fk.p, fk.R))
        return (not hangs, round(float(np.arccos(np.clip(fk.R[2, 2], -1.0, 1.0))), 6),
                fk.residual)

    return min((fk for fk in solutions if fk.residual <= band), key=key)


def _residual_band(solutions, longest_m):
    """The largest residual (m) of solutions that explain the lengths as well as the best
    of ``solutions``: twice its residual, and LSQ_FLOOR_M per m of the longest cable."""
    return 2.0 * min(fk.residual for fk in solutions) + LSQ_FLOOR_M * max(longest_m, 1.0)


def _rotation_seeds():
    for turn in _SEED_TURNS:
        Rz = rotation_vector_exp([0.0, 0.0, turn])
        for tilt in _SEED_TILTS:
            yield rotation_vector_exp(tilt) @ Rz


def _position_seeds(robot, L, R):
    """Positions p with |p - c_i| = L_i in the least-squares sense, c_i = a_i - R b_i.
    Differences of the squared equations are linear in p; when the c_i are (nearly)
    coplanar one direction is left free and the mean equation gives it as a quadratic:
    both roots (above and below the plane) are returned."""
    c = robot.base_anchors - robot.platform_anchors @ R.T
    c_mean = c.mean(axis=0)
    sq = np.sum(c * c, axis=1)
    A = -2.0 * (c - c_mean)
    b = (L ** 2 - np.mean(L ** 2)) - (sq - sq.mean())
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    if s[2] > 1e-6 * s[0]:
        return [np.linalg.lstsq(A, b, rcond=None)[0]]
    p0 = Vt[:2].T @ ((U[:, :2].T @ b) / s[:2])       # the solution in the plane
    n = Vt[2]
    # |p0 + t n|^2 - 2 c_mean . (p0 + t n) + mean |c|^2 = mean L^2, a quadratic in t
    half_b = float(n @ (p0 - c_mean))
    const = float(p0 @ p0 - 2 * c_mean @ p0 + sq.mean() - np.mean(L ** 2))
    disc = half_b ** 2 - const
    root = np.sqrt(max(disc, 0.0))
    return [p0 + (-half_b + root) * n, p0 + (-half_b - root) * n]
