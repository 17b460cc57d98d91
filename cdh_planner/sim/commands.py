"""Command sources of the simulated robot: each winch's unstretched length (m) and its rate
(m/s) as functions of time (s).

``Trajectory(times, L, V, A)`` is what a ros2_control JointTrajectoryController makes of a
trajectory: with velocities and accelerations, per segment the quintic through both ends'
position, velocity and acceleration (``trajectory.executed.quintic``, the planner's own
model of that controller); with positions only, straight lines between them (constant
velocity per segment, as the controller interpolates positions alone); before the first
point and after the last the end is held. ``hold(L)`` holds lengths; ``ramp(L_from, L_to,
t0, period)`` moves to a streamed setpoint in a straight line over one setpoint period (a
JointGroupPositionController's or a custom driver's setpoints, 50 Hz, reached without a
jump).
"""

import numpy as np

from ..trajectory.executed import quintic


class Trajectory:
    """Unstretched lengths over time: points at ``times`` (N,) s with positions ``L`` (N, m)
    m, and velocities ``V`` (m/s) and accelerations ``A`` (m/s^2), or None (positions only:
    linear interpolation)."""

    def __init__(self, times, L, V=None, A=None):
        self.times = np.atleast_1d(np.asarray(times, dtype=float))
        self.L = np.atleast_2d(np.asarray(L, dtype=float))
        if len(self.times) == 1:     # one point: held
            self.times = np.array([self.times[0], self.times[0] + 1.0])
            self.L = np.vstack([self.L, self.L])
            V = A = None if V is None else np.zeros_like(self.L)
        self.V = None if V is None else np.atleast_2d(np.asarray(V, dtype=float))
        self.A = None if self.V is None else (np.zeros_like(self.L) if A is None else
                                              np.atleast_2d(np.asarray(A, dtype=float)))

    @property
    def end(self):
        """The last point's time (s)."""
        return float(self.times[-1])

    def sample(self, ts):
        """Lengths (M, m) m and rates (M, m) m/s at times ``ts`` (M,) s."""
        ts = np.asarray(ts, dtype=float)
        if self.V is not None:
            pos, vel, _ = quintic(self.times, self.L, self.V, self.A, ts)
            return pos, vel
        k = np.clip(np.searchsorted(self.times, ts, side="right") - 1, 0, len(self.times) - 2)
        h = self.times[k + 1] - self.times[k]
        s = np.clip((ts - self.times[k]) / h, 0.0, 1.0)[:, None]
        pos = self.L[k] + s * (self.L[k + 1] - self.L[k])
        vel = (self.L[k + 1] - self.L[k]) / h[:, None]
        vel[(ts < self.times[0]) | (ts >= self.times[-1])] = 0.0
        return pos, vel


def hold(L, t0=0.0):
    """Lengths L (m,) m held from ``t0`` (s) on."""
    return Trajectory([t0], [L])


def ramp(L_from, L_to, t0, period):
    """From L_from to L_to (m,) m in a straight line over ``period`` s from ``t0`` s, then held."""
    return Trajectory([t0, t0 + period], [L_from, L_to])
