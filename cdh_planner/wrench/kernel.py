"""The facet test (maths: the package docstring, docs/more-cables.md), plain Python
compiled by numba (``compiled``: ahead of time, else the JIT; no numba import here).

``facet_kernel`` is the facet test in the coordinates of a basis of 6 columns: with
E = J_B^-1 (Gauss-Jordan, complete pivoting), N = E J has unit columns on the basis, so a
subset S's normal is c = E^T y with y supported on the basis rows off S and orthogonal to
the (at most m - 6) columns of S off the basis: a tiny null-vector problem (y = 1 for
m = 6: c is a row of J^-1, the closed form). Then c.J_i = y.N_i, c.w0 = y.(E w0) and
L^T c = (E L)^T y touch only the rows of y's support. The direct transcription (a normal
per subset from J's columns) is the reference the tests compare it with
(test/wrench_reference.py).

``stiffness_band_kernel`` is the band of weighted cables, |rows of P_W L| with
P_W = W J^T (J W J^T)^-1 (``rules.stiffness_band``'s, W the elastic cables' stiffness):
numpy's batched solve one pose at a time, by the same Gaussian elimination with partial
pivoting (``kernel_linalg.eliminate``), to rounding.

``six_cable_kernel`` is the six-cable rule P = J^-1 (``closed_form``'s envelope, its numpy
reference) at many poses, for the trajectory's per-sample tensions. Units: m, N, N m.
"""

import numpy as np

from ..kernel_linalg import eliminate
from .linalg import gauss_jordan, householder_r, lu_factor6, lu_solve6, null_vector

# a 5-subset whose last pivot is below this fraction of its first one is rank 4: it spans
# no facet (every facet hyperplane is spanned by some 5 independent columns)
RANK_TOL = 1e-12
# from PARALLEL_MIN poses the kernels work in chunks of PARALLEL_CHUNK poses (the centred
# rule's Newton starts cold at a chunk's first pose), which threads may share out
# (``cdh_planner.parallel``): the chunks, not the threads, fix the numbers
PARALLEL_CHUNK = 512
PARALLEL_MIN = 4096


def _null_normal(T, zrows, xcols, k, nx, M, y, perm):
    """y (nx + 1,) on the basis rows ``zrows[k]`` off subset k, orthogonal to its nx > 2
    off-basis columns ``xcols[k]`` of N (T's first columns; ``_facet_poses`` writes nx <= 2,
    all m = 8 needs, in closed form). False when those columns are dependent (the subset
    has rank 4)."""
    for i in range(nx):
        for b in range(nx + 1):
            M[i, b] = T[zrows[k, b], xcols[k, i]]
    return null_vector(M, nx, y, perm) > RANK_TOL


def pose_geometry(p, R, a, b, g):
    """Per pose (p (N, 3) m, R (N, 3, 3)) of a robot with base anchors a (m, 3), platform
    anchors b (m, 3) and load point g (3,): cable lengths (N, m) m, unit vectors u (N, m, 3)
    from base to platform anchor, J (N, 6, m) with columns [u_i; a_i x u_i] (as
    ``geometry.screw_jacobian``) and the load point c = p + R g (N, 3) m."""
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


def load_wrench(q, c, w_local, L3, load_frame, w0, L):
    """w0 (6,) and L (6, 6) (L L^T = E^-1) of pose q in the base frame, from the ellipsoid's
    centre w_local (6,) and factor L3 given in the load frame (``load_frame``, which moves
    with the load point c[q]) or the base frame."""
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


def facet_kernel(J, c, w_local, L3, load_frame, tmin, tmax, subsets, singular_det):
    """Per pose: J (N, 6, m), load point c (N, 3); the ellipsoid's centre w_local (6,) and
    factor L3 (6, 6) in the load frame (``load_frame``) or the base frame; tension bounds
    (m,) N; subsets (K, 5) of the cables (none: only the rank test). Returns
    sqrt(det J J^T) (N,); the least facet slack (N,) N and normalised by the zonotope's
    width (N,) (-inf where singular; +inf with no subset), the facet attaining it (2 k +
    (0 for +c, 1 for -c), k the subset; -1 if none) and the bit mask of its cables at t_max
    (bit i: cable i at t_max_i on that facet, the cables off the subset at t_min); and
    ``ranked`` (N,): J of rank 6 (where a tension rule is defined)."""
    out = _facet_outputs(J.shape[0])
    _facet_poses(0, J.shape[0], J, c, w_local, L3, load_frame, tmin, tmax, subsets, singular_det,
                 *out)
    return out


