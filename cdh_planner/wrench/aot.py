"""Build the wrench kernels (compiled.py) ahead of time next to their sources.

    python -m cdh_planner.wrench.aot

The build, its naming and the JIT fallback without a C compiler: ``cdh_planner.aot``.
numba's cache of a function is keyed to its own file's time stamp, not to the files of the
functions it calls, so the package's wrench cache is cleared first: what is compiled here is
of the current sources. ``make`` runs this.
"""

import sys
from itertools import combinations
from pathlib import Path

import numpy as np

from .. import aot
from . import compiled


def clear_jit_cache():
    """Remove numba's cached machine code of the wrench kernels (__pycache__/*.nbi, *.nbc)."""
    for path in (Path(compiled.__file__).resolve().parent / "__pycache__").glob("*.nb[ic]"):
        path.unlink()


def warm_inputs(n=2, m=8):
    """Arguments of the facet kernel and the centred rule at n poses of an m-cable robot
    (anchors on two boxes, the platform at the centre): J, c, the ellipsoid, the limits."""
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    a, b = 2.0 * corners[:m], 0.1 * corners[:m]
    p, R = np.zeros((n, 3)), np.tile(np.eye(3), (n, 1, 1))
    _, _, J, c = compiled.pose_geometry(p, R, a, b, np.zeros(3))
    ellipsoid = (np.array([0.0, 0.0, -10.0, 0.0, 0.0, 0.0]), 0.1 * np.eye(6), True)
    return (J, c) + ellipsoid + (np.full(m, 1.0), np.full(m, 100.0))


def warm_jit():
    """Compile the JIT entries once (the fallback), so that their cache is there."""
    args = warm_inputs()
    kernels = compiled.jit_kernels()
    kernels["pose_geometry"](np.zeros((1, 3)), np.eye(3)[None], np.eye(3), np.eye(3), np.zeros(3))
    ranked = kernels["facet_kernel"](*args, np.array(list(combinations(range(8), 5))), 1e-9)[-1]
    kernels["centred_kernel"](*args, ranked, ranked, 1)
    six = warm_inputs(1, 6)
    kernels["six_cable_kernel"](np.zeros((1, 3)), np.eye(3)[None], 2.0 * np.eye(6, 3),
                                0.1 * np.eye(6, 3), np.zeros(3), six[2], six[3], True,
                                np.zeros((1, 1, 6)), 1e-12)


def main():
    """The ahead-of-time build (else the JIT warmed)."""
    clear_jit_cache()
    return aot.main("wrench kernels", compiled, warm_jit)


if __name__ == "__main__":
    sys.exit(main())
