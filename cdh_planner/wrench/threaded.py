"""The facet test and the centred rule on numba's threads, for large batches (``compiled``
decides when): chunks of PARALLEL_CHUNK poses, the chunks of the serial entries from
PARALLEL_MIN poses on, so the same numbers. JIT only: numba.pycc compiles no
``parallel=True`` code. They call kernel.py's and centred.py's helpers as numba functions:
reach them through ``compiled.threaded_kernels()``, which makes them so first (importing
numba and their machine code from its cache: 0.4 - 0.5 s of CPU).

numba's cache of these two functions is keyed to this file's time stamp, not to the
kernels' sources they call: ``python -m cdh_planner.wrench.aot`` (``make``) recompiles them.
"""

import numpy as np
from numba import njit, prange

from . import centred, kernel
from .kernel import PARALLEL_CHUNK


@njit(cache=True, parallel=True)
def facet_kernel(J, c, w_local, L3, load_frame, tmin, tmax, subsets, singular_det):
    """``kernel.facet_kernel`` over chunks of PARALLEL_CHUNK poses on numba's threads."""
    n = J.shape[0]
    out = kernel._facet_outputs(n)
    chunks = (n + PARALLEL_CHUNK - 1) // PARALLEL_CHUNK
    for k in prange(chunks):
        kernel._facet_poses(k * PARALLEL_CHUNK, min(n, (k + 1) * PARALLEL_CHUNK), J, c, w_local,
                            L3, load_frame, tmin, tmax, subsets, singular_det, *out)
    return out


@njit(cache=True, parallel=True)
def centred_kernel(J, c, w_local, L3, load_frame, tmin, tmax, ranked, centre):
    """``centred.centred_kernel`` over chunks of PARALLEL_CHUNK poses on numba's threads."""
    n, m = J.shape[0], J.shape[2]
    t0, v = np.full((n, m), np.nan), np.full((n, m), np.inf)
    chunks = (n + PARALLEL_CHUNK - 1) // PARALLEL_CHUNK
    for k in prange(chunks):
        centred._centred_poses(k * PARALLEL_CHUNK, min(n, (k + 1) * PARALLEL_CHUNK), J, c,
                               w_local, L3, load_frame, tmin, tmax, ranked, centre, t0, v)
    return t0, v
