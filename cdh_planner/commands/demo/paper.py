"""The paper's story (``STEPS``): 1. its Robot 1 and Robot 2 and their tasks (Robot 1: the
slice p = [0, 0, 0.35] m, sigma = 34 deg; Robot 2: the sphere task of Eq. 17); 2. closed-form
wrench feasibility of its poses; 3. dense verification of the straight motions it discusses,
as a controller moves (linear + slerp) or as lines in task coordinates; 4. the C-space
slices of its Figs. 9 and 13. Verdicts are compared with its Sec. 5 (SI units, N mm moments).
"""

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

from ...errors import InputError
from ...wrench import wrench_feasibility
from ...pictures.slices import FEASIBLE, Marker, SliceView
from ...model.pose import quaternion_from_tau
from ...model.robot import load_robot
from ...model.task import SliceTask
from ...trajectory.path_check import check_motion, check_task_motion
from ..slice import render_slice, task_in_yaml
from .steps import Step, table

ROBOT_FILES = {"robot1": "robot1.yaml", "robot2": "robot2.yaml"}
# Robot 1's slice (paper Sec. 5.1): p = [0, 0, 350] mm, sigma = 17 pi / 90 (34 deg).
ROBOT1_SLICE = SliceTask(fixed={"x": 0.0, "y": 0.0, "z": 0.35, "sigma": 17 * math.pi / 90})


@dataclass(frozen=True)
class PaperPose:
    """A pose of the paper in its robot's task coordinates (rad), expected feasible or not."""

    robot: str
    label: str
    coords: tuple
    feasible: bool = True


@dataclass(frozen=True)
class PaperMotion:
    """A straight motion between two paper poses. ``interpolation``: "slerp" (what a
    controller executes) or "task" (a line in task coordinates). ``safe``: the expected
    verdict (None: no claim); ``leaves_before``: when unsafe, it leaves C before this share."""

    robot: str
    start: str
    goal: str
    interpolation: str
    safe: Optional[bool]
    leaves_before: Optional[float] = None
    note: str = ""


PAPER_POSES = (
    PaperPose("robot1", "q_s", (-2.3, 1.6)),
    PaperPose("robot1", "q_g", (1.7, 1.7)),
    PaperPose("robot2", "q_1", (0.55, math.pi / 2)),
    PaperPose("robot2", "q_2", (0.55, 0.75)),
    PaperPose("robot2", "q_3", (2.63, 0.75)),
)

PAPER_MOTIONS = (
    PaperMotion("robot1", "q_s", "q_g", "slerp", safe=False),
    PaperMotion("robot1", "q_s", "q_g", "task", safe=False,
                note="the query the paper plans on this slice (its Fig. 9, top centre)"),
    PaperMotion("robot2", "q_1", "q_2", "task", safe=True),
    PaperMotion("robot2", "q_2", "q_3", "task", safe=False, leaves_before=0.10,
                note="the paper: it \"rapidly leaves C at the beginning\""),
    PaperMotion("robot2", "q_2", "q_3", "slerp", safe=None,
                note="leaves the sphere task on the way; the paper makes no claim about it"),
)


@dataclass(frozen=True)
class PictureSpec:
    """A C-space picture: ``axes``, their ``ranges`` (rad), labelled ``points`` and the
    straight ``segment`` (start label, goal label)."""

    file: str
    robot: str
    axes: tuple
    ranges: tuple
    points: tuple
    segment: tuple


PICTURES = (
    PictureSpec("robot1_slice.png", "robot1", ("phi", "theta"), ((-math.pi, math.pi), (0.0, math.pi)),
                ("q_s", "q_g"), ("q_s", "q_g")),
    PictureSpec("robot2_sphere.png", "robot2", ("alpha1", "alpha2"), ((-math.pi, math.pi), (0.0, math.pi / 2)),
                ("q_1", "q_2", "q_3"), ("q_2", "q_3")),
)
PICTURE_RESOLUTION = 400  # grid cells per axis
PICTURE_SIZE = (1000, 800)  # pixels


@dataclass(frozen=True)
class PoseVerdict:
    """Closed-form feasibility of a paper pose (tensions in N, margin normalised)."""

    pose: PaperPose
    position: np.ndarray
    tau: np.ndarray
    feasible: bool
    margin: float
    binding: str
    tension_low: float  # min over cables of f0_i - v_ii
    tension_high: float  # max over cables of f0_i + v_ii
    agrees: bool


@dataclass(frozen=True)
class MotionVerdict:
    """Dense verification of a paper motion (``check``: a SegmentCheck)."""

    motion: PaperMotion
    check: object
    agrees: Optional[bool]  # None when nothing is expected

    @property
    def safe(self):
        return self.check.feasible

    @property
    def leaves_at(self):
        return None if self.check.first_unsafe is None else self.check.first_unsafe.s


