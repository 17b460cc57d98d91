"""``cdh-planner replay``: play a recorded run back.

    cdh-planner replay RUN.mcap [--rate X] [--topics T ...] [--delay S]
    cdh-planner replay RUN.mcap --requests [--node /cdh_planner] [--tolerance M]

Without ``--requests``: republish the recorded topics with their original timing (scaled by
``--rate``), e.g. the streamed ``/cdh_planner/cable_command`` to test a winch controller.
With ``--requests``: re-send the recorded plan requests to a running node and report, for
each, whether the new answer matches the recorded one (pose by pose, within the tolerance).
The planner keeps its atlas between requests, so the answers are the recorded ones on a node
in the state the recording started from: a freshly started node with the same parameters. A
node that has already planned may answer with other (equally valid) paths.

Exit codes: 0 done (every answer matches); 1 an answer differs; 2 bad input; 3 the node
did not answer.
"""

import argparse
import math
import sys
from collections import Counter

EXIT_OK, EXIT_DIFFERS, EXIT_NO_NODE = 0, 1, 3


def add_parser(subparsers):
    p = subparsers.add_parser(
        "replay", help="republish a recorded run, or re-send its plan requests",
        description="Republish the topics of a run file (MCAP) with their recorded timing, or "
                    "with --requests re-send its plan requests to a running node and compare "
                    "the answers with the recorded ones.",
        epilog="examples:\n"
               "  cdh-planner replay runs/cdh_planner_20250101-120000_42.mcap --rate 2\n"
               "  cdh-planner replay RUN.mcap --topics /cdh_planner/cable_command\n"
               "  cdh-planner replay RUN.mcap --requests --tolerance 1e-4",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run", metavar="RUN.mcap", help="a run file written by the node")
    p.add_argument("--rate", type=float, default=1.0, metavar="X",
                   help="playback speed factor (default: %(default)g, real time)")
    p.add_argument("--topics", nargs="+", metavar="T",
                   help="only these topics (default: all but service events)")
    p.add_argument("--delay", type=float, default=1.0, metavar="S",
                   help="wait up to S seconds for a subscriber on every replayed topic before "
                        "the first message (default: %(default)g)")
    p.add_argument("--requests", action="store_true",
                   help="re-send the recorded plan requests to a running node and compare "
                        "(to reproduce the recorded answers: a freshly started node with the "
                        "recording's parameters; the planner keeps its atlas between requests)")
    p.add_argument("--node", help="node for --requests (default: the recorded one)")
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
    from ..ros import replay as R
    for name in ("rate", "timeout", "tolerance", "delay"):
        value = getattr(args, name)
        low_ok = value >= 0 if name in ("tolerance", "delay") else value > 0
        if not (math.isfinite(value) and low_ok):
            raise InputError(f"--{name}", value, "must be a positive finite number")
    records = R.read_records(args.run)
    counts = Counter(r.topic for r in records)
    span = (records[-1].log_time_ns - records[0].log_time_ns) * 1e-9 if records else 0.0
    print(f"{args.run}: {len(records)} messages on {len(counts)} topics over {span:.3f} s")
    for topic, n in sorted(counts.items()):
        print(f"  {topic}: {n}")
    if args.requests:
        return replay_requests(args, records)
    return replay_topics(args, records)


def replay_topics(args, records):
    import rclpy
    from rclpy.node import Node

    from ..ros import replay as R
    chosen = R.select_topics(records, args.topics)
    context = rclpy.Context()
    rclpy.init(args=["cdh-planner-replay", "--ros-args", *args.ros_args], context=context)
    try:
        node = Node("cdh_planner_replay", context=context)
        stats = R.replay_topics(node, chosen, rate=args.rate, delay_s=args.delay)
        print(f"republished {stats.messages} messages on {stats.topics} topics in "
              f"{stats.replay_s:.3f} s (recorded span {stats.recorded_s:.3f} s, rate "
              f"{args.rate:g}; latest {1e3 * stats.late_s:.1f} ms behind schedule)")
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    return EXIT_OK


def replay_requests(args, records):
    from ..ros import replay as R
    from ..ros.client import ClientError, PlannerClient
    plans = R.recorded_plans(records)
    if not plans:
        print("no recorded plan requests in this file")
        return EXIT_OK
    node = args.node or plans[0].service.rsplit("/", 1)[0]
    differs = 0
    with PlannerClient(node, args=["cdh-planner-replay", "--ros-args", *args.ros_args]) \
            as client:
        try:
            client.wait_for_node(min(args.timeout, 30.0))
            for plan in plans:
                answer = client.plan(plan.request.start, plan.request.goal, args.timeout,
                                     tolerance=plan.request.tolerance)
                if plan.response is None:
                    print(f"request {plan.sequence}: no recorded response (run ended); now "
                          f"{len(answer.path.poses)} poses")
                    continue
                ok, text = R.compare_paths(plan.response.plan, answer.path, args.tolerance,
                                           args.tolerance)
                differs += not ok
                why = "" if answer.success else f" ({answer.values.get('error_msg', '')})"
                print(f"request {plan.sequence}: {'MATCHES' if ok else 'DIFFERS'}: {text}{why}")
        except ClientError as exc:
            print(f"cdh-planner replay: error: {exc}", file=sys.stderr)
            return EXIT_NO_NODE
    print(f"{len(plans) - differs} of {len(plans)} answers match the recording")
    return EXIT_DIFFERS if differs else EXIT_OK
