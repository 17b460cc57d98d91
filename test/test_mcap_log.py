"""Run recording to MCAP: what we write must read back, field by field, through rosbags (an
independent pure-Python reader), through read_run (mcap + mcap_ros2) and through rclpy's own
deserializer (the reference CDR), and must survive the recording process being killed."""

import os
import signal
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("mcap_ros2")
pytest.importorskip("rosbags")
pytest.importorskip("nav_msgs")

from builtin_interfaces.msg import Duration, Time  # noqa: E402
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue  # noqa: E402
from geometry_msgs.msg import Point, PoseStamped  # noqa: E402
from mcap.reader import make_reader  # noqa: E402
from nav_msgs.msg import Path as PathMsg  # noqa: E402
from nav_msgs.srv import GetPlan  # noqa: E402
from rosbags.highlevel import AnyReader, AnyReaderError  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import ColorRGBA, Float64MultiArray, MultiArrayDimension  # noqa: E402
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint  # noqa: E402
from visualization_msgs.msg import Marker, MarkerArray  # noqa: E402

from cdh_planner.recording.mcap_log import (  # noqa: E402
    MAGIC, REQUEST_RECEIVED, RESPONSE_SENT, RunRecorder, read_run, recover_run)
from cdh_planner.recording.ros_schemas import full_definition  # noqa: E402

from conftest import REPO, default_sigint
T0 = 1_700_000_000_000_000_000
GID = bytes(range(200, 216))            # bytes > 127: ROS 'char' is unsigned


# ---------------------------------------------------------------- messages as the node makes them

def _path():
    msg = PathMsg()
    msg.header.frame_id = "base"
    msg.header.stamp = Time(sec=1_700_000_000, nanosec=250)
    for i in range(3):
        pose = PoseStamped()
        pose.header = msg.header
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = 0.1 * i, -0.2, 1.5
        pose.pose.orientation.z, pose.pose.orientation.w = np.sin(0.1 * i), np.cos(0.1 * i)
        msg.poses.append(pose)
    return msg


def _trajectory():
    msg = JointTrajectory()
    msg.header.frame_id = "base"
    msg.joint_names = [f"winch_{i}" for i in range(6)]
    for k in range(2):
        pt = JointTrajectoryPoint()
        pt.positions = [1.0 + 0.01 * i + k for i in range(6)]
        pt.velocities = [0.1 * i for i in range(6)]
        pt.accelerations = [-0.05 * i for i in range(6)]
        pt.effort = [100.0 + i for i in range(6)]
        pt.time_from_start = Duration(sec=k, nanosec=500_000_000)
        msg.points.append(pt)
    return msg


def _envelope():
    msg = Float64MultiArray()
    n_wp, n_cable, n_bound = 2, 6, 3
    msg.layout.dim = [
        MultiArrayDimension(label="waypoint", size=n_wp, stride=n_wp * n_cable * n_bound),
        MultiArrayDimension(label="cable", size=n_cable, stride=n_cable * n_bound),
        MultiArrayDimension(label="bound", size=n_bound, stride=n_bound)]
    msg.data = np.linspace(10.0, 200.0, n_wp * n_cable * n_bound).tolist()
    return msg


def _command():
    msg = JointState()
    msg.header.stamp = Time(sec=5, nanosec=7)
    msg.name = [f"winch_{i}" for i in range(6)]
    msg.position = [1.1 + i for i in range(6)]
    msg.velocity = [0.01 * i for i in range(6)]
    msg.effort = [50.0 + i for i in range(6)]
    return msg


def _result():
    msg = DiagnosticStatus()
    msg.level = DiagnosticStatus.ERROR           # 'byte' field: rclpy gives b'\x02'
    msg.name = "cdh_planner/plan"
    msg.message = "goal not wrench-feasible"
    msg.hardware_id = "robot2"
    msg.values = [KeyValue(key="error_code", value="GOAL_INFEASIBLE"),
                  KeyValue(key="planning_time_s", value="0.125"),
                  KeyValue(key="run_id", value="run-0001")]
    return msg


def _markers():
    line = Marker(ns="cables", id=3, type=Marker.LINE_LIST, action=Marker.ADD)
    line.header.frame_id = "base"
    line.points = [Point(x=0.0, y=0.0, z=2.0), Point(x=1.0, y=0.5, z=0.5)]
    line.colors = [ColorRGBA(r=1.0, g=0.25, b=0.0, a=1.0), ColorRGBA(r=0.0, g=1.0, b=0.0, a=0.5)]
    line.scale.x = 0.01
    line.lifetime = Duration(sec=2, nanosec=0)
    platform = Marker(ns="platform", id=0, type=Marker.CUBE, frame_locked=True, text="p")
    platform.pose.position.z = 1.2
    platform.pose.orientation.w = 1.0
    platform.color = ColorRGBA(r=0.2, g=0.2, b=0.8, a=1.0)
    return MarkerArray(markers=[line, platform])


