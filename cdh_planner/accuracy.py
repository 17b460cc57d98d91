"""Pose accuracy from the winches (numpy; the error map and the zonotope maximum compiled in
``accuracy_kernel``): how far the platform can be from a planned
pose when every winch realises its cable length only within +- e_i (``robot.length_error``,
m). The paper's first item of future work ("propagating known bounds on the position error
of the actuators to a bound on the platform pose").

The map. At a pose let A (6 x m) have columns [u_i; r_i x u_i], u_i the unit cable vector
from the base anchor to the platform anchor and r_i = R b_i the platform anchor from the
platform's origin, so that a small motion dx = [dp; dw] (dp m of the platform origin, dw
rad a rotation vector, both in the base frame) changes the lengths by A^T dx. A cable of
unstretched length L0_i carries t_i = k_i (L_i(x) - L0_i), k_i = EA_i / L0_i
(``model.elastic``; L0 from the nominal tensions, ``wrench.rule_tensions``),
and the platform is in equilibrium when A t balances the load. A winch error dl in L0
moves the platform, to first order and leaving out the geometric stiffness (the tensions'
own change of direction, t / L against EA / L0), by

    dx = G dl,   G = (A K A^T)^-1 A K,   K = diag(k_i).

(The issue writes -(A K A^T)^-1 A K with u_i pointing to the winch; the norms are the same.)
For six cables G = A^-T whatever K is (rigid and elastic agree). A rigid robot with more
than six cables has no K: we take equal EA (K = diag(1 / L_i), EA cancels), the limit of
stiff equal cables.

The accuracy at the pose is max ||G_p dl|| (m, position rows) and max ||G_w dl|| (rad,
rotation rows) over the box |dl_i| <= e_i, computed EXACTLY (``box_max_norm``): a convex
function's maximum over the box is at a vertex of the zonotope Z = M box (M 3 x m), and Z
in R^3 has O(m^2) vertices: each maximises c . z for c in a cell of the arrangement of the
great circles c . g_i = 0 (g_i = e_i M[:, i]); every cell has a corner c = +-(g_i x g_j), and
the vertices of Z around that corner are sign(M^T c) with the signs of g_i and g_j free
(4 per pair; -c gives their negatives, the same norms). Poses where that is not reliable in
floating point (two generators within PARALLEL_TOL of parallel, a third within ORTHO_TOL of
the plane of two) are searched over all 2^m vertices when m <= BRUTE_FORCE_MAX_CABLES, else
given the upper bound sum_i |g_i| (never below the exact value). Generators shorter than
TINY of the largest are left out and their lengths added: the result is then above the
exact value by at most that sum (1e-13 of it).
"""

from dataclasses import dataclass

import numpy as np

from .errors import InputError
from .wrench import rule_tensions
from .model import elastic
from .model.pose import rotation_tt
from .parallel import blocks

PARALLEL_TOL = 1e-6   # sin of the angle between two generators below which they count as parallel
ORTHO_TOL = 1e-9      # |g_k . c| / (|g_k| |c|) below which g_k counts as in the plane of a pair
TINY = 1e-13          # generators shorter than this times the largest are left out (added)
BRUTE_FORCE_MAX_CABLES = 16  # degenerate poses: all 2^m vertices up to here, else the bound
SINGULAR_SCALE = 1e-12  # sqrt(det A A^T) below this: A singular, the accuracy is inf


@dataclass(frozen=True)
class Accuracy:
    """The worst platform error over the winch error box at N poses: ``position_m`` (N,) m
    (the platform origin), ``orientation_rad`` (N,) rad (the rotation angle); inf where
    the pose is singular."""

    position_m: np.ndarray
    orientation_rad: np.ndarray


def has_accuracy(robot):
    """Does the robot file give its winches an error bound (``robot.length_error``)?"""
    return robot.length_error is not None


def error_map(robot, p, R, tensions=None):
    """G (N, 6, m): dx = G dl, the platform motion [dp m; dw rad] of winch errors dl (m) in
    the unstretched lengths (module docstring); nan where the pose is singular. A (N, 6, m)
    has columns [u_i; (R b_i) x u_i] at the poses; k_i = EA_i / L0_i, L0 the unstretched
    lengths that carry the nominal tensions (``tensions`` (N, m) N if known, a
    Feasibility's, else ``rule_tensions``'s t0); rigid cables 1 / L_i (equal EA). Compiled,
    one pose at a time (``accuracy_kernel.error_map_kernel``: numpy's batched products and
    solves spent 3 us a pose on temporaries)."""
    from .accuracy_kernel import error_map_kernel  # machine code: loaded only when needed
    return error_map_kernel(*_map_inputs(robot, p, R, tensions), SINGULAR_SCALE)


