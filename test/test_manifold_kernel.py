"""The compiled kernel (manifold/kernels.py) against the numpy reference of F and F_X.

Compared in the atlas' dimensionless units (rows over NavigationManifold.equation_scale,
columns times variable_scale, as TaskConstraint sees them): F to 1e-12 of max(1, |F_i|),
each row of F_X to 1e-12 of that row's largest entry. Entries that are round-off of a
cancellation (F ~ 1e-14 on the manifold, some F_X entries ~ 1e-17) have no meaningful
relative error on their own; measured against the size of their equation they do.
"""
from dataclasses import replace

import numpy as np
import pytest

from cdh_planner.parsing.problem import load_problem
from cdh_planner.manifold.navigation import N_EQS, N_VARS, NavigationManifold

from conftest import CONFIG
from navigation_reference import residual_and_jacobian_reference
PROBLEMS = {"robot1": "robot1_qs_qg", "robot2": "robot2_q2_q3_free_flight"}
RTOL = 1e-12


def random_lifted_points(robot_name, count=4, seed=0):
    """(robot, [X ...]): lifted points near the problem's start and goal, random feasible poses."""
    pr = load_problem(CONFIG / "problems" / f"{PROBLEMS[robot_name]}.yaml")
    nav = NavigationManifold(pr.robot)
    rng = np.random.default_rng(seed)
    points, tries = [], 0
    while len(points) < count:
        tries += 1
        assert tries < 200, "no feasible random pose found"
        pose = (pr.start, pr.goal)[len(points) % 2]
        p = pose.p + rng.normal(scale=0.01, size=3)
        tau = pose.tau + rng.normal(scale=0.05, size=3)
        try:
            points.append(nav.lift(p, tau))
        except ValueError:
            continue
    return pr.robot, points


def assert_same(nav, X):
    rs, vs = nav.equation_scale(), nav.variable_scale()
    F, Jx = nav.residual_and_jacobian(X)
    Fr, Jr = residual_and_jacobian_reference(nav, X)
    assert F.shape == (N_EQS,) and Jx.shape == (N_EQS, N_VARS)
    F, Fr = F / rs, Fr / rs
    Jx, Jr = Jx / rs[:, None] * vs, Jr / rs[:, None] * vs
    assert np.all(np.abs(F - Fr) <= RTOL * np.maximum(1.0, np.abs(Fr)))
    row_size = np.max(np.abs(Jr), axis=1, keepdims=True)
    assert np.all(row_size > 0)
    assert np.all(np.abs(Jx - Jr) <= RTOL * row_size)
    # the residual-only path returns the same F and no Jacobian
    F2, none = nav.residual_and_jacobian(X, jacobian=False)
    assert none is None
    np.testing.assert_array_equal(F2 / rs, F)


@pytest.mark.parametrize("robot_name", ["robot1", "robot2"])
def test_kernel_equals_reference_at_lifted_points(robot_name):
    robot, points = random_lifted_points(robot_name)
    nav = NavigationManifold(robot)
    for X in points:
        assert_same(nav, X)


@pytest.mark.parametrize("robot_name", ["robot1", "robot2"])
def test_kernel_equals_reference_off_the_manifold(robot_name):
    """Near but off M (F clearly nonzero): every term of F and F_X is exercised."""
    robot, points = random_lifted_points(robot_name, seed=1)
    nav = NavigationManifold(robot)
    rng = np.random.default_rng(2)
    for X in points:
        Y = X * (1.0 + 1e-2 * rng.normal(size=X.size))
        assert np.max(np.abs(nav.residual(Y) / nav.equation_scale())) > 1e-4
        assert_same(nav, Y)


@pytest.mark.parametrize("robot_name", ["robot1", "robot2"])
def test_kernel_equals_reference_with_the_ellipsoid_in_the_base_frame(robot_name):
    """Both shipped robots use the load frame F3; the base frame F1 skips the c-terms."""
    robot, points = random_lifted_points(robot_name, count=2, seed=3)
    nav = NavigationManifold(replace(robot, ellipsoid_frame="base"))
    assert not nav.load_frame
    for X in points:
        assert_same(nav, X)
        assert_same(nav, X * 1.001)


def test_kernel_accepts_views_and_rejects_wrong_shapes():
    robot, (X,) = random_lifted_points("robot2", count=1)
    nav = NavigationManifold(robot)
    padded = np.concatenate([X, [0.3, -0.2]])  # a task constraint's x carries task variables
    F, Jx = nav.residual_and_jacobian(padded[:N_VARS])
    np.testing.assert_array_equal(F, nav.residual_and_jacobian(X)[0])
    strided = np.repeat(X, 2)[::2]  # not contiguous
    np.testing.assert_array_equal(nav.residual_and_jacobian(strided)[1], Jx)
    with pytest.raises(ValueError, match="shape"):
        nav.residual_and_jacobian(padded)
