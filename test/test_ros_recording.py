"""Run recording and replay over real DDS, nodes in their own processes and ROS domain:
a node stopped with SIGTERM mid-stream leaves a complete MCAP holding, field by field, what
subscribers received; one killed with SIGKILL leaves a readable file that lost nothing it
had published; ``cdh-planner replay`` republishes with the recorded timing and re-sends
requests; ``cdh-planner call`` prints the outcome and exits by it.

The node runs around the TEST DOUBLE planner (test/doubles/fake_planner.py): these are tests
of recording and replay, not of planning.
"""

import signal
import subprocess
import time

import numpy as np
import pytest

pytest.importorskip("rosbags")
pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticStatus  # noqa: E402
from nav_msgs.msg import Path as PathMsg  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rosbags.highlevel import AnyReader, AnyReaderError  # noqa: E402
from rosbags.typesys.msg import normalize_msgtype  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from trajectory_msgs.msg import JointTrajectory  # noqa: E402

from cdh_planner.io.mcap_log import REQUEST_RECEIVED, RESPONSE_SENT, read_run, recover_run  # noqa: E402
from cdh_planner.ros.client import PlannerClient  # noqa: E402
from ros_harness import (Q1, Q2, Collector, NodeProcess, claimed_domain, cli,  # noqa: E402
                         pose_text, ros_env, run_cli, sphere_pose_msg, stamp_s)

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
TOPICS = {"/cdh_planner/path": (PathMsg, LATCHED),
          "/cdh_planner/cable_trajectory": (JointTrajectory, LATCHED),
          "/cdh_planner/tension_envelope": (Float64MultiArray, LATCHED),
          "/cdh_planner/plan_result": (DiagnosticStatus, LATCHED),
          "/cdh_planner/cable_command": (JointState, 100)}


@pytest.fixture(scope="module")
def domain():
    with claimed_domain() as d:
        yield d


@pytest.fixture(scope="module")
def client(domain):
    with PlannerClient(domain_id=domain) as c:
        c.live = {t: Collector(c.node, cls, t, qos) for t, (cls, qos) in TOPICS.items()}
        yield c


def _plan_execute_and_signal(client, node, sig, after_s):
    """Plan q1 -> q2, execute, send ``sig`` to the node ``after_s`` into the motion."""
    client.wait_for_node(20.0)
    start, goal = sphere_pose_msg(Q1), sphere_pose_msg(Q2)
    answer = client.plan(start, goal, timeout_s=30)
    assert answer.success
    assert client.execute()[0]
    client.spin(after_s)
    rc = node.stop(sig)
    client.spin(0.3)
    return answer, start, rc


def _since(collector, t0):
    return [m for t, m in collector.items if t >= t0]


@pytest.fixture(scope="module")
def sigterm_run(domain, client, tmp_path_factory):
    """A node that planned, executed, and got SIGTERM mid-stream; (file, live, answer, start)."""
    runs = tmp_path_factory.mktemp("sigterm")
    t0 = time.time()
    node = NodeProcess(domain, runs, fake=True)
    answer, start, rc = _plan_execute_and_signal(client, node, signal.SIGTERM, 0.8)
    assert rc == 0, node.log()
    assert "shutting down while executing: held the last setpoint" in node.log()
    [run_file] = node.run_files()
    live = {t: _since(c, t0) for t, c in client.live.items()}
    return run_file, live, answer, start


def _rosbags_messages(path):
    out = {}
    with AnyReader([path]) as reader:
        for conn, _, raw in reader.messages():
            # rosbags files 'pkg/srv/T' under 'pkg/srv/msg/T'
            typ = conn.msgtype if conn.msgtype in reader.typestore.fielddefs \
                else normalize_msgtype(conn.msgtype)
            out.setdefault(conn.topic, []).append(reader.deserialize(raw, typ))
    return out


