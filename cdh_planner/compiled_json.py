"""JSON in and out by compiled C (compiled_json.c), with the GIL released (ctypes), where
the Python libraries cost most: ``verify --json``'s rows (``rows_text``: in one pass, numbers
as Python's json module writes them, floats by repr: Ryu's shortest round-trip digits,
vendored in ryu/, as orjson and CPython find them; blocks of rows on threads side by side)
and a poses file in its plain form (``read_poses``: straight into arrays, numbers
correctly rounded as the json module reads them: Clinger's exact fast path, else Eisel and
Lemire's for up to 19 digits (its table of powers of ten written by the build), else strtod).
For 20,000 eight-cable poses the JSON's 25 MB took orjson (under the GIL), a pass rewriting
its odd numbers as repr does and a compiled assembly of the rows 0.085 - 0.107 s, now 0.042
- 0.056; reading the poses with orjson and lists 0.025 s, now 0.004; docs/performance.md.

    python -m cdh_planner.compiled_json     # the build, which ``make`` runs

builds ``_compiled_json_<digest>.so`` beside the source (the digest: of the C sources and
this file, so an edited source never runs a stale build), loaded with ctypes. Without a
build (no C compiler) both return None and their callers take the Python way: the same
bytes and numbers, slower.
"""

import ctypes
import json
import os
import sys
from pathlib import Path

import numpy as np

from .aot import sha256  # CPython's own SHA-256: hashlib's import loads OpenSSL

FLOAT, INT, BOOL, TEXT = 0, 1, 2, 3  # a field's kind, as compiled_json.c reads it
SOURCES = ("compiled_json.c", "ryu/d2s.c", "ryu/common.h", "ryu/d2s_full_table.h",
           "ryu/d2s_intrinsics.h", "ryu/digit_table.h", "ryu/ryu.h")
PREFIX = "_compiled_json_"
FLAGS = ("-O2", "-shared", "-fPIC")
FOLDER = Path(__file__).resolve().parent
# the most bytes a number's text takes: a float's repr ("-2.2250738585072014e-308"), an int64
MAX_TEXT = {FLOAT: 24, INT: 20, BOOL: 5}
SLACK = 48  # compiled_json.c writes up to 16 bytes past a number's text; it is overwritten

_library = None  # the loaded build's functions (a dict), False if there is none


def library_path():
    """Where the build of the current sources is (or would be)."""
    h = sha256(Path(__file__).read_bytes())
    for name in SOURCES:
        h.update((FOLDER / name).read_bytes())
    return FOLDER / f"{PREFIX}{h.hexdigest()[:12]}.so"


def built():
    """The C functions of the current sources' build (``json_rows``, ``read_poses``), or
    None if it is not built."""
    global _library
    if _library is None:
        try:
            lib = ctypes.CDLL(str(library_path()))
        except OSError:  # not built (or a build of other sources only)
            _library = False
        else:
            rows, read = lib.json_rows, lib.read_poses
            rows.restype = read.restype = ctypes.c_int64
            rows.argtypes = ([ctypes.c_int64, ctypes.c_int32] + [ctypes.c_void_p] * 7
                             + [ctypes.c_int64, ctypes.c_void_p])
            read.argtypes = [ctypes.c_char_p, ctypes.c_int64, ctypes.c_int64, ctypes.c_void_p,
                             ctypes.c_void_p]
            _library = {"json_rows": rows, "read_poses": read}
    return _library or None


