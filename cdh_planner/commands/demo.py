"""``cdh-planner demo``: the paper's robots, poses and straight motions, checked, and
C-space pictures; then the ROS story: the node plans Robot 2's sphere task q_1 -> q_2 -> q_3,
streams it, records it, and the recording is replayed.

    cdh-planner demo [--out DIR] [--config-dir DIR]

The demo is a list of steps (``STEPS``) run in order on one shared ``Demo`` record. Each
step is a small function ``step(demo) -> None`` that prints its part and stores what it
found on ``demo``; a step may use what earlier steps stored. Later features add their
part by appending a ``Step`` (planning, the ROS node, replay).

1. ``robots``: load the paper's Robot 1 and Robot 2 (``config/robot1.yaml``,
   ``config/robot2.yaml``) and their tasks (Robot 1: the slice p = [0, 0, 0.35] m,
   sigma = 34 deg; Robot 2: the sphere task of the paper's Eq. 17, from robot2.yaml);
2. ``poses``: closed-form wrench feasibility of the paper's poses q_s, q_g (Robot 1) and
   q_1, q_2, q_3 (Robot 2): verdict, normalised margin, binding constraint and tension
   envelope (lowest f0 - v_ii and highest f0 + v_ii over the six cables);
3. ``motions``: dense verification (``cdh_planner.trajectory.verify``) of the straight
   motions the paper discusses: q_s -> q_g as a controller moves (position linear,
   orientation slerp) and as a straight line in the slice's (phi, theta); q_1 -> q_2 and
   q_2 -> q_3 as straight lines in the sphere task's (alpha1, alpha2);
4. ``pictures``: the two C-space slices (like the paper's Figs. 9 and 13) as PNGs in the
   output directory, drawn by the same code as ``cdh-planner slice``;
5. - 10. the ROS story (``demo_ros``): start ``cdh-planner node`` (Robot 2, sphere task) in
   a ROS domain of its own, recording to ``<out>/runs``; plan q_1 -> q_2 and q_2 -> q_3 over
   ROS, check the planned motion densely and execute it (streamed cable commands); replay
   the recording (commands republished; requests re-sent to a fresh node); SIGINT, read the
   run file back; pictures of the plans and the execution, and a summary table.

Every verdict with an expected value (the paper's results of Sec. 5, checked numerically
in SI units with moments in N mm) is compared with it. Exit code 0 when all agree, 1 when one differs (printed as DIFFERS FROM THE EXPECTED), 2 for bad input.
"""

import argparse
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

from ..errors import InputError
from ..feasibility import evaluate
from ..io.plots import FEASIBLE, Marker, SliceView
from ..model.pose import quaternion_from_tau
from ..model.robot import load_robot
from ..model.task import SliceTask
from ..trajectory.verify import check_motion, check_task_motion
from . import demo_ros
from .demo_steps import Step, table
from .slice import render_slice, task_in_yaml

PACKAGE = "cdh_planner"
DEFAULT_OUT = "demo_out"
ROBOT_FILES = {"robot1": "robot1.yaml", "robot2": "robot2.yaml"}
EXIT_OK, EXIT_DIFFERS = 0, 1

# Robot 1's slice (paper Sec. 5.1): p = [0, 0, 350] mm, sigma = 17 pi / 90 (34 deg).
ROBOT1_SLICE = SliceTask(fixed={"x": 0.0, "y": 0.0, "z": 0.35, "sigma": 17 * math.pi / 90})


@dataclass(frozen=True)
class PaperPose:
    """A pose of the paper, in its robot's task coordinates (rad), and whether it is
    expected to be wrench-feasible (the paper's Sec. 5)."""

    robot: str
    label: str
    coords: tuple
    feasible: bool = True


@dataclass(frozen=True)
class PaperMotion:
    """A straight motion between two paper poses. ``interpolation``: "slerp" (position
    linear, orientation slerp: what a controller executes) or "task" (a straight line in
    the task coordinates). ``safe``: the expected verdict (the paper's Sec. 5; None:
    no claim); ``leaves_before``: when unsafe, expected to leave C before this fraction."""

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
    """One C-space picture: ``axes`` and their ``ranges`` (rad), labelled ``points``
    (paper pose labels) and the straight ``segment`` (start label, goal label) drawn."""

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
    """Closed-form feasibility of one paper pose (tensions in N, margin normalised)."""

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
    """Dense verification of one paper motion (``check``: a SegmentCheck)."""

    motion: PaperMotion
    check: object
    agrees: Optional[bool]  # None when nothing is expected

    @property
    def safe(self):
        return self.check.feasible

    @property
    def leaves_at(self):
        return None if self.check.first_unsafe is None else self.check.first_unsafe.s


@dataclass(frozen=True)
class PictureResult:
    spec: PictureSpec
    path: Path
    feasible_share: float
    grid_seconds: float
    segment: object  # SegmentCheck of the drawn segment


