"""Build the elastic equilibrium's kernel (elastic_kernel.py) ahead of time next to its
source.

    python -m cdh_planner.model.elastic_aot

The build, its naming and the JIT fallback without a C compiler: ``cdh_planner.aot``.
``make`` runs this.
"""

import sys

import numpy as np

from .. import aot
from . import elastic_kernel


def warm_jit():
    """Compile the JIT kernel once (six cables, one pose) so that its cache is there."""
    m = 6
    angles = np.linspace(0.0, 2 * np.pi, m, endpoint=False)
    a = np.stack([np.cos(angles), np.sin(angles), np.ones(m)], axis=1)
    b = 0.1 * np.stack([np.cos(angles), np.sin(angles), np.zeros(m)], axis=1)
    L0 = np.linalg.norm(a - b, axis=1)[None]
    rows = np.zeros((1, 3))
    elastic_kernel.jit_kernels()["equilibrium_kernel"](
        a, b, np.zeros(3), np.full(m, 1e5), L0, rows.copy(), np.eye(3)[None].copy(),
        np.array([[0.0, 0.0, -1.0]]), rows.copy(), rows.copy(), np.array([1e-9]), 5, 2)


if __name__ == "__main__":
    sys.exit(aot.main("elastic kernel", elastic_kernel, warm_jit))
