"""Build the ahead-of-time compiled collision kernel (kernels.py) next to its source.

    python -m cdh_planner.scene.aot

The build, its naming and the JIT fallback without a C compiler: ``cdh_planner.aot``.
``make`` runs this.
"""

import sys

import numpy as np

from .. import aot
from ..model.shape_forms import COAL_FORM
from . import kernels


def warm_jit():
    """Compile the JIT kernel once (two cables, one obstacle, one pose) so that its cache
    (in __pycache__) is there."""
    m, K, n = 2, 1, 1
    o = 6 * m + 7 * K + 2  # the offset of the cable radius (one pair: 2 trims)
    static = np.zeros(o + 19)
    static[o + 5] = -1.0  # no platform
    static[o + 6] = COAL_FORM
    kernels.jit_kernel()(np.zeros((n, 3)), np.tile(np.eye(3), (n, 1, 1)), static,
                         np.array([[0, 1]], dtype=np.int64), np.empty((n, m + 1, K + 1)),
                         np.empty((n, m, 16)), np.empty((n, m, 13)), np.empty((n, 1)),
                         np.empty((n, m)), np.empty((n, 3)))


if __name__ == "__main__":
    sys.exit(aot.main("collision kernel", kernels, warm_jit))
