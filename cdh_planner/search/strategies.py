"""Search over an atlas while it is built (paper Sec. 4.3), from both ends.

    outcome = run(atlas, x_start, x_goal, cost, Stop(deadline=...), strategy="gbf",
                  direct=direct_motion_ok)
    outcome.status          # Status.OK, NO_PATH, TIMEOUT, CHART_LIMIT, RESOURCE_LIMIT, CANCELED
    outcome.points          # points on M from x_start to x_goal (when OK)

Knows nothing of robots: it sees an ``Atlas``, a ``cost(x_a, x_b)`` between two points of
the manifold (the task metric, or the planner's clearance cost; the cost of a chart link
and of a direct motion), optionally a ``heuristic(x, target)`` (default: ``cost``; for A*
a lower bound of the cost, e.g. the task metric under the clearance cost) and
``direct(x_a, x_b)``:
whether the caller's direct motion between two points of M is safe (a dense closed-form
check, much cheaper than charts). The direct motion from start to goal itself is the
caller's to try first, before any chart exists (``Planner.plan`` does).

Two searches run on the one atlas, from a chart at the start and one at the goal, each
with the other end as its heuristic target. A chart reached by both joins them; so does a
direct motion from a chart of one side to the other side's root (or, for GBF, to the other
side's chart closest to this side's root). Popping a chart that is still open first grows
it, so the same loop answers a first query, which builds the atlas, and later queries,
which mostly walk charts that already exist (multi-query).

A strategy is one registered class (``Strategy``, ``register``; ``STRATEGIES``: name ->
class): its name, picture ``label``, ``description``, whether its heuristic must be
``admissible`` (a lower bound of the cost: the planner then gives it the task metric under
a clearance cost, not its greedy heuristic), the ``priority`` of a chart on a side's heap
and its ``search`` of the shared ``Bidirectional`` state, which stops on ``Stop``. That
registry drives the settings' choices, the CLI, the node parameter, the action's check, the
benchmarks and the pictures. The two built-in strategies:

- A* (``AStar``): each side pops least g + h and grows the chart until closed. Direct
  motions to the other root are edges of their cost (h itself when h is the cost), so the
  answer is the least-cost route of the chart graph (Pohl's stopping rule: the best
  meeting cost mu <= the larger of the two least f).
- Greedy Best-First (``GreedyBestFirst``): each side pops least h and grows the chart one
  child at a time, towards its target, until a child beats its parent; the first meeting
  is the answer.

A new strategy that only reorders A* (weighted A*: g + w h) overrides ``priority``; one
with its own loop overrides ``search`` too (test/test_strategies.py).

Links are checked lazily: a route's links once it is found (``link_ok``, the caller's
``route_check``); a bad one is cut and the search restarts, sharing what it computed.
Past a thin obstacle (``check_meetings``) GBF also checks the link where its sides meet
before it answers, and a restart first walks the charts there are before it grows more.

"No path" (``Status.NO_PATH``): one side has no chart left to pop, so the component of
its end (at this resolution, see ``atlas.domain``) holds no path to the other end.
"""

import abc
import heapq
import itertools
import math
import time
from dataclasses import dataclass, field
from typing import Callable, ClassVar, Optional

from ..status import Status

AUTO = "auto"  # not a strategy: the caller's choice by dimension (planner.default_strategy)
STRATEGIES = {}  # name -> registered Strategy class (``register``)
PROGRESS_PERIOD_S = 0.2
MAX_EXPANSIONS_PER_CHART = 500  # growth steps of one chart (safety: each step clips its domain)
MB = 1 << 20


@dataclass
class Stop:
    """When a search must stop: ``deadline`` (time.perf_counter() seconds), ``max_charts``,
    ``max_bytes`` (the atlas' own memory, ``Atlas.nbytes``), and ``cancel`` (anything with
    ``is_set()``, e.g. a threading.Event that a node sets)."""

    deadline: Optional[float] = None
    max_charts: int = 100_000
    max_bytes: int = 1024 * MB
    cancel: object = None

    def expired(self):
        """CANCELED or TIMEOUT when the call must end now, else None (no atlas needed: the
        stages after the search ask it too)."""
        if self.cancel is not None and self.cancel.is_set():
            return Status.CANCELED
        if self.deadline is not None and time.perf_counter() > self.deadline:
            return Status.TIMEOUT
        return None

    def status(self, atlas):
        """The limit reached now, or None."""
        expired = self.expired()
        if expired is not None:
            return expired
        if len(atlas.charts) >= self.max_charts:
            return Status.CHART_LIMIT
        if atlas.nbytes >= self.max_bytes:
            return Status.RESOURCE_LIMIT
        return None


