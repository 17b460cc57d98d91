"""The rows of ``verify --json`` put together by a compiled loop: each row is fixed texts
(keys, brackets) around its fields' texts, which lie in one buffer of the columns' texts
(each numeric column written by orjson at once, its entries found by the loop as it copies
them: searching the 27 MB for them first cost 0.015 s). Python's per-row ``%`` formatting, and the
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

COMMA, SPACE, CLOSE = 44, 32, 93  # ASCII ",", " ", "]"
GIVEN, ENTRIES, ROWS = 0, 1, 2  # how a field's texts lie in the buffer (``_assemble_rows``)


def _assemble_rows(src, starts, ends, layout, literals, bounds, separator):
    """The rows joined by ``separator`` (uint8): row r is literals piece 0, field 0, piece 1,
    ..., field F - 1, piece F, where piece k is literals[bounds[k]:bounds[k + 1]] (bounds
    (F + 2,)). Field k's texts lie in ``src`` as ``layout[k]`` says: GIVEN, row r's text is
    src[starts[r, k]:ends[r, k]]; ENTRIES, the field is the compact JSON array of the rows'
    numbers in src[starts[0, k]:ends[0, k]] ("[1.5,null,2]", no entry holds "," or "]"),
    walked here; ROWS, the compact JSON array of the rows' arrays ("[[1,2],[3,4]]"), each
    written with a space after its commas. One pass into room for a space after every byte
    (pages never written are never allocated); the arrays are not searched beforehand."""
    n, f = starts.shape
    room = n * (bounds[f + 1] - bounds[0]) + max(n - 1, 0) * separator.size
    cursor = np.empty(f, dtype=np.int64)  # where the next row's entry of an array begins
    for k in range(f):
        cursor[k] = starts[0, k] + 1  # after the array's "["
        if layout[k] != GIVEN:
            room += 2 * (ends[0, k] - starts[0, k])
            continue
        for r in range(n):
            room += ends[r, k] - starts[r, k]
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
            if layout[k] == GIVEN:
                a, b = starts[r, k], ends[r, k]
                out[o:o + b - a] = src[a:b]
                o += b - a
                continue
            i = cursor[k]
            if layout[k] == ENTRIES:  # up to the "," or "]" after it
                while src[i] != COMMA and src[i] != CLOSE:
                    out[o] = src[i]
                    o += 1
                    i += 1
            else:  # "[" ... "]", a space after each comma
                while True:
                    c = src[i]
                    out[o] = c
                    o += 1
                    i += 1
                    if c == COMMA:
                        out[o] = SPACE
                        o += 1
                    elif c == CLOSE:
                        break
            cursor[k] = i + 1  # past the "," between rows
    return out[:o]


# ----- compilation -------------------------------------------------------------------------
HELPERS = ()
AOT_EXPORTS = {"assemble_rows": (
    "uint8[::1](uint8[::1], int64[:, ::1], int64[:, ::1], int64[::1], uint8[::1], int64[::1], "
    "uint8[::1])")}
AOT_PREFIX = "_json_rows_aot_"


AOT_SOURCES = ("json_rows.py",)  # what the machine code is of: this file


def jit_kernels():
    """numba's JIT entry (cache=True) by name (``cdh_planner.aot``)."""
    return {"assemble_rows": aot.jit(globals(), HELPERS)(_assemble_rows)}


assemble_rows = aot.entries(sys.modules[__name__])["assemble_rows"]
