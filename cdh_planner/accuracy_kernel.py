"""The exact zonotope maximum of ``accuracy.box_max_norm`` compiled by numba, one pose at a
time: the pairs of generators, their corner normals c = g_i x g_j and the four vertices
around each (``accuracy``'s module docstring has the maths). numpy's version built
(N, P, m) temporaries for every pose block and spent most of verify's accuracy time
allocating them; this loop does the same arithmetic in the same order (the norms'
sums, the cross products, the vertices' coordinates: bit for bit the same maximum), with
one exception that cannot change the result: the dot products c . g_k, read only for
their signs and for the in-plane test, need not round like BLAS's (nor is c normalised
first: the tests multiply instead of dividing; a sign that rounding could flip is that of
a g_k the in-plane test already calls degenerate).

``error_map_kernel`` is ``accuracy.error_map`` one pose at a time (A, K, and the 6 x 6
system by Gaussian elimination with partial pivoting), without numpy's (N, 6, m)
temporaries: the same algebra as its batched solve, to rounding rather than bit for bit
(test_accuracy: 1e-12 of G's largest entry; the accuracies move by about 1e-15).
``accuracy_kernel`` is both in one pass, G's rows never stored: what ``pose_accuracy``
runs (bit for bit ``box_max_norm`` of ``error_map``'s rows where it answers).

Plain Python here (no numba import): ``vertex_max_kernel``, ``error_map_kernel`` and
``accuracy_kernel`` are the build ahead of time (``python -m cdh_planner.accuracy_aot``, run by ``make``), else
numba's JIT with ``cache=True`` (``cdh_planner.aot``). Their arguments are C-contiguous
arrays as AOT_EXPORTS says, unchecked.
"""

import sys

import numpy as np

from . import aot
from .kernel_linalg import eliminate as _eliminate


def _pose_vertex_max(g, norms, tiny, parallel_tol, ortho_tol):
    """(the largest vertex norm^2 over the usable pairs (0 if none), whether the pose is
    degenerate, whether any pair is usable) of one pose: g (3, m) the generators with the
    tiny ones zeroed, norms (m,) their lengths before, tiny (m,) bool."""
    m = g.shape[1]
    best = 0.0
    degenerate = False
    used = False
    for i in range(m - 1):
        for j in range(i + 1, m):
            if tiny[i] or tiny[j]:
                continue  # not a pair of two real generators
            c0 = g[1, i] * g[2, j] - g[2, i] * g[1, j]
            c1 = g[2, i] * g[0, j] - g[0, i] * g[2, j]
            c2 = g[0, i] * g[1, j] - g[1, i] * g[0, j]
            cn = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
            if not cn > parallel_tol * (norms[i] * norms[j]):
                degenerate = True  # parallel: the pair gives no corner
                continue
            near = ortho_tol * cn  # |c . g_k| / (|c| |g_k|) at most ortho_tol: in the plane
            b0 = b1 = b2 = 0.0  # the vertex: sum of sign(c . g_k) g_k over the other k
            for k in range(m):
                if k == i or k == j or tiny[k]:
                    continue
                d = c0 * g[0, k] + c1 * g[1, k] + c2 * g[2, k]
                if not abs(d) > near * norms[k]:
                    degenerate = True  # g_k in the plane of the pair
                if d > 0.0:
                    b0 += g[0, k]
                    b1 += g[1, k]
                    b2 += g[2, k]
                elif d < 0.0:
                    b0 -= g[0, k]
                    b1 -= g[1, k]
                    b2 -= g[2, k]
            used = True
            for a in (1.0, -1.0):
                p0, p1, p2 = b0 + a * g[0, i], b1 + a * g[1, i], b2 + a * g[2, i]
                for b in (1.0, -1.0):
                    x0, x1, x2 = p0 + b * g[0, j], p1 + b * g[1, j], p2 + b * g[2, j]
                    sq = x0 * x0 + x1 * x1 + x2 * x2
                    if sq > best:
                        best = sq
    return best, degenerate, used


