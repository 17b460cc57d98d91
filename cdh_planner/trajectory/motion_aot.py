"""Build the trajectory's per-sample kernels (motion_kernel.py) ahead of time next to their
source.

    python -m cdh_planner.trajectory.motion_aot

The build, its naming and the JIT fallback without a C compiler: ``cdh_planner.aot``.
``make`` runs this.
"""

import sys

import numpy as np

from .. import aot
from . import motion_kernel


def warm_jit():
    """Compile the JIT kernels once (six cables, one sample) so that their cache is there."""
    rows = np.zeros((1, 3))
    angles = np.linspace(0.0, 2 * np.pi, 6, endpoint=False)
    a = np.stack([np.cos(angles), np.sin(angles), np.ones(6)], axis=1)
    motion_kernel.jit_kernels()["motion_terms_kernel"](
        rows, rows, rows, np.eye(3)[None].copy(), rows, rows, a, 0.1 * a, np.zeros(3), 1.0,
        np.eye(3))
    motion_kernel.jit_kernels()["turns_kernel"](np.eye(3)[None].copy(), np.zeros(1, dtype=np.int64),
                                               np.zeros(1, dtype=np.int64), 1e-3)


if __name__ == "__main__":
    sys.exit(aot.main("motion kernel", motion_kernel, warm_jit))
