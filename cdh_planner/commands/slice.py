"""``cdh-planner slice``: draw a 2-D slice of the wrench-feasible C-space to a PNG.

Examples (the README pictures)::

    cdh-planner slice config/robot1.yaml --fixed x=0 y=0 z=0.35 sigma=34deg \\
        --free phi theta --range phi=-pi:pi theta=0:pi \\
        --start -2.3 1.6 --goal 1.7 1.7 --start-label q_s --goal-label q_g --segment \\
        -o docs/robot1_slice.png
    cdh-planner slice config/robot2.yaml --sphere 0,0,0.306,0.13 \\
        --range alpha1=-pi:pi alpha2=0:pi/2 --point q_1=0.55,pi/2 \\
        --start 0.55 0.75 --goal 2.63 0.75 --start-label q_2 --goal-label q_3 --segment \\
        -o docs/robot2_sphere.png

``cdh-planner demo`` draws the same two pictures through ``render_slice``.

The task (which poses the picture covers) comes from ``--task-file`` (a problem file with
``task:`` or a ROS parameters file with ``ros__parameters.task``), ``--sphere``, or
``--fixed`` alone (a slice task fixing those pose coordinates); with none of them, the
robot file's own ``task`` is used. With a task file or ``--sphere``, ``--fixed`` holds the
task's extra free coordinates (e.g. sigma of a free-torsion sphere task).
Angles accept radians (``0.75``, ``pi/2``, ``-3pi/4``) or degrees (``34deg``); positions
metres (``0.35``) or ``350mm``. A value starting with '-' that is not a plain number
(``-pi``) must be attached with '=': ``--start=-pi,1.6``, ``--range phi=-pi:pi`` is fine.
"""

ORDER = 20  # its place in `cdh-planner --help`
SUMMARY = "draw a 2-D slice of the wrench-feasible C-space to a PNG"

import argparse
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

from ..accuracy import accuracy_limits
from ..errors import InputError, check_text
from ..wrench import wrench_feasibility
from .outputs import check_output, writing
from ..pictures.slices import FEASIBLE, INACCURATE, Marker, SegmentOverlay, SliceGrid, SliceView, \
    compute_slice, plot_slice
from ..parsing.poses import parse_angle, parse_length
from ..model.pose import rotation_tt
from ..model.robot import load_robot, read_yaml, ros_parameters
from ..model.task import COORDINATES, POSE_NAMES, SliceTask, SphereTask, describe_value, task_from_dict
from ..trajectory.path_check import DEFAULT_STEP_M, DEFAULT_STEP_RAD, SegmentCheck, \
    TaskLinePath, check_path

EXAMPLES = """examples:
  cdh-planner slice config/robot1.yaml --fixed x=0 y=0 z=0.35 sigma=34deg --free phi theta \\
      --start -2.3 1.6 --goal 1.7 1.7 --start-label q_s --goal-label q_g --segment -o slice.png
  cdh-planner slice config/robot2.yaml --sphere 0,0,0.306,0.13 --range alpha1=-pi:pi alpha2=0:pi/2 \\
      --start 0.55 0.75 --goal 2.63 0.75 --segment -o sphere.png
"""
MAX_RESOLUTION = 4000
MAX_PIXELS = 8000
MAX_LABEL_CHARS = 200


