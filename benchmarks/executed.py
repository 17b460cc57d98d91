"""Executed as checked: the Table 1 paths as a JointTrajectoryController executes them.

    python benchmarks/executed.py [--limits 1 20 --limits 0.05 0.2] [--inertia 2e-3 2e-3 3.5e-3]

Each row is planned once quasi-statically (one search); then, per pair of winch limits
(m/s, m/s^2), the planner's output stage runs on it (trajectory.dynamics.timed_path: the
dynamic timing, then trajectory.executed.executable). Printed per row and limits: the
points TOPP-RA gives and the least tension slack (N, normalised by fmax - fmin in
brackets) of a JTC's quintic through them alone, then the points handed out, the
slow-down, the duration and the least slack after, and the seconds the executable stage
took. Robots without a load mass are timed quasi-statically (no inertia in the check).
Exit code 0 always (a benchmark, not a test).
"""

import argparse
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from cdh_planner.parsing.problem import load_problem
from cdh_planner.planner import Planner
from cdh_planner.trajectory import dynamics as D
from cdh_planner.trajectory import executed as E
from cdh_planner.trajectory.timing import time_path

PROBLEMS = Path(__file__).resolve().parents[1] / "config" / "problems"
ROWS = ("robot1_qs_qg", "robot1_qs1_qg", "robot1_qs2_qg", "robot2_q1_q2", "robot2_q2_q3",
        "robot2_q2_q3_sigma_free", "robot2_q2_q3_free_flight")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--limits", nargs=2, type=float, action="append", metavar=("V", "A"))
    ap.add_argument("--inertia", nargs=3, type=float, help="Robot 2's load inertia diagonal")
    ap.add_argument("--rows", nargs="*", default=ROWS)
    args = ap.parse_args()
    limits = args.limits or [(1.0, 20.0), (0.05, 0.2)]
    print(f"{'row':26s} {'limits':>10s} {'pts':>5s} {'alone N':>16s} {'out':>5s} "
          f"{'slow':>5s} {'s':>7s} {'after N':>18s} {'stage s':>8s}")
    for row in args.rows:
        pr = load_problem(PROBLEMS / f"{row}.yaml")
        robot = pr.robot
        if args.inertia and robot.mass is not None and row.startswith("robot2"):
            robot = replace(robot, inertia=np.diag(args.inertia))
        s = replace(pr.settings, dynamics="quasi_static")
        res = Planner(robot, pr.task, s).plan(pr.start, pr.goal)
        if not res.success:
            print(f"{row:26s} no path ({res.reason})")
            continue
        for v, a in limits:
            _row(row, robot, res.path, v, a)


def _row(row, robot, route, v, a):
    """One line: the row's route timed at winch limits v, a and made executable."""
    path = time_path(route, v, a)
    load, before = (None, None), path
    if robot.mass is not None:
        load = (robot.mass, robot.inertia)
        timing = D.dynamic_timing(robot, path, *load, v, a)
        before = timing.path if timing.feasible else path
    alone = E.check_path(robot, before, *load, v, a)
    t0 = time.perf_counter()
    out, note, check = D.timed_path(robot, path, "auto", v, a)
    stage = time.perf_counter() - t0
    print(f"{row:26s} {v:4g}/{a:<5g} {len(before):5d} {_slack(alone):>16s} {len(out):5d} "
          f"{check.slowdown:5.3g} {out.t[-1]:7.3f} {_slack(check):>18s} {stage:8.3f}"
          + ("" if check.ok else f"  refused: {check.reason}"))


def _slack(check):
    if not np.isfinite(check.least_tension_margin_n):  # the winch check failed first
        return f"winch x{max(check.speed_ratio, check.accel_ratio):.3g}"
    return f"{check.least_tension_margin_n:+.3g} ({check.least_margin:+.4f})"


if __name__ == "__main__":
    main()
