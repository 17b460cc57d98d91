"""``verify --json``'s rows written by compiled C (json_text.c) in one pass, numbers as
Python's json module writes them (floats by repr: Ryu's shortest round-trip digits, vendored
in ryu/, as orjson and CPython find them), with the GIL released: blocks of rows are written
on threads side by side (``parallel.in_order``). For 20,000 eight-cable poses the JSON's
25 MB took orjson (under the GIL), a pass rewriting its odd numbers as repr does and a
compiled assembly of the rows 0.085 - 0.105 s; measurements in docs/performance.md.

    python -m cdh_planner.commands.json_text     # the build, which ``make`` runs

builds ``_json_text_<digest>.so`` beside the source (the digest: of the C sources and this
file, so an edited source never runs a stale build), loaded with ctypes. Without a build (no
C compiler), ``rows_text`` returns None and verify writes the rows with the json module:
the same bytes, some ten times slower.
"""

import ctypes
import json
import os
import sys
from pathlib import Path

import numpy as np

try:  # CPython's built-in SHA-256 (to 3.11): hashlib's import loads OpenSSL (cdh_planner.aot)
    from _sha256 import sha256
except ImportError:
    from hashlib import sha256

FLOAT, INT, BOOL, TEXT = 0, 1, 2, 3  # a field's kind, as json_text.c reads it
SOURCES = ("json_text.c", "ryu/d2s.c", "ryu/common.h", "ryu/d2s_full_table.h",
           "ryu/d2s_intrinsics.h", "ryu/digit_table.h", "ryu/ryu.h")
PREFIX = "_json_text_"
FLAGS = ("-O2", "-shared", "-fPIC")
FOLDER = Path(__file__).resolve().parent
# the most bytes a number's text takes: a float's repr ("-2.2250738585072014e-308"), an int64
MAX_TEXT = {FLOAT: 24, INT: 20, BOOL: 5}
SLACK = 48  # json_text.c writes up to 16 bytes past a number's text; it is overwritten

_entry = None  # json_rows of the loaded build, False if there is none


def library_path():
    """Where the build of the current sources is (or would be)."""
    h = sha256(Path(__file__).read_bytes())
    for name in SOURCES:
        h.update((FOLDER / name).read_bytes())
    return FOLDER / f"{PREFIX}{h.hexdigest()[:12]}.so"


def built():
    """The C function ``json_rows`` of the current sources' build, or None if not built."""
    global _entry
    if _entry is None:
        try:
            function = ctypes.CDLL(str(library_path())).json_rows
        except OSError:  # not built (or a build of other sources only)
            _entry = False
        else:
            function.restype = ctypes.c_int64
            function.argtypes = ([ctypes.c_int64, ctypes.c_int32] + [ctypes.c_void_p] * 7
                                 + [ctypes.c_int64, ctypes.c_void_p])
            _entry = function
    return _entry or None


def rows_text(literals, columns, separator):
    """The rows of ``columns`` joined by ``separator`` (str) as a uint8 array of ASCII, or None
    without a build: row r is literals[0], field 0's text, literals[1], ..., literals[F]
    (``literals``: F + 1 str). A column is a numeric or boolean array, first axis the rows
    (a 2-D one a list a row), or a list of the rows' JSON texts (ASCII), written as given."""
    function = built()
    if function is None:
        return None
    n = len(columns[0])
    kinds, widths, data, offsets = [], [], [], []
    room = n * (sum(map(len, literals)) + len(separator)) + SLACK
    for col in columns:
        kind, width, values, starts = _field(col)
        kinds.append(kind)
        widths.append(width)
        data.append(values)
        offsets.append(starts)
        room += (values.size if kind == TEXT else
                 n * (MAX_TEXT[kind] if width < 0 else 2 + width * (MAX_TEXT[kind] + 2)))
    text = "".join(literals).encode("ascii")
    bounds = np.cumsum([0] + [len(t) for t in literals], dtype=np.int64)
    sep = separator.encode("ascii")
    out = np.empty(room, dtype=np.uint8)
    # every array the C function reads is held here for the call (an address alone is not)
    held = (np.array(kinds, dtype=np.int32), np.array(widths, dtype=np.int64), _addresses(data),
            _addresses(offsets), bounds)
    size = function(n, len(columns), *(a.ctypes.data for a in held[:4]), text,
                    bounds.ctypes.data, sep, len(sep), out.ctypes.data)
    return out[:size]


def _field(col):
    """(kind, width, values, offsets) of one column as json_rows reads it: numbers as
    float64 / int64 / uint8 rows (width -1: one a row, else a list of width), texts as
    their bytes and the (n + 1) int64 offsets of the rows' texts in them (None for
    numbers); unsigned integers beyond int64 as texts."""
    if isinstance(col, np.ndarray) and col.dtype.kind == "u" and col.size and \
            col.max() > np.iinfo(np.int64).max:
        col = [json.dumps(v) for v in col.tolist()]
    if isinstance(col, list):
        lengths = np.fromiter(map(len, col), dtype=np.int64, count=len(col))
        offsets = np.zeros(len(col) + 1, dtype=np.int64)
        np.cumsum(lengths, out=offsets[1:])
        return TEXT, 0, np.frombuffer("".join(col).encode("ascii"), dtype=np.uint8), offsets
    arr = np.asarray(col)
    width = -1 if arr.ndim == 1 else arr.shape[1]
    if arr.dtype.kind == "b":
        return BOOL, width, np.ascontiguousarray(arr).view(np.uint8), None
    if arr.dtype.kind in "iu":
        return INT, width, np.ascontiguousarray(arr, dtype=np.int64), None
    return FLOAT, width, np.ascontiguousarray(arr, dtype=np.float64), None


def _addresses(arrays):
    """The arrays' data addresses (0 for None), a uint64 array (the arrays must stay
    referenced while it is used)."""
    return np.array([0 if a is None else a.ctypes.data for a in arrays], dtype=np.uint64)


# ----- the build ---------------------------------------------------------------------------

def build():
    """Compile json_text.c into ``library_path()`` (CC, else Python's compiler, else cc);
    older builds (PREFIX*) are removed. Its path."""
    import shlex  # the build's only: 5 ms of every verify's start
    import subprocess
    import sysconfig

    target = library_path()
    part = target.with_name(f".{target.name}.{os.getpid()}.part")
    compiler = shlex.split(os.environ.get("CC") or sysconfig.get_config_var("CC") or "cc")
    try:
        subprocess.run([*compiler, *FLAGS, f"-I{FOLDER}", str(FOLDER / SOURCES[0]), "-o", str(part)],
                       check=True, capture_output=True, text=True)
        os.replace(part, target)
    finally:
        part.unlink(missing_ok=True)
    for old in FOLDER.glob(PREFIX + "*"):
        if old != target:
            old.unlink()
    return target


def main():
    """Build; if that fails, say so and exit 0 (verify then writes with the json module)."""
    import subprocess
    import time

    t = time.perf_counter()
    try:
        path = build()
    except (OSError, subprocess.CalledProcessError) as exc:
        detail = getattr(exc, "stderr", "") or ""
        print(f"JSON rows: the C build failed ({type(exc).__name__}: {exc} {detail.strip()[:300]}); "
              "verify --json writes with the json module instead", file=sys.stderr)
        return 0
    print(f"JSON rows: {path.name} built in {time.perf_counter() - t:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