@dataclass
class Demo:
    """What the steps share: inputs, and what each step found."""

    out_dir: Path
    config_dir: Path
    robots: dict = field(default_factory=dict)  # name -> Robot
    tasks: dict = field(default_factory=dict)  # robot name -> task
    poses: dict = field(default_factory=dict)  # (robot, label) -> PoseVerdict
    motions: list = field(default_factory=list)  # MotionVerdict
    files: list = field(default_factory=list)  # every file written
    differs: list = field(default_factory=list)  # one line per verdict not the expected one
    ros: object = None  # ros_story.NodeStory once the node is started

    def pose(self, robot, label):
        """(position (3,), tau (3,)) of a paper pose in its robot's task."""
        p, tau = self.tasks[robot].pose(np.array([paper_pose(robot, label).coords]))
        return p[0], tau[0]


def load_robots(demo):
    """Load the two robot files and the tasks the paper uses with them."""
    for name, file in ROBOT_FILES.items():
        path = demo.config_dir / file
        demo.robots[name] = robot = load_robot(path)
        print(f"{name}: {path}: {_limits(robot)}")
    demo.tasks["robot1"] = ROBOT1_SLICE
    sphere = task_in_yaml(demo.config_dir / ROBOT_FILES["robot2"])
    if sphere is None or sphere.type != "sphere":
        raise InputError("ros__parameters.task", getattr(sphere, "type", None),
                         f"{ROBOT_FILES['robot2']} must carry the paper's sphere task (type: sphere)")
    demo.tasks["robot2"] = sphere
    print("robot1 task: slice p = [0, 0, 0.35] m, sigma = 34 deg; free (phi, theta)")
    c = ", ".join(f"{v:g}" for v in sphere.center)
    print(f"robot2 task: sphere (paper Eq. 17), centre [{c}] m, radius {sphere.radius:g} m; "
          f"free (alpha1, alpha2)")


def check_poses(demo):
    """Closed-form wrench feasibility of the paper's poses."""
    rows = []
    for spec in PAPER_POSES:
        robot = demo.robots[spec.robot]
        p, tau = demo.pose(spec.robot, spec.label)
        f = wrench_feasibility(robot, p[None], tau[None])
        feasible = bool(f.feasible[0])
        v = PoseVerdict(pose=spec, position=p, tau=tau, feasible=feasible, margin=float(f.margin[0]),
                        binding=str(f.binding[0]), tension_low=float(np.min(f.tension_min[0])),
                        tension_high=float(np.max(f.tension_max[0])), agrees=feasible == spec.feasible)
        demo.poses[(spec.robot, spec.label)] = v
        expected = "feasible" if spec.feasible else "not feasible"
        if not v.agrees:
            demo.differs.append(f"{spec.robot} {spec.label}: "
                                f"{'feasible' if feasible else 'not feasible'}, expected {expected}")
        names = demo.tasks[spec.robot].names
        rows.append([spec.robot, spec.label, ", ".join(f"{n} {x:.4g}" for n, x in zip(names, spec.coords)),
                     "yes" if feasible else "NO", f"{v.margin:+.4f}", v.binding, _envelope(robot, v),
                     _agreement(v.agrees, "feasible" if spec.feasible else "infeasible")])
    table(["robot", "pose", "task coords (rad)", "feasible", "margin", "binding",
           "tensions over K: lowest .. highest (limits)", "expected"], rows)
    print("margin: least distance to a length or tension bound, as a fraction of that bound's "
          "range (> 0 iff feasible)")


def verify_motions(demo):
    """Dense verification of the paper's straight motions."""
    rows, notes = [], []
    for spec in PAPER_MOTIONS:
        robot, task = demo.robots[spec.robot], demo.tasks[spec.robot]
        if spec.interpolation == "slerp":
            (p0, t0), (p1, t1) = demo.pose(spec.robot, spec.start), demo.pose(spec.robot, spec.goal)
            check = check_motion(robot, np.array([p0, p1]), quaternion_from_tau(np.array([t0, t1])))[0]
            how = "linear + slerp"
        elif spec.interpolation == "task":
            coords = [paper_pose(spec.robot, label).coords for label in (spec.start, spec.goal)]
            check = check_task_motion(robot, task, np.array(coords))[0]
            how = f"line in ({', '.join(task.names)})"
        else:
            raise InputError("interpolation", spec.interpolation, "expected 'slerp' or 'task'")
        verdict = MotionVerdict(motion=spec, check=check, agrees=_motion_agrees(spec, check))
        demo.motions.append(verdict)
        name = f"{spec.robot} {spec.start} -> {spec.goal} ({how})"
        if verdict.agrees is False:
            demo.differs.append(f"{name}: {_motion_text(check)}, expected {_paper_motion(spec)}")
        if spec.note:
            notes.append(f"{name}: {spec.note}")
        rows.append([spec.robot, f"{spec.start} -> {spec.goal}", how, str(check.samples), _motion_text(check),
                     "(no claim)" if spec.safe is None else _agreement(verdict.agrees, _paper_motion(spec))])
    table(["robot", "motion", "interpolation", "samples", "verdict", "expected"], rows)
    print("linear + slerp: position linear, orientation slerp (what a controller executes); "
          "s: fraction of the way; samples at most 1 mm and 0.2 deg apart, refined where the "
          "margin could dip below 0")
    for line in notes:
        print(f"note: {line}")


