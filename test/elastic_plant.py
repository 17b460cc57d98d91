"""A test oracle, independent of the planner's own check: the platform as a free rigid body
on elastic, tension-only cables, driven by a JointTrajectoryController's quintic of the
lengths it is commanded (scipy's solve_ivp; SI units).

State: the centre of mass c (3), the orientation (quaternion x, y, z, w), its velocity (3)
and the body angular velocity (3). Each cable i, of unstretched length l_i(t) commanded,
pulls the platform anchor q_i = p + R b_i towards its base anchor a_i with

    t_i = max(0, k_i (L_i - l_i) + DAMPING k_i (L_i' - l_i')),   k_i = EA_i / l_i,

L_i = |q_i - a_i|. Newton-Euler about c with the robot's load mass and inertia; the external
load is the robot's load wrench (its force at c, its moment about the origin moved to c).
The quintic is solved here per segment from the two ends' positions, velocities and
accelerations (a linear solve, not the planner's closed form).
"""

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import root
from scipy.spatial.transform import Rotation, Slerp

DAMPING = 0.02  # s: damping on the stretch rate per unit stiffness


def jtc_coefficients(t_wp, L, V, A):
    """Per segment k the quintic's coefficients c (K, 6, J) in s = t - t_k, solved from the
    two ends' positions, velocities and accelerations (a linear solve per segment)."""
    h = np.diff(t_wp)
    M = np.zeros((len(h), 6, 6))
    M[:, 0, 0], M[:, 1, 1], M[:, 2, 2] = 1.0, 1.0, 2.0
    for j in range(6):
        M[:, 3, j] = h ** j
        M[:, 4, j] = j * h ** max(j - 1, 0) if j else 0.0
        M[:, 5, j] = j * (j - 1) * h ** max(j - 2, 0) if j > 1 else 0.0
    rhs = np.stack([L[:-1], V[:-1], A[:-1], L[1:], V[1:], A[1:]], axis=1)
    return np.linalg.solve(M, rhs)


def jtc_points(t_wp, coef, L, t):
    """Positions and velocities (J,) of the JTC quintic at time t (held before / after)."""
    if t <= t_wp[0]:
        return L[0], np.zeros(L.shape[1])
    if t >= t_wp[-1]:
        return L[-1], np.zeros(L.shape[1])
    k = int(np.searchsorted(t_wp, t, side="right") - 1)
    s = t - t_wp[k]
    c = coef[k]
    pos = c[0] + s * (c[1] + s * (c[2] + s * (c[3] + s * (c[4] + s * c[5]))))
    vel = c[1] + s * (2 * c[2] + s * (3 * c[3] + s * (4 * c[4] + s * 5 * c[5])))
    return pos, vel


