"""Time: the dense-valid PlannedPath -> the trajectory that leaves the planner, timed
(quasi-static or with the platform's dynamics, ``trajectory.dynamics.timed_path``) and
checked as a JointTrajectoryController executes it (``trajectory.executed``), with the
path's least margins (``trajectory.clearance.path_margins``) and, with a scene, its least
clearance.
"""

from dataclasses import dataclass

import numpy as np

from ..model.pose import rotation_tt
from ..trajectory import clearance
from ..trajectory.dynamics import timed_path


@dataclass
class Timed:
    """The timing stage's answer: ``path`` (PlannedPath, timed), ``timing`` (the dynamic
    timing or None: quasi-static), ``executed`` (trajectory.executed's report: ``ok``,
    ``reason``), ``least`` (least normalised margin, least tension margin N) of the path
    before timing, ``scene_clearance`` ({least_clearance_m, clearance_binding} over its
    waypoints with a scene, else {})."""

    path: object
    timing: object
    executed: object
    least: tuple
    scene_clearance: dict


def time_stage(robot, path, settings, collision=None, expired=None):
    """Timed of the PlannedPath ``path`` under ``settings`` (PlannerSettings: dynamics,
    max_cable_speed m/s, max_cable_accel m/s^2); ``collision``: the scene's
    CollisionModel or None; ``expired()``: true when the call must end (the executed
    check then stops between its rounds, not passed)."""
    least = clearance.path_margins(robot, path.p, path.quaternion)
    extra = least_clearance(collision, path)
    path, timing, executed = timed_path(robot, path, settings.dynamics, settings.max_cable_speed,
                                        settings.max_cable_accel, collision, expired)
    return Timed(path, timing, executed, least, extra)


def least_clearance(collision, path):
    """{least_clearance_m, clearance_binding} over the path's waypoints (with a scene)."""
    if collision is None:
        return {}
    R = rotation_tt(path.tau)
    k = int(np.argmin(collision.margins(path.p, R)[0]))  # one batch; what binds at the least
    c = collision.clearance(path.p[k], R[k])
    return {"least_clearance_m": c.distance, "clearance_binding": c.binding}