def test_sigterm_leaves_a_complete_file_with_what_subscribers_got(sigterm_run):
    run_file, live, answer, start = sigterm_run
    recorded = _rosbags_messages(run_file)       # rosbags opens only complete files
    [path] = recorded["/cdh_planner/path"]
    assert path.header.frame_id == live["/cdh_planner/path"][-1].header.frame_id == "cdh_base"
    got = np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z]
                    for p in live["/cdh_planner/path"][-1].poses])
    rec = np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z]
                    for p in path.poses])
    np.testing.assert_array_equal(rec, got)
    [traj] = recorded["/cdh_planner/cable_trajectory"]
    live_traj = live["/cdh_planner/cable_trajectory"][-1]
    assert list(traj.joint_names) == list(live_traj.joint_names)
    for a, b in zip(traj.points, live_traj.points):
        np.testing.assert_array_equal(a.positions, b.positions)
        np.testing.assert_array_equal(a.effort, b.effort)
        assert (a.time_from_start.sec, a.time_from_start.nanosec) == \
            (b.time_from_start.sec, b.time_from_start.nanosec)
    [env] = recorded["/cdh_planner/tension_envelope"]
    np.testing.assert_array_equal(env.data, live["/cdh_planner/tension_envelope"][-1].data)
    assert [d.label for d in env.layout.dim] == ["waypoint", "cable", "bound"]
    [status] = recorded["/cdh_planner/plan_result"]
    values = {kv.key: kv.value for kv in status.values}
    assert values == answer.values
    assert values["log_file"] == str(run_file)
    # every streamed command a subscriber got is in the file, the shutdown hold last
    rec_cmds = {(c.header.stamp.sec, c.header.stamp.nanosec): c
                for c in recorded["/cdh_planner/cable_command"]}
    live_cmds = live["/cdh_planner/cable_command"]
    assert len(live_cmds) >= 30
    for c in live_cmds:
        r = rec_cmds[(c.header.stamp.sec, c.header.stamp.nanosec)]
        np.testing.assert_array_equal(r.position, c.position)
        np.testing.assert_array_equal(r.velocity, c.velocity)
    assert np.all(recorded["/cdh_planner/cable_command"][-1].velocity == 0.0)
    # the service calls, as rosbag2 records them
    events = recorded["/cdh_planner/plan/_service_event"]
    assert [e.info.event_type for e in events] == [REQUEST_RECEIVED, RESPONSE_SENT]
    assert events[0].request[0].start.pose.position.z == start.pose.position.z
    assert len(events[1].response[0].plan.poses) == len(answer.path.poses)
    trig = recorded["/cdh_planner/execute/_service_event"]
    assert trig[1].response[0].success


def test_mcap_decoder_reads_the_same(sigterm_run):
    run_file, live, _, _ = sigterm_run
    by_topic = {}
    for topic, _, msg, _ in read_run(run_file):
        by_topic.setdefault(topic, []).append(msg)
    assert len(by_topic["/cdh_planner/cable_command"]) >= len(live["/cdh_planner/cable_command"])
    np.testing.assert_array_equal(by_topic["/cdh_planner/tension_envelope"][0].data,
                                  live["/cdh_planner/tension_envelope"][-1].data)


def test_sigkill_loses_nothing_that_was_published(domain, client, tmp_path):
    t0 = time.time()
    node = NodeProcess(domain, tmp_path, fake=True)
    _, _, rc = _plan_execute_and_signal(client, node, signal.SIGKILL, 0.7)
    assert rc == -signal.SIGKILL
    [run_file] = node.run_files()
    with pytest.raises(AnyReaderError):
        _rosbags_messages(run_file)       # no summary: rosbags refuses, read_run does not
    recorded = {}
    for topic, _, msg, _ in read_run(run_file):
        recorded.setdefault(topic, []).append(msg)
    for topic in ("/cdh_planner/path", "/cdh_planner/cable_trajectory",
                  "/cdh_planner/tension_envelope", "/cdh_planner/plan_result"):
        assert len(recorded[topic]) == 1
    stamps = {(c.header.stamp.sec, c.header.stamp.nanosec)
              for c in recorded["/cdh_planner/cable_command"]}
    live = _since(client.live["/cdh_planner/cable_command"], t0)
    assert len(live) >= 25
    assert all((c.header.stamp.sec, c.header.stamp.nanosec) in stamps for c in live)
    fixed = tmp_path / "recovered.mcap"
    assert recover_run(run_file, fixed) == sum(len(v) for v in recorded.values())
    assert len(_rosbags_messages(fixed)["/cdh_planner/cable_command"]) == len(stamps)


