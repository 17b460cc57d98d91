"""verify's JSON rows by compiled C (commands/json_text.py, json_text.c with the vendored
Ryu): the json module's text of every number, the same bytes as the Python fallback."""

import hashlib
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from cdh_planner.commands import json_text
from cdh_planner.commands.verify import ROW_SEPARATOR, _block_text, _python_rows, _rows_text

BUILT = json_text.built() is not None
NOT_BUILT = "verify's JSON writer not built (make, or python -m cdh_planner.commands.json_text)"


def _json_rows(values):
    """The json module's rows of one numeric column: a number (or a list) a row."""
    return ROW_SEPARATOR.join(json.dumps(np.where(np.isfinite(row), row, None).tolist()
                                         if np.asarray(row).dtype.kind == "f" else row.tolist())
                              for row in values)


def _c_rows(values):
    return json_text.rows_text(["", ""], [values], ROW_SEPARATOR).tobytes().decode()


def _every_kind_of_float():
    """Every magnitude (subnormals to the largest, both sides of repr's 1e-4 and 1e16
    switches, one- to three-digit exponents), signed zeros, non-finite numbers, integers
    and short decimals, and random bit patterns."""
    rng = np.random.default_rng(5)
    n = 20_000
    with np.errstate(over="ignore"):
        wide = rng.uniform(1, 10, n) * 10.0 ** rng.integers(-330, 309, n) * rng.choice([-1, 1], n)
    bits = rng.integers(0, 2 ** 63, 100_000, dtype=np.uint64) | (
        rng.integers(0, 2, 100_000, dtype=np.uint64) << np.uint64(63))
    powers = 2.0 ** np.arange(-1074, 1024)
    return np.concatenate([
        wide, rng.uniform(0, 1e6, n), rng.uniform(1e-5, 1e-4, n), powers, -powers,
        bits.view(np.float64), np.arange(-1000.0, 1000.0), np.round(rng.uniform(-100, 100, n), 3),
        [0.0, -0.0, np.nan, -np.nan, np.inf, -np.inf, 47740.00003585525, 1e-4,
         np.nextafter(1e-4, 0), 1e-5, 1e15, 1e16, np.nextafter(1e16, 0), 1e22, 1e23, 0.1, 0.3,
         5e-324, 1.7976931348623157e308, 123456789012345680.0, 9007199254740993.0]])


