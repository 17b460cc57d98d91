"""``cdh-planner plan``: plan a wrench-feasible path for a problem file, without ROS.

    cdh-planner plan PROBLEM.yaml [--strategy S] [--radius R] [--timeout S]
                     [--max-charts N] [--max-memory MB] [--complete] ... [--json OUT] [--plot OUT.png]

Every planner setting has a flag (settings.py: the schema the node's parameters and the
problem file use too).

Prints the outcome (reason, charts, seconds, cost, waypoints, duration, least margin and
least tension margin) with a progress bar while the atlas grows. Exit 0 with a path, 1
without one (no path at this resolution, timeout, chart or memory limit, infeasible start
or goal), 2 for bad input
(the output paths are checked before planning), 3 for an internal error.

``--json OUT`` writes the plan JSON contract (README, the plan command): success, reason, message, strategy,
n, m, charts, time_s, cost, least_margin, least_tension_margin_n, and path: [{p, quaternion,
tau, lengths, tension_min, tension_nominal, tension_max, margin, t, velocities,
accelerations, and with robot.length_error position_error_m, orientation_error_rad}]
(m, rad, N, s; cable rates m/s and m/s^2: a JointTrajectoryController's
quintic through these points is the motion that was checked, ``trajectory.executed``).
"""

ORDER = 30  # its place in `cdh-planner --help`
SUMMARY = "plan a wrench-feasible path for a problem file (no ROS needed)"

import json
import math
from dataclasses import replace

from ..accuracy import has_accuracy, pose_accuracy
from ..model.pose import rotation_from_quaternion
from .outputs import check_output, write_text, writing
from ..parsing.problem import load_problem
from ..progress import chart_progress
from ..planner import Planner
from ..fields import BOOL, CHOICE
from ..settings import SETTINGS, check_setting
from ..status import Status

EXIT_OK, EXIT_NO_PLAN, EXIT_INTERNAL = 0, 1, 3  # cdh_planner.cli's contract
# every way a plan ends has its exit code: a path, an answer without one, a bug
EXIT_CODES = {s: EXIT_OK if s is Status.OK else EXIT_INTERNAL if s is Status.INTERNAL_ERROR
              else EXIT_NO_PLAN for s in Status}


