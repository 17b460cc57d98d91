"""Reach-job scaling on a local Ray (target: 2 workers >= 1.7x faster than 1): the same
plans on 1 and on 2 workers, alternated (1, 2, 1, 2, ...: each pair sees about the same load
on a shared machine), medians printed, and the ratio.

    python benchmarks/workspace_scaling.py [--plans 80] [--rounds 3] [--robot config/robot2.yaml]

Per run: the wall time of the job (warm actors: each has planned once, its kernels loaded),
plans/s, the workers' CPU seconds and the share of a core each got (CPU / (wall x workers):
below 1 when other processes held the cores), the CPU seconds of the driver and of Ray's
own daemons (raylet, GCS, agents: what the job costs beside the plans), and the load
average; and a core-bound estimate of the ratio from the CPU seconds (what an idle machine
would give: the busiest worker's CPU, or all the CPU over the cores, whichever is more),
robust to the load where the measured ratio is not. Prints numbers only; the target is printed beside the ratio, never an exit code.
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

from cdh_planner.model.robot import load_robot  # noqa: E402
from cdh_planner.studies import workspace as ws  # noqa: E402
from cdh_planner.studies.executors import RayExecutor, SerialExecutor  # noqa: E402


def reach_job(robot_file, plans, seed):
    """(job, targets): the first ``plans`` feasible samples of Robot 2's default study."""
    robot = load_robot(robot_file)
    low, high = ws.default_box(robot)
    home = ws.default_home(robot)
    spec = ws.WorkspaceSpec(samples=20 * plans, seed=seed, box_low=low, box_high=high,
                            home_position=home[0], home_quaternion=home[1], reach=True,
                            timeout_s=30.0).check()
    points = ws.run_workspace(robot, ws.WorkspaceSpec(**{**spec.__dict__, "reach": False}),
                              SerialExecutor())
    return ws.Job(robot, spec), np.flatnonzero(points.feasible)[:plans].tolist()


def descendants_cpu_seconds():
    """CPU seconds (user + system) of every process below this one (Ray's daemons and
    workers), from /proc (Linux; 0 elsewhere)."""
    parent, cpu = {}, {}
    tick = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    for d in Path("/proc").glob("[0-9]*"):
        try:
            fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue  # gone meanwhile
        parent[int(d.name)] = int(fields[1])
        cpu[int(d.name)] = (int(fields[11]) + int(fields[12])) / tick
    me, total = os.getpid(), 0.0
    for pid in cpu:
        p = pid
        while p in parent and p != me and p > 1:
            p = parent[p]
        total += cpu[pid] if p == me and pid != me else 0.0
    return total


def run(workers, job, targets):
    """One timed run on a fresh local Ray of ``workers``: a dict of the figures."""
    ex = RayExecutor(workers)
    try:
        list(ex.map(job, [("reach", (j,)) for j in targets[:workers]]))  # warm every actor
        cpu0, tree0 = np.array(ex.cpu_seconds()), descendants_cpu_seconds()
        driver0, t0 = time.process_time(), time.perf_counter()
        answers = [a for _, batch in ex.map(job, ws.reach_calls(targets, workers)) for a in batch]
        wall = time.perf_counter() - t0
        driver, each = time.process_time() - driver0, np.array(ex.cpu_seconds()) - cpu0
        cpu = float(each.sum())
        ray_cpu = descendants_cpu_seconds() - tree0 - cpu
    finally:
        ex.close()
    assert sorted(a[0] for a in answers) == sorted(targets)
    # the wall time if each worker had a core of its own (an idle machine): the busiest
    # worker's CPU, or all the CPU (the driver's and Ray's daemons' too) over the cores
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    idle = max(float(each.max()), (cpu + driver + ray_cpu) / cores)
    return {"workers": workers, "wall": wall, "idle": idle, "rate": len(targets) / wall, "cpu": cpu,
            "share": cpu / (wall * workers), "driver": driver, "ray": ray_cpu, "start": ex.start_s,
            "load": os.getloadavg()[0], "ok": sum(a[1] == "ok" for a in answers)}


def autogroup_note():
    """A line on Linux's autogroup scheduling, which shares the cores between sessions
    (terminals, jobs) first: the workers, in this process's session, share one session's
    slice when other sessions are busy, however many they are."""
    try:
        on = Path("/proc/sys/kernel/sched_autogroup_enabled").read_text().strip() == "1"
    except OSError:
        return "autogroup scheduling: unknown (not Linux?)"
    return ("autogroup scheduling on: the workers share this session's slice of the cores; "
            "with other sessions busy, 2 workers get no more CPU than 1" if on else
            "autogroup scheduling off")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", default=str(ROOT / "config" / "robot2.yaml"))
    ap.add_argument("--plans", type=int, default=80)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    job, targets = reach_job(args.robot, args.plans, args.seed)
    print(f"{len(targets)} plans (Robot 2 seed {args.seed}, default box and home, 30 deg tilt); "
          f"{args.rounds} rounds of 1 worker then 2; {autogroup_note()}")
    runs = {1: [], 2: []}
    for r in range(args.rounds):
        for w in (1, 2):
            x = run(w, job, targets)
            runs[w].append(x)
            print(f"  round {r + 1}, {w} worker(s): {x['wall']:.2f} s = {x['rate']:.2f} plans/s "
                  f"({x['ok']} ok); workers' CPU {x['cpu']:.2f} s = {x['share']:.2f} of a core "
                  f"each; driver CPU {x['driver']:.2f} s, Ray's daemons {x['ray']:.2f} s; Ray start {x['start']:.2f} s; "
                  f"load {x['load']:.2f}", flush=True)
    med = {w: statistics.median(x["rate"] for x in runs[w]) for w in runs}
    pairs = [b["rate"] / a["rate"] for a, b in zip(runs[1], runs[2])]
    print(f"median plans/s: 1 worker {med[1]:.2f}, 2 workers {med[2]:.2f}")
    idle = [a["idle"] / b["idle"] for a, b in zip(runs[1], runs[2])]
    print(f"core-bound estimate (each worker a core of its own; from the CPU seconds, not the "
          f"wall clock): {statistics.median(idle):.2f}x, per round {', '.join(f'{p:.2f}' for p in idle)}")
    print(f"2 workers / 1 worker: {med[2] / med[1]:.2f}x of the medians, per round "
          f"{', '.join(f'{p:.2f}' for p in pairs)} (target >= 1.7x); "
          f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f}")


if __name__ == "__main__":
    main()