@dataclass
class SearchOutcome:
    """``status``; when OK, ``points`` on M from start to goal, ``direct`` the indices k
    where points[k] -> points[k + 1] is a direct motion (checked by ``direct``, not a chart
    link), ``charts`` the chart route and ``cost`` its cost in task units."""

    status: Status
    points: list = field(default_factory=list)
    direct: frozenset = frozenset()
    charts: list = field(default_factory=list)
    cost: float = math.nan
    expanded: int = 0


def run(atlas, x_start, x_goal, cost: Callable, stop: Stop, strategy="astar",
        direct: Optional[Callable] = None, progress: Optional[Callable] = None,
        edge_costs: Optional[dict] = None, link_ok: Optional[Callable] = None,
        heuristic: Optional[Callable] = None, route_check: Optional[Callable] = None,
        check_meetings=False) -> SearchOutcome:
    """One query from x_start to x_goal (points on M) on ``atlas``; module docstring.
    ``progress`` is called with {"charts", "time_s", "best_h"} every PROGRESS_PERIOD_S;
    ``edge_costs`` caches chart-link costs across queries; ``link_ok(points)`` is the
    caller's check of the points that join two charts (a link that fails it is cut and
    the search is run again); ``heuristic(x, target)`` orders the search (default
    ``cost``); ``route_check(points, direct)`` is the caller's check of a whole route whose
    links passed ``link_ok`` (``direct``: the indices of direct motions): the index k of a
    motion points[k] -> points[k + 1] that fails, whose link is then cut, or None. One
    dense check of a route is cheaper than one per link, and finds the walls thinner than
    link_ok's probe. ``check_meetings``: a strategy checks the link where the two sides
    meet (its points and ``link_ok``, else ``direct``) before it answers, and cuts a bad
    one and goes on: past a thin obstacle the sides' charts overlap across it, so that is
    the link that fails, and each failure found in the route instead restarts the search;
    and a restarted search of a strategy whose answer need not be least-cost (not
    ``admissible``: GBF) first walks the charts there are, growing none, and grows only
    when they hold no route (a restart from the roots grew charts near them again, for a
    route the atlas already had)."""
    if strategy not in STRATEGIES:
        raise ValueError(f"unknown strategy {strategy!r} (expected one of {', '.join(STRATEGIES)})")
    strategy = STRATEGIES[strategy]()
    i_start, i_goal = atlas.chart_at(x_start), atlas.chart_at(x_goal)
    memo = _Memo({} if edge_costs is None else edge_costs)
    walk = False  # check_meetings: a restart of a strategy that need not answer least cost
    while True:  # lazy links: a route's links are checked once found; a bad one is cut
        search = Bidirectional(atlas, cost, strategy, direct, progress, memo, heuristic,
                               link_ok if check_meetings else None, walk)
        status, route, hops = search.run(i_start, i_goal, stop)
        if walk and status == Status.NO_PATH:
            walk = False  # no route on them: grow
            continue
        if status != Status.OK:
            return SearchOutcome(status, expanded=search.expanded)
        walk = check_meetings and not strategy.admissible
        points, direct_idx, owners, bad = _route_points(atlas, route, hops, link_ok,
                                                        search.direct_ok, memo.links_ok)
        if bad is None and route_check is not None:
            k = route_check(points, frozenset(direct_idx))
            if k is not None and k in direct_idx:  # the caller's check is stricter than direct
                memo.direct[owners[k]] = False
                continue
            bad = None if k is None else owners[k]
        if bad is None:
            return SearchOutcome(Status.OK, points, frozenset(direct_idx), route,
                                 search.route_cost(route, hops), search.expanded)
        atlas.unlink(*bad)


class _Memo:
    """What the searches of one query share across their restarts (a cut link restarts
    the search; without these each restart recomputed h of every chart it reached and
    re-checked every link of its route: the query slowed as the atlas grew). Each is a
    pure function of the charts, which never move, so sharing changes no answer."""

    def __init__(self, edge_costs):
        self.edge_costs = edge_costs  # (i, j), i < j -> cost (the caller's, across queries)
        self.h = {}  # (root, i) -> heuristic of chart i towards the other end
        self.hop = {}  # (root, i) -> cost of the direct motion from chart i to the other end
        self.direct = {}  # (i, j), i < j -> the direct motion is safe
        self.links_ok = set()  # (i, j), i < j: links whose points passed link_ok
        self.t0 = time.perf_counter()  # the query's start, for progress


