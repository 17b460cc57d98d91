"""The node with the real planner, over real DDS (node in its own process and ROS domain):
a plan over ROS is the offline planner's answer; every output topic arrives with the right
type, frame, joint names, layout and units; infeasible and unreachable requests are answered
with nav2 error codes and the node serves the next good request; a recorded run's requests
replay to the same answers.

Robot 2's sphere task (config/robot2.yaml, paper Eq. 17): q1 -> q2 = (0.55, pi/2) ->
(0.55, 0.75).
"""

import math
import signal

import numpy as np
import pytest

pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticStatus  # noqa: E402
from nav_msgs.msg import Path as PathMsg  # noqa: E402
from nav_msgs.srv import GetPlan  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from cdh_planner_interfaces.msg import TensionEnvelope  # noqa: E402
from trajectory_msgs.msg import JointTrajectory  # noqa: E402
from visualization_msgs.msg import Marker, MarkerArray  # noqa: E402

from cdh_planner.model.pose import rotation_from_quaternion  # noqa: E402
from cdh_planner.ros.msgs import messages as M  # noqa: E402
from cdh_planner.ros.core import plan_requests  # noqa: E402
from cdh_planner.ros.client import PlannerClient  # noqa: E402
from cdh_planner.ros.core.params import node_config  # noqa: E402
from conftest import REPO  # noqa: E402
from ros_harness import (EQUATOR, EQUATOR_Q3, Q1, Q2, Q3, ROBOT2, Collector,  # noqa: E402
                         NodeProcess, claimed_domain, file_parameters, run_cli,
                         sphere_pose_msg, stamp_s)

planner_module = pytest.importorskip("cdh_planner.planner")
if not hasattr(planner_module, "Planner"):
    pytest.fail("cdh_planner.planner.Planner is missing: the node cannot plan", pytrace=False)

CONFIG = node_config(file_parameters(ROBOT2))
ROBOT, TASK = CONFIG.robot, CONFIG.task
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
OUTPUTS = {"path": PathMsg, "planned_cable_trajectory": JointTrajectory,
           "tension_envelope": TensionEnvelope, "markers": MarkerArray,
           "plan_result": DiagnosticStatus}


@pytest.fixture(scope="module")
def ros(tmp_path_factory):
    runs = tmp_path_factory.mktemp("node")
    with claimed_domain() as domain:
        node = NodeProcess(domain, runs)
        try:
            with PlannerClient(domain_id=domain) as client:
                client.wait_for_node(30.0)
                client.domain, client.process = domain, node
                client.out = {k: Collector(client.node, cls, f"/cdh_planner/{k}", LATCHED)
                              for k, cls in OUTPUTS.items()}
                yield client
        finally:
            rc = node.stop()
            assert rc == 0, node.log()


@pytest.fixture(scope="module")
def q1_q2(ros):
    """The first plan of the node (a fresh atlas, like the offline planner's)."""
    request = GetPlan.Request(start=sphere_pose_msg(Q1), goal=sphere_pose_msg(Q2))
    answer = ros.plan(request.start, request.goal, timeout_s=120)
    assert answer.success, answer.values
    key = str(M.time_ns(answer.path.header.stamp))
    assert ros.spin_until(lambda: all(c.items for c in ros.out.values()) and M.status_values(
        ros.out["plan_result"].messages[-1]).get("path_stamp") == key, 5.0)
    return request, answer, {k: c.messages[-1] for k, c in ros.out.items()}


def _positions(path_msg):
    return M.path_arrays(path_msg)[0]


def _quaternions(path_msg):
    return M.path_arrays(path_msg)[1]


