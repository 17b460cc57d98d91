"""Route: start -> goal on M as task coordinate rows, by the direct motion when it is valid
(a dense closed-form check, milliseconds), else by the atlas search (``search.run``, which
owns the algorithm: this stage hands it the costs and the checks of direct motions and
chart links).

The cost is the task metric, or under a clearance weight w > 0 the clearance cost
(``trajectory.clearance``): length times 1 + w times the mean of phi(margin); with a
scene, inf to or from a point in collision. Start and goal on opposite sides of det J = 0
have no path at all (``singular_between``), answered before any chart.
"""

import math

import numpy as np

from ..wrench import band_feasibility
from ..model.pose import quaternion_from_tau, tau_from_rotation
from ..search.strategies import STRATEGIES, run
from ..status import Status
from ..trajectory import clearance
from ..trajectory.path_check import TaskLinePath

CHORD_SAMPLES = 9  # poses probed between two link points before the dense check
DIRECT_STEP_M, DIRECT_STEP_RAD = 5e-3, np.deg2rad(1.0)  # waypoint spacing on a direct motion
# a motion longer than CLEARANCE_LINK chart radii (a direct motion, not a chart link) has
# its margin sampled along it
CLEARANCE_LINK = 2.5


class Route:
    """The route stage of one constraint, atlas and validity (module docstring)."""

    def __init__(self, constraint, atlas, validity, length, clearance_weight, radius, densify):
        """``length(xa, xb)``: the task metric between two points of M (rad or m);
        ``densify(y) -> (y, ok)``: the densify stage (``route_unsafe``)."""
        self.constraint, self.atlas, self.validity = constraint, atlas, validity
        self.length, self.weight, self.radius = length, clearance_weight, radius
        self.densify = densify
        self._clear_cache = {}
        self.cost = self.blocked(length if clearance_weight == 0 else self.clearance_cost)
        self._edge_costs = {}  # (i, j), i < j -> cost between the chart centres

    def heuristic(self, strategy):
        """The search's heuristic of ``strategy`` (a registered strategy's name): None (the
        cost itself) without clearance; else, for a strategy whose heuristic must be
        admissible, the metric (a lower bound of the clearance cost), for the others the
        metric times the clearance density (``greedy_heuristic``)."""
        if self.weight == 0:
            return None
        admissible = STRATEGIES[strategy].admissible
        return self.blocked(self.length if admissible else self.greedy_heuristic)

    def blocked(self, cost):
        """``cost`` between points of M, inf when either is in collision or outside the
        accuracy limits (``Validity.clear``): chart transitions into collision cost inf (the
        paper's Sec. 6), so A* never takes them and GBF tries them last; the search's lazy
        link check cuts any that are still used."""
        if not self.validity.blocks:
            return cost
        return lambda xa, xb: cost(xa, xb) if self._clear(xa) and self._clear(xb) else math.inf

    def _clear(self, x):
        """Is the pose of the point x of M clear of collision and within the accuracy limits
        by the margin floor? (cached)"""
        key = x.tobytes()
        if key not in self._clear_cache:
            self._clear_cache[key] = self.validity.clear(*self.constraint.pose(x))
        return self._clear_cache[key]

    def __call__(self, points, stop, strategy, progress=None):
        """(task coordinates (N, k), charts on the route, direct?, None) from
        points["start"] to points["goal"], or (None, 0, False, (Status, message or None, stats))
        of a route that is not there: a search that ended otherwise than OK (message None:
        ``failure_message``; stats {"expanded": charts}), or ends on opposite sides of
        det J = 0."""
        xs = [points["start"], points["goal"]]
        ys = self.coords(xs)
        if self.validity.motion(ys[0], ys[1]):
            return self.direct_points(ys[0], ys[1]), 0, True, None
        det = self.det_j(xs)
        if det[0] * det[1] < 0:
            return None, 0, False, (Status.NO_PATH, SINGULAR_BETWEEN.format(*det), {})
        out = run(self.atlas, xs[0], xs[1], self.cost, stop, strategy, self.direct_x, progress,
                  self._edge_costs, self.link_ok, self.heuristic(strategy), self.route_unsafe,
                  check_meetings=self.validity.blocks)
        if out.status != Status.OK:
            return None, 0, False, (out.status, None, {"expanded": out.expanded})
        return self.route_coords(out), len(out.charts), False, None

    def det_j(self, xs):
        """det J (the cables' screw Jacobian) at points of M. J is never singular on C (a
        singular J makes the tension set of the wrench ellipsoid unbounded: the tension set is the image of the ellipsoid under J^-1),
        so its sign is the same all along any path: ends of opposite signs have none."""
        poses = [self.constraint.pose(x) for x in xs]
        return band_feasibility(self.validity.robot, np.array([a for a, _ in poses]),
                        np.array([b for _, b in poses])).det_j

    def route_unsafe(self, xs, direct):
        """The first motion k (xs[k] -> xs[k + 1]; not the direct motions in ``direct``,
        checked densely already) that densification cannot make dense-feasible, or None.
        One dense check of the route finds the walls thinner than link_ok's probe (Robot
        2: 6 mrad wide, margin -52 inside, between two link points 0.06 rad apart); the
        search cuts that link instead of answering with a route that cannot be a path."""
        y = self.coords(xs)
        p, tau = self.validity.task.pose(y)
        for k, seg in enumerate(self.validity.segments(p, quaternion_from_tau(tau))):
            if k in direct or (seg.feasible and seg.unresolved == 0):
                continue
            if not self.densify(y[k:k + 2])[1]:
                return k
        return None

    def coords(self, xs):
        """Task coordinates (N, k) of points of M."""
        poses = [self.constraint.pose(x) for x in xs]
        return self.validity.task.coords(np.array([a for a, _ in poses]),
                                         np.array([b for _, b in poses]))

    def direct_x(self, xa, xb):
        """Is the direct motion between two points of M valid (the search's shortcut)?"""
        ya, yb = self.coords([xa, xb])
        return self.validity.motion(ya, yb)

    def link_ok(self, xs):
        """Are the points joining two charts one motion of C? Large charts can link two
        sheets of M across a thin gap of C; a few poses between each pair show the gap
        (the dense check of the whole path comes later)."""
        return self.validity.probe(self.coords(xs), CHORD_SAMPLES)

    def direct_points(self, ya, yb):
        """Task coordinates along the direct motion ya -> yb, DIRECT_STEP_M / _RAD apart."""
        motion = self.validity.direct_motion([ya, yb])
        dp, da = motion.speeds()
        n = int(max(2, math.ceil(max(dp[0] / DIRECT_STEP_M, da[0] / DIRECT_STEP_RAD)) + 1))
        s = np.linspace(0.0, 1.0, n)
        if isinstance(motion, TaskLinePath):  # a line in the task's own coordinates
            y = motion.coords[0] + s[:, None] * (motion.coords[1] - motion.coords[0])
        else:  # slerp: free-flight coordinates are (p, tau), phi continued from the start
            p, R = motion(np.zeros(n, dtype=int), s)
            y = self.validity.task.coords(p, tau_from_rotation(R, phi_hint=float(ya[3])))
        y[0], y[-1] = ya, yb
        return y

    def route_coords(self, out):
        """Task coordinates of the search's points, direct motions sampled on the way; with
        m > 6 cables every motion is (a controller's quintic of the lengths between points
        far apart gives lengths no pose has: slack or overloaded cables)."""
        y = self.coords(out.points)
        parts = [y[:1]]
        every = len(self.validity.robot.base_anchors) > 6
        for k in range(len(y) - 1):
            parts.append(self.direct_points(y[k], y[k + 1])[1:] if every or k in out.direct
                         else y[k + 1:k + 2])
        return np.concatenate(parts)

    def clearance_cost(self, xa, xb):
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
            motion = self.validity.direct_motion(self.coords([xa, xb]))
            p, R = motion(np.zeros(n - 1, dtype=int), np.arange(1, n) / n)
            inner = clearance.phi(self.validity.pose_margins(p, R=R)[0])
            mean = (0.5 * float(ends.sum()) + float(inner.sum())) / n  # trapezoid
        return self.length(xa, xb) * (1.0 + self.weight * mean)

    def greedy_heuristic(self, x, target):
        """Greedy Best-First's order under the clearance cost: the metric to the target
        times the clearance density where the chart is (charts near the boundary of C
        come later)."""
        return self.length(x, target) * float(clearance.density(self.constraint.margin(x),
                                                                self.weight))


SINGULAR_BETWEEN = ("no path: start and goal lie on opposite sides of the singularity det J = 0 "
                    "(det J = {:.3g} and {:.3g}); every motion between them passes a pose where the "
                    "cable Jacobian is singular, which no tension in range can hold (at any resolution)")


def failure_message(status, charts, settings, radius):
    """What a search that ended with ``status`` (not OK) means, for the user."""
    s = settings
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
