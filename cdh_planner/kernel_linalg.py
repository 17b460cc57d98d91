"""Dense linear algebra that compiled kernels share: plain Python (no numba import),
compiled into each kernel module that imports it as a helper (manifold/kernels.py,
accuracy_kernel.py; each lists this file in its AOT_SOURCES)."""


def eliminate(M, X):
    """X <- M^-1 X for M (n, n) (overwritten by its eliminated form) and X (n, k), by
    Gaussian elimination with partial pivoting: (True, det M), or (False, 0.0) where a
    pivot is zero or not a number (X then meaningless)."""
    n, k = M.shape[0], X.shape[1]
    det = 1.0
    for c in range(n):
        piv, big = c, abs(M[c, c])
        for i in range(c + 1, n):
            if abs(M[i, c]) > big:
                piv, big = i, abs(M[i, c])
        if not big > 0.0:
            return False, 0.0
        if piv != c:
            det = -det
            for j in range(n):
                M[c, j], M[piv, j] = M[piv, j], M[c, j]
            for j in range(k):
                X[c, j], X[piv, j] = X[piv, j], X[c, j]
        det *= M[c, c]
        for i in range(c + 1, n):
            f = M[i, c] / M[c, c]
            if f != 0.0:
                for j in range(c + 1, n):
                    M[i, j] -= f * M[c, j]
                for j in range(k):
                    X[i, j] -= f * X[c, j]
    for c in range(n - 1, -1, -1):
        for j in range(k):
            acc = X[c, j]
            for i in range(c + 1, n):
                acc -= M[c, i] * X[i, j]
            X[c, j] = acc / M[c, c]
    return True, det