def test_plan_over_ros_is_the_offline_planners_answer(q1_q2):
    request, answer, _ = q1_q2
    start, goal = plan_requests.request_poses(request, CONFIG.base_frame)
    offline = planner_module.Planner(ROBOT, TASK, CONFIG.settings).plan(start, goal)
    assert offline.success
    path = offline.path
    assert len(answer.path.poses) == len(path)
    np.testing.assert_allclose(_positions(answer.path), path.p, rtol=0, atol=1e-12)
    np.testing.assert_allclose(_quaternions(answer.path), path.quaternion, rtol=0, atol=1e-12)
    offsets = [(M.time_ns(p.header.stamp) - M.time_ns(answer.path.header.stamp)) * 1e-9
               for p in answer.path.poses]
    np.testing.assert_allclose(offsets, path.t, atol=1e-9)
    values = answer.values
    assert values["error_code"] == "0" and values["strategy"] == offline.strategy
    assert int(values["charts"]) == offline.charts
    assert float(values["cost"]) == pytest.approx(offline.cost, rel=1e-9)
    summary = plan_requests.path_summary(path, ROBOT)
    assert float(values["duration_s"]) == pytest.approx(summary["duration_s"], rel=1e-12)
    assert float(values["min_tension_margin_n"]) == pytest.approx(
        summary["min_tension_margin_n"], rel=1e-12)


def test_path_topic_frames_stamps_and_task(q1_q2):
    _, answer, out = q1_q2
    path = out["path"]
    assert path.header.frame_id == "cdh_base"
    assert all(p.header.frame_id == "cdh_base" for p in path.poses)
    np.testing.assert_array_equal(_positions(path), _positions(answer.path))
    stamps = [M.time_ns(p.header.stamp) for p in path.poses]
    assert stamps[0] == M.time_ns(path.header.stamp) and np.all(np.diff(stamps) > 0)
    q = _quaternions(path)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    p = _positions(path)
    from cdh_planner.model.pose import tau_from_quaternion
    assert np.max(TASK.residual(p, tau_from_quaternion(q))) < 1e-6   # on the sphere task
    np.testing.assert_allclose(p[0], [0.0, 0.0, 0.306 - 0.130], atol=1e-9)   # q1: below c


def test_cable_trajectory_joint_names_units_and_limits(q1_q2):
    _, answer, out = q1_q2
    traj = out["planned_cable_trajectory"]
    assert list(traj.joint_names) == list(ROBOT.winch_names)
    assert traj.header.frame_id == "cdh_base" and M.time_ns(traj.header.stamp) == 0
    assert len(traj.points) == len(answer.path.poses)
    t = np.array([M.to_seconds(pt.time_from_start) for pt in traj.points])
    assert t[0] == 0.0 and np.all(np.diff(t) > 0)
    L = np.array([pt.positions for pt in traj.points])
    V = np.array([pt.velocities for pt in traj.points])
    A = np.array([pt.accelerations for pt in traj.points])
    assert L.shape == V.shape == A.shape == (len(t), 6)
    E = np.array([pt.effort for pt in traj.points])   # the nominal tensions (N)
    assert E.shape == L.shape
    assert np.all(E >= ROBOT.tension_min - 1e-9) and np.all(E <= ROBOT.tension_max + 1e-9)
    # positions are cable lengths (m) of the path's poses: |a_i - (p + R b_i)|
    p, R = _positions(answer.path), rotation_from_quaternion(_quaternions(answer.path))
    attach = p[:, None, :] + np.einsum("kij,nj->kni", R, ROBOT.platform_anchors)
    np.testing.assert_allclose(L, np.linalg.norm(ROBOT.base_anchors[None] - attach, axis=2),
                               atol=1e-9)
    assert np.all((L >= ROBOT.length_min) & (L <= ROBOT.length_max))
    assert np.all(np.abs(V) <= CONFIG.settings.max_cable_speed * (1 + 1e-9))
    assert np.all(np.abs(A) <= CONFIG.settings.max_cable_accel * (1 + 1e-9))
    assert np.all(V[0] == 0) and np.all(V[-1] == 0)


def test_tension_envelope_matches_waypoints(q1_q2):
    _, answer, out = q1_q2
    env_msg = out["tension_envelope"]
    n = len(answer.path.poses)
    assert list(env_msg.winch_names) == list(ROBOT.winch_names)
    assert env_msg.header.frame_id == "cdh_base"
    assert [p.time_from_start for p in env_msg.points] == [
        p.time_from_start for p in out["planned_cable_trajectory"].points]
    env = M.envelope_from_msg(env_msg)
    assert env.shape == (n, 6, 3)
    assert np.all(env[..., 0] <= env[..., 1]) and np.all(env[..., 1] <= env[..., 2])
    assert np.all(env[..., 0] > ROBOT.tension_min) and np.all(env[..., 2] < ROBOT.tension_max)