def _vertex_max_poses(g, norms, tiny, parallel_tol, ortho_tol):
    """Per pose of g (N, 3, m) (tiny generators zeroed), norms (N, m), tiny (N, m): the
    largest vertex norm (N,) over the usable pairs (0 if none), degenerate (N,) bool, and
    whether any pair was usable (N,) bool."""
    n = g.shape[0]
    best = np.empty(n)
    degenerate = np.empty(n, dtype=np.bool_)
    used = np.empty(n, dtype=np.bool_)
    for r in range(n):
        sq, degenerate[r], used[r] = _pose_vertex_max(g[r], norms[r], tiny[r], parallel_tol,
                                                      ortho_tol)
        best[r] = np.sqrt(sq)
    return best, degenerate, used


def _pose_error_map(q, a, b, p, R, EA, t, elastic, singular_scale, A, k, M, X):
    """``accuracy.error_map`` of pose q (of p (N, 3), R (N, 3, 3); anchors a, b (m, 3)) into
    X (6, m), with A (6, m), k (m,), M (6, 6) as room: whether the pose is singular (sqrt
    |det A A^T| not above singular_scale, a length not positive, a stiffness not finite and
    positive; X then meaningless). Six cables G = A^-T; more (A K A^T)^-1 A K,
    k_i = EA_i / L0_i with L0 = L / (1 + t / EA) where ``elastic``, else 1 / L_i."""
    m = a.shape[0]
    bad = False
    for i in range(m):
        r0 = R[q, 0, 0] * b[i, 0] + R[q, 0, 1] * b[i, 1] + R[q, 0, 2] * b[i, 2]
        r1 = R[q, 1, 0] * b[i, 0] + R[q, 1, 1] * b[i, 1] + R[q, 1, 2] * b[i, 2]
        r2 = R[q, 2, 0] * b[i, 0] + R[q, 2, 1] * b[i, 1] + R[q, 2, 2] * b[i, 2]
        d0, d1, d2 = p[q, 0] + r0 - a[i, 0], p[q, 1] + r1 - a[i, 1], p[q, 2] + r2 - a[i, 2]
        L = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        if not L > 0.0:
            bad = True
            L = 1.0
        u0, u1, u2 = d0 / L, d1 / L, d2 / L
        A[0, i], A[1, i], A[2, i] = u0, u1, u2
        # (R b_i) x u_i = (a_i - p) x u_i
        e0, e1, e2 = a[i, 0] - p[q, 0], a[i, 1] - p[q, 1], a[i, 2] - p[q, 2]
        A[3, i] = e1 * u2 - e2 * u1
        A[4, i] = e2 * u0 - e0 * u2
        A[5, i] = e0 * u1 - e1 * u0
        stretch = 1.0 + t[q, i] / EA[i] if elastic else 1.0
        L0 = L / stretch if stretch != 0.0 else np.inf  # (numba raises on x / 0)
        k[i] = (EA[i] / L0 if elastic else 1.0 / L) if L0 != 0.0 else np.inf
        if not (np.isfinite(k[i]) and k[i] > 0.0):
            bad = True
            k[i] = 1.0
    if m == 6:  # G = A^-T: A^T G = I
        for r in range(6):
            for c in range(6):
                M[r, c] = A[c, r]
                X[r, c] = 1.0 if r == c else 0.0
        scale = abs(_eliminate(M, X)[1])
    else:
        for r in range(6):
            for c in range(r + 1):
                acc = 0.0
                for i in range(m):
                    acc += A[r, i] * A[c, i]
                M[r, c] = acc
                M[c, r] = acc
        scale = np.sqrt(abs(_eliminate(M, X[:, :0])[1]))
        for r in range(6):
            for c in range(r + 1):
                acc = 0.0
                for i in range(m):
                    acc += A[r, i] * k[i] * A[c, i]
                M[r, c] = acc
                M[c, r] = acc
            for i in range(m):
                X[r, i] = A[r, i] * k[i]
        if _eliminate(M, X)[1] == 0.0:
            bad = True
    return bad or not scale > singular_scale