def draw_pictures(demo):
    """The two C-space slices, with the paper's poses and the straight segment."""
    for spec in PICTURES:
        view = SliceView(task=demo.tasks[spec.robot], axes=spec.axes, ranges=spec.ranges)
        coords = {label: paper_pose(spec.robot, label).coords for label in spec.points}
        path = demo.out_dir / spec.file
        result = render_slice(demo.robots[spec.robot], view, path, resolution=PICTURE_RESOLUTION,
                              size=PICTURE_SIZE, markers=[Marker(k, *c) for k, c in coords.items()],
                              segment=tuple(coords[label] for label in spec.segment))
        demo.files.append(path)
        share = float(np.mean(result.grid.classes == FEASIBLE))
        leaves = result.segment.first_unsafe
        seg = "stays in C" if leaves is None else f"leaves C at {100 * leaves.s:.1f} %"
        print(f"{spec.robot}: {PICTURE_RESOLUTION} x {PICTURE_RESOLUTION} grid over "
              f"({', '.join(spec.axes)}) in {result.elapsed:.1f} s, {100 * share:.1f} % feasible; "
              f"segment {spec.segment[0]} -> {spec.segment[1]} {seg}")
        print(f"  wrote {path}")
    print("colours: green wrench-feasible, orange a cable length out of range, blue a tension "
          "out of range; red det J = 0")


STEPS = [
    Step("robots", "The paper's robots", load_robots),
    Step("poses", "The paper's poses: closed-form wrench feasibility", check_poses),
    Step("motions", "Straight motions between them: dense verification", verify_motions),
    Step("pictures", "C-space pictures", draw_pictures),
]


def paper_pose(robot, label):
    """The PaperPose ``label`` of ``robot``."""
    for spec in PAPER_POSES:
        if spec.robot == robot and spec.label == label:
            return spec
    raise InputError("pose", f"{robot} {label}", "not one of the paper's poses")


def _motion_agrees(spec, check):
    if spec.safe is None:
        return None
    if check.feasible != spec.safe:
        return False
    if not check.feasible and spec.leaves_before is not None:
        return check.first_unsafe.s < spec.leaves_before
    return True


def _paper_motion(spec):
    if spec.safe:
        return "safe"
    return "unsafe" if spec.leaves_before is None else f"unsafe within {100 * spec.leaves_before:.0f} %"


def _motion_text(check):
    unresolved = f", {check.unresolved} intervals unresolved" if check.unresolved else ""
    if check.first_unsafe is None:
        return f"safe, worst margin {check.worst.margin:+.4f} at s = {check.worst.s:.3f}{unresolved}"
    return f"UNSAFE, leaves C at s = {check.first_unsafe.s:.3f} ({check.first_unsafe.binding})"


def _agreement(agrees, paper):
    return f"{paper}: {'agrees' if agrees else 'DIFFERS'}"


def _envelope(robot, v):
    lo, hi = _span(robot.tension_min), _span(robot.tension_max)
    if not np.isfinite(v.tension_low) or not np.isfinite(v.tension_high):
        return f"unbounded (singular J) ({lo} .. {hi})"
    return f"{v.tension_low:.3f} .. {v.tension_high:.3f} N ({lo} .. {hi})"


def _span(values):
    """'0.05' when all cables share a limit, else 'min-max'."""
    lo, hi = float(np.min(values)), float(np.max(values))
    return f"{lo:g}" if lo == hi else f"{lo:g}-{hi:g}"


def _limits(robot):
    return (f"lengths {_span(robot.length_min)} .. {_span(robot.length_max)} m, tensions "
            f"{_span(robot.tension_min)} .. {_span(robot.tension_max)} N, load "
            f"{np.linalg.norm(robot.force):.4g} N at "
            f"[{', '.join(f'{v:g}' for v in robot.load_point)}] m (platform frame)")
