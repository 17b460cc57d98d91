"""Build the ahead-of-time compiled kernel (kernels.py) next to its source.

    python -m cdh_planner.manifold.aot

The build, its naming and the JIT fallback without a C compiler: ``cdh_planner.aot``.
``make`` runs this.
"""

import sys
from pathlib import Path

import numpy as np

from .. import aot
from . import kernels

HERE = Path(kernels.__file__).resolve().parent


def build(output_dir=HERE):
    """Compile the kernel ahead of time into ``output_dir``; the extension's path."""
    jit = kernels.jit_kernel()  # the helpers as numba functions, which the export calls
    return aot.build(kernels.aot_module_name(), {kernels.AOT_EXPORT: (kernels.AOT_SIGNATURE, jit)},
                     output_dir, kernels.AOT_PREFIX)


def warm_jit():
    """Compile the JIT kernel once so that its cache (in __pycache__) is there."""
    X = np.ones(kernels.N_VARS)
    kernels.jit_kernel()(X, np.ones(kernels.N_PARAMS), True)


if __name__ == "__main__":
    sys.exit(aot.main("kernel", build, warm_jit))
