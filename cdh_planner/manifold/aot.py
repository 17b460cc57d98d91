"""Build the ahead-of-time compiled kernel (kernels.py) next to its source.

    python -m cdh_planner.manifold.aot

The build, its naming and the JIT fallback without a C compiler: ``cdh_planner.aot``.
``make`` runs this.
"""

import sys

import numpy as np

from .. import aot
from . import kernels


def warm_jit():
    """Compile the JIT kernels once so that their cache (in __pycache__) is there."""
    X, prm = np.ones(kernels.N_VARS), np.ones(kernels.N_PARAMS)
    prm[kernels.K_KAPPA] = 0.1
    prm[kernels.K_LMAX:kernels.K_FMIN] = 3.0  # length and tension ranges of non-zero width
    prm[kernels.K_FMAX:kernels.K_KAPPA] = 4.0
    kernels.jit_kernel()(X, prm, True)
    kernels.jit_kernels()["block_solve"](np.eye(kernels.N_VARS), X, kernels.navigation_blocks())


if __name__ == "__main__":
    sys.exit(aot.main("kernel", kernels, warm_jit))
