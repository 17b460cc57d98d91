"""The navigation manifold restricted by a task, in the scaled variables the atlas uses.

x = X / scale, X = [the 90 navigation variables | task variables]. Task equations:
- slice: each fixed pose coordinate equals its value (angles compared modulo 2 pi);
- sphere (paper Eq. 17): task variables (alpha1, alpha2);
  p = c + r [cos a2 cos a1, cos a2 sin a1, -sin a2], phi = a1 - pi, theta = pi/2 - a2,
  sigma = 0 unless the torsion is free;
- implicit (paper Eq. 15): the task's own C(p, tau) = 0 and its Jacobian;
- free: none (n = 6).
"""

import numpy as np

from ..model.pose import wrap_angle
from ..model.task import POSE_NAMES, ImplicitTask, SliceTask, SphereTask
from .navigation import I_G, I_P, I_TAU, N_EQS, N_VARS, NavigationManifold

PHI, THETA, SIGMA = 3, 4, 5
# Length of the cos/sin embedding of periodic coordinates in the spatial-index key.


class TaskConstraint:
    """F(x) = 0 of the navigation manifold plus task equations, scaled (see module doc).

    ``margin_floor``: normalised margin below which the slack variables leave the domain;
    the atlas never places charts there (the resolution of the "no path" answer).
    """

    def __init__(self, robot, task, margin_floor=1e-3, kappa=None):
        self.nav = NavigationManifold(robot) if kappa is None else NavigationManifold(robot, kappa)
        self.task = task
        self.n_task_vars = 2 if isinstance(task, SphereTask) else 0
        self.n_vars = N_VARS + self.n_task_vars
        self.scale = np.concatenate([self.nav.variable_scale(), np.ones(self.n_task_vars)])
        self.row_scale = self.nav.equation_scale()
        self._task_rows = self._task_equation_count()
        self.dim = self.n_vars - N_EQS - self._task_rows
        self.periodic = np.zeros(self.n_vars, dtype=bool)
        self.periodic[[PHI, SIGMA]] = True
        if self.n_task_vars:
            self.periodic[N_VARS] = True  # alpha1
        self.lower, self.upper = self._domain(robot, margin_floor)
        self.margin_floor = margin_floor

    # ----- the constraint ------------------------------------------------------------
    def _task_equation_count(self):
        if isinstance(self.task, SliceTask):
            return len(self.task.fixed)
        if isinstance(self.task, SphereTask):
            return 5 if self.task.free_torsion else 6
        if isinstance(self.task, ImplicitTask):
            return int(self.task.count)
        return 0

    def residual_and_jacobian(self, x):
        X = x * self.scale
        F, FX = self.nav.residual_and_jacobian(X[:N_VARS])
        F = F / self.row_scale
        FX = FX / self.row_scale[:, None]
        Ft, FtX = self._task(X)
        F_all = np.concatenate([F, Ft])
        J = np.zeros((F_all.size, self.n_vars))
        J[:N_EQS, :N_VARS] = FX
        J[N_EQS:] = FtX
        return F_all, J * self.scale

    def _task(self, X):
        rows = self._task_rows
        Ft = np.zeros(rows)
        Jt = np.zeros((rows, self.n_vars))
        L = self.nav.length_ref
        if isinstance(self.task, SliceTask):
            for r, name in enumerate(n for n in POSE_NAMES if n in self.task.fixed):
                j = POSE_NAMES.index(name)
                value = self.task.fixed[name]
                if j in (PHI, SIGMA):
                    Ft[r] = wrap_angle(X[j] - value)
                else:
                    Ft[r] = (X[j] - value) / (L if j < 3 else 1.0)
                Jt[r, j] = 1.0 / (L if j < 3 else 1.0)
        elif isinstance(self.task, ImplicitTask):
            C, dC = self.task.equations(X[I_P:I_TAU], X[I_TAU:I_TAU + 3])
            Ft[:] = C
            Jt[:, I_P:I_TAU + 3] = dC
        elif isinstance(self.task, SphereTask):
            a1, a2 = X[N_VARS], X[N_VARS + 1]
            c1, s1, c2, s2 = np.cos(a1), np.sin(a1), np.cos(a2), np.sin(a2)
            rs, c = self.task.radius, np.asarray(self.task.center)
            n = np.array([c2 * c1, c2 * s1, -s2])
            dn_da1 = np.array([-c2 * s1, c2 * c1, 0.0])
            dn_da2 = np.array([-s2 * c1, -s2 * s1, -c2])
            Ft[0:3] = (X[I_P:I_TAU] - c - rs * n) / L
            Jt[0:3, I_P:I_TAU] = np.eye(3) / L
            Jt[0:3, N_VARS] = -rs * dn_da1 / L
            Jt[0:3, N_VARS + 1] = -rs * dn_da2 / L
            Ft[3] = wrap_angle(X[PHI] - a1 + np.pi)
            Jt[3, PHI], Jt[3, N_VARS] = 1.0, -1.0
            Ft[4] = X[THETA] - np.pi / 2 + a2
            Jt[4, THETA], Jt[4, N_VARS + 1] = 1.0, 1.0
            if not self.task.free_torsion:
                Ft[5] = wrap_angle(X[SIGMA])
                Jt[5, SIGMA] = 1.0
        return Ft, Jt

    def _domain(self, robot, margin_floor):
        lo = np.full(self.n_vars, -np.inf)
        hi = np.full(self.n_vars, np.inf)
        reach = robot.length_max.max() + np.linalg.norm(robot.platform_anchors, axis=1).max()
        lo[I_P:I_TAU] = robot.base_anchors.min(axis=0) - reach
        hi[I_P:I_TAU] = robot.base_anchors.max(axis=0) + reach
        lo[THETA], hi[THETA] = 0.0, np.pi
        lo[I_G:N_VARS] = self.nav.kappa * np.log(margin_floor)
        if self.n_task_vars:
            lo[N_VARS + 1], hi[N_VARS + 1] = -np.pi / 2, np.pi / 2
        return lo / self.scale, hi / self.scale

    def key(self, x):
        """Pose (and task variables) with angles as (cos, sin): 1-Lipschitz in x."""
        parts = [x[I_P:I_TAU], [np.cos(x[PHI]), np.sin(x[PHI]), x[THETA], np.cos(x[SIGMA]), np.sin(x[SIGMA])]]
        if self.n_task_vars:
            a1 = x[N_VARS]
            parts.append([np.cos(a1), np.sin(a1), x[N_VARS + 1]])
        return np.concatenate(parts)

    # ----- poses <-> points ----------------------------------------------------------
    def lift(self, p, tau):
        """The scaled point x on the manifold above a feasible pose satisfying the task."""
        X = self.nav.lift(p, tau)
        if self.n_task_vars:
            X = np.concatenate([X, self.task.coords(np.atleast_2d(p), np.atleast_2d(tau))[0, :2]])
        return X / self.scale

    def pose(self, x):
        """(p m, tau rad) of a scaled point."""
        X = x[:I_G] * self.scale[:I_G]
        return X[I_P:I_TAU].copy(), X[I_TAU:I_TAU + 3].copy()
