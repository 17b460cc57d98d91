"""Small dense linear algebra for the wrench kernels (``kernel``, ``centred``): one pose at
a time on 6 x m matrices, in scratch arrays the caller owns, so that a pose allocates
nothing. Pivoting is complete (Gauss) or by Householder reflections. Plain Python compiled
by numba (``compiled``: ahead of time, else the JIT; no numba import here)."""

import numpy as np


def gauss_jordan(T, m, pivcol, rowof):
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

def null_vector(M, k, y, perm):
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

def householder_r(A, R, hv0, hvv):
    """R (6, 6), upper triangular, of the QR factorisation of A (m, 6); A keeps the
    reflectors below its diagonal, their first entries in hv0 (6,) and |v|^2 in hvv (6,)
    (``null_basis`` forms Q's last m - 6 columns from them). Returns |det R|
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

def null_basis(A, hv0, hvv, Q2):
    """Q2 (m, m - 6): the last columns of Q = H_0 ... H_5 from ``householder_r``'s
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

def cholesky_solve(H, g, n, x):
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

def forward_substitute(R, B, X):
    """X = R^-T B (6, c) for upper-triangular R (6, 6), column by column (one call for all
    of them: a call passing arrays costs numba's reference counting)."""
    for j in range(B.shape[1]):
        for i in range(6):
            s = B[i, j]
            for k in range(i):
                s -= R[k, i] * X[k, j]
            X[i, j] = s / R[i, i]


def lu_factor6(A, perm):
    """A (6, 6) <- its LU factors in place (Gaussian elimination with partial pivoting, as
    LAPACK's getrf: the unit lower factor's multipliers below the diagonal), perm (6,) <-
    the original row of each factor row. Returns det A (0.0 at a zero pivot, where the
    factors are incomplete). The size is fixed so that numba unrolls the loops (twice as
    fast as A.shape[0])."""
    n = 6
    det = 1.0
    for i in range(n):
        perm[i] = i
    for k in range(n):
        piv, big = k, abs(A[k, k])
        for i in range(k + 1, n):
            if abs(A[i, k]) > big:
                piv, big = i, abs(A[i, k])
        if big == 0.0:
            return 0.0
        if piv != k:
            for j in range(n):
                A[k, j], A[piv, j] = A[piv, j], A[k, j]
            perm[k], perm[piv] = perm[piv], perm[k]
            det = -det
        det *= A[k, k]
        for i in range(k + 1, n):
            f = A[i, k] / A[k, k]
            A[i, k] = f
            for j in range(k + 1, n):
                A[i, j] -= f * A[k, j]
    return det


def lu_solve6(A, perm, b, x):
    """x (6,) <- A^-1 b from ``lu_factor6``'s factors A and row order perm (b (6,) unchanged;
    x is not b)."""
    n = 6
    for i in range(n):
        s = b[perm[i]]
        for j in range(i):
            s -= A[i, j] * x[j]
        x[i] = s
    for i in range(n - 1, -1, -1):
        s = x[i]
        for j in range(i + 1, n):
            s -= A[i, j] * x[j]
        x[i] = s / A[i, i]