def rows_text(literals, columns, separator):
    """The rows of ``columns`` joined by ``separator`` (str) as a uint8 array of ASCII, or None
    without a build: row r is literals[0], field 0's text, literals[1], ..., literals[F]
    (``literals``: F + 1 str). A column is a numeric or boolean array, first axis the rows
    (a 2-D one a list a row), or a list of the rows' JSON texts (ASCII), written as given."""
    library = built()
    if library is None:
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
    # the arrays the C function reads, named so that they live through the call (their
    # addresses alone do not keep them)
    kinds, widths = np.array(kinds, dtype=np.int32), np.array(widths, dtype=np.int64)
    data_at, offsets_at = _addresses(data), _addresses(offsets)
    size = library["json_rows"](n, len(columns), kinds.ctypes.data, widths.ctypes.data,
                                data_at.ctypes.data, offsets_at.ctypes.data, text,
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


MIN_POSE_BYTES = 30  # the shortest pose text: {"tau":[0,0,0],"position":[0,0,0]} less 5


def read_poses(data, max_poses):
    """The poses of a poses file's bytes ``data`` in its plain form (compiled_json.c says
    which): (values (N, 7), quaternion (N,) bool) with row k the position (m) then pose
    k's quaternion (x, y, z, w) if quaternion[k] else its tau (rad) and a nan; None for
    any other document (or more than ``max_poses`` poses), or without a build."""
    library = built()
    if library is None:
        return None
    rows = min(max_poses, len(data) // MIN_POSE_BYTES + 1)
    # empty, not filled: the C writes every value of the rows it reads, and a bound of
    # ~5x the poses of a usual file leaves most pages never touched (1,100 page faults)
    values = np.empty((rows, 7))
    quaternion = np.empty(rows, dtype=np.int8)
    n = library["read_poses"](data, len(data), rows, values.ctypes.data, quaternion.ctypes.data)
    if n < 0:
        return None
    return values[:n], quaternion[:n].astype(bool)


# ----- the build ---------------------------------------------------------------------------

POW10_RANGE = (-342, 308)  # 10^q for the reader's Eisel-Lemire (beyond: strtod)


def pow10_mantissa(q):
    """The 128 leading bits of 10^q, truncated: the integer T with 2^127 <= T < 2^128 and
    T <= 10^q 2^s < T + 1 for some integer s (exact, Python's integers)."""
    if q >= 0:
        v = 10 ** q
        n = v.bit_length()
        return v >> (n - 128) if n > 128 else v << (128 - n)
    d = 10 ** -q  # not a power of two: 2^(127 + bits) / d lies strictly within [2^127, 2^128)
    return (1 << (127 + d.bit_length())) // d


def pow10_table():
    """The C header of ``pow10_mantissa`` over POW10_RANGE (compiled_json.c's POW10_128:
    {high word, low word} a row), which ``build`` writes into a temporary folder for the
    compiler."""
    lo, hi = POW10_RANGE
    rows = [f"  {{0x{t >> 64:016X}u, 0x{t & (2**64 - 1):016X}u}},  /* 1e{q} */"
            for q in range(lo, hi + 1) for t in [pow10_mantissa(q)]]
    return (f"/* written by cdh_planner/compiled_json.py (pow10_table) */\n"
            f"enum {{ POW10_MIN = {lo}, POW10_MAX = {hi} }};\n"
            f"static const uint64_t POW10_128[{hi - lo + 1}][2] = {{\n"
            + "\n".join(rows) + "\n};\n")


def build():
    """Compile compiled_json.c into ``library_path()`` (CC, else Python's compiler, else cc);
    older builds (PREFIX*) are removed. Its path."""
    import shlex  # the build's only: 5 ms of every verify's start
    import subprocess
    import sysconfig
    import tempfile

    target = library_path()
    part = target.with_name(f".{target.name}.{os.getpid()}.part")
    compiler = shlex.split(os.environ.get("CC") or sysconfig.get_config_var("CC") or "cc")
    try:
        with tempfile.TemporaryDirectory() as generated:
            (Path(generated) / "pow10_128.h").write_text(pow10_table())
            subprocess.run([*compiler, *FLAGS, f"-I{FOLDER}", f"-I{generated}",
                            str(FOLDER / SOURCES[0]), "-o", str(part)],
                           check=True, capture_output=True, text=True)
        os.replace(part, target)
    finally:
        part.unlink(missing_ok=True)
    for old in FOLDER.glob(PREFIX + "*"):
        if old != target:
            old.unlink()
    return target


def main():
    """Build; if that fails, say so and exit 0 (the callers then take the Python way)."""
    import subprocess
    import time

    t = time.perf_counter()
    try:
        path = build()
    except (OSError, subprocess.CalledProcessError) as exc:
        detail = getattr(exc, "stderr", "") or ""
        print(f"compiled JSON: the C build failed ({type(exc).__name__}: {exc} {detail.strip()[:300]}); "
              "verify reads and writes JSON with Python's libraries instead", file=sys.stderr)
        return 0
    print(f"compiled JSON: {path.name} built in {time.perf_counter() - t:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