def test_replay_republishes_with_recorded_timing(domain, client, sigterm_run):
    run_file = sigterm_run[0]
    recorded = {t: [m for tt, _, m, _ in read_run(run_file) if tt == t]
                for t in ("/cdh_planner/cable_command", "/cdh_planner/path")}
    times = [lt for t, _, _, lt in read_run(run_file) if t == "/cdh_planner/cable_command"]
    t0 = time.time()
    proc = subprocess.Popen(cli("replay", str(run_file), "--rate", "2", "--topics",
                                "/cdh_planner/cable_command", "/cdh_planner/path",
                                "--delay", "10"),
                            env=ros_env(domain), stdout=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 20
    while proc.poll() is None and time.monotonic() < deadline:
        client.spin(0.05)
    client.spin(0.3)
    out = proc.stdout.read()
    assert proc.returncode == 0, out
    assert "republished" in out
    items = [(t, m) for t, m in client.live["/cdh_planner/cable_command"].items if t >= t0]
    assert len(items) == len(recorded["/cdh_planner/cable_command"])
    assert [stamp_s(m.header.stamp) for _, m in items] == \
        [stamp_s(m.header.stamp) for m in recorded["/cdh_planner/cable_command"]]
    arrival = np.diff([t for t, _ in items])
    original = np.diff(times) * 1e-9
    assert abs(np.sum(arrival) - np.sum(original) / 2) < 0.1 * np.sum(original) / 2
    assert np.median(arrival) == pytest.approx(np.median(original) / 2, rel=0.2)
    paths = _since(client.live["/cdh_planner/path"], t0)
    assert len(paths) == 1 and len(paths[0].poses) == len(recorded["/cdh_planner/path"][0].poses)


def test_replay_requests_and_call_against_a_live_node(domain, client, sigterm_run, tmp_path):
    run_file = sigterm_run[0]
    with NodeProcess(domain, tmp_path, fake=True):
        client.wait_for_node(20.0)
        r = run_cli(domain, "replay", str(run_file), "--requests")
        assert r.returncode == 0, r.stdout + r.stderr
        assert "request 1: MATCHES" in r.stdout and "1 of 1 answers match" in r.stdout
        # the task sequencer's command line
        r = run_cli(domain, "call", "--start", pose_text(Q1), "--goal", pose_text(Q2),
                    "--execute")
        assert r.returncode == 0, r.stdout + r.stderr
        for line in ("outcome: planned", "path length:", "duration:", "lowest tension margin:",
                     "log file: " + str(tmp_path), "execute: executing", "streamed:"):
            assert line in r.stdout, r.stdout
        r = run_cli(domain, "call", "--start", pose_text(Q1), "--goal", pose_text(Q2),
                    "--frame", "world")
        assert r.returncode == 1
        assert "outcome: NO PLAN (error code 202)" in r.stdout
        # a changed sphere: same requests, other answers
        assert client.set_parameters({"task.radius": 0.12}) == [(True, "")]
        r = run_cli(domain, "replay", str(run_file), "--requests")
        assert r.returncode == 1 and "request 1: DIFFERS" in r.stdout, r.stdout
    r = run_cli(domain, "call", "--start", pose_text(Q1), "--goal", pose_text(Q2),
                "--timeout", "1")
    assert r.returncode == 3 and "no service /cdh_planner/plan" in r.stderr
    r = run_cli(domain, "call", "--start", "1 2 3", "--goal", pose_text(Q2))
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--start" in r.stderr
