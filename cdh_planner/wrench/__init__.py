"""Wrench feasibility: can the cables hold every wrench of the ellipsoid at a pose, and
with which tensions. This module is the package's one entry (test_layers checks that no
other package imports its modules). Units: m, N, N m; poses as positions p (N, 3) m and
either tau (N, 3) rad or R (N, 3, 3).

Entries, one test each:
- ``wrench_feasibility``: the exact test, the wrench ellipsoid inside the zonotope of the
  wrenches the cables can hold. Six cables: the paper's closed form (``closed_form``); more:
  the facet test (``facets``, compiled), a ``WrenchFeasibility``. What ``verify``, the
  slices, the workspace study and the live state report. ``wrench_margin``: its margin and
  binding alone (for more than six cables without the tension rule: the dense motion check).
- ``band_feasibility``: what the planner asks. Six cables: the closed form; more: the
  robot's tension rule's band t0 +- v within the limits (which implies the facet test, so
  that is not run). ``band_margin``: its margin alone (the atlas's domain test).
- ``rule_tensions``: the rule's nominal tensions t0 and band v at poses (no facet test),
  optionally under an inertial wrench; ``rule_responses``: t0, v and P w for given wrenches
  (the trajectory's per-sample tensions); ``tension_map``: the rule's P, t(w) = t0 + P (w - w0).
- ``stiffness_band``: the band of elastic cables under length control, whatever the rule.
- ``stiff_nominal``: the rule's t0 of elastic cables moved least in the null space of J so
  that the platform stays at least ``least_stiffness`` stiff (m > 6; every t0 the package
  gives, so the domain's band is that of a stiff nominal).
- ``RULES`` / ``TensionRule``: the tension rules (``rules``), chosen by ``robot.tension_rule``.
Six cables have one rule, P = J^-1: ``_six_cables`` is the one place that case is decided.

The facet test (maths: docs/more-cables.md). The wrenches m cables can hold form the
zonotope Z = {J t : t_min <= t <= t_max} (J is 6 x m, column i = [u_i; a_i x u_i]). Its
facets lie on the hyperplanes spanned by 5 independent columns: for each 5-subset S of rank
5, c is orthogonal to the columns in S and both signs of n = c / |c| are facet normals with
support value h(n) = sum_i max(n.J_i t_min_i, n.J_i t_max_i). The wrench ellipsoid
{w0 + L u : |u| <= 1} (L L^T = E^-1 in the base frame) lies in Z iff for every such n
    s(n) = h(n) - n.w0 - |L^T n| >= 0      (hyperplane shifting; Bouchard et al. 2010).
``margin_newtons`` is min s(n) (N, or N m: n mixes force and moment rows); the normalised
margin divides each slack by Z's width along n, h(n) + h(-n) = sum_i |n.J_i| (t_max_i -
t_min_i), before the minimum. With m = 6 the facet test is the paper's closed form and the
normalised margin its margin, exactly.

Tensions are not unique when m > 6. The envelope published per cable comes from a rule a
winch controller can run, affine in the wrench at each pose (``rules``): over the
ellipsoid its tensions are exactly t0 +- v, v_i = |row i of P L|; a controller applies t0
(published per waypoint) plus P (w - w0). The rule may leave [t_min, t_max] at a pose Z
holds (an affine rule is a stronger demand than Z containing the ellipsoid):
``tension_status`` then says "rule_exceeds_limits". With elastic cables
(``robot.cable_stiffness``) under length control the cables' stiffness, not the rule,
shares a wrench change: the band is |rows of P_K L|, P_K = K J^T (J K J^T)^-1,
K = diag(EA / L0) at t0 (``stiffness_band``).

The compiled kernels (``compiled``: built ahead of time by ``make``, else numba's JIT) are
imported on first use by an m > 6 robot, or by a six-cable robot's ``rule_responses`` (the
trajectory's tensions at thousands of samples); built ahead of time, no command loads numba
for them (test_startup_imports). They release the GIL: from ``parallel.MIN_POSES`` poses a
batch runs in blocks on threads, with the same numbers.
"""

import numpy as np

from ..model.pose import rotation_tt
from .closed_form import closed_form
from .geometry import (cable_vectors, inverse_ellipsoid_factor, inverse_factor, load_point,
                       nominal_wrench, screw_jacobian, skew)
from .record import (CONSTRAINTS, SINGULAR_DET, STATUS_EXCEEDS, STATUS_INFEASIBLE, STATUS_OK,
                     STATUS_SINGULAR, Feasibility, Margin, WrenchFeasibility)
from .rules import (DEFAULT_RULE, RULES, TensionRule, least_stiffness, register, rule_of,
                    stiff_nominal, stiffness_band)

__all__ = ["wrench_feasibility", "wrench_margin", "band_feasibility", "band_margin",
           "rule_tensions", "rule_responses", "tension_map", "stiffness_band", "stiff_nominal", "least_stiffness",
           "RULES", "DEFAULT_RULE", "TensionRule", "register", "Feasibility", "WrenchFeasibility",
           "Margin", "CONSTRAINTS", "SINGULAR_DET", "STATUS_OK", "STATUS_EXCEEDS",
           "STATUS_INFEASIBLE", "STATUS_SINGULAR", "cable_vectors", "screw_jacobian", "load_point",
           "nominal_wrench", "inverse_ellipsoid_factor", "skew"]


