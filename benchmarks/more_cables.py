"""Planning robots with more than six cables: CoGiRo free-flight queries whose direct
motion is infeasible (docs/more-cables.md), and the robot2_8 problem files.

    python benchmarks/more_cables.py [--queries N] [--seed S] [--strategy gbf]

The CoGiRo queries are of config/problems/cogiro_turn_at_edge.yaml's kind, drawn at
random: near the x = +-6 m edge (|x| in 4.6..5.4 m, |y| <= 1 m, z in 1.5..2.5 m) the
platform turns by about 2 rad about the vertical through the yaw window where the tension
rule's band leaves the limits; each end has a planning margin >= 0.01 and the direct motion
(slerp, 64 samples) leaves the domain. Printed per query: total plan time, the route's
share (lift and atlas search; the rest is smoothing, densifying, dynamic timing and the
executed check), charts; then the medians against the target (median < 1 s), with
the machine's load average (2 CPUs shared). Exit code 0 always.
"""

import argparse
import dataclasses
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cdh_planner.wrench import band_feasibility  # noqa: E402
from cdh_planner.parsing.problem import load_problem  # noqa: E402
from cdh_planner.model.pose import Pose, rotation_tt  # noqa: E402
from cdh_planner.planner import Planner  # noqa: E402
from cdh_planner.trajectory.path_check import SlerpPath  # noqa: E402
from cdh_planner.model.pose import quaternion_from_tau  # noqa: E402

PROBLEMS = ROOT / "config" / "problems"
TARGET_S = 1.0


def queries(robot, n, rng):
    """n (start, goal) Poses of the kind described in the module docstring."""
    out = []
    while len(out) < n:
        side = rng.choice([-1.0, 1.0])
        p = np.column_stack([side * rng.uniform(4.6, 5.4, 2), rng.uniform(-1, 1, 2),
                             rng.uniform(1.5, 2.5, 2)])
        yaw0 = rng.uniform(-2.8, -2.4)
        yaw = np.array([yaw0, yaw0 + rng.uniform(1.9, 2.3)]) + (0.0 if side > 0 else np.pi)
        tau = np.column_stack([np.zeros(2), np.zeros(2), (yaw + np.pi) % (2 * np.pi) - np.pi])
        if np.any(band_feasibility(robot, p, tau).margin < 0.01):
            continue
        motion = SlerpPath(p, quaternion_from_tau(tau))
        pp, R = motion(np.zeros(64, dtype=int), np.linspace(0, 1, 64))
        if np.all(band_feasibility(robot, pp, R=R).margin > 0):
            continue
        out.append((Pose(p[0], tau[0]), Pose(p[1], tau[1])))
    return out


def timed_plan(planner, start, goal):
    """(PlanResult, seconds in the route stage)."""
    route, spent = planner.route, [0.0]

    def timed(*args, **kwargs):
        t = time.perf_counter()
        try:
            return route(*args, **kwargs)
        finally:
            spent[0] += time.perf_counter() - t
    planner.route = timed
    try:
        return planner.plan(start, goal), spent[0]
    finally:
        planner.route = route


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--queries", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--strategy", default="auto")
    args = ap.parse_args()
    pr = load_problem(PROBLEMS / "cogiro_turn_at_edge.yaml")
    settings = dataclasses.replace(pr.settings, strategy=args.strategy, timeout_s=60)
    Planner(pr.robot, pr.task, settings).plan(pr.start, pr.goal)  # warm up (compiled code)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    totals, routes, cpus, ok = [], [], [], 0
    for k, (start, goal) in enumerate(queries(pr.robot, args.queries,
                                              np.random.default_rng(args.seed))):
        cpu = time.process_time()
        res, route_s = timed_plan(Planner(pr.robot, pr.task, settings), start, goal)
        cpus.append(time.process_time() - cpu)
        ok += res.success
        totals.append(res.time_s)
        routes.append(route_s)
        print(f"cogiro query {k}: {'ok' if res.success else res.reason.value:<10} "
              f"{res.time_s:6.2f} s (route {route_s:5.2f} s; CPU {cpus[-1]:5.2f} s), {res.charts:4d} charts, "
              f"{res.stats.get('timing', '')}")
    med = statistics.median(totals)
    print(f"cogiro: {ok}/{len(totals)} planned; median {med:.2f} s (route {statistics.median(routes):.2f} s), "
          f"CPU {statistics.median(cpus):.2f} s; target {TARGET_S:g} s: {'met' if med < TARGET_S else 'NOT MET'}; "
          f"load average {os.getloadavg()[0]:.1f}")
    for name in ("robot2_8_q2_q3", "robot2_8_pivot", "robot2_8_slice", "robot2_8_q2_q3_free_flight"):
        p2 = load_problem(PROBLEMS / f"{name}.yaml")
        for strategy in ("astar", "gbf"):
            s = dataclasses.replace(p2.settings, strategy=strategy, timeout_s=60)
            res = Planner(p2.robot, p2.task, s).plan(p2.start, p2.goal)
            print(f"{name} {strategy}: {'ok' if res.success else res.reason.value} "
                  f"{res.time_s:.2f} s, {res.charts} charts, {res.message}")


if __name__ == "__main__":
    main()