def _route_points(atlas, route, hops, link_ok=None, direct_ok=None, links_ok=None):
    """Points on M along a chart route; direct hops add only their far end, and so do links
    whose points fail but whose direct motion is safe. Returns (points, direct indices,
    owners, None), owners[k] the charts (i, j), i < j, whose link or direct motion gives
    motion k (points[k] -> points[k + 1]), or (None, None, None, the first link that
    failed). ``links_ok``: a set of links known to pass ``link_ok`` (read and extended)."""
    links_ok = set() if links_ok is None else links_ok
    points = [atlas.charts[route[0]].x]
    direct_idx, owners = [], []
    if len(route) == 1:  # start == goal: a path that stays
        return [points[0], points[0].copy()], [], [(route[0], route[0])], None
    for a, b in zip(route, route[1:]):
        if (a, b) in hops:
            direct_idx.append(len(points) - 1)
            points.append(atlas.charts[b].x)
            owners.append((min(a, b), max(a, b)))
            continue
        pts = atlas.edge_points(a, b)
        if pts is not None and link_ok is not None and (min(a, b), max(a, b)) not in links_ok:
            if not link_ok(pts):
                pts = None
            else:
                links_ok.add((min(a, b), max(a, b)))
        if pts is None:
            if direct_ok is None or not direct_ok(a, b):
                return None, None, None, (min(a, b), max(a, b))
            direct_idx.append(len(points) - 1)
            points.append(atlas.charts[b].x)
            owners.append((min(a, b), max(a, b)))
            continue
        points.extend(pts[1:])
        owners.extend([(min(a, b), max(a, b))] * (len(pts) - 1))
    return points, direct_idx, owners, None


class _Side:
    """One direction of the search: ``root`` chart, ``target`` point (the other end)."""

    def __init__(self, root, target):
        self.root = root
        self.target = target
        self.g = {root: 0.0}
        self.parent = {root: None}
        self.heap = []
        self.done = set()
        self.best = root  # the chart with the least h so far

    def path(self, i):
        out = [i]
        while self.parent[out[-1]] is not None:
            out.append(self.parent[out[-1]])
        return out[::-1]  # root -> i


