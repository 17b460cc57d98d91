"""Ahead-of-time compilation of the package's numba kernels, one way for all of them
(manifold/kernels.py, scene/kernels.py).

A kernel module holds plain Python functions (no numba import) and names its entry
points and their signatures. Two compilations of the same source, the first one found
is used:

- ahead of time (numba.pycc, ``python -m cdh_planner.manifold.aot`` / ``.scene.aot``, run
  by ``make``): an extension module next to the source, named after a digest of it, so an
  edited kernel never runs stale machine code; importing it and a first call take about
  10 ms and numba is not imported at all. Built for the generic CPU of the architecture.
- numba's JIT with ``cache=True`` (``jit``): importing numba and loading the machine code
  from __pycache__ cost 0.4 - 1 s in a fresh process (a first compilation, seconds).

numba marks pycc "pending deprecation" (0.57 - 0.68 still ship it): if it is missing or
the build fails (no C compiler), ``main`` warms numba's JIT cache instead and exits 0.
"""

import hashlib
import importlib
import sys
import time
import warnings
from pathlib import Path


def source_digest(directory, names):
    """12 hex digits of sha256 over the files ``names`` in ``directory``: what the
    machine code is of."""
    h = hashlib.sha256()
    for name in names:
        h.update((Path(directory) / name).read_bytes())
    return h.hexdigest()[:12]


def load(package, module_name, exports):
    """The exported functions (a tuple, in the order of ``exports``) of the ahead-of-time
    module ``package.module_name``, or None if it was not built for this source."""
    try:
        module = importlib.import_module(f"{package}.{module_name}")
    except (ImportError, OSError):  # not built, or the source not readable as files
        return None
    return tuple(getattr(module, name) for name in exports)


def jit(namespace, helpers, inline=()):
    """Turn the functions ``helpers`` of a kernel module's globals ``namespace`` into numba
    functions (cache=True; those in ``inline`` inlined), once; entries then compile with
    ``njit(cache=True)`` and call them."""
    from numba import njit

    for name in helpers:
        if not hasattr(namespace[name], "py_func"):
            options = {"inline": "always"} if name in inline else {}
            namespace[name] = njit(cache=True, **options)(namespace[name])
    return njit(cache=True)


def build(module_name, exports, output_dir, prefix):
    """Compile ``exports`` ({exported name: (signature, numba function)}) ahead of time
    into the extension ``module_name`` in ``output_dir``; older builds (``prefix``*) are
    removed. The extension's path."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # pycc's pending-deprecation notice
        from numba.pycc import CC
    cc = CC(module_name)
    cc.output_dir = str(output_dir)
    cc.verbose = False
    for name, (signature, function) in exports.items():
        cc.export(name, signature)(function.py_func)
    cc.compile()  # object files go to a temporary directory of pycc's own
    built = [p for p in Path(output_dir).glob(f"{module_name}.*") if p.suffix in (".so", ".pyd")]
    if not built:
        raise RuntimeError(f"numba.pycc wrote no {module_name}.* in {output_dir}")
    for old in Path(output_dir).glob(prefix + "*"):
        if not old.name.startswith(module_name + "."):
            old.unlink()
    return built[0]


def main(label, build_kernel, warm_jit):
    """Run ``build_kernel()`` (the extension's path); if it fails, ``warm_jit()``. Exit code
    0 either way: the kernel works, only its first call in a process costs more."""
    t = time.perf_counter()
    try:
        path = build_kernel()
    except Exception as exc:  # noqa: BLE001 - any failure leaves the JIT, which works
        print(f"{label}: ahead-of-time build failed ({type(exc).__name__}: {exc}); "
              f"warming numba's JIT cache instead", file=sys.stderr)
        warm_jit()
        return 0
    print(f"{label}: {path.name} built in {time.perf_counter() - t:.1f} s")
    return 0
