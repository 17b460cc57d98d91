"""Run recording and replay over real DDS, nodes in their own processes and ROS domain:
a node stopped with SIGTERM mid-stream leaves a complete MCAP holding, field by field, what
subscribers received, which stock mcap_ros2, rosbags and rosbags-convert read whole; one
killed with SIGKILL leaves a readable file that lost nothing it had published, which
``cdh-planner recover`` (named in the node's start-up line) completes; ``cdh-planner replay``
republishes with the recorded timing and re-sends requests with the recorded parameters
(rotated files and runtime parameter changes included); ``cdh-planner call`` prints the
outcome and exits by it.

The node runs around the TEST DOUBLE planner (test/doubles/fake_planner.py): these are tests
of recording and replay, not of planning.
"""

import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")
pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticStatus  # noqa: E402
from mcap.reader import make_reader  # noqa: E402
from mcap_ros2.decoder import DecoderFactory  # noqa: E402
from nav_msgs.msg import Path as PathMsg  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rosbags.highlevel import AnyReader, AnyReaderError  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from cdh_planner_interfaces.msg import TensionEnvelope  # noqa: E402
from trajectory_msgs.msg import JointTrajectory  # noqa: E402

from cdh_planner.recording.mcap_log import REQUEST_RECEIVED, RESPONSE_SENT, read_run  # noqa: E402
from ros_harness import (Q1, Q2, Collector, NodeProcess, claimed_domain, cli,  # noqa: E402
                         pose_text, ros_env, run_cli, sphere_pose_msg, stamp_s)

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
TOPICS = {"/cdh_planner/path": (PathMsg, LATCHED),
          "/cdh_planner/planned_cable_trajectory": (JointTrajectory, LATCHED),
          "/cdh_planner/tension_envelope": (TensionEnvelope, LATCHED),
          "/cdh_planner/plan_result": (DiagnosticStatus, LATCHED),
          "/cdh_planner/cable_command": (JointState, 100)}


@pytest.fixture(scope="module")
def live(client):
    """{topic: Collector} of TOPICS on the shared ``client`` (conftest.py), from the first
    test that asks on."""
    return {t: Collector(client.node, cls, t, qos) for t, (cls, qos) in TOPICS.items()}


def _plan_execute_and_signal(client, live, node, sig, commands):
    """Plan q1 -> q2, execute, send ``sig`` to the node once ``commands`` cable commands of
    the motion (about 2 s at 50 Hz) have arrived: mid-way, however loaded the machine."""
    client.wait_for_node(20.0)
    start, goal = sphere_pose_msg(Q1), sphere_pose_msg(Q2)
    answer = client.plan(start, goal, timeout_s=30)
    assert answer.success
    t0 = time.time()
    assert client.execute()[0]
    got = live["/cdh_planner/cable_command"]
    assert client.spin_until(lambda: len(_since(got, t0)) >= commands, 30.0)
    rc = node.stop(sig)
    if sig == signal.SIGTERM:   # its last message, the hold, is in (not in a later test's)
        assert client.spin_until(lambda: not any(_since(got, t0)[-1].velocity), 10.0)
    return answer, start, rc


def _since(collector, t0):
    return [m for t, m in collector.items if t >= t0]


@pytest.fixture(scope="module")
def sigterm_run(domain, client, live, tmp_path_factory):
    """A node that planned, executed, and got SIGTERM mid-stream; (file, live, answer, start)."""
    runs = tmp_path_factory.mktemp("sigterm")
    t0 = time.time()
    node = NodeProcess(domain, runs, fake=True)
    answer, start, rc = _plan_execute_and_signal(client, live, node, signal.SIGTERM, 30)
    assert rc == 0, node.log()
    assert "shutting down while executing: held the last setpoint" in node.log()
    [run_file] = node.run_files()
    assert f"recording to {run_file}; if the node is killed: cdh-planner recover {run_file}" \
        in node.log()
    received = {t: _since(c, t0) for t, c in live.items()}
    return run_file, received, answer, start


