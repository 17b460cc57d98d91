"""Build the ahead-of-time compiled kernel (kernels.py) next to its source.

    python -m cdh_planner.manifold.aot

numba.pycc compiles the same Python source as the JIT into an extension module named
after the source's digest (``kernels.aot_module_name()``), for the generic CPU of this
architecture (a venv copied to another x86-64 machine still runs it); older builds are
removed. numba marks pycc "pending deprecation" (0.57 - 0.68 still ship it): if it is
missing or the build fails (no C compiler), this warms numba's JIT cache instead, and the
planner uses the JIT. Exit code 0 either way: the kernel works, only its first call in a
process costs more. ``make`` runs this.
"""

import sys
import time
import warnings
from pathlib import Path

import numpy as np

from . import kernels

HERE = Path(kernels.__file__).resolve().parent


def build(output_dir=HERE):
    """Compile the kernel ahead of time into ``output_dir``; the extension's path."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # pycc's pending-deprecation notice
        from numba.pycc import CC
    name = kernels.aot_module_name()
    cc = CC(name)
    cc.output_dir = str(output_dir)
    cc.verbose = False
    jit = kernels.jit_kernel()  # the helpers as numba functions, which the export calls
    cc.export(kernels.AOT_EXPORT, kernels.AOT_SIGNATURE)(jit.py_func)
    cc.compile()  # object files go to a temporary directory of pycc's own
    built = [p for p in Path(output_dir).glob(f"{name}.*") if p.suffix in (".so", ".pyd")]
    if not built:
        raise RuntimeError(f"numba.pycc wrote no {name}.* in {output_dir}")
    for old in Path(output_dir).glob(kernels.AOT_PREFIX + "*"):
        if not old.name.startswith(name + "."):
            old.unlink()
    return built[0]


def warm_jit():
    """Compile the JIT kernel once so that its cache (in __pycache__) is there."""
    X = np.ones(kernels.N_VARS)
    kernels.jit_kernel()(X, np.ones(kernels.N_PARAMS), True)


def main():
    t = time.perf_counter()
    try:
        path = build()
    except Exception as exc:  # noqa: BLE001 - any failure leaves the JIT, which works
        print(f"kernel: ahead-of-time build failed ({type(exc).__name__}: {exc}); "
              f"warming numba's JIT cache instead", file=sys.stderr)
        warm_jit()
        return 0
    print(f"kernel: {path.name} built in {time.perf_counter() - t:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
