"""The ahead-of-time kernel (manifold/aot.py) is the JIT kernel's twin, and only ever the
build of the current source."""

import hashlib
import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cdh_planner.manifold import kernels

AOT_BUILT = importlib.util.find_spec(f"cdh_planner.manifold.{kernels.aot_module_name()}") is not None


def test_the_aot_module_is_named_after_the_digest_of_the_kernel_source():
    d = Path(kernels.__file__).resolve().parent
    h = hashlib.sha256((d / "kernels.py").read_bytes() + (d / "layout.py").read_bytes())
    assert kernels.aot_module_name() == kernels.AOT_PREFIX + h.hexdigest()[:12]


def test_a_build_of_other_source_is_never_loaded(monkeypatch):
    monkeypatch.setattr(kernels, "source_digest", lambda: "000000000000")
    assert kernels.aot_kernel() is None


@pytest.mark.skipif(not AOT_BUILT, reason="no ahead-of-time kernel built (make, or python -m "
                                          "cdh_planner.manifold.aot)")
def test_aot_and_jit_kernels_agree_bit_for_bit():
    rng = np.random.default_rng(3)
    aot, jit = kernels.aot_kernel(), kernels.jit_kernel()
    for load_frame in (0.0, 1.0):
        for _ in range(20):
            X = rng.uniform(0.5, 1.5, kernels.N_VARS)
            prm = rng.uniform(-1.0, 1.0, kernels.N_PARAMS)
            prm[kernels.K_KAPPA], prm[kernels.K_LOAD] = 0.1, load_frame
            prm[kernels.K_LMAX:kernels.K_FMIN] = prm[kernels.K_LMIN:kernels.K_LMAX] + 2.0
            prm[kernels.K_FMAX:kernels.K_KAPPA] = prm[kernels.K_FMIN:kernels.K_FMAX] + 3.0
            for jac in (True, False):
                Fa, Ja = aot(X, prm, jac)
                Fj, Jj = jit(X, prm, jac)
                np.testing.assert_array_equal(Fa, Fj)
                np.testing.assert_array_equal(Ja, Jj)


@pytest.mark.skipif(not AOT_BUILT, reason="no ahead-of-time kernel built")
def test_with_the_aot_kernel_a_process_never_imports_numba():
    code = ("import sys\nfrom cdh_planner.manifold import kernels\n"
            "assert kernels.navigation_residual_and_jacobian is not None\n"
            "print('numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
