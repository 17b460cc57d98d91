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
