"""The robot file's schema: how one field of the ``robot:`` block is declared and read.

``model/robot.py`` declares each field once, as metadata (``RobotField``) on a field of the
``Robot`` dataclass, as ``settings.py`` does for the planner settings: its key in the file
(dotted inside a group: ``load.force``), kind, unit, size, bounds and description.
``read_fields`` reads and checks a ``robot:`` mapping by that declaration; the node's
parameters (``ros/core/params.py``: ``robot.<key>``) and their table (docs/parameters.md) are
built from it too, so a new robot field is one ``Robot`` field.

Sizes per cable follow the number of winches, m = len(winch_names): a per-cable field
holds ``count`` numbers per cable (``count * m`` in all). ``cable_count`` bounds m:
MIN_CABLES <= m <= MAX_CABLES (the wrench-feasibility test of ``wrench`` holds for any
m >= 6: docs/more-cables.md).
"""

from dataclasses import dataclass, field, fields

import numpy as np

from ..errors import InputError, check_finite, check_keys, check_numbers, is_number

NAME, NAMES, CHOICE, NUMBER, NUMBERS, MATRIX = "name", "names", "choice", "number", "numbers", \
    "matrix"
REQUIRED = object()  # the default of a field the file must give
MAX_NAME_CHARS = 64
N_CABLES = 6  # the default number of winches (the default winch names)
MIN_CABLES = 6  # fewer cables cannot hold a 6-D wrench ellipsoid: J (6 x m) has rank < 6
# the facet test visits C(m, 5) cable subsets per pose: 4368 for 16 cables (bounded work)
MAX_CABLES = 16


@dataclass(frozen=True)
class RobotField:
    """One field of the ``robot:`` block.

    ``key``: its path in the block (``load.force``); ``kind``: NAME (1 to MAX_NAME_CHARS
    characters), NAMES (one distinct NAME per winch: they give m), CHOICE (one of
    ``choices``), NUMBER, NUMBERS (``count`` numbers; ``per_cable``: ``count`` per cable;
    ``broadcast``: one number may stand for every entry) or MATRIX (``count`` x ``count``,
    row-major, or its ``count`` diagonal entries; ``definite``: "positive" (symmetric
    positive definite) or "semi" (symmetric positive semi-definite)). Numbers lie within
    +-``limit``; ``sign``: "positive" (> 0) or "non-negative" (>= 0) entries. ``default``:
    REQUIRED, None (optional, left empty) or the value an absent key takes. ``unit`` and
    ``description`` document it."""

    key: str
    kind: str
    unit: str
    description: str
    default: object = REQUIRED
    count: int = 1
    per_cable: bool = False
    broadcast: bool = False
    limit: float = None
    sign: str = ""
    definite: str = ""
    choices: tuple = ()

    @property
    def group(self):
        """The mapping the key sits in ("" for the top of ``robot:``)."""
        return self.key.rpartition(".")[0]

    @property
    def name(self):
        return self.key.rpartition(".")[2]

    def size(self, m):
        """How many numbers (or names) the field holds for m cables."""
        if self.kind == NAMES:
            return m
        return self.count * (m if self.per_cable else 1)


def robot_field(**meta):
    """A dataclass field carrying its RobotField (``robot.py``'s Robot)."""
    return field(metadata={"robot": RobotField(**meta)})


def schema_of(cls):
    """The RobotFields of the dataclass ``cls``, in declaration order."""
    return tuple(f.metadata["robot"] for f in fields(cls) if "robot" in f.metadata)


def cable_count(names):
    """m, the number of cables: one per winch name, MIN_CABLES <= m <= MAX_CABLES.

    Fewer than 6 cables make J (6 x m) rank-deficient at every pose: no wrench ellipsoid
    is ever feasible. The per-cable sizes of the schema follow m."""
    if not MIN_CABLES <= len(names) <= MAX_CABLES:
        raise InputError("robot.winch_names", list(names),
                         f"expected {MIN_CABLES} to {MAX_CABLES} distinct non-empty names (one per "
                         f"cable: fewer than {MIN_CABLES} cannot hold a 6-D wrench), got {len(names)}")
    return len(names)


