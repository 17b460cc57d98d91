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
import math
import time
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np
from scipy.linalg import solve_banded
from threadpoolctl import threadpool_limits

from .atlas.atlas import Atlas
from .errors import InputError
from .feasibility import evaluate
from .manifold.constraint import TaskConstraint
from .model.pose import (Pose, quaternion_from_tau, rotation_angle_between, rotation_tt,
                         tau_from_rotation, wrap_angle)
from .model.task import COORDINATES, end_taus
from .pipeline.metrics import task_cost, task_costs  # noqa: F401  (task_cost: API)
from .search.search import MB, Stop, run
from .settings import COSTS, PlannerSettings, check_setting  # noqa: F401  (PlannerSettings: API)
from .status import Status
from .trajectory import clearance
from .trajectory.path import PlannedPath
from .trajectory.dynamics import check_dynamics, timed_path
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
    # over the waypoints and the motion between them (trajectory.clearance.path_margins)
    least_margin: float = math.nan  # normalised (feasibility.evaluate)
    least_tension_margin: float = math.nan  # N: min over cables of f - v - fmin, fmax - f - v

    def __post_init__(self):  # one closed vocabulary: a member, never a loose string
        if not isinstance(self.reason, Status):
            raise TypeError(f"PlanResult.reason must be a Status, not {self.reason!r}")


ProgressCallback = Callable[[dict], None]  # called with {"charts": int, "time_s": float, "best_h": float}

TASK_TOL = 1e-6  # m / rad: how far a start or goal may be off the task's constraint
SMOOTHING_ROUNDS = 12
DENSIFY_ROUNDS = 10
CHORD_SAMPLES = 9  # poses probed between two link points before the dense check
COARSE_SAMPLES = 17  # a direct motion is first checked at these few points (a cheap "no")
DIRECT_STEP_M, DIRECT_STEP_RAD = 5e-3, np.deg2rad(1.0)  # waypoint spacing on a direct motion
# Clearance (weight > 0): a motion longer than CLEARANCE_LINK chart radii (a direct motion,
# not a chart link) has its margin sampled along it; smoothing resamples the waypoints at
# most CLEARANCE_STEP_M / _RAD apart and moves them while the clearance cost goes down.
CLEARANCE_LINK = 2.5
CLEARANCE_STEP_M, CLEARANCE_STEP_RAD = 1e-2, np.deg2rad(2.0)
CLEARANCE_ITERATIONS = 40
CLEARANCE_STEPS = (1.0, 0.5, 0.25, 0.125, 0.0625)  # step fractions tried (line search)
CLEARANCE_TOL = 1e-4  # stop when an iteration lowers the cost by less than this fraction
CLEARANCE_FD = 1e-5  # finite-difference step of the margin gradient (task coordinates)


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


