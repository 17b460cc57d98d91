"""The navigation manifold M (paper Sec. 3): F(x) = 0 holds exactly on wrench-feasible poses.

Physical variables X (90, SI units), in this order:
    p (3, m) | tau (3, rad) | d_1..d_6 cable vectors (18, m) | lengths l (6, m) |
    f0 (6, N) | G (36, N, row-major) | g (6) | s (6) | t (6)
followed by the task's variables (e.g. the sphere's alpha1, alpha2). Equations, in order:
    (1) d_i - (p + R b_i - a_i) = 0                       18
    (2) l_i^2 - d_i . d_i = 0                              6
    (4) J f0 - w0 = 0                                      6
    (5-6) P J G - I = 0                                   36
    (10) mu_l,i = exp(g_i / kappa)   length margin         6
    (11) mu_f-,i = exp(s_i / kappa)  lower tension margin  6
    (12) mu_f+,i = exp(t_i / kappa)  upper tension margin  6
with normalised margins mu_l = (l - dmin)(dmax - l) / ((dmax - dmin) / 2)^2,
mu_f- = (f0_i - v_ii - fmin) / (fmax - fmin), mu_f+ = (fmax - f0_i - v_ii) / (fmax - fmin).

Eqs. 5-6 are restated (same solution set in the pose, same count: 36 variables, 36
equations). With E = P^T P in the base frame (P = L3^T e(c), E3 = L3 L3^T constant in F3)
the tensions over the ellipsoid are f = f0 + G z, |z| <= 1, G = (P J)^-1, so the paper's
v_ii = |row i of G|. The paper's v_i solve B v_i = e_i / v_ii with B = J^T E J, whose
condition number is that of E squared (1e6 for the paper's robots): its v_i swing fast with
the pose and Newton from a chart's tangent space diverges at any useful radius. P J G = I
is bilinear and as well conditioned as J: charts can be about 10x larger.

Eqs. 10-12 are the paper's slack equations in logarithmic form: mu = exp(g / kappa) has
the same solution set as the paper's mu g' = 1 (both force mu > 0) and its derivative in
the slack never vanishes, so F_x keeps full rank on M (paper App. B). The log form makes
charts shrink geometrically, not harmonically, towards the boundary of C, so a lower bound
on the slacks (a margin floor mu >= exp(slack_min / kappa)) bounds the atlas.

The atlas sees scaled variables x = X / scale, so one chart radius is meaningful: lengths
over the platform radius, tensions over the tension range, angles in radians, slacks as is.
"""


import numpy as np

from ..wrench import wrench_feasibility
from ..model.pose import rotation_tt
from .layout import I_D, I_F, I_G, I_L, I_P, I_S, I_T, I_TAU, I_V, N_EQS, N_VARS  # noqa: F401  (re-exported)
KAPPA = 0.1  # default slack scale kappa (see NavigationManifold)


