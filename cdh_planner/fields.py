"""One way to declare and read a field of an input: the robot file's ``robot:`` block
(``model/robot.py``), the planner settings (``settings.py``), a task's keys
(``model/task.py``), a scene's and its shapes' keys (``scene/schema.py``,
``model/shapes.py``) and the node's parameters (``ros/core/params.py``).

A ``Field`` declares its key, its ``kind`` (one vocabulary, ``KINDS``), unit, description,
default (REQUIRED: the input must give it; None: optional, left empty) and what a value may
be: ``low`` / ``high`` (``open_low`` / ``open_high``: the bound itself excluded), ``limit``
(|x| at most), ``sign``, ``choices``, ``count`` ... ``read(f, value, where)`` is the one
check: the value converted (ints to floats for numbers, names to a tuple, lists of numbers
to float arrays) or an InputError naming ``where`` and the value on one line. An edge that
needs more metadata subclasses Field (``settings.Setting``: the CLI flag and the node
parameter; ``ros.core.param_spec.Spec``: read once at start).
"""

import math
from dataclasses import KW_ONLY, MISSING, dataclass, fields
from typing import Optional

import numpy as np

from .errors import InputError, check_finite, check_numbers, is_number

# the kinds of value a field holds
BOOL = "bool"          # true or false
INT = "int"            # an integer
NUMBER = "number"      # a finite number (float)
NUMBERS = "numbers"    # ``count`` numbers (per cable: ``count`` per cable), a float array
MATRIX = "matrix"      # ``count`` x ``count`` numbers, row-major, or its diagonal
TEXT = "text"          # any string
NAME = "name"          # 1 to MAX_NAME_CHARS characters
NAMES = "names"        # distinct NAMEs, one per cable: their number is m
TEXTS = "texts"        # a list of strings
CHOICE = "choice"      # one of ``choices``
KINDS = (BOOL, INT, NUMBER, NUMBERS, MATRIX, TEXT, NAME, NAMES, TEXTS, CHOICE)
REQUIRED = object()    # the default of a field the input must give
MAX_NAME_CHARS = 64
SIGNS = ("", "positive", "non-negative")


@dataclass(frozen=True)
class Field:
    """One field (module doc). ``key``: its path in its mapping (``load.force``: ``force``
    in the group ``load``). NUMBERS: ``per_cable``: ``count`` numbers per cable;
    ``broadcast``: one number may stand for every entry. MATRIX: ``definite`` "positive"
    (symmetric positive definite) or "semi" (symmetric positive semi-definite). ``sign``
    applies to every number; ``low`` / ``high`` to a NUMBER or INT."""

    key: str
    kind: str
    default: object = REQUIRED
    description: str = ""
    _: KW_ONLY
    unit: str = ""
    choices: tuple = ()  # or settings.LiveChoices (a registry's names)
    low: Optional[float] = None
    high: Optional[float] = None
    open_low: bool = False
    open_high: bool = False
    limit: Optional[float] = None
    sign: str = ""
    count: int = 1
    per_cable: bool = False
    broadcast: bool = False
    definite: str = ""

    def __post_init__(self):
        if self.kind not in KINDS or self.sign not in SIGNS:
            raise ValueError(f"field {self.key!r}: kind {self.kind!r} or sign {self.sign!r} is "
                             f"not one of {KINDS}, {SIGNS}")

    @property
    def group(self):
        """The mapping the key sits in ("" for the top)."""
        return self.key.rpartition(".")[0]

    @property
    def leaf(self):
        """The key in its group."""
        return self.key.rpartition(".")[2]

    def size(self, m=1):
        """How many numbers (or names) the field holds for m cables."""
        if self.kind == NAMES:
            return m
        return self.count * (m if self.per_cable else 1)

    def bounds(self):
        """(low, high, open_low, open_high) of a NUMBER or INT, for parameter tables and
        ROS ranges: the declared ones, else from its sign (0, open when positive) and, with a
        sign, its limit (a limit alone is the +- input bound of ``errors``, not a range)."""
        if self.kind not in (NUMBER, INT):
            return None, None, False, False
        low, high, open_low = self.low, self.high, self.open_low
        if low is None and self.sign:
            low, open_low = 0.0, self.sign == "positive"
        if high is None and self.sign:
            high = self.limit
        return low, high, open_low, self.open_high