def add_parser(subparsers):
    """Register ``slice`` on the top-level subparsers."""
    p = subparsers.add_parser(
        "slice", help=SUMMARY,
        description="Classify a grid over two free coordinates of a task (green: feasible, "
                    "orange: a cable length out of range, blue: a tension out of range; red: "
                    "det J = 0) and draw it, with optional start/goal and the straight segment. "
                    "Angles in rad (0.75, pi/2, -3pi/4) or deg (34deg); positions in m or mm (350mm).",
        epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("robot", help="robot file (ROS 2 parameters YAML)")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--task-file", metavar="T.yaml", help="YAML with a 'task:' mapping")
    src.add_argument("--sphere", metavar="CX,CY,CZ,R",
                     help="sphere task (paper Eq. 17): centre (m, base frame) and radius (m)")
    p.add_argument("--fixed", nargs="+", action="extend", default=[], metavar="NAME=VALUE",
                   help=f"pose coordinates to fix ({', '.join(POSE_NAMES)}); with a task, "
                        "values of its extra free coordinates")
    p.add_argument("--free", nargs=2, metavar=("A", "B"),
                   help="the two coordinates on the picture axes (default: the task's two free ones)")
    p.add_argument("--range", nargs="+", action="extend", default=[], metavar="NAME=LO:HI",
                   help="axis ranges (default: phi, sigma, alpha1 -pi:pi; theta 0:pi; "
                        "alpha2 -pi/2:pi/2; positions need one)")
    p.add_argument("--start", nargs="+", metavar="V",
                   help="start point on the picture axes: A B, or A,B (write --start=-pi,1.6 "
                        "when a value starts with '-' and is not a plain number)")
    p.add_argument("--goal", nargs="+", metavar="V", help="goal point on the picture axes, like --start")
    p.add_argument("--start-label", default="start", help="label of the start marker")
    p.add_argument("--goal-label", default="goal", help="label of the goal marker")
    p.add_argument("--point", nargs="+", action="extend", default=[], metavar="LABEL=A,B",
                   help="further labelled points (a label like q_1 is drawn with a subscript)")
    p.add_argument("--segment", action="store_true",
                   help="draw the straight start -> goal segment and check it densely")
    p.add_argument("--scene", metavar="FILE",
                   help="scene file (YAML, scene: obstacles; cdh_planner/scene/schema.py): "
                        "poses in collision are drawn dark grey, and the segment is checked "
                        "against it too")
    p.add_argument("--accuracy-position", metavar="M",
                   help="colour wrench-feasible poses apart (purple) whose position error over the "
                        "winches' length errors (robot.length_error) exceeds M (m or mm)")
    p.add_argument("--accuracy-orientation", metavar="A",
                   help="likewise for the orientation error, A (rad or deg)")
    p.add_argument("--resolution", type=int, default=400, metavar="N", help="N x N grid (default 400)")
    p.add_argument("--size", default="1000x800", metavar="WxH", help="picture size in pixels")
    p.add_argument("--title", help="picture title (default: robot and slice)")
    p.add_argument("-o", "--output", required=True, metavar="OUT.png", help="PNG file to write")
    p.set_defaults(func=run)


def run(args):
    """Compute, draw and summarise the slice; 0 when the picture was written."""
    robot = load_robot(args.robot)
    out = _check_output(args.output, [("the robot file ROBOT", args.robot),
                                      ("the --task-file", args.task_file)])
    for option, text in (("--title", args.title), ("--start-label", args.start_label),
                         ("--goal-label", args.goal_label)):
        _check_label(option, text)
    size = _parse_size(args.size)
    resolution = _check_resolution(args.resolution)
    view = build_view(args)
    start = _axis_point("--start", args.start, view) if args.start else None
    goal = _axis_point("--goal", args.goal, view) if args.goal else None
    markers = [_parse_point(text, view) for text in args.point]
    markers += [Marker(args.start_label, *start)] if start else []
    markers += [Marker(args.goal_label, *goal)] if goal else []
    if args.segment and (start is None or goal is None):
        raise InputError("--segment", "start -> goal", "needs both --start and --goal")
    segment = (start, goal) if args.segment else None

    collision = _collision(robot, args.scene)
    accuracy = _accuracy(robot, args)
    with writing("--output", out):
        result = render_slice(robot, view, out, resolution=resolution, size=size,
                              title=args.title or _title(robot, view), markers=markers,
                              segment=segment, collision=collision, accuracy=accuracy)
    if result.segment is not None:
        _print_segment(result.segment, args.start_label, args.goal_label)
    _report(robot, view, result.grid, result.elapsed, markers, out, size)
    return 0


@dataclass(frozen=True)
class SliceResult:
    """What ``render_slice`` computed: the classified ``grid``, the seconds the
    classification took, and the dense check of the straight segment (or None)."""

    grid: SliceGrid
    elapsed: float
    segment: Optional[SegmentCheck]


def render_slice(robot, view, out, resolution=400, size=(1000, 800), title=None,
                 markers=(), segment=None, collision=None, accuracy=None):
    """Classify the view's grid, check the straight segment ``(start, goal)`` (picture
    coordinates) densely when given, and draw the PNG ``out``; ``collision``: a scene's
    CollisionModel (poses in collision coloured apart); ``accuracy``: AccuracyLimits
    (feasible poses beyond them coloured apart). Prints nothing."""
    t0 = time.perf_counter()
    grid = compute_slice(robot, view, resolution, collision, accuracy)
    elapsed = time.perf_counter() - t0
    check, overlay = None, None
    if segment is not None:
        start, goal = segment
        coords = view.coords([start[0], goal[0]], [start[1], goal[1]])
        check = check_path(robot, TaskLinePath(view.task, coords), DEFAULT_STEP_M,
                           DEFAULT_STEP_RAD, collision)[0]
        s = None if check.first_unsafe is None else check.first_unsafe.s
        overlay = SegmentOverlay(start=tuple(start), goal=tuple(goal), first_unsafe_s=s)
    plot_slice(grid, out, size=size, title=title or _title(robot, view), markers=markers,
               segment=overlay)
    return SliceResult(grid=grid, elapsed=elapsed, segment=check)


def _accuracy(robot, args):
    """The AccuracyLimits of --accuracy-position / --accuracy-orientation, or None;
    InputError naming the option for a bad value or a robot without length_error."""
    position = (0.0 if args.accuracy_position is None
                else _positive_limit("--accuracy-position", parse_length(
                    args.accuracy_position, "--accuracy-position")))
    orientation = (0.0 if args.accuracy_orientation is None
                   else _positive_limit("--accuracy-orientation", parse_angle(
                       args.accuracy_orientation, "--accuracy-orientation")))
    return accuracy_limits(robot, position, orientation,
                           names=("--accuracy-position", "--accuracy-orientation"))


def _positive_limit(option, value):
    if not value > 0:
        raise InputError(option, value, "must be positive")
    return value


def _collision(robot, scene_file):
    """The CollisionModel of ``--scene`` (None without it: the collision library loads only
    with a scene)."""
    if not scene_file:
        return None
    from ..scene.collision import CollisionModel
    from ..scene.schema import load_scene
    return CollisionModel(robot, load_scene(scene_file, robot))


def build_view(args):
    """The SliceView of the parsed arguments (task, axes, held values, ranges)."""
    task, fixed_used = _task(args)
    names = task.names
    if args.free:
        axes = tuple(args.free)
        for name in axes:
            if name not in names:
                raise InputError("--free", name, f"not a free coordinate of the task (free: {', '.join(names)})")
        if axes[0] == axes[1]:
            raise InputError("--free", list(axes), "give two different coordinates")
    elif len(names) == 2:
        axes = tuple(names)
    else:
        raise InputError("--free", list(names), "the task has more than two free coordinates: choose two")
    held = {} if fixed_used else _assignments("--fixed", args.fixed)
    for name in held:
        if name not in names:
            raise InputError(f"--fixed {name}", held[name], f"not a free coordinate of the task ({', '.join(names)})")
        if name in axes:
            raise InputError(f"--fixed {name}", held[name], "is on a picture axis (--free)")
    for name in names:
        if name not in axes and name not in held:
            raise InputError("--fixed", name, f"free coordinate neither on an axis (--free) nor fixed: add --fixed {name}=VALUE")
    ranges = _ranges(args.range, axes)
    return SliceView(task=task, axes=axes, ranges=ranges, held=held)


def _task(args):
    """(task, whether --fixed was consumed to build it)."""
    if args.task_file:
        return _load_task_file(args.task_file), False
    if args.sphere:
        return _parse_sphere(args.sphere), False
    if args.fixed:
        fixed = _assignments("--fixed", args.fixed)
        for name in fixed:
            if name not in POSE_NAMES:
                raise InputError(f"--fixed {name}", fixed[name], f"unknown pose coordinate (expected {', '.join(POSE_NAMES)})")
        if len(fixed) >= 6:
            raise InputError("--fixed", args.fixed, "at least two coordinates must stay free")
        return SliceTask(fixed=fixed), True
    task = task_in_yaml(args.robot)
    if task is None or len(task.names) == 6:
        raise InputError("task", args.robot, "no task: give --fixed, --sphere or --task-file")
    return task, False


def _load_task_file(path):
    task = task_in_yaml(path)
    if task is None:
        raise InputError("--task-file", path, "no 'task:' mapping (top level or under ros__parameters)")
    return task


def task_in_yaml(path):
    """The task of a problem file (top-level ``task:``) or of a ROS parameters file."""
    doc = read_yaml(path, "--task-file")
    if isinstance(doc, dict) and "task" in doc:
        return task_from_dict(doc["task"])
    if isinstance(doc, dict) and any(isinstance(v, dict) and "ros__parameters" in v for v in doc.values()):
        params = ros_parameters(doc, str(path))
        return task_from_dict(params["task"], "ros__parameters.task") if "task" in params else None
    return None


def _parse_sphere(text):
    parts = text.split(",")
    if len(parts) != 4:
        raise InputError("--sphere", text, "expected CX,CY,CZ,R (m)")
    values = [parse_length(v, f"--sphere[{i}]") for i, v in enumerate(parts)]
    if values[3] <= 0:
        raise InputError("--sphere radius", values[3], "must be positive (m)")
    return SphereTask(center=tuple(values[:3]), radius=values[3])


def parse_value(name, text, where):
    """A coordinate value: an angle (rad or deg) or a position (m or mm) by name."""
    if name not in COORDINATES:
        raise InputError(where, text, f"unknown coordinate '{name}'")
    if COORDINATES[name].unit == "m":
        return parse_length(text, where)
    return parse_angle(text, where)


def _assignments(option, items):
    """{name: value} from NAME=VALUE strings."""
    out = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name:
            raise InputError(option, item, "expected NAME=VALUE")
        if name in out:
            raise InputError(f"{option} {name}", item, "given twice")
        out[name] = parse_value(name, text, f"{option} {name}")
    return out


def _ranges(items, axes):
    given = {}
    for item in items:
        name, sep, text = item.partition("=")
        lo_text, sep2, hi_text = text.partition(":")
        if not sep or not sep2:
            raise InputError("--range", item, "expected NAME=LO:HI")
        if name not in axes:
            raise InputError(f"--range {name}", item, f"not a picture axis ({', '.join(axes)})")
        lo = parse_value(name, lo_text, f"--range {name}")
        hi = parse_value(name, hi_text, f"--range {name}")
        if not lo < hi:
            raise InputError(f"--range {name}", item, "LO must be below HI")
        given[name] = (lo, hi)
    ranges = []
    for name in axes:
        if name not in given and COORDINATES[name].bounds is None:
            raise InputError("--range", name, f"no default range: give --range {name}=LO:HI")
        ranges.append(given.get(name, COORDINATES[name].bounds))
    return tuple(ranges)


def _axis_point(option, values, view):
    """(a, b) from two values or one 'A,B' string."""
    if len(values) == 1:
        values = values[0].split(",")
    if len(values) != 2:
        raise InputError(option, values, "expected two values: A B (or A,B)")
    return tuple(parse_value(n, v, f"{option} {n}") for n, v in zip(view.axes, values))


def _parse_point(text, view):
    label, sep, rest = text.partition("=")
    if not sep or not label:
        raise InputError("--point", text, "expected LABEL=A,B")
    _check_label("--point", label)
    return Marker(label, *_axis_point(f"--point {label}", [rest], view))


def _check_label(option, text):
    """A title or label is drawn: UTF-8 text of at most MAX_LABEL_CHARS characters."""
    if text is not None and len(text) > MAX_LABEL_CHARS:
        raise InputError(option, text, f"at most {MAX_LABEL_CHARS} characters")
    if text is not None:
        check_text(option, text)


def _parse_size(text):
    w, sep, h = text.lower().partition("x")
    try:
        size = (int(w), int(h))
    except ValueError:
        raise InputError("--size", text, "expected WIDTHxHEIGHT in pixels, e.g. 1000x800") from None
    if not sep or not all(100 <= v <= MAX_PIXELS for v in size):
        raise InputError("--size", text, f"expected WIDTHxHEIGHT, each 100 to {MAX_PIXELS} pixels")
    return size


def _check_resolution(n):
    if not 2 <= n <= MAX_RESOLUTION:
        raise InputError("--resolution", n, f"must be between 2 and {MAX_RESOLUTION}")
    return n


def _check_output(path, inputs):
    if Path(path).suffix.lower() != ".png":
        raise InputError("--output", path, "must be a .png file")
    return check_output("--output", path, inputs=inputs)


def _print_segment(check, start_label, goal_label):
    """One line on the straight segment's dense check."""
    if check.first_unsafe is None:
        print(f"segment {start_label} -> {goal_label}: stays in C "
              f"(worst margin {check.worst.margin:+.4f} at s = {check.worst.s:.3f}, {check.samples} samples)")
    else:
        print(f"segment {start_label} -> {goal_label}: leaves C at s = {check.first_unsafe.s:.4f} "
              f"({check.first_unsafe.binding}); worst margin {check.worst.margin:+.4g} "
              f"at s = {check.worst.s:.3f} ({check.worst.binding})")


def _title(robot, view):
    held = ", ".join(describe_value(n, v) for n, v in view.held.items())
    return f"{robot.name}: {view.task.describe()}" + (f", {held}" if held else "")


def _report(robot, view, grid, elapsed, markers, out, size):
    n = grid.classes.size
    share = (grid.classes == FEASIBLE).sum() / n
    print(f"{robot.name}: {grid.classes.shape[1]} x {grid.classes.shape[0]} grid over "
          f"{view.axes[0]} x {view.axes[1]} classified in {elapsed:.2f} s; {100 * share:.1f} % feasible")
    if grid.accuracy is not None:
        print(f"  {100 * (grid.classes == INACCURATE).sum() / n:.1f} % wrench-feasible but "
              f"outside the accuracy limit (purple)")
    if markers:
        coords = view.coords([m.a for m in markers], [m.b for m in markers])
        p, tau = view.task.pose(coords)
        f = wrench_feasibility(robot, p, R=rotation_tt(tau))
        for m, ok, margin, binding in zip(markers, f.feasible, f.margin, f.binding):
            print(f"  {m.label} ({m.a:.4g}, {m.b:.4g}): {'feasible' if ok else 'NOT feasible'}, "
                  f"margin {margin:+.4f} ({binding})")
    print(f"wrote {out} ({size[0]} x {size[1]} px)")
