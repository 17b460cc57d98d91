"""The one field declaration (cdh_planner/fields.py): every kind reads a good value to its
Python form and refuses a bad one in one line naming the field and the value."""

import math

import numpy as np
import pytest

from cdh_planner.errors import InputError
from cdh_planner.fields import BOOL, CHOICE, INT, KINDS, MATRIX, NAME, NAMES, NUMBER, NUMBERS, \
    TEXT, TEXTS, Field, range_text, read, with_key

GOOD = [
    (Field("f", BOOL), True, True),
    (Field("f", INT, low=2, high=10), 3.0, 3),
    (Field("f", NUMBER, sign="positive", limit=1.0), 1, 1.0),
    (Field("f", NUMBERS, count=3, per_cable=True), list(range(12)), np.arange(12.0).reshape(4, 3)),
    (Field("f", NUMBERS, per_cable=True, broadcast=True), 2, np.full(4, 2.0)),
    (Field("f", MATRIX, count=2, definite="positive"), [1, 2], np.diag([1.0, 2.0])),
    (Field("f", TEXT), "", ""),
    (Field("f", NAME), "w1", "w1"),
    (Field("f", NAMES), ["a", "b"], ("a", "b")),
    (Field("f", TEXTS), ("a",), ["a"]),
    (Field("f", CHOICE, choices=("x", "y")), "y", "y"),
]


@pytest.mark.parametrize("f, value, expected", GOOD, ids=[g[0].kind for g in GOOD])
def test_a_good_value_is_read_to_its_python_form(f, value, expected):
    got = read(f, value, m=4)
    assert type(got) is type(expected) and np.array_equal(got, expected)


BAD = [
    (Field("f", BOOL), 1, "f = 1: expected true or false"),
    (Field("f", INT), 2.5, "f = 2.5: expected an integer"),
    (Field("f", INT, low=2), 1, "f = 1: must be >= 2"),
    (Field("f", NUMBER), "0.1", "f = '0.1': expected a number, not a string"),
    (Field("f", NUMBER), math.inf, "f = inf: expected a finite number"),
    (Field("f", NUMBER, sign="non-negative"), -1.0, "f = -1.0: must be non-negative"),
    (Field("f", NUMBER, high=1.0, open_high=True), 1.0, "f = 1.0: must be < 1"),
    (Field("f", NUMBER, limit=10.0), 11, "f = 11: must be within +-10"),
    (Field("f", NUMBERS, count=3, sign="positive"), [1, 0, 1], "f[1] = 0.0: must be positive"),
    (Field("f", NUMBERS, count=3), [1, 2], "f = [1, 2]: expected 3 numbers, got 2"),
    (Field("f", MATRIX, count=2, definite="positive"), [1, 0, 1, 1], "f = [1, 0, 1, 1]: must be "
                                                                     "symmetric"),
    (Field("f", TEXT), 3, "f = 3: expected a string"),
    (Field("f", NAME), "", "f = '': expected a name of 1 to 64 characters"),
    (Field("f", NAMES), ["a", "a"], "f = ['a', 'a']: expected distinct non-empty names"),
    (Field("f", TEXTS), "ab", "f = 'ab': expected a list of strings"),
    (Field("f", CHOICE, choices=("x", "y")), "z", "f = 'z': expected one of x, y"),
]


@pytest.mark.parametrize("f, value, message", BAD, ids=[b[2] for b in BAD])
def test_a_bad_value_is_one_line_naming_the_field_and_the_value(f, value, message):
    with pytest.raises(InputError) as info:
        read(f, value, m=4)
    assert str(info.value).startswith(message) and "\n" not in str(info.value)
    with pytest.raises(InputError, match=r"^robot\.f"):
        read(f, value, "robot.f", m=4)


def test_every_kind_is_read_and_a_kind_outside_the_vocabulary_is_refused():
    assert {g[0].kind for g in GOOD} == set(KINDS)
    with pytest.raises(ValueError, match="kind 'double'"):
        Field("f", "double")


def test_a_field_under_another_key_keeps_its_declaration_and_its_range_reads_from_it():
    f = Field("load.mass", NUMBER, None, "mass", unit="kg", sign="positive", limit=1e7)
    g = with_key(f, "robot.load.mass", description="its mass")
    assert (g.key, g.group, g.leaf, g.unit, g.sign, g.description) == \
        ("robot.load.mass", "robot.load", "mass", "kg", "positive", "its mass")
    assert range_text(f) == "(0, 1e+07]" and range_text(Field("f", NUMBER, limit=1.0)) == ""
    assert range_text(Field("f", CHOICE, choices=("a", "b"))) == "a, b"