def _rosbags_messages(path):
    out = {}
    with AnyReader([path]) as reader:
        for conn, _, raw in reader.messages():
            out.setdefault(conn.topic, []).append(reader.deserialize(raw, conn.msgtype))
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
    [traj] = recorded["/cdh_planner/planned_cable_trajectory"]
    live_traj = live["/cdh_planner/planned_cable_trajectory"][-1]
    assert list(traj.joint_names) == list(live_traj.joint_names)
    for a, b in zip(traj.points, live_traj.points):
        np.testing.assert_array_equal(a.positions, b.positions)
        np.testing.assert_array_equal(a.velocities, b.velocities)
        assert (a.time_from_start.sec, a.time_from_start.nanosec) == \
            (b.time_from_start.sec, b.time_from_start.nanosec)
    [env] = recorded["/cdh_planner/tension_envelope"]
    live_env = live["/cdh_planner/tension_envelope"][-1]
    assert list(env.winch_names) == list(live_env.winch_names)
    for a, b in zip(env.points, live_env.points, strict=True):
        for bound in ("tension_min", "tension_nominal", "tension_max"):
            np.testing.assert_array_equal(getattr(a, bound), getattr(b, bound))
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
    # the parameters at start
    [params] = recorded["/parameter_events"]
    assert params.node == "/cdh_planner" and not params.changed_parameters
    values = {p.name: p.value for p in params.new_parameters}
    assert values["task.type"].string_value == "sphere"
    assert values["log_max_file_mb"].double_value == 100.0


