"""The navigation manifold M (paper Sec. 3): F(x) = 0 holds exactly on wrench-feasible poses.

Physical variables X (90, SI units), in this order:
    p (3, m) | tau (3, rad) | d_1..d_6 cable vectors (18, m) | lengths l (6, m) |
    f0 (6, N) | v_1..v_6 (36, N) | g (6) | s (6) | t (6)
followed by the task's variables (e.g. the sphere's alpha1, alpha2). Equations, in order:
    (1) d_i - (p + R b_i - a_i) = 0                       18
    (2) l_i^2 - d_i . d_i = 0                              6
    (4) J f0 - w0 = 0                                      6
    (5) v_i^T B v_i - 1 = 0,  B = J^T E J                  6
    (6) (B v_i)_k = 0 for k != i                          30
    (10) mu_l,i = exp(g_i / kappa)   length margin         6
    (11) mu_f-,i = exp(s_i / kappa)  lower tension margin  6
    (12) mu_f+,i = exp(t_i / kappa)  upper tension margin  6
with normalised margins mu_l = (l - dmin)(dmax - l) / ((dmax - dmin) / 2)^2,
mu_f- = (f0_i - v_ii - fmin) / (fmax - fmin), mu_f+ = (fmax - f0_i - v_ii) / (fmax - fmin).

Eqs. 10-12 are the paper's slack equations in logarithmic form: mu = exp(g / kappa) has
the same solution set as the paper's mu g' = 1 (both force mu > 0) and its derivative in
the slack never vanishes, so F_x keeps full rank on M (paper App. B). The log form makes
charts shrink geometrically, not harmonically, towards the boundary of C, so a lower bound
on the slacks (a margin floor mu >= exp(slack_min / kappa)) bounds the atlas.

The atlas sees scaled variables x = X / scale, so one chart radius is meaningful: lengths
over the platform radius, tensions over the tension range, angles in radians, slacks as is.
"""

import numpy as np

from ..feasibility import evaluate, skew
from ..model.pose import rotation_tt, rotation_tt_derivatives

N_POSE = 6
I_P, I_TAU, I_D, I_L, I_F, I_V, I_G, I_S, I_T = 0, 3, 6, 24, 30, 36, 72, 78, 84
N_VARS = 90
N_EQS = 84
KAPPA = 0.1  # slack scale: a chart radius of r changes a margin by a factor exp(r / KAPPA)