class Bidirectional:
    """The state both sides of one search share, which a ``Strategy`` searches: the atlas,
    ``sides`` (forward from the start, backward from the goal), the costs and heuristic
    (memoised across restarts), direct motions, chart growth and joining a route."""

    def __init__(self, atlas, cost, strategy, direct, progress, memo, heuristic=None,
                 meeting_link_ok=None, walk=False):
        self.atlas = atlas
        self.walk = walk  # no chart grows: a route on the charts there are, or NO_PATH
        self.meeting_link_ok = meeting_link_ok  # run's link_ok when it checks meetings
        self.links_ok = memo.links_ok
        self.cost = cost
        self.heuristic = cost if heuristic is None else heuristic
        self.strategy = strategy
        self.direct = direct
        self.progress = progress
        self.edge_costs = memo.edge_costs
        self.direct_cache = memo.direct
        self.expanded = 0
        self._t0 = memo.t0
        self._last_progress = 0.0
        self._h = memo.h
        self._hop = memo.hop
        self._count = itertools.count()
        self.sides = ()

    # ----- helpers ---------------------------------------------------------------------
    def h(self, side, i):
        key = (side.root, i)
        if key not in self._h:
            self._h[key] = self.heuristic(self.atlas.charts[i].x, side.target)
        return self._h[key]

    def hop_cost(self, side, i):
        """Cost of the direct motion from chart i to the other end (h itself when the
        heuristic is the cost)."""
        if self.heuristic is self.cost:
            return self.h(side, i)
        key = (side.root, i)
        if key not in self._hop:
            self._hop[key] = self.cost(self.atlas.charts[i].x, side.target)
        return self._hop[key]

    def edge_cost(self, i, j):
        key = (i, j) if i < j else (j, i)
        c = self.edge_costs.get(key)
        if c is None:
            c = self.edge_costs[key] = self.cost(self.atlas.charts[i].x, self.atlas.charts[j].x)
        return c

    def route_cost(self, route, hops):
        return sum(self.cost(self.atlas.charts[a].x, self.atlas.charts[b].x) if (a, b) in hops
                   else self.edge_cost(a, b) for a, b in zip(route, route[1:]))

    def direct_ok(self, i, j):
        if self.direct is None or i == j:
            return False
        key = (min(i, j), max(i, j))
        if key not in self.direct_cache:
            self.direct_cache[key] = bool(self.direct(self.atlas.charts[i].x, self.atlas.charts[j].x))
        return self.direct_cache[key]

    def meets(self, i, j):
        """May the sides meet on the link i - j? (``run``'s ``check_meetings``: its points
        pass the caller's link check or its direct motion is safe, else it is cut; always
        without.)"""
        if self.meeting_link_ok is None:
            return True
        bad = _route_points(self.atlas, [i, j], set(), self.meeting_link_ok, self.direct_ok,
                            self.links_ok)[3]
        if bad is not None:
            self.atlas.unlink(i, j)
        return bad is None

    def push(self, side, priority, i):
        """Chart i on ``side``'s heap (ties: first pushed first)."""
        heapq.heappush(side.heap, (priority, next(self._count), i))

    def pop(self, side):
        """The chart of least priority on ``side``'s heap."""
        return heapq.heappop(side.heap)[2]

    def limit(self, stop):
        """The Status of ``stop`` reached now, or None; reports progress on the way."""
        now = time.perf_counter()
        if self.progress is not None and now - self._last_progress >= PROGRESS_PERIOD_S:
            self._last_progress = now
            best = min(self.h(s, s.best) for s in self.sides)
            self.progress({"charts": len(self.atlas.charts), "time_s": now - self._t0, "best_h": best})
        return stop.status(self.atlas)

    def grow(self, side, i, stop, until_better):
        """Grow chart i until closed, or with ``until_better`` until a new chart has smaller
        h than i. Returns (a limit status of ``stop`` or None, the new charts)."""
        ch = self.atlas.charts[i]
        new = []
        if self.walk:
            return None, new
        for _ in range(MAX_EXPANSIONS_PER_CHART):
            if ch.closed:
                return None, new
            status = self.limit(stop)
            if status:
                return status, new
            j = self.atlas.expand(i, toward=side.target if until_better else None)
            if j is not None:
                new.append(j)
                if until_better and self.h(side, j) < self.h(side, i):
                    return None, new
        ch.domain.close()  # give up on this chart
        ch.frontier = True
        return None, new

    def join(self, fwd_side, i, j, hop):
        """The route start -> goal through chart i of ``fwd_side`` and chart j of the other
        side (i == j: a chart both reached); ``hop``: i -> j is a direct motion."""
        other = self.sides[1] if fwd_side is self.sides[0] else self.sides[0]
        a, b = fwd_side.path(i), other.path(j)[::-1]
        if i == j:
            b = b[1:]
        route = a + b
        hops = set()
        if hop:
            hops.add((i, j))
        if fwd_side is self.sides[1]:  # the goal side found it: reverse
            route = route[::-1]
            hops = {(q, p) for p, q in hops}
        return route, hops

    def run(self, i_start, i_goal, stop):
        """(Status, chart route, direct hops) of the strategy's search from both roots."""
        fwd = _Side(i_start, self.atlas.charts[i_goal].x)
        bwd = _Side(i_goal, self.atlas.charts[i_start].x)
        self.sides = (fwd, bwd)
        if i_start == i_goal:
            return Status.OK, [i_start], set()
        for s in self.sides:
            self.push(s, self.strategy.priority(0.0, self.h(s, s.root)), s.root)
        return self.strategy.search(self, stop)


# ----- the strategies -------------------------------------------------------------------
def register(cls):
    """Class decorator: make ``cls`` (a Strategy) a search strategy of every edge (module
    doc). Refused (ValueError naming it): a strategy without a name, label or description,
    one named "auto" (the caller's choice by dimension), a name registered by another class."""
    for attr in ("name", "label", "description"):
        if not isinstance(getattr(cls, attr), str) or not getattr(cls, attr):
            raise ValueError(f"strategy {cls.__name__}: {attr} must be a non-empty string")
    if cls.name == AUTO:
        raise ValueError(f"strategy {cls.__name__}: the name {AUTO!r} is the caller's choice")
    if cls.name in STRATEGIES and STRATEGIES[cls.name] is not cls:
        raise ValueError(f"strategy {cls.name!r} is already registered "
                         f"({STRATEGIES[cls.name].__name__})")
    STRATEGIES[cls.name] = cls
    return cls


