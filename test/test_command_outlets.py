"""Command outlets are plug-ins: one registered class (ros/execution/command_outlets.py) is an
``execution.mode`` everywhere (the mode parameter's choices and description, its own
parameters, the docs' table) and the node executes a plan through it over DDS."""

import re

import numpy as np
import pytest

from cdh_planner.errors import InputError
from cdh_planner.ros.core import params
from cdh_planner.ros.execution.command_outlets import (OUTLETS, FollowJointTrajectory, ForwardCommand,
                                             JointStateStream, StreamedOutlet,
                                             check_joint_order, register)
from cdh_planner.fields import TEXT
from cdh_planner.ros.core.param_spec import Spec

TOPIC = "/winches/lengths_velocities"
JOINT_ORDER = ForwardCommand.specs[1]      # execution.joint_order, shared as declared


class LengthsAndVelocities(StreamedOutlet):
    """The test's new winch command, all of it: std_msgs/Float64MultiArray of the cable
    lengths (m) then the cable velocities (m/s), in execution.joint_order."""

    name = "lengths_velocities"
    description = ("std_msgs/Float64MultiArray cable lengths then velocities on "
                   "execution.lengths_velocities_topic at stream_rate_hz")
    specs = (Spec("execution.lengths_velocities_topic", TEXT, TOPIC,
                  "lengths_velocities mode: its topic (set at start)", start_only=True),
             JOINT_ORDER)

    @classmethod
    def check(cls, values, robot):
        check_joint_order(values["execution.joint_order"], robot.winch_names)

    def make_publisher(self, context, values):
        from std_msgs.msg import Float64MultiArray
        return context.node.create_publisher(
            Float64MultiArray, values["execution.lengths_velocities_topic"], 10)

    def configure(self, config):
        self.order = check_joint_order(config.values["execution.joint_order"],
                                       config.robot.winch_names)

    def message(self, joint_state):
        from std_msgs.msg import Float64MultiArray
        k = [list(joint_state.name).index(n) for n in self.order]
        return Float64MultiArray(data=[float(joint_state.position[i]) for i in k]
                                 + [float(joint_state.velocity[i]) for i in k])


@pytest.fixture
def registered():
    register(LengthsAndVelocities)
    yield
    del OUTLETS[LengthsAndVelocities.name]


def test_a_new_outlet_is_one_class_and_a_mode_everywhere(registered):
    mode = params.SPEC["execution.mode"]
    assert "lengths_velocities" in mode.choices
    assert params.check_value(mode, "lengths_velocities") == "lengths_velocities"
    assert "lengths_velocities (std_msgs/Float64MultiArray cable lengths then velocities" \
        in mode.description
    # its parameter: declared, start-only (read-only, a ROS name), with its default
    spec = params.SPEC["execution.lengths_velocities_topic"]
    assert spec.default == TOPIC and spec in params.SPECS
    assert spec.name in params.START_ONLY and spec.name in params.READ_ONLY
    with pytest.raises(InputError, match="execution.lengths_velocities_topic"):
        params.check_value(spec, "/1bad")
    # the shared execution.joint_order is one parameter
    assert [s.name for s in params.SPECS].count("execution.joint_order") == 1
    # the docs' table
    rows = params.parameters_markdown().splitlines()
    row = next(r for r in rows if r.startswith("| `execution.mode` |"))
    assert "| stream, forward_command, follow_joint_trajectory, lengths_velocities |" in row
    assert any(r.startswith("| `execution.lengths_velocities_topic` | string | "
                            f"`{TOPIC}` |") for r in rows)


def test_unregistered_it_is_no_mode():
    assert list(OUTLETS) == ["stream", "forward_command", "follow_joint_trajectory"]
    assert (JointStateStream.streamed, ForwardCommand.streamed,
            FollowJointTrajectory.streamed) == (True, True, False)
    with pytest.raises(InputError, match="execution.mode = 'lengths_velocities': expected one "
                                         "of stream, forward_command, follow_joint_trajectory"):
        params.check_value(params.SPEC["execution.mode"], "lengths_velocities")
    assert "execution.lengths_velocities_topic" not in params.SPEC
    assert "lengths_velocities" not in params.parameters_markdown()


def test_register_refuses_what_would_be_ambiguous():
    class Undescribed(LengthsAndVelocities):
        name, description = "undescribed", ""

    class OtherStream(LengthsAndVelocities):
        name = "stream"

    class OtherOrder(LengthsAndVelocities):
        name = "other_order"
        specs = (Spec("execution.joint_order", TEXT, "", "another order"),)

    def declaring(name):
        return type("Declaring", (LengthsAndVelocities,), {
            "name": "declaring", "specs": (Spec(name, TEXT, "/x", "a topic"),)})

    for cls, match in ((Undescribed, "description must be"),
                       (OtherStream, "'stream' is already registered"),
                       (OtherOrder, "execution.joint_order is declared otherwise by mode "
                                    "'forward_command'"),
                       (declaring("lengths_topic"), "lengths_topic is not execution.<name>"),
                       (declaring("execution.mode"), "execution.mode is the node's own"),
                       (declaring("execution.joint_states_topic"), "is the node's own")):
        with pytest.raises(ValueError, match=match):
            register(cls)
    assert list(OUTLETS) == ["stream", "forward_command", "follow_joint_trajectory"]
    assert register(ForwardCommand) is ForwardCommand   # registering again is harmless


# ----------------------------------------------------------------- the node, over DDS

