"""The node's PlanPath action (``~/plan_path``) over real DDS, in a ROS domain of its own:
goal, feedback, result and cancel with the real planner; the goal's overrides (strategy,
timeout_s) and refusals (bad strategy, bad frame); ``use_current_start`` from measured cable
lengths (forward kinematics); every goal ending with a result when more arrive than the
node queues (with the test double planner); and, in follow_joint_trajectory mode with no
controller, an execution that fails naming the action instead of hanging."""

import math
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from action_msgs.msg import GoalStatus  # noqa: E402
from diagnostic_msgs.msg import DiagnosticStatus  # noqa: E402
from cdh_planner.ros.actions import RaceFreeActionClient  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from cdh_planner_interfaces.action import PlanPath  # noqa: E402

from cdh_planner.model.kinematics import cable_lengths  # noqa: E402
from cdh_planner.model.pose import rotation_from_quaternion  # noqa: E402
from cdh_planner.ros.msgs import messages as M  # noqa: E402
from cdh_planner.ros.client import PlannerClient, plan_path_goal  # noqa: E402
from cdh_planner.ros.core.params import node_config  # noqa: E402
from cdh_planner.ros.core.plan_requests import PLAN_QUEUE_DEPTH  # noqa: E402
from ros_harness import (Q1, Q2, Q3, ROBOT2, NodeProcess, claimed_domain,  # noqa: E402
                         file_parameters, sphere_pose_msg)

CONFIG = node_config(file_parameters(ROBOT2))
ROBOT = CONFIG.robot
# A small chart radius makes Robot 2's q2 -> q3 a long search: about 5 s with A* (3000
# charts), under 1 s with GBF. Long enough to cancel, short enough for the next goal.
LONG = ["planner.radius:=0.02", "planner.strategy:=astar"]
# The node's wait for joint states in this module (s): far longer than a client's timeout
# in the tests that set a short one, so that an answer within that timeout shows the
# short wait was in force, without timing the answer.
WAIT_S = 60.0


@pytest.fixture(scope="module")
def ros(tmp_path_factory):
    with claimed_domain() as domain:
        node = NodeProcess(domain, tmp_path_factory.mktemp("action"), params=LONG + [f"execution.joint_states_wait_s:={WAIT_S}"])
        try:
            with PlannerClient(domain_id=domain) as client:
                client.wait_for_node(30.0)
                client.process = node
                yield client
        finally:
            node.stop()


def rounded(coords, digits=6):
    """A sphere-task pose written to ``digits`` decimals (off the sphere by ~1e-6)."""
    msg = sphere_pose_msg(coords)
    for obj, names in ((msg.pose.position, "xyz"), (msg.pose.orientation, "xyzw")):
        for n in names:
            setattr(obj, n, round(getattr(obj, n), digits))
    return msg


def _position(pose_stamped):
    p = pose_stamped.pose.position
    return np.array([p.x, p.y, p.z])


def _quaternion(pose_stamped):
    o = pose_stamped.pose.orientation
    return np.array([o.x, o.y, o.z, o.w])


def _check_result(result, start, goal):
    """A successful result: path from start to goal (within the 1 mm projection), cable
    trajectory whose lengths are the path's and whose efforts are the nominal tensions (N,
    within the limits), envelope at the same times."""
    poses = result.path.poses
    assert len(poses) >= 2 and result.path.header.frame_id == "cdh_base"
    assert np.linalg.norm(_position(poses[0]) - _position(start)) < 1e-3
    assert np.linalg.norm(_position(poses[-1]) - _position(goal)) < 1e-3
    traj = result.cable_trajectory
    assert list(traj.joint_names) == list(ROBOT.winch_names)
    assert len(traj.points) == len(poses)
    E = np.array([pt.effort for pt in traj.points])
    assert E.shape == (len(poses), len(ROBOT.winch_names))
    assert np.all(E >= ROBOT.tension_min - 1e-9) and np.all(E <= ROBOT.tension_max + 1e-9)
    t = np.array([M.to_seconds(pt.time_from_start) for pt in traj.points])
    assert t[0] == 0.0 and np.all(np.diff(t) > 0)
    for k in (0, len(poses) - 1):
        R = rotation_from_quaternion(_quaternion(poses[k]))
        np.testing.assert_allclose(traj.points[k].positions,
                                   cable_lengths(ROBOT, _position(poses[k]), R), atol=1e-9)
    env = result.tension_envelope
    assert list(env.winch_names) == list(ROBOT.winch_names)
    assert [p.time_from_start for p in env.points] == [p.time_from_start for p in traj.points]
    bounds = M.envelope_from_msg(env)
    assert np.all(bounds[..., 0] >= ROBOT.tension_min) and np.all(bounds[..., 2] <= ROBOT.tension_max)
    assert 0.0 < result.min_margin < 1.0 and result.planning_time_s > 0.0