def test_every_record_decodes_in_every_tool(sigterm_run, tmp_path):
    """Stock mcap_ros2 (no aliasing), rosbags, and rosbags-convert to a rosbag2 directory."""
    run_file = sigterm_run[0]
    with open(run_file, "rb") as f:
        total = make_reader(f).get_summary().statistics.message_count
        f.seek(0)
        decoded = list(make_reader(f, decoder_factories=[DecoderFactory()])
                       .iter_decoded_messages())
    assert len(decoded) == total > 40
    assert sum(len(v) for v in _rosbags_messages(run_file).values()) == total
    dst = tmp_path / "rosbag2"
    r = subprocess.run([str(Path(sys.executable).with_name("rosbags-convert")), "--src",
                        str(run_file), "--dst", str(dst)], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr
    converted = _rosbags_messages(dst)
    assert sum(len(v) for v in converted.values()) == total
    assert len(converted["/cdh_planner/plan/_service_event"]) == 2


def test_mcap_decoder_reads_the_same(sigterm_run):
    run_file, live, _, _ = sigterm_run
    by_topic = {}
    for topic, _, msg, _ in read_run(run_file):
        by_topic.setdefault(topic, []).append(msg)
    assert len(by_topic["/cdh_planner/cable_command"]) >= len(live["/cdh_planner/cable_command"])
    recorded_env = by_topic["/cdh_planner/tension_envelope"][0]
    live_env = live["/cdh_planner/tension_envelope"][-1]
    for a, b in zip(recorded_env.points, live_env.points, strict=True):
        np.testing.assert_array_equal(a.tension_max, b.tension_max)


def test_sigkill_loses_nothing_that_was_published(tmp_path):
    """In a domain of its own: the killed node's endpoints stay in the others' graphs until
    their lease ends, and a later node of the same name in the module's domain could be
    taken for it (a request sent to the dead one only is never answered)."""
    from cdh_planner.ros.client import PlannerClient
    with claimed_domain() as domain, PlannerClient(domain_id=domain) as client:
        live = {t: Collector(client.node, cls, t, qos) for t, (cls, qos) in TOPICS.items()}
        _sigkill_case(domain, client, live, tmp_path)


def _sigkill_case(domain, client, live, tmp_path):
    t0 = time.time()
    node = NodeProcess(domain, tmp_path, fake=True)
    _, _, rc = _plan_execute_and_signal(client, live, node, signal.SIGKILL, 25)
    assert rc == -signal.SIGKILL
    [run_file] = node.run_files()
    with pytest.raises(AnyReaderError):
        _rosbags_messages(run_file)       # no summary: rosbags refuses, read_run does not
    recorded = {}
    for topic, _, msg, _ in read_run(run_file):
        recorded.setdefault(topic, []).append(msg)
    for topic in ("/cdh_planner/path", "/cdh_planner/planned_cable_trajectory",
                  "/cdh_planner/tension_envelope", "/cdh_planner/plan_result"):
        assert len(recorded[topic]) == 1
    stamps = {(c.header.stamp.sec, c.header.stamp.nanosec)
              for c in recorded["/cdh_planner/cable_command"]}
    # every command recorded but the last was published (the stream writes one only after
    # publishing the one before): let those in flight arrive here, not in a later test
    # (bounded, not asserted: a killed writer may not have sent them)
    sent = [(c.header.stamp.sec, c.header.stamp.nanosec)
            for c in recorded["/cdh_planner/cable_command"][:-1]]
    client.spin_until(lambda: set(sent) <= {
        (c.header.stamp.sec, c.header.stamp.nanosec)
        for c in _since(live["/cdh_planner/cable_command"], t0)}, 5.0)
    commands = _since(live["/cdh_planner/cable_command"], t0)
    assert len(commands) >= 25
    assert all((c.header.stamp.sec, c.header.stamp.nanosec) in stamps for c in commands)
    # the start-up line says what to do; doing it gives a file every tool reads
    assert f"if the node is killed: cdh-planner recover {run_file}" in node.log()
    fixed = tmp_path / "recovered.mcap"
    r = run_cli(domain, "recover", str(run_file), "-o", str(fixed))
    total = sum(len(v) for v in recorded.values())
    assert r.returncode == 0, r.stdout + r.stderr
    assert f"{total} messages on" in r.stdout and "did not end normally" in r.stdout
    assert len(_rosbags_messages(fixed)["/cdh_planner/cable_command"]) == len(stamps)
    with open(fixed, "rb") as f:
        assert len(list(make_reader(f, decoder_factories=[DecoderFactory()])
                        .iter_decoded_messages())) == total


def test_replay_republishes_every_message_in_recorded_order(domain, client, live,
                                                            sigterm_run):
    """Over DDS: every recorded command arrives, in recorded order, with its recorded stamp,
    and the path once. The pace (recorded intervals / rate) is
    test_replay_publishes_at_the_recorded_times_over_the_rate's, on a clock of its own."""
    run_file = sigterm_run[0]
    recorded = {t: [m for tt, _, m, _ in read_run(run_file) if tt == t]
                for t in ("/cdh_planner/cable_command", "/cdh_planner/path")}
    t0 = time.time()
    commands, paths = live["/cdh_planner/cable_command"], live["/cdh_planner/path"]
    proc = subprocess.Popen(cli("replay", str(run_file), "--commands", "--rate", "2", "--topics",
                                "/cdh_planner/cable_command", "/cdh_planner/path",
                                "--delay", "10"),
                            env=ros_env(domain), stdout=subprocess.PIPE, text=True)
    assert client.spin_until(lambda: proc.poll() is not None, 30.0)      # only a hang
    out = proc.stdout.read()
    assert proc.returncode == 0, out
    assert f"republished {len(recorded['/cdh_planner/cable_command']) + 1} messages" in out
    assert "rate 2;" in out
    # it waited for every subscriber to acknowledge the last: all are here or on their way
    assert client.spin_until(lambda: len(_since(commands, t0)) >= len(
        recorded["/cdh_planner/cable_command"]) and _since(paths, t0), 10.0)
    assert [stamp_s(m.header.stamp) for m in _since(commands, t0)] == \
        [stamp_s(m.header.stamp) for m in recorded["/cdh_planner/cable_command"]]
    [path] = _since(paths, t0)
    assert len(path.poses) == len(recorded["/cdh_planner/path"][0].poses)


def test_replay_publishes_at_the_recorded_times_over_the_rate(sigterm_run):
    """replay_topics on a clock of the test's own (no sleeping): each command goes out at
    its recorded time after the first, divided by the rate."""
    from cdh_planner.ros import replay as R
    records = R.select_topics(R.read_records(sigterm_run[0]), commands=True,
                              topics=["/cdh_planner/cable_command"])
    now, sent = [0.0], []

    class Publisher:
        def get_subscription_count(self):
            return 1

        def publish(self, data):
            sent.append(now[0])

        def wait_for_all_acked(self, _):
            return True

    class Node:
        def create_publisher(self, *args):
            return Publisher()

    def sleep(s):
        now[0] += s

    stats = R.replay_topics(Node(), records, rate=2.0, clock=lambda: now[0], sleep=sleep)
    recorded = (np.array([r.log_time_ns for r in records]) - records[0].log_time_ns) * 1e-9
    assert len(sent) == len(records) > 25 and stats.late_s == 0.0
    # 1 ns: the schedule sums float intervals; the log times are whole ns
    np.testing.assert_allclose(np.array(sent) - sent[0], recorded / 2.0, rtol=0, atol=1e-9)


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
                     "log file: " + str(tmp_path), "execute: executing", "streamed:",
                     "execution completed: execution finished"):
            assert line in r.stdout, r.stdout
        r = run_cli(domain, "call", "--start", pose_text(Q1), "--goal", pose_text(Q2),
                    "--frame", "map")          # not on TF
        assert r.returncode == 1
        assert "outcome: NO PLAN (error code 202)" in r.stdout
        # a changed sphere: replay sets the recorded parameters first (the next test shows
        # the answers that differ without them, and why)
        assert client.set_parameters({"task.radius": 0.12}) == [(True, "")]
        r = run_cli(domain, "replay", str(run_file), "--requests")
        assert r.returncode == 0 and "request 1: MATCHES" in r.stdout, r.stdout
        assert re.search(r"request 1: set as recorded: \d+ parameters", r.stdout), r.stdout
        assert client.get_parameters(["task.radius"]) == {"task.radius": 0.13}
    r = run_cli(domain, "call", "--start", pose_text(Q1), "--goal", pose_text(Q2),
                "--timeout", "1")
    assert r.returncode == 1 and "no service /cdh_planner/plan" in r.stderr
    r = run_cli(domain, "call", "--start", "1 2 3", "--goal", pose_text(Q2))
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--start" in r.stderr


