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
    """Compile the JIT entries once (two cables, one ball, one pose) so that their cache
    (in __pycache__) is there."""
    m, K, n = 2, 1, 1
    o = 6 * m + 20 * K + 2  # the offset of the cable radius (one pair: 2 trims)
    static = np.zeros(o + 19)
    static[6 * m + 7 * K:6 * m + 20 * K] = [kernels.SPHERE_FORM, 0.01, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1]
    static[o + 5] = -1.0  # no platform
    static[o + 6] = COAL_FORM
    pose, pairs = (np.zeros((n, 3)), np.tile(np.eye(3), (n, 1, 1))), np.array([[0, 1]], dtype=np.int64)
    entries = kernels.jit_kernels()
    entries["collision_batch"](*pose, static, pairs, np.empty((n, m + 1, K + 1)),
                               np.empty((n, m, 16)), np.empty((n, m, 13)), np.empty((n, 1)),
                               np.empty((n, m)), np.empty((n, 3)))
    entries["cable_obstacle_batch"](*pose, static, pairs, np.empty((n, m, K)))


if __name__ == "__main__":
    sys.exit(aot.main("collision kernel", kernels, warm_jit))