def _six_cables(robot):
    """The one place the six-cable case is decided: J square, the paper's closed form, the
    one rule P = J^-1."""
    return len(robot.base_anchors) == 6


def _poses(p, tau, R):
    """p (N, 3) and R (N, 3, 3) as float arrays, R from tau (N, 3) rad if not given."""
    p = np.atleast_2d(np.asarray(p, dtype=float))
    if R is None:
        R = rotation_tt(np.atleast_2d(tau))
    return p, np.asarray(R, dtype=float).reshape(-1, 3, 3)


def wrench_feasibility(robot, p, tau=None, R=None):
    """The exact test (module docstring) of poses: a ``Feasibility`` (six cables) or a
    ``WrenchFeasibility`` (more)."""
    p, R = _poses(p, tau, R)
    if _six_cables(robot):
        return closed_form(robot, p, R)
    from .facets import facet_test  # compiled kernels: m > 6 only
    return facet_test(robot, p, R)


def wrench_margin(robot, p, tau=None, R=None):
    """``wrench_feasibility``'s ``margin`` and ``binding`` of poses, the same numbers: six
    cables the closed form's record; more a ``Margin``, without the tension rule's band
    (the facet test alone; the rule cost as much again)."""
    p, R = _poses(p, tau, R)
    if _six_cables(robot):
        return closed_form(robot, p, R)
    from .facets import facet_margin  # compiled kernels: m > 6 only
    return facet_margin(robot, p, R)


def band_feasibility(robot, p, tau=None, R=None):
    """What the planner asks of poses (module docstring), a ``Feasibility``: for more than six
    cables ``margin`` and ``binding`` those of the rule's band and the lengths, the least
    of ``margins`` (N, 4, m), named as the closed form names them ("tension_max[3]"), -inf
    where singular."""
    p, R = _poses(p, tau, R)
    if _six_cables(robot):
        return closed_form(robot, p, R)
    from .facets import band_feasibility as band
    return band(robot, p, R)


def band_margin(robot, p, tau=None, R=None):
    """``band_feasibility(...).margin`` (N,) alone (for m > 6 without building the record)."""
    p, R = _poses(p, tau, R)
    if _six_cables(robot):
        return closed_form(robot, p, R).margin
    from .facets import band_margin as margin
    return margin(robot, p, R)


def rule_tensions(robot, p, R, inertial=None):
    """The rule's tensions t (N, m) N holding w0 - ``inertial`` (N, 6) (None: w0, t = t0)
    and its band v (N, m) N at poses (p (N, 3) m, R (N, 3, 3)), without the facet test:
    t0 - P inertial (``rule_responses``; J^-1 (w0 - inertial) for six cables, to rounding).
    nan / inf where singular."""
    p, R = _poses(p, None, R)
    if inertial is None:
        return rule_responses(robot, p, R, np.zeros((len(p), 0, 6)))[:2]
    t0, v, change = rule_responses(robot, p, R, np.asarray(inertial, dtype=float)[:, None, :])
    return t0 - change[:, 0], v


def rule_responses(robot, p, R, wrenches):
    """The rule at poses (p (N, 3) m, R (N, 3, 3)): its nominal tensions t0 (N, m) N, band
    v (N, m) N and the tension changes P w (N, K, m) N of the K wrenches ``wrenches``
    (N, K, 6) of each pose (``tension_map``: t(w0 + w) = t0 + P w). Six cables: J^-1 applied
    by one LU factorisation per pose, compiled (``compiled.six_cable_batch``; its numpy
    reference is ``closed_form``'s envelope); more: t0 centred at every pose
    (``facets.band_tensions``) and P = ``tension_map``. nan / inf where singular."""
    p, R = _poses(p, None, R)
    if _six_cables(robot):
        from .compiled import six_cable_batch
        t0, v, change, _ = six_cable_batch(
            p, R, robot.base_anchors, robot.platform_anchors, robot.load_point,
            robot.wrench_center_local, inverse_factor(robot), robot.ellipsoid_frame == "load",
            wrenches, SINGULAR_DET)
        return t0, v, change
    from .facets import band_tensions
    t0, v = band_tensions(robot, p, R)
    if wrenches.shape[1] == 0:
        return t0, v, np.zeros(wrenches.shape[:2] + (t0.shape[1],))
    u = cable_vectors(robot, p, R)
    u /= np.linalg.norm(u, axis=-1)[..., None]
    P = tension_map(robot, screw_jacobian(robot, u))
    return t0, v, np.einsum("nij,nkj->nki", P, wrenches)


def tension_map(robot, J):
    """The rule as an affine map of the wrench at N poses, t(w) = t0 + P (w - w0):
    P (N, m, 6) from J (N, 6, m) (J^-1 for six cables), so that callers that add an
    inertial wrench to w0 (dynamic timing, the executed check) move the tensions as the
    published rule does."""
    if _six_cables(robot):
        return np.linalg.inv(J)
    return rule_of(robot).map(robot, J)