def check_groups(d, schema, optional_groups=()):
    """``d`` (the ``robot:`` mapping) with only declared keys and every required one, at the
    top and in each group; a group in ``optional_groups`` may be absent, but when given
    needs its own required keys. InputError naming the first offending key."""
    groups = {"": ([], set())}  # group -> (its keys in declaration order, required ones)
    for f in schema:
        allowed, required = groups.setdefault(f.group, ([], set()))
        allowed.append(f.name)
        if f.default is REQUIRED:
            required.add(f.name)
    top_allowed, top_required = groups.pop("")
    for g, (_, required) in groups.items():
        top_allowed.append(g)
        if required and g not in optional_groups:
            top_required.add(g)
    check_keys("robot", d, top_allowed, required=top_required)
    for g, (allowed, required) in groups.items():
        if g in d:
            check_keys(f"robot.{g}", d[g], allowed, required=required)


def read_fields(d, schema, defaults=None):
    """key -> checked value of every field of ``schema`` in ``d`` (after ``check_groups``),
    an absent key taking ``defaults[key]`` or its declared default; names as a tuple,
    numbers as float arrays (MATRIX (n, n), per-cable ``count`` > 1 as (m, count)).
    Per-cable sizes follow the winch names, read first."""
    defaults = defaults or {}
    out, m = {}, N_CABLES
    for f in schema:
        group = d.get(f.group, {}) if f.group else d
        value = group[f.name] if f.name in group else defaults.get(f.key, f.default)
        if value is REQUIRED or (value is None and f.default is None):
            out[f.key] = None  # not given: an optional field, or a field of an absent group
            continue
        out[f.key] = read_value(f, f"robot.{f.key}", value, m)
        if f.kind == NAMES:
            m = cable_count(out[f.key])
    return out


def read_value(f, where, value, m):
    """The checked value of field ``f`` (``where``: its name in errors) for m cables."""
    if f.kind == NAME:
        if not isinstance(value, str) or not value or len(value) > MAX_NAME_CHARS:
            raise InputError(where, value, f"expected a name of 1 to {MAX_NAME_CHARS} characters")
        return value
    if f.kind == NAMES:
        if (not isinstance(value, (list, tuple)) or not value
                or not all(isinstance(w, str) and 0 < len(w) <= MAX_NAME_CHARS for w in value)
                or len(set(value)) != len(value)):
            raise InputError(where, value, f"expected distinct non-empty names of at most "
                                           f"{MAX_NAME_CHARS} characters, one per winch")
        return tuple(value)
    if f.kind == CHOICE:
        if not isinstance(value, str) or value not in f.choices:
            raise InputError(where, value, f"expected one of {', '.join(f.choices)}")
        return value
    if f.kind == NUMBER:
        value = check_finite(where, value, positive=f.sign == "positive", limit=f.limit)
        _signed(f, where, np.array([value]))
        return value
    if f.kind == MATRIX:
        return _matrix(f, where, value)
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
    positive = f.sign == "positive"
    bad = np.flatnonzero(arr <= 0 if positive else arr < 0)
    if bad.size:
        name = where if f.kind == NUMBER else f"{where}[{bad[0]}]"
        raise InputError(name, float(arr[bad[0]]), f"must be {f.sign}")
    return arr


def _matrix(f, where, value):
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


def size_text(f):
    """What the field holds, in words (for the parameter descriptions and the docs)."""
    if f.kind == NAME:
        return f"a name of 1 to {MAX_NAME_CHARS} characters"
    if f.kind == NAMES:
        return (f"one distinct name per winch (their number is the number of cables, "
                f"{MIN_CABLES} to {MAX_CABLES})")
    if f.kind == CHOICE:
        return "one of " + ", ".join(f.choices)
    if f.kind == NUMBER:
        return "a number"
    if f.kind == MATRIX:
        return f"{f.count * f.count} numbers row-major or {f.count} for a diagonal"
    if f.per_cable:
        text = "one number per cable" if f.count == 1 else f"{f.count} numbers per cable"
        return text + (", or a single number for all" if f.broadcast else "")
    return f"{f.count} numbers"


def describe(f):
    """The field's description with its unit and size: one line for a parameter table."""
    unit = f", in {f.unit}" if f.unit else ""
    return f"{f.description}{unit}: {size_text(f)}"
