"""The planner facade: robot + task + settings -> wrench-feasible path (or a reason).

    planner = Planner(robot, task, PlannerSettings(strategy="astar"))
    result = planner.plan(start, goal, progress=callback)   # start/goal: Pose

``plan`` never raises for a well-formed request that cannot be planned: the answer is a
PlanResult with ``success`` False and a ``reason`` (a ``Status``) and ``message``.
Before any atlas is built the direct motion from start to goal is tried (a dense
closed-form check): a safe one is the answer, in milliseconds.
Malformed input (NaN, wrong shapes) raises InputError naming the field. The atlas built
by one query is kept and reused by the next (multi-query) as long as robot and task stay.
"""

import dataclasses
import functools
import math
import time
from dataclasses import dataclass, field
from typing import Callable, Optional

from threadpoolctl import threadpool_limits

from .atlas.charts import Atlas
from .manifold.configuration import ConfigurationConstraint
from .manifold.constraint import TaskConstraint
from .model.pose import Pose
from .pipeline.densify import Densify
from .pipeline.lift import TASK_TOL, Lift  # noqa: F401  (TASK_TOL: API)
from .pipeline.metrics import task_cost, task_costs  # noqa: F401  (task_cost: API)
from .pipeline.route import Route, failure_message
from .pipeline.smooth import Smooth
from .pipeline.timing import time_stage
from .pipeline.validity import CollisionFreeDomain, Validity
from .search.strategies import AUTO, MB, Stop
from .settings import PlannerSettings, check_setting  # noqa: F401  (PlannerSettings: API)
from .status import Status
from .trajectory.dynamics import check_dynamics



@dataclass
class PlanResult:
    success: bool
    reason: Status
    message: str
    strategy: str
    n: int  # manifold dimension
    variables: int  # manifold variables (task coordinates and the lift's unknowns; not cables)
    charts: int
    time_s: float
    cost: float  # path cost in the task's metric (rad, or m for the sphere / free flight)
    path: Optional["PlannedPath"] = None  # noqa: F821  (trajectory.path.PlannedPath)
    stats: dict = field(default_factory=dict)
    # over the waypoints and the motion between them (trajectory.clearance.path_margins)
    least_margin: float = math.nan  # normalised (wrench.band_feasibility)
    least_tension_margin: float = math.nan  # N: min over cables of f - v - fmin, fmax - f - v

    def __post_init__(self):  # one closed vocabulary: a member, never a loose string
        if not isinstance(self.reason, Status):
            raise TypeError(f"PlanResult.reason must be a Status, not {self.reason!r}")


ProgressCallback = Callable[[dict], None]  # called with {"charts": int, "time_s": float, "best_h": float}

def default_strategy(dim, clearance_weight=0.0):
    """A* (shortest on the chart graph) up to 3-D; Greedy Best-First above, where A* must
    close charts of dozens of neighbours each (6-D free flight: measured in the README),
    and under a clearance cost (weight > 0), where A*'s heuristic, the task metric, is far
    below the cost and A* grows most of the component (README, Clearance: the sigma-free
    row times out at 60 s); GBF's route is then optimised by the clearance smoothing."""
    return "astar" if dim <= 3 and clearance_weight == 0 else "gbf"


def default_radius(dim):
    """Chart radius (scaled units) for a manifold of dimension ``dim``: 0.1 up to 3-D
    (the paper's resolution), 0.5 above (6-D free flight: 5x fewer charts per unit of
    motion in each direction, measured in the README's performance section)."""
    return 0.1 if dim <= 3 else 0.5


def planning_manifold(robot, task, margin_floor):
    """The manifold the atlas covers: the paper's navigation manifold for six cables; for
    more, the task's configuration manifold with feasibility as its domain (the closed form
    behind the navigation manifold's slack equations needs J square: docs/more-cables.md)."""
    if len(robot.base_anchors) == 6:
        return TaskConstraint(robot, task, margin_floor=margin_floor)
    return ConfigurationConstraint(robot, task, margin_floor=margin_floor)


