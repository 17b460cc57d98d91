"""Wrench feasibility for any number of cables m >= 6 (maths: docs/more-cables.md).

The wrenches m cables can hold form the zonotope Z = {J t : t_min <= t <= t_max} (J is
6 x m, column i = [u_i; a_i x u_i]). Its facets lie on the hyperplanes spanned by 5
independent columns: for each 5-subset S of rank 5, c is orthogonal to the columns in S
and both signs of n = c / |c| are facet normals with support value
    h(n) = sum_i max(n.J_i t_min_i, n.J_i t_max_i).
The wrench ellipsoid {w0 + L u : |u| <= 1} (L L^T = E^-1 in the base frame) lies in Z iff
for every such n
    s(n) = h(n) - n.w0 - |L^T n| >= 0      (hyperplane shifting; Bouchard et al. 2010).
``margin_newtons`` is min s(n) (N, or N m: n mixes force and moment rows); the normalised
margin divides each slack by Z's width along n, h(n) + h(-n) = sum_i |n.J_i| (t_max_i -
t_min_i), before the minimum. With m = 6 the facet test is the paper's closed form and the
normalised margin its margin, exactly (docs/more-cables.md).

Tensions are not unique when m > 6. The envelope published per cable comes from one rule
a winch controller can run, affine in the wrench at each pose:
    t(w) = t0 + P (w - w0),   P = D J^T (J D J^T)^-1,   D = diag(t_max - t_min)^2,
P the range-weighted pseudo-inverse of the closed-form method (Pott, Bruckmann & Mikelsons
2009), so J t(w) = w, and t0 the *centred nominal*: the closed form's tensions toward the
middle of the range, t_mid + P (w0 - J t_mid), shifted in the null space of J to centre
the band (``_centre``: the maximiser of s + CENTRE_MU sum log(slacks - s), unique and smooth
in the pose). Over the ellipsoid the rule's tensions are exactly t0 +- v,
v_i = |row i of P L|; a controller applies t0 (published per waypoint) plus P (w - w0). With
m = 6, P = J^-1 and there is no null space: the paper's envelope. The rule may leave
[t_min, t_max] at a pose Z holds (an affine rule is a stronger demand than Z containing the
ellipsoid): ``tension_status`` then says "rule_exceeds_limits" (the band is still the
rule's, but no controller should use it).
With elastic cables (``robot.cable_stiffness``) under length control, the cables' stiffness,
not the rule, shares a wrench change: the band is v_i = |row i of P_K L|,
P_K = K J^T (J K J^T)^-1, K = diag(EA / L0) at the centred t0 (``stiffness_band``).
Units: m, N, N m.
"""

from dataclasses import dataclass
from functools import cached_property, lru_cache
from itertools import combinations

import numpy as np
from numba import njit, prange

from .feasibility import CONSTRAINTS, SINGULAR_DET, Feasibility, inverse_ellipsoid_factor
from .model.pose import rotation_tt

MIN_CABLES = 6
# a 5-subset whose last pivot is below this fraction of its first one is rank 4: it spans
# no facet (every facet hyperplane is spanned by some 5 independent columns)
RANK_TOL = 1e-12
# barrier weight of the centred nominal (normalised tensions): its least band slack is within
# 2 m CENTRE_MU of the best any null-space shift achieves. Numba freezes these constants into
# the cached machine code: after changing one, delete cdh_planner/__pycache__/zonotope*.nb*.
CENTRE_MU = 1e-4
CENTRE_TOL = 1e-9  # Newton decrement^2 / mu at which the centring stops
CENTRE_ITERATIONS = 50  # Newton steps at most (bounded work)
POLISH = 2  # full Newton steps after CENTRE_TOL is met (start-independent to rounding)
PARALLEL_CHUNK = 512  # poses per task of the threaded kernel
PARALLEL_MIN = 4096  # fewer poses than this: the serial kernel (thread start-up costs more)
STATUS_OK, STATUS_EXCEEDS, STATUS_INFEASIBLE, STATUS_SINGULAR = \
    "ok", "rule_exceeds_limits", "infeasible", "singular"


@lru_cache(maxsize=None)
def facet_subsets(m):
    """The 5-subsets of m cables, (C(m, 5), 5) int64, in itertools order."""
    return np.array(list(combinations(range(m), 5)), dtype=np.int64)


@njit(cache=True)
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