def _map_inputs(robot, p, R, tensions):
    """The error map kernels' arguments of the poses (p (N, 3) m, R (N, 3, 3)): anchors,
    p, R, EA (m,), the nominal tensions t (N, m) N and whether K is the elastic one (six
    cables: G = A^-T whatever K is; rigid cables: equal EA)."""
    p = np.ascontiguousarray(np.atleast_2d(np.asarray(p, dtype=float)))
    R = np.ascontiguousarray(np.asarray(R, dtype=float).reshape(-1, 3, 3))
    m = len(robot.base_anchors)
    stiff = elastic.is_elastic(robot) and m > 6
    if stiff:
        t = rule_tensions(robot, p, R)[0] if tensions is None else tensions
        EA = np.broadcast_to(np.asarray(robot.cable_stiffness, dtype=float), (m,))
    else:
        t, EA = np.zeros((len(p), m)), np.ones(m)
    return (np.ascontiguousarray(robot.base_anchors, dtype=float),
            np.ascontiguousarray(robot.platform_anchors, dtype=float), p, R,
            np.ascontiguousarray(EA), np.ascontiguousarray(t, dtype=float), stiff)


def pose_accuracy(robot, p, tau=None, R=None, tensions=None):
    """The Accuracy of poses (p (N, 3) m, tau (N, 3) rad or R (N, 3, 3)) of a robot with
    ``length_error`` (module docstring); ``tensions``: as ``error_map``'s. One compiled pass
    (``accuracy_kernel.accuracy_kernel``: the error map and the zonotope maximum of its
    rows, the same numbers as ``box_max_norm`` of ``error_map``'s; a large batch in blocks
    on threads, ``parallel.blocks``) where the pose is
    regular and its generators are not degenerate; the others (singular, a tiny, parallel
    or coplanar generator) by ``error_map`` and ``box_max_norm``."""
    from .accuracy_kernel import accuracy_kernel, error_map_kernel
    if R is None:
        R = rotation_tt(np.atleast_2d(np.asarray(tau, dtype=float)))
    inputs = _map_inputs(robot, p, R, tensions)
    m = len(robot.base_anchors)
    e = np.ascontiguousarray(np.broadcast_to(np.asarray(robot.length_error, dtype=float), (m,)))
    a, b, p, R, EA, t, stiff = inputs
    out, other = blocks(lambda i, j: accuracy_kernel(a, b, p[i:j], R[i:j], EA, t[i:j], stiff,
                                                     SINGULAR_SCALE, e, TINY, PARALLEL_TOL,
                                                     ORTHO_TOL), len(p))
    if other.any():
        G = error_map_kernel(a, b, p[other], R[other], EA, t[other], stiff, SINGULAR_SCALE)
        out[other, 0], out[other, 1] = box_max_norm(G[:, :3], e), box_max_norm(G[:, 3:], e)
    return Accuracy(out[:, 0].copy(), out[:, 1].copy())


@dataclass(frozen=True)
class AccuracyLimits:
    """The planner's accuracy constraint: ``position_m`` (m) and ``orientation_rad`` (rad),
    0 where off. A pose's accuracy margin is 1 - error / limit (normalised like the wrench
    margin: 1 exact, 0 at the limit), the least of the two set."""

    position_m: float
    orientation_rad: float

    def margins(self, robot, p, R, tensions=None):
        """Margins (N,) and bindings (N,) ("accuracy_position" or "accuracy_orientation")
        of poses (p (N, 3) m, R (N, 3, 3)); -inf where singular."""
        acc = pose_accuracy(robot, p, R=R, tensions=tensions)
        terms = [(1.0 - err / limit, name) for err, limit, name in (
            (acc.position_m, self.position_m, "accuracy_position"),
            (acc.orientation_rad, self.orientation_rad, "accuracy_orientation")) if limit > 0]
        margin, binding = terms[0][0], np.full(len(acc.position_m), terms[0][1], dtype=object)
        for m, name in terms[1:]:
            binding = np.where(m < margin, name, binding)
            margin = np.minimum(margin, m)
        return margin, binding

    def combine(self, margin, binding, robot, p, R, tensions=None):
        """The least of wrench margins (N,) and these accuracy margins, with its binding,
        as ``scene.margin.combine`` joins the collision margin."""
        am, ab = self.margins(robot, p, R, tensions)
        worse = am < margin
        return np.where(worse, am, margin), np.where(worse, ab, binding)

    def describe(self, robot, p, R):
        """None if the pose (p (3,) m, R (3, 3)) keeps the limits, else one line saying which
        error exceeds which setting."""
        acc = pose_accuracy(robot, p[None], R=R[None])
        for err, limit, what, unit, scale in (
                (acc.position_m[0], self.position_m, "position", "mm", 1e3),
                (acc.orientation_rad[0], self.orientation_rad, "orientation", "mrad", 1e3)):
            if limit > 0 and not err < limit:
                return (f"{what} error {err * scale:.4g} {unit} over the winches' length error "
                        f"exceeds planner.accuracy_{what}_{'m' if unit == 'mm' else 'rad'} "
                        f"({limit * scale:g} {unit})")
        return None


