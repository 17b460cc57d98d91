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
from cdh_planner.ros.msgs import messages as M  # noqa: E402
from cdh_planner.ros.client import PlannerClient, path_duration, plan_path_goal  # noqa: E402
from cdh_planner.ros.core.params import node_config  # noqa: E402
from ros_harness import (Q1, Q2, Q3, ROBOT2, Collector, ControllerDouble,  # noqa: E402
                         NodeProcess, claimed_domain, file_parameters, pose_text, run_cli,
                         sphere_pose_msg, wait_node_measures)

CONFIG = node_config(file_parameters(ROBOT2))
ROBOT = CONFIG.robot
ACTION = "/cable_controller/follow_joint_trajectory"
JOINT_STATES = "/winches/joint_states"
TIME_SCALE = 4.0   # the double runs 4x faster than real time


def _rest_lengths(coords):
    """The winch (unstretched) lengths at which the simulated robot rests at ``coords``."""
    from cdh_planner.sim.plant import rest_lengths
    o = sphere_pose_msg(coords).pose
    return rest_lengths(ROBOT, np.array([o.position.x, o.position.y, o.position.z]),
                        rotation_from_quaternion(np.array([o.orientation.x, o.orientation.y,
                                                           o.orientation.z, o.orientation.w])))


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
                                  "--robot", ROBOT2,   # the simulated robot (MuJoCo)
                                  "--initial", *map(repr, _rest_lengths(Q1).tolist()))
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


def _key(stamp):
    return (stamp.sec, stamp.nanosec)


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
    # against the trajectory's first point: the commanded (unstretched) lengths at q1, within
    # the cables' stretch of the geometric ones (this plan's latched ~/planned_cable_trajectory)
    def this_plan():
        points = ros.trajectories[-1].points if ros.trajectories else []
        return points and all(np.max(np.abs(np.array(points[k].positions) - _lengths(q))) < 5e-3
                              for k, q in ((0, Q1), (-1, Q3)))
    assert ros.spin_until(this_plan, 10.0)
    first = np.array(ros.trajectories[-1].points[0].positions)
    gap = float(np.max(np.abs(_measured(ros) - first)))
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
    # the commanded lengths carry each end's nominal tensions (with its acceleration): the
    # start's differ from where the last plan's end left the winches by L dt / EA (3.4e-5 m)
    np.testing.assert_allclose(answer.result.cable_trajectory.points[0].positions,
                               _measured(ros), atol=1e-4)
    first = answer.result.path.poses[0].pose.position
    q2 = sphere_pose_msg(Q2).pose.position
    # where the simulated platform rests (its measured lengths stretched by the measured
    # tensions): at q2 to the few um the end's commanded (unstretched) lengths make
    np.testing.assert_allclose([first.x, first.y, first.z], [q2.x, q2.y, q2.z], atol=1e-5)
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
    # at q3: the lengths that carry the nominal tensions at rest there, to the difference
    # the last point's nominal tensions (with its deceleration) make, L dt / EA
    assert ros.spin_until(lambda: np.allclose(_measured(ros), _rest_lengths(Q3), rtol=0,
                                              atol=1e-4), 10.0), (_measured(ros), _rest_lengths(Q3))


def test_the_simulated_robot_measures_the_tensions_and_the_run_file_records_them(ros):
    """The double is the simulated robot (MuJoCo): /joint_states carries each cable's
    measured tension in effort; at rest at q2 they balance the platform's weight (the sum
    of the tension vectors = the load, within the cables' stretch), and the node's run file
    records them (~/cable_state with effort)."""
    answer = ros.plan_path(plan_path_goal(None, sphere_pose_msg(Q2), use_current_start=True),
                           timeout_s=60)
    assert answer.success, answer.result.error_msg
    _, status = _execute_to_the_end(ros, answer.result)
    assert M.status_values(status)["outcome"] == "completed"

    def efforts(m):
        return np.array([m.effort[list(m.name).index(n)] for n in ROBOT.winch_names])

    def settled():   # the platform at rest: two successive joint states' tensions agree
        last = ros.measured.messages[-2:]
        return len(last) == 2 and np.max(np.abs(efforts(last[1]) - efforts(last[0]))) < 1e-3

    # "completed" comes as the winches arrive; the cables' damping still swings the load
    # (on a loaded machine the last state then was 0.07 N off the statics)
    assert ros.spin_until(settled, 60.0), [efforts(m) for m in ros.measured.messages[-3:]]
    msg = ros.measured.messages[-1]
    effort = efforts(msg)
    assert effort.shape == (6,) and np.all(effort > 0), msg
    # statics at q2 from the measured lengths: J(x) t = w0 to the cables' compliance
    from cdh_planner.wrench import cable_vectors, load_point, nominal_wrench, screw_jacobian
    q2 = sphere_pose_msg(Q2).pose
    p = np.array([q2.position.x, q2.position.y, q2.position.z])
    R = rotation_from_quaternion(np.array([q2.orientation.x, q2.orientation.y,
                                           q2.orientation.z, q2.orientation.w]))
    d = cable_vectors(ROBOT, p[None], R[None])
    u = d / np.linalg.norm(d, axis=-1)[..., None]
    expected = np.linalg.solve(screw_jacobian(ROBOT, u)[0],
                               nominal_wrench(ROBOT, load_point(ROBOT, p[None], R[None]))[0])
    assert np.allclose(effort, expected, rtol=0.05, atol=0.02), (effort, expected)
    # the node computes its live state from the newest joint state at live_state_rate_hz:
    # wait until it has published that of this one or a later one, then stop it
    cables = Collector(ros.node, JointState, "/cdh_planner/cable_state", 10)
    assert ros.spin_until(lambda: any(_key(m.header.stamp) >= _key(msg.header.stamp)
                                      for m in cables.messages), 30.0)
    ros.process.stop(timeout=15.0)
    from mcap_ros2.reader import read_ros2_messages
    recorded = [m.ros_msg for f in ros.process.run_files()
                for m in read_ros2_messages(str(f), topics=["/cdh_planner/cable_state"])]
    assert recorded and all(len(m.effort) == 6 for m in recorded)
    assert _key(recorded[-1].header.stamp) >= _key(msg.header.stamp)
    # each recorded effort is the measured tensions of its joint state (by stamp), in
    # winch order
    measured = {_key(m.header.stamp): [m.effort[list(m.name).index(n)] for n in ROBOT.winch_names]
                for m in ros.measured.messages}
    same = [m for m in recorded if _key(m.header.stamp) in measured]
    assert same and all(list(m.effort) == measured[_key(m.header.stamp)] for m in same)
