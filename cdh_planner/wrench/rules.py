"""Tension rules: how an m-cable robot shares a wrench among its cables (m > 6), as
registered classes (``RULES``, by name). The robot file chooses one (``robot.tension_rule``).

A rule is affine in the wrench at each pose: t(w) = t0 + P (w - w0), J P = I, so J t(w) = w.
It gives the nominal tensions t0 (published per waypoint) and over the wrench ellipsoid the
band t0 +- v, v_i = |row i of P L| (L L^T = E^-1). A rule declares ``name``,
``description`` and ``weights`` W (m,): its map is the weighted pseudo-inverse
P = W J^T (J W J^T)^-1 (``weighted_pseudo_inverse``, the one place P is written); its t0
is the weighted closed form's tensions toward the middle of the range,
t_mid + P (w0 - J t_mid), unless the class overrides ``tensions`` (the centred rule shifts
t0 in the null space of J). A new rule is one class here, decorated ``@register``.

Whatever the rule, elastic cables under length control share a wrench change by their
stiffness (``stiffness_band``), which replaces the band v. Six cables have one rule,
P = J^-1 (the package decides that case before asking a rule). Units: m, N, N m.
"""

import numpy as np

from ..errors import InputError
from .geometry import inverse_ellipsoid_factor, inverse_factor, nominal_wrench

RULES = {}  # name -> TensionRule instance
DEFAULT_RULE = "centred"


def register(cls):
    """Class decorator: add a rule (an instance of ``cls``) to RULES under ``cls.name``; a
    rule owes a name and ``weights`` (TypeError naming what is missing)."""
    missing = [what for what, ok in (("name", bool(cls.name)),
                                     ("weights", callable(getattr(cls, "weights", None))))
               if not ok]
    if missing:
        raise TypeError(f"tension rule {cls.__name__} lacks {', '.join(missing)}")
    RULES[cls.name] = cls()
    return cls


def rule_of(robot):
    """The TensionRule the robot file chose (``robot.tension_rule``)."""
    name = robot.tension_rule
    if name not in RULES:
        raise InputError("robot.tension_rule", name, f"expected one of {sorted(RULES)}")
    return RULES[name]


def weighted_pseudo_inverse(J, W):
    """P = W J^T (J W J^T)^-1, (N, m, 6), of J (N, 6, m) with positive weights W (m,) or
    (N, m): the least W^-1-weighted change of tension that holds a wrench change."""
    JW = J * np.asarray(W)[..., None, :]
    return np.swapaxes(np.linalg.solve(JW @ np.swapaxes(J, -1, -2), JW), -1, -2)


class TensionRule:
    """A tension rule (module docstring). Subclasses set ``name``, ``description`` and
    ``weights(robot)``: W (m,) of the map P = W J^T (J W J^T)^-1 (``register`` checks
    them); they may override ``tensions``."""

    name = ""
    description = ""

    def map(self, robot, J):
        """P (N, m, 6) at N poses with J (N, 6, m)."""
        return weighted_pseudo_inverse(J, self.weights(robot))

    def tensions(self, robot, J, c, ranked, centre):
        """t0 and v (N, m) N at poses with J (N, 6, m) and load points c (N, 3) m, where
        ``ranked`` (N,) (J of rank 6; elsewhere nan and inf). ``centre`` (N,): where the facet
        test holds (a rule may use it: the centred rule centres only there)."""
        n, m = J.shape[0], J.shape[2]
        t0, v = np.full((n, m), np.nan), np.full((n, m), np.inf)
        Jr, cr = J[ranked], c[ranked]
        P = self.map(robot, Jr)
        mid = 0.5 * (robot.tension_min + robot.tension_max)
        t0[ranked] = mid + np.einsum("nij,nj->ni", P, nominal_wrench(robot, cr) - Jr @ mid)
        v[ranked] = np.linalg.norm(P @ inverse_ellipsoid_factor(robot, cr), axis=-1)
        return t0, v


