"""``cdh-planner call``: the task sequencer's view of a running node.

    cdh-planner call (--start "x y z qx qy qz qw" | --current-start) --goal "x y z qx qy qz qw"
                     [--strategy S] [--execute] [--node /cdh_planner] [--frame F]
                     [--timeout S] [--ros-args ...]

Sends a goal to the ``~/plan_path`` action (positions in m in the base frame, quaternion
x y z w; ``--current-start``: from the pose of the measured cable lengths), shows its
progress (charts) on stderr, and prints the outcome, the path length, duration, lowest
tension margin and the run's log file; Ctrl-C cancels the plan. With ``--execute`` it then
calls ``~/execute`` and waits for ``~/execution_result`` (Ctrl-C calls ``~/stop``). The frame
defaults to the node's ``base_frame``.

The poses are checked here as a pose file's are (finite, within +-1e3 m, a unit quaternion)
and so are ``--node`` and the ROS arguments, before joining ROS. The node must be there
within NODE_WAIT_S (or ``--timeout`` if shorter): ``call`` does not wait for one to start.

Exit codes: 0 planned (and executed to the last waypoint); 1 no plan: the node answered
none, refused the execution or cut it short, or no node answered (not running, another
ROS_DOMAIN_ID or name; one line saying so); 2 bad input.
"""

ORDER = 70  # its place in `cdh-planner --help`
SUMMARY = "plan through a running node's ~/plan_path action (and execute)"

import argparse
import math
import sys

from ..progress import chart_progress
from ..settings import STRATEGY_CHOICES

EXIT_OK, EXIT_NO_PLAN = 0, 1
EXIT_NO_NODE = EXIT_NO_PLAN   # no node, no plan: not bad input, and not a bug (3)
NODE_WAIT_S = 5.0   # s to wait for the node's services (a DDS announcement period is ~3 s)


def add_parser(subparsers):
    p = subparsers.add_parser(
        "call", help=SUMMARY,
        description="Plan with a running cdh_planner node (its ~/plan_path action) from a "
                    "start pose (or the measured one) to a goal pose, print the outcome, path "
                    "length, duration, lowest tension margin and the log file; --execute then "
                    "executes the plan. Ctrl-C cancels. Exit 1 when there is no plan.",
        epilog="example (Robot 2's sphere task, q1 -> q2):\n"
               "  cdh-planner call --start \"0 0 0.176 0 0 0 1\" \\\n"
               "      --goal \"0.081092 0.049718 0.217387 0.208539 -0.340136 0 0.916962\"\n"
               "values starting with '-': --start=\"-0.1 0 0.2 0 0 0 1\"",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    start = p.add_mutually_exclusive_group(required=True)
    start.add_argument("--start", metavar='"X Y Z QX QY QZ QW"',
                       help="start pose: position (m, base frame) and quaternion (x y z w)")
    start.add_argument("--current-start", action="store_true",
                       help="start from the pose of the measured cable lengths (the node's "
                            "execution.joint_states_topic)")
    p.add_argument("--goal", required=True, metavar='"X Y Z QX QY QZ QW"', help="goal pose")
    p.add_argument("--strategy", choices=STRATEGY_CHOICES,
                   help="search strategy (default: the node's planner.strategy)")
    p.add_argument("--execute", action="store_true",
                   help="after a successful plan, execute it (~/execute) and wait for the end")
    p.add_argument("--node", default="/cdh_planner", help="the planner node (default: "
                                                          "%(default)s)")
    p.add_argument("--frame", help="frame_id of the poses (default: the node's base_frame)")
    p.add_argument("--timeout", type=float, default=120.0, metavar="S",
                   help=f"seconds to wait for the answer (default: %(default)g; for the node "
                        f"itself at most {NODE_WAIT_S:g})")
    p.add_argument("--ros-args", dest="ros_args", nargs=argparse.REMAINDER, default=[],
                   metavar="ARGS", help="ROS arguments for this client (e.g. remapping)")
    p.set_defaults(func=run)


def run(args):
    from ..errors import InputError, check_text
    from ..parsing.poses import pose_values
    if not (args.timeout > 0 and math.isfinite(args.timeout)):
        raise InputError("--timeout", args.timeout, "must be a positive number of seconds")
    if args.start is not None:   # bad input refused before importing ROS (seconds)
        pose_values(args.start, "--start")
    pose_values(args.goal, "--goal")
    if args.frame is not None:
        check_text("--frame", args.frame)
    from ..ros.client import ClientError, PlannerClient, plan_path_goal, pose_stamped
    with PlannerClient(args.node, args=["cdh-planner-call", "--ros-args", *args.ros_args],
                       node_field="--node") as client:
        try:
            client.wait_for_node(min(args.timeout, NODE_WAIT_S))
            frame = args.frame or client.get_parameters(["base_frame"])["base_frame"]
            start = None if args.start is None else pose_stamped(args.start, frame, "--start")
            goal = plan_path_goal(start, pose_stamped(args.goal, frame, "--goal"),
                                  use_current_start=args.current_start,
                                  strategy=args.strategy or "")
            with chart_progress() as update:
                answer = client.plan_path(goal, args.timeout,
                                          on_feedback=lambda f: update(f.charts, f.best_h))
            print_answer(answer)
            if not answer.success:
                return EXIT_NO_PLAN
            if args.execute:
                return execute(client, answer)
        except ClientError as exc:
            print(f"cdh-planner call: error: {exc}", file=sys.stderr)
            return EXIT_NO_NODE
    return EXIT_OK


def print_answer(answer):
    """Print a PlanAnswer for a person: outcome, numbers with units, the log file."""
    from ..ros.client import path_duration, path_length
    v = answer.values
    if answer.success:
        print(f"outcome: planned ({len(answer.path.poses)} waypoints, "
              f"{v.get('charts', '?')} charts, strategy {v.get('strategy', '?')}, planning "
              f"{answer.number('planning_time_s'):.3f} s, call {answer.seconds:.3f} s)")
        print(f"path length: {path_length(answer.path):.4f} m")
        print(f"duration: {path_duration(answer.path):.3f} s")
        print(f"lowest tension margin: {answer.number('min_tension_margin_n'):.4f} N "
              f"(normalised feasibility margin {answer.number('min_margin'):.4f})")
    else:
        result = answer.result
        code = v.get("error_code", result.error_code if result is not None else "?")
        why = v.get("error_msg") or (result.error_msg if result is not None else "") \
            or "(no ~/plan_result received)"
        print(f"outcome: NO PLAN (error code {code}): {why}")
    print(f"log file: {v.get('log_file') or '(not recorded)'}")
    if v.get("run_id"):
        print(f"run id: {v['run_id']}")


def execute(client, answer):
    """Call ~/execute and follow the execution until ``~/execution_result`` says it ended
    (``PlannerClient.execute_and_follow``); Ctrl-C stops the motion. 0 when it completed
    (streamed: the last command is the last waypoint), 1 otherwise."""
    run = client.execute_and_follow(answer)
    print(f"execute: {run.message}")
    if not run.accepted:
        return EXIT_NO_PLAN
    if run.stopped:
        print(f"stop: {run.stopped}")
    if run.commands:
        span, rate = run.rate()
        _, positions = run.values()
        print(f"streamed: {len(run.commands)} commands over {span:.3f} s ({rate:.1f} Hz); "
              f"final cable lengths {' '.join(f'{x:.4f}' for x in positions[-1])} m")
    print(run.end.message if run.end is not None else
          "execution: no ~/execution_result received (the node went away?)")
    if not run.arrived:
        print("execution did not reach the last waypoint")
        return EXIT_NO_PLAN
    return EXIT_OK
