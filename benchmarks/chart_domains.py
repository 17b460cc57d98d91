"""Chart domains compared: exact polytopes against half-spaces with sampled frontier
directions (cdh_planner/atlas/domain.py), on the atlas search alone.

    python benchmarks/chart_domains.py [--timeout S] [--queries N] [--directions K ...]

For each Table 1 row (both strategies) and N random free-flight queries per robot (GBF),
the search from both ends runs without direct motions (``search.run`` with no ``direct``)
on a fresh atlas whose charts are all exact polytopes, or all sampled domains (K
directions each). Prints the status, charts, seconds, the largest chart domain (bytes) and
the atlas' memory (MiB). A representation that raises (the 6-D vertex explosion asks numpy
for hundreds of GiB) is reported as such. Exit code 0 always.
"""

import argparse
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

from cdh_planner.atlas.charts import Atlas
from cdh_planner.parsing.problem import load_problem
from random_queries import random_free_queries  # benchmarks/random_queries.py, beside this script
from cdh_planner.model.robot import load_robot
from cdh_planner.model.task import FreeTask
from cdh_planner.planner import Planner, PlannerSettings
from cdh_planner.search.strategies import MB, Stop, run

ROOT = Path(__file__).resolve().parents[1]


def search(robot, task, settings, start, goal, exact_max_dim, directions, timeout):
    planner = Planner(robot, task, settings)
    planner.atlas = atlas = Atlas(planner.constraint, radius=planner.radius,
                                  exact_max_dim=exact_max_dim, directions=directions)
    c = planner.constraint
    xs, xg = c.lift(start.p, start.tau), c.lift(goal.p, goal.tau)
    t = time.perf_counter()
    try:
        out = run(atlas, xs, xg, planner.cost, Stop(t + timeout, max_bytes=4096 * MB), planner.strategy)
        status = str(out.status)
    except MemoryError as exc:
        status = f"MemoryError ({str(exc)[:40]})"
    wall = time.perf_counter() - t
    biggest = max((ch.domain.nbytes for ch in atlas.charts), default=0)
    return status, len(atlas.charts), wall, biggest, atlas.nbytes / MB


def rows(args):
    for path in sorted((ROOT / "config" / "problems").glob("*.yaml")):
        pr = load_problem(path)
        for strategy in ("gbf", "astar"):
            yield f"{path.stem} {strategy}", pr.robot, pr.task, replace(pr.settings, strategy=strategy), pr.start, pr.goal
    for name in ("robot1", "robot2"):
        robot = load_robot(ROOT / "config" / f"{name}.yaml")
        for k, q in enumerate(random_free_queries(robot, args.queries, seed=args.seed)):
            yield f"free {name} #{k} gbf", robot, FreeTask(), PlannerSettings(strategy="gbf"), q.start, q.goal


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--timeout", type=float, default=20.0, help="seconds per search")
    ap.add_argument("--queries", type=int, default=3, help="random free-flight queries per robot")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--directions", type=int, nargs="+", default=[128, 384, 1024],
                    help="K of the sampled domains compared")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)
    kinds = [("polytope", 6, 384)] + [(f"sampled K={k}", 0, k) for k in args.directions]
    print(f"{'query':34s} {'domain':16s} {'status':14s} {'charts':>7s} {'seconds':>8s} "
          f"{'max chart B':>12s} {'atlas MiB':>10s}")
    for label, robot, task, settings, start, goal in rows(args):
        for kind, exact_max_dim, k in kinds:
            status, charts, wall, biggest, mib = search(robot, task, settings, start, goal,
                                                        exact_max_dim, k, args.timeout)
            print(f"{label:34s} {kind:16s} {status[:14]:14s} {charts:7d} {wall:8.2f} "
                  f"{biggest:12d} {mib:10.2f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
