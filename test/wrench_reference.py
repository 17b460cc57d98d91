"""Reference code the wrench tests compare the package with (never used by the package):
the facet test as written (a normal per 5-subset from J's columns, ``facet_margins``), the
tension rule before centring by numpy (``tension_rule``), a facet's normal, the ellipsoid
matrix in the base frame, and the facet test for any m (six cables included: the package
itself answers six cables by the closed form)."""

import numpy as np
from numba import njit

from cdh_planner import wrench
from cdh_planner.model.pose import rotation_tt
from cdh_planner.wrench.centred import CENTRE_MU  # noqa: F401  (re-exported)
from cdh_planner.wrench.compiled import centred_batch
from cdh_planner.wrench.facets import facet_subsets, facet_test as _facet_test
from cdh_planner.wrench.geometry import inverse_factor, wrench_transform
from cdh_planner.wrench.kernel import PARALLEL_MIN, RANK_TOL  # noqa: F401  (re-exported)


def facet_test(robot, p, tau=None, R=None):
    """The facet test's ``WrenchFeasibility`` of poses for any m >= 6 (p (N, 3) m, tau (N, 3)
    rad or R (N, 3, 3))."""
    p = np.atleast_2d(np.asarray(p, dtype=float))
    R = rotation_tt(np.atleast_2d(tau)) if R is None else np.asarray(R, dtype=float).reshape(-1, 3, 3)
    return _facet_test(robot, p, R)


def uncentred_rule(robot, J, c):
    """The compiled rule's t0 and v (N, m) N before centring, at poses with J (N, 6, m) and
    load points c (N, 3) m."""
    n = len(J)
    return centred_batch(np.ascontiguousarray(J), np.ascontiguousarray(c), robot.wrench_center_local,
                         inverse_factor(robot), robot.ellipsoid_frame == "load", robot.tension_min,
                         robot.tension_max, np.ones(n, np.bool_), np.zeros(n, np.bool_))


def tension_rule(robot, J, w0, L):
    """The weighted closed-form rule before centring at N poses, by numpy: t0 (N, m) N,
    v (N, m) N, from the package's one P (``wrench.tension_map``)."""
    mid = 0.5 * (robot.tension_min + robot.tension_max)
    P = wrench.tension_map(robot, J)
    t0 = mid + np.einsum("nij,nj->ni", P, w0 - J @ mid)
    return t0, np.linalg.norm(P @ L, axis=-1)


def ellipsoid_matrix(robot, c):
    """E in F1, shape (N, 6, 6): e^T E_F3 e for a load-frame ellipsoid, else constant."""
    if robot.ellipsoid_frame == "base":
        return np.broadcast_to(robot.ellipsoid_matrix, c.shape[:-1] + (6, 6))
    e = wrench_transform(c)
    return np.swapaxes(e, -1, -2) @ robot.ellipsoid_matrix @ e


@njit
def _normal_of(J, S, A, c, perm):
    """c (6,) orthogonal to the columns J[:, S] (S: 5 indices), by Gaussian elimination of
    their transpose with complete pivoting. Returns |last pivot| / |first pivot| (0: rank 4
    or less). ``A`` (5, 6), ``perm`` (6,) are scratch."""
    for r in range(5):
        for k in range(6):
            A[r, k] = J[k, S[r]]
    for k in range(6):
        perm[k] = k
    first = 0.0
    for step in range(5):
        best, bi, bj = -1.0, step, step
        for i in range(step, 5):
            for j in range(step, 6):
                v = abs(A[i, perm[j]])
                if v > best:
                    best, bi, bj = v, i, j
        if step == 0:
            first = best
        if best <= 0.0:
            return 0.0
        if bi != step:
            for k in range(6):
                A[step, k], A[bi, k] = A[bi, k], A[step, k]
        perm[step], perm[bj] = perm[bj], perm[step]
        pc = perm[step]
        for i in range(step + 1, 5):
            f = A[i, pc] / A[step, pc]
            if f != 0.0:
                for j in range(step, 6):
                    A[i, perm[j]] -= f * A[step, perm[j]]
    free = perm[5]
    c[free] = 1.0
    for step in range(4, -1, -1):
        s = -A[step, free]
        for j in range(step + 1, 5):
            s -= A[step, perm[j]] * c[perm[j]]
        c[perm[step]] = s / A[step, perm[step]]
    return best / first


