"""The compiled elastic equilibrium (model/elastic_kernel.py) against the numpy algebra:
its residual, tensions and Jacobian are ``elastic.wrench_balance``'s; its Newton gives the
poses, tensions and convergence of the batched numpy Newton it replaced (kept here as the
reference, ``reference_equilibria``) to 1e-9, from near and far seeds, with slack cables
and with the inertial wrenches the executed check adds; its rotation step is scipy's."""

import numpy as np
import pytest

from conftest import REPO
from cdh_planner import aot
from cdh_planner.model import elastic as E
from cdh_planner.model import elastic_kernel as K
from cdh_planner.model.kinematics import cable_lengths
from cdh_planner.model.robot import load_robot
from cdh_planner.ports.rotation import Rotation
from cdh_planner.wrench import band_feasibility

ROBOTS = ["robot2", "robot2_8", "cogiro", "ipanema2"]


# ----------------------------------------------------------------------------- the reference
# elastic.py's batched numpy Newton before the kernel (commit fe0f9f1), verbatim but for names

def reference_equilibria(robot, L0, p0, R0, force, moment, arm,
                         max_iterations=E.EQUILIBRIUM_ITERATIONS):
    p, R = np.array(p0, dtype=float), np.array(R0, dtype=float)
    load = (force, moment, arm)
    _newton(robot, L0, p, R, load, True, max_iterations)
    ok = _newton(robot, L0, p, R, load, False, max_iterations)
    res, _, t = E.wrench_balance(robot, L0, p, R, *load, jacobian=False)
    return E.Equilibria(p=p, R=R, tensions=t, residual=np.max(np.abs(res), axis=1), ok=ok)


def _newton(robot, L0, p, R, load, bilateral, max_iterations):
    scale = E.EQUILIBRIUM_TOL * np.maximum(1.0, np.linalg.norm(load[0], axis=1))
    ok = np.zeros(len(p), dtype=bool)
    todo = np.arange(len(p))
    res, _, _ = E.wrench_balance(robot, L0, p, R, *load, bilateral, jacobian=False)
    for _ in range(max_iterations):
        done = np.max(np.abs(res), axis=1) <= scale[todo]
        ok[todo[done]] = True
        todo, res = todo[~done], res[~done]
        if todo.size == 0:
            break
        _, jac, _ = E.wrench_balance(robot, L0[todo], p[todo], R[todo],
                                     *(x[todo] for x in load), bilateral)
        step = _newton_step(jac, res)
        keep = np.all(np.isfinite(step), axis=1)
        todo, res, step = todo[keep], res[keep], step[keep]
        if todo.size == 0:
            break
        p[todo], R[todo], moved, res = _line_search(robot, L0[todo], p[todo], R[todo], step, res,
                                                    tuple(x[todo] for x in load), bilateral)
        todo, res = todo[moved], res[moved]
    return ok


def _newton_step(jac, res):
    try:
        return -np.linalg.solve(jac, res[..., None])[..., 0]
    except np.linalg.LinAlgError:
        step = np.full(res.shape, np.nan)
        regular = np.linalg.matrix_rank(jac) == 6
        step[regular] = -np.linalg.solve(jac[regular], res[regular][..., None])[..., 0]
        return step


def _line_search(robot, L0, p, R, step, res, load, bilateral, halvings=E.LINE_SEARCH_HALVINGS):
    before = np.max(np.abs(res), axis=1)
    p_new, R_new, res_new = p.copy(), R.copy(), res.copy()
    scale = np.ones(len(p))
    todo = np.arange(len(p))
    for _ in range(halvings):
        s = step[todo] * scale[todo, None]
        p_try = p[todo] + s[:, :3]
        R_try = Rotation.from_rotvec(s[:, 3:]).as_matrix() @ R[todo]
        after, _, _ = E.wrench_balance(robot, L0[todo], p_try, R_try,
                                       *(x[todo] for x in load), bilateral, jacobian=False)
        better = np.max(np.abs(after), axis=1) < before[todo]
        p_new[todo[better]], R_new[todo[better]] = p_try[better], R_try[better]
        res_new[todo[better]] = after[better]
        todo = todo[~better]
        if todo.size == 0:
            break
        scale[todo] *= 0.5
    moved = np.ones(len(p), dtype=bool)
    moved[todo] = False
    return p_new, R_new, moved, res_new


# ----------------------------------------------------------------------------- cases