def add_parser(subparsers):
    p = subparsers.add_parser(
        "plan", help=SUMMARY,
        description="Try the direct motion, then grow atlases of the navigation manifold from "
                    "the start and the goal and search them (A* or Greedy Best-First) until they "
                    "meet, a component is exhausted (no path at this resolution), or a limit. "
                    "Exit 0 with a path, 1 without, 2 for bad input.",
        epilog="example: cdh-planner plan config/problems/robot2_q2_q3.yaml --json out.json "
               "--plot out.png")
    p.add_argument("problem", help="problem file (YAML: robot, task, start, goal; see config/problems)")
    for name, s in SETTINGS.items():  # one flag per setting, from the schema
        unit = f", {s.unit}" if s.unit else ""
        help_text = f"{s.description} (default: the file's, else {s.default}{unit})"
        if s.kind == BOOL:
            p.add_argument(s.flag, dest=name, action="store_const", const=True, help=help_text)
        else:
            p.add_argument(s.flag, dest=name, type=str if s.kind == CHOICE else float,
                           choices=s.choices or None, metavar=None if s.choices else name.upper(),
                           help=help_text)
    p.add_argument("--json", metavar="OUT", help="write the result as JSON")
    p.add_argument("--plot", metavar="OUT.png",
                   help="draw the atlas and path over the C-space slice (2-D tasks) and the "
                        "tension envelope along the path (OUT_tensions.png)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args):
    problem = load_problem(args.problem)
    settings = problem.settings
    overrides = {name: check_setting(name, getattr(args, name), s.flag)
                 for name, s in SETTINGS.items() if getattr(args, name) is not None}
    settings = replace(settings, **overrides)
    check_outputs(args, problem)
    planner = Planner(problem.robot, problem.task, settings, scene=problem.scene)
    result = plan_with_progress(planner, problem.start, problem.goal, quiet=args.quiet)
    print_result(result, problem)
    if args.json:
        write_text("--json", args.json, json.dumps(plan_document(result, problem.robot), indent=1))
        print(f"JSON: {args.json}")
    if args.plot:
        from ..pictures.plans import plot_plan
        with writing("--plot", args.plot):
            outs = plot_plan(planner, problem, result, args.plot)
        for out in outs:
            print(f"picture: {out}")
    return EXIT_CODES[result.reason]


def check_outputs(args, problem):
    """Refuse, before planning, an output that cannot be written or that names an input
    (the problem or robot file) or another output."""
    files = [("the problem file", args.problem), ("the robot file", problem.robot.source)]
    if args.json is not None:
        check_output("--json", args.json, inputs=files)
        files.append(("the --json output", args.json))
    if args.plot is not None:
        plot = check_output("--plot", args.plot, suffixes=(".png",), inputs=files)
        tensions = plot.with_name(plot.stem + "_tensions.png")
        check_output("--plot", tensions, inputs=files + [("the --plot picture", plot)])


def plan_with_progress(planner, start, goal, quiet=False):
    """planner.plan with a tqdm bar counting charts (on stderr)."""
    with chart_progress(quiet) as update:
        return planner.plan(start, goal,
                            progress=lambda info: update(info["charts"], info["best_h"]))


def print_result(result, problem):
    head = "path found" if result.success else f"no path ({result.reason})"
    print(f"{head}: {result.message}")
    print(f"  strategy {result.strategy}, n = {result.n}, {result.variables} variables, "
          f"{result.charts} charts, {result.time_s:.3f} s")
    if result.success:
        path = result.path
        print(f"  cost {result.cost:.4f}, {len(path)} waypoints, platform path "
              f"{path.length_m():.4f} m, duration {path.t[-1]:.2f} s, least margin "
              f"{result.least_margin:.4f} ({result.least_tension_margin:.3g} N)")
        print(f"  timing: {result.stats.get('timing', 'quasi-static')}")
        print(f"  executed: {result.stats.get('executed', '')}")
        if "least_clearance_m" in result.stats:  # a scene: the least distance at a waypoint
            print(f"  least clearance {1e3 * result.stats['least_clearance_m']:.3g} mm "
                  f"({result.stats['clearance_binding']})")


def plan_document(result, robot):
    """The plan JSON (``result_dict``) with, for a ``robot`` that has ``length_error``, each
    waypoint's ``position_error_m`` (m) and ``orientation_error_rad`` (rad): the worst
    platform error over the winches' length errors (``accuracy.pose_accuracy``)."""
    doc = result_dict(result)
    path = result.path
    if path is None or not has_accuracy(robot):
        return doc
    acc = pose_accuracy(robot, path.p, R=rotation_from_quaternion(path.quaternion),
                        tensions=path.tension_nominal)
    for row, e_p, e_w in zip(doc["path"], acc.position_m.tolist(), acc.orientation_rad.tolist()):
        row["position_error_m"], row["orientation_error_rad"] = _num(e_p), _num(e_w)
    return doc


def result_dict(result):
    """The plan JSON contract (README); non-finite numbers become null."""
    out = {"success": result.success, "reason": result.reason, "message": result.message,
           "strategy": result.strategy, "n": result.n, "m": result.variables, "charts": result.charts,
           "time_s": result.time_s, "cost": _num(result.cost),
           "least_margin": _num(result.least_margin),
           "least_tension_margin_n": _num(result.least_tension_margin),
           "timing": result.stats.get("timing", ""), "executed": result.stats.get("executed", ""),
           "path": []}
    if "least_clearance_m" in result.stats:  # with a scene (m, and what binds there)
        out["least_clearance_m"] = _num(result.stats["least_clearance_m"])
        out["clearance_binding"] = result.stats["clearance_binding"]
    path = result.path
    if path is not None:
        commanded, velocities, accelerations = path.commanded()
        for k in range(len(path)):
            out["path"].append({
                "p": path.p[k].tolist(), "quaternion": path.quaternion[k].tolist(),
                "tau": path.tau[k].tolist(), "lengths": path.lengths[k].tolist(),
                "tension_min": path.tension_min[k].tolist(),
                "tension_nominal": path.tension_nominal[k].tolist(),
                "tension_max": path.tension_max[k].tolist(), "margin": float(path.margin[k]),
                "t": float(path.t[k]), "commanded_lengths": commanded[k].tolist(),
                "velocities": velocities[k].tolist(),
                "accelerations": accelerations[k].tolist()})
    return out


def _num(x):
    return float(x) if x is not None and math.isfinite(x) else None
