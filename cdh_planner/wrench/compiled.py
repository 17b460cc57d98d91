"""The wrench kernels as machine code (kernel.py: the pose geometry, the facet test, the
band of elastic cables and the six-cable rule; centred.py: the centred rule; linalg.py and
../kernel_linalg.py: their linear algebra; plain Python, no numba import): five entries
built ahead of time into one extension module (``python -m cdh_planner.wrench.aot``, run
by ``make``; ``cdh_planner.aot``), else compiled by numba's JIT with ``cache=True``. Ahead
of time, importing this module and a first call take about 10 ms and numba is not
imported; the JIT costs 0.5 - 1 s of a fresh process (the cached code). The entries
release the GIL: large batches run in blocks of poses on threads (``cdh_planner.parallel``).

The entries take C-contiguous float64 arrays, bool arrays, a bool and an int, as
AOT_EXPORTS says, unchecked: ``pose_geometry``, ``facet_batch``, ``centred_batch``,
``stiffness_band_batch`` and ``six_cable_batch`` pass them so. Units: m, N, N m.
"""

import sys

import numpy as np

from .. import aot
from ..parallel import blocks
from . import centred, kernel
from .kernel import PARALLEL_CHUNK, PARALLEL_MIN

_F64_1, _F64_2, _F64_3 = "float64[::1]", "float64[:, ::1]", "float64[:, :, ::1]"
# J, c, the ellipsoid (w_local, L3, load_frame), tmin, tmax
_POSES_AND_LIMITS = f"{_F64_3}, {_F64_2}, {_F64_1}, {_F64_2}, boolean, {_F64_1}, {_F64_1}"
AOT_EXPORTS = {
    "pose_geometry": f"Tuple(({_F64_2}, {_F64_3}, {_F64_3}, {_F64_2}))"
                     f"({_F64_2}, {_F64_3}, {_F64_2}, {_F64_2}, {_F64_1})",
    "facet_kernel": f"Tuple(({_F64_1}, {_F64_1}, {_F64_1}, int64[::1], int64[::1], boolean[::1]))"
                    f"({_POSES_AND_LIMITS}, int64[:, ::1], float64)",
    "centred_kernel": f"Tuple(({_F64_2}, {_F64_2}))"
                      f"({_POSES_AND_LIMITS}, boolean[::1], boolean[::1], int64)",
    "stiffness_band_kernel": f"{_F64_2}({_F64_3}, {_F64_2}, {_F64_1}, {_F64_2}, boolean, "
                             f"{_F64_2}, boolean[::1])",
    "six_cable_kernel": f"Tuple(({_F64_2}, {_F64_2}, {_F64_3}, boolean[::1]))"
                        f"({_F64_2}, {_F64_3}, {_F64_2}, {_F64_2}, {_F64_1}, {_F64_1}, {_F64_2}, "
                        f"boolean, {_F64_3}, float64)",
}
AOT_PREFIX = "_kernels_aot_"
# the functions the entries call, by module: numba functions under the JIT
KERNEL_HELPERS = ("eliminate", "gauss_jordan", "_off_subsets", "_subset_structure", "householder_r", "null_vector", "_null_normal", "load_wrench",
                  "_facet_outputs", "_facet_poses", "lu_factor6", "lu_solve6")
CENTRED_HELPERS = ("householder_r", "forward_substitute", "null_basis", "cholesky_solve",
                   "load_wrench", "_log_product", "_slacks", "_centre_scratch", "_centre", "_centred_poses")


AOT_SOURCES = ("compiled.py", "kernel.py", "centred.py", "linalg.py", "../kernel_linalg.py")  # what the machine code is of: the kernels' sources and this file (the signatures)


def jit_helpers():
    """The entries' helpers as numba functions (cache=True) in kernel.py's and centred.py's
    namespaces, once; ``njit(cache=True)``, to compile the entries that call them."""
    aot.jit(vars(kernel), KERNEL_HELPERS)
    return aot.jit(vars(centred), CENTRED_HELPERS)


