"""Quasi-static against dynamic timing on the paper's Table 1 paths, at several payloads.

    python benchmarks/dynamics.py [--factors 0.5 1 1.1] [--picture docs/robot2_dynamics.png]

Each row's path is planned once with its robot file. It is then timed at payload masses
of factor x the file's own (mass = |force| / g, the force scaled with it, so gravity stays
consistent; inertia of a uniform disc of the platform's anchor radius). For each it prints
the quasi-static duration (winch limits only, tensions static), whether that timing keeps
the tensions in range once the motion's accelerations are counted (least slack, N), and the
dynamic (TOPP-RA) duration with its own least slack. A path that has no feasible speed at a
heavier payload is reported as such. Exit code 0 always (a benchmark, not a test).
"""

import argparse
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from cdh_planner.pictures.plans import plot_dynamics
from cdh_planner.parsing.problem import load_problem
from cdh_planner.planner import Planner
from cdh_planner.trajectory.dynamics import DynamicTiming, _Geometry, dynamic_timing, tensions_over_time

PROBLEMS = Path(__file__).resolve().parents[1] / "config" / "problems"
ROWS = ("robot1_qs_qg", "robot1_qs1_qg", "robot1_qs2_qg", "robot2_q1_q2", "robot2_q2_q3",
        "robot2_q2_q3_sigma_free", "robot2_q2_q3_free_flight")
G = 9.80665  # m/s^2


def disc_inertia(robot, mass):
    """Inertia (kg m^2, platform frame) of a uniform disc of the anchors' mean radius."""
    r = float(np.mean(np.linalg.norm(robot.platform_anchors, axis=1)))
    return mass * r ** 2 * np.diag([0.25, 0.25, 0.5])


def quasi_static_slack(robot, path, mass, inertia):
    """Least tension slack (N) of the quasi-static timing with the dynamic wrench: the
    quasi-static waypoint times on the same C2 path, checked by the dynamic model."""
    geo = _Geometry(robot, path)
    s, t = geo.s_wp[geo.keep], path.t[geo.keep]
    sd = np.gradient(s, t)
    sd[0] = sd[-1] = 0.0  # at rest at both ends
    timing = DynamicTiming(path=path, feasible=True, reason="", duration=float(t[-1]), slowdown=1.0,
                           least_tension_margin_n=np.nan, samples=0, s=s, sd=sd, geometry=geo)
    _, f, _, v = tensions_over_time(robot, timing, mass, inertia)
    return float(np.min(np.minimum(f - v - robot.tension_min, robot.tension_max - f - v)))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--factors", nargs="+", type=float, default=[0.5, 1.0, 1.1],
                    help="payload mass as a factor of the robot file's (default 0.5 1 1.1)")
    ap.add_argument("--picture", default=None, metavar="OUT.png",
                    help="write the Robot 2 q2 -> q3 dynamics picture (factor 1) there")
    args = ap.parse_args()
    print(f"{'query':26} {'mass kg':>8} {'quasi-static s':>15} {'its slack N':>12} "
          f"{'dynamic s':>10} {'slack N':>9} {'time s':>7}  note")
    for name in ROWS:
        problem = load_problem(PROBLEMS / f"{name}.yaml")
        quasi = replace(problem.settings, dynamics="quasi_static")  # the baseline timing
        result = Planner(problem.robot, problem.task, quasi).plan(problem.start, problem.goal)
        if not result.success:
            print(f"{name:26} no path: {result.message}")
            continue
        base_mass = float(np.linalg.norm(problem.robot.force)) / G
        s = problem.settings
        for factor in args.factors:
            mass = factor * base_mass
            robot = replace(problem.robot, force=problem.robot.force * factor)
            inertia = disc_inertia(robot, mass)
            t0 = time.perf_counter()
            timing = dynamic_timing(robot, result.path, mass, inertia, s.max_cable_speed, s.max_cable_accel)
            elapsed = time.perf_counter() - t0
            qs_slack = quasi_static_slack(robot, result.path, mass, inertia)
            dyn = f"{timing.duration:10.3f} {timing.least_tension_margin_n:9.2g}" if timing.feasible \
                else f"{'-':>10} {'-':>9}"
            note = "" if timing.feasible else timing.reason
            print(f"{name:26} {mass:8.3f} {result.path.t[-1]:15.3f} {qs_slack:12.2g} {dyn} "
                  f"{elapsed:7.2f}  {note}")
            if args.picture and name == "robot2_q2_q3" and factor == 1.0 and timing.feasible:
                plot_dynamics(robot, timing, tensions_over_time(robot, timing, mass, inertia),
                              args.picture, title=f"Robot 2 q2 -> q3, {mass:.2f} kg: tension "
                              "envelope with and without dynamics, and the path speed")
                print(f"  wrote {args.picture}")


if __name__ == "__main__":
    main()
