"""Compiled kernel of the navigation manifold: F (84,) and F_X (84, 90) in scalar loops;
and Newton's step on a chart by F_X's structure (``block_solve``).

``navigation_residual_and_jacobian(X, params, jacobian)`` computes exactly what the numpy
reference (test/navigation_reference.py) computes (same equations, same variable and
equation order, see navigation.py); test/test_manifold_kernel.py checks the two agree to
1e-12.

The robot's constants travel in one flat float64 vector (``pack_parameters``) so that a
call unboxes two arrays only: numba's per-argument dispatch cost is a visible part of a
kernel this small.

Two compilations of the same source, the first one found is used:

- ahead of time (``python -m cdh_planner.manifold.aot``, run by ``make``; ``cdh_planner.aot``):
  an extension module next to this file whose name carries a digest of this file and
  layout.py. Importing it and the first call take about 10 ms, numba is not imported;
- numba's JIT with ``cache=True``: 0.4 - 0.5 s in a fresh process.
"""

import math
import sys

import numpy as np

from .. import aot
from ..kernel_linalg import eliminate as _eliminate
from .layout import I_D, I_F, I_G, I_L, I_P, I_S, I_T, I_TAU, I_V, N_EQS, N_VARS

# Layout of the packed parameter vector.
K_A = 0          # base anchors a_i (6 x 3, row-major)
K_B = 18         # platform anchors b_i (6 x 3)
K_GLOAD = 36     # load point in the platform frame (3)
K_W = 39         # w0 in the ellipsoid frame (6)
K_L3T = 45       # L3^T, E3 = L3 L3^T (6 x 6, row-major)
K_LMIN = 81      # length_min (6)
K_LMAX = 87      # length_max (6)
K_FMIN = 93      # tension_min (6)
K_FMAX = 99      # tension_max (6)
K_KAPPA = 105    # slack scale kappa
K_LOAD = 106     # 1.0 if the ellipsoid is in the load frame F3, else 0.0
N_PARAMS = 107


def pack_parameters(a, b, g_load, w_local, L3T, length_min, length_max, tension_min, tension_max,
                    kappa, load_frame):
    """The flat parameter vector of one robot (see the K_* offsets)."""
    prm = np.empty(N_PARAMS)
    prm[K_A:K_B] = np.asarray(a, dtype=float).ravel()
    prm[K_B:K_GLOAD] = np.asarray(b, dtype=float).ravel()
    prm[K_GLOAD:K_W] = g_load
    prm[K_W:K_L3T] = w_local
    prm[K_L3T:K_LMIN] = np.asarray(L3T, dtype=float).ravel()
    prm[K_LMIN:K_LMAX] = length_min
    prm[K_LMAX:K_FMIN] = length_max
    prm[K_FMIN:K_FMAX] = tension_min
    prm[K_FMAX:K_KAPPA] = tension_max
    prm[K_KAPPA] = kappa
    prm[K_LOAD] = 1.0 if load_frame else 0.0
    return prm


def _mat3(out, a00, a01, a02, a10, a11, a12, a20, a21, a22):
    out[0, 0], out[0, 1], out[0, 2] = a00, a01, a02
    out[1, 0], out[1, 1], out[1, 2] = a10, a11, a12
    out[2, 0], out[2, 1], out[2, 2] = a20, a21, a22


def _matmul3(out, a, b):
    """out = a b for 3 x 3 matrices."""
    for i in range(3):
        for j in range(3):
            s = 0.0
            for k in range(3):
                s += a[i, k] * b[k, j]
            out[i, j] = s


def _skew(v0, v1, v2, out):
    """out = [v]x."""
    _mat3(out, 0.0, -v2, v1, v2, 0.0, -v0, -v1, v0, 0.0)


