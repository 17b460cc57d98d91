"""Throughput of the m-cable wrench-feasibility test: poses per second of
``cdh_planner.wrench.wrench_feasibility`` (the facet test) on 10^5 random poses of the 8-cable robots.

    python benchmarks/zonotope_throughput.py [--poses N] [--runs K]

Prints, per robot, the median over K runs (one call with all N poses per run) of poses per
wall-clock second and per CPU second of this process (the machine's load average is
printed too: on a shared machine the wall figure is the CPU figure times this process's
share of a core), and the cost of a one-pose call (the planner's per-pose use). Target:
>= 1e5 poses/s in one process; a miss is printed, not turned into a failing exit code.
"""

import argparse
import os
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
# robot -> (box centre, half extents) m: poses inside each robot's workspace
BOXES = {"robot2_8": ((0.0, 0.0, 0.3), (0.1, 0.1, 0.15)),
         "cogiro": ((0.0, 0.0, 2.5), (6.0, 4.5, 2.0))}


def random_poses(centre, half, n, seed=0):
    """p (n, 3) m in the box, tau (n, 3) rad: any azimuth, tilt up to 0.3 rad, torsion +-0.3."""
    rng = np.random.default_rng(seed)
    p = np.asarray(centre) + rng.uniform(-1.0, 1.0, (n, 3)) * np.asarray(half)
    tau = np.column_stack([rng.uniform(-np.pi, np.pi, n), rng.uniform(0.0, 0.3, n),
                           rng.uniform(-0.3, 0.3, n)])
    return p, tau


def rates(robot, p, tau, runs):
    """Median poses per wall second and per CPU second over ``runs`` calls."""
    wrench_feasibility(robot, p[:1000], tau[:1000])  # warm up (compiled code, allocator)
    wall, cpu = [], []
    for _ in range(runs):
        w, c = time.perf_counter(), time.process_time()
        wrench_feasibility(robot, p, tau)
        wall.append(p.shape[0] / (time.perf_counter() - w))
        cpu.append(p.shape[0] / (time.process_time() - c))
    return statistics.median(wall), statistics.median(cpu)


def one_pose_us(robot, p, tau, calls=2000):
    """Median-free mean cost of a one-pose call, microseconds (CPU time)."""
    c = time.process_time()
    for k in range(calls):
        wrench_feasibility(robot, p[k:k + 1], tau[k:k + 1])
    return 1e6 * (time.process_time() - c) / calls


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=100_000)
    parser.add_argument("--runs", type=int, default=5)
    args = parser.parse_args(argv)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    for name, (centre, half) in BOXES.items():
        robot = load_robot(ROOT / "config" / f"{name}.yaml")
        p, tau = random_poses(centre, half, args.poses)
        wall, cpu = rates(robot, p, tau, args.runs)
        feasible = wrench_feasibility(robot, p[:10_000], tau[:10_000]).feasible.mean()
        print(f"{name} ({len(robot.winch_names)} cables, {feasible:.0%} of the poses feasible): "
              f"{wall:,.0f} poses/s wall, {cpu:,.0f} poses/CPU-s (median of {args.runs} runs of "
              f"{args.poses:,} poses; target {TARGET:,.0f}: "
              f"{'ok' if wall >= TARGET else 'wall BELOW TARGET'}); one-pose call "
              f"{one_pose_us(robot, p, tau):.0f} us")
    return 0


if __name__ == "__main__":
    sys.exit(main())
