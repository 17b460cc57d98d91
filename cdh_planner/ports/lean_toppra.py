"""``toppra`` (with its ``algorithm`` and ``constraint`` modules), imported without the
libraries it loads at its top for things the planner never uses.

Those are matplotlib.pyplot (its algorithm module's plotting helpers; about 0.25 s),
scipy.interpolate (its own path classes: CubicSpline, PPoly, BPoly, UnivariateSpline; with
scipy.optimize and special about 0.2 s) and scipy.sparse (its ECOS solver wrapper; 0.12 s):
the planner hands toppra its own path and constraints (trajectory/dynamics.py) and uses its
default solver.

How, and why no other thread can see it: toppra's own modules are executed with an
``__import__`` of their own (their ``__builtins__``), which answers an import of a module
in ``DEFERRED`` that is not loaded yet with a stand-in. A name toppra takes from a stand-in
(``plt``, ``CubicSpline``, ...) imports the real module at its first use (never, unless a
toppra plot, path class or ECOS is used). ``sys.modules`` is never touched: every other
import, in any thread, gets the real modules. A module already imported is used as it is.
"""

import builtins
import importlib
import importlib.machinery
import sys
import types

DEFERRED = ("matplotlib", "matplotlib.pyplot", "scipy", "scipy.interpolate", "scipy.sparse")

_importing = False  # True while toppra's modules run their top level
_stand_ins = {}


class _Deferred(types.ModuleType):
    """Stands in for the module of its name: while toppra imports, a name taken from it
    is a _DeferredName (a deferred submodule another stand-in); afterwards an attribute
    is the real module's."""

    def __getattr__(self, attr):
        child = f"{self.__name__}.{attr}"
        if _importing and child in DEFERRED and child not in sys.modules:
            return _stand_in(child)
        if _importing and not attr.startswith("__"):
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


def _stand_in(name):
    return _stand_ins.setdefault(name, _Deferred(name))


def _toppra_import(name, globals=None, locals=None, fromlist=(), level=0):
    """``__import__`` for toppra's modules: a deferred module not yet loaded is a stand-in
    while toppra imports; everything else, and everything later, is the real import."""
    if not (_importing and level == 0 and name in DEFERRED and name not in sys.modules):
        return builtins.__import__(name, globals, locals, fromlist, level)
    if fromlist:
        return _stand_in(name)
    top = name.partition(".")[0]  # ``import a.b`` binds a
    return sys.modules.get(top) or _stand_in(top)


_TOPPRA_BUILTINS = dict(builtins.__dict__, __import__=_toppra_import)


class _ToppraLoader:
    """A toppra source module's loader that gives the module our ``__import__``."""

    def __init__(self, loader):
        self._loader = loader

    def create_module(self, spec):
        return self._loader.create_module(spec)

    def exec_module(self, module):
        module.__dict__["__builtins__"] = _TOPPRA_BUILTINS
        self._loader.exec_module(module)

    def __getattr__(self, attr):  # get_data, get_filename, is_package, ...
        return getattr(self._loader, attr)


class _ToppraFinder:
    """Finds toppra's modules as the path finder does, with _ToppraLoader on its sources."""

    @staticmethod
    def find_spec(fullname, path=None, target=None):
        if fullname != "toppra" and not fullname.startswith("toppra."):
            return None
        spec = importlib.machinery.PathFinder.find_spec(fullname, path, target)
        if spec is not None and isinstance(spec.loader, importlib.machinery.SourceFileLoader):
            spec.loader = _ToppraLoader(spec.loader)
        return spec


def import_lean():
    """The toppra package with ``algorithm`` and ``constraint`` imported (lean unless
    toppra was already imported)."""
    global _importing
    if "toppra" in sys.modules:
        import toppra.algorithm
        import toppra.constraint
        return sys.modules["toppra"]
    finder = _ToppraFinder()
    sys.meta_path.insert(0, finder)
    _importing = True
    try:
        import toppra.algorithm
        import toppra.constraint
    finally:
        _importing = False
        sys.meta_path.remove(finder)
    return sys.modules["toppra"]
