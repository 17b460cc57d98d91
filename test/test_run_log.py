"""The node's run log without a ROS graph: every record of what the node writes decodes in
the stock readers (mcap_ros2's DecoderFactory, rosbags' AnyReader) and rosbags-convert turns
it into a rosbag2 directory; parameters are recorded and handed to replay; files rotate
without splitting a call; what is not a recording is refused with the reason; replay caps
its waits; older files (rosbag2's service names) are read and recovered."""

import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("mcap_ros2")
pytest.importorskip("rosbags")
pytest.importorskip("rclpy")

from geometry_msgs.msg import PoseStamped  # noqa: E402
from mcap.reader import make_reader  # noqa: E402
from mcap.writer import Writer  # noqa: E402
from mcap_ros2.decoder import DecoderFactory  # noqa: E402
from nav_msgs.msg import Path as PathMsg  # noqa: E402
from nav_msgs.srv import GetPlan  # noqa: E402
from rcl_interfaces.msg import ParameterType  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rosbags.highlevel import AnyReader  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from cdh_planner.errors import InputError  # noqa: E402
from cdh_planner.recording.mcap_log import (  # noqa: E402
    MAGIC, REQUEST_RECEIVED, RESPONSE_SENT, NotARecording, check_recording, read_run, recover)
from cdh_planner.ros import replay as R  # noqa: E402
from cdh_planner.ros.core.run_log import PARAMETER_EVENTS, RunLog  # noqa: E402

NODE = "/cdh_planner"
SERVICE = "/cdh_planner/plan"
T0 = 1_700_000_000 * 10**9          # log times (the first record opens the file)


def _params(**values):
    return [Parameter(name.replace("__", "."), value=v).to_parameter_msg()
            for name, v in values.items()]


INITIAL = _params(task__radius=0.1, planner__strategy="auto", base_frame="cdh_base",
                  stream_rate_hz=50.0, log_dir="/tmp", robot__load__force=[0.0, 0.0, -10.0])


def _pose(x):
    msg = PoseStamped()
    msg.header.frame_id = "cdh_base"
    msg.pose.position.x, msg.pose.orientation.w = float(x), 1.0
    return msg


def _call(log, seq, t, n_poses=3):
    request = GetPlan.Request(start=_pose(seq), goal=_pose(seq + 1))
    log.service_event(SERVICE, "nav_msgs/srv/GetPlan", REQUEST_RECEIVED, request=request,
                      sequence_number=seq, log_time_ns=t)
    path = PathMsg()
    path.header.frame_id = "cdh_base"
    path.poses = [_pose(seq + i / n_poses) for i in range(n_poses)]
    log.write(f"{NODE}/path", path, t + 1, transient_local=True)
    log.service_event(SERVICE, "nav_msgs/srv/GetPlan", RESPONSE_SENT,
                      response=GetPlan.Response(plan=path), sequence_number=seq,
                      log_time_ns=t + 2)


@pytest.fixture
def run(tmp_path):
    """A node's run: parameters at start, a call, a change, a call, execute, stop; the file."""
    log = RunLog(tmp_path, True, warn=pytest.fail, info=lambda _: None, node_name=NODE)
    log.parameters(INITIAL, initial=True)
    _call(log, 1, T0 + 10_000)
    path = log.path
    log.parameters(_params(task__radius=0.12, stream_rate_hz=100.0), log_time_ns=T0 + 20_000)
    log.parameters(_params(stream_rate_hz=60.0), log_time_ns=T0 + 20_500)
    _call(log, 2, T0 + 30_000)
    for event, kw in ((REQUEST_RECEIVED, {"request": Trigger.Request()}),
                      (RESPONSE_SENT, {"response": Trigger.Response(success=True,
                                                                    message="executing")})):
        log.service_event(f"{NODE}/execute", "std_srvs/srv/Trigger", event, log_time_ns=T0 + 40_000,
                          **kw)
    log.write(f"{NODE}/cable_command", JointState(name=["w"], position=[1.0]), T0 + 41_000)
    log.close()
    return Path(path)


