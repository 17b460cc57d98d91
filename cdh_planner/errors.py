"""Input errors that name the offending field and value (never a traceback), and the
shared checks of input numbers.

Bounds on input numbers (documented in the README, Input files): a position, an anchor
coordinate, a cable length or a task's length or angle lies within +-``MAX_POSITION_M``
(1e3 m); a force, a moment or a tension within +-``MAX_FORCE_N`` (1e7 N, N m). A value
beyond them is a unit mistake or an attack, and would overflow the closed forms.
"""

import math
import reprlib

MAX_POSITION_M = 1e3  # m (and rad for task fields): the largest |coordinate| accepted
MAX_FORCE_N = 1e7  # N and N m: the largest |force|, |moment| or tension accepted
MAX_VALUE_CHARS = 80  # an error line shows at most this much of the value
MAX_FIELD_CHARS = 60  # ... and of the field's name
MAX_MESSAGE_CHARS = 200  # an InputError's whole message, whatever its parts

class _Repr(reprlib.Repr):
    """reprlib's bounded repr, with a huge integer (``int(1e308)``, a 309-digit number)
    shown as a float is (``1e+308``), not as its digits cut in the middle."""

    def repr_int(self, x, level):
        if abs(x) < 10 ** 16:
            return repr(x)
        try:
            return f"{x:.6g}"
        except OverflowError:  # beyond a float: its order of magnitude
            return f"{'-' if x < 0 else ''}~1e{int((x.bit_length() - 1) * math.log10(2))}"


_REPR = _Repr()
_REPR.maxlevel, _REPR.maxdict, _REPR.maxlist, _REPR.maxtuple = 3, 4, 6, 6
_REPR.maxset = _REPR.maxfrozenset = _REPR.maxdeque = _REPR.maxarray = 6
_REPR.maxstring, _REPR.maxlong, _REPR.maxother = MAX_VALUE_CHARS, 40, MAX_VALUE_CHARS


def clip(text, limit):
    """``text`` on one line (runs of whitespace made one space), cut to ``limit`` characters."""
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def exception_line(exc, limit=400):
    """``ZeroDivisionError: division by zero``, ``struct.error: ...``: an exception's type
    (qualified unless built in) and message on one line, cut to ``limit`` characters."""
    kind = type(exc)
    name = kind.__name__ if kind.__module__ == "builtins" else f"{kind.__module__}.{kind.__name__}"
    return f"{name}: {clip(exc, limit)}"


def short_repr(value, limit=MAX_VALUE_CHARS):
    """repr(value) on one line and at most ``limit`` characters, in time bounded by the
    limit whatever the value (deep, long or self-referencing lists included)."""
    try:
        text = _REPR.repr(value)
    except Exception:  # a value whose repr fails must not hide the error it is part of
        text = f"<{type(value).__name__}>"
    return clip(text, limit)


class InputError(ValueError):
    """Bad user input: a robot file, a problem file, a pose, a request.

    ``field`` is a dotted path to the offending entry (e.g. ``limits.length_min[2]``),
    ``value`` the value found there, ``reason`` what is wrong with it. The message is one
    line of at most MAX_MESSAGE_CHARS characters: the value is shown as a short repr.
    """

    def __init__(self, field: str, value, reason: str):
        self.field = field
        self.value = value
        self.reason = reason
        text = f"{clip(field, MAX_FIELD_CHARS)} = {short_repr(value)}: {clip(reason, MAX_MESSAGE_CHARS)}"
        super().__init__(clip(text, MAX_MESSAGE_CHARS))


def check_text(field: str, text) -> str:
    """``text`` if it is UTF-8 text; an InputError naming ``field`` if it holds bytes of the
    command line that were not UTF-8 (Python keeps them as lone surrogates, which no
    drawing or ROS message can take). File names are not checked with it: any bytes are a
    file name."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError as exc:
        raise InputError(field, text, f"not UTF-8 text (byte "
                                      f"0x{ord(text[exc.start]) & 0xFF:02x} at {exc.start})") from None
    return text


def is_number(value) -> bool:
    """True for an int or float (numpy's included), False for booleans, strings and the rest."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) or (
        type(value).__module__ == "numpy" and hasattr(value, "dtype") and value.dtype.kind in "iuf"
        and getattr(value, "ndim", 1) == 0)


def check_finite(field: str, value, positive: bool = False, limit: float = None) -> float:
    """``value`` as a float if it is a finite number (and > 0 when ``positive``, and of
    magnitude at most ``limit`` when given), else an InputError naming ``field``. Booleans
    and strings (``"0.1"``) are not numbers here."""
    try:
        ok = is_number(value) and math.isfinite(float(value))
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        kind = "a number, not a string" if isinstance(value, (str, bytes)) else "a finite number"
        raise InputError(field, value, f"expected {kind}")
    if positive and float(value) <= 0:
        raise InputError(field, value, "must be positive")
    if limit is not None and abs(float(value)) > limit:
        raise InputError(field, value, f"must be within +-{limit:g}")
    return float(value)


def check_numbers(field: str, value, n: int, limit: float = None) -> list:
    """A list (or tuple) of exactly ``n`` finite numbers as floats, each checked like
    ``check_finite``; the InputError names the list or its first bad entry (``field[i]``)."""
    if not isinstance(value, (list, tuple)):
        raise InputError(field, value, f"expected a list of {n} numbers")
    if len(value) != n:
        raise InputError(field, value, f"expected {n} numbers, got {len(value)}")
    return [check_finite(f"{field}[{i}]", x, limit=limit) for i, x in enumerate(value)]


def check_keys(where, d, allowed, required=()) -> dict:
    """``d`` if it is a mapping with only ``allowed`` keys and every ``required`` one, else
    an InputError naming the first offending key (``where.key``; ``where`` "" at top level)."""
    if not isinstance(d, dict):
        raise InputError(where, d, "expected a mapping")
    name = (lambda key: f"{where}.{key}" if where else str(key))
    unknown = sorted(set(d) - set(allowed), key=str)
    if unknown:
        raise InputError(name(unknown[0]), d[unknown[0]],
                         f"unknown key (allowed: {', '.join(map(str, allowed)) or 'none'})")
    missing = sorted(k for k in required if k not in d)
    if missing:
        raise InputError(name(missing[0]), None, "required key is missing")
    return d
