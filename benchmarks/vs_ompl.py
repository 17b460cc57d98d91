"""Our planner against OMPL's RRTConnect, side by side on the same queries.

    .venv/bin/python benchmarks/vs_ompl.py [--queries 50] [--seed 0] [--timeout 30]
        [--repeats 3] [--only ROW ...] [--skip-table1] [--skip-random]

(`make bench` installs benchmarks/requirements.txt, i.e. OMPL 2.0.1, first; without ompl
the script says so and runs our planner only.)

Queries: the seven Table 1 problems (config/problems) and ``--queries`` random free-flight
queries (benchmarks/random_queries.py: both ends feasible, the straight motion unsafe), half on Robot 1
and half on Robot 2. Every planner runs on a query before the next query starts
(interleaved, so load changes hit all alike).

Table 1 rows, cold and warm: each planner on each row in ``--repeats`` fresh processes
(this script with ``--child``), each planning the row twice: "cold" is the first call (in a
process that has imported numpy, OMPL and the planner's modules, nothing more: whatever a
first call loads or compiles is in it), "warm" the second (a new Planner, as a new request
to a running node is). "start" is the process's start until it is ready to plan (imports).
Both calls are checked. The ratios are against OMPL-fine's cold and warm medians. Random
queries: one process, each planner on each query once (warm after the first).

- ours-astar, ours-gbf: ``Planner.plan`` (lift, search, smoothing, densification, time
  parameterisation); seconds = the whole call.
- ompl-def, ompl-fine: RRTConnect, a state valid iff the closed-form margin is > 0. Free
  flight in SE(3) (position box: the base anchors in x, y; 0 .. longest cable in z); task
  rows in the task's coordinates (SO(2) for phi, sigma, alpha1). Motions checked at
  OMPL's default resolution (1 % of the space's maximum extent) or a fine one: steps of
  1e-3 in OMPL's SE(3) distance (|dp| m + half the rotation angle, so <= 1 mm and
  <= 0.12 deg) or 0.2 deg in task coordinates. Seconds = setup + solve + simplifySolution.
- ompl-atlas (Table 1 rows only): OMPL's AtlasStateSpace + RRTConnect on our navigation
  manifold (delta 0.1, rho 0.5, epsilon 0.1, alpha pi/8); seconds = solve only.

Every returned path is checked again, densely (trajectory.path_check: 1 mm / 0.2 deg steps,
adaptive refinement) between consecutive states as the planner moves between them:
position linear + slerp for free flight, straight lines in task coordinates (periodic
ones along the short arc) on task rows. "answered": a path, or our clean "no_path".
"answered right": a path that passes that check, or "no_path" on a query for which no
planner found a safe path. Cost: the task's metric (Planner's cost: SO(3) rad, great
circle m, SE(3) |dp| + L angle m) along the path, the same for every planner. Medians and
p90 of seconds count a timeout as the time limit. Peak memory: the process's peak RSS
(VmHWM, reset through /proc/self/clear_refs before each call) minus its RSS at the call's
start after gc.collect() and malloc_trim(0), MB (what the call itself added). BLAS is
limited to --blas-threads (default 1) with threadpoolctl when present.

Time on a 2-core machine: the Table 1 part 20 min at a load average of 7 - 9 (105 processes;
OMPL-fine's simplification most of it); each random query up to 4 x --timeout, and most
reach it (10 queries at --timeout 15: 8 min), so the defaults take about 1.5 h. For a
quick look: --queries 4 --timeout 5 --repeats 1 --only robot2_q2_q3 (about 3 min).
"""