N_RECORDS = 1 + 3 + 2 + 3 + 2 + 1


def test_every_record_decodes_in_stock_readers(run, tmp_path):
    """mcap_ros2's own DecoderFactory (no aliasing), rosbags' AnyReader with the types the
    file defines, and rosbags-convert to a rosbag2 directory (sqlite3 and mcap storage)."""
    with open(run, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        decoded = [(c.topic, s.name, m) for s, c, _, m in reader.iter_decoded_messages()]
    assert len(decoded) == N_RECORDS
    types = {name for _, name, _ in decoded}
    assert types == {"rcl_interfaces/msg/ParameterEvent", "nav_msgs/msg/GetPlanEvent",
                     "nav_msgs/msg/Path", "std_srvs/msg/TriggerEvent",
                     "sensor_msgs/msg/JointState"}
    events = [m for t, _, m in decoded if t == f"{SERVICE}/_service_event"]
    assert [e.info.event_type for e in events] == [REQUEST_RECEIVED, RESPONSE_SENT] * 2
    assert len(events[1].response[0].plan.poses) == 3
    trigger = [m for t, _, m in decoded if t == f"{NODE}/execute/_service_event"]
    assert trigger[1].response[0].message == "executing"

    def rosbags_count(paths):
        with AnyReader(paths) as reader:
            msgs = [(c.topic, reader.deserialize(raw, c.msgtype))
                    for c, _, raw in reader.messages()]
        assert [e.info.event_type for t, e in msgs if t.endswith("plan/_service_event")] == \
            [REQUEST_RECEIVED, RESPONSE_SENT] * 2
        return len(msgs)

    assert rosbags_count([run]) == N_RECORDS
    convert = Path(sys.executable).with_name("rosbags-convert")
    for storage in ("sqlite3", "mcap"):
        dst = tmp_path / f"converted_{storage}"
        r = subprocess.run([str(convert), "--src", str(run), "--dst", str(dst),
                            "--dst-storage", storage], capture_output=True, text=True,
                           timeout=60)
        assert r.returncode == 0, r.stdout + r.stderr
        assert (dst / "metadata.yaml").is_file()
        assert rosbags_count([dst]) == N_RECORDS


def test_parameters_are_recorded_and_given_to_replay(run):
    records = R.read_records(run)
    events = [(t, m) for t, _, m, _ in read_run(run) if t == PARAMETER_EVENTS]
    assert [len(m.new_parameters) for _, m in events] == [len(INITIAL), 0, 0]
    assert events[0][1].node == NODE
    assert [p.name for p in events[1][1].changed_parameters] == ["task.radius",
                                                                  "stream_rate_hz"]
    plans = R.recorded_plans(records)
    assert [p.sequence for p in plans] == [1, 2]
    # the snapshot, then the change; only what decides answers (not stream_rate_hz, log_dir)
    assert [[p.name for p in s] for s in plans[0].parameter_sets] == \
        [["task.radius", "planner.strategy", "base_frame", "robot.load.force"]]
    assert [[p.name for p in s] for s in plans[1].parameter_sets] == [["task.radius"]]
    assert R.parameter_value(plans[0].parameters["task.radius"]) == 0.1
    assert R.parameter_value(plans[1].parameters["task.radius"]) == 0.12
    assert R.parameter_value(plans[1].parameters["robot.load.force"]) == [0.0, 0.0, -10.0]
    assert R.parameter_differences(plans[1].parameters, {
        "task.radius": 0.1, "planner.strategy": "auto", "base_frame": "cdh_base",
        "robot.load.force": [0, 0, -10]}) == "task.radius is 0.1 here, 0.12 in the recording"
    unset = Parameter("robot.contact_ellipsoid.matrix").to_parameter_msg()
    assert unset.value.type == ParameterType.PARAMETER_NOT_SET
    assert R.settable([unset, *INITIAL[:1]]) == ([INITIAL[0]], ["robot.contact_ellipsoid.matrix"])
    # republished by default: not the parameters, not the calls, not the commands
    assert {r.topic for r in R.select_topics(records)} == {f"{NODE}/path"}
    assert {r.topic for r in R.select_topics(records, commands=True)} == {f"{NODE}/path",
                                                                         f"{NODE}/cable_command"}
    assert {r.topic for r in R.select_topics(records, [PARAMETER_EVENTS])} == {PARAMETER_EVENTS}


def test_rotation_keeps_calls_whole_and_starts_each_file_with_the_parameters(tmp_path):
    said = []
    log = RunLog(tmp_path, True, warn=pytest.fail, info=said.append, node_name=NODE,
                 max_bytes=20_000)
    log.parameters(INITIAL, initial=True)
    for seq in range(1, 9):
        _call(log, seq, T0 + seq * 1000, n_poses=20)
        first = first if seq > 1 else log.path
    log.close()
    files = sorted(tmp_path.glob("*.mcap"), key=lambda p: p.stat().st_mtime_ns)
    assert str(files[0]) == first and 2 <= len(files) <= 4
    assert [f"recording to {f}" in s for f, s in zip(files, said)] == [True] * len(files)
    assert all("; if the node is killed: cdh-planner recover " in s for s in said)
    assert ["reached" in s for s in said] == [False] + [True] * (len(files) - 1)
    sequences = []
    for f in files:
        assert check_recording(f)[1]                                   # complete
        got = read_run(f)
        assert got[0][0] == PARAMETER_EVENTS and len(got[0][2].new_parameters) == len(INITIAL)
        plans = R.recorded_plans(R.read_records(f))
        assert plans and all(p.response is not None for p in plans)   # request + response
        assert R.parameter_value(plans[0].parameters["task.radius"]) == 0.1
        sequences += [p.sequence for p in plans]
    assert sequences == list(range(1, 9))


class Overflowing:
    """A JointState whose stamp does not fit its int32 field (as a message built from an
    absurd duration would be)."""

    header = {"stamp": {"sec": 2**40, "nanosec": 0}, "frame_id": ""}
    name, position, velocity, effort = [], [], [], []

    def get_fields_and_field_types(self):
        return JointState.get_fields_and_field_types()


Overflowing.__name__, Overflowing.__module__ = "JointState", "sensor_msgs.msg._joint_state"


def test_a_message_that_cannot_be_encoded_is_dropped_and_recording_goes_on(tmp_path):
    warnings = []
    log = RunLog(tmp_path, True, warn=warnings.append, info=lambda _: None)
    log.write("/cmd", JointState(name=["w"], position=[0.0]), 1)
    log.write("/cmd", Overflowing(), 2)
    log.write("/cmd", Overflowing(), 3)
    log.write("/cmd", JointState(name=["w"], position=[1.0]), 4)
    log.service_event(SERVICE, "nav_msgs/srv/GetPlan", REQUEST_RECEIVED,    # both: refused
                      request=GetPlan.Request(), response=GetPlan.Response(), log_time_ns=5)
    log.close()
    assert len(warnings) == 2 and "not recorded: a message on /cmd" in warnings[0]
    assert "not both" in warnings[1]
    [path] = tmp_path.glob("*.mcap")
    assert [lt for _, _, _, lt in read_run(path)] == [1, 4]


# ---------------------------------------------------------------- not a recording

def _not_recordings(tmp_path, good):
    data = Path(good).read_bytes()
    files = {"empty": b"", "stub": bytes(range(100)), "text": b"# not MCAP\n" * 30,
             "cut before the first message": data[:100], "magic only": MAGIC}
    out = {}
    for name, content in files.items():
        out[name] = tmp_path / f"{name.replace(' ', '_')}.mcap"
        out[name].write_bytes(content)
    out["directory"] = tmp_path
    return out


def test_what_is_not_a_recording_is_refused_with_the_reason(run, tmp_path):
    reasons = {"empty": r"empty \(0 bytes\)", "stub": "not an MCAP file",
               "text": "not an MCAP file", "cut before the first message": "no complete message",
               "magic only": "no complete message", "directory": "a directory"}
    for name, path in _not_recordings(tmp_path, run).items():
        with pytest.raises(InputError, match=reasons[name]):
            R.read_records(path)
        with pytest.raises(NotARecording, match=reasons[name]):
            recover(path, tmp_path / "out.mcap")
        assert not (tmp_path / "out.mcap").exists()


def test_replay_and_recover_commands_refuse_in_one_line(run, tmp_path, capsys):
    from cdh_planner import cli
    for name, path in _not_recordings(tmp_path, run).items():
        for args in (["replay", str(path)], ["replay", str(path), "--requests"],
                     ["recover", str(path), "-o", str(tmp_path / "out.mcap")]):
            rc = cli.main(args)
            out, err = capsys.readouterr()
            assert rc == 2, (name, args, out, err)
            assert out == "" and err.count("\n") == 1, (name, err)
            assert "messages on" not in err
    # the wait cap must be a finite number
    assert cli.main(["replay", str(run), "--max-gap", "inf"]) == 2
    assert "--max-gap" in capsys.readouterr().err


def test_waits_are_capped(run):
    records = R.select_topics(R.read_records(run))
    far = R.Record(records[-1].topic, records[-1].type_name, records[-1].data,
                   records[-1].log_time_ns + 30 * 365 * 86400 * 10**9, False)
    records.append(far)          # 30 years later
    offsets, capped, skipped = R.schedule(records, rate=1.0, max_gap_s=2.0)
    assert capped == 1 and skipped > 9e8 and offsets[-1] - offsets[-2] == pytest.approx(2.0)
    assert offsets[:-1] == R.schedule(records[:-1], 1.0, 2.0)[0]

    class Publisher:
        sent = []

        def get_subscription_count(self):
            return 1

        def publish(self, data):
            self.sent.append(data)

        def wait_for_all_acked(self, _):
            return True

    class Node:
        def create_publisher(self, *args):
            return Publisher()

    now = [0.0]

    def sleep(s):
        now[0] += s
    stats = R.replay_topics(Node(), records, clock=lambda: now[0], sleep=sleep, max_gap_s=3.0)
    assert stats.capped == 1 and len(Publisher.sent) == len(records)
    assert now[0] < 10.0          # a 30-year gap replayed in seconds


# ---------------------------------------------------------------- older files

def _with_rosbag2_names(src, dst):
    """``src`` rewritten as files were recorded before: rosbag2's service names."""
    import re
    with open(src, "rb") as f, open(dst, "wb") as out:
        reader = make_reader(f)
        writer = Writer(out)
        writer.start(profile="ros2", library="old")
        schemas, channels = {}, {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if schema.id not in schemas:
                name = re.sub(r"^(\w+)/msg/(GetPlan|Trigger)(Event)$", r"\1/srv/\2_\3",
                              schema.name)
                text = re.sub(r"/(GetPlan|Trigger)(Request|Response)\b", r"/\1_\2",
                              schema.data.decode())
                schemas[schema.id] = writer.register_schema(name, "ros2msg", text.encode())
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic, "cdr", schemas[schema.id], dict(channel.metadata))
            writer.add_message(channels[channel.id], message.log_time, message.data,
                               message.publish_time)
        writer.finish()


def test_files_with_rosbag2_service_names_are_read_and_recovered(run, tmp_path):
    old = tmp_path / "old.mcap"
    _with_rosbag2_names(run, old)
    with open(old, "rb") as f:
        names = {s.name for s in make_reader(f).get_summary().schemas.values()}
    assert "nav_msgs/srv/GetPlan_Event" in names
    with open(old, "rb") as f, pytest.raises(Exception, match="invalid message name"):
        list(make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages())
    assert [t for t, *_ in read_run(old)] == [t for t, *_ in read_run(run)]
    assert len(R.recorded_plans(R.read_records(old))) == 2
    fixed = tmp_path / "fixed.mcap"
    result = recover(old, fixed)
    assert result.complete and result.messages == N_RECORDS
    assert set(result.renamed_schemas) == {"nav_msgs/srv/GetPlan_Event",
                                           "std_srvs/srv/Trigger_Event"}
    with open(fixed, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert len(list(reader.iter_decoded_messages())) == N_RECORDS
