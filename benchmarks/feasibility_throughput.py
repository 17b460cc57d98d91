"""Throughput of the closed-form feasibility test: poses per second of
``cdh_planner.wrench.wrench_feasibility`` (six cables: the closed form) on 10^5 random poses, for the paper's two robots.

    python benchmarks/feasibility_throughput.py [--poses N] [--runs K]

Prints the median over K runs (one call with all N poses per run). Target: >= 1e5 poses/s;
a miss is printed, not turned into a failing exit code (machines differ; `make bench` runs
every benchmark).
"""

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing

from cdh_planner.wrench import wrench_feasibility  # noqa: E402
from cdh_planner.model.robot import load_robot  # noqa: E402

TARGET = 1e5


def random_poses(n, seed=0):
    """Poses around the paper robots' workspace: p (n, 3) m, tau (n, 3) rad."""
    rng = np.random.default_rng(seed)
    p = np.column_stack([rng.uniform(-0.1, 0.1, n), rng.uniform(-0.1, 0.1, n), rng.uniform(0.15, 0.45, n)])
    tau = np.column_stack([rng.uniform(-np.pi, np.pi, n), rng.uniform(0.0, np.pi, n), rng.uniform(-np.pi, np.pi, n)])
    return p, tau


def throughput(robot, p, tau, runs):
    """Median poses/s over ``runs`` calls on all poses."""
    wrench_feasibility(robot, p[:1000], tau[:1000])  # warm up (imports, allocator)
    rates = []
    for _ in range(runs):
        t0 = time.perf_counter()
        wrench_feasibility(robot, p, tau)
        rates.append(p.shape[0] / (time.perf_counter() - t0))
    return statistics.median(rates)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=100_000)
    parser.add_argument("--runs", type=int, default=5)
    args = parser.parse_args(argv)
    p, tau = random_poses(args.poses)
    for name in ("robot1", "robot2"):
        robot = load_robot(ROOT / "config" / f"{name}.yaml")
        rate = throughput(robot, p, tau, args.runs)
        print(f"{name}: {rate:,.0f} poses/s (median of {args.runs} runs of {args.poses:,} poses; "
              f"target {TARGET:,.0f}) {'ok' if rate >= TARGET else 'BELOW TARGET'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
