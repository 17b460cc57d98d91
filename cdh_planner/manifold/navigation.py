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

import math

import numpy as np

from ..wrench import skew, wrench_feasibility
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
        self.a_skew = skew(self.a)  # (6, 3, 3)
        self.L3T = np.linalg.cholesky(self.E3).T  # E3 = L3 L3^T
        self.de_dc = np.zeros((3, 6, 6))  # d e(c) / dc_m
        for m in range(3):
            self.de_dc[m, 3:, :3] = -skew(np.eye(3)[m])
        self._index_tables()
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

    def _index_tables(self):
        """Constant entries and scatter indices of F_X, computed once."""
        self._rows6 = np.arange(6)
        self._template = np.zeros((N_EQS, N_VARS))
        for i in range(6):
            r0 = 3 * i
            self._template[r0:r0 + 3, I_P:I_TAU] = -np.eye(3)
            self._template[r0:r0 + 3, I_D + r0:I_D + r0 + 3] = np.eye(3)
        self._r2 = 18 + np.repeat(self._rows6, 3)
        self._c2 = I_D + np.arange(18)
        self._col_dd = np.concatenate([np.broadcast_to(np.eye(3), (6, 3, 3)), self.a_skew], axis=1)
        idx_k, idx_j = np.repeat(self._rows6, 6), np.tile(self._rows6, 6)
        self._r_env = np.arange(36)[:, None]
        self._c_env = I_V + 6 * self._rows6[None, :] + idx_j[:, None]
        self._k_env = idx_k
        self._r_v = np.repeat(self._rows6, 6)
        self._c_v = np.arange(36)
        self._force_skew = skew(self.w_local[:3])

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
    def _unpack(self, X):
        p, tau = X[I_P:I_TAU], X[I_TAU:I_D]
        d = X[I_D:I_L].reshape(6, 3)
        l, f0 = X[I_L:I_F], X[I_F:I_V]
        G = X[I_V:I_G].reshape(6, 6)  # tension envelope map: f = f0 + G z, |z| <= 1
        return p, tau, d, l, f0, G, X[I_G:I_S], X[I_S:I_T], X[I_T:N_VARS]

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

        The compiled kernel (kernels.py, numba); ``residual_and_jacobian_reference`` is the
        same computation in numpy, kept as the reference the kernel is tested against.
        """
        X = np.ascontiguousarray(X, dtype=np.float64)
        if X.shape != (N_VARS,):  # the kernel does not bounds-check
            raise ValueError(f"expected X of shape ({N_VARS},), got {X.shape}")
        if self._kernel is None:
            self._load_kernel()
        F, Jx = self._kernel(X, self._kernel_params, bool(jacobian))
        return F, (Jx if jacobian else None)

    def residual_and_jacobian_reference(self, X, jacobian=True):
        """F(X) (84,) and F_X(X) (84, 90) in physical units: numpy reference of the kernel."""
        p, tau, d, l, f0, G, g, s, t = self._unpack(X)
        R, dR = rotation_and_derivatives(tau)
        c = p + R @ self.g_load
        w0, P = self._wrench_and_factor(c)
        cols = np.concatenate([d, np.einsum("kij,kj->ki", self.a_skew, d)], axis=1)  # row i = l_i J col i
        J = (cols / l[:, None]).T
        JG = J @ G
        M = P @ J
        vdiag = np.linalg.norm(G, axis=1)
        mu_l, mu_lo, mu_hi = self.margins(l, f0, vdiag)

        Fv = np.empty(N_EQS)
        Fv[0:18] = (d - (p + self.b @ R.T - self.a)).ravel()
        Fv[18:24] = l ** 2 - np.einsum("ij,ij->i", d, d)
        Fv[24:30] = J @ f0 - w0
        Fv[30:66] = (P @ JG - np.eye(6)).ravel()
        Fv[66:72] = mu_l - np.exp(g / self.kappa)
        Fv[72:78] = mu_lo - np.exp(s / self.kappa)
        Fv[78:84] = mu_hi - np.exp(t / self.kappa)
        if not jacobian:
            return Fv, None

        Jx = self._template.copy()  # the constant entries (identities of Eq. 1)
        db = np.einsum("ijk,nj->nik", dR, self.b)  # (6 cables, 3, 3 angles)
        dc_dtau = np.einsum("ijk,j->ik", dR, self.g_load)  # (3, 3)
        rows = self._rows6
        # (1)
        Jx[0:18, I_TAU:I_D] = -db.reshape(18, 3)
        # (2)
        Jx[18 + rows, I_L + rows] = 2.0 * l
        Jx[self._r2, self._c2] = -2.0 * d.ravel()
        # dJcol_i / dd_i = [I; [a_i]x] / l_i and dJcol_i / dl_i = -Jcol_i / l_i
        dcol_dd = self._col_dd / l[:, None, None]  # (6, 6, 3)
        dcol_dl = -J.T / l[:, None]  # (6, 6): row i = d Jcol_i / d l_i
        # (4) J f0 - w0
        Jx[24:30, I_F:I_V] = J
        Jx[24:30, I_D:I_L] = (f0[:, None, None] * dcol_dd).transpose(1, 0, 2).reshape(6, 18)
        Jx[24:30, I_L:I_F] = (f0[:, None] * dcol_dl).T
        if self.load_frame:
            Fx = self._force_skew  # d(-w0)/dc = [0; [F]x]
            Jx[27:30, I_P:I_TAU] = Fx
            Jx[27:30, I_TAU:I_D] = Fx @ dc_dtau
        # envelope: P J G - I, rows (k, j) row-major
        blk = Jx[30:66]
        blk[self._r_env, self._c_env] = M[self._k_env]
        # d(P J G)_kj / dJcol_i = P_k: G_ij
        D = np.einsum("ka,ij->ikja", P, G).reshape(6, 36, 6)
        blk[:, I_D:I_L] = np.einsum("ira,iac->ric", D, dcol_dd).reshape(36, 18)
        blk[:, I_L:I_F] = np.einsum("ira,ia->ri", D, dcol_dl)
        if self.load_frame:
            dc = np.einsum("kb,mbc,cj->kjm", self.L3T, self.de_dc, JG).reshape(36, 3)
            blk[:, I_P:I_TAU] = dc
            blk[:, I_TAU:I_D] = dc @ dc_dtau
        # (10)-(12)
        rr = self.robot
        dv = (G / vdiag[:, None] / self.range_f[:, None]).ravel()  # d|G_i| / dG_i over the range
        Jx[66 + rows, I_L + rows] = (rr.length_max + rr.length_min - 2.0 * l) / self.half_range_l ** 2
        Jx[66 + rows, I_G + rows] = -np.exp(g / self.kappa) / self.kappa
        Jx[72 + rows, I_F + rows] = 1.0 / self.range_f
        Jx[78 + rows, I_F + rows] = -1.0 / self.range_f
        Jx[72 + self._r_v, I_V + self._c_v] = -dv
        Jx[78 + self._r_v, I_V + self._c_v] = -dv
        Jx[72 + rows, I_S + rows] = -np.exp(s / self.kappa) / self.kappa
        Jx[78 + rows, I_T + rows] = -np.exp(t / self.kappa) / self.kappa
        return Fv, Jx

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


def rotation_and_derivatives(tau):
    """R = Rz(phi) Ry(theta) Rz(sigma - phi) of one pose and dR / d(phi, theta, sigma)
    stacked as (3, 3, 3) (last index = angle); scalar code, the Newton loop's hot path."""
    phi, theta, sigma = float(tau[0]), float(tau[1]), float(tau[2])
    cf, sf = math.cos(phi), math.sin(phi)
    ct, st = math.cos(theta), math.sin(theta)
    cp, sp = math.cos(sigma - phi), math.sin(sigma - phi)
    Rzf = np.array([[cf, -sf, 0.0], [sf, cf, 0.0], [0.0, 0.0, 1.0]])
    dRzf = np.array([[-sf, -cf, 0.0], [cf, -sf, 0.0], [0.0, 0.0, 0.0]])
    Ry = np.array([[ct, 0.0, st], [0.0, 1.0, 0.0], [-st, 0.0, ct]])
    dRy = np.array([[-st, 0.0, ct], [0.0, 0.0, 0.0], [-ct, 0.0, -st]])
    Rzp = np.array([[cp, -sp, 0.0], [sp, cp, 0.0], [0.0, 0.0, 1.0]])
    dRzp = np.array([[-sp, -cp, 0.0], [cp, -sp, 0.0], [0.0, 0.0, 0.0]])
    A = Rzf @ Ry
    d_sigma = A @ dRzp
    dR = np.empty((3, 3, 3))
    dR[:, :, 0] = dRzf @ Ry @ Rzp - d_sigma
    dR[:, :, 1] = Rzf @ dRy @ Rzp
    dR[:, :, 2] = d_sigma
    return A @ Rzp, dR
