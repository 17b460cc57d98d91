"""The closed-form wrench feasibility (paper Sec. 2, App. A) and the paper's examples."""
import dataclasses

import numpy as np
import pytest

from cdh_planner import wrench as fz
from cdh_planner.model.pose import rotation_tt
from cdh_planner.model.robot import load_robot
from cdh_planner.model.task import SliceTask, SphereTask
from cdh_planner.trajectory.path_check import check_task_motion

from conftest import CONFIG
from wrench_reference import ellipsoid_matrix
ROBOT1 = load_robot(CONFIG / "robot1.yaml")
ROBOT2 = load_robot(CONFIG / "robot2.yaml")
RNG = np.random.default_rng(7)

SLICE1 = SliceTask(fixed={"x": 0.0, "y": 0.0, "z": 0.35, "sigma": 17 * np.pi / 90})
Q_S, Q_G = (-2.3, 1.6), (1.7, 1.7)
SPHERE2 = SphereTask(center=(0.0, 0.0, 0.306), radius=0.13)
Q1, Q2, Q3 = (0.55, np.pi / 2), (0.55, 0.75), (2.63, 0.75)


def random_spd(n=6, cond=1e3):
    Q, _ = np.linalg.qr(RNG.normal(size=(n, n)))
    return Q @ np.diag(np.geomspace(1.0, cond, n)) @ Q.T


# A well-conditioned variant (E of order 1) to test the algebra to tight tolerances, the
# paper's robots (E up to 1e10) to test it where it is used.
GENERIC = dataclasses.replace(ROBOT2, ellipsoid_matrix=random_spd() * 50.0,
                              load_point=np.array([0.01, -0.02, 0.015]),
                              moment=np.array([0.01, 0.0, -0.02]))
ROBOTS = {"generic": GENERIC, "robot1": ROBOT1, "robot2": ROBOT2}


def random_poses(robot, n=40):
    """Random non-singular poses around the robots' workspace (not necessarily feasible)."""
    p = np.column_stack([RNG.uniform(-0.05, 0.05, n), RNG.uniform(-0.05, 0.05, n), RNG.uniform(0.25, 0.4, n)])
    tau = np.column_stack([RNG.uniform(-np.pi, np.pi, n), RNG.uniform(0, 0.6, n), RNG.uniform(-0.5, 0.5, n)])
    return p, tau


def pieces(robot, p, tau):
    """J, w0, E (in F1) and the evaluate() result for poses."""
    R = rotation_tt(tau)
    f = fz.wrench_feasibility(robot, p, R=R)
    J = fz.screw_jacobian(robot, f.unit_vectors)
    c = fz.load_point(robot, p, R)
    return J, fz.nominal_wrench(robot, c), ellipsoid_matrix(robot, c), f


@pytest.mark.parametrize("name", ROBOTS)
def test_nominal_tensions_balance_the_nominal_wrench(name):
    robot = ROBOTS[name]
    J, w0, _, f = pieces(robot, *random_poses(robot))
    assert not f.singular.any()
    np.testing.assert_allclose(np.einsum("nij,nj->ni", J, f.tension_nominal), w0, rtol=1e-9, atol=1e-12)


def test_jacobian_columns_are_unit_screws_about_the_base_origin():
    p, tau = random_poses(ROBOT2, 5)
    J, _, _, f = pieces(ROBOT2, p, tau)
    d = p[:, None, :] + np.einsum("nij,kj->nki", rotation_tt(tau), ROBOT2.platform_anchors) - ROBOT2.base_anchors
    np.testing.assert_allclose(f.lengths, np.linalg.norm(d, axis=-1))
    u = d / f.lengths[..., None]
    np.testing.assert_allclose(J[:, :3, :], np.swapaxes(u, 1, 2))
    np.testing.assert_allclose(J[:, 3:, :], np.swapaxes(np.cross(ROBOT2.base_anchors, u), 1, 2), atol=1e-15)


@pytest.mark.parametrize("name", ROBOTS)
def test_v_i_solves_paper_eqs_5_and_6_and_equals_the_spread(name):
    robot = ROBOTS[name]
    J, _, E, f = pieces(robot, *random_poses(robot))
    for n in range(J.shape[0]):
        Jinv = np.linalg.inv(J[n])
        B = J[n].T @ E[n] @ J[n]
        B_inv = Jinv @ np.linalg.inv(E[n]) @ Jinv.T
        for i in range(6):
            v = B_inv[:, i] / np.sqrt(B_inv[i, i])
            assert v @ B @ v == pytest.approx(1.0, rel=1e-6)  # Eq. 5
            rows = np.delete(B, i, axis=0)
            scale = np.abs(rows).max(axis=1) * np.abs(v).max()
            assert np.all(np.abs(rows @ v) <= 1e-6 * scale)  # Eq. 6
            assert v[i] > 0  # Eq. 7
            assert v[i] == pytest.approx(f.tension_spread[n, i], rel=1e-9)


