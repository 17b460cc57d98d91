"""TEST DOUBLE: the simulated cable controller (cdh_planner/ros/execution/simulated_controller.py), a
FollowJointTrajectory server that checks what the Jazzy JointTrajectoryController checks
before accepting a goal and publishes the joints' JointState. It is NOT a controller; the
tests use it in place of one (test/test_execution.py, test/test_ros_execution.py).

    python follow_joint_trajectory_server.py JOINT [JOINT ...] [options of simulated_controller]
"""

import sys

from cdh_planner.ros.execution.simulated_controller import main

if __name__ == "__main__":
    sys.exit(main())