@register
class CentredRule(TensionRule):
    """The range-weighted pseudo-inverse (Pott, Bruckmann & Mikelsons 2009), W = D =
    diag(t_max - t_min)^2, with the centred nominal: the closed form's t0 shifted in the null
    space of J to the maximiser of s + CENTRE_MU sum log(slacks - s), s the least band
    slack (unique and smooth in the pose; docs/more-cables.md). Compiled (``centred``)."""

    name = "centred"
    description = ("range-weighted pseudo-inverse P = D J^T (J D J^T)^-1, D = diag(t_max - "
                   "t_min)^2; nominal centred in the null space of J within the limits")

    def weights(self, robot):
        return (robot.tension_max - robot.tension_min) ** 2

    def tensions(self, robot, J, c, ranked, centre):
        # the compiled kernels: imported on first use (six-cable commands never need them)
        from .compiled import centred_batch
        return centred_batch(J, c, robot.wrench_center_local, inverse_factor(robot),
                             robot.ellipsoid_frame == "load", robot.tension_min,
                             robot.tension_max, ranked, centre)


def stiffness_band(robot, J, c, t0, lengths, v):
    """The band v (N, m) N under length control of elastic cables: a wrench change dw moves
    the tensions of cables held at their lengths by P_K dw, P_K = K J^T (J K J^T)^-1,
    K = diag(EA / L0) = diag((EA + t0) / L) at the nominal t0 (N, m) N and lengths (N, m) m,
    whatever rule chose t0; over the ellipsoid that is +- |rows of P_K L| (L L^T = E^-1 at
    the load points c (N, 3) m; inf where J K J^T is singular). J (N, 6, m). Compiled
    (``compiled.stiffness_band_batch``: ``weighted_pseudo_inverse``'s algebra one pose at a
    time, to rounding). Rigid cables (no ``robot.cable_stiffness``), six cables (P_K = J^-1
    = P, whatever K: kept exact rather than rounded) and poses where t0 is not finite:
    ``v`` unchanged."""
    if robot.cable_stiffness is None or J.shape[-1] == 6:
        return v
    ok = np.all(np.isfinite(t0), axis=1)
    if not ok.any():
        return v
    from .compiled import stiffness_band_batch
    K = np.ones_like(t0)  # weights of the poses not ``ok`` are not read
    K[ok] = (robot.cable_stiffness + t0[ok]) / lengths[ok]
    band = stiffness_band_batch(J, c, robot.wrench_center_local, inverse_factor(robot),
                                robot.ellipsoid_frame == "load", K, ok)
    return np.where(ok[:, None], band, v)


STIFFNESS_ITERATIONS = 30   # linearised projections at most
STIFFNESS_TOL = 1e-6        # of the largest eigenvalue: a least one this close below kappa meets it


def least_stiffness(robot):
    """kappa (N/m, N m/rad): the least eigenvalue of the platform's stiffness
    (``model.elastic.platform_stiffness``) that a nominal of elastic cables keeps:
    ``robot.least_stiffness``, else 0 (a stable equilibrium: one that is not cannot be
    executed)."""
    return 0.0 if robot.least_stiffness is None else float(robot.least_stiffness)


def _within_reach(robot, t, shift):
    """The largest a in [0, 1] (M,) that keeps t + a shift (M, m) N within one tension range
    of the limits (tension_min - range .. tension_max + range): a nominal the shift takes
    further is outside the limits either way (its band too), and a far shift would reach
    tensions that stretch elastic cables beyond any meaning (robot2_8: 1e13 N)."""
    span = robot.tension_max - robot.tension_min
    lo, hi = robot.tension_min - span, robot.tension_max + span
    with np.errstate(divide="ignore", invalid="ignore"):
        room = np.where(shift > 0, (hi - t) / shift, np.where(shift < 0, (lo - t) / shift, np.inf))
    return np.clip(np.min(room, axis=1), 0.0, 1.0)


