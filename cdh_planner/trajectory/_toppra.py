"""``toppra`` (with its ``algorithm`` and ``constraint`` modules), imported without the
libraries it loads at its top for things the planner never uses.

    from ._toppra import toppra

Those are matplotlib.pyplot (its algorithm module's plotting helpers; about 0.25 s),
scipy.interpolate (its own path classes: CubicSpline, PPoly, BPoly, UnivariateSpline; with
scipy.optimize and special about 0.2 s) and scipy.sparse (its ECOS solver wrapper; 0.12 s;
scipy's own package 10 - 20 ms): the planner hands toppra its own path and constraints
(trajectory/dynamics.py) and uses its default solver. So while toppra is imported, the
modules in ``DEFERRED`` are placeholders, removed from ``sys.modules`` right after: a name
toppra takes from one (``plt``, ``CubicSpline``, ...) is a stand-in that imports the real
module at its first use (never, unless a toppra plot, path class or ECOS is used), and
every other import of those modules gets the real one. A module already imported is used
as it is.

Import this module at start-up in a process with threads (the node imports it with the
planner, before it spins): another thread importing one of those modules during the few
milliseconds of toppra's import would get a placeholder.
"""

import importlib
import sys
import types


DEFERRED = ("matplotlib", "matplotlib.pyplot", "scipy", "scipy.interpolate", "scipy.sparse")


class _Deferred(types.ModuleType):
    """A module that imports the real module of its name at its first attribute use; a
    name taken from it while it stands in (``from M import name``) is a _DeferredName."""

    def __getattr__(self, attr):
        if sys.modules.get(self.__name__) is self:  # still inside toppra's import
            if attr.startswith("__"):
                raise AttributeError(f"{self.__name__}.{attr} (deferred while toppra imports)")
            return _DeferredName(self.__name__, attr)
        return getattr(importlib.import_module(self.__name__), attr)


class _DeferredName:
    """``module.attr``, looked up in the real module when called or its attributes read."""

    def __init__(self, module, attr):
        self._module, self._attr = module, attr

    def _real(self):
        return getattr(importlib.import_module(self._module), self._attr)

    def __call__(self, *args, **kwargs):
        return self._real()(*args, **kwargs)

    def __getattr__(self, attr):
        if attr.startswith("__"):
            raise AttributeError(attr)
        return getattr(self._real(), attr)


def _import_lean():
    placeholders = {name: _Deferred(name) for name in DEFERRED if name not in sys.modules}
    for name, module in placeholders.items():  # a placeholder's placeholder submodules
        parent, _, child = name.rpartition(".")
        if parent in placeholders:
            setattr(placeholders[parent], child, module)
    sys.modules.update(placeholders)
    try:
        import toppra.algorithm
        import toppra.constraint
    finally:
        for name, module in placeholders.items():
            if sys.modules.get(name) is module:
                del sys.modules[name]
    return toppra


toppra = _import_lean()
