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

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from threadpoolctl import threadpool_limits

from .atlas.atlas import Atlas
from .errors import InputError
from .feasibility import evaluate
from .manifold.constraint import TaskConstraint
from .model.pose import (Pose, quaternion_from_tau, rotation_angle_between, rotation_tt,
                         tau_from_rotation, wrap_angle)
from .search.search import MB, Stop, run
from .settings import COSTS, PlannerSettings  # noqa: F401  (PlannerSettings: part of this API)
from .status import Status
from .trajectory.path import PlannedPath
from .trajectory.timing import time_path
from .trajectory.verify import SlerpPath, TaskLinePath, check_motion, check_path



@dataclass
class PlanResult:
    success: bool
    reason: Status
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

TASK_TOL = 1e-6  # m / rad: how far a start or goal may be off the task's constraint
SMOOTHING_ROUNDS = 12
DENSIFY_ROUNDS = 10
CHORD_SAMPLES = 9  # poses probed between two link points before the dense check
COARSE_SAMPLES = 17  # a direct motion is first checked at these few points (a cheap "no")
DIRECT_STEP_M, DIRECT_STEP_RAD = 5e-3, np.deg2rad(1.0)  # waypoint spacing on a direct motion


def default_strategy(dim):
    """A* (shortest on the chart graph) up to 3-D; Greedy Best-First above, where A* must
    close charts of dozens of neighbours each (6-D free flight: measured in the README)."""
    return "astar" if dim <= 3 else "gbf"


def default_radius(dim):
    """Chart radius (scaled units) for a manifold of dimension ``dim``: 0.1 up to 3-D
    (the paper's resolution), 0.5 above (6-D free flight: 5x fewer charts per unit of
    motion in each direction, measured in the README's performance section)."""
    return 0.1 if dim <= 3 else 0.5


