"""Cost of the navigation manifold's hot kernel: F (84,) and F_x (84, 90) per call.

    python benchmarks/manifold_kernel.py [--calls N] [--table1] [--reference]

Prints microseconds per call of ``TaskConstraint(robot, task).residual_and_jacobian(x)``
for Robot 2 in free flight at the lifted start pose of robot2_q2_q3_free_flight (and of
``NavigationManifold.residual_and_jacobian`` alone), the best of a few repeats, after the
time of the first call (in a fresh process: importing the ahead-of-time kernel that
``make`` builds, or without it importing numba and loading the JIT kernel from its cache,
or compiling it when there is none); which kernel ran is printed. With ``--table1`` it also
runs ``benchmarks/table1.py --only robot1_qs_qg --strategies astar`` in a fresh process
and prints its output and wall time (process start included). ``--reference`` measures
the numpy reference (test/navigation_reference.py, ``residual_and_jacobian_reference``)
instead of the compiled kernel, in both.
"""

import argparse
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))  # the numpy reference is test code
TABLE1_ARGS = ["--only", "robot1_qs_qg", "--strategies", "astar"]
# table1.py with the numpy reference in place of the kernel
TABLE1_REFERENCE = f"""
import runpy, sys
sys.path.insert(0, {str(ROOT / "test")!r})
from cdh_planner.manifold.navigation import NavigationManifold
from navigation_reference import residual_and_jacobian_reference
NavigationManifold.residual_and_jacobian = residual_and_jacobian_reference
sys.argv = ["table1.py"] + {TABLE1_ARGS!r}
runpy.run_path({str(ROOT / "benchmarks" / "table1.py")!r}, run_name="__main__")
"""


def per_call_us(fun, x, calls, repeats=5):
    fun(x)  # warm-up
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        for _ in range(calls):
            fun(x)
        best = min(best, time.perf_counter() - t)
    return 1e6 * best / calls


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--calls", type=int, default=2000, help="calls per repeat (default 2000)")
    ap.add_argument("--table1", action="store_true", help="also time the table1 robot1_qs_qg astar row")
    ap.add_argument("--reference", action="store_true", help="measure the numpy reference, not the kernel")
    args = ap.parse_args(argv)

    t0 = time.perf_counter()
    from cdh_planner.parsing.problem import load_problem
    from cdh_planner.manifold.constraint import TaskConstraint
    from cdh_planner.manifold.navigation import N_VARS, NavigationManifold
    from cdh_planner.model.task import FreeTask
    t_import = time.perf_counter() - t0
    if args.reference:
        from navigation_reference import residual_and_jacobian_reference
        NavigationManifold.residual_and_jacobian = residual_and_jacobian_reference

    pr = load_problem(ROOT / "config" / "problems" / "robot2_q2_q3_free_flight.yaml")
    c = TaskConstraint(pr.robot, FreeTask())
    x = c.lift(pr.start.p, pr.start.tau)
    X = (x * c.scale)[:N_VARS]
    t0 = time.perf_counter()
    c.residual_and_jacobian(x)
    t_first = time.perf_counter() - t0

    if args.reference:
        which = "numpy reference"
    else:
        from cdh_planner.manifold import kernels
        which = ("compiled kernel, ahead of time" if c.nav._kernel is kernels.aot_kernel()
                 else "compiled kernel, numba JIT")
    print(f"F, F_x by the {which}")
    print(f"import cdh_planner modules               {1e3 * t_import:8.1f} ms")
    print(f"first call in this process               {1e3 * t_first:8.1f} ms")
    for name, fun, arg in [("TaskConstraint.residual_and_jacobian", c.residual_and_jacobian, x),
                           ("NavigationManifold.residual_and_jacobian", c.nav.residual_and_jacobian, X),
                           ("NavigationManifold.residual", c.nav.residual, X)]:
        print(f"{name:40s} {per_call_us(fun, arg, args.calls):8.1f} us/call")

    if args.table1:
        if args.reference:
            cmd = [sys.executable, "-c", TABLE1_REFERENCE]
        else:
            cmd = [sys.executable, str(ROOT / "benchmarks" / "table1.py")] + TABLE1_ARGS
        t0 = time.perf_counter()
        out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=False)
        wall = time.perf_counter() - t0
        print(out.stdout.rstrip())
        if out.returncode:
            print(out.stderr.rstrip(), file=sys.stderr)
        print(f"table1 robot1_qs_qg astar: process wall {wall:.2f} s")


if __name__ == "__main__":
    main()
