"""The navigation manifold, its task constraints, and the atlas' charts and polytopes."""

import numpy as np
import pytest
from scipy.spatial import HalfspaceIntersection

from cdh_planner.atlas.charts import Atlas
from cdh_planner.atlas.polytope import Polytope
from cdh_planner.wrench import wrench_feasibility
from cdh_planner.manifold.constraint import TaskConstraint
from cdh_planner.manifold.navigation import I_G, I_V, N_EQS, N_VARS, NavigationManifold
from cdh_planner.model.robot import load_robot
from cdh_planner.model.task import FreeTask, SliceTask, SphereTask

from conftest import CONFIG
ROBOT1 = load_robot(CONFIG / "robot1.yaml")
ROBOT2 = load_robot(CONFIG / "robot2.yaml")
SIGMA1 = 17 * np.pi / 90
SLICE1 = SliceTask(fixed={"x": 0.0, "y": 0.0, "z": 0.35, "sigma": SIGMA1})
SPHERE2 = SphereTask(center=(0.0, 0.0, 0.306), radius=0.13)
SPHERE2_FREE = SphereTask(center=(0.0, 0.0, 0.306), radius=0.13, free_torsion=True)
Q_S = (np.array([0.0, 0.0, 0.35]), np.array([-2.3, 1.6, SIGMA1]))
Q2 = tuple(a[0] for a in SPHERE2.pose(np.array([[0.55, 0.75]])))

CASES = {  # robot, task, a feasible pose on the task
    "robot1-slice": (ROBOT1, SLICE1, Q_S),
    "robot2-sphere": (ROBOT2, SPHERE2, Q2),
    "robot2-sphere-sigma": (ROBOT2, SPHERE2_FREE, Q2),
    "robot2-free": (ROBOT2, FreeTask(), Q2),
}


def fd_jacobian(fun, x, h=1e-7):
    f0 = fun(x)
    J = np.empty((f0.size, x.size))
    for k in range(x.size):
        e = np.zeros_like(x)
        e[k] = h
        J[:, k] = (fun(x + e) - fun(x - e)) / (2 * h)
    return J


@pytest.mark.parametrize("robot", [ROBOT1, ROBOT2], ids=["robot1", "robot2"])
def test_lift_is_on_the_manifold_and_on_the_right_branch(robot):
    nav = NavigationManifold(robot)
    p, tau = Q_S if robot is ROBOT1 else Q2
    X = nav.lift(p, tau)
    F, _ = nav.residual_and_jacobian(X)
    assert X.shape == (N_VARS,) and F.shape == (N_EQS,)
    assert np.max(np.abs(F / np.r_[nav.equation_scale()])) < 1e-10
    f = wrench_feasibility(robot, p[None], tau[None])
    G = X[I_V:I_G].reshape(6, 6)
    vdiag = np.linalg.norm(G, axis=1)
    assert np.all(vdiag > 0)
    np.testing.assert_allclose(vdiag, f.tension_spread[0], rtol=1e-9)
    np.testing.assert_allclose(X[30:36], f.tension_nominal[0], rtol=1e-9)
    # slacks encode the margins: finite, and exp(slack / kappa) is the normalised margin
    assert np.all(np.isfinite(X[I_G:]))
    assert 0 < nav.min_margin(X) < 1


def test_lift_refuses_an_infeasible_pose():
    nav = NavigationManifold(ROBOT2)
    with pytest.raises(ValueError, match="not wrench-feasible"):
        nav.lift(np.array([0.0, 0.0, 0.9]), np.zeros(3))  # cables longer than 0.6 m


@pytest.mark.parametrize("case", CASES)
def test_jacobian_matches_finite_differences(case):
    robot, task, (p, tau) = CASES[case]
    c = TaskConstraint(robot, task)
    x = c.lift(p, tau)
    F, J = c.residual_and_jacobian(x)
    assert np.max(np.abs(F)) < 1e-9
    Jfd = fd_jacobian(lambda y: c.residual_and_jacobian(y)[0], x)
    err = np.max(np.abs(J - Jfd)) / max(1.0, np.max(np.abs(J)))
    assert err < 1e-6
    # full row rank on M (paper App. B): the manifold is smooth with dimension n
    assert np.linalg.matrix_rank(J) == J.shape[0]
    assert c.dim == {"robot1-slice": 2, "robot2-sphere": 2, "robot2-sphere-sigma": 3,
                     "robot2-free": 6}[case]


