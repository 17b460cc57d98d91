"""Start the cdh_planner node with a robot file.

    ros2 launch cdh_planner cdh_planner.launch.py [robot:=/path/to/robot.yaml]
        [execution_mode:=stream|forward_command|follow_joint_trajectory|...]
        [namespace:=NS] [use_sim_time:=false|true] [log_level:=info]

``robot``: the robot file, a ROS 2 parameters file whose ``cdh_planner: ros__parameters:``
hold the robot, its task and the planner settings (default: the installed
``config/robot2.yaml``, the paper's Robot 2). ``execution_mode``: the node's
``execution.mode``, one of the registered command outlets (its choices and description
come from ``cdh_planner/ros/execution/command_outlets.py``, so a new one needs no change here).
``namespace``: the node's namespace (its topics,
services and action follow it; /tf, /tf_static and /diagnostics stay absolute).
``use_sim_time``: the node's clock from /clock. ``log_level``: rcl's (debug, info, warn,
error, fatal). The node runs as ``cdh-planner node --ros-args --params-file <robot>
-p execution.mode:=<mode> ...``, as started by hand.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

from cdh_planner.ros.execution.command_outlets import OUTLETS, modes_description


def generate_launch_description():
    robot = DeclareLaunchArgument(
        "robot",
        default_value=PathJoinSubstitution([FindPackageShare("cdh_planner"), "config",
                                            "robot2.yaml"]),
        description="robot file: a ROS 2 parameters file for node cdh_planner (robot, task, "
                    "planner settings)")
    mode = DeclareLaunchArgument(
        "execution_mode", default_value="stream",
        choices=list(OUTLETS), description=modes_description())
    namespace = DeclareLaunchArgument("namespace", default_value="",
                                      description="the node's namespace")
    sim_time = DeclareLaunchArgument("use_sim_time", default_value="false",
                                     choices=["true", "false"],
                                     description="use the /clock topic's time")
    log_level = DeclareLaunchArgument(
        "log_level", default_value="info", choices=["debug", "info", "warn", "error", "fatal"],
        description="the node's log level")
    node = Node(
        package="cdh_planner",
        executable="cdh-planner",
        arguments=["node"],
        namespace=LaunchConfiguration("namespace"),
        parameters=[LaunchConfiguration("robot"),
                    {"execution.mode": LaunchConfiguration("execution_mode"),
                     "use_sim_time": LaunchConfiguration("use_sim_time")}],
        ros_arguments=["--log-level", LaunchConfiguration("log_level")],
        output="screen",
        emulate_tty=True,
    )
    return LaunchDescription([robot, mode, namespace, sim_time, log_level, node])
