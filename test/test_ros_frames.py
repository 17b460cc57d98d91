"""Frames and TF over DDS (REP 103 / 105): the z-up fixed frame ``world`` with the paper's
z-down frame ``cdh_base`` under it (static), the platform's pose on /tf from the forward
kinematics of the measured cable lengths with the live state (~/cable_state,
~/least_margin, ~/live_markers), and goals in other frames transformed through TF.

The execution test runs the node around the TEST DOUBLE planner (test/doubles/fake_planner.py)
with the simulated controller; the z-up goal test runs the real planner.
"""

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped, TransformStamped
from nav_msgs.srv import GetPlan
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64
from visualization_msgs.msg import MarkerArray
from tf2_msgs.msg import TFMessage

from cdh_planner.wrench import wrench_feasibility
from cdh_planner.model.pose import rotation_from_quaternion
from cdh_planner.ros.msgs import messages as M
from cdh_planner.ros.core import plan_requests
from cdh_planner.ros.client import PlannerClient
from cdh_planner.ros.execution.winches import current_pose
from cdh_planner.ros.node.frames import TF_QOS, TF_STATIC_QOS
from cdh_planner.ros.core.params import node_config
from ros_harness import (Q1, Q2, ROBOT2, Collector, ControllerDouble, NodeProcess,
                         claimed_domain, file_parameters, sphere_pose_msg, wait_node_measures)
from test_ros_execution import _lengths

CONFIG = node_config(file_parameters(ROBOT2))
ROBOT = CONFIG.robot
ACTION = "/cable_controller/follow_joint_trajectory"
JOINT_STATES = "/winches/joint_states"


def _key(stamp):
    return (stamp.sec, stamp.nanosec)


def _pose(tf):
    t, r = tf.transform.translation, tf.transform.rotation
    return np.array([t.x, t.y, t.z]), rotation_from_quaternion(np.array([r.x, r.y, r.z, r.w]))


def test_tf_gives_the_platform_pose_during_an_execution(tmp_path):
    # the live state at every joint state the double publishes (50 Hz), not at the default
    # 20 Hz: more than 10 poses during the motion on a loaded machine too
    params = ["execution.mode:=follow_joint_trajectory", f"execution.controller_action:={ACTION}",
              f"execution.joint_states_topic:={JOINT_STATES}", "live_state_rate_hz:=200.0"]
    with claimed_domain() as domain, \
            ControllerDouble(domain, *ROBOT.winch_names, "--action", ACTION, "--joint-states",
                             JOINT_STATES, "--time-scale", 1.0,   # real time: the node
                             # looks for joint states at 50 Hz, and > 10 poses must be seen
                             "--kinematic", "--initial", *map(repr, _lengths(Q1).tolist())) as double, \
            NodeProcess(domain, tmp_path, params=params, fake=True) as node, \
            PlannerClient(domain_id=domain) as client:
        tf = Collector(client.node, TFMessage, "/tf", TF_QOS)
        static = Collector(client.node, TFMessage, "/tf_static", TF_STATIC_QOS)
        poses = Collector(client.node, PoseStamped, "/cdh_planner/platform_pose", 100)
        measured = Collector(client.node, JointState, JOINT_STATES, 100)
        cables = Collector(client.node, JointState, "/cdh_planner/cable_state", 100)
        margins = Collector(client.node, Float64, "/cdh_planner/least_margin", 100)
        live = Collector(client.node, MarkerArray, "/cdh_planner/live_markers", 100)
        assert double.ready.wait(30.0)
        client.wait_for_node(30.0)
        client.watch_execution()
        assert wait_node_measures(client, sphere_pose_msg(Q1)).success
        assert client.plan(sphere_pose_msg(Q1), sphere_pose_msg(Q2), timeout_s=30).path.poses
        first = len(tf.items)
        ok, message = client.execute()
        assert ok, message
        status = client.wait_execution_result(0, timeout_s=30.0)
        assert M.status_values(status)["outcome"] == "completed", node.log()
        client.spin(0.3)

        def settled():   # the newest TF, platform pose and cable state are of one joint state
            if not (cables.messages and poses.messages and tf.messages[first:]):
                return False
            stamp = tf.messages[-1].transforms[-1].header.stamp
            return cables.messages[-1].header.stamp == stamp == poses.messages[-1].header.stamp

        assert client.spin_until(settled, 10.0)   # the winches rest at the goal: it comes
        [fixed] = [t for m in static.messages for t in m.transforms]
        assert (fixed.header.frame_id, fixed.child_frame_id) == ("world", "cdh_base")
        r = fixed.transform.rotation
        assert (r.x, r.y, r.z, r.w) == (1.0, 0.0, 0.0, 0.0)        # pi about x: z down

        lengths = {_key(m.header.stamp): np.array(m.position) for m in measured.messages}
        platform = [t for m in tf.messages[first:] for t in m.transforms]
        assert len(platform) > 10, "the platform's pose during the execution"
        assert all((t.header.frame_id, t.child_frame_id) == ("cdh_base", "cdh_platform")
                   for t in platform)
        guess = current_pose(ROBOT, _lengths(Q1))
        compared = 0
        for t in platform:
            if _key(t.header.stamp) not in lengths:
                continue        # a joint state this client missed
            p, R = _pose(t)
            guess = current_pose(ROBOT, lengths[_key(t.header.stamp)], guess)
            np.testing.assert_allclose(p, guess[0], rtol=0, atol=1e-9)
            np.testing.assert_allclose(R, guess[1], rtol=0, atol=1e-9)
            compared += 1
        assert compared > 10
        moved = np.linalg.norm(_pose(platform[-1])[0] - _pose(platform[0])[0])
        assert moved > 0.01                          # it did move with the winches
        assert {_key(p.header.stamp) for p in poses.messages} >= {
            _key(t.header.stamp) for t in platform}  # ~/platform_pose: the same poses

        # live state: the measured lengths as they came, the margin of the measured pose
        for state in cables.messages[-20:]:
            assert list(state.name) == list(ROBOT.winch_names)
            np.testing.assert_array_equal(state.position, lengths[_key(state.header.stamp)])
        last = platform[-1]
        assert cables.messages[-1].header.stamp == last.header.stamp
        p, R = _pose(last)
        expected = wrench_feasibility(ROBOT, p[None], R=R[None]).margin[0]
        assert margins.messages[-1].data == pytest.approx(expected, abs=1e-9)
        drawn = {m.ns: m for m in live.messages[-1].markers}
        assert set(drawn) == {"platform_measured", "cables_measured"}
        assert len(drawn["cables_measured"].points) == 2 * len(ROBOT.winch_names)


