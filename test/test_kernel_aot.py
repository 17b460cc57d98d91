"""The ahead-of-time kernels (manifold/aot.py, scene/aot.py through cdh_planner/aot.py) are
their JIT kernels' twins, and only ever the build of the current source (the collision
kernel's twin test: test_scene_batch.py)."""

import hashlib
import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cdh_planner.manifold import kernels
from cdh_planner.scene import kernels as scene_kernels

AOT_BUILT = importlib.util.find_spec(f"cdh_planner.manifold.{kernels.aot_module_name()}") is not None


SOURCES = [(kernels, ("kernels.py", "layout.py")), (scene_kernels, ("kernels.py", "../model/shape_forms.py"))]


@pytest.mark.parametrize("module, sources", SOURCES, ids=["manifold", "scene"])
def test_the_aot_module_is_named_after_the_digest_of_the_kernel_source(module, sources):
    d = Path(module.__file__).resolve().parent
    h = hashlib.sha256(b"".join((d / name).read_bytes() for name in sources))
    assert module.aot_module_name() == module.AOT_PREFIX + h.hexdigest()[:12]


@pytest.mark.parametrize("module", [kernels, scene_kernels], ids=["manifold", "scene"])
def test_a_build_of_other_source_is_never_loaded(module, monkeypatch):
    monkeypatch.setattr(module, "source_digest", lambda: "000000000000")
    assert module.aot_kernel() is None


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


def test_without_a_compiler_the_build_falls_back_to_warming_the_jit(monkeypatch, capsys):
    from cdh_planner import aot

    def fail(module):
        raise OSError("no C compiler")

    warmed = []
    monkeypatch.setattr(aot, "build", fail)
    assert aot.main("collision kernel", scene_kernels, lambda: warmed.append(1)) == 0
    assert warmed == [1] and "no C compiler" in capsys.readouterr().err


@pytest.mark.parametrize("name", ["manifold", "scene"])
def test_the_jit_warm_up_runs_on_its_own_inputs(name):
    """The fallback's warm-up call compiles and runs (no division by zero in its inputs)."""
    module = importlib.import_module(f"cdh_planner.{name}.aot")
    module.warm_jit()