class Strategy(abc.ABC):
    """Base of every search strategy (module doc). ``search(s, stop)`` runs on the shared
    ``Bidirectional`` state ``s`` (both roots already on their heaps with ``priority(0, h)``)
    and returns (Status, chart route start -> goal, its direct hops (i, j)): NO_PATH when a
    side runs out of charts, the Status of ``s.limit(stop)`` when it is reached."""

    name: ClassVar[str] = ""         # the setting's value (planner.strategy, --strategy)
    label: ClassVar[str] = ""        # in pictures
    description: ClassVar[str] = ""  # in the settings' description (node parameter, CLI, docs)
    admissible: ClassVar[bool] = False  # its heuristic must be a lower bound of the cost

    @abc.abstractmethod
    def priority(self, g, h):
        """Order of a chart on a side's heap: cost so far ``g``, heuristic ``h`` to the other end."""

    @abc.abstractmethod
    def search(self, s, stop):
        """The search over ``s`` until a route or ``stop`` (class docstring)."""


@register
class AStar(Strategy):
    """A* from both ends (module doc): the least-cost route of the chart graph."""

    name = "astar"
    label = "A*"
    description = "A*, least cost on the chart graph"
    admissible = True

    def priority(self, g, h):
        return g + h

    def search(self, s, stop):
        mu, meet = math.inf, None
        while True:
            status = s.limit(stop)
            if status:
                return status, None, None
            fwd, bwd = s.sides
            if not fwd.heap or not bwd.heap:  # a component is exhausted
                break
            if mu <= max(fwd.heap[0][0], bwd.heap[0][0]):
                break
            side = fwd if len(fwd.heap) <= len(bwd.heap) else bwd
            other = bwd if side is fwd else fwd
            i = s.pop(side)
            if i in side.done:
                continue
            side.done.add(i)
            s.expanded += 1
            closer = s.h(side, i) < s.h(side, side.best)  # direct motions are tried from here
            if closer:
                side.best = i
            status, _ = s.grow(side, i, stop, until_better=False)
            if status:
                return status, None, None
            gi = side.g[i]
            if i in other.g and gi + other.g[i] < mu:
                mu, meet = gi + other.g[i], (side, i, i, False)
            if closer and gi + s.h(side, i) < mu and s.direct_ok(i, other.root) \
                    and gi + s.hop_cost(side, i) < mu:
                mu, meet = gi + s.hop_cost(side, i), (side, i, other.root, True)
            for j in s.atlas.charts[i].neighbours:
                if j in side.done:
                    continue
                gj = gi + s.edge_cost(i, j)
                if gj < side.g.get(j, math.inf):
                    side.g[j] = gj
                    side.parent[j] = i
                    s.push(side, self.priority(gj, s.h(side, j)), j)
                    if j in other.g and gj + other.g[j] < mu:
                        mu, meet = gj + other.g[j], (side, j, j, False)
        if meet is None:
            return Status.NO_PATH, None, None
        route, hops = s.join(*meet)
        return Status.OK, route, hops


@register
class GreedyBestFirst(Strategy):
    """Greedy Best-First from both ends (module doc): the first meeting."""

    name = "gbf"
    label = "Greedy Best-First"
    description = "greedy best-first, faster"
    admissible = False

    def priority(self, g, h):
        return h

    def search(self, s, stop):
        turn = 0
        while True:
            status = s.limit(stop)
            if status:
                return status, None, None
            side, other = s.sides[turn], s.sides[1 - turn]
            turn = 1 - turn
            if not side.heap:  # this end's component is exhausted
                return Status.NO_PATH, None, None
            i = s.pop(side)
            if i in side.done:
                continue
            if s.h(side, i) < s.h(side, side.best):
                side.best = i
            status, new = s.grow(side, i, stop, until_better=True)
            if status:
                return status, None, None
            for j in new:  # direct motions from the new charts to the other side
                for k in dict.fromkeys((other.root, other.best)):
                    if s.direct_ok(j, k):
                        side.parent.setdefault(j, i)
                        return (Status.OK, *s.join(side, j, k, True))
            ch = s.atlas.charts[i]
            if ch.closed or s.walk:
                side.done.add(i)
                s.expanded += 1
            else:
                s.push(side, self.priority(0.0, s.h(side, i)), i)
            for j in sorted(ch.neighbours):
                if j in side.parent or (j in other.parent and not s.meets(i, j)):
                    continue
                side.parent[j] = i
                if j in other.parent:
                    return (Status.OK, *s.join(side, j, j, False))
                s.push(side, self.priority(0.0, s.h(side, j)), j)