def _z_up(msg):
    """The same pose in ``world`` (z up): (x, -y, -z); i * q (pi about x, then q)."""
    out = PoseStamped()
    out.header.frame_id = "world"
    p, o = msg.pose.position, msg.pose.orientation
    out.pose.position.x, out.pose.position.y, out.pose.position.z = p.x, -p.y, -p.z
    q = out.pose.orientation
    q.x, q.y, q.z, q.w = o.w, -o.z, o.y, -o.x
    return out


def _shifted(msg, frame, offset):
    """``msg`` (world) in a frame whose origin is at ``offset`` in world (no rotation)."""
    out = PoseStamped()
    out.header.frame_id = frame
    p = msg.pose.position
    out.pose.position.x, out.pose.position.y, out.pose.position.z = (
        p.x - offset[0], p.y - offset[1], p.z - offset[2])
    out.pose.orientation = msg.pose.orientation
    return out


def _plan_once_heard(client, start, goal, frame, offset):
    """The plan start -> goal (paper frame) asked in ``frame``, whose origin is at ``offset``
    in world: asked again while the node answers that it has no transform from ``frame``
    (another node's new TF publisher is heard once discovery has matched it; up to 30 s)."""
    for _ in range(60):
        answer = client.plan(_shifted(_z_up(start), frame, offset),
                             _shifted(_z_up(goal), frame, offset), timeout_s=120)
        if answer.success or f"no transform from '{frame}'" not in answer.values["error_msg"]:
            break
        client.spin(0.5)
    return answer


