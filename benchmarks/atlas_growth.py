"""Charts per second as the atlas grows: does a chart cost more when the atlas is larger?

    python benchmarks/atlas_growth.py [--mode search|atlas] [--robot robot2] [--count 25]
        [--index 21] [--radius 0.5] [--strategy gbf] [--timeout 60] [--batch 250]

The query is one of the random free-flight queries of benchmarks/vs_ompl.py (seed 0):
``random_free_queries(robot, count, 0)[index]``; the default, Robot 2's 22nd of 25 (vs_ompl's
query 43 of --queries 50, 13 of --queries 16), is the pair no planner answered within 60 s.

First the planner's own answer (``Planner.plan``: on the default pair, no_path before any
chart, its ends lying across det J = 0). Then, to watch an atlas grow:

- ``--mode search``: the search from both ends as the planner runs it (its direct motions,
  link and route checks), without that rule; prints the atlas size every ``--batch``
  charts with the seconds since the start and the charts/s of the batch, then the answer
  (status, charts, seconds).
- ``--mode atlas``: the atlas alone, no search: from the start's chart, every open chart
  grown in turn (breadth first) until the time limit; the same lines. What a chart costs
  in Newton steps, index queries and domain clips, without the search's link checks.

A benchmark (prints numbers, exit 0), not a test. Several minutes with --timeout 900.
"""

import argparse
import dataclasses
import sys
import time
from collections import deque
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from random_queries import random_free_queries  # benchmarks/random_queries.py, beside this script
from cdh_planner.model.robot import load_robot
from cdh_planner.model.task import FreeTask
from cdh_planner.planner import Planner, PlannerSettings
from cdh_planner.search.strategies import STRATEGIES, Stop, run

ROOT = Path(__file__).resolve().parents[1]


class Rate:
    """Prints one line every ``batch`` charts: size, seconds, charts/s of the batch (per
    second of wall time, and per second of this process's CPU time: the machine may be
    shared), and (atlas mode) growth steps tried per chart made."""

    def __init__(self, batch, steps=False):
        self.batch = batch
        self.t0, self.c0 = time.perf_counter(), time.process_time()
        self.last = (0, 0.0, 0, 0.0)
        self.steps = 0
        print(f"{'charts':>7s} {'seconds':>8s} {'charts/s':>9s} {'per CPU s':>9s}"
              + ("  steps/chart" if steps else ""), flush=True)

    def __call__(self, charts):
        if charts - self.last[0] < self.batch:
            return
        t, cpu = time.perf_counter() - self.t0, time.process_time() - self.c0
        made = charts - self.last[0]
        rate = made / max(t - self.last[1], 1e-9)
        cpu_rate = made / max(cpu - self.last[3], 1e-9)
        steps = f"  {(self.steps - self.last[2]) / made:11.2f}" if self.steps else ""
        print(f"{charts:7d} {t:8.1f} {rate:9.1f} {cpu_rate:9.1f}{steps}", flush=True)
        self.last = (charts, t, self.steps, cpu)


def grow_atlas(planner, x0, timeout, rate):
    """Grow every open chart breadth first from x0's chart until closed or timeout."""
    atlas = planner.atlas
    queue = deque([atlas.chart_at(x0)])
    deadline = time.perf_counter() + timeout
    while queue and time.perf_counter() < deadline:
        i = queue[0]
        if atlas.charts[i].closed:
            queue.popleft()
            continue
        j = atlas.expand(i)
        rate.steps += 1
        if j is not None:
            queue.append(j)
            rate(len(atlas.charts))
    return "closed" if not queue else "timeout"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mode", choices=("search", "atlas"), default="search")
    ap.add_argument("--robot", default="robot2")
    ap.add_argument("--count", type=int, default=25, help="queries drawn for the robot (seed 0)")
    ap.add_argument("--index", type=int, default=21, help="which of them")
    ap.add_argument("--radius", type=float, default=0.5, help="chart radius (scaled units)")
    ap.add_argument("--strategy", choices=list(STRATEGIES), default="gbf")
    ap.add_argument("--timeout", type=float, default=60.0, help="s")
    ap.add_argument("--batch", type=int, default=250, help="charts per printed line")
    args = ap.parse_args(argv)
    robot = load_robot(ROOT / "config" / f"{args.robot}.yaml")
    q = random_free_queries(robot, args.count, seed=0)[args.index]
    settings = dataclasses.replace(PlannerSettings(), strategy=args.strategy, radius=args.radius,
                                   timeout_s=args.timeout, max_charts=10 ** 6)
    print(f"{args.robot} query {args.index} of {args.count} (seed 0), {args.mode}, radius {args.radius:g}, "
          f"{args.strategy if args.mode == 'search' else 'no search'}, timeout {args.timeout:g} s", flush=True)
    t = time.perf_counter()
    res = Planner(robot, FreeTask(), settings).plan(q.start, q.goal)
    print(f"plan: {res.reason} in {time.perf_counter() - t:.2f} s, {res.charts} charts ({res.message})")
    with threadpool_limits(limits=1, user_api="blas"):  # as Planner.plan runs
        grow(args, robot, q, settings)
    return 0


def grow(args, robot, q, settings):
    """The search or the atlas alone on q (module docstring), printing as it grows."""
    planner = Planner(robot, FreeTask(), settings)
    rate = Rate(args.batch, steps=args.mode == "atlas")
    t = time.perf_counter()
    xs, xg = (planner.constraint.lift(e.p, e.tau) for e in (q.start, q.goal))
    if args.mode == "search":
        out = run(planner.atlas, xs, xg, planner.cost, Stop(t + args.timeout), args.strategy,
                  planner.route.direct_x, lambda d: rate(d["charts"]), link_ok=planner.route.link_ok,
                  route_check=planner.route.route_unsafe)
        status = str(out.status)
    else:
        status = grow_atlas(planner, xs, args.timeout, rate)
    seconds = time.perf_counter() - t
    links = [len(ch.neighbours) for ch in planner.atlas.charts]
    print(f"answer: {status}; {len(links)} charts in {seconds:.1f} s; neighbours per chart: "
          f"mean {np.mean(links):.1f}, max {max(links)}", flush=True)


if __name__ == "__main__":
    sys.exit(main())