def _error_maps(a, b, p, R, EA, t, elastic, singular_scale):
    """``accuracy.error_map`` at poses p (N, 3), R (N, 3, 3): G (N, 6, m), nan where
    singular (``_pose_error_map``)."""
    n, m = p.shape[0], a.shape[0]
    G = np.empty((n, 6, m))
    A, k, M, X = np.empty((6, m)), np.empty(m), np.empty((6, 6)), np.empty((6, m))
    for q in range(n):
        bad = _pose_error_map(q, a, b, p, R, EA, t, elastic, singular_scale, A, k, M, X)
        for r in range(6):
            for i in range(m):
                G[q, r, i] = np.nan if bad else X[r, i]
    return G


def _pose_accuracies(a, b, p, R, EA, t, elastic, singular_scale, e, tiny_tol, parallel_tol,
                     ortho_tol):
    """``accuracy.pose_accuracy``'s position and orientation errors (N, 2) at poses p
    (N, 3), R (N, 3, 3) of winch errors e (m,), where that is the common case: the pose not
    singular, the generators g = G[rows] e finite, none tiny (<= tiny_tol of the largest),
    a pair usable and none degenerate; there the same numbers as ``error_map`` then
    ``box_max_norm`` (sqrt of the largest vertex norm^2, the tiny generators' sum 0 added).
    Elsewhere ``other`` (N,) is True and the errors are to be found by those."""
    n, m = p.shape[0], a.shape[0]
    out = np.empty((n, 2))
    other = np.zeros(n, dtype=np.bool_)
    A, k, M, X = np.empty((6, m)), np.empty(m), np.empty((6, 6)), np.empty((6, m))
    g = np.empty((3, m))
    norms = np.empty(m)
    tiny = np.zeros(m, dtype=np.bool_)
    for q in range(n):
        if _pose_error_map(q, a, b, p, R, EA, t, elastic, singular_scale, A, k, M, X):
            other[q] = True
            continue
        for block in range(2):
            largest = 0.0
            for i in range(m):
                for x in range(3):
                    g[x, i] = X[3 * block + x, i] * e[i]
                norms[i] = np.sqrt(g[0, i] * g[0, i] + g[1, i] * g[1, i] + g[2, i] * g[2, i])
                if not np.isfinite(norms[i]):
                    other[q] = True
                largest = max(largest, norms[i])
            for i in range(m):
                if norms[i] <= tiny_tol * largest:
                    other[q] = True
            if other[q]:
                break
            sq, degenerate, used = _pose_vertex_max(g, norms, tiny, parallel_tol, ortho_tol)
            if degenerate or not used:
                other[q] = True
                break
            out[q, block] = np.sqrt(sq)
    return out, other


# ----- compilation -------------------------------------------------------------------------
HELPERS = ("_pose_vertex_max", "_eliminate", "_pose_error_map")
AOT_EXPORTS = {"vertex_max_kernel": (
    "Tuple((float64[::1], boolean[::1], boolean[::1]))"
    "(float64[:, :, ::1], float64[:, ::1], boolean[:, ::1], float64, float64)"),
    "error_map_kernel": ("float64[:, :, ::1](float64[:, ::1], float64[:, ::1], float64[:, ::1], "
                         "float64[:, :, ::1], float64[::1], float64[:, ::1], boolean, float64)"),
    "accuracy_kernel": ("Tuple((float64[:, ::1], boolean[::1]))(float64[:, ::1], float64[:, ::1], "
                        "float64[:, ::1], float64[:, :, ::1], float64[::1], float64[:, ::1], boolean, "
                        "float64, float64[::1], float64, float64, float64)")}
AOT_PREFIX = "_accuracy_aot_"


AOT_SOURCES = ("accuracy_kernel.py", "kernel_linalg.py")  # what the machine code is of


def jit_kernels():
    """numba's JIT entry (cache=True) by name (``cdh_planner.aot``); the helper becomes a
    numba function here."""
    njit = aot.jit(globals(), HELPERS)
    return {"vertex_max_kernel": njit(_vertex_max_poses), "error_map_kernel": njit(_error_maps),
            "accuracy_kernel": njit(_pose_accuracies)}


_entries = aot.entries(sys.modules[__name__])
vertex_max_kernel, error_map_kernel = _entries["vertex_max_kernel"], _entries["error_map_kernel"]
accuracy_kernel = _entries["accuracy_kernel"]