def _request():
    req = GetPlan.Request(tolerance=0.25)
    req.start = _path().poses[0]
    req.goal = _path().poses[2]
    return req


# topic -> (message, class for rclpy's deserializer, latched)
TOPICS = {
    "/cdh_planner/path": (_path(), PathMsg, True),
    "/cdh_planner/cable_trajectory": (_trajectory(), JointTrajectory, True),
    "/cdh_planner/tension_envelope": (_envelope(), Float64MultiArray, True),
    "/cdh_planner/cable_command": (_command(), JointState, False),
    "/cdh_planner/plan_result": (_result(), DiagnosticStatus, False),
    "/cdh_planner/markers": (_markers(), MarkerArray, False),
}
EVENT_TOPIC = "/cdh_planner/plan/_service_event"


def _events():
    """The GetPlan call as rclpy's Event messages: what rosbag2 would have recorded."""
    request = GetPlan.Event(request=[_request()])
    request.info.event_type, request.info.sequence_number = REQUEST_RECEIVED, 42
    request.info.client_gid = list(GID)
    request.info.stamp = Time(sec=T0 // 10**9 + 10, nanosec=0)
    response = GetPlan.Event(response=[GetPlan.Response(plan=_path())])
    response.info.event_type, response.info.sequence_number = RESPONSE_SENT, 42
    response.info.client_gid = list(GID)
    response.info.stamp = Time(sec=T0 // 10**9 + 11, nanosec=0)
    return [request, response]


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("mcap") / "run.mcap"
    with RunRecorder(path) as rec:
        for i, (topic, (msg, _, latched)) in enumerate(TOPICS.items()):
            rec.write(topic, msg, T0 + i, transient_local=latched)
        req, resp = _events()
        rec.write_service_event("/cdh_planner/plan", "nav_msgs/srv/GetPlan", REQUEST_RECEIVED,
                                request=req.request[0], sequence_number=42, client_gid=GID,
                                stamp_ns=T0 + 10 * 10**9, log_time_ns=T0 + 10 * 10**9)
        rec.write_service_event("/cdh_planner/plan/", "nav_msgs/srv/GetPlan", RESPONSE_SENT,
                                response=resp.response[0], sequence_number=42, client_gid=GID,
                                stamp_ns=T0 + 11 * 10**9, log_time_ns=T0 + 11 * 10**9)
    return path


def _expected():
    """(topic, rclpy message, class, log time) in log-time order."""
    out = [(t, m, cls, T0 + i) for i, (t, (m, cls, _)) in enumerate(TOPICS.items())]
    for k, event in enumerate(_events()):
        out.append((EVENT_TOPIC, event, GetPlan.Event, T0 + (10 + k) * 10**9))
    return out


def assert_same(written, read, where="msg"):
    """Every field of rclpy message ``written`` equals the same field of ``read`` (a rosbags,
    mcap_ros2 or rclpy object). Floats to float32 precision; bytes compared modulo 256 (mcap_ros2
    decodes 'char' as int8, rosbags as uint8)."""
    for name in written.get_fields_and_field_types():
        w, r, here = getattr(written, name), getattr(read, name), f"{where}.{name}"
        if hasattr(w, "get_fields_and_field_types"):
            assert_same(w, r, here)
        elif isinstance(w, list) and w and hasattr(w[0], "get_fields_and_field_types"):
            assert len(r) == len(w), here
            for i, (wi, ri) in enumerate(zip(w, r)):
                assert_same(wi, ri, f"{here}[{i}]")
        elif isinstance(w, list) and w and isinstance(w[0], str):
            assert list(r) == w, here
        elif isinstance(w, (str, bool)):
            assert r == w, here
        elif isinstance(w, bytes):                            # 'byte' scalar
            assert (r[0] if isinstance(r, bytes) else int(r)) == w[0], here
        elif np.asarray(w).dtype == np.uint8:               # uint8[] and char[]
            r = list(r) if isinstance(r, bytes) else r      # mcap_ros2: uint8[] as bytes
            assert list(np.asarray(r, dtype=np.int64) % 256) == list(np.asarray(w)), here
        else:
            w_arr, r_arr = np.asarray(w, dtype=float), np.asarray(r, dtype=float)
            assert w_arr.shape == r_arr.shape, here
            np.testing.assert_allclose(r_arr, w_arr, rtol=1e-6, err_msg=here)


# ---------------------------------------------------------------- reading back

def test_rosbags_reads_every_field(run_file):
    from rclpy.serialization import deserialize_message
    expected = _expected()
    with AnyReader([run_file]) as reader:
        got = list(reader.messages())
        assert len(got) == len(expected)
        for (conn, log_time, raw), (topic, msg, cls, t) in zip(got, expected):
            assert (conn.topic, log_time) == (topic, t)
            assert_same(msg, reader.deserialize(raw, conn.msgtype), topic)
            # rclpy's deserializer (the reference CDR) reads it back too. (Bytes differ from
            # rclpy's serialize_message only in alignment padding, which rmw leaves unset.)
            assert_same(msg, deserialize_message(raw, cls), f"rclpy {topic}")


def test_read_run_reads_every_field(run_file):
    got = read_run(run_file)
    expected = _expected()
    assert [(t, lt) for t, _, _, lt in got] == [(t, lt) for t, _, _, lt in expected]
    for (topic, type_name, decoded, _), (_, msg, _, _) in zip(got, expected):
        module, name = type(msg).__module__.split("."), type(msg).__name__
        assert type_name == f"{module[0]}/{module[1]}/{name}"
        assert_same(msg, decoded, topic)


def test_spot_checks(run_file):
    """The contract fields, spelled out."""
    got = {(topic, decoded.info.event_type if "service" in topic else None): decoded
           for topic, _, decoded, _ in read_run(run_file)}
    env = got["/cdh_planner/tension_envelope", None]
    assert [d.label for d in env.layout.dim] == ["waypoint", "cable", "bound"]
    assert [d.size for d in env.layout.dim] == [2, 6, 3] and len(env.data) == 36
    traj = got["/cdh_planner/cable_trajectory", None]
    assert traj.joint_names[5] == "winch_5"
    assert (traj.points[1].time_from_start.sec, traj.points[1].time_from_start.nanosec) \
        == (1, 500_000_000)
    assert traj.points[1].effort[5] == 105.0
    result = got["/cdh_planner/plan_result", None]
    assert result.level == 2 and result.values[0].key == "error_code"
    request = got[EVENT_TOPIC, REQUEST_RECEIVED]
    assert request.info.sequence_number == 42 and not request.response
    assert bytes(b % 256 for b in request.info.client_gid) == GID
    assert request.request[0].tolerance == 0.25
    assert request.info.stamp.sec == T0 // 10**9 + 10
    response = got[EVENT_TOPIC, RESPONSE_SENT]
    assert not response.request and len(response.response[0].plan.poses) == 3


def test_file_layout(run_file):
    """ros2 profile, ros2msg schemas in rosbag2's layout, cdr channels, QoS metadata."""
    with open(run_file, "rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
    assert summary.statistics.message_count == len(TOPICS) + 2
    schemas = {s.name: s for s in summary.schemas.values()}
    assert set(schemas) == {
        "nav_msgs/msg/Path", "trajectory_msgs/msg/JointTrajectory",
        "std_msgs/msg/Float64MultiArray", "sensor_msgs/msg/JointState",
        "diagnostic_msgs/msg/DiagnosticStatus", "visualization_msgs/msg/MarkerArray",
        "nav_msgs/msg/GetPlanEvent"}
    assert {s.encoding for s in schemas.values()} == {"ros2msg"}
    assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}

    text = schemas["nav_msgs/msg/Path"].data.decode()
    headers = [line for line in text.splitlines() if line.startswith("MSG: ")]
    # sorted, depth first, each once (rosbag2's LocalMessageDefinitionSource)
    assert headers == ["MSG: geometry_msgs/PoseStamped", "MSG: geometry_msgs/Pose",
                       "MSG: geometry_msgs/Point", "MSG: geometry_msgs/Quaternion",
                       "MSG: std_msgs/Header", "MSG: builtin_interfaces/Time"]
    assert text.count("\n" + "=" * 80 + "\nMSG: ") == len(headers)
    assert text.startswith("# An array of poses")
    # service events: rosbag2's layout under names every reader decodes (ros_schemas)
    event = schemas["nav_msgs/msg/GetPlanEvent"].data.decode()
    assert event.startswith("service_msgs/ServiceEventInfo info\n"
                            "nav_msgs/GetPlanRequest[<=1] request\n"
                            "nav_msgs/GetPlanResponse[<=1] response\n")
    assert "\nMSG: service_msgs/ServiceEventInfo\n" in event
    headers = [line for line in event.splitlines() if line.startswith("MSG: ")]
    assert {"MSG: nav_msgs/GetPlanRequest", "MSG: nav_msgs/GetPlanResponse"} <= set(headers)
    assert not any("_" in h.split("/")[-1] for h in headers)
    assert event == full_definition("nav_msgs/srv/GetPlan_Event")

    by_topic = {c.topic: c for c in summary.channels.values()}
    assert "durability: transient_local" in \
        by_topic["/cdh_planner/path"].metadata["offered_qos_profiles"]
    assert "durability: volatile" in \
        by_topic["/cdh_planner/cable_command"].metadata["offered_qos_profiles"]
    with AnyReader([run_file]) as reader:          # rosbags parses rosbag2's QoS YAML
        qos = {c.topic: c.ext.offered_qos_profiles[0] for c in reader.connections}
    assert qos["/cdh_planner/path"].durability.name == "TRANSIENT_LOCAL"
    assert qos["/cdh_planner/markers"].reliability.name == "RELIABLE"


def test_recorder_misuse(tmp_path):
    rec = RunRecorder(tmp_path / "r.mcap")
    rec.write("/a", _command(), 1)
    with pytest.raises(ValueError, match="cannot record"):
        rec.write("/a", _result(), 2)
    with pytest.raises(ValueError, match="not a service type"):
        rec.write_service_event("/s", "nav_msgs/msg/Path", REQUEST_RECEIVED)
    rec.close()
    rec.close()                                     # idempotent
    with pytest.raises(ValueError, match="closed"):
        rec.write("/a", _command(), 3)
    assert [t for t, *_ in read_run(tmp_path / "r.mcap")] == ["/a"]


# ---------------------------------------------------------------- killed recorder

CHILD = """
import sys, time
from sensor_msgs.msg import JointState
from cdh_planner.recording.mcap_log import RunRecorder
with RunRecorder(sys.argv[1]) as rec:
    for i in range(int(sys.argv[2])):
        rec.write("/cmd", JointState(name=["w"], position=[float(i)]), 1000 + i)
    print("ready", flush=True)
    time.sleep(30)
"""
N_KILL = 5


def _record_and_signal(path, sig):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get(
        "PYTHONPATH", "")]))
    child = subprocess.Popen([sys.executable, "-c", CHILD, str(path), str(N_KILL)],
                             stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env,
                             text=True, preexec_fn=default_sigint)
    try:
        assert child.stdout.readline().strip() == "ready"
        child.send_signal(sig)
        assert child.wait(timeout=120) == -sig   # a bound for a hang
    finally:
        child.kill()
        child.stdout.close()


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM], ids=lambda s: s.name)
def test_killed_run_is_readable(tmp_path, sig):
    """SIGKILL, and SIGTERM (the recorder installs no handler: same thing), leave a file
    without summary or footer. read_run still has every message; rosbags and the seeking
    mcap reader refuse the file until recover_run rewrites it."""
    path = tmp_path / "killed.mcap"
    _record_and_signal(path, sig)
    got = read_run(path)
    assert [(t, list(m.position), lt) for t, _, m, lt in got] == \
        [("/cmd", [float(i)], 1000 + i) for i in range(N_KILL)]
    assert not path.read_bytes().endswith(MAGIC)
    with pytest.raises(AnyReaderError):
        with AnyReader([path]):
            pass
    # the seeking reader parses the file's tail as a footer; what it raises depends on the
    # bytes it finds there (here RecordLengthLimitExceeded)
    with open(path, "rb") as f, pytest.raises(Exception):
        list(make_reader(f).iter_messages())

    fixed = tmp_path / "fixed.mcap"
    assert recover_run(path, fixed) == N_KILL
    with AnyReader([fixed]) as reader:
        values = [reader.deserialize(raw, c.msgtype).position[0]
                  for c, _, raw in reader.messages()]
        assert reader.connections[0].ext.offered_qos_profiles      # metadata kept
    assert values == [float(i) for i in range(N_KILL)]

    # killed mid-write: a torn tail is dropped, everything before it is kept
    data = path.read_bytes()
    for cut in range(1, 150):
        path.write_bytes(data[:-cut])
        got = read_run(path)
        assert len(got) >= N_KILL - 1
        assert [m.position[0] for _, _, m, _ in got] == [float(i) for i in range(len(got))]


def test_sigint_closes_the_file(tmp_path):
    """SIGINT raises KeyboardInterrupt in the child, so the ``with`` block closes the file."""
    path = tmp_path / "interrupted.mcap"
    _record_and_signal(path, signal.SIGINT)
    assert path.read_bytes().endswith(MAGIC)
    with AnyReader([path]) as reader:
        assert len(list(reader.messages())) == N_KILL


def test_damage_in_a_complete_file_is_not_hidden(run_file, tmp_path):
    """Only a torn tail is tolerated: a corrupted chunk in a finished file raises."""
    data = bytearray(run_file.read_bytes())
    where = data.index(b"winch_3")                 # inside a chunk of the trajectory
    data[where] ^= 0xFF
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    with pytest.raises(Exception, match="(?i)crc"):
        read_run(damaged)
