"""Throughput of the workspace analysis: poses/s of the point test, plans/s of
the reach map in this process and on a local Ray of 1 and 2 workers, and Ray's start-up.

    python benchmarks/workspace.py [--robot config/robot2.yaml] [--scene SCENE.yaml]
                                   [--samples 200000] [--plans 60] [--workers 1 2] [--no-ray]

The point test is timed warm (a first small run loads the kernels: the facet test of more
than six cables, the collision kernel of a scene).

Prints numbers only (machines differ); the targets (2 workers >= 1.7x 1 worker on a
reach job, Ray start < 3 s) are printed beside them, never turned into an exit code.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing

from cdh_planner.model.robot import load_robot  # noqa: E402
from cdh_planner.scene.schema import load_scene  # noqa: E402
from cdh_planner.studies import workspace as ws  # noqa: E402
from cdh_planner.studies.executors import RayExecutor, SerialExecutor  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", default=str(ROOT / "config" / "robot2.yaml"))
    ap.add_argument("--samples", type=int, default=200_000)
    ap.add_argument("--plans", type=int, default=60, help="plans of the reach job")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-ray", action="store_true")
    ap.add_argument("--scene", help="a scene file: poses also clear of it, plans around it")
    args = ap.parse_args(argv)

    robot = load_robot(args.robot)
    scene = load_scene(args.scene, robot) if args.scene else None
    low, high = ws.default_box(robot)
    home = ws.default_home(robot, scene=scene)
    spec = ws.WorkspaceSpec(samples=args.samples, seed=args.seed, box_low=low, box_high=high,
                            home_position=home[0], home_quaternion=home[1]).check()
    ws.run_workspace(robot, ws.WorkspaceSpec(**{**spec.__dict__, "samples": 100}), SerialExecutor(),
                     scene=scene)  # warm
    t0 = time.perf_counter()
    points = ws.run_workspace(robot, spec, SerialExecutor(), scene=scene)
    dt = time.perf_counter() - t0
    what = f"{len(robot.base_anchors)} cables" + (", scene" if scene else "")
    print(f"{robot.name} ({what}): point test (sample + validity), one core: {args.samples} poses in "
          f"{dt:.2f} s = {args.samples / dt:,.0f} poses/s; feasible {100 * points.fractions()['feasible']:.2f} %")

    targets = np.flatnonzero(points.feasible)[:args.plans].tolist()
    reach = ws.WorkspaceSpec(**{**spec.__dict__, "reach": True, "timeout_s": 30.0})
    job, calls = ws.Job(robot, reach, scene=scene), [("reach", (j,)) for j in targets]
    _reach("in this process", SerialExecutor(), job, calls)
    if args.no_ray:
        return
    rates = {}
    for w in args.workers:
        ex = RayExecutor(w)
        try:
            print(f"Ray, {w} worker(s): start {ex.start_s:.2f} s (target < 3 s)")
            list(ex.map(job, calls[:w]))  # warm: every actor builds its context, compiles
            rates[w] = _reach(f"Ray, {w} worker(s)", ex, job, calls)
        finally:
            ex.close()
    if 1 in rates and 2 in rates:
        print(f"2 workers / 1 worker: {rates[2] / rates[1]:.2f}x (target >= 1.7x)")


def _reach(label, executor, job, calls):
    t0 = time.perf_counter()
    answers = [a for _, batch in executor.map(job, calls) for a in batch]
    dt = time.perf_counter() - t0
    statuses = [a[1] for a in answers]
    cpu = sum(a[2] for a in answers)
    rate = len(calls) / dt
    print(f"{label}: {len(calls)} plans in {dt:.2f} s = {rate:.2f} plans/s "
          f"(planner time {cpu:.2f} s; {statuses.count('ok')} ok, "
          f"{len(statuses) - statuses.count('ok')} other)")
    return rate


if __name__ == "__main__":
    main()
