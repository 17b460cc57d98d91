"""The task's configuration manifold for robots with more than six cables, in the scaled
variables the atlas uses (docs/more-cables.md, "Planning with m > 6 cables").

The navigation manifold (``navigation.py``) encodes wrench feasibility by slack equations on
the closed form's per-cable f0 +- v, which needs J square. With m > 6 there is no such
smooth per-cable closed form, so the manifold here is the task's configuration manifold

    X = [p (3, m) | tau (3, rad) | the task's variables],   F = the task's equations

(free flight: no equation, n = 6), and wrench feasibility is the atlas's domain: a point
is inside when its pose's margin (``wrench.band_margin``: the tension rule's band within the limits) is
at least the margin floor, as the slack variables' lower bounds are on the navigation
manifold. The atlas ends a chart where a new point would leave that domain.

Same duck type as ``constraint.TaskConstraint`` (the atlas's, the planner's).
"""

import numpy as np

from ..model.task import COORDINATES
from ..wrench import band_margin
from .constraint import PHI, SIGMA, THETA

N_POSE = 6  # p (3) and tau (3): the first variables of X


class ConfigurationConstraint:
    """F(x) = 0 of the task's equations on [pose | task variables], scaled; the domain is
    the box of the navigation manifold's pose bounds and the feasibility predicate
    ``inside`` (module docstring)."""

    def __init__(self, robot, task, margin_floor=1e-3):
        self.robot, self.task = robot, task
        self.margin_floor = margin_floor
        self.n_task_vars = task.n_vars
        self.n_vars = N_POSE + self.n_task_vars
        self.dim = self.n_vars - task.n_equations
        # lengths in platform radii, as the navigation manifold's pose (a chart radius reads
        # as radians of platform motion)
        self.length_ref = float(np.mean(np.linalg.norm(robot.platform_anchors, axis=1))) or 0.1
        self.scale = np.ones(self.n_vars)
        self.scale[:3] = self.length_ref
        self._task_row_scale = np.where(task.length_rows, self.length_ref, 1.0)
        names = task.names[:self.n_task_vars]
        self.periodic = np.zeros(self.n_vars, dtype=bool)
        self.periodic[[PHI, SIGMA]] = True
        self.periodic[N_POSE:] = [COORDINATES[n].periodic for n in names]
        self.lower, self.upper = self._domain(robot, names)

    def _domain(self, robot, names):
        """The box: positions within reach of the base anchors, theta in [0, pi], the task
        variables' bounds (scaled)."""
        lo = np.full(self.n_vars, -np.inf)
        hi = np.full(self.n_vars, np.inf)
        reach = robot.length_max.max() + np.linalg.norm(robot.platform_anchors, axis=1).max()
        lo[:3] = robot.base_anchors.min(axis=0) - reach
        hi[:3] = robot.base_anchors.max(axis=0) + reach
        lo[THETA], hi[THETA] = 0.0, np.pi
        for j, name in enumerate(names):
            c = COORDINATES[name]
            if c.bounds is not None and not c.periodic:
                lo[N_POSE + j], hi[N_POSE + j] = c.bounds
        return lo / self.scale, hi / self.scale

    def residual_and_jacobian(self, x):
        """The task's equations (rows in metres over the length scale) and their Jacobian
        in the scaled variables."""
        X = x * self.scale
        C, dC = self.task.equations(X[:N_POSE], X[N_POSE:])
        C = C / self._task_row_scale
        dC = dC / self._task_row_scale[:, None]
        return C, dC * self.scale

    def inside(self, x):
        """Is the pose of x wrench-feasible with margin at least the floor? (the domain's
        predicate part; the box is ``lower``, ``upper``)"""
        return self.margin(x) >= self.margin_floor

    def inside_many(self, xs):
        """``inside`` of the rows of xs (N, n_vars), in one call: (N,) bool."""
        X = np.asarray(xs)[:, :N_POSE] * self.scale[:N_POSE]
        return band_margin(self.robot, X[:, :3], X[:, 3:N_POSE]) >= self.margin_floor

    def key(self, x):
        """Pose (and task variables) with angles as (cos, sin): 1-Lipschitz in x."""
        parts = [x[:3], [np.cos(x[PHI]), np.sin(x[PHI]), x[THETA], np.cos(x[SIGMA]), np.sin(x[SIGMA])]]
        for v, periodic in zip(x[N_POSE:], self.periodic[N_POSE:]):
            parts.append([np.cos(v), np.sin(v)] if periodic else [v])
        return np.concatenate(parts)

    def lift(self, p, tau):
        """The scaled point x above a pose (p m, tau rad) on the task."""
        X = np.concatenate([np.asarray(p, dtype=float), np.asarray(tau, dtype=float)])
        if self.n_task_vars:
            X = np.concatenate([X, self.task.variables(np.atleast_2d(p), np.atleast_2d(tau))[0]])
        return X / self.scale

    def pose(self, x):
        """(p m, tau rad) of a scaled point."""
        X = x[:N_POSE] * self.scale[:N_POSE]
        return X[:3].copy(), X[3:N_POSE].copy()

    def margin(self, x):
        """The normalised margin the planner asks (``wrench.band_margin``) of the pose of x."""
        p, tau = self.pose(x)
        return float(band_margin(self.robot, p[None], tau[None])[0])