import argparse
import atexit
import ctypes
import dataclasses
import gc
import json
import os
import re
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cdh_planner.wrench import wrench_feasibility
from cdh_planner.parsing.problem import load_problem
from random_queries import random_free_queries  # benchmarks/random_queries.py, beside this script
from cdh_planner.model.robot import workspace_box as random_workspace_box
from cdh_planner.search.strategies import STRATEGIES
from cdh_planner.manifold.constraint import TaskConstraint
from cdh_planner.model.pose import quaternion_from_tau, tau_from_quaternion
from cdh_planner.model.robot import load_robot
from cdh_planner.model.task import FreeTask
from cdh_planner.planner import Planner, PlannerSettings, task_cost
from cdh_planner.trajectory.path_check import check_motion, check_task_motion

try:
    from ompl import base as ob, geometric as og, util as ou
except ImportError as e:  # benchmark-only dependency (benchmarks/requirements.txt)
    ob = og = ou = None
    OMPL_MISSING = f"{type(e).__name__}: {e}"

ROOT = Path(__file__).resolve().parents[1]
TABLE1 = ("robot1_qs_qg", "robot1_qs1_qg", "robot1_qs2_qg", "robot2_q1_q2", "robot2_q2_q3",
          "robot2_q2_q3_sigma_free", "robot2_q2_q3_free_flight")
FINE_STEP_SE3 = 1e-3  # OMPL SE(3) distance: m + rad (half rotation angle)
FINE_STEP_TASK = np.deg2rad(0.2)  # rad in task coordinates
COORD_BOUNDS = {"theta": (0.0, np.pi), "alpha2": (-np.pi / 2, np.pi / 2)}  # rad
ATLAS = dict(delta=0.1, rho=0.5, epsilon=0.1, alpha=np.pi / 8)
ATLAS_MARGIN = 5.0  # scaled units around start / goal for unbounded ambient coordinates
COST_SUBSTEPS = 8  # task rows: cost summed over this many steps per segment


@dataclass
class Query:
    group: str
    robot: object
    task: object
    settings: PlannerSettings
    start: object  # Pose
    goal: object


@dataclass
class Run:
    """One planner call: ``status`` "path", "no_path", "timeout", ... or "error";
    ``seconds`` s; ``peak_mb`` MB; ``safe`` (paths only); ``cost`` (task metric)."""

    status: str
    seconds: float
    peak_mb: float
    safe: bool = None
    cost: float = np.nan
    right: bool = False
    error: str = ""


# ----- paths: waypoints as the planner interpolates them -----------------------------------
def is_free(task):
    return task.slerp


def unwrap(task, y):
    """Task coordinates (N, k) with periodic columns unwrapped (short arcs as lines)."""
    y = np.array(y, dtype=float)
    for j, periodic in enumerate(task.periodic):
        if periodic:
            y[:, j] = np.unwrap(y[:, j])
    return y


def motion_from_poses(q, p, tau):
    """Free flight: (positions (N, 3) m, quaternions (N, 4)); task rows: coordinates (N, k)."""
    if is_free(q.task):
        return p, quaternion_from_tau(tau)
    return unwrap(q.task, q.task.coords(p, tau))


def is_safe(q, motion):
    """Dense check of every segment of a motion (trajectory.path_check)."""
    if is_free(q.task):
        segs = check_motion(q.robot, *motion)
    else:
        segs = check_task_motion(q.robot, q.task, motion)
    return all(s.feasible for s in segs)


def path_cost(q, motion):
    """Length in the task's metric (Planner.task_cost): rad or m."""
    if is_free(q.task):
        p, tau = motion[0], tau_from_quaternion(motion[1])
    else:
        y = np.asarray(motion)
        s = np.linspace(0.0, 1.0, COST_SUBSTEPS + 1)[:-1]
        dense = (y[:-1, None, :] + s[None, :, None] * np.diff(y, axis=0)[:, None, :]).reshape(-1, y.shape[1])
        p, tau = q.task.pose(np.vstack([dense, y[-1:]]))
    cost = task_cost(q.robot, q.task, q.settings.cost)
    return float(sum(cost(p[k], tau[k], p[k + 1], tau[k + 1]) for k in range(len(p) - 1)))


