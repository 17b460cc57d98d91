"""Workspace analysis: where the robot holds its load, and which of those poses it reaches.

    spec = WorkspaceSpec.for_robot(robot, samples=10_000, seed=1, tilt=np.pi / 6, reach=True)
    result = run_workspace(robot, spec, SerialExecutor())      # or executors.RayExecutor(2)

Sample ``i`` of seed ``s`` is a function of ``(s, i)`` alone: its eight uniform numbers are
the two Philox blocks at counter ``2 i`` under key ``s``, so any split of the samples over
any number of workers gives the same poses (and the same answers, timeouts apart).
Position: uniform in the box; orientation: the home orientation turned by a rotation vector
uniform in the ball of radius ``tilt`` (axis uniform on the sphere, angle ``tilt u^(1/3)``).

Feasibility and margin are the planner's validity at margin floor 0
(``pipeline.validity.Validity.pose_margins``, ``pose_margins`` here): wrench feasibility of
any number of cables (``wrench.wrench_feasibility``) and, with a scene, the least of
it and the collision margin (``scene.margin.combine``), as ``verify --scene`` reports them.
With ``reach``, each feasible sample gets a plan from the home pose (free flight, a fresh
planner per query so that the answer does not depend on what the worker planned before; the
scene's obstacles kept clear): ``reachable`` True (a path), False (no path at the planner's
resolution, or the goal refused), None (a bound: timeout, chart or memory limit). A goal is
refused (``reach_refused``, counted apart from "no path") when the planner does not accept
the sample as a goal though it is feasible: with m > 6 cables the published tension rule's
band t0 +- v leaves the limits where the facet test holds (the planner's validity is the
band's, docs/more-cables.md), or its margin is under the planner's floor. Infeasible
samples are not reachable (False, not planned). Nothing here assumes six
cables.

This module imports no Ray: executors run its calls (``run_call``) where they like.
"""

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..wrench import wrench_feasibility
from ..errors import InputError
from ..model.pose import (Pose, quaternion_from_tau, rotation_from_quaternion, tau_from_quaternion,
                          tau_from_rotation)
from ..model.robot import workspace_box
from ..ports import Rotation
from ..model.task import COORDINATES, FreeTask
from ..pipeline.validity import Validity
from ..planner import Planner, PlannerSettings
from ..status import Status

MAX_SAMPLES = 1_000_000     # per run: the JSON holds every pose (~200 bytes each: <= 200 MB)
MAX_TIMEOUT_S = 3600.0      # per plan
POINT_CHUNK = 5_000         # samples per point call (~20 ms of closed form; fixed: not a knob)
CALLS_PER_WORKER = 16       # reach calls per worker at least: the last one's tail is <= 1/16
MAX_PLANS_PER_CALL = 32     # plans per reach call at most: 32x fewer calls for the driver
HOME_DRAWS = 100_000        # random poses the default home is the best of
BLOCKS_PER_SAMPLE = 2       # Philox blocks (4 uint64 each) per sample: 8 uniforms, 6 used


