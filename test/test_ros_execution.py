"""Execution through ros2_control, over real DDS: the node (real planner) in
``execution.mode:=follow_joint_trajectory`` sends its plans to a FollowJointTrajectory test
double that checks what the Jazzy JointTrajectoryController checks
(test/doubles/follow_joint_trajectory_server.py) and publishes the winches' JointState. The
node checks the measured start before executing, plans from the measured pose
(``use_current_start``), and reports how each execution ended on ``~/execution_result``."""

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticStatus  # noqa: E402
from nav_msgs.srv import GetPlan  # noqa: E402, F401 (the plan service's type)
from sensor_msgs.msg import JointState  # noqa: E402

from cdh_planner.model.kinematics import cable_lengths  # noqa: E402
from cdh_planner.model.pose import rotation_from_quaternion  # noqa: E402
from cdh_planner.ros import messages as M  # noqa: E402
from cdh_planner.ros.client import PlannerClient, path_duration, plan_path_goal  # noqa: E402
from cdh_planner.ros.params import node_config  # noqa: E402
from ros_harness import (Q1, Q2, Q3, ROBOT2, Collector, ControllerDouble,  # noqa: E402
                         NodeProcess, claimed_domain, file_parameters, pose_text, run_cli,
                         sphere_pose_msg, wait_node_measures)

CONFIG = node_config(file_parameters(ROBOT2))
ROBOT = CONFIG.robot
ACTION = "/cable_controller/follow_joint_trajectory"
JOINT_STATES = "/winches/joint_states"
TIME_SCALE = 4.0   # the double runs 4x faster than real time


def _lengths(coords):
    msg = sphere_pose_msg(coords)
    p, o = msg.pose.position, msg.pose.orientation
    R = rotation_from_quaternion(np.array([o.x, o.y, o.z, o.w]))
    return cable_lengths(ROBOT, np.array([p.x, p.y, p.z]), R)


@pytest.fixture(scope="module")
def ros(tmp_path_factory):
    params = ["execution.mode:=follow_joint_trajectory",
              f"execution.controller_action:={ACTION}",
              f"execution.joint_states_topic:={JOINT_STATES}"]
    with claimed_domain() as domain:
        double = ControllerDouble(domain, *ROBOT.winch_names, "--action", ACTION,
                                  "--joint-states", JOINT_STATES, "--time-scale", TIME_SCALE,
                                  "--initial", *map(repr, _lengths(Q1).tolist()))
        node = NodeProcess(domain, tmp_path_factory.mktemp("execution"), params=params)
        try:
            assert double.ready.wait(30.0), "\n".join(double.lines)
            with PlannerClient(domain_id=domain) as client:
                client.wait_for_node(30.0)
                client.double, client.process, client.domain = double, node, domain
                client.measured = Collector(client.node, JointState, JOINT_STATES, 10)
                client.watch_execution()
                assert client.spin_until(lambda: client.measured.items, 10.0)
                answer = wait_node_measures(client, sphere_pose_msg(Q1))
                assert answer.success, answer.result.error_msg
                yield client
        finally:
            node.stop()
            rc, log = double.stop()
            assert rc == 0 and "Traceback" not in log, log


def _measured(ros):
    msg = ros.measured.messages[-1]
    return np.array([msg.position[list(msg.name).index(n)] for n in ROBOT.winch_names])


def _execute_to_the_end(ros, result):
    """Execute the last plan; (execute's message, how it ended: DiagnosticStatus)."""
    seen = len(ros.execution_results)
    accepted = len(ros.double.events("accepted"))
    ok, message = ros.execute()
    assert ok, message
    assert ACTION in message and "start not checked" not in message, message
    status = ros.wait_execution_result(seen, timeout_s=30.0)
    assert status is not None, ros.process.log()
    [event] = ros.double.events("accepted")[accepted:]
    assert event["joint_names"] == list(ROBOT.winch_names)
    assert event["has_effort"] is False and event["points"] == len(result.cable_trajectory.points)
    return message, status


def test_a_plan_executes_through_the_controller_and_ends_completed(ros):
    answer = ros.plan_path(plan_path_goal(sphere_pose_msg(Q1), sphere_pose_msg(Q2)),
                           timeout_s=60)
    assert answer.success, answer.result.error_msg
    _, status = _execute_to_the_end(ros, answer.result)
    assert status.level == DiagnosticStatus.OK, status.message
    assert M.status_values(status) == {"outcome": "completed",
                                       "mode": "follow_joint_trajectory"}
    # the double publishes the goal's end state before its result: wait for it to arrive
    last = answer.result.cable_trajectory.points[-1].positions
    assert ros.spin_until(lambda: np.allclose(_measured(ros), last, rtol=0, atol=1e-6), 10.0), \
        (_measured(ros), last)                                       # the winches are at q2


