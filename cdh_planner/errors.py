"""Input errors that name the offending field and value (never a traceback)."""


class InputError(ValueError):
    """Bad user input: a robot file, a problem file, a pose, a request.

    ``field`` is a dotted path to the offending entry (e.g. ``limits.length_min[2]``),
    ``value`` the value found there, ``reason`` what is wrong with it.
    """

    def __init__(self, field: str, value, reason: str):
        self.field = field
        self.value = value
        self.reason = reason
        super().__init__(f"{field} = {value!r}: {reason}")


def check_finite(field: str, value, positive: bool = False) -> float:
    """``value`` as a float if it is a finite number (and > 0 when ``positive``), else an
    InputError naming ``field``. Booleans are not numbers here."""
    try:
        ok = not isinstance(value, (bool, str, bytes)) and abs(float(value)) < float("inf")
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise InputError(field, value, "expected a finite number")
    if positive and float(value) <= 0:
        raise InputError(field, value, "must be positive")
    return float(value)


def check_keys(where: str, d, allowed, required=()) -> dict:
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