@njit(cache=True)
def facet_margins(J, w0, L, tmin, tmax, subsets):
    """The facet test as written (a normal per subset from J's columns): the reference
    ``evaluate_kernel`` is tested against. Least facet slack of each pose: J (N, 6, m),
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


# ---------------------------------------------------------------- the compiled per-pose kernel
# The same facet test as ``facet_margins`` (the direct transcription, kept as the reference
# the tests compare with), computed in the coordinates of a basis of 6 columns: with
# E = J_B^-1 (Gauss-Jordan, complete pivoting), N = E J has unit columns on the basis, so a
# subset S's normal is c = E^T y with y supported on the basis rows off S and orthogonal to
# the (at most m - 6) columns of S off the basis: a tiny null-vector problem (y = 1 for
# m = 6: c is a row of J^-1, the closed form). Then c.J_i = y.N_i, c.w0 = y.(E w0) and
# L^T c = (E L)^T y touch only the rows of y's support.

@njit(cache=True)
def _gauss_jordan(T, m, pivcol, rowof):
    """Reduce T (6, ncol) in place to E T, choosing 6 pivot columns among its first m by
    complete pivoting; pivcol[r] is row r's column, rowof[j] column j's row (-1: off the
    basis). Returns False if the first m columns have rank < 6."""
    ncol = T.shape[1]
    for j in range(m):
        rowof[j] = -1
    for r in range(6):
        best, bi, bj = 0.0, r, -1
        for i in range(r, 6):
            for j in range(m):
                if rowof[j] < 0 and abs(T[i, j]) > best:
                    best, bi, bj = abs(T[i, j]), i, j
        if bj < 0:
            return False
        if bi != r:
            for k in range(ncol):
                T[r, k], T[bi, k] = T[bi, k], T[r, k]
        piv = T[r, bj]
        for k in range(ncol):
            T[r, k] /= piv
        for i in range(6):
            f = T[i, bj]
            if i != r and f != 0.0:
                for k in range(ncol):
                    T[i, k] -= f * T[r, k]
                T[i, bj] = 0.0
        T[r, bj] = 1.0
        pivcol[r], rowof[bj] = bj, r
    return True


@njit(cache=True)
def _null_vector(M, k, y, perm):
    """y (k + 1,) with M[:k, :k + 1] y = 0 (M is overwritten), by Gaussian elimination with
    complete pivoting. Returns the last pivot's magnitude (0: rank < k); 1.0 when k = 0."""
    n = k + 1
    for j in range(n):
        perm[j] = j
    last = 1.0
    for step in range(k):
        best, bi, bj = -1.0, step, step
        for i in range(step, k):
            for j in range(step, n):
                v = abs(M[i, perm[j]])
                if v > best:
                    best, bi, bj = v, i, j
        if best <= 0.0:
            return 0.0
        if bi != step:
            for j in range(n):
                M[step, j], M[bi, j] = M[bi, j], M[step, j]
        perm[step], perm[bj] = perm[bj], perm[step]
        pc = perm[step]
        for i in range(step + 1, k):
            f = M[i, pc] / M[step, pc]
            if f != 0.0:
                for j in range(step, n):
                    M[i, perm[j]] -= f * M[step, perm[j]]
        last = best
    free = perm[k]
    y[free] = 1.0
    for step in range(k - 1, -1, -1):
        s = -M[step, free]
        for j in range(step + 1, k):
            s -= M[step, perm[j]] * y[perm[j]]
        y[perm[step]] = s / M[step, perm[step]]
    return last


@njit(cache=True)
def _householder_r(A, R, hv0, hvv):
    """R (6, 6), upper triangular, of the QR factorisation of A (m, 6); A keeps the
    reflectors below its diagonal, their first entries in hv0 (6,) and |v|^2 in hvv (6,)
    (``_null_basis`` forms Q's last m - 6 columns from them). Returns |det R|
    (= sqrt(det(A^T A)))."""
    m = A.shape[0]
    det = 1.0
    for j in range(6):
        s = 0.0
        for i in range(j, m):
            s += A[i, j] * A[i, j]
        norm = np.sqrt(s)
        if norm == 0.0:
            return 0.0
        alpha = -norm if A[j, j] >= 0.0 else norm
        v0 = A[j, j] - alpha
        vv = s - A[j, j] * A[j, j] + v0 * v0  # |v|^2, v = (v0, A[j+1:, j])
        A[j, j] = alpha
        hv0[j], hvv[j] = v0, vv
        for k in range(j + 1, 6):
            d = v0 * A[j, k]
            for i in range(j + 1, m):
                d += A[i, j] * A[i, k]
            f = 2.0 * d / vv
            A[j, k] -= f * v0
            for i in range(j + 1, m):
                A[i, k] -= f * A[i, j]
        det *= abs(alpha)
    for i in range(6):
        for j in range(6):
            R[i, j] = A[i, j] if j >= i else 0.0
    return det


@njit(cache=True)
def _null_basis(A, hv0, hvv, Q2):
    """Q2 (m, m - 6): the last columns of Q = H_0 ... H_5 from ``_householder_r``'s
    reflectors: an orthonormal basis of the null space of A^T."""
    m = A.shape[0]
    for c in range(m - 6):
        for i in range(m):
            Q2[i, c] = 0.0
        Q2[6 + c, c] = 1.0
        for j in range(5, -1, -1):
            d = hv0[j] * Q2[j, c]
            for i in range(j + 1, m):
                d += A[i, j] * Q2[i, c]
            f = 2.0 * d / hvv[j]
            Q2[j, c] -= f * hv0[j]
            for i in range(j + 1, m):
                Q2[i, c] -= f * A[i, j]


@njit(cache=True)
def _cholesky_solve(H, g, n, x):
    """x = H^-1 g for the symmetric positive definite H[:n, :n] (H is overwritten)."""
    for j in range(n):
        s = H[j, j]
        for k in range(j):
            s -= H[j, k] * H[j, k]
        H[j, j] = np.sqrt(max(s, 1e-300))
        for i in range(j + 1, n):
            s = H[i, j]
            for k in range(j):
                s -= H[i, k] * H[j, k]
            H[i, j] = s / H[j, j]
    for i in range(n):
        s = g[i]
        for k in range(i):
            s -= H[i, k] * x[k]
        x[i] = s / H[i, i]
    for i in range(n - 1, -1, -1):
        s = x[i]
        for k in range(i + 1, n):
            s -= H[k, i] * x[k]
        x[i] = s / H[i, i]


