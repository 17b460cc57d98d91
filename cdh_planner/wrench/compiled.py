"""The wrench kernels as machine code (kernel.py: the pose geometry and the facet test;
centred.py: the centred rule; linalg.py: their linear algebra; plain Python, no numba
import): four entries built ahead of time into one extension module (``python -m
cdh_planner.wrench.aot``, run by ``make``; ``cdh_planner.aot``), else compiled by numba's JIT
with ``cache=True``. Ahead of time, importing this module and a first call take about 10 ms
and numba is not imported; the JIT costs 0.5 - 1 s of a fresh process (the cached code).

numba.pycc compiles no ``parallel=True`` code (a parfor needs numba's threading layer at run
time), so the threaded variants (``threaded``) are JIT only: ``facet_batch`` and
``centred_batch`` use them only where they pay for loading numba (``threads_pay``).

The entries take C-contiguous float64 arrays, bool arrays, a bool and an int, as
AOT_EXPORTS says, unchecked: ``pose_geometry``, ``facet_batch``, ``centred_batch`` and
``six_cable_batch`` pass them so. Units: m, N, N m.
"""

import sys

import numpy as np

from .. import aot
from . import centred, kernel
from .kernel import PARALLEL_CHUNK, PARALLEL_MIN

# from this many poses the threaded kernels repay loading numba and themselves in a fresh
# process (0.47 s of CPU): CoGiRo's facet test and centred rule take 19 - 25 us a pose
# serially, so two idle cores repay it from ~43,000 poses, eight from ~24,000; measured on 2
# loaded cores, from ~72,000 (benchmarks/wrench_kernels.py). verify's 20,000 stay serial.
THREADS_PAY_MIN = 50_000

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
    "six_cable_kernel": f"Tuple(({_F64_2}, {_F64_2}, {_F64_3}, boolean[::1]))"
                        f"({_F64_2}, {_F64_3}, {_F64_2}, {_F64_2}, {_F64_1}, {_F64_1}, {_F64_2}, "
                        f"boolean, {_F64_3}, float64)",
}
AOT_PREFIX = "_kernels_aot_"
# the functions the entries call, by module: numba functions under the JIT
KERNEL_HELPERS = ("gauss_jordan", "householder_r", "null_vector", "_subset_normal", "load_wrench",
                  "_facet_outputs", "_facet_poses", "lu_factor6", "lu_solve6")
CENTRED_HELPERS = ("householder_r", "forward_substitute", "null_basis", "cholesky_solve",
                   "load_wrench", "_log_product", "_slacks", "_centre", "_centred_poses")


AOT_SOURCES = ("compiled.py", "kernel.py", "centred.py", "linalg.py")  # what the machine code is of: the kernels' sources and this file (the signatures)


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


def threaded_kernels():
    """The module ``threaded`` (its facet_kernel and centred_kernel), the helpers it calls
    made numba functions first."""
    jit_helpers()
    from . import threaded
    return threaded


def threads_pay(n):
    """Whether n poses go to numba's threads (``threaded``): from PARALLEL_MIN poses once the
    threaded kernels are loaded in this process, from THREADS_PAY_MIN before."""
    loaded = f"{__package__}.threaded" in sys.modules
    return n >= (PARALLEL_MIN if loaded else THREADS_PAY_MIN)


def facet_batch(J, c, w_local, L3, load_frame, tmin, tmax, subsets, singular_det):
    """``kernel.facet_kernel`` (its arguments and outputs), on threads where that pays."""
    J, c, w_local, L3, tmin, tmax = _typed((J, c, w_local, L3, tmin, tmax))
    args = (J, c, w_local, L3, bool(load_frame), tmin, tmax,
            np.ascontiguousarray(subsets, dtype=np.int64), float(singular_det))
    if threads_pay(len(J)):
        return threaded_kernels().facet_kernel(*args)
    return _entries["facet_kernel"](*args)


def centred_batch(J, c, w_local, L3, load_frame, tmin, tmax, ranked, centre):
    """``centred.centred_kernel``'s t0 and v (N, m) N, in chunks of PARALLEL_CHUNK poses
    from PARALLEL_MIN poses (else one chunk), on threads where that pays."""
    J, c, w_local, L3, tmin, tmax, ranked, centre = _typed((J, c, w_local, L3, tmin, tmax),
                                                           (ranked, centre))
    args = (J, c, w_local, L3, bool(load_frame), tmin, tmax, ranked, centre)
    n = len(J)
    if threads_pay(n):
        return threaded_kernels().centred_kernel(*args)
    return _entries["centred_kernel"](*args, PARALLEL_CHUNK if n >= PARALLEL_MIN else max(n, 1))
