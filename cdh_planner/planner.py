"""The planner facade: robot + task + settings -> wrench-feasible path (or a reason).

    planner = Planner(robot, task, PlannerSettings(strategy="astar"))
    result = planner.plan(start, goal, progress=callback)   # start/goal: Pose

``plan`` never raises for a well-formed request that cannot be planned: the answer is a
PlanResult with ``success`` False and a ``reason`` (one of REASONS) and ``message``.
Malformed input (NaN, wrong shapes) raises InputError naming the field. The atlas built
by one query is kept and reused by the next (multi-query) as long as robot and task stay.
"""

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from .atlas.atlas import Atlas
from .errors import InputError
from .feasibility import evaluate
from .manifold.constraint import TaskConstraint
from .model.pose import quaternion_from_tau, rotation_angle_between, rotation_tt, wrap_angle
from .model.task import PERIODIC, SliceTask, SphereTask
from .search.search import STRATEGIES, AtlasSearch
from .trajectory.path import PlannedPath
from .trajectory.timing import time_path
from .trajectory.verify import check_motion

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
    cost: str = "auto"  # one of COSTS; auto: the paper's choice for the task
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

COSTS = ("auto", "so3", "great_circle", "se3")
TASK_TOL = 1e-6  # m / rad: how far a start or goal may be off the task's constraint
EDGE_RETRIES = 20  # chart-graph edges found not to carry a path before giving up
SMOOTHING_ROUNDS = 12
DENSIFY_ROUNDS = 10
POINT_SPACING = 0.25  # path points per edge: one per this fraction of the chart radius