class NavigationManifold:
    """F(X) and F_X(X) of the robot's navigation manifold in physical variables."""

    def __init__(self, robot, kappa=KAPPA):
        self.robot = robot
        self.kappa = float(kappa)
        self.a = robot.base_anchors
        self.b = robot.platform_anchors
        self.g_load = robot.load_point
        self.load_frame = robot.ellipsoid_frame == "load"
        self.w_local = robot.wrench_center_local
        self.E3 = robot.ellipsoid_matrix
        self.half_range_l = (robot.length_max - robot.length_min) / 2.0
        self.range_f = robot.tension_max - robot.tension_min
        self.length_ref = float(np.mean(np.linalg.norm(self.b, axis=1))) or 0.1
        self.tension_ref = float(np.mean(self.range_f))
        self.L3T = np.linalg.cholesky(self.E3).T  # E3 = L3 L3^T
        self._kernel = self._kernel_params = None  # see _load_kernel

    def _load_kernel(self):
        """The compiled F, F_X (kernels.py), imported on the first evaluation, not with this
        module: importing numba and loading the cached machine code cost about 0.4 s, which
        processes that never evaluate F (problem checks, direct motions) need not pay."""
        from .kernels import navigation_residual_and_jacobian, pack_parameters
        r = self.robot
        self._kernel_params = pack_parameters(
            self.a, self.b, self.g_load, self.w_local, self.L3T, r.length_min, r.length_max,
            r.tension_min, r.tension_max, self.kappa, self.load_frame)
        self._kernel = navigation_residual_and_jacobian

    # ----- scaling -------------------------------------------------------------------
    def variable_scale(self):
        """Physical units per scaled unit for each of the 90 variables.

        Position in platform radii (moving by one is like turning by 1 rad), angles in
        radians. The 18 + 6 cable coordinates and 6 + 36 tension coordinates are functions
        of the pose; they get coarser units (4 and 2 platform radii; 3 and 2 tension
        ranges) so that the pose keeps about 60 % of a tangent vector's length and the
        chart radius reads roughly as radians of platform motion. Slacks are unscaled.
        """
        s = np.ones(N_VARS)
        s[I_P:I_TAU] = self.length_ref
        s[I_D:I_L] = 4.0 * self.length_ref
        s[I_L:I_F] = 2.0 * self.length_ref
        s[I_F:I_V] = 3.0 * self.tension_ref
        s[I_V:I_G] = 2.0 * self.tension_ref
        return s

    def equation_scale(self):
        """Divisors that make each equation dimensionless (rows of F)."""
        r = np.ones(N_EQS)
        r[0:18] = self.length_ref
        r[18:24] = self.length_ref ** 2
        r[24:27] = self.tension_ref
        r[27:30] = self.tension_ref * self.length_ref
        return r

    # ----- pieces ----------------------------------------------------------------------
    def _wrench_and_factor(self, c):
        """w0(c) in the base frame and P(c) = L3^T e(c), so that E_base = P^T P."""
        w0 = self.w_local.copy()
        if not self.load_frame:
            return w0, self.L3T
        w0[3:] += _cross(c, self.w_local[:3])
        e = np.eye(6)
        e[3:, :3] = -_skew3(c)
        return w0, self.L3T @ e

    def margins(self, l, f0, vdiag):
        r = self.robot
        mu_l = (l - r.length_min) * (r.length_max - l) / self.half_range_l ** 2
        mu_lo = (f0 - vdiag - r.tension_min) / self.range_f
        mu_hi = (r.tension_max - f0 - vdiag) / self.range_f
        return mu_l, mu_lo, mu_hi

    # ----- F and F_X -------------------------------------------------------------------
    def residual(self, X):
        return self.residual_and_jacobian(X, jacobian=False)[0]

    def residual_and_jacobian(self, X, jacobian=True):
        """F(X) (84,) and F_X(X) (84, 90) in physical units (F_X None if not ``jacobian``).

        The compiled kernel (kernels.py, numba); test/navigation_reference.py holds the same
        computation in numpy, the reference the kernel is tested against.
        """
        X = np.ascontiguousarray(X, dtype=np.float64)
        if X.shape != (N_VARS,):  # the kernel does not bounds-check
            raise ValueError(f"expected X of shape ({N_VARS},), got {X.shape}")
        if self._kernel is None:
            self._load_kernel()
        F, Jx = self._kernel(X, self._kernel_params, bool(jacobian))
        return F, (Jx if jacobian else None)

    # ----- lifting -----------------------------------------------------------------------
    def lift(self, p, tau):
        """The point X on M above a feasible pose (p m, tau rad); ValueError if infeasible."""
        p, tau = np.asarray(p, dtype=float), np.asarray(tau, dtype=float)
        fz = wrench_feasibility(self.robot, p[None], tau[None])
        if not fz.feasible[0]:
            raise ValueError(f"pose is not wrench-feasible (binding {fz.binding[0]}, margin {fz.margin[0]:.3g})")
        R = rotation_tt(tau)
        d = p + self.b @ R.T - self.a
        l = np.linalg.norm(d, axis=1)
        J = np.concatenate([d, np.cross(self.a, d)], axis=1).T / l
        c = p + R @ self.g_load
        w0, P = self._wrench_and_factor(c)
        f0 = np.linalg.solve(J, w0)
        G = np.linalg.inv(P @ J)
        mu_l, mu_lo, mu_hi = self.margins(l, f0, np.linalg.norm(G, axis=1))
        return np.concatenate([p, tau, d.ravel(), l, f0, G.ravel(),
                               self.kappa * np.log(mu_l), self.kappa * np.log(mu_lo), self.kappa * np.log(mu_hi)])

    def min_margin(self, X):
        """Smallest normalised margin encoded by the slacks of X (> 0 on M)."""
        return float(np.exp(np.min(X[I_G:N_VARS]) / self.kappa))

    def margin(self, X):
        """The normalised margin of ``wrench.wrench_feasibility`` at the pose of X on M, read from
        X without evaluating the pose: the cable lengths over their range and the tension
        margins exp(s / kappa), exp(t / kappa) (the length slacks g use another
        normalisation, see the module doc)."""
        r = self.robot
        a = (X[I_L:I_F] - r.length_min) / (r.length_max - r.length_min)
        return float(min(np.min(a), np.min(1.0 - a), np.exp(np.min(X[I_S:N_VARS]) / self.kappa)))


def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _skew3(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