class Planner:
    """Wrench-feasible paths for one robot and task (module docstring)."""

    def __init__(self, robot, task, settings: Optional[PlannerSettings] = None):
        self.robot = robot
        self.task = task
        self.settings = (settings or PlannerSettings()).check()
        s = self.settings
        self.constraint = TaskConstraint(robot, task, margin_floor=s.margin_floor)
        self.radius = s.radius or default_radius(self.constraint.dim)
        self.strategy = default_strategy(self.constraint.dim) if s.strategy == "auto" else s.strategy
        self.atlas = Atlas(self.constraint, radius=self.radius)
        self.pose_cost = task_cost(robot, task, self.settings.cost)
        pose = self.constraint.pose
        self.cost = lambda xa, xb: self.pose_cost(*pose(xa), *pose(xb))
        self._edge_costs = {}  # (i, j), i < j -> task cost between the chart centres

    # ----- the query -------------------------------------------------------------------
    def plan(self, start: Pose, goal: Pose, progress: Optional[ProgressCallback] = None,
             cancel=None):
        """A PlanResult from ``start`` to ``goal``. ``cancel``: an object with ``is_set()``
        (threading.Event) that stops the search (answer ``canceled``)."""
        with threadpool_limits(limits=1, user_api="blas"):  # many small solves: threads only hurt
            return self._plan(start, goal, progress, cancel)

    def _plan(self, start, goal, progress, cancel):
        t0 = time.perf_counter()
        s = self.settings
        c = self.constraint

        def answer(ok, reason, message, cost=math.nan, path=None, **stats):
            return PlanResult(ok, reason, message, self.strategy, c.dim, c.n_vars,
                              len(self.atlas.charts), time.perf_counter() - t0, cost, path, stats)

        points = {}
        for label, pose in (("start", start), ("goal", goal)):
            x, why = self._lift(label, pose)
            if x is None:
                return answer(False, why[0], why[1])
            points[label] = x
        ys = self._task_coords([points["start"], points["goal"]])
        stop = Stop(t0 + s.timeout_s, s.max_charts, int(s.max_memory_mb * MB), cancel)
        if self._direct_ok(ys[0], ys[1]):
            y, charts, direct = self._direct_points(ys[0], ys[1]), 0, True
        else:
            out = run(self.atlas, points["start"], points["goal"], self.cost, stop, self.strategy,
                      self._direct_x, progress, self._edge_costs, self._link_ok)
            if out.status != Status.OK:
                return answer(False, out.status, _failure_message(out.status, len(self.atlas.charts),
                                                                  s, self.radius),
                              expanded=out.expanded)
            y, charts, direct = self._route_coords(out), len(out.charts), False
        if s.complete:
            self.atlas.chart_at(points["start"])
            self.grow_complete(stop.deadline)
        for y in (self._smooth(y), y):  # smoothing can cut a corner through a thin gap of C
            y, verified = self._densify(y)
            path = self._planned_path(y, verified)
            if path is not None:
                break
        if path is None:
            return answer(False, Status.NO_PATH, "the path could not be made dense-feasible "
                                                 "(a bug: please report the problem file)")
        cost = float(sum(self.pose_cost(path.p[k], path.tau[k], path.p[k + 1], path.tau[k + 1])
                         for k in range(len(path) - 1)))
        how = "the direct motion" if direct else f"{charts} charts"
        return answer(True, Status.OK, f"path of {len(path)} waypoints over {how}", cost=cost,
                      path=path, chart_path=charts, direct=direct)

    def grow_complete(self, deadline=None):
        """Grow every open chart until the atlas covers the start's component (or the
        deadline / chart limit): the search's "complete" mode."""
        i = 0
        while i < len(self.atlas.charts) and len(self.atlas.charts) < self.settings.max_charts:
            if deadline is not None and time.perf_counter() > deadline:
                return False
            if self.atlas.charts[i].closed:
                i += 1
            else:
                self.atlas.expand(i)
        return i >= len(self.atlas.charts)

    # ----- direct motions -----------------------------------------------------------------
    def _direct_motion(self, y):
        """The direct motion through task coordinates y (N, k): position linear and
        orientation slerp in free flight (what a controller executes), straight lines in a
        task's coordinates otherwise (slerp would leave the task)."""
        y = np.array(y, dtype=float)
        if self.task.slerp:
            p, tau = self.task.pose(y)
            return SlerpPath(p, quaternion_from_tau(tau))
        per = self._periodic_mask()
        y[1:, per] = y[0, per] + np.cumsum(wrap_angle(np.diff(y[:, per], axis=0)), axis=0)  # short arcs
        return TaskLinePath(self.task, y)

    def _probe(self, y, n):
        """Are n evenly spaced poses of every direct motion between the rows of y feasible
        with margin above the floor? (one vectorised closed-form call)"""
        motion = self._direct_motion(y)
        seg = np.repeat(np.arange(motion.n_segments), n)
        s = np.tile(np.linspace(0.0, 1.0, n), motion.n_segments)
        p, R = motion(seg, s)
        return bool(np.all(evaluate(self.robot, p, R=R).margin >= self.settings.margin_floor))

    def _direct_ok(self, ya, yb):
        """Is the direct motion ya -> yb dense-feasible with margin above the floor? A few
        points first (most unsafe motions fail there), then the dense check."""
        y = np.array([ya, yb])
        if not (self._probe(y, COARSE_SAMPLES) and self._probe(y, 8 * COARSE_SAMPLES)):
            return False
        seg = check_path(self.robot, self._direct_motion(y))[0]
        return seg.feasible and seg.unresolved == 0 and seg.worst.margin >= self.settings.margin_floor

    def _direct_x(self, xa, xb):
        ya, yb = self._task_coords([xa, xb])
        return self._direct_ok(ya, yb)

    def _direct_points(self, ya, yb):
        """Task coordinates along the direct motion ya -> yb, DIRECT_STEP_M / _RAD apart."""
        motion = self._direct_motion([ya, yb])
        dp, da = motion.speeds()
        n = int(max(2, math.ceil(max(dp[0] / DIRECT_STEP_M, da[0] / DIRECT_STEP_RAD)) + 1))
        s = np.linspace(0.0, 1.0, n)
        if isinstance(motion, TaskLinePath):  # a line in the task's own coordinates
            y = motion.coords[0] + s[:, None] * (motion.coords[1] - motion.coords[0])
        else:  # slerp: free-flight coordinates are (p, tau), phi continued from the start
            p, R = motion(np.zeros(n, dtype=int), s)
            y = self.task.coords(p, tau_from_rotation(R, phi_hint=float(ya[3])))
        y[0], y[-1] = ya, yb
        return y

    def _link_ok(self, xs):
        """Are the points joining two charts one motion of C? Large charts can link two
        sheets of M across a thin gap of C; a few poses between each pair show the gap
        (the dense check of the whole path comes later)."""
        return self._probe(self._task_coords(xs), CHORD_SAMPLES)

    def _route_coords(self, out):
        """Task coordinates of the search's points, direct motions sampled on the way."""
        y = self._task_coords(out.points)
        parts = [y[:1]]
        for k in range(len(y) - 1):
            parts.append(self._direct_points(y[k], y[k + 1])[1:] if k in out.direct else y[k + 1:k + 2])
        return np.concatenate(parts)

    # ----- start and goal ----------------------------------------------------------------
    def _lift(self, label, pose):
        """(x on M, None) or (None, (reason, message))."""
        p = _finite_vector(f"{label}.p", pose.p, 3)
        tau = _finite_vector(f"{label}.tau", pose.tau, 3)
        off = float(self.task.residual(p[None], tau[None])[0]) if hasattr(self.task, "residual") else 0.0
        if off > TASK_TOL:
            return None, ("invalid", f"{label} pose is off the {self.task.type} task by "
                                     f"{off:.3g} (m or rad): {_describe(p, tau)}")
        p, tau = (a[0] for a in self.task.pose(self.task.coords(p[None], tau[None])))
        f = evaluate(self.robot, p[None], tau[None])
        if not f.feasible[0]:
            return None, (f"{label}_infeasible", f"{label} pose is not wrench-feasible: "
                          f"{f.binding[0]} violated (margin {f.margin[0]:.3g}) at {_describe(p, tau)}")
        x = self.constraint.lift(p, tau)
        if not self.atlas.in_domain(x):
            return None, (f"{label}_infeasible", f"{label} pose is feasible but closer to the "
                          f"boundary of C than the planner's margin floor "
                          f"({self.settings.margin_floor:g}): {_describe(p, tau)}")
        return x, None

    # ----- smoothing and densification in task coordinates ------------------------------
    # M is the graph of the (closed-form) lift over the feasible poses of the task, so a
    # point of M is a task coordinate vector y whose pose is feasible: moving y and checking
    # feasibility keeps every point on M, vectorised over the whole path.
    def _task_coords(self, xs):
        p, tau = self._pose_arrays(xs)
        return self.task.coords(p, tau)

    def _periodic_mask(self):
        return np.array(self.task.periodic, dtype=bool)

    def _feasible(self, y):
        """Which task coordinate rows (N, k) are feasible with margin above the floor."""
        p, tau = self.task.pose(y)
        return evaluate(self.robot, p, tau).margin >= self.settings.margin_floor

    def _smooth(self, y):
        """Laplacian smoothing of the interior points (Jacobi, half steps); a moved point
        that would not be feasible stays where it was."""
        per = self._periodic_mask()
        y = y.copy()
        if len(y) < 3:
            return y
        for _ in range(SMOOTHING_ROUNDS):
            lap = 0.5 * (_wrapped(y[:-2] - y[1:-1], per) + _wrapped(y[2:] - y[1:-1], per))
            trial = _wrapped(y[1:-1] + 0.5 * lap, per)
            ok = self._feasible(trial)
            y[1:-1][ok] = trial[ok]
        return y

    def _densify(self, y):
        """Insert feasible midpoints (task coordinates) until the motion between consecutive
        waypoints (position linear, orientation slerp) is dense-feasible."""
        per = self._periodic_mask()
        for _ in range(DENSIFY_ROUNDS):
            p, tau = self.task.pose(y)
            segs = check_motion(self.robot, p, quaternion_from_tau(tau))
            bad = np.array([k for k, seg in enumerate(segs) if not seg.feasible], dtype=int)
            if bad.size == 0 and all(seg.unresolved == 0 for seg in segs):
                return y, True
            if bad.size == 0:
                break
            mid = _wrapped(y[bad] + 0.5 * _wrapped(y[bad + 1] - y[bad], per), per)
            ok = self._feasible(mid)
            if not ok.any():
                break
            y = np.insert(y, bad[ok] + 1, mid[ok], axis=0)
        return y, False

    def _pose_arrays(self, xs):
        poses = [self.constraint.pose(x) for x in xs]
        return np.array([a for a, _ in poses]), np.array([b for _, b in poses])

    def _planned_path(self, y, verified=False):
        """The PlannedPath through task coordinates y (N, k), or None if the final dense
        check fails (``verified``: y is exactly what ``_densify`` just checked densely)."""
        p, tau = self.task.pose(y)
        q = quaternion_from_tau(tau)
        f = evaluate(self.robot, p, tau)
        if not np.all(f.feasible):
            return None
        if not verified and not all(seg.feasible and seg.unresolved == 0
                                    for seg in check_motion(self.robot, p, q)):
            return None
        n = len(y)
        zeros = np.zeros((n, 6))
        path = PlannedPath(p=p, quaternion=q, tau=tau, lengths=f.lengths,
                           tension_min=f.tension_min, tension_nominal=f.tension_nominal,
                           tension_max=f.tension_max, margin=f.margin, t=np.zeros(n),
                           velocities=zeros, accelerations=zeros)
        return time_path(path, self.settings.max_cable_speed, self.settings.max_cable_accel)