def _facet_outputs(n):
    """The facet kernel's output arrays, filled as for singular poses."""
    return (np.zeros(n), np.full(n, -np.inf), np.full(n, -np.inf), np.full(n, -1, np.int64),
            np.zeros(n, np.int64), np.zeros(n, np.bool_))


def _facet_poses(q0, q1, J, c, w_local, L3, load_frame, tmin, tmax, subsets, singular_det,
                 scale, out_n, out_r, arg_r, hi_r, ranked):
    """``facet_kernel`` for poses q0 <= q < q1, into its output arrays."""
    m = J.shape[2]
    K = subsets.shape[0]
    T = np.empty((6, m + 13))  # [J | I | w0 | L] -> [N | E | E w0 | E L]
    pivcol = np.empty(6, np.int64)
    basis = np.full(6, -1, np.int64)  # the pivot columns the subsets' structure is of
    rowof = np.empty(m, np.int64)
    off = _off_subsets(subsets, m)
    nxs, xcols = np.empty(K, np.int64), np.empty((K, 6), np.int64)
    nzs, zrows, zposs = np.empty(K, np.int64), np.empty((K, 6), np.int64), np.empty((K, 6), np.int64)
    M = np.empty((5, 6))
    y = np.empty(6)
    perm = np.empty(6, np.int64)
    A = np.empty((m, 6))
    R = np.empty((6, 6))
    w0 = np.empty(6)
    L = np.empty((6, 6))
    EE = np.empty((6, 6))
    GG = np.empty((6, 6))
    hv0 = np.empty(6)
    hvv = np.empty(6)
    for q in range(q0, q1):
        Jq = J[q]
        load_wrench(q, c, w_local, L3, load_frame, w0, L)
        for i in range(m):
            for r in range(6):
                A[i, r] = Jq[r, i]
        scale[q] = householder_r(A, R, hv0, hvv)
        if not scale[q] > singular_det:
            continue
        for r in range(6):
            for i in range(m):
                T[r, i] = Jq[r, i]
            for j in range(6):
                T[r, m + j] = 1.0 if j == r else 0.0
                T[r, m + 7 + j] = L[r, j]
            T[r, m + 6] = w0[r]
        if not gauss_jordan(T, m, pivcol, rowof):
            continue
        ranked[q] = True
        for r in range(6):  # Grams of E and E L: |c|^2 = y^T EE y, |L^T c|^2 = y^T GG y
            for r2 in range(r, 6):
                se, sg = 0.0, 0.0
                for j in range(6):
                    se += T[r, m + j] * T[r2, m + j]
                    sg += T[r, m + 7 + j] * T[r2, m + 7 + j]
                EE[r, r2], EE[r2, r], GG[r, r2], GG[r2, r] = se, se, sg, sg
        best_n, best_r = np.inf, np.inf
        same = True
        for r in range(6):
            same = same and basis[r] == pivcol[r]
        if not same:  # a new basis (rarely between neighbouring poses)
            _subset_structure(subsets, pivcol, rowof, nxs, xcols, nzs, zrows, zposs)
            for r in range(6):
                basis[r] = pivcol[r]
        for k in range(K):
            nx, nz = nxs[k], nzs[k]
            # y (nx + 1,) on the basis rows zrows[k] off subset k, orthogonal to its off-basis
            # columns xcols[k] of N; closed forms for nx <= 2 written out here (a call that
            # passes arrays costs numba's reference counting: 40 % of this kernel's time)
            if nx == 0:
                y[0] = 1.0
                spans = True
            elif nx == 1:
                x0 = xcols[k, 0]
                a0, a1 = T[zrows[k, 0], x0], T[zrows[k, 1], x0]
                y[0], y[1] = a1, -a0
                spans = max(abs(a0), abs(a1)) > RANK_TOL
            elif nx == 2:
                x0, x1 = xcols[k, 0], xcols[k, 1]
                z0, z1, z2 = zrows[k, 0], zrows[k, 1], zrows[k, 2]
                a0, a1, a2 = T[z0, x0], T[z1, x0], T[z2, x0]
                b0, b1, b2 = T[z0, x1], T[z1, x1], T[z2, x1]
                y[0], y[1], y[2] = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
                spans = max(abs(y[0]), abs(y[1]), abs(y[2])) > RANK_TOL * max(
                    abs(a0), abs(a1), abs(a2), abs(b0), abs(b1), abs(b2), 1.0)
            else:
                spans = _null_normal(T, zrows, xcols, k, nx, M, y, perm)
            if not spans:
                continue  # rank 4: no facet
            # p_i = c.J_i = y.N_i for the cables off S (0 on S: exactly)
            hp, hm, width = 0.0, 0.0, 0.0
            up, down = 0, 0
            for o in range(m - 5):
                i = off[k, o]
                if rowof[i] >= 0:
                    p = y[zposs[k, rowof[i]]]
                else:
                    p = 0.0
                    for b in range(nz):
                        p += y[b] * T[zrows[k, b], i]
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
            cw, cc, lt = 0.0, 0.0, 0.0
            for b in range(nz):
                rb = zrows[k, b]
                cw += y[b] * T[rb, m + 6]
                se, sg = 0.0, 0.0
                for b2 in range(nz):
                    se += EE[rb, zrows[k, b2]] * y[b2]
                    sg += GG[rb, zrows[k, b2]] * y[b2]
                cc += y[b] * se
                lt += y[b] * sg
            lt, norm = np.sqrt(max(lt, 0.0)), np.sqrt(cc)
            # the lesser slack of the two sides, divided once: dividing by a positive number
            # keeps the order (rounding too), so these are the least of both quotients
            slack, sign = hp - cw - lt, 0
            if hm + cw - lt < slack:
                slack, sign = hm + cw - lt, 1
            if slack / norm < best_n:
                best_n = slack / norm
            sr = slack / width if width > 0.0 else (-np.inf if slack < 0.0 else np.inf)
            if sr < best_r:
                best_r, arg_r[q] = sr, 2 * k + sign
                hi_r[q] = up if sign == 0 else down
        out_n[q], out_r[q] = best_n, best_r


