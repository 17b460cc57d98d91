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

from ..feasibility import evaluate, skew, wrench_transform
from ..model.pose import rotation_tt, rotation_tt_derivatives

N_POSE = 6
I_P, I_TAU, I_D, I_L, I_F, I_V, I_G, I_S, I_T = 0, 3, 6, 24, 30, 36, 72, 78, 84
N_VARS = 90
N_EQS = 84
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
        w0[3:] += np.cross(c, self.w_local[:3])
        return w0, self.L3T @ wrench_transform(c)

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
        """F(X) (84,) and F_X(X) (84, 90) in physical units."""
        p, tau, d, l, f0, G, g, s, t = self._unpack(X)
        R = rotation_tt(tau)
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

        Jx = np.zeros((N_EQS, N_VARS))
        dR = rotation_tt_derivatives(tau)  # (3, 3, 3): dR[:, :, k]
        db = np.einsum("ijk,nj->nik", dR, self.b)  # (6 cables, 3, 3 angles)
        dc_dtau = np.einsum("ijk,j->ik", dR, self.g_load)  # (3, 3)
        rows = np.arange(6)
        # (1)
        for i in range(6):
            r0 = 3 * i
            Jx[r0:r0 + 3, I_P:I_TAU] = -np.eye(3)
            Jx[r0:r0 + 3, I_TAU:I_D] = -db[i]
            Jx[r0:r0 + 3, I_D + r0:I_D + r0 + 3] = np.eye(3)
        # (2)
        Jx[18 + rows, I_L + rows] = 2.0 * l
        for i in range(6):
            Jx[18 + i, I_D + 3 * i:I_D + 3 * i + 3] = -2.0 * d[i]
        # dJcol_i / dd_i = [I; [a_i]x] / l_i and dJcol_i / dl_i = -Jcol_i / l_i
        dcol_dd = np.concatenate([np.broadcast_to(np.eye(3), (6, 3, 3)), self.a_skew], axis=1) / l[:, None, None]
        dcol_dl = -J.T / l[:, None]  # (6, 6): row i = d Jcol_i / d l_i
        # (4) J f0 - w0
        Jx[24:30, I_F:I_V] = J
        for i in range(6):
            Jx[24:30, I_D + 3 * i:I_D + 3 * i + 3] = f0[i] * dcol_dd[i]
            Jx[24:30, I_L + i] = f0[i] * dcol_dl[i]
        if self.load_frame:
            Fx = skew(self.w_local[:3])  # d(-w0)/dc = [0; [F]x]
            Jx[27:30, I_P:I_TAU] = Fx
            Jx[27:30, I_TAU:I_D] = Fx @ dc_dtau
        # envelope: P J G - I, rows (k, j) row-major
        blk = Jx[30:66]
        idx_k = np.repeat(rows, 6)  # k of each row
        idx_j = np.tile(rows, 6)  # j of each row
        for a in range(6):
            blk[np.arange(36), I_V + 6 * a + idx_j] = M[idx_k, a]
        for i in range(6):
            # d(P J G)_kj / dJcol_i = P_k: G_ij
            dcol = np.einsum("ka,j->kja", P, G[i]).reshape(36, 6)
            blk[:, I_D + 3 * i:I_D + 3 * i + 3] = dcol @ dcol_dd[i]
            blk[:, I_L + i] = dcol @ dcol_dl[i]
        if self.load_frame:
            dc = np.einsum("kb,mbc,cj->kjm", self.L3T, self.de_dc, JG).reshape(36, 3)
            blk[:, I_P:I_TAU] = dc
            blk[:, I_TAU:I_D] = dc @ dc_dtau
        # (10)-(12)
        rr = self.robot
        dv = G / vdiag[:, None]  # d|G_i| / dG_i
        Jx[66 + rows, I_L + rows] = (rr.length_max + rr.length_min - 2.0 * l) / self.half_range_l ** 2
        Jx[66 + rows, I_G + rows] = -np.exp(g / self.kappa) / self.kappa
        Jx[72 + rows, I_F + rows] = 1.0 / self.range_f
        Jx[78 + rows, I_F + rows] = -1.0 / self.range_f
        for i in range(6):
            Jx[72 + i, I_V + 6 * i:I_V + 6 * i + 6] = -dv[i] / self.range_f[i]
            Jx[78 + i, I_V + 6 * i:I_V + 6 * i + 6] = -dv[i] / self.range_f[i]
        Jx[72 + rows, I_S + rows] = -np.exp(s / self.kappa) / self.kappa
        Jx[78 + rows, I_T + rows] = -np.exp(t / self.kappa) / self.kappa
        return Fv, Jx

    # ----- lifting -----------------------------------------------------------------------
    def lift(self, p, tau):
        """The point X on M above a feasible pose (p m, tau rad); ValueError if infeasible."""
        p, tau = np.asarray(p, dtype=float), np.asarray(tau, dtype=float)
        fz = evaluate(self.robot, p[None], tau[None])
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
