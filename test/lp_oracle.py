"""The independent oracle of the m-cable tests: a linear programme (scipy's HiGHS) asking
whether some tensions t_min <= t <= t_max hold a wrench, J t = w. The package never uses
it for its own answers (test_zonotope, test_more_cables_planning)."""

import numpy as np
from scipy.optimize import linprog

from cdh_planner import wrench as fz
from wrench_reference import facet_test
from cdh_planner.model.pose import rotation_tt


def lp_holds(J, w, robot):
    """True if some t with t_min <= t <= t_max has J t = w (HiGHS)."""
    res = linprog(np.zeros(J.shape[1]), A_eq=J, b_eq=w,
                  bounds=np.column_stack([robot.tension_min, robot.tension_max]), method="highs")
    assert res.status in (0, 2), res.message
    return res.status == 0


def pose_pieces(robot, p, tau=None, R=None):
    """J (N, 6, m), w0 (N, 6), L (N, 6, 6) and the facet test at the poses."""
    R = rotation_tt(tau) if R is None else R
    f = facet_test(robot, p, R=R)
    c = fz.load_point(robot, p, R)
    J = fz.screw_jacobian(robot, f.unit_vectors)
    L = np.broadcast_to(fz.inverse_ellipsoid_factor(robot, c), (len(p), 6, 6))
    return J, fz.nominal_wrench(robot, c), L, f


def ellipsoid_held(robot, p, R, rng, boundary=4):
    """Poses (p (N, 3) m, R (N, 3, 3)) at which the LP holds w0 and ``boundary`` random
    wrenches on the ellipsoid's boundary: a bool (N,)."""
    J, w0, L, _ = pose_pieces(robot, p, R=R)
    held = np.ones(len(p), dtype=bool)
    for q in range(len(p)):
        u = rng.normal(size=(boundary, 6))
        ws = np.vstack([w0[q], w0[q] + (L[q] @ (u / np.linalg.norm(u, axis=1, keepdims=True)).T).T])
        held[q] = all(lp_holds(J[q], w, robot) for w in ws)
    return held