class NavigationManifold:
    """F(X) and F_X(X) of the robot's navigation manifold in physical variables."""

    def __init__(self, robot):
        self.robot = robot
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
        r[36:66] = 1.0 / self.tension_ref
        return r

    # ----- pieces ----------------------------------------------------------------------
    def _unpack(self, X):
        p, tau = X[I_P:I_TAU], X[I_TAU:I_D]
        d = X[I_D:I_L].reshape(6, 3)
        l, f0 = X[I_L:I_F], X[I_F:I_V]
        V = X[I_V:I_G].reshape(6, 6)  # row i = v_i
        return p, tau, d, l, f0, V, X[I_G:I_S], X[I_S:I_T], X[I_T:N_VARS]

    def _wrench_and_ellipsoid(self, c):
        """w0(c), E(c) in the base frame and the force part F of the load wrench."""
        F = self.w_local[:3]
        w0 = self.w_local.copy()
        if not self.load_frame:
            return w0, self.E3, F
        w0[3:] += np.cross(c, F)
        e = np.eye(6)
        e[3:, :3] = -skew(c)
        return w0, e.T @ self.E3 @ e, F

    def _ellipsoid_derivatives(self, c):
        """dE/dc_m, shape (3, 6, 6); zeros for a base-frame ellipsoid."""
        if not self.load_frame:
            return np.zeros((3, 6, 6))
        e = np.eye(6)
        e[3:, :3] = -skew(c)
        out = np.empty((3, 6, 6))
        for m in range(3):
            G = np.zeros((6, 6))
            G[3:, :3] = -skew(np.eye(3)[m])
            A = G.T @ self.E3 @ e
            out[m] = A + A.T
        return out

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
        p, tau, d, l, f0, V, g, s, t = self._unpack(X)
        R = rotation_tt(tau)
        c = p + R @ self.g_load
        w0, E, Fload = self._wrench_and_ellipsoid(c)
        cols = np.concatenate([d, np.einsum("kij,kj->ki", self.a_skew, d)], axis=1)  # (6, 6): row i = J col i * l_i
        J = (cols / l[:, None]).T
        Y = V @ J.T  # row i = y_i = J v_i
        Z = Y @ E  # row i = z_i = E y_i (E symmetric)
        BV = Z @ J  # row i = (B v_i)^T
        vdiag = np.diag(V)
        mu_l, mu_lo, mu_hi = self.margins(l, f0, vdiag)
        off = ~np.eye(6, dtype=bool)

        Fv = np.empty(N_EQS)
        Fv[0:18] = (d - (p + self.b @ R.T - self.a)).ravel()
        Fv[18:24] = l ** 2 - np.einsum("ij,ij->i", d, d)
        Fv[24:30] = J @ f0 - w0
        Fv[30:36] = np.einsum("ij,ij->i", V, BV) - 1.0
        Fv[36:66] = BV[off]
        Fv[66:72] = mu_l - np.exp(g / KAPPA)
        Fv[72:78] = mu_lo - np.exp(s / KAPPA)
        Fv[78:84] = mu_hi - np.exp(t / KAPPA)
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
            Fx = skew(Fload)  # d(-w0)/dc = [0; [F]x]
            Jx[27:30, I_P:I_TAU] = Fx
            Jx[27:30, I_TAU:I_D] = Fx @ dc_dtau
        # (5) and (6): derivatives through J (per column j), v_i and c
        dE = self._ellipsoid_derivatives(c)
        dEy = np.einsum("mab,ib->ima", dE, Y)  # (i, m, 6): dE/dc_m y_i
        JtE = J.T @ E
        B = JtE @ J
        for i in range(6):
            vi, yi, zi = V[i], Y[i], Z[i]
            # d(v^T B v)/dJcol_j = 2 v_j z ; d(Bv)/dJcol_j = e_j z^T + v_j J^T E
            q5 = 2.0 * vi[:, None] * zi[None, :]  # (j, 6)
            Jx[30 + i, I_V + 6 * i:I_V + 6 * i + 6] = 2.0 * BV[i]
            ks = [k for k in range(6) if k != i]
            r6 = 36 + 5 * i
            Jx[r6:r6 + 5, I_V + 6 * i:I_V + 6 * i + 6] = B[ks]
            for j in range(6):
                D = vi[j] * JtE
                D[j] += zi
                Jx[30 + i, I_D + 3 * j:I_D + 3 * j + 3] = q5[j] @ dcol_dd[j]
                Jx[30 + i, I_L + j] = q5[j] @ dcol_dl[j]
                Jx[r6:r6 + 5, I_D + 3 * j:I_D + 3 * j + 3] = D[ks] @ dcol_dd[j]
                Jx[r6:r6 + 5, I_L + j] = D[ks] @ dcol_dl[j]
            if self.load_frame:
                d5_dc = np.einsum("a,ma->m", yi, dEy[i])  # (3,)
                d6_dc = (J.T @ dEy[i].T)[ks]  # (5, 3)
                Jx[30 + i, I_P:I_TAU] = d5_dc
                Jx[30 + i, I_TAU:I_D] = d5_dc @ dc_dtau
                Jx[r6:r6 + 5, I_P:I_TAU] = d6_dc
                Jx[r6:r6 + 5, I_TAU:I_D] = d6_dc @ dc_dtau
        # (10)-(12)
        rr = self.robot
        Jx[66 + rows, I_L + rows] = (rr.length_max + rr.length_min - 2.0 * l) / self.half_range_l ** 2
        Jx[66 + rows, I_G + rows] = -np.exp(g / KAPPA) / KAPPA
        Jx[72 + rows, I_F + rows] = 1.0 / self.range_f
        Jx[72 + rows, I_V + 7 * rows] = -1.0 / self.range_f
        Jx[72 + rows, I_S + rows] = -np.exp(s / KAPPA) / KAPPA
        Jx[78 + rows, I_F + rows] = -1.0 / self.range_f
        Jx[78 + rows, I_V + 7 * rows] = -1.0 / self.range_f
        Jx[78 + rows, I_T + rows] = -np.exp(t / KAPPA) / KAPPA
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
        w0, E, _ = self._wrench_and_ellipsoid(c)
        f0 = np.linalg.solve(J, w0)
        B_inv = np.linalg.inv(J.T @ E @ J)
        V = (B_inv / np.sqrt(np.diag(B_inv))).T  # row i = B^-1 e_i / sqrt(e_i^T B^-1 e_i)
        mu_l, mu_lo, mu_hi = self.margins(l, f0, np.diag(V))
        return np.concatenate([p, tau, d.ravel(), l, f0, V.ravel(),
                               KAPPA * np.log(mu_l), KAPPA * np.log(mu_lo), KAPPA * np.log(mu_hi)])

    def min_margin(self, X):
        """Smallest normalised margin encoded by the slacks of X (> 0 on M)."""
        return float(np.exp(np.min(X[I_G:N_VARS]) / KAPPA))