def _cases(name, n, seed, spread=1e-3):
    """Poses of ``name`` (feasible near the workspace's middle), L0 from their nominal
    tensions (some perturbed so that cables slacken), seeds ``spread`` m / 10 x spread rad
    away and the load rows with an inertial wrench."""
    robot = load_robot(REPO / "config" / f"{name}.yaml")
    rng = np.random.default_rng(seed)
    centre = np.mean(robot.base_anchors, axis=0) * np.array([1.0, 1.0, 0.0])
    centre[2] = 0.306 if robot.tension_max.max() < 100 else np.mean(robot.base_anchors[:, 2]) * 0.6
    p = centre + rng.normal(scale=0.05, size=(20 * n, 3))       # candidates, one batch
    R = Rotation.from_rotvec(rng.normal(scale=0.1, size=(20 * n, 3))).as_matrix()
    keep = np.flatnonzero(band_feasibility(robot, p, R=R).margin > 0)[:n]
    assert keep.size == n
    p, R = p[keep], R[keep]
    f = band_feasibility(robot, p, R=R)
    L0 = E.unstretched_lengths(robot, f.lengths, f.tension_nominal)
    L0[: n // 4, 0] *= 1.02                              # a slack cable in a quarter
    seed_R = Rotation.from_rotvec(rng.normal(scale=10 * spread, size=(n, 3))).as_matrix() @ R
    seed_p = p + rng.normal(scale=spread, size=p.shape)
    w = np.broadcast_to(robot.wrench_center_local, (n, 6))
    scale = np.abs(robot.wrench_center_local[:3]).max()
    force = w[:, :3] + rng.normal(scale=0.05 * scale, size=(n, 3))    # minus an inertial wrench
    moment = w[:, 3:] + rng.normal(scale=0.01 * scale, size=(n, 3))
    arm = force if robot.ellipsoid_frame == "load" else np.zeros((n, 3))
    return robot, L0, seed_p, seed_R, force, moment, arm


def _kernel_args(robot):
    m = len(robot.base_anchors)
    return (np.ascontiguousarray(robot.base_anchors, dtype=float),
            np.ascontiguousarray(robot.platform_anchors, dtype=float),
            np.asarray(robot.load_point, dtype=float),
            np.broadcast_to(np.asarray(robot.cable_stiffness, dtype=float), (m,)).copy())


@pytest.mark.parametrize("name", ROBOTS)
@pytest.mark.parametrize("bilateral", [True, False])
def test_the_kernels_balance_is_wrench_balance(name, bilateral):
    """Residual, tensions and Jacobian of one pose, compiled, equal the numpy algebra's
    (whose Jacobian test_elastic_execution.py checks by finite differences)."""
    robot, L0, p, R, force, moment, arm = _cases(name, 12, 1, spread=5e-3)
    res, jac, t = E.wrench_balance(robot, L0, p, R, force, moment, arm, bilateral)
    a, b, g, EA = _kernel_args(robot)
    m = len(a)
    assert np.any(t == 0) or bilateral  # slack cables are among the cases
    for q in range(len(p)):
        r, j, tq = np.empty(6), np.empty((6, 6)), np.empty(m)
        K._balance(a, b, g, EA, L0[q], p[q], R[q], force[q], moment[q], arm[q], bilateral, r, j,
                   tq, True, np.empty((m, K.CABLE_TERMS)))
        scale = np.abs(jac[q]).max()
        np.testing.assert_allclose(r, res[q], rtol=0, atol=1e-9 * max(1.0, np.abs(t[q]).max()))
        np.testing.assert_allclose(tq, t[q], rtol=0, atol=1e-9 * max(1.0, np.abs(t[q]).max()))
        np.testing.assert_allclose(j, jac[q], rtol=0, atol=1e-12 * scale)


def test_the_kernels_rotation_step_is_scipys():
    rng = np.random.default_rng(2)
    v = np.concatenate([rng.normal(size=(20, 3)), 1e-9 * rng.normal(size=(5, 3)),
                        np.zeros((1, 3))])
    for x in v:
        out = np.empty((3, 3))
        K._rotvec_matrix(x, out)
        np.testing.assert_allclose(out, Rotation.from_rotvec(x).as_matrix(), rtol=0, atol=1e-15)


@pytest.mark.parametrize("name", ROBOTS)
@pytest.mark.parametrize("spread", [1e-3, 3e-2])
def test_the_compiled_newton_is_the_numpy_newton(name, spread):
    """equilibrium_poses (compiled) and the numpy Newton it replaced: the same convergence
    flags, poses to 1e-9 m / rad, tensions to 1e-9 of the largest tension, from seeds 1 mm
    and 3 cm away, with slack cables and inertial wrenches."""
    robot, L0, p, R, force, moment, arm = _cases(name, 24, 7, spread)
    got = E.equilibrium_poses(robot, L0, p, R, force, moment, arm)
    ref = reference_equilibria(robot, L0, p, R, force, moment, arm)
    np.testing.assert_array_equal(got.ok, ref.ok)
    assert got.ok.sum() >= len(p) // 2
    ok = ref.ok
    np.testing.assert_allclose(got.p[ok], ref.p[ok], rtol=0, atol=1e-9)
    np.testing.assert_allclose(got.R[ok], ref.R[ok], rtol=0, atol=1e-9)
    np.testing.assert_allclose(got.tensions[ok], ref.tensions[ok], rtol=0,
                               atol=1e-9 * robot.tension_max.max())
    tol = E.EQUILIBRIUM_TOL * np.maximum(1.0, np.linalg.norm(force, axis=1))
    assert np.all(got.residual[ok] <= tol[ok])


@pytest.mark.skipif(aot.load(K) is None, reason="no ahead-of-time kernel built (make, or "
                                                "python -m cdh_planner.model.elastic_aot)")
@pytest.mark.parametrize("name", ["cogiro", "ipanema2"])
def test_the_aot_and_jit_kernels_agree_bit_for_bit(name, monkeypatch):
    robot, L0, p, R, force, moment, arm = _cases(name, 24, 7, 3e-2)
    monkeypatch.setattr(K, "equilibrium_kernel", aot.load(K)["equilibrium_kernel"])
    built = E.equilibrium_poses(robot, L0, p, R, force, moment, arm)
    monkeypatch.setattr(K, "equilibrium_kernel", K.jit_kernels()["equilibrium_kernel"])
    jit = E.equilibrium_poses(robot, L0, p, R, force, moment, arm)
    for field in ("p", "R", "tensions", "residual", "ok"):
        np.testing.assert_array_equal(getattr(built, field), getattr(jit, field))


def test_a_pose_the_cables_cannot_hold_is_not_converged():
    """Every cable far too long (all slack): no equilibrium, ok False, as numpy's."""
    robot, L0, p, R, force, moment, arm = _cases("cogiro", 3, 3)
    L0 = L0 * 1.5
    got = E.equilibrium_poses(robot, L0, p, R, force, moment, arm)
    ref = reference_equilibria(robot, L0, p, R, force, moment, arm)
    assert not got.ok.any() and not ref.ok.any()
