"""``cdh-planner workspace``: where the robot holds its load, and what it reaches from home.

    cdh-planner workspace ROBOT.yaml [--samples N] [--seed S] [--box X0,Y0,Z0,X1,Y1,Z1]
                          [--tilt A | --task-file T.yaml] [--scene SCENE.yaml]
                          [--reach [--home X Y Z PHI THETA SIGMA] [--timeout S]]
                          [--workers N | --no-ray] [--ray-address HOST:PORT]
                          [--max-seconds S] [--json OUT] [--plot OUT.png] [--quiet]

Samples poses (``studies.workspace``: sample i of seed S is a function of (S, i) alone, so
the answers do not depend on the workers), gives each its feasibility and margin as
``verify`` does (wrench feasibility of any number of cables; with ``--scene``, also clear of
the obstacles and of the other cables) and, with ``--reach``, plans from the home pose to
each feasible one, around the scene's obstacles (``reachable``: true,
false = no path at the planner's resolution, null = the plan's --timeout or another bound).
Runs on a local Ray of ``--workers`` actors (default: the cores), on a cluster with
``--ray-address``, or in this process with ``--no-ray``. Exit 0 with the answer (also when
--max-seconds stopped it: the JSON says ``"complete": false``), 2 for bad input.
"""

ORDER = 40  # its place in `cdh-planner --help`
SUMMARY = "sample poses: wrench feasibility, margin and reachability from home"

import math
from dataclasses import replace

import numpy as np

from ..errors import InputError
from .outputs import check_output, write_text, writing
from ..parsing.poses import parse_angle, parse_length
from ..model.robot import load_robot
from ..planner import PlannerSettings
from ..scene.schema import load_scene
from ..studies import workspace as ws
from ..studies.executors import make_executor
from ..studies.progress import count_progress
from .verify import dump_rows

MAX_SECONDS = 7 * 24 * 3600.0  # one run at most a week


def add_parser(subparsers):
    """Register ``workspace`` on the top-level subparsers."""
    p = subparsers.add_parser(
        "workspace", help=SUMMARY,
        description="Sample poses in a box and within a tilt of the home orientation; give "
                    "each its feasibility and margin and, with --reach, whether a path from "
                    "the home pose reaches it. Runs on Ray (local or a cluster) or in this "
                    "process (--no-ray). Exit 0 with the answer, 2 for bad input.")
    p.add_argument("robot", help="robot file (ROS 2 parameters YAML)")
    p.add_argument("--samples", type=int, default=10_000, metavar="N",
                   help=f"poses to sample, 1 to {ws.MAX_SAMPLES} (default 10000)")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="random seed (default 0)")
    p.add_argument("--box", metavar="X0,Y0,Z0,X1,Y1,Z1",
                   help="position box corners, m or with unit (default: the box under the "
                        "base anchors the cables reach)")
    p.add_argument("--task-file", metavar="T.yaml",
                   help="sample a task's coordinates instead (a problem file with 'task:' or a "
                        "ROS parameters file; x, y, z over --box, angles over their bounds); "
                        "--reach then plans on the task")
    p.add_argument("--tilt", metavar="A",
                   help="largest rotation from the home orientation, rad or deg (default 30deg)")
    p.add_argument("--scene", metavar="FILE",
                   help="scene file (YAML: obstacles, cable radius, platform shape): a pose is "
                        "feasible only if also clear of it (as verify --scene); plans keep clear")
    p.add_argument("--reach", action="store_true",
                   help="plan from the home pose to every feasible sample")
    p.add_argument("--home", nargs=6, metavar=("X", "Y", "Z", "PHI", "THETA", "SIGMA"),
                   help="home pose (m, rad or deg; default: the largest-margin pose of 100000 "
                        "random ones in the default box, numpy seed 0)")
    p.add_argument("--timeout", type=float, default=10.0, metavar="S",
                   help=f"seconds per plan, up to {ws.MAX_TIMEOUT_S:g} (default 10)")
    p.add_argument("--workers", type=int, metavar="N", help="Ray workers (default: the cores)")
    p.add_argument("--ray-address", metavar="HOST:PORT", help="attach to a running Ray cluster")
    p.add_argument("--no-ray", action="store_true", help="run in this process, without Ray")
    p.add_argument("--max-seconds", type=float, default=MAX_SECONDS, metavar="S",
                   help="stop after S seconds with what is answered (default one week)")
    p.add_argument("--json", metavar="OUT", help="write every pose and the summary as JSON")
    p.add_argument("--plot", metavar="OUT.png", help="draw the feasible and reachable sets")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args):
    """Sample, evaluate (and plan), print the summary, write the outputs; exit code 0."""
    robot = load_robot(args.robot)
    scene = load_scene(args.scene, robot) if args.scene else None
    spec = build_spec(args, robot, scene)
    workers = check_workers(args)
    max_seconds = _positive("--max-seconds", args.max_seconds, MAX_SECONDS)
    inputs = [("the robot file ROBOT", args.robot)] + ([("the --scene file", args.scene)] if args.scene else [])
    if args.json:
        check_output("--json", args.json, inputs=inputs)
        inputs.append(("the --json output", args.json))
    if args.plot:
        check_output("--plot", args.plot, suffixes=(".png",), inputs=inputs)
    res = run_spec(robot, spec, workers, args.ray_address, not args.no_ray, max_seconds, args.quiet,
                   scene)
    print_summary(robot, res)
    if args.json:
        write_text("--json", args.json, dump_rows(ws.result_dict(robot, res)))
        print(f"wrote {args.json}")
    if args.plot:
        from ..studies.plots import plot_workspace
        with writing("--plot", args.plot):
            plot_workspace(args.plot, res.position, res.feasible, res.reachable, spec.reach,
                           title_of(robot, res), home=spec.home_position)
        print(f"wrote {args.plot}")
    return 0


