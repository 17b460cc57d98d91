"""``cdh-planner replay``: play a recorded run back.

    cdh-planner replay RUN.mcap [RUN_2.mcap ...] [--rate X] [--topics T ...] [--delay S]
                       [--max-gap S]
    cdh-planner replay RUN.mcap [RUN_2.mcap ...] --requests [--node /cdh_planner]
                       [--tolerance M] [--keep-parameters]

Without ``--requests``: republish the recorded topics with their original timing (scaled by
``--rate``; no wait between two messages longer than ``--max-gap``). The command topics
(``cable_command``, a streamed mode's topic as recorded in its parameter, e.g.
``execution.forward_command_topic``, and ``cable_trajectory``) move the robot: they are republished only with
``--commands``, e.g. ``--commands --topics /cdh_planner/cable_command`` to test a winch
controller on a bench.
With ``--requests``: re-send the recorded plan requests to a running node, in recorded
order: GetPlan calls to ``~/plan`` ("request N") and PlanPath goals to ``~/plan_path``
("goal N", e.g. those of ``cdh-planner call``; N is the node's call number). Report, for
each, whether the new answer matches the recorded one (pose by pose, within the tolerance;
for a goal also the error code), and for an answer that differs, why it may (parameters
that differ, the node's history). A goal recorded with ``use_current_start`` was planned
from the pose the node measured, which the goal does not hold: it is sent with the recorded
path's first pose as its start instead (its line says so); without a recorded path, as
recorded.
Before each request the parameters recorded since the previous one (the file's snapshot,
then each change) are set on the node, those that decide answers (``base_frame``,
``scene_file``, ``robot.*``, ``task.*``, ``planner.*``, ``trajectory.*``), each recorded
change in one atomic call; then the node's obstacles are made those of its last recorded
``~/scene`` (REMOVE and ADD on its ``~/obstacles``); ``--keep-parameters`` leaves the node's
own parameters and obstacles. The planner keeps its atlas between
requests, so the answers are the recorded ones on a node in the state the recording started
from: a freshly started node. A node that has already planned may answer with other
(equally valid) paths.

A file that is not a recording (missing, empty, not MCAP, no complete message) is refused
with the reason (exit 2); a killed run's file is read (``cdh-planner recover`` completes it).

Exit codes: 0 done (every answer matches); 1 an answer differs, or no node answered (one
line saying so); 2 bad input (a file that is not a recording, damaged data, bad --ros-args).
"""

ORDER = 80  # its place in `cdh-planner --help`
SUMMARY = "republish a recorded run, or re-send its plan requests"

import argparse
import math
import sys
from collections import Counter

EXIT_OK, EXIT_DIFFERS = 0, 1
EXIT_NO_NODE = EXIT_DIFFERS   # no node: nothing matched; not bad input, and not a bug (3)
MAX_GAP_S = 5.0     # = ros.replay.MAX_GAP_S (not imported: --help needs no rclpy)


def add_parser(subparsers):
    p = subparsers.add_parser(
        "replay", help=SUMMARY,
        description="Republish the topics of a run file (MCAP) with their recorded timing, or "
                    "with --requests re-send its plan requests to a running node and compare "
                    "the answers with the recorded ones.",
        epilog="examples:\n"
               "  cdh-planner replay runs/cdh_planner_20250101-120000_42.mcap --rate 2\n"
               "  cdh-planner replay RUN.mcap --commands --topics /cdh_planner/cable_command\n"
               "  cdh-planner replay RUN.mcap --requests --tolerance 1e-4",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run", nargs="+", metavar="RUN.mcap",
                   help="a run file written by the node; several (e.g. the files of a "
                        "rotated run) are replayed as one, in log-time order")
    p.add_argument("--rate", type=float, default=1.0, metavar="X",
                   help="playback speed factor (default: %(default)g, real time)")
    p.add_argument("--topics", nargs="+", metavar="T",
                   help="only these topics (default: all but service events and "
                        "/parameter_events)")
    p.add_argument("--commands", action="store_true",
                   help="also republish the command topics (cable_command, a streamed mode's "
                        "topic such as execution.forward_command_topic, cable_trajectory): "
                        "they move the robot, so they are left alone unless asked for")
    p.add_argument("--delay", type=float, default=1.0, metavar="S",
                   help="wait up to S seconds for a subscriber on every replayed topic before "
                        "the first message (default: %(default)g)")
    p.add_argument("--max-gap", dest="max_gap", type=float, default=MAX_GAP_S, metavar="S",
                   help="never wait more than S seconds between two messages: longer "
                        "recorded gaps (after --rate) are cut to S (default: %(default)g)")
    p.add_argument("--requests", action="store_true",
                   help="re-send the recorded plan requests (GetPlan calls, PlanPath goals) "
                        "to a running node, after setting the parameters recorded before "
                        "each, and compare (to reproduce the recorded answers: a freshly "
                        "started node, since the planner keeps its atlas between requests)")
    p.add_argument("--node", help="node for --requests (default: the recorded one)")
    p.add_argument("--keep-parameters", dest="keep_parameters", action="store_true",
                   help="--requests: do not set the recorded parameters (and obstacles) "
                        "on the node")
    p.add_argument("--tolerance", type=float, default=1e-6, metavar="M",
                   help="--requests: largest pose difference that still matches, in m for "
                        "positions and rad for orientations (default: %(default)g)")
    p.add_argument("--timeout", type=float, default=120.0, metavar="S",
                   help="--requests: seconds to wait for the node and each answer "
                        "(default: %(default)g)")
    p.add_argument("--ros-args", dest="ros_args", nargs=argparse.REMAINDER, default=[],
                   metavar="ARGS", help="ROS arguments (e.g. -r /cdh_planner/path:=/other)")
    p.set_defaults(func=run)