def test_goal_feedback_and_result_with_poses_to_six_decimals(ros):
    start, goal = rounded(Q2), rounded(Q3)
    answer = ros.plan_path(plan_path_goal(start, goal, strategy="gbf"), timeout_s=60)
    assert answer.success, answer.result.error_msg
    assert answer.goal_status == GoalStatus.STATUS_SUCCEEDED and answer.result.error_msg == ""
    _check_result(answer.result, start, goal)
    assert answer.result.charts > 0
    # feedback while planning: charts and time grow, the estimate is a distance
    assert answer.feedback, "no feedback"
    charts = [f.charts for f in answer.feedback]
    times = [f.time_s for f in answer.feedback]
    assert charts == sorted(charts) and times == sorted(times) and charts[-1] <= answer.result.charts
    assert all(f.best_h >= 0.0 for f in answer.feedback)


def test_cancel_during_a_long_plan_then_the_next_goal_plans(ros):
    answer = ros.plan_path(plan_path_goal(sphere_pose_msg(Q2), sphere_pose_msg(Q3)),
                           timeout_s=60, cancel_after_s=1.0)
    assert answer.goal_status == GoalStatus.STATUS_CANCELED, answer.result.error_msg
    assert answer.result.error_code == PlanPath.Result.CANCELED
    assert "cancel" in answer.result.error_msg
    # how fast a cancel ends a plan is benchmarks/plan_path_cancel.py's: here the answer's
    # words say it was the cancel, and plan_path's 60 s bounds a hang
    assert len(answer.result.path.poses) == 0
    start, goal = sphere_pose_msg(Q2), sphere_pose_msg(Q3)
    after = ros.plan_path(plan_path_goal(start, goal, strategy="gbf"), timeout_s=60)
    assert after.success, after.result.error_msg
    _check_result(after.result, start, goal)


def test_goal_overrides_and_refusals_end_with_a_reason(ros):
    q2, q3 = sphere_pose_msg(Q2), sphere_pose_msg(Q3)
    bad = ros.plan_path(plan_path_goal(q2, q3, strategy="dijkstra"), timeout_s=30)
    assert bad.goal_status == GoalStatus.STATUS_ABORTED
    assert bad.result.error_code == PlanPath.Result.INVALID_PLANNER
    assert "strategy" in bad.result.error_msg and "dijkstra" in bad.result.error_msg
    quick = ros.plan_path(plan_path_goal(q2, q3, timeout_s=0.3), timeout_s=30)  # A*: ~5 s
    assert quick.goal_status == GoalStatus.STATUS_ABORTED
    assert quick.result.error_code == PlanPath.Result.TIMEOUT
    assert quick.result.planning_time_s >= 0.3     # stopped at its deadline (causal)
    negative = ros.plan_path(plan_path_goal(q2, q3, timeout_s=-1.0), timeout_s=30)
    assert negative.result.error_code == PlanPath.Result.INVALID_REQUEST
    assert "timeout_s" in negative.result.error_msg
    frame = sphere_pose_msg(Q2, frame="map")
    wrong = ros.plan_path(plan_path_goal(frame, q3), timeout_s=30)
    assert wrong.result.error_code == PlanPath.Result.TF_ERROR and "map" in wrong.result.error_msg
    off = sphere_pose_msg(Q2)
    off.pose.position.z += 0.01                        # 1 cm off the sphere: beyond 1 mm
    far = ros.plan_path(plan_path_goal(off, q3), timeout_s=30)
    assert far.result.error_code == PlanPath.Result.INVALID_REQUEST
    assert "off the sphere task" in far.result.error_msg
    assert ros.plan_path(plan_path_goal(sphere_pose_msg(Q1), q2), timeout_s=30).success


