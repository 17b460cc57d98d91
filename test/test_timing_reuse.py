"""Work the dynamic timing and the executed check no longer do twice, and the numbers they
still give bit for bit: the dynamic timing's J^-1 reused for the rule's tensions
(``rule_tensions(..., inverted=...)``), and the executed check's rotation between two
samples of its stencil computed once for the sample before and the one after
(``_stencil_turns``)."""

import numpy as np
import pytest

from conftest import PROBLEMS
from cdh_planner.model.robot import load_robot
from cdh_planner.parsing.problem import load_problem
from cdh_planner.planner import Planner
from cdh_planner.ports import Rotation
from cdh_planner.trajectory import dynamics as D, executed
from cdh_planner.trajectory.dynamics import _Geometry, _terms
from cdh_planner.wrench import cable_vectors, rule_tensions, screw_jacobian, tension_map


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


def _inverted(robot, p, R):
    d = cable_vectors(robot, p, R)
    L = np.linalg.norm(d, axis=-1)
    J = screw_jacobian(robot, d / L[..., None])
    return L, J, tension_map(robot, J)


@pytest.mark.parametrize("robot_file", ["robot2.yaml", "robot1.yaml"])
def test_rule_tensions_from_the_callers_inverse_are_the_same_bits(robot_file):
    robot = load_robot(PROBLEMS.parent / robot_file)
    p, R = _poses(robot)
    inverted = _inverted(robot, p, R)
    for inertial in (None, np.random.default_rng(1).normal(size=(len(p), 6))):
        old = rule_tensions(robot, p, R, inertial)
        new = rule_tensions(robot, p, R, inertial, inverted=inverted)
        for a, b in zip(old, new):
            assert np.array_equal(a, b, equal_nan=True)


def test_a_singular_pose_stays_nan_and_inf_with_the_callers_inverse():
    robot = load_robot(PROBLEMS.parent / "robot2.yaml")
    p, R = _poses(robot, n=4)
    L, J, J_inv = _inverted(robot, p, R)
    L[1, 2] = 0.0  # a cable of no length: singular whatever J^-1 says
    f0, v = rule_tensions(robot, p, R, inverted=(L, J, J_inv))
    assert np.all(np.isnan(f0[1])) and np.all(np.isinf(v[1]))
    assert np.array_equal(f0[[0, 2, 3]], rule_tensions(robot, p[[0, 2, 3]], R[[0, 2, 3]])[0])


def test_the_timing_terms_invert_j_once_and_give_the_rules_tensions(ball, monkeypatch):
    robot, path = ball
    geo = _Geometry(robot, path)
    s = np.linspace(0.0, geo.length, 500)
    calls = []
    inv = np.linalg.inv
    monkeypatch.setattr(np.linalg, "inv", lambda a: calls.append(len(a)) or inv(a))
    _, _, _, f0, v, _, _ = _terms(robot, geo, s, robot.mass, robot.inertia)
    assert calls == [len(s)]  # the tension map's; the rule's tensions reuse it
    monkeypatch.undo()
    p, _, _, R, _, _ = geo.at(s)
    old_f0, old_v = rule_tensions(robot, p, R)
    assert np.array_equal(f0, old_f0) and np.array_equal(v, old_v)


def _old_turns(R, need, mid, q):
    """The executed check's turns as computed before: each stencil side on its own."""
    at = [np.searchsorted(need, mid + o) for o in (-q, 0, q)]
    Rs = [R[i] for i in at]
    back = Rotation.from_matrix(np.swapaxes(Rs[1], 1, 2) @ Rs[2]).as_rotvec()
    front = Rotation.from_matrix(np.swapaxes(Rs[0], 1, 2) @ Rs[1]).as_rotvec()
    return front, back


@pytest.mark.parametrize("sparse", [False, True])
def test_stencil_turns_are_the_same_bits_and_computed_once(ball, sparse, monkeypatch):
    robot, path = ball
    q, n = executed.PHASES, 2000
    ts = np.linspace(path.t[0], path.t[-1], n + 1)
    mid = np.arange(q, n + 1 - q)
    if sparse:  # a ``within`` check: a few runs of samples
        mid = mid[(mid % 400 < 30) | (mid % 977 == 5)]
    need = executed.unique_sorted(np.concatenate([mid - q, mid, mid + q]))
    _, R = executed.path_seed(path)(ts[need])
    rows = []
    from_matrix = Rotation.from_matrix.__func__
    monkeypatch.setattr(Rotation, "from_matrix",
                        classmethod(lambda cls, m: rows.append(len(m)) or from_matrix(cls, m)))
    front, back = executed._stencil_turns(R, need, mid, q)
    assert rows == [len(executed.unique_sorted(np.concatenate([mid - q, mid])))]
    if not sparse:
        assert rows[0] == len(mid) + q  # half the 2 len(mid) of one per side
    monkeypatch.undo()
    old_front, old_back = _old_turns(R, need, mid, q)
    assert np.array_equal(front, old_front) and np.array_equal(back, old_back)
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
