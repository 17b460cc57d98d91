"""Work the dynamic timing and the executed check no longer do twice, and the numbers they
still give: the six-cable rule's tensions, band and tension rates in one compiled pass
(``wrench.rule_responses``, against closed_form's numpy inverse to rounding), and the
executed check's rotation between two samples of its stencil computed once for the sample
before and the one after (``_stencil_turns``, compiled: the port's numbers to 1e-15 rad)."""

import numpy as np
import pytest

from conftest import PROBLEMS
from cdh_planner.model.robot import load_robot
from cdh_planner.parsing.problem import load_problem
from cdh_planner.planner import Planner
from cdh_planner.ports import Rotation
from cdh_planner.trajectory import dynamics as D, executed
from cdh_planner.trajectory.dynamics import _Geometry, _terms
import importlib

from cdh_planner.wrench import rule_responses, rule_tensions

CF = importlib.import_module("cdh_planner.wrench.closed_form")  # the numpy reference


@pytest.fixture(scope="module")
def ball():
    problem = load_problem(PROBLEMS / "robot2_q2_q3_ball.yaml")
    result = Planner(problem.robot, problem.task, problem.settings,
                     scene=problem.scene).plan(problem.start, problem.goal)
    assert result.success
    return problem.robot, result.path


def _poses(robot, n=300, seed=0):
    """Poses around the middle of the robot's anchors, some far enough to be singular or
    infeasible (nan / inf rows must come out the same too)."""
    rng = np.random.default_rng(seed)
    centre = np.mean(robot.base_anchors, axis=0)
    p = centre + rng.normal(scale=0.2, size=(n, 3))
    R = Rotation.from_rotvec(rng.normal(scale=0.6, size=(n, 3))).as_matrix()
    return p, R


def _reference(robot, p, R, W):
    """The six-cable rule by numpy: closed_form's J^-1 (LAPACK) and envelope, J^-1 W, and
    where singular."""
    _, _, _, J_inv, c, singular = CF.inverse_jacobian(robot, p, R)
    t0, v = CF._envelope(robot, J_inv, c)
    return t0, v, np.einsum("nij,nkj->nki", J_inv, W), singular


@pytest.mark.parametrize("robot_file", ["robot2.yaml", "robot1.yaml"])
def test_the_compiled_six_cable_rule_is_the_numpy_closed_form(robot_file):
    """rule_responses (one LU per pose, compiled) against closed_form's LAPACK inverse: the
    same tensions, band and J^-1 W to rounding (1e-9 of their scale), nan / inf at the
    same singular poses (robot2's ellipsoid in the load frame, robot1's in the base frame)."""
    robot = load_robot(PROBLEMS.parent / robot_file)
    p, R = _poses(robot)
    p[:2], R[:2] = [0.0, 0.0, 0.05], np.eye(3)  # platform in a plane parallel to the base
    p[:2, 2] = robot.base_anchors[0, 2] - robot.platform_anchors[0, 2]  # anchors': singular
    W = np.random.default_rng(1).normal(size=(len(p), 3, 6))
    t0, v, change = rule_responses(robot, p, R, W)
    r_t0, r_v, r_change, singular = _reference(robot, p, R, W)
    assert singular[:2].all() and not singular.all()
    ok = ~singular
    assert np.all(np.isnan(t0[singular])) and np.all(np.isinf(v[singular]))
    assert np.all(np.isnan(change[singular]))
    for a, b in ((t0, r_t0), (v, r_v), (change, r_change)):
        scale = np.max(np.abs(b[ok]), axis=tuple(range(1, b.ndim)), keepdims=True)
        assert np.all(np.abs(a[ok] - b[ok]) <= 1e-9 * scale)


def test_rule_tensions_under_a_wrench_are_t0_minus_its_change():
    robot = load_robot(PROBLEMS.parent / "robot2.yaml")
    p, R = _poses(robot)
    inertial = np.random.default_rng(2).normal(size=(len(p), 6))
    t0, v, change = rule_responses(robot, p, R, inertial[:, None, :])
    t, v_t = rule_tensions(robot, p, R, inertial)
    assert np.array_equal(t, t0 - change[:, 0], equal_nan=True) and np.array_equal(v, v_t)
    assert np.array_equal(rule_tensions(robot, p, R)[0], t0, equal_nan=True)


def test_a_cable_of_no_length_is_singular():
    robot = load_robot(PROBLEMS.parent / "robot2.yaml")
    p, R = _poses(robot, n=3)
    p[1] = robot.base_anchors[2] - R[1] @ robot.platform_anchors[2]  # cable 2 of length 0
    t0, v, _ = rule_responses(robot, p, R, np.zeros((3, 0, 6)))
    assert np.all(np.isnan(t0[1])) and np.all(np.isinf(v[1]))