def _sqrt_inv(E):
    """E^-1/2 (symmetric)."""
    lam, V = np.linalg.eigh(E)
    return V @ np.diag(lam ** -0.5) @ V.T


@pytest.mark.parametrize("name", ROBOTS)
def test_tensions_over_the_ellipsoid_boundary_stay_in_the_envelope_and_attain_it(name):
    robot = ROBOTS[name]
    J, w0, E, f = pieces(robot, *random_poses(robot, 15))
    for n in range(J.shape[0]):
        Jinv = np.linalg.inv(J[n])
        spread = f.tension_spread[n]
        # Sampled boundary: w = w0 + E^-1/2 n, |n| = 1.
        dirs = RNG.normal(size=(2000, 6))
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        w = w0[n] + dirs @ _sqrt_inv(E[n]).T
        dw = w - w0[n]
        np.testing.assert_allclose(np.einsum("ki,ij,kj->k", dw, E[n], dw), 1.0, rtol=1e-6)
        tensions = w @ Jinv.T
        tol = 1e-9 * np.abs(f.tension_nominal[n]).max() + 1e-6 * spread
        assert np.all(tensions >= f.tension_min[n] - tol)
        assert np.all(tensions <= f.tension_max[n] + tol)
        # The bounds are attained by w = w0 +- E^-1 J^-T e_i / sqrt(e_i^T J^-1 E^-1 J^-T e_i).
        E_inv = np.linalg.inv(E[n])
        for i in range(6):
            g = E_inv @ Jinv[i]
            step = g / np.sqrt(Jinv[i] @ g)
            for sign, bound in ((1, f.tension_max[n, i]), (-1, f.tension_min[n, i])):
                w_star = w0[n] + sign * step
                assert (sign * step) @ E[n] @ (sign * step) == pytest.approx(1.0, rel=1e-6)
                assert (Jinv @ w_star)[i] == pytest.approx(bound, rel=1e-7, abs=1e-7 * spread[i])


@pytest.mark.parametrize("name", ROBOTS)
def test_ellipsoid_transformation_matches_a_direct_computation_in_the_load_frame(name):
    robot = ROBOTS[name]
    p, tau = random_poses(robot, 10)
    R = rotation_tt(tau)
    c = fz.load_point(robot, p, R)
    np.testing.assert_allclose(c, p + R @ robot.load_point)
    E1 = ellipsoid_matrix(robot, c)
    w0_1 = fz.nominal_wrench(robot, c)
    E3 = robot.ellipsoid_matrix
    w0_3 = robot.wrench_center_local
    for n in range(len(p)):
        w = w0_1[n] + RNG.normal(size=(50, 6)) * np.sqrt(1.0 / np.diag(E3))
        # The same wrenches in F3: same force, moment about the load point c.
        w3 = np.concatenate([w[:, :3], w[:, 3:] - np.cross(c[n], w[:, :3])], axis=1)
        direct = np.einsum("ki,ij,kj->k", w3 - w0_3, E3, w3 - w0_3)
        via_f1 = np.einsum("ki,ij,kj->k", w - w0_1[n], E1[n], w - w0_1[n])
        np.testing.assert_allclose(via_f1, direct, rtol=1e-8)
    # The factor used by evaluate(): L L^T = E_F1^-1.
    L = fz.inverse_ellipsoid_factor(robot, c)
    np.testing.assert_allclose(L @ np.swapaxes(L, 1, 2) @ E1, np.broadcast_to(np.eye(6), E1.shape), atol=1e-6)


def test_base_frame_ellipsoid_is_used_as_given():
    robot = dataclasses.replace(GENERIC, ellipsoid_frame="base")
    p, tau = random_poses(robot, 5)
    c = fz.load_point(robot, p, rotation_tt(tau))
    np.testing.assert_allclose(ellipsoid_matrix(robot, c), np.broadcast_to(robot.ellipsoid_matrix, (5, 6, 6)))
    np.testing.assert_allclose(fz.nominal_wrench(robot, c), np.broadcast_to(robot.wrench_center_local, (5, 6)))


def test_singular_jacobian_is_infeasible_without_nan():
    # All platform anchors at P: every cable passes through P, so J has rank 3.
    robot = dataclasses.replace(ROBOT2, platform_anchors=np.zeros((6, 3)))
    p = np.array([[0.0, 0.0, 0.3], [0.01, 0.02, 0.25]])
    f = fz.wrench_feasibility(robot, p, tau=np.zeros((2, 3)))
    assert np.all(f.singular)
    assert not np.any(f.feasible)
    assert np.all(f.margin == -np.inf)
    assert not np.any(np.isnan(f.margin))
    assert list(f.binding) == ["singular", "singular"]
    assert np.all(np.abs(f.det_j) < fz.SINGULAR_DET)
    assert np.all(np.isfinite(f.lengths))


def test_singular_and_regular_poses_in_one_call():
    # Platform in the base plane: all cables horizontal, no vertical force possible.
    p = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.35]])
    f = fz.wrench_feasibility(ROBOT1, p, tau=np.zeros((2, 3)))
    assert list(f.singular) == [True, False]
    assert f.binding[0] == "singular" and f.binding[1] != "singular"
    assert np.isfinite(f.margin[1]) and np.all(np.isfinite(f.tension_nominal[1]))


