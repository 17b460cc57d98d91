"""The ahead-of-time kernels (manifold/aot.py, scene/aot.py, wrench/aot.py through
cdh_planner/aot.py) are their JIT kernels' twins, only ever the build of the current source,
and a fresh process that uses them compiles nothing (the collision kernel's twin test:
test_scene_batch.py)."""

import hashlib
import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cdh_planner import accuracy_kernel, aot as aot_helper, parallel
from cdh_planner.manifold import kernels
from cdh_planner.model import elastic_kernel
from cdh_planner.trajectory import motion_kernel
from cdh_planner.accuracy import error_map
from cdh_planner.model.pose import rotation_tt
from cdh_planner.model.robot import load_robot
from cdh_planner.scene import kernels as scene_kernels
from cdh_planner.wrench import compiled as wrench_kernels
from cdh_planner.wrench.facets import facet_subsets
from cdh_planner.wrench.geometry import inverse_factor
from conftest import CONFIG, aot_built

AOT_BUILT = aot_built(kernels)
ALL_BUILT = aot_built(kernels, scene_kernels, wrench_kernels, elastic_kernel, accuracy_kernel,
                      motion_kernel)
NOT_BUILT = ("no ahead-of-time kernels built (make, or python -m "
             "cdh_planner.<manifold|scene|wrench>.aot, cdh_planner.model.elastic_aot, "
             "cdh_planner.accuracy_aot, "
             "cdh_planner.trajectory.motion_aot)")

SOURCES = [(kernels, ("kernels.py", "layout.py", "../kernel_linalg.py")),
           (scene_kernels, ("kernels.py", "../model/shape_forms.py")),
           (wrench_kernels, ("compiled.py", "kernel.py", "centred.py", "linalg.py", "../kernel_linalg.py")),
           (elastic_kernel, ("elastic_kernel.py",)),
           (accuracy_kernel, ("accuracy_kernel.py", "kernel_linalg.py")),
           (motion_kernel, ("motion_kernel.py",))]
MODULES = ["manifold", "scene", "wrench", "elastic", "accuracy", "motion"]
BUILDERS = {"manifold": "cdh_planner.manifold.aot", "scene": "cdh_planner.scene.aot",
            "wrench": "cdh_planner.wrench.aot", "elastic": "cdh_planner.model.elastic_aot",
            "accuracy": "cdh_planner.accuracy_aot",
            "motion": "cdh_planner.trajectory.motion_aot"}


@pytest.mark.parametrize("module, sources", SOURCES, ids=MODULES)
def test_the_aot_module_is_named_after_the_digest_of_the_kernel_source(module, sources):
    """... and of aot.py, which says how it is built (release_gil)."""
    d = Path(module.__file__).resolve().parent
    h = hashlib.sha256(Path(aot_helper.__file__).read_bytes()
                       + b"".join((d / name).read_bytes() for name in sources))
    assert aot_helper.module_name(module) == module.AOT_PREFIX + h.hexdigest()[:12]


@pytest.mark.parametrize("module", [kernels, scene_kernels, wrench_kernels, elastic_kernel,
                                    accuracy_kernel, motion_kernel], ids=MODULES)
def test_a_build_of_other_source_is_never_loaded(module, monkeypatch):
    monkeypatch.setattr(module, "AOT_SOURCES", ("__init__.py",))  # another source's digest
    assert aot_helper.load(module) is None


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