def quat_matrix(q):
    """Rotation matrix of a unit quaternion (x, y, z, w)."""
    x, y, z, w = q / np.sqrt(q @ q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


class Plant:
    """The platform of ``robot`` (its mass, inertia about the load point, load wrench) on
    elastic cables of stiffness ``EA`` (m,) N, commanded (t_wp, L, V, A)."""

    def __init__(self, robot, EA, t_wp, L, V, A):
        self.robot, self.EA = robot, np.broadcast_to(np.asarray(EA, dtype=float), (L.shape[1],))
        t_wp, L, V, A = (np.asarray(x, dtype=float) for x in (t_wp, L, V, A))
        self.cmd = (t_wp, jtc_coefficients(t_wp, L, V, A), L)
        w = np.asarray(robot.wrench_center_local, dtype=float)
        self.force, self.moment_local = w[:3], w[3:]
        self.I = np.asarray(robot.inertia, dtype=float).reshape(3, 3)
        self.I_inv = np.linalg.inv(self.I)

    def _cables(self, c, R, v, omega_world, l0, l0dot):
        g = self.robot.load_point
        p = c - R @ g
        r = (R @ self.robot.platform_anchors.T).T                    # anchors from P (m, 3)
        d = p + r - self.robot.base_anchors
        L = np.linalg.norm(d, axis=1)
        u = d / L[:, None]
        qdot = v + np.cross(omega_world, r - R @ g)                  # anchor velocities
        Ldot = np.einsum("ij,ij->i", u, qdot)
        k = self.EA / l0
        t = np.maximum(0.0, k * (L - l0) + DAMPING * k * (Ldot - l0dot))
        return p, r, u, t

    def external_moment_about(self, c):
        """The load's moment about c (N m): its moment about the origin moved to c."""
        if self.robot.ellipsoid_frame == "load":
            return self.moment_local
        return self.moment_local - np.cross(c, self.force)

    def rhs(self, time, y):
        c, q, v, wb = y[:3], y[3:7], y[7:10], y[10:13]
        R = quat_matrix(q)
        l0, l0dot = jtc_points(*self.cmd, time)
        p, r, u, t = self._cables(c, R, v, R @ wb, l0, l0dot)
        F = self.force - t @ u
        arm = r - R @ self.robot.load_point                           # anchor from c
        M = self.external_moment_about(c) + np.sum(np.cross(arm, -t[:, None] * u), axis=0)
        wdot = self.I_inv @ (R.T @ M - np.cross(wb, self.I @ wb))
        x, y_, z, w = q
        qdot = 0.5 * np.array([w * wb[0] + y_ * wb[2] - z * wb[1],
                               w * wb[1] + z * wb[0] - x * wb[2],
                               w * wb[2] + x * wb[1] - y_ * wb[0],
                               -x * wb[0] - y_ * wb[1] - z * wb[2]])
        return np.concatenate([v, qdot, F / self.robot.mass, wdot])

    def rest(self, p0, R0):
        """The static equilibrium (c, quaternion) of the first commanded lengths, near p0, R0
        (scipy's root on the force and moment balance)."""
        l0 = self.cmd[2][0]
        g = self.robot.load_point

        def balance(x):
            R = Rotation.from_rotvec(x[3:]).as_matrix() @ R0
            c = p0 + x[:3] + R @ g
            _, r, u, t = self._cables(c, R, np.zeros(3), np.zeros(3), l0, np.zeros_like(l0))
            arm = r - R @ g
            return np.concatenate([self.force - t @ u, self.external_moment_about(c)
                                   + np.sum(np.cross(arm, -t[:, None] * u), axis=0)])
        sol = root(balance, np.zeros(6), tol=1e-13)
        assert np.max(np.abs(balance(sol.x))) < 1e-9, sol.message
        R = Rotation.from_rotvec(sol.x[3:]).as_matrix() @ R0
        return p0 + sol.x[:3] + R @ g, Rotation.from_matrix(R).as_quat()

    def run(self, p0, R0, settle_s=0.5, dt=1e-3):
        """From rest at the first command to ``settle_s`` after the last: times (M,), P's
        positions (M, 3), rotations (M, 3, 3) and tensions (M, m), every dt s."""
        c, q = self.rest(p0, R0)
        y0 = np.concatenate([c, q, np.zeros(6)])
        T = self.cmd[0][-1] + settle_s
        ts = np.arange(0.0, T, dt)
        sol = solve_ivp(self.rhs, (0.0, T), y0, t_eval=ts, rtol=1e-6, atol=1e-9,
                        max_step=5e-3)
        assert sol.success, sol.message
        P, Rs, tensions = [], [], []
        for time, y in zip(sol.t, sol.y.T):
            R = quat_matrix(y[3:7])
            l0, l0dot = jtc_points(*self.cmd, time)
            p, _, _, t = self._cables(y[:3], R, y[7:10], R @ y[10:13], l0, l0dot)
            P.append(p), Rs.append(R), tensions.append(t)
        return sol.t, np.array(P), np.array(Rs), np.array(tensions)


def planned_at(t_wp, p_wp, quat_wp, t):
    """The plan's pose at times t: positions linear, orientations slerp between waypoints."""
    tc = np.clip(t, t_wp[0], t_wp[-1])
    p = np.stack([np.interp(tc, t_wp, p_wp[:, j]) for j in range(3)], axis=1)
    return p, Slerp(t_wp, Rotation.from_quat(quat_wp))(tc).as_matrix()


def envelope_at(t_wp, lo, hi, t):
    """The published envelope (min, max) (M, m) at times t, linear between waypoints."""
    tc = np.clip(t, t_wp[0], t_wp[-1])
    return (np.stack([np.interp(tc, t_wp, c) for c in lo.T], axis=1),
            np.stack([np.interp(tc, t_wp, c) for c in hi.T], axis=1))
