"""How fast a cancel of a ~/plan_path goal ends it, over real DDS.

    python benchmarks/plan_path_cancel.py [--runs N]

Starts ``cdh-planner node`` on Robot 2 (config/robot2.yaml) with a small chart radius
(planner.radius 0.02, A*: q2 -> q3 is a ~5 s search) in a ROS domain of its own, sends the
goal q2 -> q3 N times, cancels each one after a random 0.3 to 2 s of planning, and prints
the s from the cancel request to the CANCELED result (client side), then one last goal
planned to the end (GBF) to show the node still plans.
"""

import argparse
import contextlib
import random
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
Q2, Q3 = (0.55, 0.75), (2.63, 0.75)


def sphere_pose(task, coords):
    from cdh_planner.model.pose import quaternion_from_tau
    from cdh_planner.ros.client import pose_stamped
    p, tau = task.pose(np.array([coords]))
    return pose_stamped(list(p[0]) + list(quaternion_from_tau(tau)[0]), "cdh_base")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=10)
    args = ap.parse_args()
    from action_msgs.msg import GoalStatus

    from cdh_planner.commands.slice import task_in_yaml
    from cdh_planner.ros.client import PlannerClient, plan_path_goal
    from cdh_planner.ros.isolation import claimed_domain, isolated_env, stop_process
    robot_file = ROOT / "config" / "robot2.yaml"
    task = task_in_yaml(robot_file)
    start, goal = sphere_pose(task, Q2), sphere_pose(task, Q3)
    with claimed_domain() as domain, contextlib.ExitStack() as stack:
        node = subprocess.Popen(
            [sys.executable, "-m", "cdh_planner.cli", "node", "--ros-args", "--params-file",
             str(robot_file), "-p", "log_enabled:=false", "-p", "planner.radius:=0.02",
             "-p", "planner.strategy:=astar"], env=isolated_env(domain),
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        stack.callback(stop_process, node)
        client = stack.enter_context(PlannerClient(domain_id=domain))
        client.wait_for_node(60.0)
        rng = random.Random(1)
        latencies = []
        for _ in range(args.runs):
            answer = client.plan_path(plan_path_goal(start, goal), timeout_s=60,
                                      cancel_after_s=rng.uniform(0.3, 2.0))
            if answer.goal_status != GoalStatus.STATUS_CANCELED:
                # the node keeps its atlas: a later search may end before the cancel time
                print(f"finished before the cancel ({answer.seconds:.2f} s): "
                      f"{answer.result.error_msg or 'planned'}")
                continue
            latencies.append(answer.cancel_s)
        ms = np.array(latencies) * 1e3
        print(f"{len(ms)} of {args.runs} goals CANCELED; cancel request -> result: median "
              f"{np.median(ms):.1f} ms, max {ms.max():.1f} ms")
        t0 = time.perf_counter()
        after = client.plan_path(plan_path_goal(start, goal, strategy="gbf"), timeout_s=60)
        print(f"next goal (gbf): {'planned' if after.success else after.result.error_msg}, "
              f"{len(after.path.poses)} waypoints, {after.result.charts} charts, "
              f"{time.perf_counter() - t0:.2f} s")


if __name__ == "__main__":
    main()
