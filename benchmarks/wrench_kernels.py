"""The compiled kernels in a fresh process, and the wrench kernels on threads.

    .venv/bin/python benchmarks/wrench_kernels.py [--runs 3] [--poses 4096 20000 100000]

1. First call of each compiled kernel in a fresh interpreter (the manifold's F / F_x, the
   collision kernel, the wrench entries' pose geometry, facet test and centred rule of
   CoGiRo), ms wall and CPU, median of ``--runs`` processes, and whether numba was imported.
   Target: under 20 ms each, numba never imported (built ahead of time by ``make``).
2. The facet test plus the centred rule on CoGiRo batches of ``--poses`` poses, on the
   caller's thread (``CDH_PLANNER_THREADS=1``) against blocks on one thread a core
   (``cdh_planner.parallel``: the builds release the GIL), wall s, median of ``--runs``.

On a shared machine wall figures are inflated by the load (printed); CPU figures are not,
except that threads spend CPU time waiting. Exit code 0 always.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing

from cdh_planner.model.pose import rotation_tt  # noqa: E402
from cdh_planner.model.robot import load_robot  # noqa: E402

COGIRO = ROOT / "config" / "cogiro.yaml"
TARGET_MS = 20.0

# one kernel's first call in a fresh interpreter; prints [wall ms, CPU ms, numba imported]
SETUP = f"""
import json, sys, time
import numpy as np
from cdh_planner.model.robot import load_robot
robot = load_robot({str(COGIRO)!r})
p, R = np.array([[0.0, 0.0, 2.5]]), np.eye(3)[None]
"""
CALLS = {  # name: (untimed preparation, timed first use: the kernel's import and call; the
    # collision kernel's module is imported untimed: coal's import is most of it)
    "manifold F / F_x": ("",
                         "from cdh_planner.manifold import kernels as k\n"
                         "X, prm = np.ones(k.N_VARS), np.ones(k.N_PARAMS)\n"
                         "prm[k.K_KAPPA] = 0.1\nprm[k.K_LMAX:k.K_FMIN] = 3.0\n"
                         "prm[k.K_FMAX:k.K_KAPPA] = 4.0\n"
                         "k.navigation_residual_and_jacobian(X, prm, True)"),
    "collision kernel": (f"from cdh_planner.scene.collision import CollisionModel\n"
                         f"from cdh_planner.scene.schema import load_scene\n"
                         f"r2 = load_robot({str(ROOT / 'config' / 'robot2.yaml')!r})\n"
                         f"scene = load_scene("
                         f"{str(ROOT / 'config' / 'scenes' / 'robot2_ball.yaml')!r}, r2)\n",
                         "CollisionModel(r2, scene).clearance(np.array([0, 0, 0.4]), np.eye(3))"),
    "wrench pose geometry": ("", "from cdh_planner.wrench import compiled as k\n"
                                 "k.pose_geometry(p, R, robot.base_anchors, "
                                 "robot.platform_anchors, robot.load_point)"),
    "wrench facet test (+geometry, rule)": ("from cdh_planner import wrench\n",
                                            "wrench.wrench_feasibility(robot, p, R=R)"),
    "wrench centred rule (+geometry)": ("from cdh_planner import wrench\n",
                                        "wrench.rule_tensions(robot, p, R)"),
}


def first_call(prepare, call):
    """[wall ms, CPU ms, numba imported] of ``call`` after ``prepare`` in a fresh process."""
    body = "\n    ".join(call.splitlines())
    code = (SETUP + prepare + "_w, _c = time.perf_counter(), time.process_time()\n"
            f"if True:\n    {body}\n"
            "print(json.dumps([1e3 * (time.perf_counter() - _w), 1e3 * (time.process_time() - _c), "
            "'numba' in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=ROOT)
    return json.loads(out.stdout.strip().splitlines()[-1])


def batch(robot, n, seed=0):
    """The facet test's and the centred rule's arguments at n CoGiRo poses (a slow walk)."""
    from cdh_planner.wrench import compiled
    from cdh_planner.wrench.facets import facet_subsets
    from cdh_planner.wrench.geometry import inverse_factor
    rng = np.random.default_rng(seed)
    p = np.array([0.0, 0.0, 2.5]) + np.cumsum(rng.normal(0.0, 0.002, (n, 3)), axis=0)
    R = rotation_tt(np.cumsum(rng.normal(0.0, 0.002, (n, 3)), axis=0))
    _, _, J, c = compiled.pose_geometry(p, R, robot.base_anchors, robot.platform_anchors,
                                        robot.load_point)
    e = (robot.wrench_center_local, inverse_factor(robot), robot.ellipsoid_frame == "load",
         robot.tension_min, robot.tension_max)
    return J, c, e, facet_subsets(len(robot.base_anchors))


def serial_and_threaded(robot, n, runs):
    """Median wall s of the facet test + centred rule on n poses: on the caller's thread,
    in blocks on threads."""
    from cdh_planner.wrench import compiled
    J, c, e, subsets = batch(robot, n)

    def run():
        out = compiled.facet_batch(J, c, *e, subsets, 1e-9)
        compiled.centred_batch(J, c, *e, out[-1], out[-1] & (out[2] > 0))

    times = {}
    for name, threads in (("serial", "1"), ("threaded", "")):
        os.environ["CDH_PLANNER_THREADS"] = threads
        run()
        samples = []
        for _ in range(runs):
            t = time.perf_counter()
            run()
            samples.append(time.perf_counter() - t)
        times[name] = statistics.median(samples)
    os.environ.pop("CDH_PLANNER_THREADS")
    return times["serial"], times["threaded"]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--poses", type=int, nargs="+", default=[4096, 20_000, 100_000])
    args = parser.parse_args(argv)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    print(f"1. first call in a fresh process, median of {args.runs} (target < {TARGET_MS:.0f} ms, "
          "no numba)")
    for name, (prepare, call) in CALLS.items():
        rows = [first_call(prepare, call) for _ in range(args.runs)]
        wall, cpu = (statistics.median(r[i] for r in rows) for i in (0, 1))
        numba = any(r[2] for r in rows)
        print(f"  {name:38s} {wall:8.1f} ms wall {cpu:8.1f} ms CPU  numba imported: {numba}")
    robot = load_robot(COGIRO)
    from cdh_planner import parallel
    print(f"2. CoGiRo facet test + centred rule, median of {args.runs}: the caller's thread vs "
          f"blocks on {parallel.threads()} threads")
    for n in args.poses:
        s, t = serial_and_threaded(robot, n, args.runs)
        print(f"  {n:>9,d} poses: one thread {s:.3f} s ({n / s:,.0f} poses/s), threads {t:.3f} s "
              f"({n / t:,.0f} poses/s, {s / t:.2f}x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
