"""JSON by compiled C (cdh_planner/compiled_json.py, compiled_json.c with the vendored
Ryu): verify's rows, the json module's text of every number and the same bytes as the
Python fallback; poses files read into the numbers the json module reads."""

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

from cdh_planner import compiled_json
from cdh_planner.commands.verify import ROW_SEPARATOR, _block_text, _python_rows, _rows_text

BUILT = compiled_json.built() is not None
NOT_BUILT = "compiled JSON not built (make, or python -m cdh_planner.compiled_json)"


def _json_rows(values):
    """The json module's rows of one numeric column: a number (or a list) a row."""
    return ROW_SEPARATOR.join(json.dumps(np.where(np.isfinite(row), row, None).tolist()
                                         if np.asarray(row).dtype.kind == "f" else row.tolist())
                              for row in values)


def _c_rows(values):
    return compiled_json.rows_text(["", ""], [values], ROW_SEPARATOR).tobytes().decode()


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
    monkeypatch.setattr(compiled_json, "_library", False)  # as without a build
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
    folder = Path(compiled_json.__file__).parent
    h = hashlib.sha256(Path(compiled_json.__file__).read_bytes()
                       + b"".join((folder / name).read_bytes() for name in compiled_json.SOURCES))
    assert compiled_json.library_path().name == f"_compiled_json_{h.hexdigest()[:12]}.so"
    includes = (folder / "compiled_json.c").read_text() + (folder / "ryu/d2s.c").read_text()
    for name in compiled_json.SOURCES[1:]:  # every file the build reads is in the digest
        assert Path(name).name in includes


def test_a_build_of_other_sources_is_never_loaded(monkeypatch):
    monkeypatch.setattr(compiled_json, "SOURCES", ("planner.py",))
    monkeypatch.setattr(compiled_json, "_library", None)
    assert compiled_json.built() is None and compiled_json.rows_text(["", ""], [np.ones(2)], ",") is None


