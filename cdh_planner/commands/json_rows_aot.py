"""Build the JSON rows' kernel (json_rows.py) ahead of time next to its source.

    python -m cdh_planner.commands.json_rows_aot

The build, its naming and the JIT fallback without a C compiler: ``cdh_planner.aot``.
``make`` runs this.
"""

import sys

import numpy as np

from .. import aot
from . import json_rows


def warm_jit():
    """Compile the JIT kernel once (two rows of two fields) so that its cache is there."""
    src = np.frombuffer(b"[[1,2],[3,4]]x", dtype=np.uint8).copy()
    starts, ends = np.array([[0, 13], [0, 13]]), np.array([[13, 14], [13, 14]])
    literals = np.frombuffer(b"{a: , b: }", dtype=np.uint8).copy()
    json_rows.jit_kernels()["assemble_rows"](src, starts, ends, np.array([2, 0]),
                                             literals, np.array([0, 4, 9, 10]),
                                             np.frombuffer(b",\n", dtype=np.uint8).copy())


if __name__ == "__main__":
    sys.exit(aot.main("JSON rows kernel", json_rows, warm_jit))