def run_spec(robot, spec, workers, address, use_ray, max_seconds, quiet, scene=None):
    """``run_workspace`` on the executor of the options, closed afterwards."""
    executor = make_executor(workers, address, ray=use_ray)
    try:
        with count_progress(quiet) as update:
            res = ws.run_workspace(robot, spec, executor, progress=update, max_seconds=max_seconds,
                                   scene=scene)
        res.seconds["ray_start"] = getattr(executor, "start_s", 0.0)
        return res
    finally:
        executor.close()


def build_spec(args, robot, scene=None):
    """The WorkspaceSpec of the options, checked (InputError naming the option)."""
    low, high = parse_box(args.box) if args.box else ws.default_box(robot)
    if args.tilt is not None and args.task_file:
        raise InputError("--tilt", args.tilt, "not with --task-file: the task fixes the orientations")
    tilt = parse_angle(args.tilt or "30deg", "--tilt")
    task = None
    if args.task_file:
        from .slice import task_in_yaml
        task = task_in_yaml(args.task_file)
        if task is None:
            raise InputError("--task-file", args.task_file, "no 'task:' mapping (top level or "
                                                            "under ros__parameters)")
    if args.home:
        position = [parse_length(v, f"--home {n}") for v, n in zip(args.home[:3], "xyz")]
        tau = [parse_angle(v, f"--home {n}") for v, n in zip(args.home[3:], ("phi", "theta", "sigma"))]
        home = ws.home_from_tau(position, tau)
    else:
        home = ws.default_home(robot, scene=scene) if task is None else None
    if not math.isfinite(args.timeout):
        raise InputError("--timeout", args.timeout, "must be a finite number of seconds")
    spec = ws.WorkspaceSpec(samples=args.samples, seed=args.seed, box_low=low, box_high=high,
                            home_position=(0.0, 0.0, 0.0), home_quaternion=(0.0, 0.0, 0.0, 1.0),
                            tilt=tilt, reach=args.reach, timeout_s=args.timeout,
                            settings=PlannerSettings(), task=task).check("--")
    if home is None:
        home = ws.default_task_home(robot, spec, scene=scene)
    elif task is not None:
        ws.check_on_task(task, *home)
    ws.check_home(robot, *home, scene=scene)
    if spec.reach:
        ws.check_planner(robot, spec, scene)
    return replace(spec, home_position=home[0], home_quaternion=home[1])


def parse_box(text):
    """(low, high) corners of "X0,Y0,Z0,X1,Y1,Z1" (m, or with a unit each)."""
    parts = text.split(",")
    if len(parts) != 6:
        raise InputError("--box", text, "expected six values X0,Y0,Z0,X1,Y1,Z1")
    v = [parse_length(s, "--box") for s in parts]
    return tuple(v[:3]), tuple(v[3:])


def check_workers(args):
    if args.workers is not None and not 1 <= args.workers <= 4096:
        raise InputError("--workers", args.workers, "must be between 1 and 4096")
    if args.no_ray and (args.workers not in (None, 1) or args.ray_address):
        raise InputError("--no-ray", "", "runs in this process: no --workers above 1, no --ray-address")
    return args.workers


def _positive(option, value, limit):
    if not (math.isfinite(value) and 0 < value <= limit):
        raise InputError(option, value, f"must be in (0, {limit:g}]")
    return value


def title_of(robot, res):
    f = res.fractions()
    scene = "" if res.job is None or res.job.scene is None else ", scene"
    head = f"{robot.name}{scene}: {res.spec.samples} samples, tilt {np.rad2deg(res.spec.tilt):.0f} deg, " \
           f"{100 * f['feasible']:.1f} % feasible"
    if res.spec.reach:
        head += f", {100 * f['reachable']:.1f} % reachable (plan timeout {res.spec.timeout_s:g} s)"
    return head


def refusal_reasons(robot, res):
    """Why the refused goals were refused, as counted (``counts``): "" when none."""
    c = res.counts()
    if not c["refused"]:
        return ""
    parts = [f"{c['refused_under_floor']} feasible but under the margin floor "
             f"{res.spec.settings.margin_floor:g}"] if c["refused_under_floor"] else []
    if c["refused_band"]:
        parts.append(f"{c['refused_band']} " + ("where the tension rule's band does not fit"
                                                if len(robot.base_anchors) > 6 else
                                                "under the planner's margin"))
    return f" ({', '.join(parts)})"


def print_summary(robot, res):
    c, f, s = res.counts(), res.fractions(), res.seconds
    print(f"robot {robot.name} ({robot.source}): {c['evaluated']}/{c['samples']} samples evaluated, "
          f"{c['feasible']} feasible ({100 * f['feasible']:.2f} %)")
    if res.spec.reach:
        print(f"  reach from home: {c['reachable']} reachable ({100 * f['reachable']:.2f} % of the "
              f"samples, {100 * f['reachable_of_feasible']:.2f} % of the feasible), "
              f"{c['unreachable_feasible']} without a path, {c['refused']} refused as goals"
              f"{refusal_reasons(robot, res)}, {c['unknown']} unknown (a bound)")
    print(f"  {res.workers} worker(s); seconds: points {s['points']:.2f}, reach {s['reach']:.2f}, "
          f"total {s['total']:.2f} (Ray start {s.get('ray_start', 0.0):.2f})")
    if res.stopped:
        print(f"  stopped early: {res.stopped} (the answers above are of the samples done)")
