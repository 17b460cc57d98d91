"""Newton's step on a chart by F_x's structure (manifold/kernels.py ``block_solve``,
``TaskConstraint.solve``) against LAPACK's dense solve of the same system: F_x's
dependent columns are block lower triangular where ``navigation_blocks`` says (each
block of variables a function of the pose and the blocks before it), the step equals the
dense one to 1e-12 of its size, and without that structure (a task's rows, a dense matrix,
a zero pivot) the dense solve answers."""

import numpy as np
import pytest

from cdh_planner import aot
from cdh_planner.atlas.charts import Atlas
from cdh_planner.manifold import kernels
from cdh_planner.manifold.constraint import TaskConstraint
from cdh_planner.parsing.problem import load_problem

from conftest import CONFIG


def _systems(problem, count=12, seed=0):
    """(constraint, [(A, rhs)]): Newton's systems [F_x; basis^T] at points a chart's
    tangent step away from the start and goal, as ``Atlas.newton`` builds them."""
    pr = load_problem(CONFIG / "problems" / f"{problem}.yaml")
    c = TaskConstraint(pr.robot, pr.task)
    atlas = Atlas(c, radius=0.5)
    rng = np.random.default_rng(seed)
    out = []
    for k in range(count):
        pose = (pr.start, pr.goal)[k % 2]
        x0 = c.lift(pose.p, pose.tau)
        basis = atlas.tangent_basis(x0)
        x = x0 + basis @ rng.normal(scale=0.3, size=c.dim)
        F, Fx = c.residual_and_jacobian(x)
        A = np.vstack([Fx, basis.T])
        out.append((A, rng.normal(size=c.n_vars)))
    return c, out


@pytest.mark.parametrize("problem", ["robot2_q2_q3_free_flight", "robot2_q2_q3_ball"])
def test_free_flight_jacobian_has_the_blocks(problem):
    """Right of each diagonal block of F_x's dependent columns every entry is zero."""
    c, systems = _systems(problem)
    blocks = kernels.navigation_blocks()
    p = c.n_vars - blocks[-1]
    for A, _ in systems:
        for r0, r1 in zip(blocks[:-1], blocks[1:]):
            assert not np.any(A[r0:r1, p + r1:])
            assert np.any(A[r0:r1, p + r0:p + r1])  # the block itself is there


@pytest.mark.parametrize("problem", ["robot2_q2_q3_free_flight", "robot2_q2_q3_ball"])
def test_the_block_step_is_the_dense_step(problem):
    c, systems = _systems(problem)
    for A, rhs in systems:
        x, ok = kernels.block_solve(A, rhs, kernels.navigation_blocks())
        assert ok
        dense = np.linalg.solve(A, rhs)
        np.testing.assert_allclose(x, dense, rtol=0, atol=1e-12 * np.abs(dense).max())
        np.testing.assert_allclose(A @ x, rhs, rtol=0, atol=1e-10 * np.abs(rhs).max())
        np.testing.assert_array_equal(c.solve(A, rhs), x)


def test_without_the_structure_the_dense_solve_answers():
    """A dense matrix (entries right of a block), a singular block: not ok, and the
    constraint's solve is LAPACK's, bit for bit (LinAlgError where singular)."""
    c, systems = _systems("robot2_q2_q3_free_flight", count=2)
    A, rhs = systems[0]
    dense = A.copy()
    dense[0, -1] = 1e-3
    assert not kernels.block_solve(dense, rhs, kernels.navigation_blocks())[1]
    np.testing.assert_array_equal(c.solve(dense, rhs), np.linalg.solve(dense, rhs))
    singular = A.copy()
    singular[:, 6:24] = 0.0  # the d block and every column of d
    assert not kernels.block_solve(singular, rhs, kernels.navigation_blocks())[1]
    with pytest.raises(np.linalg.LinAlgError):
        c.solve(singular, rhs)


@pytest.mark.parametrize("problem", ["robot1_qs_qg", "robot2_q1_q2"])
def test_a_task_with_its_own_rows_solves_densely(problem):
    """Tasks with equations of their own (Robot 1's slices, Robot 2's orientation slices):
    LAPACK's step, bit for bit."""
    c, systems = _systems(problem, count=4)
    for A, rhs in systems:
        np.testing.assert_array_equal(c.solve(A, rhs), np.linalg.solve(A, rhs))


@pytest.mark.skipif(aot.load(kernels) is None, reason="no ahead-of-time kernel built (make, or "
                                                      "python -m cdh_planner.manifold.aot)")
def test_aot_and_jit_block_solve_agree_bit_for_bit():
    _, systems = _systems("robot2_q2_q3_free_flight", count=6)
    built, jit = aot.load(kernels)["block_solve"], kernels.jit_kernels()["block_solve"]
    for A, rhs in systems:
        xa, oka = built(A, rhs, kernels.navigation_blocks())
        xj, okj = jit(A, rhs, kernels.navigation_blocks())
        assert oka and okj
        np.testing.assert_array_equal(xa, xj)
