"""The robot file's schema: how one field of the ``robot:`` block is declared and read.

``model/robot.py`` declares each field once, as metadata (a ``fields.Field``, the schema
style of every input) on a field of the ``Robot`` dataclass: its key in the file (dotted
inside a group: ``load.force``), kind, unit, size, bounds and description. ``read_fields``
reads and checks a ``robot:`` mapping by that declaration (``fields.read``); the node's
parameters (``ros/core/params.py``: ``robot.<key>``) and their table (docs/parameters.md) are
built from it too, so a new robot field is one ``Robot`` field.

Sizes per cable follow the number of winches, m = len(winch_names): a per-cable field
holds ``count`` numbers per cable (``count * m`` in all). ``cable_count`` bounds m:
MIN_CABLES <= m <= MAX_CABLES (the wrench-feasibility test of ``wrench`` holds for any
m >= 6: docs/more-cables.md).
"""

from dataclasses import field

from ..errors import InputError, check_keys
from ..fields import MATRIX, MAX_NAME_CHARS, NAME, NAMES, NUMBER, CHOICE, REQUIRED, Field, declared, \
    read

N_CABLES = 6  # the default number of winches (the default winch names)
MIN_CABLES = 6  # fewer cables cannot hold a 6-D wrench ellipsoid: J (6 x m) has rank < 6
# the facet test visits C(m, 5) cable subsets per pose: 4368 for 16 cables (bounded work)
MAX_CABLES = 16


def robot_field(**meta):
    """A dataclass field carrying its ``fields.Field`` (``robot.py``'s Robot): key (dotted
    in a group: ``load.force``), kind, unit, size, bounds, description; ``default`` REQUIRED,
    None (optional, left empty) or the value an absent key takes."""
    return field(metadata={"robot": Field(**meta)})


def schema_of(cls):
    """The Fields of the dataclass ``cls``, in declaration order."""
    return declared(cls, "robot")


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
        allowed.append(f.leaf)
        if f.default is REQUIRED:
            required.add(f.leaf)
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
        value = group[f.leaf] if f.leaf in group else defaults.get(f.key, f.default)
        if value is REQUIRED or (value is None and f.default is None):
            out[f.key] = None  # not given: an optional field, or a field of an absent group
            continue
        out[f.key] = read(f, value, f"robot.{f.key}", m)
        if f.kind == NAMES:
            m = cable_count(out[f.key])
    return out


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