def stiff_nominal(robot, p, R, J, t0, where=None):
    """The nominal tensions t0 (N, m) N at poses (p (N, 3) m, R (N, 3, 3), J (N, 6, m))
    moved least (Euclidean, in N) within the null space of J (the same wrench J t0) so that
    elastic cables held at the lengths that carry them leave the platform at least
    ``least_stiffness`` stiff: the least eigenvalue of K(t) (``platform_stiffness``) at
    least kappa. Where the rule's t0 already is, it is kept (bit for bit). The least
    eigenvalue of K, affine in t, is concave in t: the stiff set is convex and its nearest
    point unique (continuous along a path). Found by projecting onto the tangent half-space
    of lambda_min = kappa (gradient v^T K_a v, v its eigenvector) until met, at most
    STIFFNESS_ITERATIONS times (a pose no shift makes stiff ends wherever that leaves it;
    its band then usually leaves the limits), each shift cut where it leaves the limits by
    a whole range (``_within_reach``: that pose is outside the domain). Rigid cables, six
    cables, poses where t0 is not finite, poses outside ``where`` (N,) bool (None: all; the
    facet test's infeasible poses, which no nominal makes feasible and whose shift can be
    unbounded) and poses whose stiffness is not finite: t0 unchanged. The elastic platform otherwise has a soft
    mode there (a tilt of CoGiRo where the centred nominal turns), or an unstable
    equilibrium."""
    m = J.shape[-1]
    if robot.cable_stiffness is None or m == 6:
        return t0
    from ..model.elastic import platform_stiffness, soft_poses
    kappa = least_stiffness(robot)
    ok = np.all(np.isfinite(t0), axis=1)
    if where is not None:
        ok &= where
    # compiled, decided by Cholesky; a pose it calls soft within rounding of kappa is kept
    # as it is below (its first projection finds it within STIFFNESS_TOL): the same t0
    soft = soft_poses(robot, p, R, t0, ok, kappa)
    if not soft.any():
        return t0
    p, R, t = p[soft], R[soft], t0[soft]
    N = np.linalg.svd(J[soft])[2][:, 6:, :]                     # (M, k, m): null(J), orthonormal
    K0 = platform_stiffness(robot, p, R, t)
    Ka = np.stack([platform_stiffness(robot, p, R, t + N[:, a]) - K0
                   for a in range(m - 6)], axis=1)              # (M, k, 6, 6): exact (affine)
    z = np.zeros((len(t), m - 6))
    tol = STIFFNESS_TOL * np.linalg.eigvalsh(K0)[:, -1]         # of the stiffest mode (kappa may be 0)
    todo = np.arange(len(t))                                    # poses not yet stiff enough
    for _ in range(STIFFNESS_ITERATIONS):
        lam, vec = np.linalg.eigh(K0[todo] + np.einsum("na,naij->nij", z[todo], Ka[todo]))
        short = lam[:, 0] < kappa - tol[todo]
        todo, lam, v = todo[short], lam[short, 0], vec[short, :, 0]
        if not todo.size:
            break
        g = np.einsum("ni,naij,nj->na", v, Ka[todo], v)         # d lambda_min / dz
        gg = np.maximum(np.sum(g * g, axis=1), 1e-300)
        # the nearest point of {y: lambda + g . (y - z) >= kappa}, a little inside
        need = np.sum(g * z[todo], axis=1) + kappa + tol[todo] - lam
        target = g * (need / gg)[:, None]
        step = _within_reach(robot, t[todo], np.einsum("na,nai->ni", target, N[todo]))
        z[todo] = target * step[:, None]
        todo = todo[step >= 1.0]  # the others left the limits' reach: out of the domain
    t0 = t0.copy()
    t0[soft] = t + np.einsum("na,nai->ni", z, N)
    return t0
