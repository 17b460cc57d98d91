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