def test_markers_and_plan_result(q1_q2):
    _, answer, out = q1_q2
    markers = out["markers"].markers
    assert markers[0].action == Marker.DELETEALL
    assert all(m.header.frame_id == "cdh_base" for m in markers)
    [line] = [m for m in markers if m.ns == "path"]
    assert len(line.points) == len(answer.path.poses)
    assert {m.ns for m in markers[1:]} == {"path", "platform", "cables"}
    status = out["plan_result"]
    assert status.level == DiagnosticStatus.OK
    values = M.status_values(status)
    assert set(M.STATUS_KEYS) | set(plan_requests.EXTRA_KEYS) == set(values)
    assert values["log_file"].endswith(".mcap")
    assert float(values["planning_time_s"]) > 0 and int(values["waypoints"]) == len(markers[1].points)


def _refused(ros, start, goal, code, words):
    answer = ros.plan(sphere_pose_msg(start) if isinstance(start, tuple) else start,
                      sphere_pose_msg(goal), timeout_s=60)
    assert not answer.success and len(answer.path.poses) == 0
    assert answer.values["error_code"] == str(code), answer.values
    assert any(w in answer.values["error_msg"].lower() for w in words), answer.values
    assert answer.status.level == DiagnosticStatus.ERROR


def _serves(ros):
    assert ros.plan(sphere_pose_msg(Q1), sphere_pose_msg(Q2), timeout_s=60).success


def test_infeasible_start_and_goal(ros, q1_q2):
    _refused(ros, EQUATOR, Q2, M.START_OCCUPIED, ("start",))
    _serves(ros)
    _refused(ros, Q2, EQUATOR_Q3, M.GOAL_OCCUPIED, ("goal",))
    _serves(ros)


def test_pose_off_the_task_is_invalid(ros, q1_q2):
    off = sphere_pose_msg(Q1)
    off.pose.position.z = 0.1                           # not on the sphere
    _refused(ros, off, Q2, M.INVALID_REQUEST, ("task", "sphere", "invalid", "start"))
    _serves(ros)


def test_poses_to_six_decimals_plan_within_the_tolerance(ros, q1_q2):
    """The README's and `call --help`'s q1 -> q2, written to 6 decimals (3e-6 off the
    sphere), plans: within task.tolerance (1 mm / 1 mrad) a pose is projected onto the task.
    GetPlan's own tolerance overrides the parameter: 1e-7 refuses it, naming the distance."""
    def rounded(coords):
        msg = sphere_pose_msg(coords)
        for obj, names in ((msg.pose.position, "xyz"), (msg.pose.orientation, "xyzw")):
            for n in names:
                setattr(obj, n, round(getattr(obj, n), 6))
        return msg
    assert ros.plan(rounded(Q1), rounded(Q2), timeout_s=60).success
    answer = ros.plan(rounded(Q1), rounded(Q2), timeout_s=60, tolerance=1e-7)
    assert not answer.success and "beyond the tolerance 1e-07" in answer.values["error_msg"]
    _serves(ros)


def test_the_call_help_example_plans_as_printed(ros, q1_q2):
    """`cdh-planner call --help`'s example, copied from the help text, plans (exit 0)."""
    import re
    help_text = run_cli(ros.domain, "call", "--help").stdout
    example = help_text[help_text.index("example"):]
    start = re.search(r'--start "([^"]+)"', example).group(1)
    goal = re.search(r'--goal "([^"]+)"', example).group(1)
    r = run_cli(ros.domain, "call", "--start", start, "--goal", goal)
    assert r.returncode == 0 and "outcome: planned" in r.stdout, r.stdout + r.stderr