def _wrapped(d, periodic):
    """Rows of task coordinates with the periodic columns wrapped to [-pi, pi)."""
    d = d.copy()
    d[:, periodic] = wrap_angle(d[:, periodic])
    return d


# ----- task metrics ------------------------------------------------------------------------
def task_cost(robot, task, kind="auto"):
    """cost(p_a, tau_a, p_b, tau_b) between two poses (m, rad) of ``kind`` (COSTS), one of
    the task's ``costs``: ``so3`` the SO(3) geodesic (rad, the paper's for orientation
    slices), ``se3`` |dp| + L |angle| (m, L = mean platform anchor radius), or the task's
    own (the sphere's ``great_circle``). ``auto``: the task's ``default_cost``."""
    kind = task.default_cost if kind == "auto" else kind
    if kind not in COSTS:
        raise InputError("cost", kind, f"expected one of {', '.join(COSTS)}")
    if kind not in task.costs:
        raise InputError("cost", kind, f"not a cost of the {task.describe()} (its costs: "
                                       f"{', '.join(task.costs)})")
    L = float(np.mean(np.linalg.norm(robot.platform_anchors, axis=1)))

    def angle(ta, tb):
        return float(rotation_angle_between(rotation_tt(ta), rotation_tt(tb)))

    if kind == "so3":
        return lambda pa, ta, pb, tb: angle(ta, tb)
    if kind == "se3":
        return lambda pa, ta, pb, tb: float(np.linalg.norm(pb - pa)) + L * angle(ta, tb)
    return task.own_cost(kind)