def with_key(f, key, **changes):
    """``f`` declared under ``key`` (and ``changes``), as its own class or ``cls`` given in
    changes: e.g. a robot field as the node parameter ``robot.<key>``."""
    cls = changes.pop("cls", type(f))
    values = {a.name: getattr(f, a.name) for a in fields(Field)}
    extra = {a.name: getattr(f, a.name) for a in fields(f) if a.name not in values}
    values.update({k: v for k, v in extra.items() if k in {a.name for a in fields(cls)}})
    values.update(key=key, **changes)
    return cls(**values)


def declared(cls, tag):
    """The Fields on the dataclass ``cls`` (metadata[tag]), in declaration order; one
    declared with key "" takes the attribute's name, and its default the attribute's."""
    out = []
    for a in fields(cls):
        if tag not in a.metadata:
            continue
        f = a.metadata[tag]
        if not f.key:
            default = a.default if a.default_factory is MISSING else a.default_factory()
            f = with_key(f, a.name, default=default)
        out.append(f)
    return tuple(out)


def read(f, value, where=None, m=1):
    """The checked value of field ``f`` for m cables; InputError naming ``where`` (default
    the key) and the value otherwise. NUMBER: float; INT: int; NUMBERS: a float array
    ((m, count) per cable with count > 1); MATRIX: (count, count); NAMES: a tuple; TEXTS:
    a list."""
    return _READERS[f.kind](f, value, where or f.key, m)


def _bool(f, value, where, m):
    if not isinstance(value, bool):
        raise InputError(where, value, "expected true or false")
    return value


def _text(f, value, where, m):
    if not isinstance(value, str):
        raise InputError(where, value, "expected a string")
    return value


def _name(f, value, where, m):
    if not isinstance(value, str) or not value or len(value) > MAX_NAME_CHARS:
        raise InputError(where, value, f"expected a name of 1 to {MAX_NAME_CHARS} characters")
    return value


def _names(f, value, where, m):
    if (not isinstance(value, (list, tuple)) or not value
            or not all(isinstance(w, str) and 0 < len(w) <= MAX_NAME_CHARS for w in value)
            or len(set(value)) != len(value)):
        raise InputError(where, value, f"expected distinct non-empty names of at most "
                                       f"{MAX_NAME_CHARS} characters, one per winch")
    return tuple(value)


def _texts(f, value, where, m):
    if isinstance(value, str) or not hasattr(value, "__iter__") \
            or not all(isinstance(v, str) for v in value):
        raise InputError(where, value, "expected a list of strings")
    return list(value)


def _choice(f, value, where, m):
    if not isinstance(value, str) or value not in f.choices:
        raise InputError(where, value, f"expected one of {', '.join(f.choices)}")
    return value


def _number(f, value, where, m):
    value = check_finite(where, value, positive=f.sign == "positive", limit=f.limit)
    _signed(f, where, np.array([value]))
    return check_range(where, value, f)


def _int(f, value, where, m):
    value = check_finite(where, value, positive=f.sign == "positive", limit=f.limit)
    if not float(value).is_integer():
        raise InputError(where, value, "expected an integer")
    _signed(f, where, np.array([value]))
    return check_range(where, int(value), f)


def _numbers_field(f, value, where, m):
    n = f.size(m)
    if f.broadcast and is_number(value):
        value = [value] * n
    arr = _signed(f, where, _numbers(where, value, n, f.limit))
    return arr.reshape(-1, f.count) if f.per_cable and f.count > 1 else arr