@dataclass(frozen=True)
class WorkspaceSpec:
    """What to sample and ask. Lengths m, angles rad, times s; quaternions [x, y, z, w]."""

    samples: int
    seed: int
    box_low: tuple
    box_high: tuple
    home_position: tuple
    home_quaternion: tuple
    tilt: float = math.pi / 6
    reach: bool = False
    timeout_s: float = 10.0
    settings: PlannerSettings = field(default_factory=PlannerSettings)
    tilt_about: tuple = None  # the orientation the tilt is measured from (None: the home's)
    task: object = None       # a Task: sample its coordinates (not the box and tilt), plan on it

    def check(self, prefix=""):
        """This spec, or InputError naming the field out of range (``prefix`` + its name:
        "--" for the command's options, "workspace." for a sweep file)."""
        if isinstance(self.samples, bool) or not isinstance(self.samples, int) \
                or not 1 <= self.samples <= MAX_SAMPLES:
            raise InputError(f"{prefix}samples", self.samples, f"must be an integer from 1 to {MAX_SAMPLES}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or not 0 <= self.seed < 2 ** 63:
            raise InputError(f"{prefix}seed", self.seed, "must be an integer in [0, 2^63)")
        if not np.all(np.asarray(self.box_low) < np.asarray(self.box_high)):
            raise InputError(f"{prefix}box", [list(self.box_low), list(self.box_high)],
                             "each low corner coordinate must be below the high one")
        if not 0 <= self.tilt <= math.pi:
            raise InputError(f"{prefix}tilt", self.tilt, "must be between 0 and pi rad (180 deg)")
        if not 0 < self.timeout_s <= MAX_TIMEOUT_S:
            raise InputError(f"{prefix}timeout", self.timeout_s, f"must be in (0, {MAX_TIMEOUT_S:g}] s")
        if self.task is not None:
            task_ranges(self)
        return self


def default_box(robot):
    """The box under the base anchors that the cables reach (``model.robot.workspace_box``)."""
    lo, hi = workspace_box(robot)
    return tuple(map(float, lo)), tuple(map(float, hi))


def default_home(robot, draws=HOME_DRAWS, seed=0, scene=None):
    """The documented default home: the pose of largest margin (``pose_margins``: with a
    scene, clear of it) among ``draws`` random poses in ``default_box`` (positions uniform,
    orientations uniform in SO(3), numpy seed 0), as (position (3,) m, quaternion (4,)
    [x, y, z, w]); InputError naming the robot file if it holds its load at none of them."""
    rng = np.random.default_rng(seed)
    lo, hi = workspace_box(robot)
    p = rng.uniform(lo, hi, size=(draws, 3))
    q = Rotation.random(draws, rng).as_quat()
    return _best_pose(robot, p, q, scene, "in its box")


def _best_pose(robot, p, q, scene, where):
    """(position, quaternion) of the largest-margin pose of p (N, 3), q (N, 4); InputError
    naming the robot file when none holds the load: the robot holds it nowhere, a property
    of the robot, not of an option."""
    margin, binding = pose_margins(point_validity(robot, scene), p, q)
    k = int(np.argmax(margin))
    if not margin[k] > 0:
        what = "wrench-feasible" + (" and clear of the scene" if scene is not None else "")
        raise InputError("robot", robot.source or robot.name,
                         f"holds its load nowhere: none of {len(p)} poses drawn {where} is "
                         f"{what} (best margin {margin[k]:+.3g}, {binding[k]})")
    return tuple(map(float, p[k])), tuple(map(float, q[k]))


def task_ranges(spec):
    """(low, high) per coordinate of ``spec.task``: x, y, z over the box, the angles over
    their natural bounds (``model.task.COORDINATES``); InputError for one without bounds."""
    names = spec.task.names
    if len(names) > 4 * BLOCKS_PER_SAMPLE:
        raise InputError("--task-file", spec.task.describe(), f"more than {4 * BLOCKS_PER_SAMPLE} coordinates")
    out = []
    for name in names:
        if name in ("x", "y", "z"):
            k = "xyz".index(name)
            out.append((spec.box_low[k], spec.box_high[k]))
        elif COORDINATES[name].bounds is not None:
            out.append(tuple(COORDINATES[name].bounds))
        else:
            raise InputError("--task-file", name, "a task coordinate without natural bounds: "
                                                  "it cannot be sampled")
    return np.array(out, dtype=float)


def sample_poses(spec, start, count):
    """Samples ``start .. start + count - 1``: positions (count, 3) m, quaternions (count, 4).
    With a task, its coordinates uniform in ``task_ranges``, mapped to poses."""
    bitgen = np.random.Philox(key=spec.seed, counter=BLOCKS_PER_SAMPLE * start)
    u = np.random.Generator(bitgen).random((count, 4 * BLOCKS_PER_SAMPLE))
    if spec.task is not None:
        r = task_ranges(spec)
        p, tau = spec.task.pose(r[:, 0] + (r[:, 1] - r[:, 0]) * u[:, :len(r)])
        return p, quaternion_from_tau(tau)
    lo, hi = np.asarray(spec.box_low), np.asarray(spec.box_high)
    p = lo + (hi - lo) * u[:, :3]
    z = 2.0 * u[:, 3] - 1.0
    r, az = np.sqrt(np.maximum(0.0, 1.0 - z * z)), 2.0 * np.pi * u[:, 4]
    axis = np.stack([r * np.cos(az), r * np.sin(az), z], axis=1)
    angle = spec.tilt * np.cbrt(u[:, 5])  # uniform in the ball of rotation vectors
    about = spec.home_quaternion if spec.tilt_about is None else spec.tilt_about
    R = Rotation.from_quat(about) * Rotation.from_rotvec(axis * angle[:, None])
    q = R.as_quat()
    q *= np.where(q[:, 3:] < 0, -1.0, 1.0)  # one sign: w >= 0
    return p, q


def point_validity(robot, scene=None):
    """The validity the point test asks (``pose_margins``): the planner's, at margin floor 0
    (a pose's validity does not depend on the task), with ``verify``'s wrench margin (for
    m > 6 cables the facet test; the planner keeps to the tension rule's band, a subset:
    docs/more-cables.md). Building it with a scene loads the collision library and compiles
    its kernel: once per worker."""
    return Validity(robot, FreeTask(), 0.0, scene, feasibility=wrench_feasibility)


def pose_margins(validity, p, q):
    """The one feasibility call: (margin (N,), binding (N,) str) of poses p (N, 3) m,
    quaternions q (N, 4) under ``validity`` (``point_validity``): the wrench margin of any
    number of cables, with a scene the least of it and the collision margin, exactly as
    ``verify`` (``--scene``) gives them. Feasible iff margin > 0."""
    return validity.pose_margins(p, R=rotation_from_quaternion(q))


def check_planner(robot, spec, scene=None):
    """Make the planner once for ``robot`` with ``spec``'s task and settings and ``scene``,
    before any worker plans: its InputError (a cost the task has not, ...) is the command's."""
    Planner(robot, spec.task or FreeTask(), replace(spec.settings, timeout_s=spec.timeout_s),
            scene=scene)


def point_call(context, start, count):
    """Feasibility of samples ``start ..``: a dict of plain arrays (picklable, small)."""
    p, q = sample_poses(context.job.spec, start, count)
    margin, binding = pose_margins(context.validity, p, q)
    return {"start": start, "position": p, "quaternion": q, "margin": margin,
            "binding": np.asarray(binding).astype(str)}


def reach_call(context, indices):
    """Plan from the home pose to each sample of ``indices``: [(index, status str, seconds)]."""
    return [_reach_one(context, int(i)) for i in indices]


def _reach_one(context, index):
    job, spec = context.job, context.job.spec
    p, q = sample_poses(spec, index, 1)
    home = _pose(spec.home_position, spec.home_quaternion)
    settings = replace(spec.settings, timeout_s=spec.timeout_s)
    planner = Planner(job.model, spec.task or FreeTask(), settings, scene=job.scene)
    result = planner.plan(home, _pose(p[0], q[0]))
    return index, str(result.reason), float(result.time_s)


def reach_calls(targets, workers):
    """The reach calls of sample indices ``targets`` on ``workers``: [("reach", (i, ..)), ..],
    several plans per call when there are many per worker (fewer calls for the driver to
    send and collect), at least CALLS_PER_WORKER calls per worker (a short tail)."""
    per_call = max(1, min(MAX_PLANS_PER_CALL, len(targets) // (max(workers, 1) * CALLS_PER_WORKER)))
    return [("reach", tuple(int(j) for j in targets[k:k + per_call]))
            for k in range(0, len(targets), per_call)]


def _pose(p, q):
    R = rotation_from_quaternion(np.asarray(q, dtype=float)[None])
    return Pose(np.asarray(p, dtype=float), tau_from_rotation(R)[0])


def refused_goal(status):
    """Did the planner refuse the sample as its goal (``Status.GOAL_INFEASIBLE``: for m > 6
    the tension rule's band does not fit, or the margin is under the floor)? False when not
    planned (None)."""
    return status is not None and Status(status) is Status.GOAL_INFEASIBLE


def reachable_of(status):
    """True, False or None (a bound was hit) of a plan's status string."""
    status = Status(status)
    if status is Status.OK:
        return True
    return None if status.is_limit else False


# ----- what a worker runs: one context per job, then calls ---------------------------------
@dataclass(frozen=True)
class Job:
    """What workers need to answer calls: the model (robot), the spec, the scene
    (scene.schema.Scene or None) and the queries (``(task, settings, start, goal, scene)``
    each, planned on the model). Picklable."""

    model: object
    spec: WorkspaceSpec
    queries: tuple = ()
    scene: object = None


@dataclass(frozen=True)
class Context:
    """A worker's state for one job: the job and its point validity (built once)."""

    job: Job
    validity: Validity


def make_context(job):
    """The worker-side state of a job (built once per worker: the collision kernel compiles
    here, the planner's on the first plan)."""
    return Context(job, point_validity(job.model, job.scene))


def query_call(model, query):
    """Plan one query ``(task, settings, start, goal, scene)`` on ``model``: a dict of the
    answer."""
    task, settings, start, goal, scene = query
    result = Planner(model, task, settings, scene=scene).plan(start, goal)
    return {"success": bool(result.success), "reason": str(result.reason),
            "cost": float(result.cost) if result.success else None,
            "time_s": float(result.time_s), "charts": int(result.charts)}


def run_call(context, call):
    """Answer one call ``(kind, args)``: ("points", (start, count)), ("reach", (index, ..))
    or ("query", k) (the job's k-th query)."""
    kind, args = call
    if kind == "points":
        return point_call(context, *args)
    if kind == "reach":
        return reach_call(context, args)
    if kind == "query":
        return query_call(context.job.model, context.job.queries[args])
    raise ValueError(f"unknown call kind {kind!r}")


# ----- the driver ---------------------------------------------------------------------------
@dataclass
class WorkspaceResult:
    """Every sample's answer, in index order, and how the run went."""

    spec: WorkspaceSpec
    position: np.ndarray      # (N, 3) m
    quaternion: np.ndarray    # (N, 4) [x, y, z, w]
    margin: np.ndarray        # (N,) normalised, > 0 feasible; NaN: not evaluated (a bound)
    binding: list             # (N,) str
    reach_status: list        # (N,) str or None (not planned)
    seconds: dict             # {"points", "reach", "total"} s
    workers: int
    stopped: str = None       # None, or the bound that stopped the run early
    job: "Job" = None           # what the workers answered from

    @property
    def evaluated(self):
        return np.isfinite(self.margin) | (self.margin == -np.inf)

    @property
    def feasible(self):
        return self.margin > 0

    @property
    def reachable(self):
        """(N,) True / False / None, or all None without ``reach``."""
        if not self.spec.reach:
            return [None] * len(self.margin)
        return [None if s is None and f else (False if s is None else reachable_of(s))
                for s, f in zip(self.reach_status, self.feasible.tolist())]

    @property
    def reach_refused(self):
        """(N,) bool: planned samples the planner refused as a goal (module docstring)."""
        return [refused_goal(s) for s in self.reach_status]

    def counts(self):
        """Samples, evaluated, feasible; with reach: planned, reachable, refused (goals the
        planner refused: refused_under_floor, feasible but margin under the planner's margin
        floor, and refused_band, the rest: for m > 6 the tension rule's band does not fit),
        unreachable_feasible (planned, not refused, no path), unknown."""
        reach = self.reachable
        out = {"samples": int(self.spec.samples), "evaluated": int(self.evaluated.sum()),
               "feasible": int(self.feasible.sum())}
        if self.spec.reach:
            planned = [s for s in self.reach_status if s is not None]
            refused = self.reach_refused
            floor = self.spec.settings.margin_floor
            under = [x and bool(m < floor) for x, m in zip(refused, self.margin.tolist())]
            out.update(planned=len(planned), reachable=sum(r is True for r in reach),
                       refused=sum(refused), refused_under_floor=sum(under),
                       refused_band=sum(refused) - sum(under),
                       unreachable_feasible=sum(r is False and not x for r, x, f in
                                                zip(reach, refused, self.feasible.tolist()) if f),
                       unknown=sum(r is None for r in reach))
        return out

    def fractions(self):
        c = self.counts()
        n = max(c["evaluated"], 1)
        out = {"feasible": c["feasible"] / n}
        if self.spec.reach:
            out["reachable"] = c["reachable"] / n
            out["reachable_of_feasible"] = c["reachable"] / max(c["feasible"], 1)
        return out


def point_calls(spec):
    """The point calls of a spec, fixed chunks: [("points", (start, count)), ...]."""
    return [("points", (s, min(POINT_CHUNK, spec.samples - s)))
            for s in range(0, spec.samples, POINT_CHUNK)]


def run_workspace(model, spec, executor, progress=None, max_seconds=None, clock=time.monotonic,
                  queries=(), scene=None):
    """Evaluate every sample (and plan the feasible ones with ``spec.reach``) on
    ``executor``; ``progress(stage, done, total)`` after each answer; stop early (an answer
    with ``stopped``) when ``max_seconds`` (s, None: no bound) have passed. ``spec`` is
    checked by the caller (``WorkspaceSpec.check``). ``scene``: obstacles the poses and
    paths keep clear of (scene.schema.Scene or None). ``queries``: of the job (``Job``), for
    the caller to plan on the same workers (``res.job``)."""
    t0 = clock()
    deadline = None if max_seconds is None else t0 + max_seconds
    n = spec.samples
    res = WorkspaceResult(spec, np.full((n, 3), np.nan), np.full((n, 4), np.nan),
                          np.full(n, np.nan), [""] * n, [None] * n, {}, executor.workers)
    job = res.job = Job(model, spec, tuple(queries), scene)
    calls = point_calls(spec)
    done = 0
    for _key, out in executor.map(job, calls, deadline=deadline, clock=clock):
        s, k = out["start"], len(out["margin"])
        res.position[s:s + k], res.quaternion[s:s + k] = out["position"], out["quaternion"]
        res.margin[s:s + k] = out["margin"]
        res.binding[s:s + k] = out["binding"].tolist()
        done += k
        if progress:
            progress("points", done, n)
    t1 = clock()
    res.seconds["points"] = t1 - t0
    if done < n:
        res.stopped = "max_seconds"
    elif spec.reach:
        targets = np.flatnonzero(res.feasible).tolist()
        planned = 0
        for _key, answers in executor.map(job, reach_calls(targets, executor.workers),
                                          deadline=deadline, clock=clock):
            for index, status, _s in answers:
                res.reach_status[index] = status
            planned += len(answers)
            if progress:
                progress("reach", planned, len(targets))
        if sum(s is not None for s in res.reach_status) < len(targets):
            res.stopped = "max_seconds"
    res.seconds["reach"] = clock() - t1
    res.seconds["total"] = clock() - t0
    return res


def result_dict(robot, res):
    """The ``--json`` document: every pose and the summary (plain Python types)."""
    spec = res.spec
    reach = res.reachable
    margin = [m if math.isfinite(m) else None for m in res.margin.tolist()]
    poses = [{"index": i, "position": p, "quaternion": q, "feasible": m is not None and m > 0,
              "margin": m, "binding": b or None, "reachable": r, "reach_status": s,
              "reach_refused": refused_goal(s)}
             for i, (p, q, m, b, r, s) in enumerate(zip(
                 _rows(res.position), _rows(res.quaternion), margin, res.binding, reach,
                 res.reach_status))]
    return {"robot": robot.name, "robot_file": robot.source, "samples": spec.samples,
            "seed": spec.seed, "box": {"low": list(spec.box_low), "high": list(spec.box_high)},
            "tilt_rad": spec.tilt, "tilt_about": None if spec.tilt_about is None else list(spec.tilt_about),
            "home": {"position": list(spec.home_position),
                                            "quaternion": list(spec.home_quaternion)},
            "task": None if spec.task is None else spec.task.describe(),
            "scene": None if res.job is None or res.job.scene is None else res.job.scene.source,
            "cables": len(robot.base_anchors),
            "reach": spec.reach, "timeout_s": spec.timeout_s if spec.reach else None,
            "counts": res.counts(), "fractions": res.fractions(), "seconds": res.seconds,
            "workers": res.workers, "complete": res.stopped is None, "stopped": res.stopped,
            "poses": poses}


def _rows(a):
    return [None if not np.all(np.isfinite(r)) else r for r in a.tolist()]


def default_task_home(model, spec, draws=HOME_DRAWS // 5, scene=None):
    """The default home on ``spec.task``: the largest-margin of ``draws`` task samples of
    seed 0 (position (3,), quaternion (4,))."""
    p, q = sample_poses(replace(spec, seed=0), 0, draws)
    return _best_pose(model, p, q, scene, f"on the task ({spec.task.describe()})")


def check_on_task(task, position, quaternion, tol=1e-6):
    """InputError naming --home unless the pose is on ``task`` (within ``tol`` m or rad)."""
    tau = tau_from_quaternion(np.asarray([quaternion], float))
    off = float(task.residual(np.asarray([position], float), tau)[0])
    if not off <= tol:
        raise InputError("--home", list(position), f"{off:.3g} off the task ({task.describe()})")


def check_home(model, position, quaternion, scene=None):
    """InputError naming --home unless the home pose is feasible (``pose_margins``: wrench
    feasible and, with a scene, clear of it)."""
    margin, binding = pose_margins(point_validity(model, scene), np.asarray([position], float),
                                   np.asarray([quaternion], float))
    if not margin[0] > 0:
        what = "feasible and clear of the scene" if scene is not None else "wrench-feasible"
        raise InputError("--home", list(position) + list(quaternion),
                         f"not {what} (margin {margin[0]:+.4g}, {binding[0]})")


def home_from_tau(position, tau):
    """(position, quaternion) of a home given as x y z (m) and phi theta sigma (rad)."""
    return tuple(map(float, position)), tuple(map(float, quaternion_from_tau(np.asarray([tau]))[0]))