@njit(cache=True)
def _centre(lo, hi, Q2, z, warm=False):
    """The null-space shift z (k,) of the centred nominal (module doc): the maximiser of
    s + CENTRE_MU sum_j log(r_j) over (z, s), r the 2m slacks lo_i + Q2_i z - s and
    hi_i - Q2_i z - s (lo, hi: the normalised room below and above the band at z = 0), by
    Newton's method with an Armijo line search that stays inside. Strictly concave, so the
    maximiser is unique and smooth in the data; defined whether or not the band fits
    (s < 0 then). At most CENTRE_ITERATIONS steps (about 12 for 8 cables from z = 0).
    ``warm``: start from the given z (a neighbouring pose's answer: along a motion Newton
    then needs a few steps; the maximiser is the same, the start only changes rounding)."""
    m, k = Q2.shape
    n = k + 1
    mu = CENTRE_MU
    x = np.zeros(n)  # (z, s)
    r = np.empty(2 * m)
    if warm:
        for a in range(k):
            x[a] = z[a]
        _slacks(lo, hi, Q2, x, r)
        x[k] = r.min() - mu  # strictly inside
    else:
        x[k] = min(lo.min(), hi.min()) - mu  # strictly inside
    g = np.empty(n)
    H = np.empty((n, n))
    dx = np.empty(n)
    xt = np.empty(n)
    rt = np.empty(2 * m)
    polished = 0
    for _ in range(CENTRE_ITERATIONS):
        _slacks(lo, hi, Q2, x, r)
        g[:] = 0.0
        H[:, :] = 0.0
        g[k] = 1.0
        for j in range(2 * m):  # gradient g and minus the Hessian H (lower triangle)
            i, sg = (j, 1.0) if j < m else (j - m, -1.0)
            w1, w2 = mu / r[j], mu / (r[j] * r[j])
            for a in range(k):
                g[a] += sg * w1 * Q2[i, a]
                for b in range(a + 1):
                    H[a, b] += w2 * Q2[i, a] * Q2[i, b]
                H[k, a] -= sg * w2 * Q2[i, a]
            g[k] -= w1
            H[k, k] += w2
        for a in range(n):
            for b in range(a + 1, n):
                H[a, b] = H[b, a]
        _cholesky_solve(H, g, n, dx)
        dec = 0.0  # the Newton decrement squared: twice the rise left, about
        for a in range(n):
            dec += g[a] * dx[a]
        if dec <= CENTRE_TOL * mu:
            # POLISH more full steps: Newton converges quadratically here (an error e becomes
            # ~e^2 / r), so the answer is the maximiser to rounding whatever the start (cold,
            # or a neighbour's warm one; one step left 2e-11 of the range between them)
            if polished == POLISH:
                break
            polished += 1
            for a in range(n):
                xt[a] = x[a] + dx[a]
            _slacks(lo, hi, Q2, xt, rt)
            if not rt.min() > 0.0:
                break
            x[:] = xt
            continue
        phi = x[k] + mu * _log_product(r)
        # the slacks are affine in x: start the line search inside (ratio test), so that
        # it halves for the rise only, not to find the interior (21 halvings a pose before)
        _slacks(lo, hi, Q2, dx, rt)  # rt = r(dx) = r(0) + slope, r(0) = (lo, hi)
        step = 1.0
        for j in range(2 * m):
            slope = rt[j] - (lo[j] if j < m else hi[j - m])
            if slope < 0.0 and -0.99 * r[j] / slope < step:
                step = -0.99 * r[j] / slope
        accepted = False
        for _ in range(60):  # halve until inside and rising enough (Armijo)
            for a in range(n):
                xt[a] = x[a] + step * dx[a]
            _slacks(lo, hi, Q2, xt, rt)
            if rt.min() > 0.0:
                phit = xt[k] + mu * _log_product(rt)
                if phit >= phi + 0.25 * step * dec:
                    accepted = True
                    break
            step *= 0.5
        if not accepted:
            break  # no rise left above rounding
        x[:] = xt
    for a in range(k):
        z[a] = x[a]


@njit(cache=True)
def _log_product(r):
    """sum_j log(r_j) of positive r, by one log per 8 factors (the line search's hot loop);
    the sum of logs itself if a partial product leaves the double range."""
    total, prod = 0.0, 1.0
    for j in range(r.size):
        prod *= r[j]
        if j % 8 == 7:
            total += np.log(prod)
            prod = 1.0
    total += np.log(prod)
    if np.isfinite(total):
        return total
    total = 0.0
    for j in range(r.size):
        total += np.log(r[j])
    return total


@njit(cache=True)
def _slacks(lo, hi, Q2, x, r):
    """r (2m,): lo_i + Q2_i z - s, then hi_i - Q2_i z - s, at x = (z, s)."""
    m, k = Q2.shape
    for i in range(m):
        d = 0.0
        for a in range(k):
            d += Q2[i, a] * x[a]
        r[i] = lo[i] + d - x[k]
        r[m + i] = hi[i] - d - x[k]


