"""Build the accuracy's zonotope kernel (accuracy_kernel.py) ahead of time next to its source.

    python -m cdh_planner.accuracy_aot

The build, its naming and the JIT fallback without a C compiler: ``cdh_planner.aot``.
``make`` runs this.
"""

import sys

import numpy as np

from . import aot, accuracy_kernel


def warm_jit():
    """Compile the JIT kernel once (six generators, one pose) so that its cache is there."""
    g = np.random.default_rng(0).normal(size=(1, 3, 6))
    norms = np.linalg.norm(g, axis=1)
    accuracy_kernel.jit_kernels()["vertex_max_kernel"](g, norms, np.zeros((1, 6), dtype=bool),
                                                        1e-6, 1e-9)


if __name__ == "__main__":
    sys.exit(aot.main("accuracy kernel", accuracy_kernel, warm_jit))