def test_use_current_start_without_measurements_is_refused_after_the_wait(ros):
    """The reason says the wait ended with nothing received; the answer within 20 s (the
    client's bound, only a hang) while the module's wait is WAIT_S shows the 1 s wait set
    was the one in force. No answer before the wait: causality (the node's wait begins
    after the goal is sent), not a threshold."""
    wait_s = 1.0
    assert ros.set_parameters({"execution.joint_states_wait_s": wait_s}) == [(True, "")]
    try:
        t0 = time.monotonic()
        answer = ros.plan_path(plan_path_goal(None, sphere_pose_msg(Q3),
                                              use_current_start=True), timeout_s=20)
        took = time.monotonic() - t0
    finally:
        assert ros.set_parameters({"execution.joint_states_wait_s": WAIT_S}) == [(True, "")]
    assert answer.goal_status == GoalStatus.STATUS_ABORTED
    assert answer.result.error_code == PlanPath.Result.NO_CURRENT_STATE
    assert ("use_current_start: nothing received on /joint_states (no publishers seen)"
            == answer.result.error_msg)
    assert took >= wait_s, took


@pytest.mark.parametrize("fault,code,words", [
    ("nan", "INVALID_REQUEST", "goal.pose.position.x"),
    ("frame", "TF_ERROR", "goal.header.frame_id"),
    ("strategy", "INVALID_PLANNER", "strategy"),
    ("timeout", "INVALID_REQUEST", "timeout_s"),
])
def test_use_current_start_with_a_bad_goal_is_refused_before_any_wait(ros, fault, code, words):
    """The goal's own error, not "nothing received" after the wait: with the module's
    WAIT_S (60 s) wait for joint states and none coming, the answer arrives within the
    client's 30 s."""
    goal = plan_path_goal(None, sphere_pose_msg(Q3, frame="map" if fault == "frame"
                                                else "cdh_base"), use_current_start=True)
    if fault == "nan":
        goal.goal.pose.position.x = math.nan
    elif fault == "strategy":
        goal.strategy = "dijkstra"
    elif fault == "timeout":
        goal.timeout_s = -1.0
    answer = ros.plan_path(goal, timeout_s=30)
    assert answer.goal_status == GoalStatus.STATUS_ABORTED
    assert answer.result.error_code == getattr(PlanPath.Result, code), answer.result.error_msg
    assert words in answer.result.error_msg and "joint_states" not in answer.result.error_msg


def test_use_current_start_waits_for_winches_that_appear_after_the_goal(ros):
    """The goal is sent while nothing publishes joint states; a publisher that starts once
    the goal is accepted (a controller coming up) is waited for, and the plan starts at
    its pose: an answer that could only come from messages published after the goal."""
    q2 = sphere_pose_msg(Q2)
    lengths = cable_lengths(ROBOT, _position(q2), rotation_from_quaternion(_quaternion(q2)))
    msg = JointState(name=list(ROBOT.winch_names), position=[float(v) for v in lengths])
    assert ros.node.count_publishers("/joint_states") == 0
    sent = ros.plan_path_client.send_goal_async(plan_path_goal(
        None, sphere_pose_msg(Q3), use_current_start=True, strategy="gbf"))
    assert ros.spin_until(sent.done, 30.0) and sent.result().accepted
    result = sent.result().get_result_async()
    assert not result.done()
    pub = ros.node.create_publisher(JointState, "/joint_states", 10)
    timer = ros.node.create_timer(0.02, lambda: pub.publish(msg))
    try:
        assert ros.spin_until(result.done, 60.0), "no result"
    finally:
        ros.node.destroy_timer(timer)
        ros.node.destroy_publisher(pub)
    answer = result.result()
    assert answer.status == GoalStatus.STATUS_SUCCEEDED, answer.result.error_msg
    np.testing.assert_allclose(_position(answer.result.path.poses[0]), _position(q2), atol=1e-6)
    np.testing.assert_allclose(answer.result.cable_trajectory.points[0].positions, lengths,
                               atol=1e-6)