def _rotation_and_derivatives(phi, theta, sigma, R, dR):
    """R = Rz(phi) Ry(theta) Rz(sigma - phi) and dR[:, :, k] = dR / d(phi, theta, sigma)_k."""
    cf, sf = math.cos(phi), math.sin(phi)
    ct, st = math.cos(theta), math.sin(theta)
    cp, sp = math.cos(sigma - phi), math.sin(sigma - phi)
    T = np.empty((6, 3, 3))  # Rz(phi), dRz(phi), Ry, dRy, Rz(psi), dRz(psi)
    _mat3(T[0], cf, -sf, 0.0, sf, cf, 0.0, 0.0, 0.0, 1.0)
    _mat3(T[1], -sf, -cf, 0.0, cf, -sf, 0.0, 0.0, 0.0, 0.0)
    _mat3(T[2], ct, 0.0, st, 0.0, 1.0, 0.0, -st, 0.0, ct)
    _mat3(T[3], -st, 0.0, ct, 0.0, 0.0, 0.0, -ct, 0.0, -st)
    _mat3(T[4], cp, -sp, 0.0, sp, cp, 0.0, 0.0, 0.0, 1.0)
    _mat3(T[5], -sp, -cp, 0.0, cp, -sp, 0.0, 0.0, 0.0, 0.0)
    A = np.empty((3, 3, 3))  # Rz Ry, dRz Ry, Rz dRy
    _matmul3(A[0], T[0], T[2])
    _matmul3(A[1], T[1], T[2])
    _matmul3(A[2], T[0], T[3])
    P = np.empty((3, 3, 3))  # d/dsigma, d/dphi (before the psi term), d/dtheta
    _matmul3(R, A[0], T[4])
    _matmul3(P[0], A[0], T[5])
    _matmul3(P[1], A[1], T[4])
    _matmul3(P[2], A[2], T[4])
    for i in range(3):
        for j in range(3):
            dR[i, j, 0] = P[1, i, j] - P[0, i, j]  # psi = sigma - phi
            dR[i, j, 1] = P[2, i, j]
            dR[i, j, 2] = P[0, i, j]