class Planner:
    """Wrench-feasible paths for one robot and task (module docstring)."""

    def __init__(self, robot, task, settings: Optional[PlannerSettings] = None):
        self.robot = robot
        self.task = task
        self.settings = (settings or PlannerSettings()).check()
        s = self.settings
        self.constraint = TaskConstraint(robot, task, margin_floor=s.margin_floor)
        self.radius = s.radius or default_radius(self.constraint.dim)
        self.clearance_weight = s.clearance_weight
        self.atlas = Atlas(self.constraint, radius=self.radius)
        check_dynamics(robot, self.settings.dynamics)
        self.pose_cost = task_cost(robot, task, self.settings.cost)
        self.pose_costs = task_costs(robot, task, self.settings.cost)
        pose = self.constraint.pose
        self.length = lambda xa, xb: self.pose_cost(*pose(xa), *pose(xb))
        self.strategy, self.heuristic = self._search_strategy(s.strategy)  # the settings'
        # the task metric, or the clearance cost (trajectory.clearance), whose A* heuristic
        # is the metric (a lower bound): _search_strategy
        self.cost = self.length if self.clearance_weight == 0 else self._clearance_cost
        self._edge_costs = {}  # (i, j), i < j -> cost between the chart centres

    # ----- the query -------------------------------------------------------------------
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

    def _search_strategy(self, strategy):
        """(strategy, heuristic) of a call's ``strategy`` setting (auto, astar, gbf)."""
        if strategy == "auto":
            strategy = default_strategy(self.constraint.dim, self.clearance_weight)
        if self.clearance_weight == 0:
            return strategy, None
        return strategy, self.length if strategy == "astar" else self._greedy_heuristic

    def _plan(self, start, goal, progress, cancel, tolerance, s):
        t0 = time.perf_counter()
        c = self.constraint
        strategy, heuristic = self._search_strategy(s.strategy)

        def answer(ok, reason, message, cost=math.nan, path=None, **stats):
            return PlanResult(ok, reason, message, strategy, c.dim, c.n_vars,
                              len(self.atlas.charts), time.perf_counter() - t0, cost, path, stats)

        points, tolerance = {}, tolerance or self.settings.task_tolerance
        for label, p, tau in self._end_poses(start, goal, tolerance):
            x, why = self._lift(label, p, tau, tolerance)
            if x is None:
                return answer(False, why[0], why[1])
            points[label] = x
        ys = self._task_coords([points["start"], points["goal"]])
        stop = Stop(t0 + s.timeout_s, s.max_charts, int(s.max_memory_mb * MB), cancel)
        if self._direct_ok(ys[0], ys[1]):
            y, charts, direct = self._direct_points(ys[0], ys[1]), 0, True
        else:
            out = run(self.atlas, points["start"], points["goal"], self.cost, stop, strategy,
                      self._direct_x, progress, self._edge_costs, self._link_ok, heuristic)
            if out.status != Status.OK:
                return answer(False, out.status, _failure_message(out.status, len(self.atlas.charts),
                                                                  s, self.radius),
                              expanded=out.expanded)
            y, charts, direct = self._route_coords(out), len(out.charts), False
        if s.complete:
            self.atlas.chart_at(points["start"])
            self.grow_complete(stop.deadline, cancel)
        smooth = self._smooth if self.clearance_weight == 0 else self._smooth_clearance
        for y in (smooth(y), y):  # smoothing can cut a corner through a thin gap of C
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
        least = clearance.path_margins(self.robot, path.p, path.quaternion)
        path, timing, executed = timed_path(self.robot, path, s.dynamics, s.max_cable_speed,
                                            s.max_cable_accel)
        if not executed.ok:  # bounded: never hand out a trajectory that was not checked
            return answer(False, Status.NOT_EXECUTABLE, "no trajectory a JointTrajectory"
                          f"Controller executes within the limits: {executed.reason}")
        out = answer(True, Status.OK, f"path of {len(path)} waypoints over {how}", cost=cost,
                     path=path, chart_path=charts, direct=direct, timing=timing or "quasi-static",
                     executed=executed.describe(), points_added=executed.added)
        out.least_margin, out.least_tension_margin = least
        return out

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

    # ----- clearance (trajectory.clearance) ------------------------------------------------
    def _clearance_cost(self, xa, xb):
        """Clearance cost between two points of M: their task-metric length times
        1 + w times the mean of phi(margin) along the direct motion between them, from the
        two ends (a chart link: margins read from the points) or sampled every half chart
        radius (a direct motion longer than CLEARANCE_LINK radii)."""
        c = self.constraint
        ends = clearance.phi(np.array([c.margin(xa), c.margin(xb)]))
        n = int(np.linalg.norm(c.key(xa) - c.key(xb)) / (0.5 * self.radius))
        if n <= 2 * CLEARANCE_LINK:
            mean = 0.5 * float(ends.sum())
        else:
            motion = self._direct_motion(self._task_coords([xa, xb]))
            p, R = motion(np.zeros(n - 1, dtype=int), np.arange(1, n) / n)
            inner = clearance.phi(evaluate(self.robot, p, R=R).margin)
            mean = (0.5 * float(ends.sum()) + float(inner.sum())) / n  # trapezoid
        return self.length(xa, xb) * (1.0 + self.clearance_weight * mean)

    def _greedy_heuristic(self, x, target):
        """Greedy Best-First's order under the clearance cost: the metric to the target
        times the clearance density where the chart is (charts near the boundary of C
        come later)."""
        return self.length(x, target) * float(clearance.density(self.constraint.margin(x),
                                                                self.clearance_weight))

    def _route_coords(self, out):
        """Task coordinates of the search's points, direct motions sampled on the way."""
        y = self._task_coords(out.points)
        parts = [y[:1]]
        for k in range(len(y) - 1):
            parts.append(self._direct_points(y[k], y[k + 1])[1:] if k in out.direct else y[k + 1:k + 2])
        return np.concatenate(parts)

    # ----- start and goal ----------------------------------------------------------------
    def _end_poses(self, start, goal, tolerance):
        """(label, p m, tau rad) of start and goal, their angles as the query plans between
        them (``task.end_taus``: from the rotation only, snapped onto theta = 0 or pi
        within ``tolerance`` (rad, at least TASK_TOL), phi chosen there by the task and the
        other end), so one pose plans one path whichever way it was written."""
        ends = [(label, _finite_vector(f"{label}.p", pose.p, 3),
                 _finite_vector(f"{label}.tau", pose.tau, 3))
                for label, pose in (("start", start), ("goal", goal))]
        taus = end_taus(self.task, [tau for _, _, tau in ends], max(tolerance, TASK_TOL))
        return [(label, p, tau) for (label, p, _), tau in zip(ends, taus)]

    def _lift(self, label, p, tau, tolerance):
        """(x on M, None) or (None, (reason, message)) of the pose (p m, tau rad). A pose
        within ``tolerance`` (m or rad) of the task is projected onto it (the pose of its
        own task coordinates)."""
        off = float(self.task.residual(p[None], tau[None])[0])
        if off > max(tolerance, TASK_TOL):
            return None, (Status.INVALID, f"{label} pose is off the {self.task.type} task by "
                                     f"{off:.3g} (m or rad), beyond the tolerance {tolerance:g}: "
                                     f"{_describe(p, tau)}")
        p, tau = (a[0] for a in self.task.pose(self.task.coords(p[None], tau[None])))
        if float(self.task.residual(p[None], tau[None])[0]) > TASK_TOL:  # e.g. an implicit task
            return None, (Status.INVALID, f"{label} pose is off the {self.task.type} task by "
                                     f"{off:.3g} (m or rad) and cannot be projected onto it: "
                                     f"{_describe(p, tau)}")
        f = evaluate(self.robot, p[None], tau[None])
        if not f.feasible[0]:
            return None, (Status.infeasible(label), f"{label} pose is not wrench-feasible: "
                          f"{f.binding[0]} violated (margin {f.margin[0]:.3g}) at {_describe(p, tau)}")
        x = self.constraint.lift(p, tau)
        if not self.atlas.in_domain(x):
            return None, (Status.infeasible(label), f"{label} pose is feasible but closer to the "
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

    def _smooth_clearance(self, y):
        """Smoothing under the clearance cost J = sum of length (1 + w mean phi) over the
        segments (weight w > 0, trajectory.clearance): the waypoints are spaced evenly
        (CLEARANCE_STEP_M / _RAD apart), then moved by damped Newton steps on J, all at once.

        The model, in task coordinates: each segment a spring of stiffness rho / length
        (rho its clearance density), each waypoint pushed by w times its segments' mean
        length times the gradient of phi across the path (central differences), damped by
        the square of that gradient (phi = -ln m + c, whose Hessian is about grad phi
        grad phi^T). One tridiagonal solve gives the step; the step is halved until J
        (task-metric lengths, margins from the closed form) goes down, waypoints that would
        fall below the margin floor stay. J never increases: smoothing cannot pull the
        path back to the boundary for length it is not worth."""
        w = self.clearance_weight
        per = self._periodic_mask()
        y = self._resample(y)
        if len(y) < 3:
            return y
        dim = y.shape[1]
        eye = np.eye(dim) * CLEARANCE_FD
        lo, hi = self._coordinate_bounds()
        margin = self._margins(y)
        length = self._lengths(y[:-1], y[1:])
        cost = float(np.sum(clearance.segment_costs(length, margin, w)))
        for _ in range(CLEARANCE_ITERATIONS):
            d = _wrapped(np.diff(y, axis=0), per)
            seg = np.maximum(np.linalg.norm(d, axis=1), 1e-12)
            ph = clearance.phi(margin)
            rho = 1.0 + w * 0.5 * (ph[:-1] + ph[1:])
            inner = y[1:-1]
            probe = (inner[:, None, :] + np.stack([eye, -eye])[:, None]).reshape(-1, dim)
            g = clearance.phi(self._margins(_wrapped(probe, per))).reshape(2, len(inner), dim)
            gphi = (g[0] - g[1]) / (2 * CLEARANCE_FD)
            tangent = d[1:] / seg[1:, None] + d[:-1] / seg[:-1, None]
            tangent /= np.maximum(np.linalg.norm(tangent, axis=1), 1e-12)[:, None]
            gphi -= np.sum(gphi * tangent, axis=1)[:, None] * tangent  # across the path only
            reach = 0.5 * (seg[:-1] + seg[1:])
            grad = (rho[:-1, None] * d[:-1] / seg[:-1, None] - rho[1:, None] * d[1:] / seg[1:, None]
                    + w * reach[:, None] * gphi)
            stiff = rho / seg
            band = np.zeros((3, len(inner)))
            band[1] = stiff[:-1] + stiff[1:] + w * reach * np.sum(gphi ** 2, axis=1)
            band[0, 1:] = -stiff[1:-1]
            band[2, :-1] = -stiff[1:-1]
            step = solve_banded((1, 1), band, -grad)
            improved = False
            for alpha in CLEARANCE_STEPS:
                trial = np.clip(_wrapped(inner + alpha * step, per), lo, hi)
                m_t = self._margins(trial)
                keep = m_t < self.settings.margin_floor
                trial[keep], m_t[keep] = inner[keep], margin[1:-1][keep]
                y_t = np.concatenate([y[:1], trial, y[-1:]])
                m_all = np.concatenate([margin[:1], m_t, margin[-1:]])
                l_t = self._lengths(y_t[:-1], y_t[1:])
                c_t = float(np.sum(clearance.segment_costs(l_t, m_all, w)))
                if c_t < cost:
                    improved = cost - c_t > CLEARANCE_TOL * cost
                    y, margin, length, cost = y_t, m_all, l_t, c_t
                    break
            if not improved:
                break
        return y

    def _resample(self, y):
        """Task coordinates y (N, k) resampled evenly along their polyline (straight in y),
        at most CLEARANCE_STEP_M / _RAD apart in the pose; the ends kept."""
        per = self._periodic_mask()
        if len(y) < 2:
            return y
        dp, da = self._direct_motion(y).speeds()
        u = np.concatenate([[0.0], np.cumsum(np.maximum(dp / CLEARANCE_STEP_M, da / CLEARANCE_STEP_RAD))])
        n = max(1, int(np.ceil(u[-1])))
        t = np.linspace(0.0, u[-1], n + 1)
        k = np.clip(np.searchsorted(u, t, side="right") - 1, 0, len(y) - 2)
        frac = np.where(u[k + 1] > u[k], (t - u[k]) / np.maximum(u[k + 1] - u[k], 1e-300), 0.0)
        out = _wrapped(y[k] + frac[:, None] * _wrapped(y[k + 1] - y[k], per), per)
        out[0], out[-1] = y[0], y[-1]
        return out

    def _coordinate_bounds(self):
        """(lo, hi) of each task coordinate: its natural bounds if it is not periodic
        (theta in [0, pi], the sphere's alpha2), else unbounded."""
        bounds = [COORDINATES[n].bounds if COORDINATES[n].bounds and not COORDINATES[n].periodic
                  else (-np.inf, np.inf) for n in self.task.names]
        return np.array([b[0] for b in bounds]), np.array([b[1] for b in bounds])

    def _margins(self, y):
        """Normalised margins of task coordinate rows (N, k)."""
        p, tau = self.task.pose(y)
        return evaluate(self.robot, p, tau).margin

    def _lengths(self, ya, yb):
        """Task-metric lengths between task coordinate rows ya, yb (N, k) (the path cost)."""
        pa, ta = self.task.pose(ya)
        pb, tb = self.task.pose(yb)
        return self.pose_costs(pa, ta, pb, tb)

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
    # 6 significant digits: a position of 1e308 (a node's goal) is not 309 digits long
    return (f"p = [{', '.join(f'{v:.6g}' for v in p)}] m, "
            f"tau = [{', '.join(f'{v:.6g}' for v in tau)}] rad")


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