def test_a_goal_in_the_z_up_frame_plans_the_same_path_as_in_the_paper_frame(tmp_path):
    planner_module = pytest.importorskip("cdh_planner.planner")
    start, goal = sphere_pose_msg(Q1), sphere_pose_msg(Q2)
    with claimed_domain() as domain, NodeProcess(domain, tmp_path) as node, \
            PlannerClient(domain_id=domain) as client:
        client.wait_for_node(30.0)
        answer = client.plan(_z_up(start), _z_up(goal), timeout_s=120)
        assert answer.success, (answer.values, node.log())
        assert answer.path.header.frame_id == "cdh_base"             # outputs: paper frame
        # the first plan of the node: the offline planner's, from the paper-frame poses
        poses = plan_requests.request_poses(GetPlan.Request(start=start, goal=goal), "cdh_base")
        offline = planner_module.Planner(ROBOT, CONFIG.task, CONFIG.settings).plan(*poses)
        assert offline.success
        positions, quaternions = M.path_arrays(answer.path)[:2]
        np.testing.assert_allclose(positions, offline.path.p, rtol=0, atol=1e-12)
        np.testing.assert_allclose(quaternions, offline.path.quaternion, rtol=0, atol=1e-12)

        # a frame another node puts on TF (a table 10 cm along world x)
        table = TransformStamped()
        table.header.frame_id, table.child_frame_id = "world", "table"
        table.transform.translation.x, table.transform.rotation.w = 0.1, 1.0
        publisher = client.node.create_publisher(TFMessage, "/tf_static", TF_STATIC_QOS)
        publisher.publish(TFMessage(transforms=[table]))
        again = _plan_once_heard(client, start, goal, "table", (0.1, 0, 0))
        assert again.success, again.values
        ends = M.path_arrays(again.path)[0][[0, -1]]
        np.testing.assert_allclose(ends, offline.path.p[[0, -1]], rtol=0, atol=1e-9)

        # a moving frame on /tf, broadcast at 20 Hz as a TF broadcaster does (read by the
        # node when a request needs it, not a callback); /tf is volatile and arrives on the
        # node's own thread, so a request is refused until the first one is in: ask again
        cart = TransformStamped()
        cart.header.frame_id, cart.child_frame_id = "world", "cart"
        cart.transform.translation.y, cart.transform.rotation.w = -0.2, 1.0
        moving_tf = client.node.create_publisher(TFMessage, "/tf", TF_QOS)

        def broadcast():
            cart.header.stamp = client.node.get_clock().now().to_msg()
            moving_tf.publish(TFMessage(transforms=[cart]))

        client.node.create_timer(0.05, broadcast)
        assert client.spin_until(lambda: moving_tf.get_subscription_count() > 0, 30.0)
        moving = _plan_once_heard(client, start, goal, "cart", (0, -0.2, 0))
        assert moving.success, moving.values
        np.testing.assert_allclose(M.path_arrays(moving.path)[0][[0, -1]], offline.path.p[[0, -1]],
                                   rtol=0, atol=1e-9)

        unknown = client.plan(_shifted(start, "map", (0, 0, 0)), goal, timeout_s=30)
        assert not unknown.success
        assert unknown.values["error_code"] == str(M.TF_ERROR)
        assert "start.header.frame_id = 'map': no transform from 'map' to 'cdh_base'" in \
            unknown.values["error_msg"]


def test_a_burst_of_joint_states_is_taken_latest_only_while_a_plan_runs(tmp_path):
    """Joint states published as fast as a loop can while a plan runs over ROS: the plan
    succeeds, the node publishes far fewer cable states than it was sent (it computes the
    newest one at live_state_rate_hz, never a backlog), in the order sent, and the last
    one is the last one sent. Counted in messages, not timed."""
    import threading
    lengths = _lengths(Q1)
    with claimed_domain() as domain, \
            NodeProcess(domain, tmp_path, params=["live_state_rate_hz:=5.0"]) as node, \
            PlannerClient(domain_id=domain) as client:
        cables = Collector(client.node, JointState, "/cdh_planner/cable_state", 1000)
        winch_state = client.node.create_publisher(JointState, "/joint_states", 10)
        client.wait_for_node(60.0)
        sent, done = [0], threading.Event()

        def state(k):
            msg = JointState(name=list(ROBOT.winch_names), position=list(lengths))
            msg.header.stamp.sec = k
            return msg

        def burst():    # at least 2000 states, and on until the plan has its answer
            while not done.is_set() or sent[0] < 2000:
                sent[0] += 1
                winch_state.publish(state(sent[0]))
                if sent[0] % 100 == 0:
                    threading.Event().wait(0.001)     # let the others have the core too
        burster = threading.Thread(target=burst, daemon=True)
        burster.start()
        assert client.spin_until(lambda: cables.messages, 60.0), node.log()
        during = sent[0]
        answer = client.plan(sphere_pose_msg(Q1), sphere_pose_msg(Q2), timeout_s=120)
        assert answer.success, (answer.values, node.log())
        assert sent[0] > during          # the states kept coming through the plan
        done.set()
        burster.join(60.0)
        last = sent[0]
        # the last state sent, again until it is seen (best effort may lose one)
        assert client.spin_until(lambda: cables.messages[-1].header.stamp.sec == last or
                                 winch_state.publish(state(last)), 60.0), node.log()
        stamps = [m.header.stamp.sec for m in cables.messages]
        assert stamps == sorted(stamps) and stamps[-1] == last
        assert len(set(stamps)) * 4 < last, (len(set(stamps)), last)   # latest only
        for m in cables.messages:
            np.testing.assert_array_equal(m.position, lengths)