def _numbers(where, value, n, limit):
    """``n`` finite numbers within +-``limit`` (a single number when n is 1; numpy arrays
    flattened); InputError naming the list or its first bad entry."""
    if is_number(value):
        value = [value]
    if isinstance(value, np.ndarray):
        value = value.ravel().tolist()
    return np.array(check_numbers(where, value, n, limit), dtype=float)


def _signed(f, where, arr):
    """``arr`` if its entries have the field's sign; else InputError naming the first bad one
    (``where[i]`` for a list)."""
    if not f.sign:
        return arr
    bad = np.flatnonzero(arr <= 0 if f.sign == "positive" else arr < 0)
    if bad.size:
        name = where if f.kind in (NUMBER, INT) else f"{where}[{bad[0]}]"
        raise InputError(name, float(arr[bad[0]]), f"must be {f.sign}")
    return arr


def _matrix(f, value, where, m):
    """An n x n matrix from n*n numbers (row-major) or n numbers (its diagonal), checked
    for the field's ``definite``."""
    n = f.count
    if isinstance(value, (list, tuple)) and len(value) == n:
        M = np.diag(_numbers(where, value, n, f.limit))
    else:
        M = _numbers(where, value, n * n, f.limit).reshape(n, n)
    if f.definite == "positive":
        if not np.allclose(M, M.T, rtol=1e-9, atol=0.0):
            raise InputError(where, value, "must be symmetric")
        eig = np.linalg.eigvalsh(M)
        if eig[0] <= 0:
            raise InputError(where, value, f"must be positive definite (smallest eigenvalue "
                                           f"{eig[0]:.3g})")
    elif f.definite == "semi":
        if not np.allclose(M, M.T, rtol=1e-9, atol=1e-15) or np.linalg.eigvalsh(M)[0] < -1e-12:
            raise InputError(where, value, f"must be symmetric positive semi-definite ({f.unit})")
    return M


_READERS = {BOOL: _bool, INT: _int, NUMBER: _number, NUMBERS: _numbers_field, MATRIX: _matrix,
            TEXT: _text, NAME: _name, NAMES: _names, TEXTS: _texts, CHOICE: _choice}


def check_range(where, value, f):
    """``value`` if it lies within ``f.low`` .. ``f.high`` (None: unbounded; ``open_low``
    / ``open_high``: the bound excluded), else InputError naming ``where``."""
    if f.low is not None and (value < f.low or (f.open_low and value == f.low)):
        raise InputError(where, value, f"must be {'>' if f.open_low else '>='} {f.low:g}")
    if f.high is not None and (value > f.high or (f.open_high and value == f.high)):
        raise InputError(where, value, f"must be {'<' if f.open_high else '<='} {f.high:g}")
    return value


def range_text(f):
    """The field's range in words for a parameter table: its choices, or its bounds
    ("[0, 1]", "> 0", ...); "" for none."""
    if f.choices:
        return ", ".join(f.choices)
    low, high, open_low, open_high = f.bounds()
    lo = None if low is None else f"{low:g}"
    hi = None if high is None else f"{high:g}"
    if lo is not None and hi is not None:
        return f"{'(' if open_low else '['}{lo}, {hi}{')' if open_high else ']'}"
    if lo is not None:
        return f"{'>' if open_low else '>='} {lo}"
    if hi is not None:
        return f"{'<' if open_high else '<='} {hi}"
    return ""


def default_text(value):
    """A default for a parameter table: "required", "empty" (None), true/false, numbers
    by %g, lists, strings in backticks."""
    if value is REQUIRED:
        return "required"
    if value is None:
        return "empty"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, (int, float)):
        return "NaN" if math.isnan(value) else f"{value:g}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(str(v) if isinstance(v, str) else default_text(v) for v in value) + "]"
    return f"`{value}`" if value != "" else '""'