def test_the_node_executes_a_plan_through_it(tmp_path, registered):
    """An in-process node (TEST DOUBLE planner) in execution.mode lengths_velocities, and a
    subscriber of the same ROS domain: ~/execute streams the plan on the new topic, in
    execution.joint_order, and completes; the last command is the trajectory's last point
    at rest."""
    pytest.importorskip("nav_msgs")
    import rclpy
    from nav_msgs.srv import GetPlan
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import Float64MultiArray
    from std_srvs.srv import Trigger
    from cdh_planner.ros.msgs import messages as M
    from ros_harness import Q1, Q2, in_process_nodes, sphere_pose_msg, until
    with in_process_nodes(tmp_path / "runs") as make:
        node = make()
        winches = list(node.config.robot.winch_names)
        order = winches[::-1]     # the command's order, not the robot's
        node = make(params=["execution.mode:=lengths_velocities",
                            f"execution.joint_order:=[{', '.join(order)}]"])
        results, commands = [], []
        real = node.pub_execution.publish
        node.pub_execution.publish = lambda msg: (results.append(msg), real(msg))
        listener = rclpy.create_node("outlet_listener", context=node.context)
        listener.create_subscription(Float64MultiArray, TOPIC, commands.append, 1000)
        executor = SingleThreadedExecutor(context=node.context)
        for n in (node, listener):
            executor.add_node(n)

        def spin_until(condition):
            return until(lambda: executor.spin_once(timeout_sec=0.01) or condition(), 30.0)

        try:
            outlet = node.execution.outlets["lengths_velocities"]
            assert spin_until(lambda: outlet.publisher.get_subscription_count() > 0)
            request = GetPlan.Request(start=sphere_pose_msg(Q1), goal=sphere_pose_msg(Q2))
            assert node._plan(request, GetPlan.Response()).plan.poses
            answer = node._execute(Trigger.Request(), Trigger.Response())
            assert answer.success and TOPIC in answer.message, answer.message
            assert spin_until(lambda: results), "no execution result"
            assert M.status_values(results[0]) == {"outcome": "completed",
                                                   "mode": "lengths_velocities"}
            sent = int(re.search(r"finished: (\d+) commands", results[0].message).group(1))
            assert sent > 10 and spin_until(lambda: len(commands) == sent), (sent, len(commands))
        finally:
            executor.shutdown()
            listener.destroy_node()
        trajectory = node.plans.with_last(lambda p: p)[2].cable_trajectory
        last = list(trajectory.points[-1].positions)                   # robot order
        data = np.array([c.data for c in commands])
        assert data.shape[1] == 2 * len(winches)
        np.testing.assert_allclose(data[-1, :6], [last[winches.index(n)] for n in order],
                                   rtol=0, atol=1e-12)
        np.testing.assert_array_equal(data[-1, 6:], 0.0)     # the end: at rest
        assert np.any(np.abs(data[:-1, 6:]) > 1e-6)          # moving on the way


def test_a_mode_registered_after_configure_ends_its_run_failed(tmp_path):
    """Its outlet was not made at configure: ~/execute is refused with why, the run ends
    (one result, failed) and the node executes again."""
    pytest.importorskip("nav_msgs")
    from nav_msgs.srv import GetPlan
    from rclpy.parameter import Parameter
    from std_srvs.srv import Trigger
    from ros_harness import Q1, Q2, in_process_nodes, sphere_pose_msg
    with in_process_nodes(tmp_path / "runs") as make:
        node = make()
        request = GetPlan.Request(start=sphere_pose_msg(Q1), goal=sphere_pose_msg(Q2))
        assert node._plan(request, GetPlan.Response()).plan.poses
        register(LengthsAndVelocities)
        try:
            assert node.set_parameters([Parameter("execution.mode",
                                                  value="lengths_velocities")])[0].successful
            answer = node._execute(Trigger.Request(), Trigger.Response())
            assert not answer.success and "configure it again" in answer.message, answer.message
            assert not node.execution.running
        finally:
            del OUTLETS[LengthsAndVelocities.name]
        node.set_parameters([Parameter("execution.mode", value="stream")])
        answer = node._execute(Trigger.Request(), Trigger.Response())
        assert answer.success, answer.message
        node._stop(Trigger.Request(), Trigger.Response())


def test_replay_keeps_a_streamed_outlets_recorded_commands_off_unless_asked(registered):
    """The topic a recorded parameter names for a streamed outlet (the new one's included)
    is a command topic of the run file, resolved as the node resolved it."""
    pytest.importorskip("rcl_interfaces")
    from rcl_interfaces.msg import Parameter, ParameterEvent, ParameterValue
    from rclpy.serialization import serialize_message
    from cdh_planner.ros import replay as R

    def record(topic, type_name="std_msgs/msg/Float64MultiArray", data=b""):
        return R.Record(topic, type_name, data, 0, False)

    def setting(name, value):
        return Parameter(name=name, value=ParameterValue(type=4, string_value=value))

    event = ParameterEvent(node="/ns/cdh_planner", new_parameters=[
        setting("execution.forward_command_topic", "/cable_controller/commands"),
        setting("execution.lengths_velocities_topic", "~/lengths_velocities"),
        setting("log_dir", "/ns/cdh_planner/path")])
    records = [record(R.PARAMETER_EVENTS, "rcl_interfaces/msg/ParameterEvent",
                      serialize_message(event)),
               record("/cable_controller/commands"), record("/ns/cdh_planner/lengths_velocities"),
               record("/ns/cdh_planner/cable_command", "sensor_msgs/msg/JointState"),
               record("/ns/cdh_planner/path", "nav_msgs/msg/Path")]
    assert R.command_topics(records) == {"/cable_controller/commands",
                                         "/ns/cdh_planner/lengths_velocities",
                                         "/ns/cdh_planner/cable_command"}
    assert {r.topic for r in R.select_topics(records)} == {"/ns/cdh_planner/path"}
    with pytest.raises(InputError, match="a command topic"):
        R.select_topics(records, ["/ns/cdh_planner/lengths_velocities"])