@dataclass
class Demo:
    """What the steps share: inputs, and what each step found."""

    out_dir: Path
    config_dir: Path
    robots: dict = field(default_factory=dict)  # name -> Robot
    tasks: dict = field(default_factory=dict)  # robot name -> task
    poses: dict = field(default_factory=dict)  # (robot, label) -> PoseVerdict
    motions: list = field(default_factory=list)  # MotionVerdict
    pictures: list = field(default_factory=list)  # PictureResult
    files: list = field(default_factory=list)  # every file written
    differs: list = field(default_factory=list)  # one line per verdict that is not the expected one

    def pose(self, robot, label):
        """(position (3,), tau (3,)) of a paper pose in its robot's task."""
        spec = _paper_pose(robot, label)
        p, tau = self.tasks[robot].pose(np.array([spec.coords]))
        return p[0], tau[0]


# --- steps -------------------------------------------------------------------------------

def load_robots(demo):
    """Load the two robot files and the tasks the paper uses with them."""
    for name, file in ROBOT_FILES.items():
        path = demo.config_dir / file
        robot = load_robot(path)
        demo.robots[name] = robot
        print(f"{name}: {path}: {_limits(robot)}")
    demo.tasks["robot1"] = ROBOT1_SLICE
    sphere = task_in_yaml(demo.config_dir / ROBOT_FILES["robot2"])
    if sphere is None or sphere.type != "sphere":
        raise InputError("ros__parameters.task", getattr(sphere, "type", None),
                         f"{ROBOT_FILES['robot2']} must carry the paper's sphere task (type: sphere)")
    demo.tasks["robot2"] = sphere
    print(f"robot1 task: slice p = [0, 0, 0.35] m, sigma = 34 deg; free (phi, theta)")
    c = ", ".join(f"{v:g}" for v in sphere.center)
    print(f"robot2 task: sphere (paper Eq. 17), centre [{c}] m, radius {sphere.radius:g} m; "
          f"free (alpha1, alpha2)")


