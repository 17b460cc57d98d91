"""Wrench feasibility of poses of any robot, the one entry its callers use: the closed form
(``feasibility.evaluate``) for six cables, the facet test (``zonotope.evaluate``) for more.
The facet test's compiled kernels are imported only for a robot that needs them, so that a
six-cable command loads no numba (test_startup_imports)."""

from .feasibility import evaluate


def feasibility_of(robot, p, tau=None, R=None):
    """Feasibility (``feasibility.Feasibility``) of poses: positions p (N, 3) m and either
    tau (N, 3) rad or R (N, 3, 3)."""
    if len(robot.base_anchors) == 6:
        return evaluate(robot, p, tau=tau, R=R)
    from .zonotope import evaluate as facet_test
    return facet_test(robot, p, tau=tau, R=R)
