"""The route's faster forms give the numbers of the plain ones, bit for bit: Newton's
projection onto M (``Atlas.newton``) against the reference loop, the free-flight
constraint without the task's empty rows against the stacked form, a link's points with
its middle projected (and checked against the domain) first against all in order, and
``Validity``'s remembered quaternions against the conversion itself."""

import math

import numpy as np
import pytest

from cdh_planner.atlas.charts import Atlas
from cdh_planner.manifold.constraint import TaskConstraint
from cdh_planner.model.pose import quaternion_from_tau
from cdh_planner.model.task import FreeTask
from cdh_planner.pipeline.validity import CollisionFreeDomain, Validity
from cdh_planner.planner import Planner

from test_manifold import CASES, ROBOT2, Q2
from test_scene_domain import PROBLEM


def reference_newton(atlas, x0, basis, s_target, x_start):
    """psi in its plain form: Newton on [F(x); basis^T (x - x0) - s] = 0, the system stacked
    afresh each step, every test on the whole vector (the reference the loop must equal)."""
    x = x_start.copy()
    with np.errstate(all="ignore"):
        for _ in range(atlas.newton_iters):
            F, Fx = atlas.c.residual_and_jacobian(x)
            rhs = np.concatenate([F, basis.T @ atlas.diff(x0, x) - s_target])
            if not np.isfinite(rhs).all():
                return None
            if np.abs(rhs).max() < atlas.newton_tol:
                return x
            try:
                step = np.linalg.solve(np.vstack([Fx, basis.T]), rhs)
            except np.linalg.LinAlgError:
                return None
            if not np.isfinite(step).all():
                return None
            x = x - step
        F = atlas.c.residual_and_jacobian(x)[0]
    return x if np.isfinite(F).all() and np.abs(F).max() < 1e3 * atlas.newton_tol else None


@pytest.mark.parametrize("case", CASES)
def test_newton_is_the_reference_loop(case):
    """Near and far (some diverge, some leave the domain): the same point or both None."""
    robot, task, pose = CASES[case]
    constraint = TaskConstraint(robot, task)
    atlas = Atlas(constraint, radius=0.5)
    ch = atlas.charts[atlas.add_chart(constraint.lift(*pose))]
    steps = np.random.default_rng(7).normal(size=(36, constraint.dim))
    steps /= np.linalg.norm(steps, axis=1, keepdims=True)
    outcomes = set()
    for s in steps * np.repeat([0.0, 0.05, 0.3, 1.0, 3.0, 30.0], 6)[:, None]:
        got = atlas.psi(ch.index, s)
        want = reference_newton(atlas, ch.x, ch.basis, s, ch.x + ch.basis @ s)
        assert (got is None) == (want is None)
        assert got is None or np.array_equal(got, want)
        outcomes.add(got is None)
    assert outcomes == {True, False}  # both ends of the loop were taken


def test_free_flight_constraint_is_the_stacked_form():
    c = TaskConstraint(ROBOT2, FreeTask())
    assert c._navigation_only
    x = c.lift(*Q2)
    rng = np.random.default_rng(1)
    for k in range(5):
        xk = x + 0.05 * k * rng.normal(size=x.size)
        F, J = c.residual_and_jacobian(xk)
        c._navigation_only = False
        F0, J0 = c.residual_and_jacobian(xk)
        c._navigation_only = True
        assert np.array_equal(F, F0) and np.array_equal(J, J0)


def grown_atlas():
    """The atlas of the ball problem after its plan (charts on both sides of the ball)."""
    planner = Planner(PROBLEM.robot, PROBLEM.task, PROBLEM.settings, scene=PROBLEM.scene)
    assert planner.plan(PROBLEM.start, PROBLEM.goal).success
    assert isinstance(planner.atlas.c, CollisionFreeDomain)
    return planner.atlas


def reference_edge_points(atlas, a, b, spacing=0.25):
    """Atlas._edge_points with every point projected in order, then the domain of all."""
    gap = np.linalg.norm(atlas.diff(atlas.charts[a].x, atlas.charts[b].x))
    n = max(3, int(math.ceil(gap / (spacing * atlas.radius))) + 1)
    pts = atlas.segment(a, b, n)
    if pts is None or not atlas._all_in_domain(pts):
        return None
    steps = [np.linalg.norm(atlas.diff(u, v)) for u, v in zip(pts, pts[1:])]
    return pts if max(steps) <= 3.0 * gap / (n - 1) + 1e-12 else None


def test_link_points_middle_first_are_the_points_in_order():
    """Every pair of overlapping charts of an atlas around an obstacle: the same points,
    or None for both (links through the ball among them)."""
    atlas = grown_atlas()
    seen = set()
    for a, ca in enumerate(atlas.charts):
        for b in range(a + 1, len(atlas.charts)):
            cb = atlas.charts[b]
            if np.linalg.norm(atlas.diff(ca.x, cb.x)) >= ca.radius + cb.radius:
                continue
            got, want = atlas._edge_points(a, b, 0.25), reference_edge_points(atlas, a, b)
            assert (got is None) == (want is None), (a, b)
            if got is not None:
                assert all(np.array_equal(u, v) for u, v in zip(got, want))
            seen.add(got is None)
    assert seen == {True, False}


def test_remembered_quaternions_are_the_conversion():
    v = Validity(PROBLEM.robot, PROBLEM.task, PROBLEM.settings.margin_floor, PROBLEM.scene)
    rng = np.random.default_rng(3)
    taus = rng.uniform(-np.pi, np.pi, (40, 3))
    for rows in (taus[:2], taus[1:3], taus[:40], taus[[5, 5, 7]], taus[:1]):
        assert np.array_equal(v._quaternions(rows), quaternion_from_tau(rows))