def test_execute_refuses_when_the_winches_are_not_at_the_start(ros):
    """The winches are at q2 now; a plan from q1 is refused, naming the distance."""
    answer = ros.plan(sphere_pose_msg(Q1), sphere_pose_msg(Q3), timeout_s=60)
    assert answer.success
    accepted = len(ros.double.events("accepted"))
    ok, message = ros.execute()
    assert not ok and message.startswith("refused:"), message
    gap = float(np.max(np.abs(_measured(ros) - _lengths(Q1))))
    assert f"{gap:.4g}" in message or f"{gap:.3g}" in message, (gap, message)
    assert any(name in message for name in ROBOT.winch_names), message
    # nothing was sent, shown by a later goal rather than by a quiet while: a plan that
    # stays at q2 executed after the refusal is the only goal the controller accepted since
    stay = ros.plan_path(plan_path_goal(None, sphere_pose_msg(Q2), use_current_start=True),
                         timeout_s=60)
    assert stay.success, stay.result.error_msg
    _, status = _execute_to_the_end(ros, stay.result)
    assert M.status_values(status)["outcome"] == "completed"
    assert len(ros.double.events("accepted")) == accepted + 1


def test_use_current_start_plans_from_where_the_winches_are_and_executes(ros):
    answer = ros.plan_path(plan_path_goal(None, sphere_pose_msg(Q3), use_current_start=True),
                           timeout_s=60)
    assert answer.success, answer.result.error_msg
    np.testing.assert_allclose(answer.result.cable_trajectory.points[0].positions,
                               _measured(ros), atol=1e-6)
    first = answer.result.path.poses[0].pose.position
    q2 = sphere_pose_msg(Q2).pose.position
    np.testing.assert_allclose([first.x, first.y, first.z], [q2.x, q2.y, q2.z], atol=1e-6)
    _, status = _execute_to_the_end(ros, answer.result)
    assert M.status_values(status)["outcome"] == "completed"


SLOW_SPEED = 0.0005   # m/s: a motion of minutes, tens of seconds at the double's time scale


def test_stop_cancels_the_controller_goal_and_ends_stopped(ros):
    """Stop while the controller runs the goal: canceled there, the execution ends stopped.
    The plan is made slow (trajectory.max_cable_speed) so that the goal is still running
    when the stop arrives on a loaded machine: the cancel is caught, not raced."""
    normal = CONFIG.values["trajectory.max_cable_speed"]
    assert all(ok for ok, _ in ros.set_parameters({"trajectory.max_cable_speed": SLOW_SPEED}))
    try:
        answer = ros.plan_path(plan_path_goal(None, sphere_pose_msg(Q2), use_current_start=True),
                               timeout_s=120)
    finally:
        assert all(ok for ok, _ in ros.set_parameters({"trajectory.max_cable_speed": normal}))
    assert answer.success, answer.result.error_msg
    assert path_duration(answer.path) / TIME_SCALE > 20.0, path_duration(answer.path)
    seen = len(ros.execution_results)
    accepted = len(ros.double.events("accepted"))
    ok, message = ros.execute()
    assert ok, message
    assert ros.spin_until(lambda: len(ros.double.events("accepted")) > accepted, 60.0)
    ok, message = ros.stop()
    assert ok and "cancel" in message, message
    status = ros.wait_execution_result(seen, timeout_s=60.0)   # a limit for a hang
    assert status is not None and status.level == DiagnosticStatus.WARN, status
    assert M.status_values(status)["outcome"] == "stopped"
    assert ros.spin_until(lambda: ros.double.events("canceled"), 30.0)
    ok, message = ros.stop()
    assert ok and message.startswith("not executing"), message


def test_call_from_where_the_winches_stopped_to_the_goal_and_execute(ros):
    """The command line a task sequencer's script uses: plan from the measured pose (the
    winches stopped part way, above) and execute through the controller to the end."""
    r = run_cli(ros.domain, "call", "--current-start", "--goal", pose_text(Q3), "--execute")
    assert r.returncode == 0, r.stdout + r.stderr
    for line in ("outcome: planned", f"through {ACTION}", "execution completed"):
        assert line in r.stdout, r.stdout
    assert ros.spin_until(lambda: np.allclose(_measured(ros), _lengths(Q3), rtol=0, atol=1e-6),
                          10.0), (_measured(ros), _lengths(Q3))
