"""The exact zonotope maximum of ``accuracy.box_max_norm`` compiled by numba, one pose at a
time: the pairs of generators, their corner normals c = g_i x g_j and the four vertices
around each (``accuracy``'s module docstring has the maths). numpy's version built
(N, P, m) temporaries for every pose block and spent most of verify's accuracy time
allocating them; this loop does the same arithmetic in the same order (the norms'
sums, the cross products, the vertices' coordinates: bit for bit the same maximum), with
one exception that cannot change the result: the dot products c . g_k, read only for
their signs and for the in-plane test, need not round like BLAS's.

Plain Python here (no numba import): ``vertex_max_kernel`` is the build ahead of time
(``python -m cdh_planner.accuracy_aot``, run by ``make``), else numba's JIT with
``cache=True`` (``cdh_planner.aot``). Its arguments are C-contiguous arrays as AOT_EXPORTS
says, unchecked.
"""

import sys

import numpy as np

from . import aot


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
            if not cn / (norms[i] * norms[j]) > parallel_tol:
                degenerate = True  # parallel: the pair gives no corner
                continue
            h0, h1, h2 = c0 / cn, c1 / cn, c2 / cn
            b0 = b1 = b2 = 0.0  # the vertex: sum of sign(c . g_k) g_k over the other k
            for k in range(m):
                if k == i or k == j or tiny[k]:
                    continue
                d = h0 * g[0, k] + h1 * g[1, k] + h2 * g[2, k]
                if not abs(d) / norms[k] > ortho_tol:
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


# ----- compilation -------------------------------------------------------------------------
HELPERS = ("_pose_vertex_max",)
AOT_EXPORTS = {"vertex_max_kernel": (
    "Tuple((float64[::1], boolean[::1], boolean[::1]))"
    "(float64[:, :, ::1], float64[:, ::1], boolean[:, ::1], float64, float64)")}
AOT_PREFIX = "_accuracy_aot_"


AOT_SOURCES = ("accuracy_kernel.py",)  # what the machine code is of: this file


def jit_kernels():
    """numba's JIT entry (cache=True) by name (``cdh_planner.aot``); the helper becomes a
    numba function here."""
    return {"vertex_max_kernel": aot.jit(globals(), HELPERS)(_vertex_max_poses)}


vertex_max_kernel = aot.entries(sys.modules[__name__])["vertex_max_kernel"]