@njit
def facet_margins(J, w0, L, tmin, tmax, subsets):
    """The facet test as written (a normal per subset from J's columns): the reference
    ``kernel.facet_kernel`` is tested against. Least facet slack of each pose: J (N, 6, m),
    w0 (N, 6), L (N, 6, 6), tension bounds
    (m,), subsets (K, 5). Returns (margin in N, normalised margin, its facet, its cables at
    t_max): facet = 2 k + (0 for +c, 1 for -c), k the subset, -1 (margins +inf) when no
    subset has rank 5; the last is a bit mask (bit i: cable i sits at t_max_i on that facet,
    the other cables off the subset at t_min)."""
    n, m = J.shape[0], J.shape[2]
    K = subsets.shape[0]
    out_n = np.full(n, np.inf)
    out_r = np.full(n, np.inf)
    arg_r = np.full(n, -1, np.int64)
    hi_r = np.zeros(n, np.int64)
    A = np.empty((5, 6))
    c = np.empty(6)
    perm = np.empty(6, np.int64)
    inS = np.zeros(m, np.bool_)
    for q in range(n):
        Jq, Lq, wq = J[q], L[q], w0[q]
        for k in range(K):
            S = subsets[k]
            if _normal_of(Jq, S, A, c, perm) <= RANK_TOL:
                continue
            for r in range(5):
                inS[S[r]] = True
            hp, hm, width = 0.0, 0.0, 0.0
            up, down = 0, 0  # cables at t_max on the +c facet, on the -c facet
            for i in range(m):
                if inS[i]:
                    continue  # c.J_i = 0 for the spanning columns: exactly, not rounded
                p = 0.0
                for r in range(6):
                    p += c[r] * Jq[r, i]
                a, b = p * tmin[i], p * tmax[i]
                if a > b:
                    hp += a
                    hm -= b
                else:
                    hp += b
                    hm -= a
                if p > 0.0:
                    up |= 1 << i
                else:
                    down |= 1 << i
                width += abs(p) * (tmax[i] - tmin[i])
            for r in range(5):
                inS[S[r]] = False
            cw, cc, lt = 0.0, 0.0, 0.0
            for r in range(6):
                cw += c[r] * wq[r]
                cc += c[r] * c[r]
                s = 0.0
                for j in range(6):
                    s += Lq[j, r] * c[j]
                lt += s * s
            lt = np.sqrt(lt)
            norm = np.sqrt(cc)
            for sign in range(2):
                slack = (hp - cw - lt) if sign == 0 else (hm + cw - lt)
                sn = slack / norm
                if sn < out_n[q]:
                    out_n[q] = sn
                sr = slack / width if width > 0.0 else (-np.inf if slack < 0.0 else np.inf)
                if sr < out_r[q]:
                    out_r[q], arg_r[q] = sr, 2 * k + sign
                    hi_r[q] = up if sign == 0 else down
    return out_n, out_r, arg_r, hi_r


def facet_normal(J, subset, up):
    """The outward unit normal n (6,) of a facet at a pose with Jacobian J (6, m): the one
    of subset ``subset`` (an index into facet_subsets(m)) whose cables at t_max are the bit
    mask ``up`` (as ``WrenchFeasibility.wrench_facet`` / ``wrench_facet_up`` give it), so
    that its slack is h(n) - n.w0 - |L^T n|."""
    m = J.shape[1]
    S = facet_subsets(m)[subset]
    c = np.empty(6)
    _normal_of(np.ascontiguousarray(J), S, np.empty((5, 6)), c, np.empty(6, np.int64))
    off = [i for i in range(m) if i not in S]
    agree = sum(np.sign(c @ J[:, i]) * (1.0 if up >> i & 1 else -1.0) for i in off)
    return (1.0 if agree >= 0 else -1.0) * c / np.linalg.norm(c)
