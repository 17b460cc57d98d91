"""Robot 2 free flight past one obstacle: whole ``cdh-planner plan`` calls against OMPL's
RRTConnect on the same queries.

    .venv/bin/python benchmarks/obstacles.py [--cases 9] [--seed 0] [--repeats 3]
        [--timeout 30] [--only 0 3 ...] [--no-ompl] [--checkout DIR] [--keep DIR]

Queries (fixed seed): two random wrench-feasible Robot 2 poses (benchmarks/random_queries.py's
``feasible_poses``, within 30 deg of q2's orientation) whose straight motion (position linear, orientation slerp) is
dense-feasible without obstacles (cables clear of each other too), and one obstacle on it: at the straight motion's midpoint,
a point 30 - 70 % along a random cable; in turn a sphere (radius 1 - 2 cm), a box (edges
1.5 - 3 cm, random orientation) and a bead on the cable (a sphere of 4 - 6 mm). Kept when
both ends are at least 5 mm clear of it and the straight motion hits it (so every case
needs a planner). Cable radius 1 mm.

- ours: ``cdh-planner plan PROBLEM --json OUT --quiet`` (the problem and scene written to a
  temporary folder), each in a fresh process; seconds = the process's wall clock, and its
  CPU seconds (user + system: a loaded machine inflates them less), and in-process the plan
  call's own time (the JSON's ``time_s``: lift to the executed check).
  ``--keep DIR`` also writes each case's problem file as DIR/case_K.yaml (to profile a case).
- ompl: OMPL RRTConnect in SE(3) (benchmarks/vs_ompl.py's SE3Adapter and bounds) with this
  project's validity as the point-wise checker: a state is valid iff
  ``pipeline.validity.Validity.pose_margins`` (the wrench margin joined with the
  collision margin) is > 0; motions at OMPL's default resolution; in a fresh process
  (this script with ``--child``); seconds = setup + solve + simplifySolution, as in
  vs_ompl.py, and the process's wall clock and CPU seconds (which include the child's own
  dense check of the path for the "unsafe" count, a few ms). Like ours, with one BLAS thread
  from its start (OPENBLAS_NUM_THREADS=1 unless set): else the pool it starts costs ~30 ms.

Both run on a case before the next case starts (interleaved). Every path is checked
densely with the scene (``trajectory.path_check.check_motion`` with the collision model,
1 mm / 0.2 deg steps): "unsafe" counts paths that fail it. Medians over ``--repeats`` runs
per case, then the median over the cases (a timeout counts as --timeout); the last line
compares the whole processes (ours / OMPL's median wall and CPU). ``--checkout DIR``: both
sides run DIR's cdh_planner (OMPL's validity too), for a before/after. Needs ompl
(benchmarks/requirements.txt) for the OMPL column; ``--no-ompl`` runs ours only.
"""

import argparse
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from random_queries import feasible_poses  # benchmarks/random_queries.py, beside this script
from cdh_planner.model.pose import Pose, quaternion_from_tau, rotation_tt
from cdh_planner.model.robot import load_robot
from cdh_planner.ports.rotation import Rotation
from cdh_planner.scene.collision import CollisionModel
from cdh_planner.scene.schema import scene_from_dict
from cdh_planner.trajectory.path_check import SlerpPath, check_motion, check_path

ROOT = Path(__file__).resolve().parents[1]
ROBOT = ROOT / "config" / "robot2.yaml"
# orientations near this problem's start (q2): the cables clear of each other (near the
# largest-margin orientation that random_queries.py uses, Robot 2's cables cross)
HOME_PROBLEM = ROOT / "config" / "problems" / "robot2_q2_q3_ball.yaml"
CABLE_RADIUS = 0.001  # m
END_CLEARANCE = 0.005  # m: both ends at least this clear of the obstacle
SHAPES = ("sphere", "box", "bead")
DRAWS = 100  # pose pairs drawn at a time
MIN_MARGIN, MAX_TILT = 0.02, np.pi / 6  # both ends: wrench margin, rad from home orientation
PLANNER = {"radius": 0.5}  # free flight: as config/problems/robot2_q2_q3_ball.yaml