def run(args):
    from ..errors import InputError
    from ..recording.mcap_log import check_recording
    from ..ros import replay as R
    for name in ("rate", "timeout", "tolerance", "delay", "max_gap"):
        value = getattr(args, name)
        low_ok = value >= 0 if name in ("tolerance", "delay", "max_gap") else value > 0
        if not (math.isfinite(value) and low_ok):
            raise InputError(f"--{name.replace('_', '-')}", value,
                             "must be a positive finite number")
    records = []
    for path in args.run:
        records += R.read_records(path)     # InputError (exit 2) if not a recording
    records.sort(key=lambda r: r.log_time_ns)
    counts = Counter(r.topic for r in records)
    span = (records[-1].log_time_ns - records[0].log_time_ns) * 1e-9
    print(f"{' '.join(args.run)}: {len(records)} messages on {len(counts)} topics over "
          f"{span:.3f} s")
    for topic, n in sorted(counts.items()):
        print(f"  {topic}: {n}")
    for path in args.run:
        if not check_recording(path)[1]:
            print(f"  ({path} has no summary: its recording did not end normally (the "
                  f"node killed, or a write failed, e.g. a full disk); cdh-planner "
                  f"recover {path} writes a complete copy)")
    if args.requests:
        return replay_requests(args, records)
    return replay_topics(args, records)


def replay_topics(args, records):
    import rclpy
    from rclpy.node import Node

    from ..ros import replay as R
    from ..ros.context import init_context
    chosen = R.select_topics(records, args.topics, args.commands)
    _check_topic_names(chosen)
    context = init_context(["cdh-planner-replay", "--ros-args", *args.ros_args])
    try:
        node = Node("cdh_planner_replay", context=context)
        offsets, capped, skipped = R.schedule(chosen, args.rate, args.max_gap)
        if capped:
            print(f"{capped} wait{'s' if capped > 1 else ''} between messages longer than "
                  f"--max-gap {args.max_gap:g} s cut to {args.max_gap:g} s "
                  f"({skipped:.6g} s of recorded time skipped)")
        stats = R.replay_topics(node, chosen, rate=args.rate, delay_s=args.delay,
                                max_gap_s=args.max_gap)
        print(f"republished {stats.messages} messages on {stats.topics} topics in "
              f"{stats.replay_s:.3f} s (recorded span {stats.recorded_s:.3f} s, rate "
              f"{args.rate:g}; latest {1e3 * stats.late_s:.1f} ms behind schedule)")
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    return EXIT_OK


def _check_topic_names(records):
    """InputError naming a recorded topic that is not a valid ROS name (a file written by
    another tool): rclpy would refuse its publisher mid-replay."""
    from rclpy.exceptions import NameValidationException
    from rclpy.validate_full_topic_name import validate_full_topic_name

    from ..errors import InputError
    for topic in sorted({r.topic for r in records}):
        try:
            validate_full_topic_name(topic if topic.startswith("/") else "/" + topic)
        except NameValidationException:
            raise InputError("RUN", topic, "a recorded topic whose name is not a valid ROS "
                                           "topic name: it cannot be republished") from None