@njit(cache=True)
def _forward(R, b, x):
    """x = R^-T b for upper-triangular R (6, 6)."""
    for i in range(6):
        s = b[i]
        for k in range(i):
            s -= R[k, i] * x[k]
        x[i] = s / R[i, i]


@njit(cache=True)
def _subset_normal(T, zrow, xcol, nx, M, y, perm):
    """y (nx + 1,) on the basis rows ``zrow`` off a subset, orthogonal to its off-basis
    columns ``xcol`` of N (T's first columns); closed forms for nx <= 2 (m = 8 needs no
    more). False when those columns are dependent (the subset has rank 4)."""
    if nx == 0:
        y[0] = 1.0
        return True
    if nx == 1:
        a0, a1 = T[zrow[0], xcol[0]], T[zrow[1], xcol[0]]
        y[0], y[1] = a1, -a0
        return max(abs(a0), abs(a1)) > RANK_TOL
    if nx == 2:
        a0, a1, a2 = T[zrow[0], xcol[0]], T[zrow[1], xcol[0]], T[zrow[2], xcol[0]]
        b0, b1, b2 = T[zrow[0], xcol[1]], T[zrow[1], xcol[1]], T[zrow[2], xcol[1]]
        y[0], y[1], y[2] = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
        return max(abs(y[0]), abs(y[1]), abs(y[2])) > RANK_TOL * max(
            abs(a0), abs(a1), abs(a2), abs(b0), abs(b1), abs(b2), 1.0)
    for i in range(nx):
        for b in range(nx + 1):
            M[i, b] = T[zrow[b], xcol[i]]
    return _null_vector(M, nx, y, perm) > RANK_TOL


@njit(cache=True)
def pose_geometry(p, R, a, b, g):
    """Per pose (p (N, 3) m, R (N, 3, 3)) of a robot with base anchors a (m, 3), platform
    anchors b (m, 3) and load point g (3,): cable lengths (N, m) m, unit vectors u (N, m, 3)
    from base to platform anchor, J (N, 6, m) with columns [u_i; a_i x u_i] (as
    ``feasibility.screw_jacobian``) and the load point c = p + R g (N, 3) m."""
    n, m = p.shape[0], a.shape[0]
    lengths = np.empty((n, m))
    u = np.empty((n, m, 3))
    J = np.empty((n, 6, m))
    c = np.empty((n, 3))
    d = np.empty(3)
    for q in range(n):
        Rq = R[q]
        for r in range(3):
            c[q, r] = p[q, r] + Rq[r, 0] * g[0] + Rq[r, 1] * g[1] + Rq[r, 2] * g[2]
        for i in range(m):
            for r in range(3):
                d[r] = p[q, r] + Rq[r, 0] * b[i, 0] + Rq[r, 1] * b[i, 1] + Rq[r, 2] * b[i, 2] - a[i, r]
            length = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
            lengths[q, i] = length
            s = 1.0 / length if length > 0.0 else 1.0
            for r in range(3):
                u[q, i, r] = d[r] * s
                J[q, r, i] = d[r] * s
            J[q, 3, i] = a[i, 1] * u[q, i, 2] - a[i, 2] * u[q, i, 1]
            J[q, 4, i] = a[i, 2] * u[q, i, 0] - a[i, 0] * u[q, i, 2]
            J[q, 5, i] = a[i, 0] * u[q, i, 1] - a[i, 1] * u[q, i, 0]
    return lengths, u, J, c


@njit(cache=True)
def evaluate_kernel(J, c, w_local, L3, load_frame, tmin, tmax, subsets, singular_det, centre=True):
    """Per pose: J (N, 6, m), load point c (N, 3). Returns sqrt(det J J^T) (N,), the facet
    margins (N, normalised, facet, cables at t_max: as ``facet_margins``) and the tension
    rule's t0, v (N, m) (module doc); margins -inf, t0 nan, v inf where singular."""
    out = _outputs(J.shape[0], J.shape[2])
    _evaluate_poses(0, J.shape[0], J, c, w_local, L3, load_frame, tmin, tmax, subsets, singular_det,
                    centre, *out)
    return out


@njit(cache=True, parallel=True)
def evaluate_kernel_parallel(J, c, w_local, L3, load_frame, tmin, tmax, subsets, singular_det,
                             centre=True):
    """``evaluate_kernel`` over chunks of PARALLEL_CHUNK poses on numba's threads."""
    n = J.shape[0]
    out = _outputs(n, J.shape[2])
    chunks = (n + PARALLEL_CHUNK - 1) // PARALLEL_CHUNK
    for k in prange(chunks):
        _evaluate_poses(k * PARALLEL_CHUNK, min(n, (k + 1) * PARALLEL_CHUNK), J, c, w_local, L3,
                        load_frame, tmin, tmax, subsets, singular_det, centre, *out)
    return out


@njit(cache=True)
def _outputs(n, m):
    """The kernel's output arrays, filled as for singular poses."""
    return (np.zeros(n), np.full(n, -np.inf), np.full(n, -np.inf), np.full(n, -1, np.int64),
            np.zeros(n, np.int64), np.full((n, m), np.nan), np.full((n, m), np.inf))