def test_use_current_start_plans_from_the_forward_kinematics_pose(ros):
    """Lengths measured at q2 (inverse kinematics, in a shuffled joint order with an extra
    joint) give back q2's pose: the path starts there, and its first cable lengths are the
    measured ones."""
    q2 = sphere_pose_msg(Q2)
    lengths = cable_lengths(ROBOT, _position(q2), rotation_from_quaternion(_quaternion(q2)))
    order = [3, 0, 5, 1, 4, 2]
    msg = JointState(name=["gripper"] + [ROBOT.winch_names[i] for i in order],
                     position=[0.0] + [float(lengths[i]) for i in order])
    pub = ros.node.create_publisher(JointState, "/joint_states", 10)
    timer = ros.node.create_timer(0.02, lambda: pub.publish(msg))
    try:
        ros.spin_until(lambda: pub.get_subscription_count() > 0, 10.0)
        answer = ros.plan_path(plan_path_goal(None, sphere_pose_msg(Q3), use_current_start=True,
                                              strategy="gbf"), timeout_s=60)
    finally:
        ros.node.destroy_timer(timer)
        ros.node.destroy_publisher(pub)
    assert answer.success, answer.result.error_msg
    first = answer.result.path.poses[0]
    np.testing.assert_allclose(_position(first), _position(q2), atol=1e-6)
    assert abs(abs(float(np.dot(_quaternion(first), _quaternion(q2)))) - 1.0) < 1e-9
    np.testing.assert_allclose(answer.result.cable_trajectory.points[0].positions, lengths,
                               atol=1e-6)
    _check_result(answer.result, q2, sphere_pose_msg(Q3))


def test_every_goal_gets_a_result_when_more_arrive_than_are_queued(tmp_path):
    """1 planning + PLAN_QUEUE_DEPTH waiting; the rest end at once with BUSY (aborted),
    never without a result."""
    delay = tmp_path / "delay"
    delay.write_text("1.0")
    extra = 2
    with claimed_domain() as domain, \
            NodeProcess(domain, tmp_path, fake=True,
                        env={"FAKE_PLANNER_DELAY_FILE": str(delay)}) as node, \
            PlannerClient(domain_id=domain) as client:
        client.wait_for_node(30.0)
        action = RaceFreeActionClient(client.node, PlanPath, client.topic("plan_path"))
        assert action.wait_for_server(timeout_sec=10.0)
        goal = plan_path_goal(sphere_pose_msg(Q1), sphere_pose_msg(Q2))
        sent = [action.send_goal_async(goal) for _ in range(1 + PLAN_QUEUE_DEPTH + extra)]
        assert client.spin_until(lambda: all(f.done() for f in sent), 20.0)
        assert all(f.result().accepted for f in sent)
        results = [f.result().get_result_async() for f in sent]
        assert client.spin_until(lambda: all(r.done() for r in results), 30.0), node.log()
        codes = sorted(r.result().result.error_code for r in results)
        assert codes == [PlanPath.Result.NONE] * (1 + PLAN_QUEUE_DEPTH) + \
            [PlanPath.Result.BUSY] * extra, codes
        busy = [r.result() for r in results if r.result().result.error_code != 0]
        assert all(b.status == GoalStatus.STATUS_ABORTED and "busy" in b.result.error_msg
                   for b in busy)
        action.destroy()


def test_execution_without_a_controller_fails_naming_the_action(ros):
    """follow_joint_trajectory mode with no controller running: ~/execute starts, and
    ~/execution_result says within about a second that there is no action server."""
    assert ros.set_parameters({"execution.mode": "follow_joint_trajectory"}) == [(True, "")]
    try:
        assert ros.plan_path(plan_path_goal(sphere_pose_msg(Q1), sphere_pose_msg(Q2)),
                             timeout_s=30).success
        ros.watch_execution()
        seen = len(ros.execution_results)
        ok, message = ros.execute()
        assert ok and "/cable_controller/follow_joint_trajectory" in message, message
        status = ros.wait_execution_result(seen, timeout_s=10.0)
        assert status is not None and status.level == DiagnosticStatus.ERROR
        assert M.status_values(status)["outcome"] == "failed"
        assert "no action server /cable_controller/follow_joint_trajectory" in status.message
        ok, message = ros.execute()                     # not stuck executing: tried again
        assert ok, message
        assert ros.wait_execution_result(seen + 1, timeout_s=10.0) is not None
    finally:
        assert ros.set_parameters({"execution.mode": "stream"}) == [(True, "")]


def test_names_read_at_start_are_read_only_afterwards(ros):
    """execution.controller_action and execution.joint_states_topic name the action client
    and the subscription made at start: a later change is refused with the reason, not
    accepted and ignored."""
    for name, value in (("execution.controller_action", "/other/follow_joint_trajectory"),
                        ("execution.joint_states_topic", "/other/joint_states")):
        before = ros.get_parameters([name])[name]
        [(ok, reason)] = ros.set_parameters({name: value})
        assert not ok and "read-only" in reason and name in reason, reason
        assert ros.get_parameters([name])[name] == before