def test_margins_name_the_binding_constraint():
    p, tau = random_poses(ROBOT2, 50)
    f = fz.wrench_feasibility(ROBOT2, p, tau)
    assert f.margins.shape == (50, 4, 6)
    flat = f.margins.reshape(50, -1)
    np.testing.assert_array_equal(f.margin, flat.min(axis=1))
    for n in range(50):
        k = int(np.argmin(flat[n]))
        assert f.binding[n] == f"{fz.CONSTRAINTS[k // 6]}[{k % 6 + 1}]"
    np.testing.assert_array_equal(f.feasible, f.margin > 0)


# --- The paper's examples (Sec. 5; SI units, moments in N mm as the README says) ----------

def _slice_poses(points):
    p, tau = SLICE1.pose(np.array(points))
    return p, tau


def test_robot1_start_and_goal_are_feasible_with_the_config_file():
    f = fz.wrench_feasibility(ROBOT1, *_slice_poses([Q_S, Q_G]))
    assert np.all(f.feasible)
    assert np.all((f.margin > 0.03) & (f.margin < 0.05))  # "a normalised margin of about 0.04"


def test_robot1_start_and_goal_are_not_feasible_with_plain_si_ellipsoid():
    robot = dataclasses.replace(ROBOT1, ellipsoid_matrix=1e4 * np.eye(6))
    f = fz.wrench_feasibility(robot, *_slice_poses([Q_S, Q_G]))
    assert not np.any(f.feasible)


def test_robot1_straight_segment_in_the_slice_leaves_c():
    (check,) = check_task_motion(ROBOT1, SLICE1, np.array([Q_S, Q_G]))
    assert not check.feasible


def test_robot2_task_points_are_feasible():
    p, tau = SPHERE2.pose(np.array([Q1, Q2, Q3]))
    f = fz.wrench_feasibility(ROBOT2, p, tau)
    assert np.all(f.feasible), f.binding


def test_robot2_q1_to_q2_straight_is_safe():
    (check,) = check_task_motion(ROBOT2, SPHERE2, np.array([Q1, Q2]))
    assert check.feasible and check.first_unsafe is None
    assert check.worst.margin > 0


def test_robot2_q2_to_q3_straight_leaves_c_early():
    (check,) = check_task_motion(ROBOT2, SPHERE2, np.array([Q2, Q3]))
    assert not check.feasible
    assert 0.0 < check.first_unsafe.s < 0.10
    assert check.first_unsafe.s == pytest.approx(0.043, abs=0.005)  # "after about 4 %"
    assert check.first_unsafe.margin <= 0


def test_a_large_batch_in_blocks_on_threads_is_the_one_call(monkeypatch):
    """closed_form cuts a batch of parallel.MIN_POSES poses or more into blocks on threads
    (numpy releases the GIL): every field bit for bit that of one call on one thread."""
    from cdh_planner import parallel
    from cdh_planner.wrench.closed_form import closed_form
    robot = load_robot(CONFIG / "robot2.yaml")
    rng = np.random.default_rng(12)
    n = parallel.MIN_POSES + 777
    p = rng.uniform(-0.1, 0.1, (n, 3)) + [0.0, 0.0, 0.3]
    R = rotation_tt(rng.uniform(-0.5, 0.5, (n, 3)) + [0.0, 0.5, 0.0])
    answers = {}
    for threads in ("1", "3"):
        monkeypatch.setenv("CDH_PLANNER_THREADS", threads)
        answers[threads] = closed_form(robot, p, R)
    assert 0 < answers["1"].feasible.sum() < n
    for f in dataclasses.fields(answers["1"]):
        np.testing.assert_array_equal(getattr(answers["1"], f.name), getattr(answers["3"], f.name))


def test_row_min_is_numpys_row_minimum():
    """``row_min`` (k - 1 minima of columns) gives a.min(axis=1)'s values, nan where a row
    holds one, for rows of 1 to 32 entries and a strided view (the facet test's tension
    rows); only a zero's sign may differ, which no comparison sees."""
    from cdh_planner.wrench.record import row_min
    rng = np.random.default_rng(2)
    for k in (1, 2, 3, 6, 8, 16, 32):
        a = rng.normal(size=(500, k))
        special = rng.random(a.shape) < 0.3
        a[special] = rng.choice([-np.inf, -0.0, 0.0, np.inf, np.nan], special.sum())
        expected = a.min(axis=1)
        got = row_min(a)
        np.testing.assert_array_equal(got, expected)  # nan == nan here; -0.0 == 0.0
        assert np.array_equal(got <= 0, expected <= 0) and np.array_equal(got > 0, expected > 0)
    margins = rng.normal(size=(300, 4, 8))
    view = margins[:, 2:, :].reshape(300, -1)
    assert np.shares_memory(view, margins)
    np.testing.assert_array_equal(row_min(view), view.min(axis=1))