@pytest.mark.parametrize("param,value,code", [
    ("planner.max_charts", 3, M.NO_VALID_PATH),
    ("planner.timeout_s", 0.001, M.TIMEOUT),
])
def test_unreachable_within_limits_then_serves(ros, q1_q2, param, value, code):
    default = ros.get_parameters([param])[param]
    assert ros.set_parameters({param: value}) == [(True, "")]
    try:
        _refused(ros, Q2, Q3, code, ("chart", "time", "path"))
    finally:
        assert ros.set_parameters({param: default}) == [(True, "")]
    _serves(ros)


def test_a_recorded_run_replays_to_the_same_answers_on_a_fresh_node(tmp_path):
    """The planner keeps its atlas between requests (multi-query): the same request can get
    another path once the atlas has grown. So a recorded run replays to the recorded answers
    on a node in the state the recording started from: a fresh node, same parameters. The
    recording node is stopped with SIGTERM before the replay reads its file."""
    with claimed_domain() as recorded_domain, claimed_domain() as fresh_domain:
        recorder = NodeProcess(recorded_domain, tmp_path / "recorded")
        fresh = NodeProcess(fresh_domain, tmp_path / "fresh", params=["log_enabled:=false"])
        try:
            try:
                with PlannerClient(domain_id=recorded_domain) as client:
                    client.wait_for_node(30.0)
                    first = client.plan(sphere_pose_msg(Q1), sphere_pose_msg(Q2), 120.0)
                    refused = client.plan(sphere_pose_msg(EQUATOR), sphere_pose_msg(Q2), 60.0)
                    second = client.plan(sphere_pose_msg(Q2), sphere_pose_msg(Q3), 120.0)
                    assert first.success and second.success and not refused.success
            finally:
                assert recorder.stop() == 0, recorder.log()
            run_file = first.values["log_file"]
            r = run_cli(fresh_domain, "replay", run_file, "--requests", "--tolerance", "1e-12")
            assert r.returncode == 0, r.stdout + r.stderr
            assert "3 of 3 answers match the recording" in r.stdout, r.stdout
            assert "DIFFERS" not in r.stdout
            assert fresh.run_files() == []                        # log_enabled false
        finally:
            assert fresh.stop() == 0, fresh.log()


def test_an_idle_node_stops_cleanly(tmp_path):
    """SIGINT before any request: exit 0 (an executor thread left inside rclpy's wait at
    interpreter exit used to abort the process: exit 134)."""
    with claimed_domain() as domain:
        node = NodeProcess(domain, tmp_path)
        try:
            with PlannerClient(domain_id=domain) as client:
                client.wait_for_node(30.0)
        finally:
            rc = node.stop(signal.SIGINT)
        assert rc == 0, node.log()
        assert "terminate called" not in node.log()


def test_no_path_between_components_over_ros(tmp_path):
    """Robot 1's (phi, theta) slice (paper Sec. 5.1) as node parameters: from the island of
    C around (-1.3, 2.0) the goal q_g is unreachable (NO_VALID_PATH, "no path"); the node
    then serves a reachable goal."""
    from cdh_planner.model.pose import quaternion_from_tau
    from cdh_planner.ros.client import pose_stamped

    sigma = 17 * math.pi / 90
    fixed = {"x": 0.0, "y": 0.0, "z": 0.35, "sigma": sigma}
    params = ["task.type:=slice"] + [f"task.fixed.{k}:={v!r}" for k, v in fixed.items()]

    def pose(phi, theta):
        q = quaternion_from_tau(np.array([phi, theta, sigma]))
        return pose_stamped([0.0, 0.0, 0.35] + list(q), "cdh_base")

    with claimed_domain() as domain:
        node = NodeProcess(domain, tmp_path, params=params, params_file=REPO / "config" / "robot1.yaml")
        try:
            with PlannerClient(domain_id=domain) as client:
                client.wait_for_node(30.0)
                answer = client.plan(pose(-1.3, 2.0), pose(1.7, 1.7), timeout_s=120)
                assert not answer.success and len(answer.path.poses) == 0
                assert answer.values["error_code"] == str(M.NO_VALID_PATH), answer.values
                assert "no path" in answer.values["error_msg"].lower(), answer.values
                assert client.plan(pose(-1.3, 2.0), pose(-1.2, 1.9), timeout_s=120).success
        finally:
            assert node.stop() == 0, node.log()