def _residual_and_jacobian(X, prm, jacobian):
    """F(X) (84,) and, if ``jacobian``, F_X(X) (84, 90) (else an empty (0, 0) array)."""
    kappa = prm[K_KAPPA]
    load_frame = prm[K_LOAD] != 0.0

    R = np.empty((3, 3))
    dR = np.empty((3, 3, 3))
    _rotation_and_derivatives(X[I_TAU], X[I_TAU + 1], X[I_TAU + 2], R, dR)

    # load point c = p + R g, nominal wrench w0 and the ellipsoid factor P (E = P^T P)
    c = np.empty(3)
    for i in range(3):
        s = 0.0
        for j in range(3):
            s += R[i, j] * prm[K_GLOAD + j]
        c[i] = X[I_P + i] + s
    w0 = np.empty(6)
    for i in range(6):
        w0[i] = prm[K_W + i]
    P = np.empty((6, 6))
    for k in range(6):
        for j in range(6):
            P[k, j] = prm[K_L3T + 6 * k + j]
    if load_frame:
        f0x, f1x, f2x = prm[K_W], prm[K_W + 1], prm[K_W + 2]
        w0[3] += c[1] * f2x - c[2] * f1x
        w0[4] += c[2] * f0x - c[0] * f2x
        w0[5] += c[0] * f1x - c[1] * f0x
        # P = L3^T e(c), e = [[I, 0], [-[c]x, I]]: only P[:, :3] changes
        S = np.empty((3, 3))
        _skew(c[0], c[1], c[2], S)
        for k in range(6):
            for j in range(3):
                s = prm[K_L3T + 6 * k + j]
                for u in range(3):
                    s -= prm[K_L3T + 6 * k + 3 + u] * S[u, j]
                P[k, j] = s

    # J (6 x 6): column i = [d_i; a_i x d_i] / l_i
    J = np.empty((6, 6))
    for i in range(6):
        li = X[I_L + i]
        d0, d1, d2 = X[I_D + 3 * i], X[I_D + 3 * i + 1], X[I_D + 3 * i + 2]
        a0, a1, a2 = prm[K_A + 3 * i], prm[K_A + 3 * i + 1], prm[K_A + 3 * i + 2]
        J[0, i] = d0 / li
        J[1, i] = d1 / li
        J[2, i] = d2 / li
        J[3, i] = (a1 * d2 - a2 * d1) / li
        J[4, i] = (a2 * d0 - a0 * d2) / li
        J[5, i] = (a0 * d1 - a1 * d0) / li
    JG = np.empty((6, 6))
    M = np.empty((6, 6))
    for k in range(6):
        for j in range(6):
            s = 0.0
            m = 0.0
            for i in range(6):
                s += J[k, i] * X[I_V + 6 * i + j]
                m += P[k, i] * J[i, j]
            JG[k, j] = s
            M[k, j] = m
    vdiag = np.empty(6)
    for i in range(6):
        s = 0.0
        for j in range(6):
            s += X[I_V + 6 * i + j] * X[I_V + 6 * i + j]
        vdiag[i] = math.sqrt(s)

    F = np.empty(N_EQS)
    # (1) d_i - (p + R b_i - a_i)
    for i in range(6):
        for k in range(3):
            rb = 0.0
            for j in range(3):
                rb += prm[K_B + 3 * i + j] * R[k, j]
            F[3 * i + k] = X[I_D + 3 * i + k] - (X[I_P + k] + rb - prm[K_A + 3 * i + k])
    # (2) l_i^2 - d_i . d_i
    for i in range(6):
        dd = 0.0
        for k in range(3):
            dd += X[I_D + 3 * i + k] * X[I_D + 3 * i + k]
        F[18 + i] = X[I_L + i] ** 2 - dd
    # (4) J f0 - w0
    for r in range(6):
        s = 0.0
        for i in range(6):
            s += J[r, i] * X[I_F + i]
        F[24 + r] = s - w0[r]
    # (5-6) P J G - I
    for k in range(6):
        for j in range(6):
            s = 0.0
            for i in range(6):
                s += P[k, i] * JG[i, j]
            F[30 + 6 * k + j] = s - (1.0 if k == j else 0.0)
    # (10)-(12) margins
    for i in range(6):
        li, fi = X[I_L + i], X[I_F + i]
        lmin, lmax = prm[K_LMIN + i], prm[K_LMAX + i]
        fmin, fmax = prm[K_FMIN + i], prm[K_FMAX + i]
        hl = (lmax - lmin) / 2.0
        rf = fmax - fmin
        mu_l = (li - lmin) * (lmax - li) / hl ** 2
        mu_lo = (fi - vdiag[i] - fmin) / rf
        mu_hi = (fmax - fi - vdiag[i]) / rf
        F[66 + i] = mu_l - math.exp(X[I_G + i] / kappa)
        F[72 + i] = mu_lo - math.exp(X[I_S + i] / kappa)
        F[78 + i] = mu_hi - math.exp(X[I_T + i] / kappa)
    if not jacobian:
        return F, np.empty((0, 0))

    Jx = np.zeros((N_EQS, N_VARS))
    # (1): d/dp = -I, d/dd_i = I, d/dtau = -dR b_i
    for i in range(6):
        for k in range(3):
            Jx[3 * i + k, I_P + k] = -1.0
            Jx[3 * i + k, I_D + 3 * i + k] = 1.0
            for m in range(3):
                s = 0.0
                for j in range(3):
                    s += dR[k, j, m] * prm[K_B + 3 * i + j]
                Jx[3 * i + k, I_TAU + m] = -s
    # dc / dtau (3 x 3)
    dc_dtau = np.empty((3, 3))
    for k in range(3):
        for m in range(3):
            s = 0.0
            for j in range(3):
                s += dR[k, j, m] * prm[K_GLOAD + j]
            dc_dtau[k, m] = s
    # (2)
    for i in range(6):
        Jx[18 + i, I_L + i] = 2.0 * X[I_L + i]
        for k in range(3):
            Jx[18 + i, I_D + 3 * i + k] = -2.0 * X[I_D + 3 * i + k]
    # dJcol_i / dd_i = [I; [a_i]x] / l_i (6 x 3) and dJcol_i / dl_i = -Jcol_i / l_i (6,)
    dcol_dd = np.empty((6, 6, 3))
    dcol_dl = np.empty((6, 6))
    Sa = np.empty((3, 3))
    for i in range(6):
        li = X[I_L + i]
        _skew(prm[K_A + 3 * i], prm[K_A + 3 * i + 1], prm[K_A + 3 * i + 2], Sa)
        for r in range(3):
            for k in range(3):
                dcol_dd[i, r, k] = (1.0 if r == k else 0.0) / li
                dcol_dd[i, 3 + r, k] = Sa[r, k] / li
        for r in range(6):
            dcol_dl[i, r] = -J[r, i] / li
    # (4) J f0 - w0
    for r in range(6):
        for i in range(6):
            fi = X[I_F + i]
            Jx[24 + r, I_F + i] = J[r, i]
            for k in range(3):
                Jx[24 + r, I_D + 3 * i + k] = fi * dcol_dd[i, r, k]
            Jx[24 + r, I_L + i] = fi * dcol_dl[i, r]
    if load_frame:
        # d(-w0)/dc = [0; [F]x]
        Sf = np.empty((3, 3))
        _skew(prm[K_W], prm[K_W + 1], prm[K_W + 2], Sf)
        for u in range(3):
            for w in range(3):
                Jx[27 + u, I_P + w] = Sf[u, w]
            for m in range(3):
                s = 0.0
                for w in range(3):
                    s += Sf[u, w] * dc_dtau[w, m]
                Jx[27 + u, I_TAU + m] = s
    # (5-6) P J G - I, rows 30 + 6 k + j
    PD = np.empty(3)  # sum_a P[k, a] dcol_dd[i, a, :]
    for k in range(6):
        for i in range(6):
            for q in range(3):
                s = 0.0
                for a in range(6):
                    s += P[k, a] * dcol_dd[i, a, q]
                PD[q] = s
            pl = 0.0
            for a in range(6):
                pl += P[k, a] * dcol_dl[i, a]
            for j in range(6):
                row = 30 + 6 * k + j
                gij = X[I_V + 6 * i + j]
                Jx[row, I_V + 6 * i + j] = M[k, i]  # d(P J G)_kj / dG_ij = (P J)_ki
                for q in range(3):
                    Jx[row, I_D + 3 * i + q] = gij * PD[q]
                Jx[row, I_L + i] = gij * pl
    if load_frame:
        # d(P J G)_kj / dc_m = (L3^T de(c)/dc_m J G)_kj, de/dc_m = [[0, 0], [-[e_m]x, 0]]:
        # with q = row k of L3^T[:, 3:] and v = JG[:3, j] that is -q . (e_m x v) = (q x v)_m
        dc = np.empty(3)
        for k in range(6):
            q0, q1, q2 = prm[K_L3T + 6 * k + 3], prm[K_L3T + 6 * k + 4], prm[K_L3T + 6 * k + 5]
            for j in range(6):
                row = 30 + 6 * k + j
                v0, v1, v2 = JG[0, j], JG[1, j], JG[2, j]
                dc[0] = q1 * v2 - q2 * v1
                dc[1] = q2 * v0 - q0 * v2
                dc[2] = q0 * v1 - q1 * v0
                for m in range(3):
                    Jx[row, I_P + m] = dc[m]
                for m in range(3):
                    s = 0.0
                    for w in range(3):
                        s += dc[w] * dc_dtau[w, m]
                    Jx[row, I_TAU + m] = s
    # (10)-(12)
    for i in range(6):
        li = X[I_L + i]
        lmin, lmax = prm[K_LMIN + i], prm[K_LMAX + i]
        hl = (lmax - lmin) / 2.0
        rf = prm[K_FMAX + i] - prm[K_FMIN + i]
        Jx[66 + i, I_L + i] = (lmax + lmin - 2.0 * li) / hl ** 2
        Jx[66 + i, I_G + i] = -math.exp(X[I_G + i] / kappa) / kappa
        Jx[72 + i, I_F + i] = 1.0 / rf
        Jx[78 + i, I_F + i] = -1.0 / rf
        for j in range(6):
            dv = X[I_V + 6 * i + j] / vdiag[i] / rf  # d|G_i| / dG_ij over the range
            Jx[72 + i, I_V + 6 * i + j] = -dv
            Jx[78 + i, I_V + 6 * i + j] = -dv
        Jx[72 + i, I_S + i] = -math.exp(X[I_S + i] / kappa) / kappa
        Jx[78 + i, I_T + i] = -math.exp(X[I_T + i] / kappa) / kappa
    return F, Jx