def replay_requests(args, records):
    from rclpy.impl.implementation_singleton import rclpy_implementation

    from ..errors import InputError, exception_line
    from ..ros import replay as R
    from ..ros.client import ClientError, PlannerClient
    try:
        plans = R.recorded_plans(records)
    except rclpy_implementation.RMWError as exc:  # bytes that are not the recorded type
        raise InputError("RUN", " ".join(args.run), f"a recorded request or parameter event "
                                                    f"does not decode: "
                                                    f"{exception_line(exc, 100)}") from None
    if not plans:
        print("no recorded plan requests in this file")
        return EXIT_OK
    node = args.node or R.node_of(plans[0].service)
    if not args.keep_parameters and not any(p.parameters for p in plans):
        print("no recorded parameters in this file (recorded before they were): the node's "
              "own are used")
    differs = 0
    first_call = None
    with PlannerClient(node, args=["cdh-planner-replay", "--ros-args", *args.ros_args],
                       node_field="--node" if args.node else "the recorded node") as client:
        try:
            client.wait_for_node(min(args.timeout, 30.0))
            setter = R.ParameterSetter(client, min(args.timeout, 30.0))
            for plan in plans:
                problems = [] if args.keep_parameters else _apply(setter, plan)
                problems += [] if args.keep_parameters else _apply_scene(client, plan)
                note = ""
                if plan.action:
                    goal, note = R.goal_to_replay(plan)
                    answer = client.plan_path(goal, args.timeout)
                    error_msg = answer.result.error_msg
                else:
                    answer = client.plan(plan.request.start, plan.request.goal, args.timeout,
                                         tolerance=plan.request.tolerance)
                    error_msg = answer.values.get("error_msg", "")
                note = f" ({note})" if note else ""
                call = R.call_number(answer.values)
                first_call = call if first_call is None else first_call
                if plan.response is None:
                    print(f"{plan.label}{note}: no recorded response (run ended); now "
                          f"{len(answer.path.poses)} poses")
                    continue
                if plan.action:
                    ok, text = R.compare_results(plan.response, answer.result, args.tolerance,
                                                 args.tolerance)
                else:
                    ok, text = R.compare_paths(plan.response.plan, answer.path, args.tolerance,
                                               args.tolerance)
                why = "" if answer.success else f" ({error_msg})"
                if not ok:
                    differs += 1
                    why += "; why: " + "; ".join(
                        _reasons(args, setter, plan, plans[0], problems, first_call))
                print(f"{plan.label}{note}: {'MATCHES' if ok else 'DIFFERS'}: {text}{why}")
        except ClientError as exc:
            print(f"cdh-planner replay: error: {exc}", file=sys.stderr)
            return EXIT_NO_NODE
    print(f"{len(plans) - differs} of {len(plans)} answers match the recording")
    return EXIT_DIFFERS if differs else EXIT_OK


def _apply(setter, plan):
    """Set the parameters recorded before ``plan``; print what was set; the problems."""
    problems = []
    for params in plan.parameter_sets:
        names, problem = setter.set(params)
        if names:
            shown = ", ".join(names) if len(names) <= 4 else f"{len(names)} parameters"
            print(f"{plan.label}: set as recorded: {shown}")
        if problem:
            problems.append(problem)
            print(f"{plan.label}: parameters not applied: {problem}")
    return problems


def _apply_scene(client, plan):
    """Bring the node's obstacles to those recorded before ``plan`` (the node's ~/scene);
    print what changed; the problems."""
    from ..ros.client import ClientError
    from ..ros.msgs.scene_msgs import scene_change
    if plan.scene is None:
        return []
    try:
        change = scene_change(client.get_scene(), plan.scene)
        if change.obstacles:
            client.update_scene(change)
            print(f"{plan.label}: obstacles as recorded (scene version "
                  f"{plan.scene.version}): {len(change.obstacles)} added or removed")
    except ClientError as exc:
        print(f"{plan.label}: obstacles not applied: {exc}")
        return [f"obstacles: {exc}"]
    return []


def _reasons(args, setter, plan, first, problems, first_call):
    """Why an answer may differ from the recorded one (the likeliest first)."""
    from ..ros import replay as R
    from ..ros.client import ClientError
    out = []
    if plan.action and plan.response is not None and \
            plan.response.error_code in (R.CANCELED, R.BUSY):
        out.append(f"the recorded goal ended {R.error_code_name(plan.response.error_code)} "
                   f"(a cancel, the node shutting down or a full queue), which a replay does "
                   f"not repeat")
    if plan.action and plan.request.use_current_start and \
            (plan.response is None or not plan.response.path.poses):
        out.append("use_current_start: planned from the pose the recording's node measured, "
                   "which is not recorded")
    if problems:
        out.append("recorded parameters not applied (" + "; ".join(problems) + ")")
    if not plan.parameters:
        out.append("the file records no parameters for this request, so the node's own "
                   "were used")
    else:
        try:
            diff = R.parameter_differences(plan.parameters, setter.get(plan.parameters))
        except ClientError as exc:
            diff = f"could not read the node's parameters: {exc}"
        if diff:
            out.append(("parameters differ: " if args.keep_parameters else "") + diff)
    if first_call is not None and first_call > 1:
        out.append(f"the node had answered {first_call - 1} plan call(s) before this replay "
                   f"(a planner keeps its atlas between calls: a fresh node reproduces a "
                   f"recording)")
    if first.sequence > 1:
        out.append(f"the recording's node had answered {first.sequence - 1} call(s) before "
                   f"this file's first request (e.g. a rotated file)")
    if not out:
        out.append("same parameters, and both nodes fresh: the planner itself answered "
                   "differently")
    return out