def check_poses(demo):
    """Closed-form wrench feasibility of the paper's poses."""
    rows = []
    for spec in PAPER_POSES:
        robot = demo.robots[spec.robot]
        p, tau = demo.pose(spec.robot, spec.label)
        f = evaluate(robot, p[None], tau[None])
        feasible = bool(f.feasible[0])
        verdict = PoseVerdict(pose=spec, position=p, tau=tau, feasible=feasible, margin=float(f.margin[0]),
                              binding=str(f.binding[0]), tension_low=float(np.min(f.tension_min[0])),
                              tension_high=float(np.max(f.tension_max[0])), agrees=feasible == spec.feasible)
        demo.poses[(spec.robot, spec.label)] = verdict
        if not verdict.agrees:
            demo.differs.append(f"{spec.robot} {spec.label}: {'feasible' if feasible else 'not feasible'}, "
                                f"expected {'feasible' if spec.feasible else 'not feasible'}")
        names = demo.tasks[spec.robot].names
        rows.append([spec.robot, spec.label,
                     ", ".join(f"{n} {v:.4g}" for n, v in zip(names, spec.coords)),
                     "yes" if feasible else "NO", f"{verdict.margin:+.4f}", verdict.binding,
                     _envelope(robot, verdict), _agreement(verdict.agrees, "feasible" if spec.feasible else "infeasible")])
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
            coords = [_paper_pose(spec.robot, spec.start).coords, _paper_pose(spec.robot, spec.goal).coords]
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
        rows.append([spec.robot, f"{spec.start} -> {spec.goal}", how, str(check.samples),
                     _motion_text(check),
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
        robot, task = demo.robots[spec.robot], demo.tasks[spec.robot]
        view = SliceView(task=task, axes=spec.axes, ranges=spec.ranges)
        coords = {label: _paper_pose(spec.robot, label).coords for label in spec.points}
        markers = [Marker(label, *coords[label]) for label in spec.points]
        path = demo.out_dir / spec.file
        result = render_slice(robot, view, path, resolution=PICTURE_RESOLUTION, size=PICTURE_SIZE,
                              markers=markers, segment=(coords[spec.segment[0]], coords[spec.segment[1]]))
        share = float(np.mean(result.grid.classes == FEASIBLE))
        demo.pictures.append(PictureResult(spec=spec, path=path, feasible_share=share,
                                           grid_seconds=result.elapsed, segment=result.segment))
        demo.files.append(path)
        leaves = result.segment.first_unsafe
        seg = ("stays in C" if leaves is None else f"leaves C at {100 * leaves.s:.1f} %")
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

# The ROS story (node, q_1 -> q_2 -> q_3 over ROS, streaming, recording, replay, shutdown,
# pictures). demo_ros imports rclpy only inside its steps.
STEPS += demo_ros.steps()


# --- command -----------------------------------------------------------------------------

def add_parser(subparsers):
    """Register ``demo`` on the top-level subparsers."""
    p = subparsers.add_parser(
        "demo", help="the whole story: the paper's robots, poses and motions checked, then "
                     "the ROS node planning, streaming, recording and replaying Robot 2's "
                     "sphere task",
        description="Load the paper's Robot 1 and Robot 2, check the paper's poses (closed-form "
                    "wrench feasibility) and the straight motions between them (dense "
                    "verification), compare each verdict with the paper's results, and write the "
                    "C-space pictures. Then start the ROS 2 node (its own ROS domain, discovery "
                    "on localhost), plan Robot 2's sphere task q1 -> q2 -> q3 over ROS, execute "
                    "it (streamed cable commands), record the run to MCAP, replay it, stop the "
                    "node and draw the plans and the execution. Exit 0 when every verdict "
                    "agrees, 1 if one differs.",
        epilog="example:\n  cdh-planner demo --out /tmp/demo", formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR",
                   help=f"directory for the pictures, created if missing (default: {DEFAULT_OUT}/ "
                        "in the current directory)")
    p.add_argument("--config-dir", metavar="DIR",
                   help="directory holding robot1.yaml and robot2.yaml (default: the package's "
                        "config/, found in the source tree or the installed share directory)")
    p.set_defaults(func=run)


def run(args):
    """Run every step; 0 when every verdict is the expected one, else 1."""
    demo = run_demo(args.out, config_dir=args.config_dir)
    return EXIT_OK if not demo.differs else EXIT_DIFFERS


def run_demo(out_dir=DEFAULT_OUT, config_dir=None, steps=None):
    """Run ``steps`` (default ``STEPS``) in order, printing as they go; return the Demo."""
    t0 = time.perf_counter()
    demo = Demo(out_dir=prepare_out_dir(out_dir), config_dir=find_config_dir(config_dir))
    steps = STEPS if steps is None else steps
    for i, step in enumerate(steps, 1):
        print(f"\n== {i}. {step.title}")
        step.run(demo)
    print(f"\n== Done in {time.perf_counter() - t0:.1f} s")
    if demo.files:
        print(f"files in {demo.out_dir.resolve()}/: {', '.join(f.name for f in demo.files)}")
    if demo.differs:
        print("DIFFERS FROM THE EXPECTED (the paper's Sec. 5 results):")
        for line in demo.differs:
            print(f"  {line}")
    else:
        print("every verdict is the expected one (the paper's Sec. 5 results)")
    return demo


def prepare_out_dir(path):
    """The output directory, created if missing."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise InputError("--out", str(path), "exists and is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError("--out", str(path), f"cannot create the directory: {exc.strerror}") from None
    return out


def config_dir_candidates():
    """Where robot1.yaml / robot2.yaml may be, in order: the source tree (checkout or
    editable install), the ament index (colcon install), ``<sys.prefix>/share/cdh_planner/config``
    (pip install into a venv), and the share directory of the prefix the package sits in."""
    pkg = Path(__file__).resolve().parents[1]  # .../cdh_planner
    candidates = [pkg.parent / "config"]
    try:
        from ament_index_python.packages import get_package_share_directory
        candidates.append(Path(get_package_share_directory(PACKAGE)) / "config")
    except Exception:  # not installed, AMENT_PREFIX_PATH unset, or package not indexed
        pass
    candidates.append(Path(sys.prefix) / "share" / PACKAGE / "config")
    if len(pkg.parents) > 3:  # <prefix>/lib/pythonX.Y/site-packages/cdh_planner
        candidates.append(pkg.parents[3] / "share" / PACKAGE / "config")
    return list(dict.fromkeys(candidates))  # without repeats, in order


def find_config_dir(explicit=None):
    """The directory holding the paper's robot files (``explicit`` if given)."""
    if explicit is not None:
        path = Path(explicit)
        missing = [f for f in ROBOT_FILES.values() if not (path / f).is_file()]
        if missing:
            raise InputError("--config-dir", str(explicit), f"no {', '.join(missing)} there")
        return path
    candidates = config_dir_candidates()
    for path in candidates:
        if all((path / f).is_file() for f in ROBOT_FILES.values()):
            return path
    raise InputError("config", [str(p) for p in candidates],
                     "robot1.yaml and robot2.yaml not found in any of these; give --config-dir")


# --- helpers -----------------------------------------------------------------------------

def _paper_pose(robot, label):
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
    if spec.leaves_before is not None:
        return f"unsafe within {100 * spec.leaves_before:.0f} %"
    return "unsafe"


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
    """'0.05' when all cables share a limit, else 'min..max'."""
    lo, hi = float(np.min(values)), float(np.max(values))
    return f"{lo:g}" if lo == hi else f"{lo:g}-{hi:g}"


def _limits(robot):
    force = np.linalg.norm(robot.force)
    return (f"lengths {_span(robot.length_min)} .. {_span(robot.length_max)} m, tensions "
            f"{_span(robot.tension_min)} .. {_span(robot.tension_max)} N, load {force:.4g} N at "
            f"[{', '.join(f'{v:g}' for v in robot.load_point)}] m (platform frame)")