@njit(cache=True)
def _evaluate_poses(q0, q1, J, c, w_local, L3, load_frame, tmin, tmax, subsets, singular_det,
                    centre, scale, out_n, out_r, arg_r, hi_r, t0, v):
    """``evaluate_kernel`` for poses q0 <= q < q1, into its output arrays."""
    m = J.shape[2]
    K = subsets.shape[0]
    T = np.empty((6, m + 13))  # [J | I | w0 | L] -> [N | E | E w0 | E L]
    pivcol = np.empty(6, np.int64)
    rowof = np.empty(m, np.int64)
    zrow = np.empty(6, np.int64)
    zpos = np.empty(6, np.int64)
    xcol = np.empty(6, np.int64)
    inS = np.zeros(m, np.bool_)
    M = np.empty((5, 6))
    y = np.empty(6)
    perm = np.empty(6, np.int64)
    A = np.empty((m, 6))
    R = np.empty((6, 6))
    w0 = np.empty(6)
    L = np.empty((6, 6))
    Y = np.empty((6, 6))
    EE = np.empty((6, 6))
    GG = np.empty((6, 6))
    hv0 = np.empty(6)
    hvv = np.empty(6)
    Q2 = np.empty((m, max(m - 6, 0)))
    room_lo = np.empty(m)
    room_hi = np.empty(m)
    zc = np.empty(max(m - 6, 0))
    col = np.empty(6)
    a = np.empty(6)
    mid = 0.5 * (tmin + tmax)
    sqd = tmax - tmin  # D^(1/2)
    shift = np.zeros(m)  # the last centred pose's normalised null-space shift Q2 z
    centred = q0 - 2     # which pose that was
    for q in range(q0, q1):
        Jq = J[q]
        # w0 and L (L L^T = E^-1) in the base frame; a load-frame ellipsoid moves with c
        for r in range(6):
            w0[r] = w_local[r]
            for j in range(6):
                L[r, j] = L3[r, j]
        if load_frame:
            c0, c1, c2 = c[q, 0], c[q, 1], c[q, 2]
            w0[3] += c1 * w_local[2] - c2 * w_local[1]
            w0[4] += c2 * w_local[0] - c0 * w_local[2]
            w0[5] += c0 * w_local[1] - c1 * w_local[0]
            for j in range(6):
                L[3, j] += c1 * L3[2, j] - c2 * L3[1, j]
                L[4, j] += c2 * L3[0, j] - c0 * L3[2, j]
                L[5, j] += c0 * L3[1, j] - c1 * L3[0, j]
        for i in range(m):
            for r in range(6):
                A[i, r] = Jq[r, i]
        scale[q] = _householder_r(A, R, hv0, hvv)
        if not scale[q] > singular_det:
            continue
        for r in range(6):
            for i in range(m):
                T[r, i] = Jq[r, i]
            for j in range(6):
                T[r, m + j] = 1.0 if j == r else 0.0
                T[r, m + 7 + j] = L[r, j]
            T[r, m + 6] = w0[r]
        if not _gauss_jordan(T, m, pivcol, rowof):
            continue
        for r in range(6):  # Grams of E and E L: |c|^2 = y^T EE y, |L^T c|^2 = y^T GG y
            for r2 in range(r, 6):
                se, sg = 0.0, 0.0
                for j in range(6):
                    se += T[r, m + j] * T[r2, m + j]
                    sg += T[r, m + 7 + j] * T[r2, m + 7 + j]
                EE[r, r2], EE[r2, r], GG[r, r2], GG[r2, r] = se, se, sg, sg
        best_n, best_r = np.inf, np.inf
        for k in range(K):
            S = subsets[k]
            nx = 0
            for s in range(5):
                inS[S[s]] = True
                if rowof[S[s]] < 0:
                    xcol[nx] = S[s]
                    nx += 1
            nz = 0
            for r in range(6):
                if not inS[pivcol[r]]:
                    zrow[nz], zpos[r] = r, nz
                    nz += 1
            if not _subset_normal(T, zrow, xcol, nx, M, y, perm):
                for s in range(5):
                    inS[S[s]] = False
                continue  # rank 4: no facet
            # p_i = c.J_i = y.N_i for the cables off S (0 on S: exactly)
            hp, hm, width = 0.0, 0.0, 0.0
            up, down = 0, 0
            for i in range(m):
                if inS[i]:
                    continue
                if rowof[i] >= 0:
                    p = y[zpos[rowof[i]]]
                else:
                    p = 0.0
                    for b in range(nz):
                        p += y[b] * T[zrow[b], i]
                lo, hi = p * tmin[i], p * tmax[i]
                if lo > hi:
                    hp += lo
                    hm -= hi
                    down |= 1 << i
                else:
                    hp += hi
                    hm -= lo
                    up |= 1 << i
                width += abs(p) * (tmax[i] - tmin[i])
            for s in range(5):
                inS[S[s]] = False
            cw, cc, lt = 0.0, 0.0, 0.0
            for b in range(nz):
                rb = zrow[b]
                cw += y[b] * T[rb, m + 6]
                se, sg = 0.0, 0.0
                for b2 in range(nz):
                    se += EE[rb, zrow[b2]] * y[b2]
                    sg += GG[rb, zrow[b2]] * y[b2]
                cc += y[b] * se
                lt += y[b] * sg
            lt, norm = np.sqrt(max(lt, 0.0)), np.sqrt(cc)
            for sign in range(2):
                slack = (hp - cw - lt) if sign == 0 else (hm + cw - lt)
                if slack / norm < best_n:
                    best_n = slack / norm
                sr = slack / width if width > 0.0 else (-np.inf if slack < 0.0 else np.inf)
                if sr < best_r:
                    best_r, arg_r[q] = sr, 2 * k + sign
                    hi_r[q] = up if sign == 0 else down
        out_n[q], out_r[q] = best_n, best_r
        # the tension rule: R from K^T = D^(1/2) J^T = Q R, so J D J^T = R^T R
        for i in range(m):
            for r in range(6):
                A[i, r] = sqd[i] * Jq[r, i]
        _householder_r(A, R, hv0, hvv)
        for j in range(6):  # Y = R^-T L
            for r in range(6):
                col[r] = L[r, j]
            _forward(R, col, a)
            for r in range(6):
                Y[r, j] = a[r]
        for r in range(6):  # col = R^-T (w0 - J mid)
            s = w0[r]
            for i in range(m):
                s -= Jq[r, i] * mid[i]
            a[r] = s
        _forward(R, a, col)
        for i in range(m):
            for r in range(6):
                a[r] = Jq[r, i]
            _forward(R, a, y)  # y = R^-T J_i
            d = sqd[i] * sqd[i]
            s = 0.0
            for r in range(6):
                s += y[r] * col[r]
            t0[q, i] = mid[i] + d * s
            vv = 0.0
            for j in range(6):
                s = 0.0
                for r in range(6):
                    s += y[r] * Y[r, j]
                vv += s * s
            v[q, i] = d * np.sqrt(vv)
        # the centred nominal (wrench-feasible poses): t0 + D^(1/2) Q2 z, Q2 spanning
        # null(J D^(1/2))
        if m > 6 and centre and best_r > 0.0:
            _null_basis(A, hv0, hvv, Q2)
            for i in range(m):
                room_lo[i] = (t0[q, i] - v[q, i] - tmin[i]) / sqd[i]
                room_hi[i] = (tmax[i] - v[q, i] - t0[q, i]) / sqd[i]
            # warm start from the previous pose's shift projected on this pose's null space
            # (Householder bases of neighbours need not agree; the shift itself is smooth)
            warm = centred == q - 1
            if warm:
                for kk in range(m - 6):
                    d = 0.0
                    for i in range(m):
                        d += Q2[i, kk] * shift[i]
                    zc[kk] = d
            _centre(room_lo, room_hi, Q2, zc, warm)
            for i in range(m):
                d = 0.0
                for kk in range(m - 6):
                    d += Q2[i, kk] * zc[kk]
                shift[i] = d
                t0[q, i] += sqd[i] * d
            centred = q