def test_the_timing_terms_invert_nothing_and_give_the_rules_tensions(ball, monkeypatch):
    """_terms: the rule's t0, v and the rates of its tensions (P A, P B) in one compiled pass
    (no LAPACK inverse), t0 and v those of rule_tensions, bit for bit."""
    robot, path = ball
    geo = _Geometry(robot, path)
    s = np.linspace(0.0, geo.length, 500)
    calls = []
    inv = np.linalg.inv
    monkeypatch.setattr(np.linalg, "inv", lambda a: calls.append(len(a)) or inv(a))
    _, _, _, f0, v, a_f, b_f = _terms(robot, geo, s, robot.mass, robot.inertia)
    assert calls == []
    monkeypatch.undo()
    p, _, _, R, _, _ = geo.at(s)
    old_f0, old_v = rule_tensions(robot, p, R)
    assert np.array_equal(f0, old_f0) and np.array_equal(v, old_v)
    assert np.all(np.isfinite(a_f)) and np.all(np.isfinite(b_f)) and np.max(np.abs(a_f)) > 0


def _old_turns(R, need, mid, q):
    """The executed check's turns as computed before: each stencil side on its own."""
    at = [np.searchsorted(need, mid + o) for o in (-q, 0, q)]
    Rs = [R[i] for i in at]
    back = Rotation.from_matrix(np.swapaxes(Rs[1], 1, 2) @ Rs[2]).as_rotvec()
    front = Rotation.from_matrix(np.swapaxes(Rs[0], 1, 2) @ Rs[1]).as_rotvec()
    return front, back


@pytest.mark.parametrize("sparse", [False, True])
def test_stencil_turns_are_the_ports_and_computed_once(ball, sparse, monkeypatch):
    """Each turn once (the compiled ``turns``), and the port's Rotation's numbers to 1e-15
    rad."""
    robot, path = ball
    q, n = executed.PHASES, 2000
    ts = np.linspace(path.t[0], path.t[-1], n + 1)
    mid = np.arange(q, n + 1 - q)
    if sparse:  # a ``within`` check: a few runs of samples
        mid = mid[(mid % 400 < 30) | (mid % 977 == 5)]
    need = executed.unique_sorted(np.concatenate([mid - q, mid, mid + q]))
    _, R = executed.path_seed(path)(ts[need])
    rows = []
    turns = executed.turns
    monkeypatch.setattr(executed, "turns", lambda R, a, b: rows.append(len(a)) or turns(R, a, b))
    front, back = executed._stencil_turns(R, need, mid, q)
    assert rows == [len(executed.unique_sorted(np.concatenate([mid - q, mid])))]
    if not sparse:
        assert rows[0] == len(mid) + q  # half the 2 len(mid) of one per side
    monkeypatch.undo()
    old_front, old_back = _old_turns(R, need, mid, q)
    assert np.allclose(front, old_front, rtol=0, atol=1e-15)
    assert np.allclose(back, old_back, rtol=0, atol=1e-15)
    assert np.max(np.abs(front)) > 0  # the path turns: the comparison is not of zeros


def test_the_limit_curve_is_solved_when_asked_and_is_the_same(ball, monkeypatch):
    """toppra's feasible sets (two LPs per gridpoint) are solved only when ``limit`` is
    read (a picture), not per plan: the same numbers as solving them right after the
    parameterization, as the timing did before."""
    robot, path = ball
    TOPPRA = D.toppra.algorithm.TOPPRA
    calls, eager = [], []

    class Counting(TOPPRA):
        def compute_parameterization(self, *args, **kwargs):
            out = super().compute_parameterization(*args, **kwargs)
            eager.append(TOPPRA.compute_feasible_sets(self).copy())  # what was done before
            return out

        def compute_feasible_sets(self):
            calls.append(1)
            return super().compute_feasible_sets()

    monkeypatch.setattr(D.toppra.algorithm, "TOPPRA", Counting)
    timing = D.dynamic_timing(robot, path, robot.mass, robot.inertia, 0.05, 0.2)
    assert timing.feasible and calls == []
    limit = timing.limit
    assert calls == [1]
    assert np.array_equal(limit, np.sqrt(np.maximum(eager[-1][:, 1], 0.0)))
    assert np.all(limit >= timing.sd - 1e-9)  # the timing's s' stays under its limit curve


def test_the_wrench_constraint_given_once_times_as_per_gridpoint(ball, monkeypatch):
    """The wrench constraint's F is one matrix for every gridpoint (``identical``: toppra's
    seidel wrapper forms F a, F b, F c in one product): the timing, its limit curve and the
    timed path are bit for bit those of the same F handed to toppra per gridpoint."""
    robot, path = ball
    fast = D.dynamic_timing(robot, path, robot.mass, robot.inertia, 0.05, 0.2)

    class PerGridpoint(D._WrenchConstraint):
        def __init__(self, *args):
            super().__init__(*args)
            self.identical = False

        def compute_constraint_params(self, path, gridpoints, *args, **kwargs):
            a, b, c, F, g, ubound, xbound = super().compute_constraint_params(path, gridpoints)
            assert F.ndim == 2
            return a, b, c, np.broadcast_to(F, (len(a),) + F.shape).copy(), g, ubound, xbound

    monkeypatch.setattr(D, "_WrenchConstraint", PerGridpoint)
    reference = D.dynamic_timing(robot, path, robot.mass, robot.inertia, 0.05, 0.2)
    assert fast.feasible and reference.feasible
    assert fast.duration == reference.duration and fast.slowdown == reference.slowdown
    for name in ("s", "sd", "limit"):
        assert np.array_equal(getattr(fast, name), getattr(reference, name)), name
    assert np.array_equal(fast.path.t, reference.path.t)
    assert np.array_equal(fast.path.p, reference.path.p)
