"""A planned platform path with everything a winch controller needs, per waypoint."""

from dataclasses import dataclass

import numpy as np


@dataclass
class PlannedPath:
    """N waypoints. Units: m, rad, N, s. Quaternions are (x, y, z, w).

    Consecutive waypoints are close enough that the motion between them (position linear,
    orientation slerp) is wrench-feasible; ``margin`` is the normalised feasibility margin
    of each waypoint (positive). ``t`` is time from start (s), from the cable-space time
    parameterisation; ``velocities`` / ``accelerations`` are the cable length rates
    (m/s, m/s^2) at the waypoints.
    """

    p: np.ndarray  # (N, 3)
    quaternion: np.ndarray  # (N, 4)
    tau: np.ndarray  # (N, 3) phi, theta, sigma
    lengths: np.ndarray  # (N, m): one column per cable
    tension_min: np.ndarray  # (N, m): one column per cable
    tension_nominal: np.ndarray  # (N, m): one column per cable
    tension_max: np.ndarray  # (N, m): one column per cable
    margin: np.ndarray  # (N,)
    t: np.ndarray  # (N,)
    velocities: np.ndarray  # (N, m): one column per cable
    accelerations: np.ndarray  # (N, m): one column per cable

    def __len__(self):
        return self.p.shape[0]

    def length_m(self):
        """Length of the platform's position path (m)."""
        return float(np.sum(np.linalg.norm(np.diff(self.p, axis=0), axis=1)))