class Planner:
    """Wrench-feasible paths for one robot and task (module docstring), by the stages of
    ``pipeline``: lift, route (direct motion or atlas search), smooth, densify, time."""

    def __init__(self, robot, task, settings: Optional[PlannerSettings] = None, scene=None):
        self.robot = robot
        self.task = task
        self.settings = s = (settings or PlannerSettings()).check()
        self.scene = scene  # scene.schema.Scene: collisions join validity (pipeline.validity)
        self.constraint = planning_manifold(robot, task, s.margin_floor)
        self.radius = s.radius or default_radius(self.constraint.dim)
        self.clearance_weight = s.clearance_weight
        check_dynamics(robot, s.dynamics)
        self.pose_cost = task_cost(robot, task, s.cost)
        self.pose_costs = task_costs(robot, task, s.cost)
        pose = self.constraint.pose
        self.length = lambda xa, xb: self.pose_cost(*pose(xa), *pose(xb))
        # the stages; every one asks the same Validity
        self.validity = Validity(robot, task, s.margin_floor, scene,
                                 accuracy=(s.accuracy_position_m, s.accuracy_orientation_rad))
        self.collision = self.validity.collision
        # with a scene, collisions are out of the atlas's domain (no chart centred in one)
        self.atlas = Atlas(self.constraint if self.collision is None
                           else CollisionFreeDomain(self.constraint, self.validity), radius=self.radius)
        self.lift = Lift(self.validity, self.constraint, self.atlas.in_domain)
        self.densify = Densify(self.validity, s.max_cable_speed, s.max_cable_accel)
        self.route = Route(self.constraint, self.atlas, self.validity, self.length,
                           self.clearance_weight, self.radius, self.densify.densify)
        self.smooth = Smooth(self.validity, self.pose_costs, self.clearance_weight)
        # the task metric, or the clearance cost (trajectory.clearance), whose A* heuristic
        # is the metric (a lower bound): Route.heuristic
        self.cost = self.route.cost
        self.strategy = self._strategy(s.strategy)  # the settings'
        self.heuristic = self.route.heuristic(self.strategy)

    def plan(self, start: Pose, goal: Pose, progress: Optional[ProgressCallback] = None,
             cancel=None, tolerance: Optional[float] = None, strategy: Optional[str] = None,
             timeout_s: Optional[float] = None):
        """A PlanResult from ``start`` to ``goal``. ``cancel``: an object with ``is_set()``
        (threading.Event) that stops the search (answer ``canceled``). ``tolerance`` (m or
        rad, > 0; default the settings' ``task_tolerance``): how far start and goal may be off
        the task; within it they are projected onto it, and onto theta = 0 or pi, where phi
        is chosen by the task or the other end (``model.task.end_taus``): one pose plans one
        path, however it is written. ``strategy`` and ``timeout_s`` (s):
        this call's, instead of the settings' (InputError naming them if invalid)."""
        s = self.settings
        if strategy is not None or timeout_s is not None:
            s = dataclasses.replace(s, strategy=s.strategy if strategy is None else strategy,
                                    timeout_s=s.timeout_s if timeout_s is None else timeout_s)
            check_setting("strategy", s.strategy, "strategy")
            check_setting("timeout_s", s.timeout_s, "timeout_s")
        with threadpool_limits(limits=1, user_api="blas"):  # many small solves: threads only hurt
            return self._plan(start, goal, progress, cancel, tolerance, s)

    def _strategy(self, strategy):
        """The search strategy of a call's ``strategy`` setting (auto, or a registered
        strategy's name)."""
        if strategy == AUTO:
            return default_strategy(self.constraint.dim, self.clearance_weight)
        return strategy

    def _plan(self, start, goal, progress, cancel, tolerance, s):
        t0 = time.perf_counter()
        strategy = self._strategy(s.strategy)
        answer = functools.partial(self._answer, t0, strategy)
        points, why = self.lift(start, goal, tolerance or s.task_tolerance)
        if points is None:
            return answer(False, *why)
        stop = Stop(t0 + s.timeout_s, s.max_charts, int(s.max_memory_mb * MB), cancel)
        y, charts, direct, failed = self.route(points, stop, strategy, progress)
        if failed is not None:
            status, message, stats = failed
            return answer(False, status, message or failure_message(
                status, len(self.atlas.charts), s, self.radius), **stats)
        if s.complete:
            self.atlas.chart_at(points["start"])
            self.grow_complete(stop.deadline, cancel)
        path = self._dense_path(y)
        if path is None:
            return answer(False, Status.NO_PATH, "the path could not be made dense-feasible "
                                                 "(a bug: please report the problem file)")
        cost = self._path_cost(path)
        # a cancel or the deadline during the executed check stops it; one that ended the
        # complete growth before it does not: the path found is checked to the end
        expired = stop.expired if stop.expired() is None else None
        timed = time_stage(self.robot, path, s, self.collision, expired)
        if not timed.executed.ok:  # bounded: never hand out a trajectory that was not checked
            why = expired() if expired else None
            if why:  # the check stopped between its rounds
                limit = "a cancel" if why == Status.CANCELED else f"{s.timeout_s:g} s"
                return answer(False, why, f"a path, but its executed check was stopped by "
                                          f"{limit} before it passed: {timed.executed.reason}")
            return answer(False, Status.NOT_EXECUTABLE, "no trajectory a JointTrajectory"
                          f"Controller executes within the limits: {timed.executed.reason}")
        how = "the direct motion" if direct else f"{charts} charts"
        out = answer(True, Status.OK, f"path of {len(timed.path)} waypoints over {how}",
                     cost=cost, path=timed.path, chart_path=charts, direct=direct,
                     timing=timed.timing or "quasi-static", executed=timed.executed.describe(),
                     points_added=timed.executed.added, **timed.scene_clearance)
        out.least_margin, out.least_tension_margin = timed.least
        return out

    def _dense_path(self, y):
        """The dense-feasible PlannedPath of the smoothed route y, else of y itself
        (smoothing can cut a corner through a thin gap of C), else None."""
        for candidate in (self.smooth(y), y):
            path = self.densify(candidate)
            if path is not None:
                return path
        return None

    def _path_cost(self, path):
        """The task-metric length of a PlannedPath (rad or m)."""
        return float(sum(self.pose_cost(path.p[k], path.tau[k], path.p[k + 1], path.tau[k + 1])
                         for k in range(len(path) - 1)))

    def _answer(self, t0, strategy, ok, reason, message, cost=math.nan, path=None, **stats):
        c = self.constraint
        return PlanResult(ok, reason, message, strategy, c.dim, c.n_vars, len(self.atlas.charts),
                          time.perf_counter() - t0, cost, path, stats)

    def grow_complete(self, deadline=None, cancel=None):
        """Grow every open chart until the atlas covers the start's component (or the
        deadline / chart limit / ``cancel``): the search's "complete" mode."""
        i = 0
        while i < len(self.atlas.charts) and len(self.atlas.charts) < self.settings.max_charts:
            if (deadline is not None and time.perf_counter() > deadline) or \
                    (cancel is not None and cancel.is_set()):
                return False
            if self.atlas.charts[i].closed:
                i += 1
            else:
                self.atlas.expand(i)
        return i >= len(self.atlas.charts)