# ----- compilation -------------------------------------------------------------------------
def _solve_in(M, X, work):
    """X <- M^-1 X for M (k, k), left as it is (eliminated in work (>= k, >= k)): False
    where a pivot is zero."""
    k = M.shape[0]
    for i in range(k):
        for j in range(k):
            work[i, j] = M[i, j]
    return _eliminate(work[:k, :k], X)[0]


def _block_solve(A, rhs, blocks):
    """(x, True) with A x = rhs for A (n, n) = [F_x (m rows); the chart's basis^T (n - m)],
    by F_x's structure, or (zeros, False) where it does not have it or a pivot is zero (the
    caller then solves densely). ``blocks`` (K + 1,): F_x's columns past the first p = n - m
    (the pose's) are block lower triangular, rows blocks[k]:blocks[k + 1] on columns
    p + blocks[k]:p + blocks[k + 1] (for the navigation manifold d, l, f0, G, slacks: each a
    function of the pose and the blocks before it, ``navigation_blocks``). So
    W = F_d^-1 [F_p | F], block by block (F_d, F_p: F_x's dependent and pose columns), the
    pose's step from the 6 x 6 Schur complement B_p - B_d W_p, then the others':
    some 45,000 flops against LAPACK's 490,000 for n = 90."""
    n, m = A.shape[0], blocks[-1]
    p = n - m
    for b in range(len(blocks) - 1):  # the structure: nothing right of the diagonal block
        for i in range(blocks[b], blocks[b + 1]):
            for j in range(p + blocks[b + 1], n):
                if A[i, j] != 0.0:
                    return np.zeros(n), False
    W = np.empty((m, p + 1))
    for i in range(m):
        for j in range(p):
            W[i, j] = A[i, j]
        W[i, p] = rhs[i]
    work = np.empty((m, m))
    for b in range(len(blocks) - 1):
        r0, r1 = blocks[b], blocks[b + 1]
        for i in range(r0, r1):
            for q in range(r0):
                a = A[i, p + q]
                if a != 0.0:
                    for j in range(p + 1):
                        W[i, j] -= a * W[q, j]
        if not _solve_in(A[r0:r1, p + r0:p + r1], W[r0:r1], work):
            return np.zeros(n), False
    S, s = np.empty((p, p)), np.empty((p, 1))  # the Schur complement on the pose
    for i in range(p):
        for j in range(p + 1):
            acc = A[m + i, j] if j < p else rhs[m + i]
            for q in range(m):
                acc -= A[m + i, p + q] * W[q, j]
            if j < p:
                S[i, j] = acc
            else:
                s[i, 0] = acc
    if not _solve_in(S, s, work):
        return np.zeros(n), False
    x = np.empty(n)
    for i in range(p):
        x[i] = s[i, 0]
    for q in range(m):
        acc = W[q, p]
        for j in range(p):
            acc -= W[q, j] * s[j, 0]
        x[p + q] = acc
    return x, True


