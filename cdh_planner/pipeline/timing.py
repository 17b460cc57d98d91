"""Time: the dense-valid PlannedPath -> the trajectory that leaves the planner, timed
(quasi-static or with the platform's dynamics, ``trajectory.dynamics.timed_path``) and
checked as a JointTrajectoryController executes it (``trajectory.executed``), with the
path's least margins (``trajectory.clearance.path_margins``).
"""

from dataclasses import dataclass

from ..trajectory import clearance
from ..trajectory.dynamics import timed_path


@dataclass
class Timed:
    """The timing stage's answer: ``path`` (PlannedPath, timed), ``timing`` (the dynamic
    timing or None: quasi-static), ``executed`` (trajectory.executed's report: ``ok``,
    ``reason``), ``least`` (least normalised margin, least tension margin N) of the path
    before timing."""

    path: object
    timing: object
    executed: object
    least: tuple


def time_stage(robot, path, settings):
    """Timed of the PlannedPath ``path`` under ``settings`` (PlannerSettings: dynamics,
    max_cable_speed m/s, max_cable_accel m/s^2)."""
    least = clearance.path_margins(robot, path.p, path.quaternion)
    path, timing, executed = timed_path(robot, path, settings.dynamics, settings.max_cable_speed,
                                        settings.max_cable_accel)
    return Timed(path, timing, executed, least)
