"""Search over an atlas while it is built (paper Sec. 4.3): A* and Greedy Best-First.

Knows nothing of robots: it sees an ``Atlas`` and a ``cost(x_a, x_b)`` between two points
of the manifold (the task metric; also the heuristic h(x) = cost(x, x_goal)).

The search runs on the graph of charts (an edge joins charts whose balls overlap). Popping
a chart that is still open first grows it (new charts on its polytope's outside vertices),
so the same loop answers a first query, which builds the atlas, and later queries, which
mostly walk charts that already exist (multi-query).

- A*: pop least g + h; a popped chart is grown until closed, then its neighbours relaxed.
  Optimal on the chart graph at the time each chart is popped.
- Greedy Best-First: pop least h; grow the chart one child at a time until a child beats
  its parent's h (then both go back on the queue), so the atlas grows towards the goal.

The answer is reached when the goal's chart is popped (A*) or discovered (GBF); "exhausted"
when no chart is left to pop: the start's component holds no path at this resolution.
"""

import heapq
import itertools
import time
from dataclasses import dataclass, field
from typing import Callable, Optional

STRATEGIES = ("astar", "gbf")
PROGRESS_PERIOD_S = 0.2
MAX_EXPANSIONS_PER_CHART = 500  # growth steps of one chart (safety: each step clips its polytope)


@dataclass
class SearchOutcome:
    """``reason``: ``reached`` | ``exhausted`` | ``timeout`` | ``chart_limit``;
    ``charts``: chart indices start -> goal (empty unless reached); ``cost`` in task units."""

    reason: str
    charts: list = field(default_factory=list)
    cost: float = float("nan")
    expanded: int = 0


class AtlasSearch:
    """One query on ``atlas`` from chart ``start`` to chart ``goal`` (both already in it)."""

    def __init__(self, atlas, cost: Callable, strategy="astar", max_charts=100_000,
                 deadline: Optional[float] = None, progress: Optional[Callable] = None,
                 blocked=frozenset(), edge_costs=None):
        if strategy not in STRATEGIES:
            raise ValueError(f"unknown strategy {strategy!r} (expected {STRATEGIES})")
        self.atlas = atlas
        self.cost = cost
        self.strategy = strategy
        self.max_charts = max_charts
        self.deadline = deadline
        self.progress = progress
        self.blocked = blocked  # edges (i, j), i < j, known not to carry a path
        self.edge_costs = {} if edge_costs is None else edge_costs  # (i, j), i < j -> cost
        self._t0 = time.perf_counter()
        self._last_progress = 0.0
        self._h = {}
        self._count = itertools.count()

    # ----- helpers ---------------------------------------------------------------------
    def h(self, i):
        if i not in self._h:
            self._h[i] = self.cost(self.atlas.charts[i].x, self._x_goal)
        return self._h[i]

    def edge_cost(self, i, j):
        key = (i, j) if i < j else (j, i)
        c = self.edge_costs.get(key)
        if c is None:
            c = self.edge_costs[key] = self.cost(self.atlas.charts[i].x, self.atlas.charts[j].x)
        return c

    def _edge_ok(self, i, j):
        return (min(i, j), max(i, j)) not in self.blocked

    def _stop_reason(self):
        now = time.perf_counter()
        if self.progress is not None and now - self._last_progress >= PROGRESS_PERIOD_S:
            self._last_progress = now
            self.progress({"charts": len(self.atlas.charts), "time_s": now - self._t0,
                           "best_h": self._best_h})
        if self.deadline is not None and now > self.deadline:
            return "timeout"
        if len(self.atlas.charts) >= self.max_charts:
            return "chart_limit"
        return None

    def _path(self, parent, goal):
        out = [goal]
        while parent[out[-1]] is not None:
            out.append(parent[out[-1]])
        return out[::-1]

    def _path_cost(self, charts):
        return sum(self.edge_cost(a, b) for a, b in zip(charts, charts[1:]))

    # ----- the searches ----------------------------------------------------------------
    def run(self, start, goal):
        self._x_goal = self.atlas.charts[goal].x
        self._best_h = self.h(start)
        if start == goal:
            return SearchOutcome("reached", [start], 0.0)
        return self._astar(start, goal) if self.strategy == "astar" else self._gbf(start, goal)

    def _astar(self, start, goal):
        g = {start: 0.0}
        parent = {start: None}
        heap = [(self.h(start), next(self._count), start)]
        done = set()
        while heap:
            reason = self._stop_reason()
            if reason:
                return SearchOutcome(reason, expanded=len(done))
            _, _, i = heapq.heappop(heap)
            if i in done:
                continue
            if i == goal:
                charts = self._path(parent, goal)
                return SearchOutcome("reached", charts, g[goal], len(done))
            done.add(i)
            self._best_h = min(self._best_h, self.h(i))
            reason = self._grow(i, goal)
            if reason:
                return SearchOutcome(reason, expanded=len(done))
            for j in self.atlas.charts[i].neighbours:
                if j in done or not self._edge_ok(i, j):
                    continue
                gj = g[i] + self.edge_cost(i, j)
                if gj < g.get(j, float("inf")):
                    g[j] = gj
                    parent[j] = i
                    heapq.heappush(heap, (gj + self.h(j), next(self._count), j))
        return SearchOutcome("exhausted", expanded=len(done))

    def _grow(self, i, goal, until_better=False):
        """Grow chart i (never the goal's) until closed, or with ``until_better`` until a
        new chart has smaller h than i. Returns a stop reason, or None."""
        if i == goal:
            return None
        ch = self.atlas.charts[i]
        for _ in range(MAX_EXPANSIONS_PER_CHART):
            if ch.closed:
                return None
            reason = self._stop_reason()
            if reason:
                return reason
            j = self.atlas.expand(i)
            if j is not None and until_better and self.h(j) < self.h(i):
                return None
        ch.polytope.close()  # give up on this chart
        ch.frontier = True
        return None

    def _gbf(self, start, goal):
        parent = {start: None}
        heap = [(self.h(start), next(self._count), start)]
        closed = set()
        while heap:
            reason = self._stop_reason()
            if reason:
                return SearchOutcome(reason, expanded=len(closed))
            _, _, i = heapq.heappop(heap)
            if i in closed:
                continue
            self._best_h = min(self._best_h, self.h(i))
            reason = self._grow(i, goal, until_better=True)
            if reason:
                return SearchOutcome(reason, expanded=len(closed))
            ch = self.atlas.charts[i]
            if ch.closed:
                closed.add(i)
            else:
                heapq.heappush(heap, (self.h(i), next(self._count), i))
            for j in sorted(ch.neighbours):
                if j in parent or not self._edge_ok(i, j):
                    continue
                parent[j] = i
                if j == goal:
                    charts = self._path(parent, goal)
                    return SearchOutcome("reached", charts, self._path_cost(charts), len(closed))
                heapq.heappush(heap, (self.h(j), next(self._count), j))
        return SearchOutcome("exhausted", expanded=len(closed))