def test_with_no_c_compiler_the_build_says_so_and_exits_0(tmp_path):
    """CC names no working compiler: exit 0 (verify writes with the json module), one
    message, no part file left and the build in place (if any) kept."""
    folder = Path(compiled_json.__file__).parent
    before = sorted(p.name for p in folder.iterdir())
    out = subprocess.run([sys.executable, "-m", "cdh_planner.compiled_json"],
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


# ----------------------------------------------------------------------------- reading poses

def _json_module_values(text):
    """(values (N, 7), quaternion (N,)) as the json module reads a plain poses document."""
    doc = json.loads(text)
    doc = doc["poses"] if isinstance(doc, dict) else doc
    values = np.full((len(doc), 7), np.nan)
    for k, pose in enumerate(doc):
        values[k, :3] = [float(x) for x in pose["position"]]
        other = pose.get("quaternion", pose.get("tau"))
        values[k, 3:3 + len(other)] = [float(x) for x in other]
    return values, np.array(["quaternion" in pose for pose in doc])


def _number_texts(rng, n):
    """JSON number texts of every form: integers (-0, big ones), decimals, exponents, long
    digit strings, subnormals, halfway cases between doubles."""
    out = []
    for _ in range(n):
        kind = rng.integers(0, 7)
        if kind == 0:
            out.append(str(int(rng.integers(-10**6, 10**6))) if rng.random() < 0.9 else "-0")
        elif kind == 1:
            out.append(repr(float(rng.normal(0, 10))))
        elif kind == 2:
            out.append(f"{rng.normal():.{int(rng.integers(1, 30))}e}".replace("e", "eE"[rng.integers(0, 2)]))
        elif kind == 3:
            out.append(f"{rng.uniform(-1, 1):.25f}")
        elif kind == 4:
            out.append(f"{rng.uniform(1, 10):.16f}e-{int(rng.integers(300, 324))}")
        elif kind == 5:  # halfway between two doubles: correct rounding decides
            x = float(rng.uniform(0.5, 1.0))
            out.append(f"{(x + np.nextafter(x, 2.0)) / 2:.30f}")
        else:
            out.append(str(int(rng.integers(0, 2**62))) + "123")
    return out


def _document(rng, n):
    """A plain poses document of n poses: either key order, quaternions or tau, whitespace
    of every JSON kind, sometimes the {"poses": ...} wrapper."""
    ws = [" ", "\n", "\t", "\r\n  ", ""]

    def sp():
        return ws[rng.integers(0, len(ws))]

    poses = []
    for k in range(n):
        position = _number_texts(rng, 3)
        if rng.random() < 0.5:
            q = rng.normal(size=4)
            key, other = "quaternion", [repr(float(x)) for x in q / np.linalg.norm(q)]
        else:
            key, other = "tau", _number_texts(rng, 3)
        fields = [f'"position"{sp()}:{sp()}[{sp()}{(sp() + "," + sp()).join(position)}{sp()}]',
                  f'"{key}"{sp()}:{sp()}[{",".join(other)}]']
        if rng.random() < 0.5:
            fields.reverse()
        poses.append("{" + sp() + ("," + sp()).join(fields) + sp() + "}")
    body = sp() + "[" + sp() + ("," + sp()).join(poses) + sp() + "]" + sp()
    return '{"poses":' + body + "}" if rng.random() < 0.3 else body


@pytest.mark.skipif(not BUILT, reason=NOT_BUILT)
def test_a_plain_poses_file_is_read_as_the_json_module_reads_it():
    rng = np.random.default_rng(11)
    for n in (1, 2, 7, 300):
        for _ in range(20 if n < 300 else 3):
            text = _document(rng, n)
            values, quaternion = compiled_json.read_poses(text.encode(), 1000)
            expected, expected_q = _json_module_values(text)
            np.testing.assert_array_equal(quaternion, expected_q)
            assert values.tobytes() == expected.tobytes(), text  # every bit, -0.0 and nan too


@pytest.mark.skipif(not BUILT, reason=NOT_BUILT)
@pytest.mark.parametrize("text", [
    '[]', '{}', '{"poses": []}', 'null', '[null]', '"poses"', '',
    '[{"position": [0, 0, 0.3]}]',                                       # no orientation
    '[{"position": [0, 0, 0.3], "tau": [0, 0, 0], "quaternion": [0, 0, 0, 1]}]',
    '[{"tau": [0, 0, 0], "quaternion": [0, 0, 0, 1]}]',                 # no position
    '[{"position": [0, 0, 0.3], "position": [0, 0, 0.3]}]',             # a key twice
    '[{"position": [0, 0, 0.3], "tau": [0, 0, 0], "extra": 1}]',
    '[{"position": [0, 0, 0.3], "tau": [0, 0]}]', '[{"position": [0, 0], "tau": [0, 0, 0]}]',
    '[{"position": [0, 0, 0.3], "quaternion": [0, 0, 1]}]',
    '[{"position": [0, 0, 0.3], "tau": [0, 0, 0, 0]}]',
    '[{"position": [0, 0, true], "tau": [0, 0, 0]}]', '[{"position": [0, 0, null], "tau": [0, 0, 0]}]',
    '[{"position": [0, 0, "1"], "tau": [0, 0, 0]}]', '[{"position": [0, 0, NaN], "tau": [0, 0, 0]}]',
    '[{"position": [0, 0, Infinity], "tau": [0, 0, 0]}]', '[{"position": [0, 0, 1e999], "tau": [0, 0, 0]}]',
    '[{"position": [0, 0, 01], "tau": [0, 0, 0]}]', '[{"position": [0, 0, 1.], "tau": [0, 0, 0]}]',
    '[{"position": [0, 0, .5], "tau": [0, 0, 0]}]', '[{"position": [0, 0, +1], "tau": [0, 0, 0]}]',
    '[{"position": [0, 0, 0x1], "tau": [0, 0, 0]}]', '[{"position": [0, 0, 1e], "tau": [0, 0, 0]}]',
    '[{"position": [0, 0, -], "tau": [0, 0, 0]}]', '[{"po\\u0073ition": [0, 0, 0.3], "tau": [0, 0, 0]}]',
    '[{"position": [0, 0, 0.3], "tau": [0, 0, 0]},]', '[{"position": [0, 0, 0.3], "tau": [0, 0, 0]}] x',
    '[{"position": [0, 0, 0.3], "tau": [0, 0, 0]}', '[{"position": [0, 0, 0.3], "tau": [0, 0, 0',
    '{"poses": [{"position": [0, 0, 0.3], "tau": [0, 0, 0]}], "more": 1}',
    '{"other": [{"position": [0, 0, 0.3], "tau": [0, 0, 0]}]}',
    '[[{"position": [0, 0, 0.3], "tau": [0, 0, 0]}]]', '[{"position": [0, 0, 0.3]; "tau": [0, 0, 0]}]',
    '[{"position": [0, 0, 0.3], "tau": [0, 0, 0]}]\x00', '\ufeff[{"position": [0, 0, 0.3], "tau": [0, 0, 0]}]'])
def test_any_other_document_is_left_to_python(text):
    assert compiled_json.read_poses(text.encode(), 1000) is None


@pytest.mark.skipif(not BUILT, reason=NOT_BUILT)
def test_more_poses_than_allowed_are_left_to_python():
    text = json.dumps([{"position": [0.0, 0.0, 0.3], "tau": [0.0, 0.1, 0.0]}] * 5)
    assert len(compiled_json.read_poses(text.encode(), 5)[0]) == 5
    assert compiled_json.read_poses(text.encode(), 4) is None


def test_load_poses_gives_the_same_poses_either_way(tmp_path, monkeypatch):
    """A file of mixed quaternion and tau poses (a quaternion with w < 0, unnormalised
    within the tolerance, tilts at 0 and pi): the compiled read and orjson's give the same
    PoseList, bit for bit."""
    from cdh_planner.parsing import poses as poses_module
    rng = np.random.default_rng(3)
    doc = []
    for k in range(500):
        if k % 2:
            q = rng.normal(size=4)
            q = q / np.linalg.norm(q) * (1 + 1e-4 * rng.uniform(-1, 1))
            doc.append({"quaternion": q.tolist(), "position": rng.uniform(-2, 2, 3).tolist()})
        else:
            tilt = [0.0, np.pi, float(rng.uniform(0, np.pi))][k % 3]
            doc.append({"position": rng.uniform(-2, 2, 3).tolist(),
                        "tau": [float(rng.uniform(-3, 3)), tilt, float(rng.uniform(-3, 3))]})
    path = tmp_path / "poses.json"
    path.write_text(json.dumps({"poses": doc}, indent=2))
    compiled = poses_module.load_poses(path)
    monkeypatch.setattr(compiled_json, "_library", False)
    python = poses_module.load_poses(path)
    for field in ("positions", "quaternions", "rotations", "tau"):
        assert getattr(compiled, field).tobytes() == getattr(python, field).tobytes(), field


@pytest.mark.skipif(not BUILT, reason=NOT_BUILT)
def test_numbers_of_every_form_are_read_as_float_reads_them():
    """Clinger's fast path (digits <= 2^53, exponent within 10^+-22) and the others beyond it:
    60,000 numbers of every form (long digit strings, leading zeros, exponents at the
    path's edges, integers) equal float() of their text, bit for bit."""
    rng = np.random.default_rng(17)
    forms = [lambda: repr(float(rng.normal() * 10.0 ** rng.integers(-30, 30))),
             lambda: str(int(rng.integers(-10**18, 10**18))),
             lambda: (f"{'-' if rng.random() < 0.5 else ''}{rng.integers(0, 10**int(rng.integers(1, 19)))}."
                      + "".join(rng.choice(list("0123456789"), rng.integers(1, 25)))),
             lambda: f"{rng.integers(1, 10**16)}e{rng.integers(-40, 40)}",
             lambda: f"0.{'0' * int(rng.integers(0, 25))}{rng.integers(1, 10**int(rng.integers(1, 18)))}",
             lambda: f"{rng.integers(1, 2**53 + 1)}E-{rng.integers(0, 24)}",
             lambda: f"{rng.integers(1, 2**53 + 1)}.{rng.integers(0, 10**6)}e{rng.integers(-25, 25)}"]
    texts = [forms[rng.integers(0, len(forms))]() for _ in range(60_000)]
    doc = ",".join('{"position":[%s,%s,%s],"tau":[0,0,0]}' % tuple(texts[k:k + 3])
                   for k in range(0, len(texts), 3))
    values, _ = compiled_json.read_poses(f"[{doc}]".encode(), len(texts))
    expected = np.array([float(t) if float(t) != 0.0 or "." in t or "e" in t.lower() else 0.0
                         for t in texts])
    assert values[:, :3].ravel().tobytes() == expected.tobytes()


def test_the_powers_of_ten_table_is_exact():
    """Eisel-Lemire's table: each row the 128 leading bits of 10^q truncated (checked with
    exact fractions), and the binary exponent the reader takes for 10^q, (217706 q) >> 16,
    floor(q log2 10) over the whole range."""
    from fractions import Fraction
    lo, hi = compiled_json.POW10_RANGE
    assert lo <= -342 and hi >= 308  # every double's decimal exponent with 19 digits
    for q in range(lo, hi + 1):
        t = compiled_json.pow10_mantissa(q)
        assert 2**127 <= t < 2**128
        e = (217706 * q) >> 16
        assert Fraction(2)**e <= Fraction(10)**q < Fraction(2)**(e + 1), q
        scaled = Fraction(10)**q * Fraction(2)**(127 - e)  # 10^q with its top bit at 2^127
        assert t <= scaled < t + 1, q


def _near_ties(rng, n):
    """Decimal texts of 19 digits at and one unit beside the midpoints of n random doubles
    and their successors (where truncating 10^q's mantissa could decide the rounding)."""
    from decimal import Decimal, localcontext
    xs = np.abs(rng.integers(0, 2**63 - 1, 4 * n, dtype=np.int64).view(np.float64))
    xs = xs[(xs > 1e-300) & (xs < 1e300)][:n]
    out = []
    with localcontext() as context:
        context.prec = 60
        for x in xs:
            mid = (Decimal(float(x)) + Decimal(float(np.nextafter(x, np.inf)))) / 2
            digits, exponent = f"{mid:.18e}".split("e")
            last = int(digits.replace(".", ""))
            for d in (str(last), str(last - 1), str(last + 1)):
                if len(d) == 19:
                    out.append(f"{d[0]}.{d[1:]}e{exponent}")
    return out


@pytest.mark.skipif(not BUILT, reason=NOT_BUILT)
def test_numbers_of_up_to_19_digits_are_read_as_float_reads_them():
    """Eisel-Lemire's path (19 digits or fewer beyond Clinger's): 60,000 numbers, the
    shortest reprs of random bit patterns (every exponent, subnormals too), 19-digit
    mantissas at every decimal exponent from -360 to 320 (zero, subnormal and infinite
    results: the ones that are not finite are left out, as the reader refuses them), near
    ties, equal float() of their text, bit for bit (1.2 million such numbers were checked
    once)."""
    rng = np.random.default_rng(29)
    xs = rng.integers(0, 2**63 - 1, 20_000, dtype=np.int64).view(np.float64)
    texts = [repr(float(x)) for x in xs[np.isfinite(xs)]]
    texts += [f"{'-' if rng.random() < 0.5 else ''}{rng.integers(1, 10**19, dtype=np.uint64)}"
              f"e{rng.integers(-360, 320)}" for _ in range(20_000)]
    texts += _near_ties(rng, 7_000)
    texts = [t for t in texts if np.isfinite(float(t))]
    texts += ["1"] * (-len(texts) % 3)
    doc = ",".join('{"position":[%s,%s,%s],"tau":[0,0,0]}' % tuple(texts[k:k + 3])
                   for k in range(0, len(texts), 3))
    values, _ = compiled_json.read_poses(f"[{doc}]".encode(), len(texts))
    expected = np.array([float(t) for t in texts])
    assert values[:, :3].ravel().tobytes() == expected.tobytes()


@pytest.mark.skipif(not BUILT, reason=NOT_BUILT)
def test_damaged_documents_are_read_right_or_left_to_python():
    """Plain documents with bytes deleted, inserted or replaced (JSON's punctuation, digits,
    NUL, a non-ASCII byte): the C reader never reads past the text (the process would die)
    and what it accepts the json module reads to the same numbers (90,000 such documents
    were checked once; these 3,000 each run)."""
    rng = np.random.default_rng(23)
    alphabet = list(b'{}[],:"-+.eE0123456789 \n\tpositnquaerl\\x\x00\xff')
    accepted = 0
    for _ in range(3000):
        doc = bytearray(_document(rng, int(rng.integers(1, 4))).encode())
        for _ in range(int(rng.integers(1, 4))):
            k, op = int(rng.integers(0, len(doc) + 1)), rng.integers(0, 3)
            byte = alphabet[rng.integers(0, len(alphabet))]
            if op == 1:
                doc[k:k] = bytes([byte])
            elif doc:
                k = min(k, len(doc) - 1)
                if op == 0:
                    del doc[k]
                else:
                    doc[k] = byte
        read = compiled_json.read_poses(bytes(doc), 10)
        if read is not None:
            accepted += 1
            values, quaternion = _json_module_values(bytes(doc).decode("ascii"))
            assert read[0].tobytes() == values.tobytes() and np.array_equal(read[1], quaternion)
    assert 0 < accepted < 3000