def test_replay_after_parameter_changes_matches_every_request(domain, client, tmp_path):
    """A node whose parameters change between requests, recording to rotated files; a fresh
    node gets the recorded changes before each request and answers every one as recorded.
    Without them, the answers that came after a change differ, and the replay says why."""
    node = NodeProcess(domain, tmp_path / "recorded", fake=True,
                       params=["log_max_file_mb:=0.06"])
    try:
        client.wait_for_node(20.0)
        start, goal = sphere_pose_msg(Q1), sphere_pose_msg(Q2)
        changes = {2: {"task.radius": 0.12}, 4: {"task.radius": 0.125, "stream_rate_hz": 40.0}}
        for k in range(1, 6):
            for name, value in changes.get(k, {}).items():    # one set call each
                assert client.set_parameters({name: value}) == [(True, "")]
            assert client.plan(start, goal, timeout_s=30).success
    finally:
        assert node.stop() == 0, node.log()
    files = node.run_files()
    assert len(files) >= 2                                  # rotated
    assert node.log().count("; if the node is killed: cdh-planner recover ") == len(files)
    with NodeProcess(domain, tmp_path / "fresh", fake=True, params=["log_enabled:=false"]):
        client.wait_for_node(20.0)
        r = run_cli(domain, "replay", *map(str, files), "--requests")
        assert r.returncode == 0, r.stdout + r.stderr
        assert "5 of 5 answers match the recording" in r.stdout, r.stdout
        assert "request 2: set as recorded: task.radius" in r.stdout
        assert "stream_rate_hz" not in r.stdout          # not a parameter of the answers
        assert "not applied" not in r.stdout
        # the node keeps the last recorded values; without setting the recorded ones, the
        # answers planned on another sphere differ, each saying why
        r = run_cli(domain, "replay", *map(str, files), "--requests", "--keep-parameters")
        assert r.returncode == 1, r.stdout + r.stderr
        assert "2 of 5 answers match the recording" in r.stdout, r.stdout
        for k, radius in ((1, 0.13), (2, 0.12), (3, 0.12)):
            line = next(x for x in r.stdout.splitlines() if x.startswith(f"request {k}:"))
            assert "DIFFERS" in line and (f"why: parameters differ: task.radius is 0.125 "
                                          f"here, {radius:g} in the recording") in line, line


def test_replay_caps_each_wait(domain, client, tmp_path):
    """A 30-year gap between two recorded messages is waited --max-gap seconds, and said."""
    from cdh_planner.recording.mcap_log import RunRecorder
    path = tmp_path / "gap.mcap"
    with RunRecorder(path) as rec:
        rec.write("/cmd", JointState(name=["w"], position=[0.0]), 10**9)
        rec.write("/cmd", JointState(name=["w"], position=[1.0]), 10**9 + 30 * 365 * 86400 * 10**9)
    # timeout=30: only a hang (an uncut wait would be 30 years); the cut itself is
    # test_run_log.py's test_waits_are_capped, on a clock of its own
    r = run_cli(domain, "replay", str(path), "--delay", "0", "--max-gap", "0.5", timeout=30)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "1 wait between messages longer than --max-gap 0.5 s cut to 0.5 s" in r.stdout
    assert "republished 2 messages" in r.stdout


def test_replay_leaves_command_topics_alone_unless_asked(tmp_path):
    """On a live system a replayed command moves the robot: without --commands, replay
    skips cable_command and cable_trajectory, and naming one in --topics is refused."""
    from sensor_msgs.msg import JointState
    from cdh_planner import cli as cli_module
    from cdh_planner.recording.mcap_log import RunRecorder
    from cdh_planner.ros.replay import read_records, select_topics
    path = tmp_path / "cmd.mcap"
    with RunRecorder(path) as rec:
        rec.write("/cdh_planner/cable_command", JointState(name=["w"], position=[0.0]), 10**9)
        rec.write("/cdh_planner/joint_states_seen", JointState(name=["w"], position=[0.0]), 10**9)
    records = read_records(path)
    assert {r.topic for r in select_topics(records)} == {"/cdh_planner/joint_states_seen"}
    assert len(select_topics(records, commands=True)) == 2
    assert cli_module.main(["replay", str(path), "--topics", "/cdh_planner/cable_command"]) == 2
