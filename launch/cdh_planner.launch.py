"""Start the cdh_planner node with a robot file.

    ros2 launch cdh_planner cdh_planner.launch.py [robot:=/path/to/robot.yaml]
        [execution_mode:=stream|follow_joint_trajectory]

``robot``: the robot file, a ROS 2 parameters file whose ``cdh_planner: ros__parameters:``
hold the robot, its task and the planner settings (default: the installed
``config/robot2.yaml``, the paper's Robot 2). ``execution_mode``: the node's
``execution.mode`` (stream: JointState setpoints on ~/cable_command; follow_joint_trajectory:
a ros2_control controller's FollowJointTrajectory action). The node runs as ``cdh-planner
node --ros-args --params-file <robot> -p execution.mode:=<mode>``, as started by hand.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def generate_launch_description():
    robot = DeclareLaunchArgument(
        "robot",
        default_value=PathJoinSubstitution([FindPackageShare("cdh_planner"), "config",
                                            "robot2.yaml"]),
        description="robot file: a ROS 2 parameters file for node cdh_planner (robot, task, "
                    "planner settings)")
    mode = DeclareLaunchArgument(
        "execution_mode", default_value="stream",
        choices=["stream", "follow_joint_trajectory"],
        description="how ~/execute moves the winches: stream (setpoints on ~/cable_command) or "
                    "follow_joint_trajectory (a ros2_control controller's action)")
    node = Node(
        package="cdh_planner",
        executable="cdh-planner",
        arguments=["node"],
        parameters=[LaunchConfiguration("robot"),
                    {"execution.mode": LaunchConfiguration("execution_mode")}],
        output="screen",
        emulate_tty=True,
    )
    return LaunchDescription([robot, mode, node])
