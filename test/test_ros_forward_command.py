"""``execution.mode: forward_command``: the node streams std_msgs/Float64MultiArray to a
ros2_control JointGroupPositionController's ``~/commands``, in the controller's joint order
(``execution.joint_order``, checked against the robot's winch names). Over DDS against the
simulated controller with ``--commands`` (cdh_planner/ros/execution/simulated_controller.py, through
test/doubles/follow_joint_trajectory_server.py), which applies a command only when the
real controller would (data size = number of joints; finite) and publishes the joints'
JointState. The node around the TEST DOUBLE planner: these tests are about execution.
Also: without a measured start, ``~/execute`` is refused unless
``execution.allow_unchecked_start``.
"""

import numpy as np
import pytest
from std_srvs.srv import Trigger

from cdh_planner.errors import InputError
from cdh_planner.ros.msgs import messages as M
from cdh_planner.ros.client import PlannerClient
from cdh_planner.ros.core.params import node_config
from cdh_planner.ros.execution.command_outlets import forward_command
from ros_harness import (Q1, Q2, ROBOT2, ControllerDouble, NodeProcess, claimed_domain,
                         file_parameters, in_process_nodes, sphere_pose_msg, wait_node_measures)
from test_ros_execution import _lengths

ROBOT = node_config(file_parameters(ROBOT2)).robot
ORDER = list(reversed(ROBOT.winch_names))        # the controller's joints, not the robot's order
TOPIC = "/cable_controller/commands"
JOINT_STATES = "/winches/joint_states"


def _yaml_list(names):
    return "[" + ", ".join(names) + "]"


def test_forward_command_drives_a_joint_group_position_controller(tmp_path):
    start = dict(zip(ROBOT.winch_names, _lengths(Q1).tolist()))
    params = ["execution.mode:=forward_command", f"execution.joint_order:={_yaml_list(ORDER)}",
              f"execution.joint_states_topic:={JOINT_STATES}",
              "execution.allow_unchecked_start:=false"]
    with claimed_domain() as domain, \
            ControllerDouble(domain, *ORDER, "--commands", TOPIC, "--joint-states", JOINT_STATES,
                             "--kinematic", "--initial", *[repr(start[n]) for n in ORDER]) as double, \
            NodeProcess(domain, tmp_path, params=params, fake=True) as node, \
            PlannerClient(domain_id=domain) as client:
        assert double.ready.wait(30.0), "\n".join(double.lines)
        client.wait_for_node(30.0)
        client.watch_execution()
        assert wait_node_measures(client, sphere_pose_msg(Q1)).success
        answer = client.plan(sphere_pose_msg(Q1), sphere_pose_msg(Q2), timeout_s=30)
        assert answer.path.poses
        ok, message = client.execute()
        assert ok and TOPIC in message and "not checked" not in message, message
        status = client.wait_execution_result(0, timeout_s=30.0)
        assert status is not None and M.status_values(status) == {
            "outcome": "completed", "mode": "forward_command"}, node.log()
        goal = client.trajectories[-1].points[-1].positions      # robot order
        expected = [goal[ROBOT.winch_names.index(n)] for n in ORDER]

        def last_is_the_goal():  # the result can come before the last commands are read
            commands = double.events("command")
            return bool(commands) and np.allclose(commands[-1]["data"], expected, rtol=0,
                                                  atol=1e-12)

        assert client.spin_until(last_is_the_goal, 30.0), (
            f"last command {double.events('command')[-1:]}, the goal {expected}")
        assert double.events("command_rejected") == []
        commands = double.events("command")
        # a stream, not one jump (116 commands at 50 Hz alone; a starved timer sends fewer,
        # each sampled at its own time: 10 in a loaded full run)
        assert len(commands) >= 3
        first = [start[n] for n in ORDER]      # sampled a few ms after the start
        np.testing.assert_allclose(commands[0]["data"], first, rtol=0, atol=1e-4)
    # the recorded commands move the robot: replay leaves them out unless asked
    from cdh_planner.ros import replay as R
    [run] = node.run_files()
    records = R.read_records(run)
    assert TOPIC not in {r.topic for r in R.select_topics(records)}
    assert TOPIC in {r.topic for r in R.select_topics(records, commands=True)}


def test_forward_command_reorders_by_name():
    from sensor_msgs.msg import JointState
    js = JointState(name=["a", "b", "c"], position=[1.0, 2.0, 3.0])
    assert list(forward_command(js, ["c", "a", "b"]).data) == [3.0, 1.0, 2.0]


@pytest.mark.parametrize("order, words", [
    (["winch_1"], "missing winch_2, winch_3"),
    (list(ROBOT.winch_names[:5]) + ["winch_1"], "missing winch_6; twice winch_1"),
    (list(ROBOT.winch_names[:5]) + ["elbow"], "missing winch_6; not a winch elbow"),
])
def test_a_joint_order_that_is_not_the_winches_is_refused_naming_it(tmp_path, order, words):
    with in_process_nodes(tmp_path) as make:
        with pytest.raises(InputError, match="execution.joint_order") as err:
            make(params=[f"execution.joint_order:={_yaml_list(order)}"])
        assert words in str(err.value)
        node = make()
        result = node._on_set_parameters([_param("execution.joint_order", order)])
        assert not result.successful and "execution.joint_order" in result.reason


def _param(name, value):
    from rclpy.parameter import Parameter
    return Parameter(name, value=value)


def test_execute_without_a_measured_start_is_refused_unless_allowed(tmp_path):
    from nav_msgs.srv import GetPlan
    with in_process_nodes(tmp_path) as make:
        node = make(params=["execution.allow_unchecked_start:=false"])
        request = GetPlan.Request(start=sphere_pose_msg(Q1), goal=sphere_pose_msg(Q2))
        assert node._plan(request, GetPlan.Response()).plan.poses
        r = node._execute(Trigger.Request(), Trigger.Response())
        assert not r.success and "start is not measured" in r.message, r.message
        assert "execution.allow_unchecked_start" in r.message
        assert node._on_set_parameters([_param("execution.allow_unchecked_start", True)]).successful
        r = node._execute(Trigger.Request(), Trigger.Response())
        assert r.success and "start not checked" in r.message, r.message
