"""Smooth: the route's waypoints (task coordinates y (N, k)) moved to a shorter path, or
under a clearance weight w > 0 down the clearance cost (``trajectory.clearance``); a
waypoint whose move would not be a valid pose stays where it was. The ends never move.
"""

import numpy as np

from ..model.task import COORDINATES
from ..trajectory import clearance
from ..ports import solve_banded
from .validity import wrapped

SMOOTHING_ROUNDS = 12
# Clearance: the waypoints are resampled at most CLEARANCE_STEP_M / _RAD apart and moved
# while the clearance cost goes down.
CLEARANCE_STEP_M, CLEARANCE_STEP_RAD = 1e-2, np.deg2rad(2.0)
CLEARANCE_ITERATIONS = 40
CLEARANCE_STEPS = (1.0, 0.5, 0.25, 0.125, 0.0625)  # step fractions tried (line search)
CLEARANCE_TOL = 1e-4  # stop when an iteration lowers the cost by less than this fraction
CLEARANCE_FD = 1e-5  # finite-difference step of the margin gradient (task coordinates)


class Smooth:
    """The smoothing stage of one Validity (module docstring)."""

    def __init__(self, validity, pose_costs, clearance_weight):
        """``pose_costs(pa, ta, pb, tb)``: the task metric between poses, vectorised."""
        self.validity, self.pose_costs, self.weight = validity, pose_costs, clearance_weight

    def __call__(self, y):
        return self.laplacian(y) if self.weight == 0 else self.clearance(y)

    def laplacian(self, y):
        """Laplacian smoothing of the interior points (Jacobi, half steps); a moved point
        that would not be valid stays where it was."""
        per = self.validity.periodic
        y = y.copy()
        if len(y) < 3:
            return y
        for _ in range(SMOOTHING_ROUNDS):
            lap = 0.5 * (wrapped(y[:-2] - y[1:-1], per) + wrapped(y[2:] - y[1:-1], per))
            trial = wrapped(y[1:-1] + 0.5 * lap, per)
            ok = self.validity.pose(trial)
            y[1:-1][ok] = trial[ok]
        return y

    def clearance(self, y):
        """Smoothing under the clearance cost J = sum of length (1 + w mean phi) over the
        segments: the waypoints are spaced evenly (``resample``), then moved by damped
        Newton steps on J (``newton_step``), all at once. The step is halved until J
        (task-metric lengths, margins from the closed form) goes down; waypoints that would
        fall below the margin floor stay. J never increases: smoothing cannot pull the path
        back to the boundary for length it is not worth."""
        y = self.resample(y)
        if len(y) < 3:
            return y
        margin = self.validity.margins(y)
        cost = self.cost(y, margin)
        for _ in range(CLEARANCE_ITERATIONS):
            step = self.newton_step(y, margin)
            found = self._line_search(y, margin, cost, step)
            if found is None:
                break
            improved = cost - found[2] > CLEARANCE_TOL * cost
            y, margin, cost = found
            if not improved:
                break
        return y

    def cost(self, y, margin):
        """The clearance cost J of the waypoints y (N, k) of ``margin`` (N,)."""
        return float(np.sum(clearance.segment_costs(self.lengths(y[:-1], y[1:]), margin,
                                                    self.weight)))

    def newton_step(self, y, margin):
        """The damped Newton step (N - 2, k) of the interior waypoints on J. The model, in
        task coordinates: each segment a spring of stiffness rho / length (rho its
        clearance density), each waypoint pushed by w times its segments' mean length times
        the gradient of phi across the path (central differences), damped by the square of
        that gradient (phi = -ln m + c, whose Hessian is about grad phi grad phi^T). One
        tridiagonal solve."""
        w, per = self.weight, self.validity.periodic
        d = wrapped(np.diff(y, axis=0), per)
        seg = np.maximum(np.linalg.norm(d, axis=1), 1e-12)
        ph = clearance.phi(margin)
        rho = 1.0 + w * 0.5 * (ph[:-1] + ph[1:])
        gphi = self._phi_gradient(y[1:-1])
        tangent = d[1:] / seg[1:, None] + d[:-1] / seg[:-1, None]
        tangent /= np.maximum(np.linalg.norm(tangent, axis=1), 1e-12)[:, None]
        gphi -= np.sum(gphi * tangent, axis=1)[:, None] * tangent  # across the path only
        reach = 0.5 * (seg[:-1] + seg[1:])
        grad = (rho[:-1, None] * d[:-1] / seg[:-1, None] - rho[1:, None] * d[1:] / seg[1:, None]
                + w * reach[:, None] * gphi)
        stiff = rho / seg
        band = np.zeros((3, len(y) - 2))
        band[1] = stiff[:-1] + stiff[1:] + w * reach * np.sum(gphi ** 2, axis=1)
        band[0, 1:] = -stiff[1:-1]
        band[2, :-1] = -stiff[1:-1]
        return solve_banded((1, 1), band, -grad)

    def _phi_gradient(self, inner):
        """Central-difference gradient of phi(margin) at the rows ``inner`` (n, k)."""
        dim = inner.shape[1]
        eye = np.eye(dim) * CLEARANCE_FD
        probe = (inner[:, None, :] + np.stack([eye, -eye])[:, None]).reshape(-1, dim)
        g = clearance.phi(self.validity.margins(wrapped(probe, self.validity.periodic)))
        g = g.reshape(2, len(inner), dim)
        return (g[0] - g[1]) / (2 * CLEARANCE_FD)

    def _line_search(self, y, margin, cost, step):
        """(y, margin, cost) of the first step fraction that lowers J, else None."""
        lo, hi = self.coordinate_bounds()
        inner = y[1:-1]
        for alpha in CLEARANCE_STEPS:
            trial = np.clip(wrapped(inner + alpha * step, self.validity.periodic), lo, hi)
            m_t = self.validity.margins(trial)
            keep = m_t < self.validity.margin_floor
            trial[keep], m_t[keep] = inner[keep], margin[1:-1][keep]
            y_t = np.concatenate([y[:1], trial, y[-1:]])
            m_all = np.concatenate([margin[:1], m_t, margin[-1:]])
            c_t = self.cost(y_t, m_all)
            if c_t < cost:
                return y_t, m_all, c_t
        return None

    def resample(self, y):
        """Task coordinates y (N, k) resampled evenly along their polyline (straight in y),
        at most CLEARANCE_STEP_M / _RAD apart in the pose; the ends kept."""
        per = self.validity.periodic
        if len(y) < 2:
            return y
        dp, da = self.validity.direct_motion(y).speeds()
        u = np.concatenate([[0.0], np.cumsum(np.maximum(dp / CLEARANCE_STEP_M, da / CLEARANCE_STEP_RAD))])
        n = max(1, int(np.ceil(u[-1])))
        t = np.linspace(0.0, u[-1], n + 1)
        k = np.clip(np.searchsorted(u, t, side="right") - 1, 0, len(y) - 2)
        frac = np.where(u[k + 1] > u[k], (t - u[k]) / np.maximum(u[k + 1] - u[k], 1e-300), 0.0)
        out = wrapped(y[k] + frac[:, None] * wrapped(y[k + 1] - y[k], per), per)
        out[0], out[-1] = y[0], y[-1]
        return out

    def coordinate_bounds(self):
        """(lo, hi) of each task coordinate: its natural bounds if it is not periodic
        (theta in [0, pi], the sphere's alpha2), else unbounded."""
        bounds = [COORDINATES[n].bounds if COORDINATES[n].bounds and not COORDINATES[n].periodic
                  else (-np.inf, np.inf) for n in self.validity.task.names]
        return np.array([b[0] for b in bounds]), np.array([b[1] for b in bounds])

    def lengths(self, ya, yb):
        """Task-metric lengths between task coordinate rows ya, yb (N, k) (the path cost)."""
        task = self.validity.task
        pa, ta = task.pose(ya)
        pb, tb = task.pose(yb)
        return self.pose_costs(pa, ta, pb, tb)
