"""The rows of ``verify --json`` put together by a compiled loop: each row is fixed texts
(keys, brackets) around its fields' texts, which lie in one buffer of the columns' texts
(each numeric column written by orjson at once). Python's per-row ``%`` formatting, and the
splitting of every column's text into one string per row before it, cost 0.1 s for 20,000
poses; this copies the 27 MB once.

Plain Python here (no numba import): ``assemble_rows`` is the build ahead of time (``python
-m cdh_planner.commands.json_rows_aot``, run by ``make``), else numba's JIT with
``cache=True`` (``cdh_planner.aot``). Its arguments are C-contiguous arrays as AOT_EXPORTS
says, unchecked.
"""

import sys

import numpy as np

from .. import aot

COMMA, SPACE = 44, 32  # ASCII ",", " "


def _assemble_rows(src, starts, ends, spaced, literals, bounds, separator):
    """The rows joined by ``separator`` (uint8): row r is literals piece 0, field 0 (src[starts[r,
    0]:ends[r, 0]], a space after each comma where ``spaced[0]``), piece 1, ..., field F - 1,
    piece F, where piece k is literals[bounds[k]:bounds[k + 1]] (bounds (F + 2,)). One pass
    into room for a space after every byte (pages never written are never allocated)."""
    n, f = starts.shape
    room = n * (bounds[f + 1] - bounds[0]) + max(n - 1, 0) * separator.size
    for r in range(n):
        for k in range(f):
            room += 2 * (ends[r, k] - starts[r, k])
    out = np.empty(room, dtype=np.uint8)
    o = 0
    for r in range(n):
        if r > 0:
            out[o:o + separator.size] = separator
            o += separator.size
        for k in range(f + 1):
            size = bounds[k + 1] - bounds[k]
            out[o:o + size] = literals[bounds[k]:bounds[k + 1]]
            o += size
            if k == f:
                break
            a, b = starts[r, k], ends[r, k]
            if not spaced[k]:
                out[o:o + b - a] = src[a:b]
                o += b - a
                continue
            for i in range(a, b):
                out[o] = src[i]
                o += 1
                if src[i] == COMMA:
                    out[o] = SPACE
                    o += 1
    return out[:o]


# ----- compilation -------------------------------------------------------------------------
HELPERS = ()
AOT_EXPORTS = {"assemble_rows": (
    "uint8[::1](uint8[::1], int64[:, ::1], int64[:, ::1], boolean[::1], uint8[::1], int64[::1], "
    "uint8[::1])")}
AOT_PREFIX = "_json_rows_aot_"


AOT_SOURCES = ("json_rows.py",)  # what the machine code is of: this file


def jit_kernels():
    """numba's JIT entry (cache=True) by name (``cdh_planner.aot``)."""
    return {"assemble_rows": aot.jit(globals(), HELPERS)(_assemble_rows)}


assemble_rows = aot.entries(sys.modules[__name__])["assemble_rows"]