def test_with_no_c_compiler_the_build_falls_back_to_warming_the_jit():
    """CC names no working compiler: pycc refuses before it writes or removes a file, and
    the build warms the JIT instead (exit code 0)."""
    code = ("import sys\nfrom cdh_planner import aot\nfrom cdh_planner.wrench import compiled\n"
            "sys.exit(aot.main('wrench kernels', compiled, lambda: print('warmed')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "CC": "/bin/false"})
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "warmed" and "ahead-of-time build failed" in out.stderr


@pytest.mark.parametrize("name", MODULES)
def test_the_jit_warm_up_runs_on_its_own_inputs(name):
    """The fallback's warm-up call compiles and runs (no division by zero in its inputs)."""
    module = importlib.import_module(BUILDERS[name])
    module.warm_jit()


def _wrench_inputs(robot, n, seed):
    """The wrench entries' arguments at n poses of ``robot`` near its workspace's centre (a
    slow random walk, so that the centred rule's warm starts matter)."""
    rng = np.random.default_rng(seed)
    centre = np.mean(robot.base_anchors, axis=0) * np.array([1.0, 1.0, 0.5])
    p = centre + np.cumsum(rng.normal(0.0, 0.003, (n, 3)), axis=0)
    R = rotation_tt(np.cumsum(rng.normal(0.0, 0.003, (n, 3)), axis=0) + [0.0, 0.1, 0.0])
    geometry = (p, R, robot.base_anchors, robot.platform_anchors, robot.load_point)
    ellipsoid = (robot.wrench_center_local, inverse_factor(robot), robot.ellipsoid_frame == "load",
                 robot.tension_min, robot.tension_max)
    return geometry, ellipsoid, facet_subsets(len(robot.base_anchors))


@pytest.mark.skipif(not ALL_BUILT, reason=NOT_BUILT)
@pytest.mark.parametrize("n", [7, wrench_kernels.PARALLEL_MIN + 700])
@pytest.mark.parametrize("name", ["robot2_8", "cogiro", "ipanema2"])
def test_aot_and_jit_wrench_kernels_agree_bit_for_bit(name, n):
    robot = load_robot(CONFIG / f"{name}.yaml")
    geometry, ellipsoid, subsets = _wrench_inputs(robot, n, 5)
    outputs = {}
    for which, entry in (("aot", aot_helper.load(wrench_kernels)),
                         ("jit", wrench_kernels.jit_kernels())):
        lengths, u, J, c = out = entry["pose_geometry"](*geometry)
        out += entry["facet_kernel"](J, c, *ellipsoid, subsets, 1e-9)
        ranked, feasible = out[-1], out[-1] & (out[6] > 0)
        for chunk in (n, wrench_kernels.PARALLEL_CHUNK):
            out += entry["centred_kernel"](J, c, *ellipsoid, ranked, feasible, chunk)
        outputs[which] = out
    assert outputs["aot"][-1].dtype == np.float64 and np.isfinite(outputs["aot"][-1]).any()
    for a, j in zip(outputs["aot"], outputs["jit"]):
        np.testing.assert_array_equal(a, j)


@pytest.mark.skipif(not ALL_BUILT, reason=NOT_BUILT)
@pytest.mark.parametrize("name", ["robot2", "robot1"])
def test_aot_and_jit_six_cable_kernels_agree_bit_for_bit(name):
    """The six-cable rule (t0, band, J^-1 W, singular) of a walk, both builds."""
    robot = load_robot(CONFIG / f"{name}.yaml")
    geometry, ellipsoid, _ = _wrench_inputs(robot, 300, 6)
    W = np.random.default_rng(6).normal(size=(300, 2, 6))
    _builds_agree(wrench_kernels, "six_cable_kernel", (*geometry, *ellipsoid[:3], W, 1e-12))


@pytest.mark.skipif(not ALL_BUILT, reason=NOT_BUILT)
@pytest.mark.parametrize("name", ["robot2", "robot2_8"])
def test_aot_and_jit_motion_kernels_agree_bit_for_bit(name):
    """The dynamic timing's per-sample geometry on a walk with random rates, and the turns
    between its rotations, both builds."""
    robot = load_robot(CONFIG / f"{name}.yaml")
    p, R, a, b, g = _wrench_inputs(robot, 200, 9)[0]
    rates = np.random.default_rng(9).normal(size=(4, 200, 3))
    _builds_agree(motion_kernel, "motion_terms_kernel",
                  (p, rates[0], rates[1], R, rates[2], rates[3], a, b, g, 0.6,
                   np.diag([1e-3, 2e-3, 3e-3])))
    index = np.arange(200, dtype=np.int64)
    _builds_agree(motion_kernel, "turns_kernel", (R, index[:-2], index[2:], 1e-3))


def _builds_agree(module, entry, args):
    """The kernel module's entry, built ahead of time and by the JIT, on ``args``: the same
    bits (its first output finite: the comparison is not of nan)."""
    aot = aot_helper.load(module)[entry](*args)
    jit = module.jit_kernels()[entry](*args)
    assert np.isfinite(aot[0]).all()
    for a, j in zip(aot, jit):
        np.testing.assert_array_equal(a, j)


@pytest.mark.skipif(not ALL_BUILT, reason=NOT_BUILT)
@pytest.mark.parametrize("name", ["robot2", "cogiro", "robot2_8"])
def test_aot_and_jit_accuracy_kernels_agree_bit_for_bit(name):
    """The zonotope kernel on the position and rotation rows of the error maps of a walk,
    and on generators made degenerate (parallel, in a pair's plane, tiny), both builds; the
    error map kernel and the one-pass accuracy on the walk, both builds."""
    robot = load_robot(CONFIG / f"{name}.yaml")
    p, R = _wrench_inputs(robot, 300, 8)[0][:2]
    G = error_map(robot, p, R)
    rng = np.random.default_rng(9)
    g = rng.normal(size=(300, 3, G.shape[-1]))
    g[:50, :, 1] = 2.0 * g[:50, :, 0]
    g[50:100, :, 3] = g[50:100, :, 0] - g[50:100, :, 2]
    tiny = np.zeros(g.shape[::2], dtype=bool)
    tiny[100:150, 2] = True
    g[tiny[:, None, :].repeat(3, axis=1)] = 0.0
    plain = np.zeros_like(tiny)
    for gen, flags in ((G[:, :3], plain), (G[:, 3:], plain), (g, tiny)):
        gen = np.ascontiguousarray(np.nan_to_num(gen))
        args = (gen, np.linalg.norm(gen, axis=1), flags, 1e-6, 1e-9)
        aot = aot_helper.load(accuracy_kernel)["vertex_max_kernel"](*args)
        jit = accuracy_kernel.jit_kernels()["vertex_max_kernel"](*args)
        assert flags is plain or (aot[1][:100].all() and aot[2].all())  # degenerate ones seen
        for a, j in zip(aot, jit):
            np.testing.assert_array_equal(a, j)
    # the error maps themselves, rigid (k = 1 / L) and elastic (k from the tensions)
    m = len(robot.base_anchors)
    t = np.ascontiguousarray(np.random.default_rng(3).uniform(100.0, 900.0, (len(p), m)))
    for elastic, EA in ((False, np.ones(m)), (True, np.full(m, 2e5))):
        args = (robot.base_anchors, robot.platform_anchors, p, R, EA, t, elastic, 1e-12)
        args = tuple(np.ascontiguousarray(x) if isinstance(x, np.ndarray) else x for x in args)
        np.testing.assert_array_equal(aot_helper.load(accuracy_kernel)["error_map_kernel"](*args),
                                      accuracy_kernel.jit_kernels()["error_map_kernel"](*args))
        args += (np.full(m, 1e-3), 1e-13, 1e-6, 1e-9)
        for a, j in zip(aot_helper.load(accuracy_kernel)["accuracy_kernel"](*args),
                        accuracy_kernel.jit_kernels()["accuracy_kernel"](*args)):
            np.testing.assert_array_equal(a, j)


def test_the_wrench_kernels_on_threads_give_the_serial_answers(monkeypatch):
    """A large batch in blocks on threads (``parallel``; the entries release the GIL) gives
    the numbers of one call on the caller's thread: the blocks start at the centred rule's
    chunks, whose first poses start Newton cold either way."""
    robot = load_robot(CONFIG / "cogiro.yaml")
    geometry, ellipsoid, subsets = _wrench_inputs(robot, parallel.MIN_POSES + 1300, 6)
    _, _, J, c = wrench_kernels.pose_geometry(*geometry)
    answers = {}
    for threads in ("1", "3"):
        monkeypatch.setenv("CDH_PLANNER_THREADS", threads)
        assert len(parallel.block_bounds(len(J), wrench_kernels.PARALLEL_CHUNK)) == int(threads)
        out = wrench_kernels.facet_batch(J, c, *ellipsoid, subsets, 1e-9)
        ranked, feasible = out[-1], out[-1] & (out[2] > 0)
        t0, v = wrench_kernels.centred_batch(J, c, *ellipsoid, ranked, feasible)
        W = (robot.cable_stiffness + t0) / 9.0
        band = wrench_kernels.stiffness_band_batch(J, c, *ellipsoid[:3], W, ranked)
        answers[threads] = out + (t0, v, band)
    assert answers["1"][-1].shape == (len(J), 8) and np.isfinite(answers["1"][-1]).all()
    for a, t in zip(answers["1"], answers["3"]):
        np.testing.assert_array_equal(a, t)


@pytest.mark.parametrize("name", ["robot2_8", "cogiro", "ipanema2"])
def test_the_stiffness_band_kernel_is_the_weighted_pseudo_inverse(name):
    """|rows of P_W L|, P_W = W J^T (J W J^T)^-1 (``rules.weighted_pseudo_inverse``, numpy's
    batched solve), to 1e-12, with positive and negative weights; inf where J W J^T is
    singular (every weight 0), nan off ``ok``."""
    from cdh_planner.wrench.rules import weighted_pseudo_inverse
    from cdh_planner.wrench.geometry import inverse_ellipsoid_factor
    robot = load_robot(CONFIG / f"{name}.yaml")
    geometry, ellipsoid, _ = _wrench_inputs(robot, 200, 8)
    _, _, J, c = wrench_kernels.pose_geometry(*geometry)
    W = np.random.default_rng(8).uniform(0.5, 2.0, (len(J), 8)) * 1e4
    W[:20, 3] *= -0.01  # a cable of negative weight: J W J^T still invertible
    W[20] = 0.0
    ok = np.ones(len(J), dtype=bool)
    ok[21] = False
    band = wrench_kernels.stiffness_band_batch(J, c, *ellipsoid[:3], W, ok)
    keep = ok & (np.arange(len(J)) != 20)
    P = weighted_pseudo_inverse(J[keep], W[keep])
    expected = np.linalg.norm(P @ inverse_ellipsoid_factor(robot, c[keep]), axis=-1)
    np.testing.assert_allclose(band[keep], expected, rtol=1e-12)
    assert np.all(np.isinf(band[20])) and np.all(np.isnan(band[21]))


@pytest.mark.skipif(not ALL_BUILT, reason=NOT_BUILT)
def test_every_ahead_of_time_build_releases_the_gil():
    """Each build's entries release the GIL while their machine code runs (``aot.build``
    compiles them with numba's ``release_gil``, whose wrappers call PyEval_SaveThread; a
    build without it imports no such symbol), so ``parallel``'s threads run side by side."""
    for module in (kernels, scene_kernels, wrench_kernels, elastic_kernel, accuracy_kernel,
                   motion_kernel):
        built = importlib.import_module(f"{module.__package__}.{aot_helper.module_name(module)}")
        assert b"PyEval_SaveThread" in Path(built.__file__).read_bytes(), module.__name__


def test_the_wrench_entries_take_any_layout_and_type():
    """The ahead-of-time entries read memory as their signatures say: the batch functions
    pass them C-contiguous float64 whatever they are given."""
    robot = load_robot(CONFIG / "robot2_8.yaml")
    geometry, ellipsoid, subsets = _wrench_inputs(robot, 40, 7)
    p, R = geometry[:2]
    R32 = R.astype(np.float32)
    strided = (np.asfortranarray(np.repeat(p, 2, axis=0)[::2]), R32, geometry[2].tolist(),
               np.asfortranarray(geometry[3]), geometry[4])
    expected = wrench_kernels.pose_geometry(p, R32.astype(np.float64), *geometry[2:])
    for a, b in zip(wrench_kernels.pose_geometry(*strided), expected):
        np.testing.assert_array_equal(a, b)
    J, c = expected[2], expected[3]
    Jf, tmin = np.asfortranarray(J), list(ellipsoid[3])
    strided = (Jf, c, *ellipsoid[:3], tmin, ellipsoid[4], subsets.astype(np.int32), 1e-9)
    for a, b in zip(wrench_kernels.facet_batch(J, c, *ellipsoid, subsets, 1e-9),
                    wrench_kernels.facet_batch(*strided)):
        np.testing.assert_array_equal(a, b)


# Each compiled kernel called once in a fresh process: the manifold's F / F_x, the collision
# kernel, the wrench entries (the pose geometry, the facet test, the centred rule) of an
# 8-cable robot and the six-cable rule through the package's entries, its elastic equilibrium,
# its accuracy (the zonotope kernel) and the dynamic timing's motion terms. Prints whether
# numba was imported.
FRESH_CALLS = f"""
import sys, json
import numpy as np
from cdh_planner.manifold import kernels
from cdh_planner.model.robot import load_robot
from cdh_planner.scene.collision import CollisionModel
from cdh_planner.scene.schema import load_scene
from cdh_planner import wrench
X, prm = np.ones(kernels.N_VARS), np.ones(kernels.N_PARAMS)
prm[kernels.K_KAPPA] = 0.1
prm[kernels.K_LMAX:kernels.K_FMIN] = 3.0
prm[kernels.K_FMAX:kernels.K_KAPPA] = 4.0
kernels.navigation_residual_and_jacobian(X, prm, True)
robot2 = load_robot({str(CONFIG / "robot2.yaml")!r})
scene = load_scene({str(CONFIG / "scenes" / "robot2_ball.yaml")!r}, robot2)
assert CollisionModel(robot2, scene).clearance(np.array([0, 0, 0.4]), np.eye(3)).distance > 0
six = float(wrench.rule_tensions(robot2, np.array([[0.0, 0.0, 0.4]]), np.eye(3)[None])[1][0, 0])
robot = load_robot({str(CONFIG / "cogiro.yaml")!r})
p, R = np.array([[0.0, 0.0, 2.5]]), np.eye(3)[None]
answers = [float(wrench.wrench_feasibility(robot, p, R=R).margin[0]),
           float(wrench.band_margin(robot, p, R=R)[0]),
           float(wrench.rule_tensions(robot, p, R)[0][0, 0]), six]
from cdh_planner.model import elastic
f = wrench.band_feasibility(robot, p, R=R)
L0 = elastic.unstretched_lengths(robot, f.lengths, f.tension_nominal)
w = robot.wrench_center_local
eq = elastic.equilibrium_poses(robot, L0, p, R, w[None, :3], w[None, 3:], np.zeros((1, 3)))
answers.append(float(eq.p[0, 2]))
from cdh_planner.accuracy import pose_accuracy
answers.append(float(pose_accuracy(robot, p, R=R).position_m[0]))
from cdh_planner.trajectory.motion_kernel import motion_terms
answers.append(float(motion_terms(robot, p, p, p, R, p, p, 1.0, np.eye(3))[2][0, 0]))
print(json.dumps(["numba" in sys.modules, answers]))
"""


def _fresh(prelude=""):
    out = subprocess.run([sys.executable, "-c", prelude + FRESH_CALLS], capture_output=True,
                         text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(not ALL_BUILT, reason=NOT_BUILT)
def test_with_the_aot_kernels_a_fresh_process_compiles_nothing():
    """Every compiled kernel called once in a fresh process: numba is never imported, so
    nothing is compiled or loaded from its cache (0.4 - 1 s each with the JIT)."""
    numba_loaded, answers = _fresh()
    assert not numba_loaded and np.all(np.isfinite(answers))


def test_without_the_aot_kernels_the_jit_gives_the_same_answers():
    """No build of the current source (as without a C compiler): numba's JIT compiles the
    same source, with the same answers as in this process (ahead of time, if built)."""
    numba_loaded, answers = _fresh("import cdh_planner.aot as a\na.load = lambda kernels: None\n")
    assert numba_loaded
    _, expected = _fresh()
    assert answers == expected
