"""The planner facade: robot + task + settings -> wrench-feasible path (or a reason).

    planner = Planner(robot, task, PlannerSettings(strategy="astar"))
    result = planner.plan(start, goal, progress=callback)   # start/goal: Pose

``plan`` never raises for a well-formed request that cannot be planned: the answer is a
PlanResult with ``success`` False and a ``reason`` (one of REASONS) and ``message``.
Malformed input (NaN, wrong shapes) raises InputError naming the field. The atlas built
by one query is kept and reused by the next (multi-query) as long as robot and task stay.
"""

from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

REASONS = (
    "ok",                # success
    "start_infeasible",  # start pose not wrench-feasible (or off the task)
    "goal_infeasible",   # goal pose not wrench-feasible (or off the task)
    "no_path",           # the atlas component of the start is exhausted: no path at this resolution
    "timeout",           # settings.timeout_s elapsed
    "chart_limit",       # settings.max_charts reached
    "invalid",           # request inconsistent with the task (e.g. off the sphere)
)


@dataclass(frozen=True)
class Pose:
    """Platform pose: position ``p`` (3,) m in the base frame, ``tau`` = (phi, theta, sigma) rad."""

    p: np.ndarray
    tau: np.ndarray


@dataclass
class PlannerSettings:
    """``radius``: chart radius in the atlas' scaled units (about radians of platform
    motion); ``timeout_s`` s; ``max_charts``; ``complete``: keep growing the atlas to the
    whole component after reaching the goal; winch limits for the time parameterisation
    (m/s, m/s^2)."""

    strategy: str = "astar"
    radius: float = 0.1
    timeout_s: float = 60.0
    max_charts: int = 100_000
    complete: bool = False
    margin_floor: float = 1e-3
    max_cable_speed: float = 0.05
    max_cable_accel: float = 0.2


@dataclass
class PlanResult:
    success: bool
    reason: str
    message: str
    strategy: str
    n: int  # manifold dimension
    m: int  # number of variables
    charts: int
    time_s: float
    cost: float  # path cost in the task's metric (rad, or m for the sphere / free flight)
    path: Optional["PlannedPath"] = None  # noqa: F821  (trajectory.path.PlannedPath)
    stats: dict = field(default_factory=dict)


ProgressCallback = Callable[[dict], None]  # called with {"charts": int, "time_s": float, "best_h": float}