def obstacle(kind, centre, rng):
    """A scene obstacle (dict) of ``kind`` centred at ``centre``."""
    c = [float(v) for v in centre]
    if kind == "sphere":
        return {"id": "ball", "type": "sphere", "radius": float(rng.uniform(0.01, 0.02)), "position": c}
    if kind == "bead":
        return {"id": "bead", "type": "sphere", "radius": float(rng.uniform(0.004, 0.006)), "position": c}
    q = rng.standard_normal(4)
    return {"id": "block", "type": "box", "size": [float(v) for v in rng.uniform(0.015, 0.03, 3)],
            "position": c, "quaternion": [float(v) for v in q / np.linalg.norm(q)]}


def cases(robot, count, seed):
    """``count`` (start Pose, goal Pose, scene dict) with the straight motion blocked by the
    scene's one obstacle only."""
    rng = np.random.default_rng(seed)
    start = yaml.safe_load(HOME_PROBLEM.read_text())["start"]["tau"]
    home = Rotation.from_matrix(rotation_tt(np.array([start]))[0])
    out = []
    while len(out) < count:
        P, TAU = feasible_poses(robot, 2 * DRAWS, rng, MIN_MARGIN, MAX_TILT, home)
        out += _blocked(robot, P, TAU, rng, count - len(out))
    return out


def _blocked(robot, P, TAU, rng, count):
    """Up to ``count`` cases from the pose pairs (P[2j], P[2j + 1])."""
    out = []
    empty = CollisionModel(robot, scene_from_dict({"cable_radius": CABLE_RADIUS, "obstacles": []}))
    for j in range(0, len(P) - 1, 2):
        if len(out) == count:
            break
        p, tau = P[j:j + 2], TAU[j:j + 2]
        motion = SlerpPath(p, quaternion_from_tau(tau))
        if not check_path(robot, motion, collision=empty)[0].feasible:
            continue  # wrench-unsafe or cables crossing already: not an obstacle case
        pm, Rm = motion(np.zeros(1, dtype=int), np.array([0.5]))
        i = rng.integers(len(robot.base_anchors))
        a, b = robot.base_anchors[i], pm[0] + Rm[0] @ robot.platform_anchors[i]
        kind = SHAPES[len(out) % len(SHAPES)]
        scene = {"cable_radius": CABLE_RADIUS,
                 "obstacles": [obstacle(kind, a + rng.uniform(0.3, 0.7) * (b - a), rng)]}
        cm = CollisionModel(robot, scene_from_dict(scene))
        R = rotation_tt(tau)
        if min(d for n in range(2) for kind, oid, _, d in cm.distances(p[n], R[n])
               if oid is not None) < END_CLEARANCE:
            continue
        if check_path(robot, motion, collision=cm)[0].feasible:
            continue
        out.append((Pose(p[0], tau[0]), Pose(p[1], tau[1]), scene))
    return out


def problem_file(folder, start, goal, scene, timeout):
    path = Path(folder) / "problem.yaml"
    path.write_text(yaml.safe_dump({
        "description": "benchmarks/obstacles.py case", "robot": str(ROBOT), "task": {"type": "free"},
        "planner": dict(PLANNER, timeout_s=float(timeout)), "scene": scene,
        "start": {"position": start.p.tolist(), "tau": start.tau.tolist()},
        "goal": {"position": goal.p.tolist(), "tau": goal.tau.tolist()}}))
    return path


def safe(robot, scene, p, quat):
    cm = CollisionModel(robot, scene_from_dict(scene))
    return all(s.feasible for s in check_motion(robot, p, quat, collision=cm))