def jit_kernels():
    """numba's JIT entries (cache=True), by name (``cdh_planner.aot``)."""
    njit = jit_helpers()
    return {"pose_geometry": njit(kernel.pose_geometry), "facet_kernel": njit(kernel.facet_kernel),
            "centred_kernel": njit(centred.centred_kernel),
            "stiffness_band_kernel": njit(kernel.stiffness_band_kernel),
            "six_cable_kernel": njit(kernel.six_cable_kernel)}


_entries = aot.entries(sys.modules[__name__])


def _typed(arrays, bools=()):
    """The arrays as the entries read them: C-contiguous float64 (``bools``: bool). The
    ahead-of-time entries check neither type nor layout (other memory reads as garbage);
    arrays that already are so are not copied."""
    return ([np.ascontiguousarray(x, dtype=np.float64) for x in arrays]
            + [np.ascontiguousarray(x, dtype=np.bool_) for x in bools])


def pose_geometry(p, R, a, b, g):
    """``kernel.pose_geometry``: lengths (N, m) m, u (N, m, 3), J (N, 6, m), load points
    c (N, 3) m at poses p (N, 3) m, R (N, 3, 3) of anchors a, b (m, 3) m, load point g (3,) m."""
    return _entries["pose_geometry"](*_typed((p, R, a, b, g)))


def six_cable_batch(p, R, a, b, g, w_local, L3, load_frame, W, singular_det):
    """``kernel.six_cable_kernel`` (its arguments and outputs): t0, v (N, 6) N, J^-1 W
    (N, K, 6), singular (N,)."""
    return _entries["six_cable_kernel"](*_typed((p, R, a, b, g, w_local, L3)), bool(load_frame),
                                        *_typed((W,)), float(singular_det))


def facet_batch(J, c, w_local, L3, load_frame, tmin, tmax, subsets, singular_det):
    """``kernel.facet_kernel`` (its arguments and outputs), a large batch in blocks on
    threads."""
    J, c, w_local, L3, tmin, tmax = _typed((J, c, w_local, L3, tmin, tmax))
    subsets = np.ascontiguousarray(subsets, dtype=np.int64)
    kernel_ = _entries["facet_kernel"]
    return blocks(lambda a, b: kernel_(J[a:b], c[a:b], w_local, L3, bool(load_frame), tmin,
                                       tmax, subsets, float(singular_det)), len(J))


def centred_batch(J, c, w_local, L3, load_frame, tmin, tmax, ranked, centre):
    """``centred.centred_kernel``'s t0 and v (N, m) N, in chunks of PARALLEL_CHUNK poses
    from PARALLEL_MIN poses (else one chunk), a large batch in blocks of chunks on threads."""
    J, c, w_local, L3, tmin, tmax, ranked, centre = _typed((J, c, w_local, L3, tmin, tmax),
                                                           (ranked, centre))
    n = len(J)
    chunk = PARALLEL_CHUNK if n >= PARALLEL_MIN else max(n, 1)
    kernel_ = _entries["centred_kernel"]
    return blocks(lambda a, b: kernel_(J[a:b], c[a:b], w_local, L3, bool(load_frame), tmin, tmax,
                                       ranked[a:b], centre[a:b], chunk), n, chunk)


def stiffness_band_batch(J, c, w_local, L3, load_frame, W, ok):
    """``kernel.stiffness_band_kernel`` (its arguments and output), a large batch in blocks
    on threads."""
    J, c, w_local, L3, W, ok = _typed((J, c, w_local, L3, W), (ok,))
    kernel_ = _entries["stiffness_band_kernel"]
    return blocks(lambda a, b: kernel_(J[a:b], c[a:b], w_local, L3, bool(load_frame), W[a:b],
                                       ok[a:b]), len(J))
