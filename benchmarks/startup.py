"""Start-up: whole processes timed from outside.

    .venv/bin/python benchmarks/startup.py [--runs 5] [--skip-node] [--before CHECKOUT]

Rows, each a median over --runs fresh processes (wall seconds, and the CPU seconds the
process used, user + system, which a loaded machine inflates less):

- ``cdh-planner --help``;
- ``cdh-planner plan config/problems/robot2_q1_q2.yaml`` (a query one direct motion
  answers, dynamically timed);
- the floor under that plan: a bare interpreter importing only the library a dynamically
  timed plan cannot do without, numpy (rotations and splines are numpy code,
  ports/rotation.py and ports/splines.py; toppra comes without scipy.interpolate and
  sparse, ports/lean_toppra.py), and for comparison the scipy modules the plan imported
  before (Rotation, which brings scipy.spatial and sparse; scipy.interpolate, which toppra
  imports at its top, with scipy.optimize and special);
- with ``--before CHECKOUT``: the same plan with another checkout first on PYTHONPATH
  (e.g. the main branch's), its runs alternating with this checkout's, so both see the
  same load;
- the node: ``cdh-planner node --ros-args --params-file config/robot2.yaml`` started, timed
  until its ``/cdh_planner/plan`` service (nav_msgs/GetPlan) is seen from this process
  (rclpy initialised here before the node starts, so only the node's start-up is timed;
  its own ROS domain, discovery on localhost), then stopped with SIGINT. Its CPU seconds
  are the node's whole life, the short stop included.

Targets: under 0.15 s, 0.4 s and 2 s. Exit code 0 always (a benchmark).
"""

import argparse
import os
import resource
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CLI = Path(sys.executable).with_name("cdh-planner")
TARGETS = {"--help": 0.15, "plan robot2_q1_q2": 0.4, "node to serving ~/plan": 2.0}
FLOOR = "import numpy"
BEFORE = "import numpy, scipy.spatial.transform, scipy.interpolate"


def cli(*args):
    return [str(CLI), *args] if CLI.exists() else [sys.executable, "-m", "cdh_planner.cli", *args]


def children_cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def timed_run(argv, env=None):
    """(wall s, CPU s) of one process run to its end; output discarded."""
    cpu0, t0 = children_cpu(), time.perf_counter()
    subprocess.run(argv, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True,
                   env=env)
    return time.perf_counter() - t0, children_cpu() - cpu0


def node_to_serving(runs):
    """[(wall s until ~/plan is seen, CPU s of the node process)] over ``runs`` starts."""
    import rclpy
    from nav_msgs.srv import GetPlan

    from cdh_planner.ros.isolation import claimed_domain, isolated_env, stop_process

    out = []
    with claimed_domain() as domain, tempfile.TemporaryDirectory() as logs:
        env = isolated_env(domain)
        os.environ.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
        rclpy.init()
        try:
            node = rclpy.create_node("startup_probe")
            client = node.create_client(GetPlan, "/cdh_planner/plan")
            for _ in range(runs):
                argv = cli("node", "--ros-args", "--params-file", str(ROOT / "config" / "robot2.yaml"),
                           "-p", f"log_dir:={logs}")
                cpu0, t0 = children_cpu(), time.perf_counter()
                proc = subprocess.Popen(argv, cwd=ROOT, env=env, stdout=subprocess.DEVNULL,
                                        stderr=subprocess.DEVNULL)
                while not client.service_is_ready() and time.perf_counter() - t0 < 60.0:
                    time.sleep(0.01)  # finer than wait_for_service's polling
                served, wall = client.service_is_ready(), time.perf_counter() - t0
                stop_process(proc, signal.SIGINT)
                out.append((wall if served else float("nan"), children_cpu() - cpu0))
                while client.service_is_ready():  # the stopped node's service leaves the graph
                    time.sleep(0.05)
            node.destroy_node()
        finally:
            rclpy.shutdown()
    return out


def row(name, samples):
    walls, cpus = [w for w, _ in samples], [c for _, c in samples]
    target = TARGETS.get(name)
    med = statistics.median(walls)
    verdict = "" if target is None else "meets" if med < target else "misses"
    print(f"| {name} | {med:.3f} | {min(walls):.3f} - {max(walls):.3f} | "
          f"{statistics.median(cpus):.3f} | {'' if target is None else f'< {target:g}'} | {verdict} |",
          flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=5, help="fresh processes per row (median)")
    ap.add_argument("--skip-node", action="store_true", help="no ROS node row")
    ap.add_argument("--before", metavar="CHECKOUT", help="also time the plan with this checkout's code")
    args = ap.parse_args(argv)
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs; PYTHONDONTWRITEBYTECODE="
          f"{os.environ.get('PYTHONDONTWRITEBYTECODE', '')!r}", flush=True)
    print("| command | median wall s | range s | median CPU s | target s | |\n|---|---|---|---|---|---|")
    row("--help", [timed_run(cli("--help")) for _ in range(args.runs)])
    plan = cli("plan", "config/problems/robot2_q1_q2.yaml")
    if args.before:
        before_env = dict(os.environ, PYTHONPATH=str(Path(args.before).resolve()))
        pairs = [(timed_run(plan), timed_run(plan, before_env)) for _ in range(args.runs)]
        row("plan robot2_q1_q2", [a for a, _ in pairs])
        row(f"plan robot2_q1_q2 ({args.before})", [b for _, b in pairs])
    else:
        row("plan robot2_q1_q2", [timed_run(plan) for _ in range(args.runs)])
    one_thread = dict(os.environ, OPENBLAS_NUM_THREADS="1")  # as cdh-planner starts numpy
    for code in (FLOOR, BEFORE):
        row(f"python -c '{code}'", [timed_run([sys.executable, "-c", code], one_thread)
                                    for _ in range(args.runs)])
    if not args.skip_node:
        row("node to serving ~/plan", node_to_serving(args.runs))
    return 0


if __name__ == "__main__":
    sys.exit(main())