@pytest.mark.skipif(not BUILT, reason=NOT_BUILT)
def test_every_float_is_written_as_the_json_module_writes_it():
    values = _every_kind_of_float()
    assert _c_rows(values) == _json_rows(values)
    square = values[: len(values) // 6 * 6].reshape(-1, 6)  # a list of six a row
    assert _c_rows(square) == _json_rows(square)
    with np.errstate(over="ignore", invalid="ignore"):  # beyond float32: inf, nan
        single = values.astype(np.float32)
    assert _c_rows(single) == _json_rows(single.astype(float))


@pytest.mark.skipif(not BUILT, reason=NOT_BUILT)
@pytest.mark.parametrize("values", [
    np.array([0, 7, -8, np.iinfo(np.int64).max, np.iinfo(np.int64).min]),
    np.array([[1, -2], [30, 400]], dtype=np.int32), np.array([3, 2**64 - 1], dtype=np.uint64),
    np.array([True, False]), np.array([[True, False, True]]), np.zeros((2, 0))],
    ids=["int64", "int32 rows", "uint64", "bool", "bool rows", "empty rows"])
def test_integers_and_booleans_are_written_as_the_json_module_writes_them(values):
    assert _c_rows(values) == _json_rows(values)


def test_the_compiled_and_the_python_rows_are_the_same_bytes(monkeypatch):
    """A small document with every kind of field, written by hand; the fallback (no build:
    the json module entry by entry) gives the same bytes."""
    columns = {"p": np.array([[1.5, -2e-5], [np.nan, 3.0]]), "ok": np.array([True, False]),
               "worst": {"binding": ["tension_min[2,5]", "singular"], "n": np.array([7, 8])},
               "first": ["null", '{"s": 0.5}']}
    from cdh_planner.commands.verify import _Texts
    columns["first"] = _Texts(columns["first"])
    expected = ('{"p": [1.5, -2e-05], "ok": true, "worst": {"binding": "tension_min[2,5]", "n": 7}, '
                '"first": null}' + ROW_SEPARATOR +
                '{"p": [null, 3.0], "ok": false, "worst": {"binding": "singular", "n": 8}, '
                '"first": {"s": 0.5}}')
    (rows,) = _rows_text(columns)
    assert bytes(rows).decode() == expected
    assert isinstance(rows, np.ndarray) == BUILT  # the compiled writer's, where built
    monkeypatch.setattr(json_text, "_entry", False)  # as without a build
    (rows,) = _rows_text(columns)
    assert isinstance(rows, bytes) and rows.decode() == expected


@pytest.mark.skipif(not BUILT, reason=NOT_BUILT)
def test_a_block_of_verify_rows_is_the_fallbacks():
    """Random columns as verify's poses have them (floats with nan, rows of eight, names,
    booleans, integers): the compiled writer's text is the json module's."""
    rng = np.random.default_rng(2)
    n = 3000
    t = rng.normal(0, 1e3, (n, 8)) * 10.0 ** rng.integers(-8, 8, (n, 8))
    t[rng.random((n, 8)) < 0.05] = np.nan
    cols = [rng.normal(size=(n, 3)), t, rng.random(n) < 0.5, rng.integers(-5, 10**12, n),
            np.array(["singular", "tension_max[3]", "collision winch_2 / ball"])[rng.integers(0, 3, n)]]
    literals = ['{"a": ', ', "b": ', ', "c": ', ', "d": ', ', "e": ', "}"]
    texts = [c if c.dtype.kind != "U" else [json.dumps(v) for v in c.tolist()] for c in cols]
    assert bytes(_block_text(literals, cols)) == _python_rows(literals, texts)


def test_the_build_is_named_after_the_digest_of_its_sources():
    folder = Path(json_text.__file__).parent
    h = hashlib.sha256(Path(json_text.__file__).read_bytes()
                       + b"".join((folder / name).read_bytes() for name in json_text.SOURCES))
    assert json_text.library_path().name == f"_json_text_{h.hexdigest()[:12]}.so"
    includes = (folder / "json_text.c").read_text() + (folder / "ryu/d2s.c").read_text()
    for name in json_text.SOURCES[1:]:  # every file the build reads is in the digest
        assert Path(name).name in includes


def test_a_build_of_other_sources_is_never_loaded(monkeypatch):
    monkeypatch.setattr(json_text, "SOURCES", ("verify.py",))
    monkeypatch.setattr(json_text, "_entry", None)
    assert json_text.built() is None and json_text.rows_text(["", ""], [np.ones(2)], ",") is None


def test_with_no_c_compiler_the_build_says_so_and_exits_0(tmp_path):
    """CC names no working compiler: exit 0 (verify writes with the json module), one
    message, no part file left and the build in place (if any) kept."""
    folder = Path(json_text.__file__).parent
    before = sorted(p.name for p in folder.iterdir())
    out = subprocess.run([sys.executable, "-m", "cdh_planner.commands.json_text"],
                         capture_output=True, text=True, env={**os.environ, "CC": "/bin/false"})
    assert out.returncode == 0 and "the C build failed" in out.stderr
    assert sorted(p.name for p in folder.iterdir()) == before


@pytest.mark.skipif(not BUILT, reason=NOT_BUILT)
def test_the_writer_releases_the_gil():
    """ctypes releases the GIL for the C call: a thread that only runs when it gets the GIL
    counts while rows are written. No forced switches meanwhile (a switch interval of 60 s):
    the spinner gives the GIL back at each sleep(0), the caller only inside the C call."""
    values = np.random.default_rng(0).normal(size=(100_000, 8))
    count, stop = [0], threading.Event()

    def spin():
        while not stop.is_set():
            count[0] += 1
            time.sleep(0)

    interval = sys.getswitchinterval()
    sys.setswitchinterval(60.0)
    worker = threading.Thread(target=spin)
    try:
        worker.start()
        before = count[0]
        _c_rows(values)
        during = count[0] - before
    finally:
        stop.set()
        sys.setswitchinterval(interval)
        worker.join()
    assert during > 0