# ----- small helpers -------------------------------------------------------------------------
def _finite_vector(name, v, n):
    try:
        a = np.asarray(v, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(name, v, f"expected {n} numbers") from None
    if a.shape != (n,):
        raise InputError(name, np.asarray(v).tolist(), f"expected {n} numbers")
    if not np.all(np.isfinite(a)):
        raise InputError(name, a.tolist(), "must be finite numbers")
    return a


def _describe(p, tau):
    return (f"p = [{', '.join(f'{v:.4f}' for v in p)}] m, "
            f"tau = [{', '.join(f'{v:.4f}' for v in tau)}] rad")


def _failure_message(status, charts, s, radius):
    """What a search that ended with ``status`` (not OK) means, for the user."""
    messages = {
        Status.NO_PATH: f"no path at resolution r = {radius:g}: a connected component of an end "
                        f"is exhausted after {charts} charts",
        Status.TIMEOUT: f"no path found within {s.timeout_s:g} s ({charts} charts)",
        Status.CHART_LIMIT: f"no path found within the chart limit ({s.max_charts} charts)",
        Status.RESOURCE_LIMIT: f"no path found within the memory limit ({s.max_memory_mb:g} MiB, "
                               f"{charts} charts)",
        Status.CANCELED: f"canceled after {charts} charts",
    }
    return messages[status]