def _off_subsets(subsets, m):
    """The cables off each subset (K, m - 5), ascending."""
    K = subsets.shape[0]
    off = np.empty((K, m - 5), np.int64)
    inS = np.zeros(m, np.bool_)
    for k in range(K):
        for s in range(5):
            inS[subsets[k, s]] = True
        o = 0
        for i in range(m):
            if not inS[i]:
                off[k, o] = i
                o += 1
        for s in range(5):
            inS[subsets[k, s]] = False
    return off


def _subset_structure(subsets, pivcol, rowof, nxs, xcols, nzs, zrows, zposs):
    """Per subset k, in the basis ``pivcol`` / ``rowof`` (``gauss_jordan``'s): its nxs[k]
    cables off the basis xcols[k], and the nzs[k] basis rows zrows[k] whose pivot cable is
    off the subset (zposs[k][r]: row r's place among them)."""
    m = rowof.shape[0]
    inS = np.zeros(m, np.bool_)
    for k in range(subsets.shape[0]):
        nx = 0
        for s in range(5):
            inS[subsets[k, s]] = True
            if rowof[subsets[k, s]] < 0:
                xcols[k, nx] = subsets[k, s]
                nx += 1
        nz = 0
        for r in range(6):
            if not inS[pivcol[r]]:
                zrows[k, nz], zposs[k, r] = r, nz
                nz += 1
        nxs[k], nzs[k] = nx, nz
        for s in range(5):
            inS[subsets[k, s]] = False


