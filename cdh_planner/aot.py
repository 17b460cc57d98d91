"""Ahead-of-time compilation of the package's numba kernels, one way for all of them
(manifold/kernels.py, scene/kernels.py, wrench/compiled.py).

A kernel module holds plain Python functions (no numba import), its entries' names and
signatures (AOT_EXPORTS, {name: numba signature}), the prefix of its builds (AOT_PREFIX),
the files beside it that its machine code is of (AOT_SOURCES, this one among them) and
``jit_kernels()`` ({name: numba's JIT function}). Two compilations
of the same source, the first one found is used (``entries``):

- ahead of time (numba.pycc, ``python -m cdh_planner.manifold.aot`` / ``.scene.aot`` /
  ``.wrench.aot``, run by ``make``): an extension module next to the source, named after a
  digest of it, so an edited kernel never runs stale machine code; importing it and a
  first call take about 10 ms and numba is not imported at all. Built for the generic CPU
  of the architecture. Its entries check neither the type nor the layout of the arrays
  they are given: callers pass exactly what AOT_EXPORTS says.
- numba's JIT with ``cache=True`` (``jit``): importing numba and loading the machine code
  from __pycache__ cost 0.4 - 1 s in a fresh process (a first compilation, seconds).

numba marks pycc "pending deprecation" (0.57 - 0.68 still ship it): if it is missing or
the build fails (no C compiler), ``main`` warms numba's JIT cache instead and exits 0.
"""

import importlib
import sys
from contextlib import contextmanager
import time
import warnings
from pathlib import Path

try:  # CPython's built-in SHA-256 (to 3.11): hashlib's import loads OpenSSL, 2.5 ms of a start
    from _sha256 import sha256
except ImportError:  # 3.12 renamed it; hashlib's is the same function
    from hashlib import sha256


def source_digest(kernels):
    """12 hex digits of sha256 over the kernel module's AOT_SOURCES (paths relative to its
    folder) and this file (how it is built): what the machine code is of."""
    folder = Path(kernels.__file__).resolve().parent
    h = sha256(Path(__file__).read_bytes())
    for name in kernels.AOT_SOURCES:
        h.update((folder / name).read_bytes())
    return h.hexdigest()[:12]


def module_name(kernels):
    """The ahead-of-time module of the kernel module ``kernels`` built from its current
    source: its AOT_PREFIX and ``source_digest``."""
    return kernels.AOT_PREFIX + source_digest(kernels)


def load(kernels):
    """The ahead-of-time compiled entries ({name: function}, AOT_EXPORTS) of the kernel
    module ``kernels``, or None if they were not built for this source."""
    try:
        module = importlib.import_module(f"{kernels.__package__}.{module_name(kernels)}")
    except (ImportError, OSError):  # not built, or the source not readable as files
        return None
    return {name: getattr(module, name) for name in kernels.AOT_EXPORTS}


def entries(kernels):
    """The entries ({name: function}) of the kernel module ``kernels``: its ahead-of-time
    build if there is one for this source, else numba's JIT (``kernels.jit_kernels()``)."""
    return load(kernels) or kernels.jit_kernels()


def jit(namespace, helpers, inline=()):
    """Turn the functions ``helpers`` of a kernel module's globals ``namespace`` into numba
    functions (cache=True, nogil=True as the ahead-of-time build; those in ``inline``
    inlined), once; entries then compile with the ``njit`` returned and call them."""
    from numba import njit

    for name in helpers:
        if not hasattr(namespace[name], "py_func"):
            options = {"inline": "always"} if name in inline else {}
            namespace[name] = njit(cache=True, nogil=True, **options)(namespace[name])
    return njit(cache=True, nogil=True)


def build(kernels, output_dir=None):
    """Compile the entries of the kernel module ``kernels`` (AOT_EXPORTS, its
    ``jit_kernels()``) ahead of time into ``output_dir`` (default: beside its source); older
    builds (AOT_PREFIX*) are removed. The extension's path."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # pycc's pending-deprecation notice
        from numba.pycc import CC
    name = module_name(kernels)
    output_dir = Path(kernels.__file__).resolve().parent if output_dir is None else Path(output_dir)
    cc = CC(name)
    cc.output_dir = str(output_dir)
    cc.verbose = False
    jit = kernels.jit_kernels()  # the helpers as numba functions, which the exports call
    for entry, signature in kernels.AOT_EXPORTS.items():
        cc.export(entry, signature)(jit[entry].py_func)
    with _releasing_gil():
        cc.compile()  # object files go to a temporary directory of pycc's own
    built = [p for p in output_dir.glob(f"{name}.*") if p.suffix in (".so", ".pyd")]
    if not built:
        raise RuntimeError(f"numba.pycc wrote no {name}.* in {output_dir}")
    for old in output_dir.glob(kernels.AOT_PREFIX + "*"):
        if not old.name.startswith(name + "."):
            old.unlink()
    return built[0]


@contextmanager
def _releasing_gil():
    """pycc's exports release the GIL while their machine code runs, as ``njit(nogil=True)``
    does (pycc has no option for it: its compile flags, made by ``Flags()``, get
    ``release_gil``): threads then run kernels side by side (``parallel.blocks``)."""
    from numba.core.compiler import Flags
    from numba.pycc import compiler

    def releasing():
        flags = Flags()
        flags.release_gil = True
        return flags

    compiler.Flags = releasing
    try:
        yield
    finally:
        compiler.Flags = Flags


def main(label, kernels, warm_jit):
    """Build the kernel module ``kernels`` ahead of time (``build``); if that fails,
    ``warm_jit()``. Exit code 0 either way: the kernel works, only its first call in a
    process costs more."""
    t = time.perf_counter()
    try:
        path = build(kernels)
    except Exception as exc:  # noqa: BLE001 - any failure leaves the JIT, which works
        print(f"{label}: ahead-of-time build failed ({type(exc).__name__}: {exc}); "
              f"warming numba's JIT cache instead", file=sys.stderr)
        warm_jit()
        return 0
    print(f"{label}: {path.name} built in {time.perf_counter() - t:.1f} s")
    return 0
