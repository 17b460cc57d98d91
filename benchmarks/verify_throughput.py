"""Throughput of the whole ``cdh-planner verify ROBOT POSES --json OUT`` command: poses per
second over N poses of a slow random walk (consecutive poses about 0.3 mm and 0.05 deg apart,
so each segment needs few samples), for Robot 2 (6 cables) and CoGiRo (8 cables), without and
with ``--scene`` (Robot 2: config/scenes/robot2_ball.yaml; CoGiRo: a ball written next to the
walk, no scene file ships for it).

    python benchmarks/verify_throughput.py [--poses N] [--runs K]

Each run is a fresh process (``python -m cdh_planner.cli verify ...``, stdout to /dev/null);
printed: the median over K runs of poses per wall-clock second and per CPU second of the
child (user + system), and the machine's load average (on a shared machine the wall figure
is the CPU figure times the child's share of a core). Target: >= 60,000 poses/s whole
command for 20,000 poses; a miss is printed, not turned into a failing exit code.
"""

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TARGET = 60_000
# robot -> (start position m, start tau rad, scene file or None to write one)
CASES = {"robot2": ((0.0, 0.0, 0.3), (0.0, 0.0, 0.0), ROOT / "config/scenes/robot2_ball.yaml"),
         "cogiro": ((0.0, 0.0, 2.5), (0.0, 0.0, 0.0), None)}
COGIRO_SCENE = """scene:
  cable_radius: 0.01
  obstacles:
    - {id: ball, type: sphere, radius: 0.2, position: [1.5, 1.0, 1.0]}
"""


def random_walk(start_p, start_tau, n, seed=0):
    """n poses as JSON-ready dicts: positions a random walk of 0.3 mm steps (m), tau
    (phi, theta, sigma) rad a walk of about 1e-3 rad steps with theta kept in [0, 0.2]."""
    rng = np.random.default_rng(seed)
    p = np.asarray(start_p) + np.cumsum(rng.normal(0.0, 0.3e-3 / np.sqrt(3), (n, 3)), axis=0)
    tau = np.asarray(start_tau) + np.cumsum(rng.normal(0.0, 1e-3, (n, 3)), axis=0)
    tau[:, 1] = 0.1 + 0.1 * np.sin(tau[:, 1])  # tilt in [0, 0.2] rad, still a slow walk
    return [{"position": pi.tolist(), "tau": ti.tolist()} for pi, ti in zip(p, tau)]


def run_once(args):
    """(wall s, CPU s of the child, exit code) of one fresh ``cdh-planner`` process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "cdh_planner.cli", *args], cwd=ROOT,
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode not in (0, 1):
        raise SystemExit(f"verify failed ({proc.returncode}): {proc.stderr.strip()}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, proc.returncode


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--poses", type=int, default=20_000)
    ap.add_argument("--runs", type=int, default=3)
    opts = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; "
          f"{opts.poses} poses, median of {opts.runs} fresh processes")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for name, (p0, tau0, scene) in CASES.items():
            poses = tmp / f"{name}_poses.json"
            poses.write_text(json.dumps(random_walk(p0, tau0, opts.poses)))
            if scene is None:
                scene = tmp / f"{name}_scene.yaml"
                scene.write_text(COGIRO_SCENE)
            for label, extra in (("no scene", []), ("scene", ["--scene", str(scene)])):
                args = ["verify", f"config/{name}.yaml", str(poses), "--json",
                        str(tmp / "out.json"), *extra]
                runs = [run_once(args) for _ in range(opts.runs)]
                wall = statistics.median(r[0] for r in runs)
                cpu = statistics.median(r[1] for r in runs)
                rate = opts.poses / wall
                print(f"{name:8s} {label:9s} exit {runs[0][2]}  {rate:9.0f} poses/s wall "
                      f"({wall:.2f} s)  {opts.poses / cpu:9.0f} poses/s CPU ({cpu:.2f} s)"
                      f"{'' if rate >= TARGET else f'  below target {TARGET}'}")
    print(f"load average {os.getloadavg()[0]:.2f} after")


if __name__ == "__main__":
    main()
