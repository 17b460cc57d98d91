"""Densify: waypoints (task coordinates) until the motion between consecutive ones is
dense-valid, then the PlannedPath through them (quasi-static cable-space timing).
"""

import numpy as np

from ..wrench import band_feasibility
from ..model.pose import quaternion_from_tau
from ..trajectory.path import PlannedPath
from ..trajectory.timing import time_path
from .validity import wrapped

DENSIFY_ROUNDS = 10


class Densify:
    """The densify stage of one Validity and cable limits (m/s, m/s^2)."""

    def __init__(self, validity, max_cable_speed, max_cable_accel):
        self.validity = validity
        self.max_cable_speed, self.max_cable_accel = max_cable_speed, max_cable_accel

    def __call__(self, y):
        """The PlannedPath through y (N, k) made dense, or None if it cannot be."""
        y, verified = self.densify(y)
        return self.planned_path(y, verified)

    def densify(self, y):
        """(y with valid midpoints inserted until every motion between consecutive rows
        (position linear, orientation slerp) is dense-feasible, whether it now is)."""
        v = self.validity
        for _ in range(DENSIFY_ROUNDS):
            p, tau = v.task.pose(y)
            segs = v.segments(p, quaternion_from_tau(tau))
            bad = np.array([k for k, seg in enumerate(segs) if not seg.feasible], dtype=int)
            if bad.size == 0 and all(seg.unresolved == 0 for seg in segs):
                return y, True
            if bad.size == 0:
                break
            mid = wrapped(y[bad] + 0.5 * wrapped(y[bad + 1] - y[bad], v.periodic), v.periodic)
            ok = v.pose(mid)
            if not ok.any():
                break
            y = np.insert(y, bad[ok] + 1, mid[ok], axis=0)
        return y, False

    def planned_path(self, y, verified=False):
        """The PlannedPath through task coordinates y (N, k), or None if the final dense
        check fails (``verified``: y is exactly what ``densify`` just checked densely)."""
        v = self.validity
        p, tau = v.task.pose(y)
        q = quaternion_from_tau(tau)
        f = band_feasibility(v.robot, p, tau)
        if not np.all(f.feasible) or not np.all(v.pose_margins(p, tau)[0] > 0):
            return None
        if not verified and not all(seg.feasible and seg.unresolved == 0
                                    for seg in v.segments(p, q)):
            return None
        n = len(y)
        zeros = np.zeros(f.lengths.shape)
        path = PlannedPath(p=p, quaternion=q, tau=tau, lengths=f.lengths,
                           tension_min=f.tension_min, tension_nominal=f.tension_nominal,
                           tension_max=f.tension_max, margin=f.margin, t=np.zeros(n),
                           velocities=zeros, accelerations=zeros)
        return time_path(path, self.max_cable_speed, self.max_cable_accel)