def navigation_blocks():
    """``_block_solve``'s blocks of the navigation manifold's F_x (free flight: no task
    rows): equations (1) d, (2) l, (4) f0, (5-6) G, (10-12) the slacks, each on its own
    variables and those before (navigation.py; test_manifold_kernel checks the zeros)."""
    return np.array([0, I_L - I_D, I_F - I_D, I_V - I_D, I_G - I_D, N_VARS - I_D],
                    dtype=np.int64)


HELPERS = ("_mat3", "_matmul3", "_skew", "_rotation_and_derivatives", "_eliminate", "_solve_in")
AOT_EXPORTS = {"navigation_residual_and_jacobian":
               "Tuple((float64[::1], float64[:, ::1]))(float64[::1], float64[::1], boolean)",
               "block_solve":
               "Tuple((float64[::1], boolean))(float64[:, ::1], float64[::1], int64[::1])"}
AOT_PREFIX = "_kernels_aot_"


AOT_SOURCES = ("kernels.py", "layout.py", "../kernel_linalg.py")  # what the machine code is of


def aot_kernel():
    """The ahead-of-time compiled kernel, or None if it was not built for this source."""
    built = aot.load(sys.modules[__name__])
    return built and built["navigation_residual_and_jacobian"]


def jit_kernel():
    """numba's JIT kernel (cache=True); the helpers become numba functions in this module."""
    return aot.jit(globals(), HELPERS)(_residual_and_jacobian)


def jit_kernels():
    """The JIT entries by name (``cdh_planner.aot``)."""
    return {"navigation_residual_and_jacobian": jit_kernel(),
            "block_solve": aot.jit(globals(), HELPERS)(_block_solve)}


_entries = aot.entries(sys.modules[__name__])  # the build of this source, else the JIT
navigation_residual_and_jacobian = _entries["navigation_residual_and_jacobian"]
block_solve = _entries["block_solve"]