def stiffness_band_kernel(J, c, w_local, L3, load_frame, W, ok):
    """The band v (N, m) N = |rows of P_W L| at poses with J (N, 6, m), load points c (N, 3)
    (the ellipsoid as ``facet_kernel``'s) and cable weights W (N, m) (elastic cables: their
    stiffness, N/m), P_W = W J^T (J W J^T)^-1, where ``ok`` (N,); inf where J W J^T is
    singular, nan off ``ok``."""
    n, m = J.shape[0], J.shape[2]
    v = np.full((n, m), np.nan)
    M = np.empty((6, 6))
    X = np.empty((6, m))
    w0 = np.empty(6)
    L = np.empty((6, 6))
    for q in range(n):
        if not ok[q]:
            continue
        Jq, Wq = J[q], W[q]
        for r in range(6):  # X = J W, M = J W J^T
            for i in range(m):
                X[r, i] = Jq[r, i] * Wq[i]
        for r in range(6):
            for r2 in range(6):
                s = 0.0
                for i in range(m):
                    s += X[r, i] * Jq[r2, i]
                M[r, r2] = s
        solved, _ = eliminate(M, X)  # X = (J W J^T)^-1 J W = P_W^T
        if not solved:
            for i in range(m):
                v[q, i] = np.inf
            continue
        load_wrench(q, c, w_local, L3, load_frame, w0, L)
        for i in range(m):
            vv = 0.0
            for j in range(6):
                s = 0.0
                for r in range(6):
                    s += X[r, i] * L[r, j]
                vv += s * s
            v[q, i] = np.sqrt(vv)
    return v


def six_cable_kernel(p, R, a, b, g, w_local, L3, load_frame, W, singular_det):
    """Six cables at poses (p (N, 3) m, R (N, 3, 3)), anchors a, b (6, 3) m, load point g (3,)
    m, the ellipsoid's centre w_local (6,) and factor L3 (6, 6) in the load frame
    (``load_frame``) or the base frame: the rule's tensions t0 = J^-1 w0 (N, 6) N, its band
    v = |rows of J^-1 L| (N, 6) N (``closed_form._envelope``), J^-1 W (N, K, 6) of the K
    wrenches W (N, K, 6) of each pose, and singular (N,) (|det J| not above singular_det,
    or a cable of no length; ``closed_form._singular``), where t0 and J^-1 W are nan and v
    inf. One LU factorisation of J (partial pivoting) per pose: J^-1 is never formed."""
    n, k_w = p.shape[0], W.shape[1]
    t0 = np.empty((n, 6))
    v = np.empty((n, 6))
    X = np.empty((n, k_w, 6))
    singular = np.zeros(n, dtype=np.bool_)
    c = np.empty((n, 3))
    J = np.empty((6, 6))
    perm = np.empty(6, dtype=np.int64)
    w0 = np.empty(6)
    L = np.empty((6, 6))
    col = np.empty(6)
    y = np.empty(6)
    for q in range(n):
        Rq = R[q]
        for r in range(3):
            c[q, r] = p[q, r] + Rq[r, 0] * g[0] + Rq[r, 1] * g[1] + Rq[r, 2] * g[2]
        short = False
        for i in range(6):
            for r in range(3):
                y[r] = p[q, r] + Rq[r, 0] * b[i, 0] + Rq[r, 1] * b[i, 1] + Rq[r, 2] * b[i, 2] - a[i, r]
            length = np.sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2])
            short = short or not length > 0.0
            s = 1.0 / length if length > 0.0 else 1.0
            u0, u1, u2 = y[0] * s, y[1] * s, y[2] * s
            J[0, i], J[1, i], J[2, i] = u0, u1, u2
            J[3, i] = a[i, 1] * u2 - a[i, 2] * u1
            J[4, i] = a[i, 2] * u0 - a[i, 0] * u2
            J[5, i] = a[i, 0] * u1 - a[i, 1] * u0
        det = lu_factor6(J, perm)
        if short or not abs(det) > singular_det:
            singular[q] = True
            for i in range(6):
                t0[q, i] = np.nan
                v[q, i] = np.inf
                for k in range(k_w):
                    X[q, k, i] = np.nan
            continue
        load_wrench(q, c, w_local, L3, load_frame, w0, L)
        lu_solve6(J, perm, w0, t0[q])
        for i in range(6):
            v[q, i] = 0.0
        for j in range(6):
            for i in range(6):
                col[i] = L[i, j]
            lu_solve6(J, perm, col, y)
            for i in range(6):
                v[q, i] += y[i] * y[i]
        for i in range(6):
            v[q, i] = np.sqrt(v[q, i])
        for k in range(k_w):
            lu_solve6(J, perm, W[q, k], X[q, k])
    return t0, v, X, singular