@pytest.mark.parametrize("case", CASES)
def test_tangent_basis_is_orthonormal_and_in_the_kernel(case):
    robot, task, (p, tau) = CASES[case]
    c = TaskConstraint(robot, task)
    atlas = Atlas(c, radius=0.1)
    x = c.lift(p, tau)
    B = atlas.tangent_basis(x)
    _, J = c.residual_and_jacobian(x)
    assert B.shape == (c.n_vars, c.dim)
    np.testing.assert_allclose(B.T @ B, np.eye(c.dim), atol=1e-12)
    assert np.max(np.abs(J @ B)) < 1e-10


@pytest.mark.parametrize("case", CASES)
def test_newton_projection_converges_from_chart_points(case):
    robot, task, (p, tau) = CASES[case]
    c = TaskConstraint(robot, task)
    atlas = Atlas(c, radius=0.1)
    i = atlas.add_chart(c.lift(p, tau))
    rng = np.random.default_rng(3)
    for _ in range(5):
        s = rng.normal(size=c.dim)
        s *= 0.05 / np.linalg.norm(s)
        x = atlas.psi(i, s)
        assert x is not None
        F, _ = c.residual_and_jacobian(x)
        assert np.max(np.abs(F)) < 1e-8
        np.testing.assert_allclose(atlas.coordinates(i, x), s, atol=1e-9)
        # a feasible pose on the task (residual: arccos resolves angles to ~1e-8)
        pp, tt = c.pose(x)
        assert wrench_feasibility(robot, pp[None], tt[None]).feasible[0]
        assert float(np.max(task.residual(pp[None], tt[None]))) < 1e-6 if hasattr(task, "residual") else True


def test_charts_on_theta_zero_and_across_phi_pi():
    """theta = 0 is a domain bound (tilt-and-torsion is singular there) and phi wraps."""
    c = TaskConstraint(ROBOT1, SLICE1)
    atlas = Atlas(c, radius=0.1)
    x0 = c.lift(np.array([0, 0, 0.35]), np.array([-2.3, 0.0, SIGMA1]))
    i = atlas.add_chart(x0)
    assert atlas.in_domain(x0)
    for _ in range(20):
        atlas.expand(i)
    thetas = [c.pose(ch.x)[1][1] for ch in atlas.charts]
    assert min(thetas) >= 0.0
    a = c.lift(np.array([0, 0, 0.35]), np.array([np.pi - 0.01, 0.4, SIGMA1]))
    b = c.lift(np.array([0, 0, 0.35]), np.array([-np.pi + 0.01, 0.4, SIGMA1]))
    assert np.linalg.norm(atlas.diff(a, b)) < 0.1  # 0.02 rad apart in phi, not 2 pi


@pytest.mark.parametrize("n", [2, 3, 4, 6])
def test_polytope_clipping_matches_qhull(n):
    rng = np.random.default_rng(n)
    for _ in range(10):
        P = Polytope(n, 1.0)
        halfspaces = [np.r_[e, -1.0] for e in np.vstack([np.eye(n), -np.eye(n)])]
        for _ in range(10):
            a = rng.normal(size=n)
            a /= np.linalg.norm(a)
            beta = rng.uniform(0.3, 1.0)
            P.clip(a, beta)
            halfspaces.append(np.r_[a, -beta])
        ref = HalfspaceIntersection(np.array(halfspaces), np.zeros(n)).intersections
        ref = np.unique(np.round(ref, 7), axis=0)
        got = np.unique(np.round(P.vertices, 7), axis=0)
        # every true vertex is found, and every vertex kept satisfies every half-space
        for v in ref:
            assert np.min(np.linalg.norm(got - v, axis=1)) < 1e-6
        H = np.array(halfspaces)
        assert np.all(P.vertices @ H[:, :-1].T + H[:, -1] <= 1e-9)


def test_scalar_rotation_derivatives_match_the_vectorised_ones():
    from navigation_reference import rotation_and_derivatives
    from cdh_planner.model.pose import rotation_tt, rotation_tt_derivatives
    for tau in np.random.default_rng(5).uniform(-3, 3, (10, 3)):
        R, dR = rotation_and_derivatives(tau)
        np.testing.assert_allclose(R, rotation_tt(tau), atol=1e-14)
        np.testing.assert_allclose(dR, rotation_tt_derivatives(tau), atol=1e-14)