def children_cpu():
    """CPU seconds (user + system) of this process's finished children."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run_ours(robot, case, timeout, checkout=ROOT):
    """(status, process wall s, process CPU s, in-process plan s, safe) of one whole
    ``cdh-planner plan`` call (``checkout``'s cdh_planner first on PYTHONPATH)."""
    start, goal, scene = case
    with tempfile.TemporaryDirectory() as tmp:
        problem, out = problem_file(tmp, start, goal, scene, timeout), Path(tmp) / "plan.json"
        t, cpu = time.perf_counter(), children_cpu()
        try:
            subprocess.run([sys.executable, "-m", "cdh_planner.cli", "plan", str(problem), "--json",
                            str(out), "--quiet"], cwd=checkout, timeout=timeout + 30,
                           env=dict(os.environ, PYTHONPATH=str(checkout)),
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        except subprocess.TimeoutExpired:
            return "timeout", timeout, timeout, timeout, None
        seconds, cpu = time.perf_counter() - t, children_cpu() - cpu
        if not out.exists():
            return "error", seconds, cpu, seconds, None
        d = json.loads(out.read_text())
        if not d["success"]:
            return d["reason"], seconds, cpu, d["time_s"], None
        p = np.array([w["p"] for w in d["path"]])
        q = np.array([w["quaternion"] for w in d["path"]])
        return "path", seconds, cpu, d["time_s"], safe(robot, scene, p, q)


def run_ompl(case, timeout, checkout=ROOT):
    """(status, seconds of setup + solve + simplify, process wall s, process CPU s, safe)
    in a fresh process (``checkout``'s cdh_planner first on PYTHONPATH: its validity)."""
    start, goal, scene = case
    job = json.dumps({"start": [start.p.tolist(), start.tau.tolist()],
                      "goal": [goal.p.tolist(), goal.tau.tolist()], "scene": scene, "timeout": timeout})
    t, cpu = time.perf_counter(), children_cpu()
    try:
        res = subprocess.run([sys.executable, __file__, "--child", job], capture_output=True, text=True,
                             timeout=timeout + 60, cwd=ROOT,
                             # one BLAS thread from the start unless told otherwise, as
                             # cdh-planner sets for itself: else OpenBLAS starts its pool
                             # (~30 ms of the process), then told to use one thread
                             env={"OPENBLAS_NUM_THREADS": "1", **os.environ, "PYTHONPATH": str(checkout)})
    except subprocess.TimeoutExpired:
        return "timeout", timeout, timeout, timeout, None
    wall, cpu = time.perf_counter() - t, children_cpu() - cpu
    try:
        d = json.loads(res.stdout.strip().splitlines()[-1])
    except (IndexError, json.JSONDecodeError):
        return "error", wall, wall, cpu, None
    return d["status"], d["seconds"], wall, cpu, d["safe"]


def child(job):
    """OMPL RRTConnect on one case (``--child``): prints one JSON line."""
    from vs_ompl import Query, rrt_connect, SE3Adapter
    from cdh_planner.model.task import FreeTask
    from cdh_planner.pipeline.validity import Validity
    from cdh_planner.planner import PlannerSettings
    import vs_ompl

    d = json.loads(job)
    robot = load_robot(ROBOT)
    scene = scene_from_dict(d["scene"])
    validity = Validity(robot, FreeTask(), 0.0, scene=scene)

    def valid(self, s):  # this project's validity, point-wise
        r = s.rotation()
        R = vs_ompl.quaternion_matrix(r.x, r.y, r.z, r.w)
        return bool(validity.pose_margins(np.array([[s.getX(), s.getY(), s.getZ()]]), R=R)[0][0] > 0)

    SE3Adapter.valid = valid
    q = Query("obstacle", robot, FreeTask(), PlannerSettings(), Pose(*map(np.array, d["start"])),
              Pose(*map(np.array, d["goal"])))
    status, motion, seconds = rrt_connect(False)(q, d["timeout"])
    ok = safe(robot, d["scene"], *motion) if motion is not None else None
    print(json.dumps({"status": status, "seconds": seconds, "safe": ok}))


def median(xs):
    return statistics.median(xs) if xs else float("nan")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=9)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--timeout", type=float, default=30.0)
    ap.add_argument("--only", type=int, nargs="*", help="case indices to run")
    ap.add_argument("--no-ompl", action="store_true")
    ap.add_argument("--checkout", type=Path, default=ROOT,
                    help="plan with this checkout's cdh_planner, and give OMPL its validity (e.g. "
                         "main's, for a before/after)")
    ap.add_argument("--keep", type=Path, help="write each case's problem file into this folder")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        return child(args.child)
    robot = load_robot(ROBOT)
    all_cases = cases(robot, args.cases, args.seed)
    if args.keep:
        args.keep.mkdir(parents=True, exist_ok=True)
        for k, case in enumerate(all_cases):
            problem_file(args.keep, *case, args.timeout).rename(args.keep / f"case_{k}.yaml")
    try:
        import ompl  # noqa: F401
        use_ompl = not args.no_ompl
    except ImportError:
        use_ompl = False
        print("ompl not installed (pip install -r benchmarks/requirements.txt): ours only")
    # per case, the median over the repeats of: ours (process wall, process CPU, in-process)
    # and OMPL's (in-process, process wall, process CPU)
    ours_med, ompl_med, unsafe, solved = [], [], {"ours": 0, "ompl": 0}, {"ours": 0, "ompl": 0}
    print("seconds, medians over the repeats; ours: whole process wall / CPU and the plan call "
          "in-process; ompl: setup + solve + simplify in-process, whole process wall / CPU")
    print(f"{'case':>4} {'obstacle':>8} | {'ours wall':>9} {'cpu':>5} {'in-proc':>7} {'status':>8} | "
          f"{'ompl in-proc':>12} {'wall':>5} {'cpu':>5} {'status':>8}")
    for k, case in enumerate(all_cases):
        if args.only and k not in args.only:
            continue
        runs_ours, runs_ompl = [], []
        for _ in range(args.repeats):
            runs_ours.append(run_ours(robot, case, args.timeout, args.checkout.resolve()))
            if use_ompl:
                runs_ompl.append(run_ompl(case, args.timeout, args.checkout.resolve()))
        for name, runs in (("ours", runs_ours), ("ompl", runs_ompl)):
            unsafe[name] += sum(r[-1] is False for r in runs)
            solved[name] += any(r[0] == "path" for r in runs)
        mo = [median([r[c] for r in runs_ours]) for c in (1, 2, 3)]
        ours_med.append(mo)
        line = (f"{k:>4} {case[2]['obstacles'][0]['id']:>8} | {mo[0]:>9.2f} {mo[1]:>5.2f} "
                f"{mo[2]:>7.2f} {runs_ours[0][0]:>8} |")
        if use_ompl:
            mp = [median([r[c] for r in runs_ompl]) for c in (1, 2, 3)]
            ompl_med.append(mp)
            line += f" {mp[0]:>12.2f} {mp[1]:>5.2f} {mp[2]:>5.2f} {runs_ompl[0][0]:>8}"
        print(line, flush=True)
    print(f"ours: {_summary(ours_med, ('process wall', 'process CPU', 'in-process'))}; "
          f"{solved['ours']} of {len(ours_med)} solved, {unsafe['ours']} unsafe paths")
    if use_ompl:
        print(f"ompl RRTConnect: {_summary(ompl_med, ('in-process', 'process wall', 'process CPU'))}; "
              f"{solved['ompl']} of {len(ompl_med)} solved, {unsafe['ompl']} unsafe paths")
        if ours_med:  # like with like: whole processes
            ratio = [median([r[c] for r in ours_med]) / median([r[c + 1] for r in ompl_med])
                     for c in (0, 1)]
            print(f"ours / ompl, whole processes (medians): wall {ratio[0]:.2f}x, CPU {ratio[1]:.2f}x")
    return 0


def _summary(rows, names):
    """"name median s (least - most)" of each column of the per-case medians ``rows``."""
    cols = list(zip(*rows)) or [()] * len(names)
    return ", ".join(f"{n} median {median(c):.2f} s ({min(c, default=math.nan):.2f} - "
                     f"{max(c, default=math.nan):.2f})" for n, c in zip(names, cols))


if __name__ == "__main__":
    sys.exit(main())