@dataclass
class WrenchFeasibility(Feasibility):
    """Feasibility of N poses of an m-cable robot (``Feasibility`` with m columns).

    ``margin`` (N,): the least of the length margins and the normalised facet margin
    (dimensionless, > 0 iff feasible; for m = 6 the closed form's margin). ``margin_newtons``
    (N,): the least facet slack, N (a facet normal is a unit 6-vector mixing N and N m).
    ``margins`` (N, 4, m): rows length_min, length_max as in ``Feasibility``; rows
    tension_min, tension_max are the tension rule's band margins (normalised by the range):
    the facet test, not them, decides feasibility when m > 6. ``binding``: "length_max[3]",
    a facet "tension_max[2]+tension_min[7,8]" (the cables off the facet's spanning set and
    the bound they sit at on it; for m = 6 the closed form's name) or "singular".
    ``tension_nominal`` / ``tension_spread``: the rule's t0 and v (module doc);
    ``tension_status`` (N,): STATUS_OK, STATUS_EXCEEDS, STATUS_INFEASIBLE or STATUS_SINGULAR.
    ``det_j``: sqrt(det(J J^T)) >= 0 (|det J| for m = 6), singular at or below SINGULAR_DET.
    """

    margin_newtons: np.ndarray  # (N,) N
    wrench_margin: np.ndarray  # (N,) normalised facet margin alone (no lengths)
    wrench_facet: np.ndarray  # (N,) int: the subset of the facet attaining it, -1 if none
    wrench_facet_up: np.ndarray  # (N,) int: bit i set if cable i is at t_max on that facet
    tension_status: np.ndarray  # (N,) str

    @cached_property
    def band_ok(self):
        """True where the rule's band lies within the tension limits (controller-usable)."""
        return self.tension_status == STATUS_OK


def tension_rule(robot, J, w0, L):
    """The weighted closed-form rule (module doc) at N poses, by numpy: t0 (N, m) N, v (N, m) N.
    The reference the tests compare ``evaluate_kernel`` with (it solves with J D J^T, whose
    condition number is J's squared)."""
    tmin, tmax = robot.tension_min, robot.tension_max
    mid, D = 0.5 * (tmin + tmax), (tmax - tmin) ** 2
    JD = J * D  # J D, (N, 6, m)
    G = JD @ np.swapaxes(J, -1, -2)  # J D J^T (N, 6, 6), symmetric positive definite
    P = np.swapaxes(np.linalg.solve(G, JD), -1, -2)  # D J^T G^-1 (N, m, 6)
    t0 = mid + np.einsum("nij,nj->ni", P, w0 - J @ mid)
    v = np.linalg.norm(P @ L, axis=-1)
    return t0, v


