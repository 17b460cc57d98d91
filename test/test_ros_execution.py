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

from cdh_planner.ros import messages as M  # noqa: E402
from cdh_planner.ros.client import plan_path_goal  # noqa: E402
from cdh_planner.ros.params import node_config  # noqa: E402
from ros_harness import (CONTROLLER_ACTION, Q1, Q2, Q3, ROBOT2,  # noqa: E402
                         file_parameters, node_with_controller, pose_lengths, pose_text,
                         run_cli, sphere_pose_msg)

CONFIG = node_config(file_parameters(ROBOT2))
ROBOT = CONFIG.robot
def _lengths(coords):
    return pose_lengths(ROBOT, coords)


@pytest.fixture(scope="module")
def ros(tmp_path_factory):
    with node_with_controller(ROBOT, Q1, tmp_path_factory.mktemp("execution"),
                              ["execution.mode:=follow_joint_trajectory"]) as client:
        yield client


def _measured(ros):
    msg = ros.measured.messages[-1]
    return np.array([msg.position[list(msg.name).index(n)] for n in ROBOT.winch_names])


def _execute_to_the_end(ros, result):
    """Execute the last plan; (execute's message, how it ended: DiagnosticStatus)."""
    seen = len(ros.execution_results)
    accepted = len(ros.double.events("accepted"))
    ok, message = ros.execute()
    assert ok, message
    assert CONTROLLER_ACTION in message and "start not checked" not in message, message
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


def test_stop_cancels_the_controller_goal_and_ends_stopped(ros):
    answer = ros.plan_path(plan_path_goal(None, sphere_pose_msg(Q2), use_current_start=True),
                           timeout_s=60)
    assert answer.success, answer.result.error_msg
    seen = len(ros.execution_results)
    ok, message = ros.execute()
    assert ok, message
    ok, message = ros.stop()
    assert ok and "cancel" in message, message
    status = ros.wait_execution_result(seen, timeout_s=15.0)
    assert status is not None and status.level == DiagnosticStatus.WARN, status
    assert M.status_values(status)["outcome"] == "stopped"
    assert ros.spin_until(lambda: ros.double.events("canceled"), 5.0)
    ok, message = ros.stop()
    assert ok and message.startswith("not executing"), message


def test_call_from_where_the_winches_stopped_to_the_goal_and_execute(ros):
    """The command line a task sequencer's script uses: plan from the measured pose (the
    winches stopped part way, above) and execute through the controller to the end."""
    r = run_cli(ros.domain, "call", "--current-start", "--goal", pose_text(Q3), "--execute")
    assert r.returncode == 0, r.stdout + r.stderr
    for line in ("outcome: planned", f"through {CONTROLLER_ACTION}", "execution completed"):
        assert line in r.stdout, r.stdout
    assert ros.spin_until(lambda: np.allclose(_measured(ros), _lengths(Q3), rtol=0, atol=1e-6),
                          10.0), (_measured(ros), _lengths(Q3))