def accuracy_limits(robot, position_m, orientation_rad,
                    names=("planner.accuracy_position_m", "planner.accuracy_orientation_rad")):
    """The AccuracyLimits of the planner settings (m, rad; 0: off), None when both are off;
    InputError naming the setting (``names``: of the position and orientation limits) when
    the robot has no ``length_error``."""
    if not (position_m > 0 or orientation_rad > 0):
        return None
    if not has_accuracy(robot):
        name, value = ((names[0], position_m) if position_m > 0 else (names[1], orientation_rad))
        raise InputError(name, value, "needs robot.length_error (the winches' length error "
                                      "bound, m) in the robot file")
    return AccuracyLimits(float(position_m), float(orientation_rad))


def bound(M, e):
    """The cheap upper bound sum_i e_i |M[:, i]| (N,) of ``box_max_norm``."""
    return np.sum(np.abs(e) * np.linalg.norm(M, axis=-2), axis=-1)


def box_max_norm(M, e):
    """max ||M dl|| over |dl_i| <= e_i, exact (module docstring): M (N, 3, m), e (m,) or
    scalar, result (N,); inf where M is not finite."""
    M = np.asarray(M, dtype=float)
    g = M * np.broadcast_to(np.asarray(e, dtype=float), M.shape[-1:])
    out = np.full(len(g), np.inf)
    ok = np.all(np.isfinite(g), axis=(1, 2))
    out[ok] = _zonotope_max(g[ok])
    return out


def _zonotope_max(g):
    """max ||sum_i s_i g_i|| over signs s, g (N, 3, m) finite generators (module docstring):
    the vertices around the pairs' corners by the compiled ``accuracy_kernel``, the poses
    without a usable pair here."""
    m = g.shape[-1]
    norms = np.linalg.norm(g, axis=1)  # (N, m)
    if m < 2:
        return norms.sum(axis=1)
    tiny = norms <= TINY * norms.max(axis=1, keepdims=True)
    g = np.ascontiguousarray(np.where(tiny[:, None, :], 0.0, g))
    extra = np.where(tiny, norms, 0.0).sum(axis=1)
    from .accuracy_kernel import vertex_max_kernel  # machine code: loaded only when needed
    best, degenerate, used = vertex_max_kernel(g, np.ascontiguousarray(norms), tiny,
                                               PARALLEL_TOL, ORTHO_TOL)
    single = ~used & ~degenerate  # at most one real generator: its length
    best = np.where(single, norms.sum(axis=1), best)
    for r in np.flatnonzero(degenerate):
        best[r] = (brute_force_max(g[r:r + 1])[0] if m <= BRUTE_FORCE_MAX_CABLES
                   else norms[r].sum())
    return best + extra


def brute_force_max(g):
    """max ||sum_i s_i g_i|| over all 2^m sign vectors s, g (N, 3, m): the exact value by
    enumeration (degenerate poses; 2^16 vertices take ~10 ms)."""
    m = g.shape[-1]
    out = np.zeros(len(g))
    step = 1 << min(m, 14)
    for start in range(0, 1 << m, step):
        codes = np.arange(start, min(start + step, 1 << m))
        S = 1.0 - 2.0 * ((codes[:, None] >> np.arange(m)) & 1)  # (V, m)
        out = np.maximum(out, np.linalg.norm(np.einsum("vk,nxk->nvx", S, g), axis=2).max(axis=1))
    return out
