"""``cdh-planner node``: run the ROS 2 planner node (``cdh_planner.ros.node.planner_node``).

    cdh-planner node --ros-args --params-file config/robot2.yaml [-p name:=value ...]

Everything after ``--ros-args`` goes to rclpy unchanged (parameters, remapping, log level).
Stops cleanly on SIGINT / SIGTERM, closing the run's MCAP file.
"""

ORDER = 60  # its place in `cdh-planner --help`
SUMMARY = "run the ROS 2 planner node"

import argparse
import sys


def add_parser(subparsers):
    p = subparsers.add_parser(
        "node", help=SUMMARY,
        description="Run the ROS 2 node cdh_planner: action ~/plan_path "
                    "(cdh_planner_interfaces/PlanPath); services ~/plan (nav_msgs/GetPlan), "
                    "~/execute and ~/stop (std_srvs/Trigger); topics ~/path, "
                    "~/planned_cable_trajectory, ~/tension_envelope, ~/markers, "
                    "~/plan_result, ~/execution_result, ~/plan_progress, ~/cable_command; "
                    "subscribes to /joint_states. Parameters: the robot file and the names in "
                    "cdh_planner/ros/core/params.py (docs/ros-node.md).",
        epilog="example:\n  cdh-planner node --ros-args --params-file config/robot2.yaml "
               "-p log_dir:=/tmp/runs -p planner.strategy:=gbf",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--ros-args", dest="ros_args", nargs=argparse.REMAINDER, default=[],
                   metavar="ARGS", help="ROS arguments for rclpy (--params-file FILE, "
                                        "-p name:=value, -r from:=to, --log-level ...)")
    p.set_defaults(func=run)


def run(args):
    from ..ros.node.main import main
    return main(args.ros_args, log=lambda line: print(line, file=sys.stderr))
