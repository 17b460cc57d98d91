"""The navigation manifold restricted by a task, in the scaled variables the atlas uses.

x = X / scale, X = [the 90 navigation variables | task variables]. F stacks the navigation
equations and the task's own (``Task.equations``, paper Eq. 15), its rows in metres
divided by the robot's length scale so that every row is O(1); free flight adds none (n = 6).
"""

import numpy as np

from ..model.task import COORDINATES
from .navigation import I_G, I_P, I_TAU, N_EQS, N_VARS, NavigationManifold

PHI, THETA, SIGMA = 3, 4, 5


class TaskConstraint:
    """F(x) = 0 of the navigation manifold plus task equations, scaled (see module doc).

    ``margin_floor``: normalised margin below which the slack variables leave the domain;
    the atlas never places charts there (the resolution of the "no path" answer).
    """

    def __init__(self, robot, task, margin_floor=1e-3, kappa=None):
        self.nav = NavigationManifold(robot) if kappa is None else NavigationManifold(robot, kappa)
        self.task = task
        self.n_task_vars = task.n_vars
        self.n_vars = N_VARS + self.n_task_vars
        self.scale = np.concatenate([self.nav.variable_scale(), np.ones(self.n_task_vars)])
        self.row_scale = self.nav.equation_scale()
        self._row_scale_col = self.row_scale[:, None]
        # free flight: no task equations or variables, F and F_x are the navigation rows
        self._navigation_only = self.n_task_vars == 0 and task.n_equations == 0
        self._task_row_scale = np.where(task.length_rows, self.nav.length_ref, 1.0)
        self.dim = self.n_vars - N_EQS - task.n_equations
        self._task_var_names = task.names[:self.n_task_vars]
        self.periodic = np.zeros(self.n_vars, dtype=bool)
        self.periodic[[PHI, SIGMA]] = True
        self.periodic[N_VARS:] = [COORDINATES[n].periodic for n in self._task_var_names]
        self.lower, self.upper = self._domain(robot, margin_floor)
        self.margin_floor = margin_floor

    # ----- the constraint ------------------------------------------------------------
    def residual_and_jacobian(self, x):
        X = x * self.scale
        F, FX = self.nav.residual_and_jacobian(X[:N_VARS])
        F = F / self.row_scale
        FX = FX / self._row_scale_col
        if self._navigation_only:  # the same numbers as the stacking below, without it
            return F, FX * self.scale
        Ft, FtX = self._task(X)
        F_all = np.concatenate([F, Ft])
        J = np.zeros((F_all.size, self.n_vars))
        J[:N_EQS, :N_VARS] = FX
        J[N_EQS:] = FtX
        return F_all, J * self.scale

    def _task(self, X):
        """The task's equations and Jacobian in X, rows in metres scaled by the length."""
        Ft, dC = self.task.equations(X[I_P:I_TAU + 3], X[N_VARS:])
        Jt = np.zeros((len(Ft), self.n_vars))
        Jt[:, I_P:I_TAU + 3] = dC[:, :6]
        Jt[:, N_VARS:] = dC[:, 6:]
        return Ft / self._task_row_scale, Jt / self._task_row_scale[:, None]

    def _domain(self, robot, margin_floor):
        lo = np.full(self.n_vars, -np.inf)
        hi = np.full(self.n_vars, np.inf)
        reach = robot.length_max.max() + np.linalg.norm(robot.platform_anchors, axis=1).max()
        lo[I_P:I_TAU] = robot.base_anchors.min(axis=0) - reach
        hi[I_P:I_TAU] = robot.base_anchors.max(axis=0) + reach
        lo[THETA], hi[THETA] = 0.0, np.pi
        lo[I_G:N_VARS] = self.nav.kappa * np.log(margin_floor)
        for j, name in enumerate(self._task_var_names):
            c = COORDINATES[name]
            if c.bounds is not None and not c.periodic:
                lo[N_VARS + j], hi[N_VARS + j] = c.bounds
        return lo / self.scale, hi / self.scale

    def key(self, x):
        """Pose (and task variables) with angles as (cos, sin): 1-Lipschitz in x."""
        parts = [x[I_P:I_TAU], [np.cos(x[PHI]), np.sin(x[PHI]), x[THETA], np.cos(x[SIGMA]), np.sin(x[SIGMA])]]
        for v, periodic in zip(x[N_VARS:], self.periodic[N_VARS:]):
            parts.append([np.cos(v), np.sin(v)] if periodic else [v])
        return np.concatenate(parts)

    # ----- poses <-> points ----------------------------------------------------------
    def lift(self, p, tau):
        """The scaled point x on the manifold above a feasible pose satisfying the task."""
        X = self.nav.lift(p, tau)
        if self.n_task_vars:
            X = np.concatenate([X, self.task.variables(np.atleast_2d(p), np.atleast_2d(tau))[0]])
        return X / self.scale

    def pose(self, x):
        """(p m, tau rad) of a scaled point."""
        X = x[:I_G] * self.scale[:I_G]
        return X[I_P:I_TAU].copy(), X[I_TAU:I_TAU + 3].copy()

    def margin(self, x):
        """The normalised feasibility margin of a scaled point on M (``nav.margin``)."""
        return self.nav.margin(x[:N_VARS] * self.scale[:N_VARS])
