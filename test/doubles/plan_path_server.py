"""TEST DOUBLE: a PlanPath action server that plans nothing. It only exercises the generated
cdh_planner_interfaces types over real DDS (test/test_ros_interfaces.py); it is NOT the node.

    python plan_path_server.py        # serves /plan_path_double/plan_path until SIGINT/SIGTERM
                                      # (rclpy's own signal handlers end the spin)

A goal "plans" for ``goal.timeout_s`` seconds, sending feedback every PERIOD_S (charts = the
feedback count, time_s, best_h counting down), then succeeds with a result whose path,
cable trajectory and tension envelope have WAYPOINTS waypoints, derived from the goal (the
path's first and last poses are the goal's start and goal). A goal with an unknown strategy
is aborted with INVALID_PLANNER. A cancel is accepted and takes effect within PERIOD_S:
the result then has error_code CANCELED. Prints "ready" once the server exists.
"""

import sys
import time

import rclpy
from builtin_interfaces.msg import Duration
from geometry_msgs.msg import PoseStamped
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from trajectory_msgs.msg import JointTrajectoryPoint

from cdh_planner_interfaces.action import PlanPath
from cdh_planner_interfaces.msg import TensionEnvelopePoint

from cdh_planner.ros.interface import ACTION_QOS

NODE = "plan_path_double"
PERIOD_S = 0.02
WAYPOINTS = 3
WINCHES = [f"winch_{i + 1}" for i in range(6)]
STRATEGIES = ("", "auto", "astar", "gbf")


def duration(seconds):
    ns = int(round(seconds * 1e9))
    return Duration(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def result_for(goal, planning_time_s, charts):
    r = PlanPath.Result(error_code=PlanPath.Result.NONE, error_msg="",
                        planning_time_s=planning_time_s, charts=charts, min_margin=0.25)
    frame = goal.goal.header.frame_id
    r.path.header.frame_id = frame
    r.path.poses = [goal.start, PoseStamped(header=goal.goal.header), goal.goal]
    r.cable_trajectory.joint_names = WINCHES
    r.tension_envelope.header.frame_id = frame
    r.tension_envelope.winch_names = WINCHES
    for k in range(WAYPOINTS):
        t = duration(0.5 * k)
        r.cable_trajectory.points.append(JointTrajectoryPoint(
            positions=[0.5 + 0.01 * k + 0.001 * i for i in range(6)], time_from_start=t))
        r.tension_envelope.points.append(TensionEnvelopePoint(
            time_from_start=t,
            tension_min=[10.0 * k + i for i in range(6)],
            tension_nominal=[10.0 * k + i + 0.5 for i in range(6)],
            tension_max=[10.0 * k + i + 1.0 for i in range(6)]))
    return r


def execute(goal_handle):
    goal = goal_handle.request
    t0 = time.monotonic()
    if goal.strategy not in STRATEGIES:
        goal_handle.abort()
        return PlanPath.Result(error_code=PlanPath.Result.INVALID_PLANNER,
                               error_msg=f"unknown strategy {goal.strategy!r}")
    charts = 0
    while (elapsed := time.monotonic() - t0) < goal.timeout_s:
        if goal_handle.is_cancel_requested:
            goal_handle.canceled()
            return PlanPath.Result(error_code=PlanPath.Result.CANCELED, error_msg="canceled",
                                   planning_time_s=elapsed, charts=charts)
        charts += 1
        goal_handle.publish_feedback(PlanPath.Feedback(
            charts=charts, time_s=elapsed, best_h=max(goal.timeout_s - elapsed, 0.0)))
        time.sleep(PERIOD_S)
    goal_handle.succeed()
    return result_for(goal, time.monotonic() - t0, charts)


def main():
    rclpy.init()
    node = rclpy.create_node(NODE)
    ActionServer(node, PlanPath, f"/{NODE}/plan_path", execute_callback=execute,
                 goal_callback=lambda goal: GoalResponse.ACCEPT,
                 cancel_callback=lambda handle: CancelResponse.ACCEPT,
                 callback_group=ReentrantCallbackGroup(), **ACTION_QOS)
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    print("ready", flush=True)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception as e:   # rclpy's RCLError when SIGINT interrupts the executor's wait
        if type(e).__name__ != "RCLError":
            raise
    finally:
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
