"""``toppra`` (with its ``algorithm`` and ``constraint`` modules), imported without matplotlib.

    from ._toppra import toppra

toppra's algorithm module imports matplotlib.pyplot at its top for plotting helpers that
the planner never calls; loading pyplot (matplotlib, its artists, mplot3d) is about 0.25 s
of every process that times a path dynamically. So while toppra is imported,
``matplotlib`` and ``matplotlib.pyplot`` are placeholder modules, removed from
``sys.modules`` right after: toppra keeps its ``plt`` name bound to a placeholder that
imports the real pyplot at its first attribute use (never, unless a toppra plot is drawn),
and every other ``import matplotlib`` gets the real one. If matplotlib is already imported
there is nothing to save and toppra is imported as it is.

Import this module at start-up in a process with threads (the node imports it with the
planner, before it spins): another thread importing matplotlib during the few
milliseconds of toppra's import would get a placeholder.
"""

import importlib
import sys
import types


class _Deferred(types.ModuleType):
    """A module that imports the real module of its name at its first attribute use."""

    def __getattr__(self, attr):
        if sys.modules.get(self.__name__) is self:  # still inside toppra's import
            raise AttributeError(f"{self.__name__}.{attr} (deferred while toppra imports)")
        return getattr(importlib.import_module(self.__name__), attr)


def _import_without_matplotlib():
    if "matplotlib" in sys.modules:
        import toppra.algorithm
        import toppra.constraint
        return toppra
    placeholders = {"matplotlib": _Deferred("matplotlib"),
                    "matplotlib.pyplot": _Deferred("matplotlib.pyplot")}
    placeholders["matplotlib"].pyplot = placeholders["matplotlib.pyplot"]
    sys.modules.update(placeholders)
    try:
        import toppra.algorithm
        import toppra.constraint
    finally:
        for name, module in placeholders.items():
            if sys.modules.get(name) is module:
                del sys.modules[name]
    return toppra


toppra = _import_without_matplotlib()