class Planner:
    """Wrench-feasible paths for one robot and task (module docstring)."""

    def __init__(self, robot, task, settings: Optional[PlannerSettings] = None):
        self.robot = robot
        self.task = task
        self.settings = settings or PlannerSettings()
        _check_settings(self.settings)
        s = self.settings
        self.constraint = TaskConstraint(robot, task, margin_floor=s.margin_floor)
        self.atlas = Atlas(self.constraint, radius=s.radius)
        self.pose_cost = task_cost(robot, task, self.settings.cost)
        pose = self.constraint.pose
        self.cost = lambda xa, xb: self.pose_cost(*pose(xa), *pose(xb))
        self._edge_costs = {}  # (i, j), i < j -> task cost between the chart centres
        self._edges = {}  # (i, j), i < j -> points on M from chart i to chart j (multi-query)

    # ----- the query -------------------------------------------------------------------
    def plan(self, start: Pose, goal: Pose, progress: Optional[ProgressCallback] = None):
        t0 = time.perf_counter()
        s = self.settings
        c = self.constraint

        def answer(ok, reason, message, charts=None, cost=math.nan, path=None, **stats):
            return PlanResult(ok, reason, message, s.strategy, c.dim, c.n_vars,
                              len(self.atlas.charts) if charts is None else charts,
                              time.perf_counter() - t0, cost, path, stats)

        points = {}
        for label, pose in (("start", start), ("goal", goal)):
            x, why = self._lift(label, pose)
            if x is None:
                return answer(False, why[0], why[1])
            points[label] = x
        i_start, i_goal = self._chart_at(points["start"]), self._chart_at(points["goal"])
        deadline = t0 + s.timeout_s
        blocked = set()
        for _ in range(EDGE_RETRIES):
            search = AtlasSearch(self.atlas, self.cost, s.strategy, s.max_charts, deadline,
                                 progress, frozenset(blocked), self._edge_costs)
            out = search.run(i_start, i_goal)
            if out.reason != "reached":
                return answer(False, *_failure(out.reason, len(self.atlas.charts), s),
                              expanded=out.expanded)
            xs, bad = self._chart_path_points(out.charts)
            if bad is None:
                break
            blocked.add(bad)
        else:
            return answer(False, "no_path", f"{EDGE_RETRIES} chart links failed to carry a "
                                            "path; try a smaller radius")
        if s.complete:
            self.grow_complete(deadline)
        y, verified = self._densify(self._smooth(self._task_coords(xs)))
        path = self._planned_path(y, verified)
        if path is None:
            return answer(False, "no_path", "the path could not be made dense-feasible "
                                            "(a bug: please report the problem file)")
        cost = float(sum(self.pose_cost(path.p[k], path.tau[k], path.p[k + 1], path.tau[k + 1])
                         for k in range(len(path) - 1)))
        return answer(True, "ok", f"path of {len(path)} waypoints over "
                                  f"{len(out.charts)} charts", cost=cost, path=path,
                      expanded=out.expanded, chart_path=len(out.charts))

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

    def _chart_at(self, x):
        for j in self.atlas.closest(x):
            if np.linalg.norm(self.atlas.diff(self.atlas.charts[j].x, x)) < 1e-9:
                return j
        return self.atlas.add_chart(x)

    # ----- chart path -> points on M ---------------------------------------------------
    def _chart_path_points(self, charts):
        """Points on M through the chart centres; or the first edge (i, j) that does not
        carry a path (Newton failed, the points left the domain or jumped)."""
        xs = [self.atlas.charts[charts[0]].x]
        if len(charts) == 1:  # start == goal: a path that stays
            return [xs[0], xs[0].copy()], None
        for a, b in zip(charts, charts[1:]):
            pts = self._edge_points(min(a, b), max(a, b))
            if pts is None:
                return None, (min(a, b), max(a, b))
            xs.extend(pts[1:] if a < b else pts[::-1][1:])
        return xs, None

    def _edge_points(self, a, b):
        """Points on M from chart a's centre to chart b's (cached: charts never move)."""
        if (a, b) in self._edges:
            return self._edges[(a, b)]
        at = self.atlas
        gap = np.linalg.norm(at.diff(at.charts[a].x, at.charts[b].x))
        n = max(3, int(math.ceil(gap / (POINT_SPACING * at.radius))) + 1)
        pts = at.segment(a, b, n)
        ok = pts is not None and all(at.in_domain(x) for x in pts)
        if ok:
            steps = [np.linalg.norm(at.diff(u, v)) for u, v in zip(pts, pts[1:])]
            ok = max(steps) <= 3.0 * gap / (n - 1) + 1e-12
        self._edges[(a, b)] = pts if ok else None
        return self._edges[(a, b)]

    # ----- smoothing and densification in task coordinates ------------------------------
    # M is the graph of the (closed-form) lift over the feasible poses of the task, so a
    # point of M is a task coordinate vector y whose pose is feasible: moving y and checking
    # feasibility keeps every point on M, vectorised over the whole path.
    def _task_coords(self, xs):
        p, tau = self._pose_arrays(xs)
        return self.task.coords(p, tau)

    def _periodic_mask(self):
        return np.array([name in PERIODIC for name in self.task.names])

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
    """cost(p_a, tau_a, p_b, tau_b) between two poses (m, rad) of ``kind`` (COSTS):
    ``so3`` the SO(3) geodesic (rad, the paper's for orientation slices), ``great_circle``
    the distance on the sphere task (m, plus r_s times the torsion change when sigma is
    free), ``se3`` |dp| + L |angle| (m, L = mean platform anchor radius) for free flight.
    ``auto``: so3 for slices that fix the position, great_circle on the sphere, else se3."""
    if kind == "auto":
        kind = ("great_circle" if isinstance(task, SphereTask) else
                "so3" if isinstance(task, SliceTask) and {"x", "y", "z"} <= set(task.fixed) else "se3")
    L = float(np.mean(np.linalg.norm(robot.platform_anchors, axis=1)))

    def angle(ta, tb):
        return float(rotation_angle_between(rotation_tt(ta), rotation_tt(tb)))

    if kind == "great_circle":
        if not isinstance(task, SphereTask):
            raise InputError("cost", kind, f"the great-circle cost needs the sphere task, not '{task.type}'")
        c = np.asarray(task.center)

        def sphere(pa, ta, pb, tb):
            na, nb = pa - c, pb - c
            arc = task.radius * math.atan2(np.linalg.norm(np.cross(na, nb)), float(na @ nb))
            if task.free_torsion:
                arc += task.radius * abs(float(wrap_angle(tb[2] - ta[2])))
            return arc
        return sphere
    if kind == "so3":
        if not (isinstance(task, SliceTask) and {"x", "y", "z"} <= set(task.fixed)):
            raise InputError("cost", kind, "the SO(3) cost needs a slice that fixes x, y and z")
        return lambda pa, ta, pb, tb: angle(ta, tb)
    if kind != "se3":
        raise InputError("cost", kind, f"expected one of {', '.join(COSTS)}")
    return lambda pa, ta, pb, tb: float(np.linalg.norm(pb - pa)) + L * angle(ta, tb)


# ----- small helpers -------------------------------------------------------------------------
def _check_settings(s):
    if s.strategy not in STRATEGIES:
        raise InputError("strategy", s.strategy, f"expected one of {', '.join(STRATEGIES)}")
    for name in ("radius", "timeout_s", "margin_floor", "max_cable_speed", "max_cable_accel"):
        v = getattr(s, name)
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise InputError(name, v, "must be a positive finite number")
    if s.margin_floor >= 1:
        raise InputError("margin_floor", s.margin_floor, "must be below 1 (a normalised margin)")
    if not (isinstance(s.max_charts, int) and s.max_charts >= 2):
        raise InputError("max_charts", s.max_charts, "must be an integer >= 2")


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


def _failure(reason, charts, s):
    if reason == "exhausted":
        return "no_path", (f"no path at resolution r = {s.radius:g}: the start's connected "
                           f"component is exhausted after {charts} charts")
    if reason == "timeout":
        return "timeout", f"no path found within {s.timeout_s:g} s ({charts} charts)"
    return "chart_limit", f"no path found within the chart limit ({s.max_charts} charts)"