def facet_name(k, hi, m):
    """Name of facet k's side whose cables at t_max are the bit mask ``hi``: the cables off
    the spanning subset k at the bound they take on it (1-based), e.g.
    "tension_max[2]+tension_min[7,8]"; for m = 6 one cable, the closed form's name."""
    S = set(facet_subsets(m)[k].tolist())
    off = [i for i in range(m) if i not in S]
    up = [str(i + 1) for i in off if hi >> i & 1]
    down = [str(i + 1) for i in off if not hi >> i & 1]
    return "+".join(([f"tension_max[{','.join(up)}]"] if up else [])
                    + ([f"tension_min[{','.join(down)}]"] if down else []))


@lru_cache(maxsize=64)
def _inverse_factor(E_bytes):
    """L3 with L3 L3^T = E^-1 for the 6 x 6 matrix E given by its bytes (one per robot)."""
    E = np.frombuffer(E_bytes).reshape(6, 6)
    return np.linalg.cholesky(np.linalg.inv(E))


def _binding_names(ml, kl, mr, arg, hi, m):
    """The binding constraint per pose: a length bound or a facet (named once per kind)."""
    names = np.array([f"{CONSTRAINTS[j // m]}[{j % m + 1}]" for j in range(2 * m)], dtype=object)
    binding = names[kl]
    facet = (mr < ml) & (arg >= 0)
    if facet.any():
        keys, inverse = np.unique((arg[facet] // 2) << m | hi[facet], return_inverse=True)
        facet_names = np.array([facet_name(int(k) >> m, int(k) & ((1 << m) - 1), m) for k in keys],
                               dtype=object)
        binding[facet] = facet_names[inverse.ravel()]
    return binding


def evaluate(robot, p, tau=None, R=None):
    """Feasibility of poses of an m-cable robot (m >= 6): positions p (N, 3) m and either tau
    (N, 3) rad or R (N, 3, 3). A ``WrenchFeasibility``."""
    p = np.atleast_2d(np.asarray(p, dtype=float))
    if R is None:
        R = rotation_tt(np.atleast_2d(tau))
    R = np.asarray(R, dtype=float).reshape(-1, 3, 3)
    n, m = p.shape[0], len(robot.base_anchors)
    lengths, u, J, c = pose_geometry(np.ascontiguousarray(p), np.ascontiguousarray(R),
                                     robot.base_anchors, robot.platform_anchors, robot.load_point)
    kernel = evaluate_kernel_parallel if n >= PARALLEL_MIN else evaluate_kernel
    scale, mn, mr, arg, hi, t0, v = kernel(
        J, c, robot.wrench_center_local, _inverse_factor(robot.ellipsoid_matrix.tobytes()),
        robot.ellipsoid_frame == "load", robot.tension_min, robot.tension_max, facet_subsets(m),
        SINGULAR_DET)
    v = stiffness_band(robot, J, c, t0, lengths, v)
    singular = ~(scale > SINGULAR_DET) | (lengths.min(axis=1) <= 0)
    span_l = robot.length_max - robot.length_min
    span_t = robot.tension_max - robot.tension_min
    margins = np.stack([(lengths - robot.length_min) / span_l, (robot.length_max - lengths) / span_l,
                        (t0 - v - robot.tension_min) / span_t, (robot.tension_max - t0 - v) / span_t],
                       axis=1)
    length_flat = margins[:, :2, :].reshape(n, -1)
    kl = np.argmin(length_flat, axis=1)
    ml = length_flat[np.arange(n), kl]
    margin = np.minimum(ml, mr)
    binding = _binding_names(ml, kl, mr, arg, hi, m)
    status = np.where(mr > 0, np.where(margins[:, 2:, :].reshape(n, -1).min(axis=1) > 0,
                                       STATUS_OK, STATUS_EXCEEDS), STATUS_INFEASIBLE)
    status = np.where(singular, STATUS_SINGULAR, status).astype(object)
    margin = np.where(singular, -np.inf, margin)
    binding = np.where(singular, "singular", binding).astype(str)
    mn, mr = np.where(singular, -np.inf, mn), np.where(singular, -np.inf, mr)
    t0 = np.where(singular[:, None], np.nan, t0)
    v = np.where(singular[:, None], np.inf, v)
    return WrenchFeasibility(lengths=lengths, unit_vectors=u, det_j=scale, tension_nominal=t0,
                             tension_spread=v, margins=margins, margin=margin, binding=binding,
                             margin_newtons=mn, wrench_margin=mr,
                             wrench_facet=np.where(singular | (arg < 0), -1, arg // 2),
                             wrench_facet_up=hi,
                             tension_status=status.astype(str))


NO_SUBSETS = np.empty((0, 5), dtype=np.int64)  # the kernel without the facet test


@lru_cache(maxsize=None)
def _band_names(m):
    """Names of the 4m band and length margins, as the closed form names its 24."""
    return np.array([f"{CONSTRAINTS[j // m]}[{j % m + 1}]" for j in range(4 * m)])


def stiffness_band(robot, J, c, t0, lengths, v):
    """The band v (N, m) N of the rule under length control of elastic cables: a wrench
    change dw moves the tensions of cables held at their lengths by P_K dw,
    P_K = K J^T (J K J^T)^-1, K = diag(EA / L0) = diag((EA + t0) / L) at the nominal t0
    (N, m) N and lengths (N, m) m, whatever rule chose t0; over the ellipsoid that is
    +- |rows of P_K L| (L L^T = E^-1 at the load points c (N, 3) m). J (N, 6, m). Rigid
    cables (no ``robot.cable_stiffness``), six cables (P_K = J^-1 = P) and poses where t0
    is not finite: ``v`` unchanged."""
    if robot.cable_stiffness is None or J.shape[-1] == 6:
        return v
    ok = np.all(np.isfinite(t0), axis=1)
    if not ok.any():
        return v
    K = (robot.cable_stiffness + t0[ok]) / lengths[ok]
    JK = J[ok] * K[:, None, :]
    P = np.swapaxes(np.linalg.solve(JK @ np.swapaxes(J[ok], -1, -2), JK), -1, -2)
    v = v.copy()
    v[ok] = np.linalg.norm(P @ inverse_ellipsoid_factor(robot, c[ok]), axis=-1)
    return v


def _centred(robot, p, R):
    """lengths (N, m), unit vectors, sqrt(det J J^T), t0 and v of poses (p (N, 3) m,
    R (N, 3, 3)): the kernel without the facet test (v of elastic cables:
    ``stiffness_band``)."""
    p = np.ascontiguousarray(np.atleast_2d(np.asarray(p, dtype=float)))
    R = np.ascontiguousarray(np.asarray(R, dtype=float).reshape(-1, 3, 3))
    lengths, u, J, c = pose_geometry(p, R, robot.base_anchors, robot.platform_anchors,
                                     robot.load_point)
    kernel = evaluate_kernel_parallel if len(p) >= PARALLEL_MIN else evaluate_kernel
    scale, _, _, _, _, t0, v = kernel(
        J, c, robot.wrench_center_local, _inverse_factor(robot.ellipsoid_matrix.tobytes()),
        robot.ellipsoid_frame == "load", robot.tension_min, robot.tension_max, NO_SUBSETS,
        SINGULAR_DET)
    return lengths, u, scale, t0, stiffness_band(robot, J, c, t0, lengths, v)


def _band(robot, p, tau, R):
    """``_centred``'s and the length and band margins (N, 4, m) of poses."""
    if R is None:
        R = rotation_tt(np.atleast_2d(tau))
    lengths, u, scale, t0, v = _centred(robot, p, R)
    span_l = robot.length_max - robot.length_min
    span_t = robot.tension_max - robot.tension_min
    margins = np.stack([(lengths - robot.length_min) / span_l, (robot.length_max - lengths) / span_l,
                        (t0 - v - robot.tension_min) / span_t, (robot.tension_max - t0 - v) / span_t],
                       axis=1)
    return lengths, u, scale, t0, v, margins


def band_margin(robot, p, tau=None, R=None):
    """``band_feasibility(...).margin`` (N,) alone: the atlas's domain test, where a
    Feasibility record per pose would cost more than the kernel."""
    lengths, _, scale, _, _, margins = _band(robot, p, tau, R)
    margin = margins.reshape(len(margins), -1).min(axis=1)  # nan where singular
    ok = (scale > SINGULAR_DET) & (lengths.min(axis=1) > 0) & ~np.isnan(margin)
    return np.where(ok, margin, -np.inf)


def band_feasibility(robot, p, tau=None, R=None):
    """The planner's feasibility of poses of an m-cable robot (``Feasibility``): ``margin``
    the least of the length margins and the centred rule's band margins ``margins``
    (N, 4, m), named as the closed form names them; positive iff the band t0 +- v is within
    the limits (which implies the facet test). One kernel call without the facet test
    (``rule_tensions``)."""
    lengths, u, scale, t0, v, margins = _band(robot, p, tau, R)
    n, m = margins.shape[0], margins.shape[2]
    singular = ~(scale > SINGULAR_DET) | (lengths.min(axis=1) <= 0)
    flat = margins.reshape(n, -1)
    k = np.argmin(np.where(np.isnan(flat), -np.inf, flat), axis=1)
    margin = flat[np.arange(n), k]
    singular |= np.isnan(margin)
    return Feasibility(lengths=lengths, unit_vectors=u, det_j=scale,
                       tension_nominal=np.where(singular[:, None], np.nan, t0),
                       tension_spread=np.where(singular[:, None], np.inf, v), margins=margins,
                       margin=np.where(singular, -np.inf, margin),
                       binding=np.where(singular, "singular", _band_names(m)[k]).astype(str))


def rule_tensions(robot, p, R):
    """The tension rule's centred nominal t0 (N, m) N and band half-widths v (N, m) N at
    poses (p (N, 3) m, R (N, 3, 3)), without the facet test: the kernel with no subset
    centres every pose. Equal to ``evaluate``'s where the facet test holds (its only use:
    along planned motions, dynamic timing and the executed check); nan / inf where singular."""
    lengths, _, scale, t0, v = _centred(robot, p, R)
    singular = ~(scale > SINGULAR_DET) | (lengths.min(axis=1) <= 0)
    return np.where(singular[:, None], np.nan, t0), np.where(singular[:, None], np.inf, v)


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