# ----- our planner ---------------------------------------------------------------------------
def ours(strategy):
    def plan(q, timeout):
        s = dataclasses.replace(q.settings, strategy=strategy, timeout_s=timeout)
        res = Planner(q.robot, q.task, s).plan(q.start, q.goal)
        if not res.success:
            return str(res.reason), None, res.time_s
        path = res.path
        motion = (path.p, path.quaternion) if is_free(q.task) else motion_from_poses(q, path.p, path.tau)
        return "path", motion, res.time_s
    return plan


# ----- OMPL RRTConnect, point-wise validity ------------------------------------------------
def workspace_box(robot, points):
    """Position bounds (m): the random queries' box under the anchors, widened to contain
    ``points`` (N, 3)."""
    lo, hi = random_workspace_box(robot)
    return np.minimum(lo, points.min(axis=0)), np.maximum(hi, points.max(axis=0))


def quaternion_matrix(x, y, z, w):
    """Rotation matrix (1, 3, 3) of a quaternion (normalised here)."""
    n = np.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array([[[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                      [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                      [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]])


class SE3Adapter:
    """Free flight in OMPL's SE3StateSpace."""

    fine_step = FINE_STEP_SE3

    def __init__(self, q):
        self.q = q
        self.space = ob.SE3StateSpace()
        lo, hi = workspace_box(q.robot, np.array([q.start.p, q.goal.p]))
        bounds = ob.RealVectorBounds(3)
        for i in range(3):
            bounds.setLow(i, lo[i])
            bounds.setHigh(i, hi[i])
        self.space.setBounds(bounds)

    def valid(self, s):
        r = s.rotation()
        R = quaternion_matrix(r.x, r.y, r.z, r.w)
        return bool(wrench_feasibility(self.q.robot, [[s.getX(), s.getY(), s.getZ()]], R=R).margin[0] > 0)

    def state(self, pose):
        s = self.space.allocState()
        s.setXYZ(*map(float, pose.p))
        r, (x, y, z, w) = s.rotation(), quaternion_from_tau(pose.tau)
        r.x, r.y, r.z, r.w = float(x), float(y), float(z), float(w)
        return s

    def motion(self, states):
        p = np.array([[s.getX(), s.getY(), s.getZ()] for s in states])
        quat = np.array([[s.rotation().x, s.rotation().y, s.rotation().z, s.rotation().w] for s in states])
        return p, quat / np.linalg.norm(quat, axis=1, keepdims=True)


class TaskAdapter:
    """Task rows in the task's coordinates: SO(2) for periodic ones, else bounded R."""

    fine_step = FINE_STEP_TASK

    def __init__(self, q):
        self.q = q
        self.periodic = list(q.task.periodic)
        self.space = ob.CompoundStateSpace()
        ends = np.array([q.start.p, q.goal.p])
        box = dict(zip("xyz", zip(*workspace_box(q.robot, ends))))
        for name, per in zip(q.task.names, self.periodic):
            if per:
                self.space.addSubspace(ob.SO2StateSpace(), 1.0)
                continue
            sub, bounds = ob.RealVectorStateSpace(1), ob.RealVectorBounds(1)
            lo, hi = COORD_BOUNDS.get(name) or box[name]
            bounds.setLow(float(lo))
            bounds.setHigh(float(hi))
            sub.setBounds(bounds)
            self.space.addSubspace(sub, 1.0)

    def coords(self, s):
        return np.array([s[j].value if per else s[j][0] for j, per in enumerate(self.periodic)])

    def valid(self, s):
        p, tau = self.q.task.pose(self.coords(s)[None])
        return bool(wrench_feasibility(self.q.robot, p, tau).margin[0] > 0)

    def state(self, pose):
        y = self.q.task.coords(pose.p[None], pose.tau[None])[0]
        s = self.space.allocState()
        for j, per in enumerate(self.periodic):
            if per:
                s[j].value = float(y[j])
            else:
                s[j][0] = float(y[j])
        return s

    def motion(self, states):
        return unwrap(self.q.task, [self.coords(s) for s in states])


def resolution_note(q):
    """OMPL's motion-check step lengths on this query's space (one line)."""
    ad = SE3Adapter(q) if is_free(q.task) else TaskAdapter(q)
    extent = ad.space.getMaximumExtent()
    return (f"  OMPL {type(ad).__name__[:-7]} space, maximum extent {extent:.3f}: default step 0.01 x "
            f"extent = {0.01 * extent:.4f}, fine step {ad.fine_step:.5f} (resolution "
            f"{ad.fine_step / extent:.2e})")


def rrt_connect(fine):
    def plan(q, timeout):
        t0 = time.perf_counter()
        ad = SE3Adapter(q) if is_free(q.task) else TaskAdapter(q)
        ss = og.SimpleSetup(ad.space)
        ss.setStateValidityChecker(ad.valid)
        si = ss.getSpaceInformation()
        if fine:
            si.setStateValidityCheckingResolution(ad.fine_step / ad.space.getMaximumExtent())
        ss.setStartAndGoalStates(ad.state(q.start), ad.state(q.goal))
        ss.setPlanner(og.RRTConnect(si))
        status = ss.solve(timeout)
        if status.getStatus() != ob.PlannerStatus.EXACT_SOLUTION:
            return "timeout", None, time.perf_counter() - t0
        ss.simplifySolution()
        path = ss.getSolutionPath()
        states = [path.getState(k) for k in range(path.getStateCount())]
        return "path", ad.motion(states), time.perf_counter() - t0
    return plan


# ----- OMPL's atlas on our manifold ---------------------------------------------------------
if ob is not None:
    class NavConstraint(ob.Constraint):
        """Our scaled F(x) = 0 (TaskConstraint) as an OMPL constraint; F and F_x computed
        together and cached for the last x (OMPL asks for both at the same point)."""

        def __init__(self, c):
            super().__init__(c.n_vars, c.n_vars - c.dim)
            self.c, self.x = c, None

        def _at(self, x):
            x = np.asarray(x)
            if self.x is None or not np.array_equal(x, self.x):
                self.x = x.copy()
                with np.errstate(over="ignore", invalid="ignore"):  # Newton's far trial points
                    self.F, self.J = self.c.residual_and_jacobian(self.x)
            return self.F, self.J

        def function(self, x, out):
            out[:] = self._at(x)[0]

        def jacobian(self, x, out):
            out[:, :] = self._at(x)[1]


def ambient_bounds(c, xs, xg):
    """Finite box of the scaled variables: the domain, periodic ones [-pi, pi], unbounded
    ones start / goal +- ATLAS_MARGIN."""
    lo, hi = c.lower.copy(), c.upper.copy()
    lo[c.periodic], hi[c.periodic] = -np.pi, np.pi
    lo = np.where(np.isfinite(lo), lo, np.minimum(xs, xg) - ATLAS_MARGIN)
    hi = np.where(np.isfinite(hi), hi, np.maximum(xs, xg) + ATLAS_MARGIN)
    return lo, hi


def atlas_rrt_connect(q, timeout):
    c = TaskConstraint(q.robot, q.task, margin_floor=q.settings.margin_floor)
    xs, xg = c.lift(q.start.p, q.start.tau), c.lift(q.goal.p, q.goal.tau)
    lo, hi = ambient_bounds(c, xs, xg)
    ambient, bounds = ob.RealVectorStateSpace(c.n_vars), ob.RealVectorBounds(c.n_vars)
    for i in range(c.n_vars):
        bounds.setLow(i, float(lo[i]))
        bounds.setHigh(i, float(hi[i]))
    ambient.setBounds(bounds)
    constraint = NavConstraint(c)
    css = ob.AtlasStateSpace(ambient, constraint)
    csi = ob.ConstrainedSpaceInformation(css)
    css.setup()
    css.setDelta(ATLAS["delta"])
    css.setRho(ATLAS["rho"])
    css.setEpsilon(ATLAS["epsilon"])
    css.setAlpha(ATLAS["alpha"])
    css.setup()
    ss = og.SimpleSetup(csi)
    free = ~c.periodic

    def in_domain(s):
        x = np.array([s[i] for i in range(c.n_vars)])[free]
        return bool(np.all(x >= c.lower[free]) and np.all(x <= c.upper[free]))

    ss.setStateValidityChecker(in_domain)
    ends = []
    for x in (xs, xg):
        s = css.allocState()
        s.copy([float(v) for v in x])
        css.anchorChart(s)
        ends.append(s)
    ss.setStartAndGoalStates(*ends)
    planner = og.RRTConnect(csi)
    planner.setRange(css.getRho_s())
    ss.setPlanner(planner)
    ss.setup()
    t0 = time.perf_counter()
    status = ss.solve(timeout)
    seconds = time.perf_counter() - t0
    if status.getStatus() != ob.PlannerStatus.EXACT_SOLUTION:
        return "timeout", None, seconds
    path = ss.getSolutionPath()
    path.interpolate()  # the discrete geodesics, delta apart
    poses = [c.pose(np.array([path.getState(k)[i] for i in range(c.n_vars)]))
             for k in range(path.getStateCount())]
    p, tau = np.array([a for a, _ in poses]), np.array([b for _, b in poses])
    return "path", motion_from_poses(q, p, tau), seconds


# ----- running and measuring -------------------------------------------------------------------
def rss_mb(key):
    """VmRSS or VmHWM of this process, MB."""
    with open("/proc/self/status") as f:
        return int(re.search(rf"{key}:\s+(\d+)", f.read()).group(1)) / 1024.0


def release_memory():
    """Free what earlier calls left (Python garbage, malloc's free heap) so that the RSS
    at a call's start is live data only."""
    gc.collect()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


def run_one(plan, q, timeout):
    """One call, measured; exceptions caught (status "error")."""
    release_memory()
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # reset the peak RSS to the current RSS
    base = rss_mb("VmRSS")
    t0 = time.perf_counter()
    try:
        status, motion, seconds = plan(q, timeout)
    except Exception as e:  # noqa: BLE001 - a benchmark counts crashes, it does not stop on them
        return Run("error", time.perf_counter() - t0, rss_mb("VmHWM") - base,
                   error=f"{type(e).__name__}: {str(e)[:200]}")
    run = Run(status, seconds, rss_mb("VmHWM") - base)
    if motion is not None:
        run.safe, run.cost = is_safe(q, motion), path_cost(q, motion)
    return run


def planners(use_atlas):
    out = {f"ours-{s}": ours(s) for s in STRATEGIES}
    if ob is not None:
        out.update({"ompl-def": rrt_connect(False), "ompl-fine": rrt_connect(True)})
        if use_atlas:
            out["ompl-atlas"] = atlas_rrt_connect
    return out


def run_query(q, plans, timeout):
    """Every planner on one query; "right" set once all have answered."""
    runs = {name: run_one(plan, q, timeout) for name, plan in plans.items()}
    any_safe = any(r.safe for r in runs.values())
    for r in runs.values():
        r.right = bool(r.safe) or (r.status == "no_path" and not any_safe)
    return runs


def progress(label, runs):
    def short(r):
        tag = {True: "ok", False: "UNSAFE"}.get(r.safe, r.status)
        return f"{tag} {r.seconds:.2f}s"
    print(f"  {label}: " + " | ".join(f"{n} {short(r)}" for n, r in runs.items()), flush=True)
    for n, r in runs.items():
        if r.error:
            print(f"    {n} raised {r.error}", flush=True)


HEAD = (f"  {'planner':11s} {'answered':>8s} {'right':>6s} {'med s':>7s} {'p90 s':>7s} "
        f"{'peak MB':>8s} {'unsafe':>12s} {'med cost':>9s} {'/fine':>6s} {'exc':>4s}")


def summary(title, table):
    """Print one row group: ``table`` planner name -> [Run, ...]."""
    print(f"== {title}\n{HEAD}", flush=True)
    med = {n: float(np.median([r.seconds for r in rs])) for n, rs in table.items() if rs}
    for name, rs in table.items():
        paths = [r for r in rs if r.safe is not None]
        unsafe = sum(not r.safe for r in paths)
        answered = sum(r.status in ("path", "no_path") for r in rs)
        secs = [r.seconds for r in rs]
        cost = f"{np.median([r.cost for r in paths]):9.4f}" if paths else "-"
        ratio = med[name] / med["ompl-fine"] if med.get("ompl-fine") else np.nan
        share = f"{unsafe}/{len(paths)}" + (f" {100 * unsafe / len(paths):3.0f}%" if paths else "")
        print(f"  {name:11s} {answered:>3d}/{len(rs):<4d} {100 * np.mean([r.right for r in rs]):5.0f}% "
              f"{np.median(secs):7.2f} {np.percentile(secs, 90):7.2f} "
              f"{max(r.peak_mb for r in rs):8.1f} {share:>12s} {cost:>9s} {ratio:6.2f} "
              f"{sum(r.status == 'error' for r in rs):4d}", flush=True)


def table1_queries(names, repeats):
    for name in names:
        pr = load_problem(ROOT / "config" / "problems" / f"{name}.yaml")
        q = Query(name, pr.robot, pr.task, pr.settings, pr.start, pr.goal)
        yield name, [q] * repeats


def random_queries(count, seed):
    """Alternating Robot 1 / Robot 2 free-flight queries (half each)."""
    per_robot = []
    for k, robot_name in enumerate(("robot1", "robot2")):
        robot = load_robot(ROOT / "config" / f"{robot_name}.yaml")
        n = (count + 1 - k) // 2
        per_robot.append([Query(f"free {robot_name}", robot, FreeTask(), PlannerSettings(), f.start, f.goal)
                          for f in random_free_queries(robot, n, seed)])
    return [q for pair in zip(*per_robot) for q in pair] + per_robot[0][len(per_robot[1]):]


def run_child(args):
    """``--child ROW PLANNER``: plan the row twice in this fresh process; print one JSON line
    {"start_s", "runs": [cold, warm]}."""
    ready = time.time() - args.spawned_at
    (name, qs), = table1_queries([args.child[0]], 2)
    plan = planners(use_atlas=True)[args.child[1]]
    runs = [run_one(plan, q, args.timeout) for q in qs]
    for r in runs:
        r.right = bool(r.safe)  # the parent sets "right" for no_path answers
    print(json.dumps({"start_s": ready, "runs": [dataclasses.asdict(r) for r in runs]}), flush=True)
    return 0


def child_runs(row, planner, args, repeat):
    """(start s, cold Run, warm Run) of ``planner`` on ``row`` in a fresh process."""
    argv = [sys.executable, __file__, "--child", row, planner, "--timeout", str(args.timeout),
            "--seed", str(args.seed + repeat), "--blas-threads", str(args.blas_threads),
            "--spawned-at", repr(time.time())]
    try:
        out = subprocess.run(argv, capture_output=True, text=True, timeout=6 * args.timeout + 300)
        data = json.loads(out.stdout.strip().splitlines()[-1])
    except (subprocess.TimeoutExpired, IndexError, json.JSONDecodeError) as exc:
        err = (out.stderr.strip().splitlines() or ["no output"])[-1][:200] \
            if not isinstance(exc, subprocess.TimeoutExpired) else "killed after its time limit"
        failed = Run("error", float("nan"), float("nan"), error=f"child process: {err}")
        return float("nan"), failed, failed
    cold, warm = (Run(**r) for r in data["runs"])
    return data["start_s"], cold, warm


FRESH_HEAD = (f"  {'planner':11s} {'answered':>8s} {'right':>6s} {'start s':>7s} {'cold s':>7s} "
              f"{'warm s':>7s} {'cold/fine':>9s} {'warm/fine':>9s} {'unsafe':>7s} {'med cost':>9s}")


def fresh_summary(title, table):
    """``table`` planner -> [(start s, cold Run, warm Run), ...]: medians, ratios to OMPL-fine."""
    print(f"== {title}\n{FRESH_HEAD}", flush=True)
    med = {n: (float(np.median([c.seconds for _, c, _ in rs])),
               float(np.median([w.seconds for _, _, w in rs])),
               all(r.right for _, c, w in rs for r in (c, w))) for n, rs in table.items()}
    fine = med.get("ompl-fine", (np.nan, np.nan))
    for name, rs in table.items():
        runs = [r for _, c, w in rs for r in (c, w)]
        paths = [r for r in runs if r.safe is not None]
        answered = sum(r.status in ("path", "no_path") for r in runs)
        cost = f"{np.median([r.cost for r in paths]):9.4f}" if paths else "        -"
        print(f"  {name:11s} {answered:>3d}/{len(runs):<4d} {100 * np.mean([r.right for r in runs]):5.0f}% "
              f"{np.median([s for s, _, _ in rs]):7.2f} {med[name][0]:7.2f} {med[name][1]:7.2f} "
              f"{med[name][0] / fine[0]:9.2f} {med[name][1] / fine[1]:9.2f} "
              f"{sum(not r.safe for r in paths):>3d}/{len(paths):<3d} {cost}", flush=True)
        for r in runs:
            if r.error:
                print(f"    {name} raised {r.error}", flush=True)
    return med


def run_table1(args):
    """Each Table 1 row: every planner in --repeats fresh processes, cold and warm."""
    exc, ratios = {}, []
    names = list(planners(use_atlas=True))
    for row in args.only or TABLE1:
        if ob is not None:
            print(resolution_note(next(table1_queries([row], 1))[1][0]), flush=True)
        table = {n: [] for n in names}
        for k in range(args.repeats):
            for n in names:
                table[n].append(child_runs(row, n, args, k))
            print(f"  {row} process {k + 1}/{args.repeats}: " + " | ".join(
                f"{n} {c.status} {c.seconds:.2f}/{w.seconds:.2f}s" for n, rs in table.items()
                for _, c, w in rs[-1:]), flush=True)
        all_runs = [r for rs in table.values() for _, c, w in rs for r in (c, w)]
        any_safe = any(r.safe for r in all_runs)
        for r in all_runs:
            r.right = bool(r.safe) or (r.status == "no_path" and not any_safe)
        med = fresh_summary(f"{row} ({args.repeats} processes x 2 calls, timeout {args.timeout:g} s)", table)
        ratios.append((row, med))
        for n, rs in table.items():
            exc[n] = exc.get(n, 0) + sum(r.status == "error" for _, c, w in rs for r in (c, w))
    targets_table(ratios)
    return exc


def targets_table(ratios):
    """The targets, ours against OMPL-fine: warm <= 1.0x, cold <= 2.0x."""
    print("== ours against OMPL RRTConnect fine (targets: warm <= 1.0x, cold <= 2.0x)\n"
          "| row | planner | cold s | OMPL-fine cold s | cold ratio | warm s | OMPL-fine warm s | warm ratio | |\n"
          "|---|---|---|---|---|---|---|---|---|", flush=True)
    for row, med in ratios:
        fine = med.get("ompl-fine")
        if fine is None:
            continue
        for n in (n for n in med if n.startswith("ours")):
            (c, w, right), rc, rw = med[n], med[n][0] / fine[0], med[n][1] / fine[1]
            ok = ("meets" if rc <= 2.0 and rw <= 1.0 else "misses") if right else "not all right"
            print(f"| {row} | {n} | {c:.2f} | {fine[0]:.2f} | {rc:.2f} | {w:.2f} | {fine[1]:.2f} | "
                  f"{rw:.2f} | {ok} |", flush=True)


def run_random(args):
    t = time.perf_counter()
    qs = random_queries(args.queries, args.seed)
    print(f"{len(qs)} random free-flight queries (seed {args.seed}) drawn in "
          f"{time.perf_counter() - t:.1f} s", flush=True)
    plans = planners(use_atlas=False)
    if ob is not None:
        for q in qs[:2]:
            print(f"{q.group}: {resolution_note(q).strip()}", flush=True)
    groups = {g: {n: [] for n in plans} for g in sorted({q.group for q in qs}) + ["free, both robots"]}
    for k, q in enumerate(qs):
        runs = run_query(q, plans, args.timeout)
        progress(f"[{k + 1}/{len(qs)}] {q.group}", runs)
        for g in (q.group, "free, both robots"):
            for n, r in runs.items():
                groups[g][n].append(r)
    for g, table in groups.items():
        summary(f"random {g} ({len(next(iter(table.values())))} queries, timeout {args.timeout:g} s)", table)
    return {n: sum(r.status == "error" for r in rs) for n, rs in groups.get("free, both robots", {}).items()}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--queries", type=int, default=50, help="random free-flight queries (half per robot)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the random queries and of OMPL")
    ap.add_argument("--only", nargs="+", choices=TABLE1, metavar="ROW", help="Table 1 rows (default: all)")
    ap.add_argument("--skip-table1", action="store_true")
    ap.add_argument("--skip-random", action="store_true")
    ap.add_argument("--timeout", type=float, default=10.0, help="time limit per planner call (s)")
    ap.add_argument("--repeats", type=int, default=3,
                    help="fresh processes per Table 1 row and planner (each plans twice)")
    ap.add_argument("--blas-threads", type=int, default=1, help="BLAS threads (0: leave as is)")
    ap.add_argument("--child", nargs=2, metavar=("ROW", "PLANNER"), help=argparse.SUPPRESS)
    ap.add_argument("--spawned-at", type=float, default=0.0, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        setup_libraries(args, quiet=True)
        return run_child(args)
    setup_libraries(args)
    exc = {}
    if not args.skip_table1:
        exc = run_table1(args)
    if not args.skip_random:
        for n, k in run_random(args).items():
            exc[n] = exc.get(n, 0) + k
    ours_exc = sum(k for n, k in exc.items() if n.startswith("ours"))
    print("exceptions: " + ", ".join(f"{n} {k}" for n, k in exc.items())
          + ("" if ours_exc == 0 else "  <- ours must be 0"), flush=True)
    return 0


def setup_libraries(args, quiet=False):
    if ob is None and not quiet:
        print(f"OMPL is absent ({OMPL_MISSING}): our planner only. Install it with "
              f"`.venv/bin/python -m pip install -r benchmarks/requirements.txt`.", flush=True)
    elif ob is not None:
        ou.setLogLevel(ou.LogLevel.LOG_ERROR)
        ou.RNG.setSeed(args.seed + 1)  # OMPL wants a seed > 0
        # nanobind lists OMPL's objects "leaked" at interpreter exit (hundreds of lines on
        # stderr); the benchmark is done by then.
        atexit.register(lambda: os.dup2(os.open(os.devnull, os.O_WRONLY), 2))
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        if not quiet:
            print("threadpoolctl absent: BLAS threads left as they are", flush=True)
        return
    if args.blas_threads > 0:
        threadpool_limits(args.blas_threads)


if __name__ == "__main__":
    sys.exit(main())
