"""Wrench feasibility of poses of any robot, the one entry its callers use: the closed form
(``feasibility.evaluate``) for six cables, the facet test (``zonotope.evaluate``) for more.
The facet test's compiled kernels are imported only for a robot that needs them, so that a
six-cable command loads no numba (test_startup_imports).

The planner asks ``planning_feasibility``: for m > 6 a pose is valid when the published
tension rule's band t0 +- v (``zonotope``) lies within the limits, which also proves the
ellipsoid inside the zonotope (docs/more-cables.md, "Planning with m > 6 cables"); for six
cables it is the closed form itself.
"""

import numpy as np

from .feasibility import evaluate


def feasibility_of(robot, p, tau=None, R=None):
    """Feasibility (``feasibility.Feasibility``) of poses: positions p (N, 3) m and either
    tau (N, 3) rad or R (N, 3, 3)."""
    if len(robot.base_anchors) == 6:
        return evaluate(robot, p, tau=tau, R=R)
    from .zonotope import evaluate as facet_test
    return facet_test(robot, p, tau=tau, R=R)


def planning_feasibility(robot, p, tau=None, R=None):
    """What the planner asks of poses (p (N, 3) m, tau (N, 3) rad or R (N, 3, 3)): for six
    cables ``feasibility.evaluate``; for more, ``zonotope.band_feasibility``: ``margin``
    and ``binding`` those of the centred tension rule's band and the lengths, the least of
    ``margins`` (N, 4, m), named as the closed form names them ("tension_max[3]"), -inf
    where singular. Positive iff the band t0 +- v is within the limits, which implies the
    facet test's feasibility (so the facet test itself is not run)."""
    if len(robot.base_anchors) == 6:
        return evaluate(robot, p, tau=tau, R=R)
    from .zonotope import band_feasibility
    return band_feasibility(robot, p, tau=tau, R=R)


def nominal_tensions(robot, p, R):
    """The nominal tensions (N, m) N at poses (p (N, 3) m, R (N, 3, 3)): the closed form's
    f0 for six cables, the centred rule's t0 for more (``zonotope.rule_tensions``: no facet
    test, for poses on a planned motion)."""
    if len(robot.base_anchors) == 6:
        return evaluate(robot, p, R=R).tension_nominal
    from .zonotope import rule_tensions
    return rule_tensions(robot, p, R)[0]


def tension_map(robot, J):
    """The tension rule at N poses as an affine map of the wrench, t(w) = t0 + P (w - w0):
    P (N, m, 6), the range-weighted pseudo-inverse D J^T (J D J^T)^-1 (``zonotope``'s rule;
    J^-1 for six cables), from J (N, 6, m), so that callers that add an inertial wrench to
    w0 (dynamic timing, the executed check) move the tensions as the published rule does."""
    if J.shape[-1] == 6:
        return np.linalg.inv(J)
    D = (robot.tension_max - robot.tension_min) ** 2
    JD = J * D
    G = JD @ np.swapaxes(J, -1, -2)
    return np.swapaxes(np.linalg.solve(G, JD), -1, -2)
