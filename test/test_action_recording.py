"""PlanPath goals in the run log: a node (the real planner: Robot 2's sphere task plans in
about a second) that planned through ``~/plan_path`` and was stopped with SIGTERM has
recorded each goal as it arrived and each result as sent, as rosbag2 records actions (events
of the send_goal and get_result services), in records that stock mcap_ros2, rosbags and
rosbags-convert decode; ``replay --requests`` re-sends the goals to a fresh node and gets
the recorded answers, also for a goal planned from measured lengths (``use_current_start``:
replayed from the recorded path's first pose). Without a ROS graph: a goal and its result
stay in one file across rotation, are handed to replay in recorded order among GetPlan calls
and parameter changes, a killed file with them is recovered, and misuse is refused."""

import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("rosbags")
pytest.importorskip("rclpy")

from geometry_msgs.msg import PoseStamped  # noqa: E402
from mcap.reader import make_reader  # noqa: E402
from mcap_ros2.decoder import DecoderFactory  # noqa: E402
from nav_msgs.msg import Path as PathMsg  # noqa: E402
from nav_msgs.srv import GetPlan  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rosbags.highlevel import AnyReader  # noqa: E402

from cdh_planner_interfaces.action import PlanPath  # noqa: E402

from cdh_planner.recording.mcap_log import (  # noqa: E402
    REQUEST_RECEIVED, RESPONSE_SENT, RunRecorder, check_recording, read_run, recover)
from cdh_planner.recording.ros_schemas import full_definition  # noqa: E402
from cdh_planner.ros import replay as R  # noqa: E402
from cdh_planner.ros.client import plan_path_goal  # noqa: E402
from cdh_planner.ros.core.run_log import RunLog  # noqa: E402
from ros_harness import (Q1, Q2, Q3, NodeProcess, run_cli,  # noqa: E402
                         sphere_pose_msg)

NODE = "/cdh_planner"
ACTION = f"{NODE}/plan_path"
ACTION_TYPE = "cdh_planner_interfaces/action/PlanPath"
GOALS = f"{ACTION}/_action/send_goal/_service_event"
RESULTS = f"{ACTION}/_action/get_result/_service_event"
T0 = 1_700_000_000 * 10**9


@pytest.fixture(scope="module")
def action_run(domain, client, tmp_path_factory):
    """A node that planned q1 -> q2, q2 -> q3 and a goal in a frame not its own through
    the action, then got SIGTERM; (run file, goals sent, answers)."""
    node = NodeProcess(domain, tmp_path_factory.mktemp("recorded"))
    try:
        client.wait_for_node(20.0)
        goals = [plan_path_goal(sphere_pose_msg(Q1), sphere_pose_msg(Q2)),
                 plan_path_goal(sphere_pose_msg(Q2), sphere_pose_msg(Q3), strategy="gbf",
                                timeout_s=20.0),
                 plan_path_goal(sphere_pose_msg(Q1, frame="map"),     # not in TF
                                sphere_pose_msg(Q2, frame="map"))]
        answers = [client.plan_path(goal, timeout_s=30.0) for goal in goals]
    finally:
        rc = node.stop(signal.SIGTERM)
    assert rc == 0, node.log()
    assert "recording failed" not in node.log()
    [run_file] = node.run_files()
    assert check_recording(run_file)[1]                    # complete: closed at SIGTERM
    assert [a.result.error_code for a in answers] == [0, 0, PlanPath.Result.TF_ERROR]
    return run_file, goals, answers


def _same_pose(a, b):
    """Two PoseStamped equal field by field (``b`` from any decoder)."""
    assert a.header.frame_id == b.header.frame_id
    assert (a.header.stamp.sec, a.header.stamp.nanosec) == (b.header.stamp.sec,
                                                            b.header.stamp.nanosec)
    for name in "xyz":
        assert getattr(a.pose.position, name) == getattr(b.pose.position, name)
    for name in "xyzw":
        assert getattr(a.pose.orientation, name) == getattr(b.pose.orientation, name)


def _check_events(goal_events, result_events, goals, answers):
    """The recorded goals are the ones sent, the results the ones received, paired."""
    assert len(goal_events) == len(result_events) == len(goals)
    assert {e.info.event_type for e in goal_events} == {REQUEST_RECEIVED}
    assert {e.info.event_type for e in result_events} == {RESPONSE_SENT}
    assert [e.info.sequence_number for e in goal_events] == \
        [e.info.sequence_number for e in result_events] == [1, 2, 3]
    for event, sent in zip(goal_events, goals, strict=True):
        [request] = event.request
        assert len(event.response) == 0
        _same_pose(sent.start, request.goal.start)
        _same_pose(sent.goal, request.goal.goal)
        assert (request.goal.use_current_start, request.goal.strategy,
                request.goal.timeout_s) == (False, sent.strategy, sent.timeout_s)
    for event, answer in zip(result_events, answers, strict=True):
        [response] = event.response
        assert len(event.request) == 0
        got = answer.result
        assert response.result.error_code == got.error_code
        assert response.result.error_msg == got.error_msg
        assert len(response.result.path.poses) == len(got.path.poses)
        for a, b in zip(got.path.poses, response.result.path.poses):
            _same_pose(a, b)
        assert len(response.result.cable_trajectory.points) == \
            len(got.cable_trajectory.points)
        assert len(response.result.tension_envelope.points) == \
            len(got.tension_envelope.points)


def _rosbags_messages(path):
    out = {}
    with AnyReader([Path(path)]) as reader:
        for conn, _, raw in reader.messages():
            out.setdefault(conn.topic, []).append(reader.deserialize(raw, conn.msgtype))
    return out


def test_goals_and_results_are_recorded_as_sent(action_run):
    run_file, goals, answers = action_run
    got = read_run(run_file)
    types = {topic: type_name for topic, type_name, _, _ in got}
    assert types[GOALS] == f"{ACTION_TYPE}_SendGoal_Event"
    assert types[RESULTS] == f"{ACTION_TYPE}_GetResult_Event"
    # rosbag2's action topics, the types named as every reader decodes them (ros_schemas)
    with open(run_file, "rb") as f:
        summary = make_reader(f).get_summary()
    schemas = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    assert schemas[GOALS] == "cdh_planner_interfaces/msg/PlanPathSendGoalEvent"
    assert schemas[RESULTS] == "cdh_planner_interfaces/msg/PlanPathGetResultEvent"
    _check_events([m for t, _, m, _ in got if t == GOALS],
                  [m for t, _, m, _ in got if t == RESULTS], goals, answers)
    # a goal is recorded before anything planned for it, its result after
    times = [(t, lt) for t, _, _, lt in got if t in (GOALS, RESULTS)]
    assert [t for t, _ in times] == [GOALS, RESULTS] * 3
    # rclpy's own classes read the same bytes
    records = [r for r in R.read_records(run_file) if r.topic in (GOALS, RESULTS)]
    from rclpy.serialization import deserialize_message
    events = [deserialize_message(r.data, R.message_class(r.type_name)) for r in records]
    assert isinstance(events[0], PlanPath.Impl.SendGoalService.Event)
    _check_events(events[::2], events[1::2], goals, answers)


def test_every_record_decodes_in_every_tool(action_run, tmp_path):
    """Stock mcap_ros2 (no aliasing), rosbags, and rosbags-convert to a rosbag2 directory,
    the goals and results among every other record of the run."""
    run_file, goals, answers = action_run
    with open(run_file, "rb") as f:
        total = make_reader(f).get_summary().statistics.message_count
        f.seek(0)
        decoded = [(c.topic, m) for _, c, _, m in
                   make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages()]
    assert len(decoded) == total > 15
    _check_events([m for t, m in decoded if t == GOALS],
                  [m for t, m in decoded if t == RESULTS], goals, answers)
    recorded = _rosbags_messages(run_file)
    assert sum(len(v) for v in recorded.values()) == total
    _check_events(recorded[GOALS], recorded[RESULTS], goals, answers)
    dst = tmp_path / "rosbag2"
    r = subprocess.run([str(Path(sys.executable).with_name("rosbags-convert")), "--src",
                        str(run_file), "--dst", str(dst)], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr
    converted = _rosbags_messages(dst)
    assert sum(len(v) for v in converted.values()) == total
    _check_events(converted[GOALS], converted[RESULTS], goals, answers)


def test_replay_requests_resends_the_goals(domain, client, action_run, tmp_path):
    run_file, _, answers = action_run
    with NodeProcess(domain, tmp_path, params=["log_enabled:=false"]):
        client.wait_for_node(20.0)
        r = run_cli(domain, "replay", str(run_file), "--requests", "--timeout", "30")
    assert r.returncode == 0, r.stdout + r.stderr
    n1, n2 = (len(a.path.poses) for a in answers[:2])
    for line in (f"goal 1: MATCHES: error code NONE as recorded; {n1} poses, max deviation 0 m",
                 f"goal 2: MATCHES: error code NONE as recorded; {n2} poses, max deviation 0 m",
                 "goal 3: MATCHES: error code TF_ERROR as recorded; both no plan (invalid "
                 "request: start.header.frame_id = 'map'",
                 "3 of 3 answers match the recording"):
        assert line in r.stdout, r.stdout
    assert "goal 1: set as recorded:" in r.stdout            # the file's parameter snapshot


def test_a_use_current_start_goal_is_replayed_from_the_recorded_path_start(domain, client,
                                                                            tmp_path):
    """A goal planned from the measured lengths (at q2) needs none on the replaying node:
    it starts from the recorded path's first pose, and the answer is the recorded one."""
    from sensor_msgs.msg import JointState
    from cdh_planner.model.kinematics import cable_lengths
    from cdh_planner.model.pose import rotation_from_quaternion
    from cdh_planner.ros.core.params import node_config
    from ros_harness import ROBOT2, file_parameters
    robot = node_config(file_parameters(ROBOT2)).robot
    q2 = sphere_pose_msg(Q2)
    p, o = q2.pose.position, q2.pose.orientation
    lengths = cable_lengths(robot, [p.x, p.y, p.z], rotation_from_quaternion([o.x, o.y, o.z, o.w]))
    measured = JointState(name=list(robot.winch_names), position=[float(v) for v in lengths])
    node = NodeProcess(domain, tmp_path / "recorded")
    pub = client.node.create_publisher(JointState, "/joint_states", 10)
    timer = client.node.create_timer(0.02, lambda: pub.publish(measured))
    try:
        client.wait_for_node(20.0)
        # the node waits (execution.joint_states_wait_s) for a measurement if none is in yet
        client.spin_until(lambda: pub.get_subscription_count() > 0, 10.0)
        answer = client.plan_path(plan_path_goal(None, sphere_pose_msg(Q3),
                                                 use_current_start=True), timeout_s=30.0)
    finally:
        client.node.destroy_timer(timer)
        client.node.destroy_publisher(pub)
        assert node.stop() == 0, node.log()
    assert answer.success, answer.result.error_msg
    [run_file] = node.run_files()
    with NodeProcess(domain, tmp_path / "fresh", params=["log_enabled:=false"]):
        client.wait_for_node(20.0)
        r = run_cli(domain, "replay", str(run_file), "--requests", "--timeout", "30")
    assert r.returncode == 0, r.stdout + r.stderr
    assert (f"goal 1 (use_current_start: replayed from the recorded path's first pose (the "
            f"measured start is not recorded)): MATCHES: error code NONE as recorded; "
            f"{len(answer.path.poses)} poses") in r.stdout, r.stdout


# ---------------------------------------------------------------- without a ROS graph

def _pose(x, frame="cdh_base"):
    msg = PoseStamped()
    msg.header.frame_id = frame
    msg.pose.position.x, msg.pose.orientation.w = float(x), 1.0
    return msg


def _result(n_poses, x0=0.0, error_code=0):
    result = PlanPath.Result(error_code=error_code, min_margin=0.5)
    result.path.header.frame_id = "cdh_base"
    result.path.poses = [_pose(x0 + 0.1 * i) for i in range(n_poses)]
    return result


def _goal_call(log, seq, t, n_poses=3, **goal):
    log.action_event(ACTION, ACTION_TYPE, REQUEST_RECEIVED,
                     goal=PlanPath.Goal(start=_pose(seq), goal=_pose(seq + 1), **goal),
                     sequence_number=seq, log_time_ns=t)
    path = PathMsg()
    path.header.frame_id = "cdh_base"
    path.poses = [_pose(seq + i / n_poses) for i in range(n_poses)]
    log.write(f"{NODE}/path", path, t + 1, transient_local=True)
    log.action_event(ACTION, ACTION_TYPE, RESPONSE_SENT, result=_result(n_poses, seq),
                     sequence_number=seq, log_time_ns=t + 2)


INITIAL = [Parameter("task.radius", value=0.1).to_parameter_msg(),
           Parameter("stream_rate_hz", value=50.0).to_parameter_msg()]


def test_a_result_joins_its_goal_across_rotation(tmp_path):
    log = RunLog(tmp_path, True, warn=pytest.fail, info=lambda _: None, node_name=NODE,
                 max_bytes=20_000)
    log.parameters(INITIAL, initial=True)
    for seq in range(1, 9):
        _goal_call(log, seq, T0 + seq * 1000, n_poses=20)
    log.close()
    files = sorted(tmp_path.glob("*.mcap"), key=lambda p: p.stat().st_mtime_ns)
    assert len(files) >= 2
    sequences = []
    for f in files:
        plans = R.recorded_plans(R.read_records(f))
        assert plans and all(p.action and p.response is not None for p in plans)
        assert all(p.response.path.poses[0].pose.position.x == p.sequence for p in plans)
        assert R.parameter_value(plans[0].parameters["task.radius"]) == 0.1
        sequences += [p.sequence for p in plans]
    assert sequences == list(range(1, 9))


def test_goals_are_replayed_in_order_among_plan_calls_and_parameter_changes(tmp_path):
    log = RunLog(tmp_path, True, warn=pytest.fail, info=lambda _: None, node_name=NODE)
    log.parameters(INITIAL, initial=True)
    log.service_event(f"{NODE}/plan", "nav_msgs/srv/GetPlan", REQUEST_RECEIVED,
                      request=GetPlan.Request(start=_pose(0), goal=_pose(1)),
                      sequence_number=1, log_time_ns=T0)
    log.service_event(f"{NODE}/plan", "nav_msgs/srv/GetPlan", RESPONSE_SENT,
                      response=GetPlan.Response(plan=_result(2).path), sequence_number=1,
                      log_time_ns=T0 + 10)
    log.parameters([Parameter("task.radius", value=0.12).to_parameter_msg()],
                   log_time_ns=T0 + 20)
    _goal_call(log, 2, T0 + 30)
    log.action_event(ACTION, ACTION_TYPE, REQUEST_RECEIVED,    # the run ended before its result
                     goal=PlanPath.Goal(goal=_pose(5)), sequence_number=3, log_time_ns=T0 + 40)
    path = log.path
    log.close()
    plans = R.recorded_plans(R.read_records(path))
    assert [p.label for p in plans] == ["request 1", "goal 2", "goal 3"]
    assert [p.service for p in plans] == [f"{NODE}/plan", ACTION, ACTION]
    assert [[q.name for q in s] for s in plans[1].parameter_sets] == [["task.radius"]]
    assert R.parameter_value(plans[1].parameters["task.radius"]) == 0.12
    assert isinstance(plans[1].request, PlanPath.Goal)
    assert plans[1].request.start.pose.position.x == 2
    assert plans[1].response.error_code == 0 and len(plans[1].response.path.poses) == 3
    assert plans[2].response is None
    # not republished as topics: they are the recorded calls
    assert {r.topic for r in R.select_topics(R.read_records(path))} == {f"{NODE}/path"}
    # the same answer matches; another error code or path does not
    assert R.compare_results(_result(3), _result(3)) == \
        (True, "error code NONE as recorded; 3 poses, max deviation 0 m, 0 deg "
               "(within 1e-06 m / 1e-06 rad)")
    ok, text = R.compare_results(_result(0, error_code=208), _result(0, error_code=207))
    assert not ok and text == "error code NO_VALID_PATH recorded, TIMEOUT now; both no plan"
    assert not R.compare_results(_result(3), _result(3, x0=1e-3))[0]


def test_a_killed_run_with_goals_is_read_and_recovered(tmp_path):
    src = tmp_path / "run.mcap"
    rec = RunRecorder(src)
    rec.write_action_event(ACTION, ACTION_TYPE, REQUEST_RECEIVED,
                           goal=PlanPath.Goal(start=_pose(1), goal=_pose(2)),
                           sequence_number=1, log_time_ns=T0)
    rec.write_action_event(ACTION, ACTION_TYPE, RESPONSE_SENT, result=_result(4),
                           sequence_number=1, log_time_ns=T0 + 1)
    killed = tmp_path / "killed.mcap"
    shutil.copy(src, killed)           # what a killed recorder leaves: no summary
    rec.close()
    assert not check_recording(killed)[1]
    assert [t for t, *_ in read_run(killed)] == [GOALS, RESULTS]
    fixed = tmp_path / "fixed.mcap"
    result = recover(killed, fixed)
    assert result.messages == 2 and result.renamed_schemas == ()
    with open(fixed, "rb") as f:
        decoded = [m for *_, m in make_reader(f, decoder_factories=[DecoderFactory()])
                   .iter_decoded_messages()]
    assert decoded[0].request[0].goal.goal.pose.position.x == 2.0
    assert len(decoded[1].response[0].result.path.poses) == 4
    assert [p.label for p in R.recorded_plans(R.read_records(fixed))] == ["goal 1"]


def test_action_event_layout_and_misuse(tmp_path):
    """One record per goal and per result, of real generated types; nothing else accepted."""
    path = tmp_path / "r.mcap"
    with RunRecorder(path) as rec:
        gid = bytes(range(200, 216))
        rec.write_action_event(ACTION, ACTION_TYPE, REQUEST_RECEIVED, goal=PlanPath.Goal(),
                               goal_id=gid, sequence_number=7, log_time_ns=T0)
        rec.write_action_event(ACTION, ACTION_TYPE, RESPONSE_SENT, result=_result(1),
                               goal_id=gid, status=4, sequence_number=7, log_time_ns=T0 + 1)
        for bad, match in (({"goal": PlanPath.Goal(), "result": _result(0)}, "one of them"),
                           ({}, "one of them"),
                           ({"goal": PlanPath.Goal(), "event_type": RESPONSE_SENT}, "a goal goes"),
                           ({"result": _result(0), "event_type": REQUEST_RECEIVED}, "a goal goes"),
                           ({"goal": PlanPath.Goal(), "goal_id": b"x"}, "16 bytes"),
                           ({"goal": PlanPath.Goal(), "action_type": "nav_msgs/srv/GetPlan"},
                            "not an action type")):
            kw = {"event_type": REQUEST_RECEIVED, "action_type": ACTION_TYPE, **bad}
            with pytest.raises(ValueError, match=match):
                rec.write_action_event(ACTION, kw.pop("action_type"), kw.pop("event_type"), **kw)
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        schemas = {s.name: s.data.decode() for s in summary.schemas.values()}
    assert summary.statistics.message_count == 2
    text = schemas["cdh_planner_interfaces/msg/PlanPathSendGoalEvent"]
    assert text.startswith("service_msgs/ServiceEventInfo info\n"
                           "cdh_planner_interfaces/PlanPathSendGoalRequest[<=1] request\n"
                           "cdh_planner_interfaces/PlanPathSendGoalResponse[<=1] response\n")
    headers = [line for line in text.splitlines() if line.startswith("MSG: ")]
    assert {"MSG: cdh_planner_interfaces/PlanPathGoal", "MSG: unique_identifier_msgs/UUID",
            "MSG: cdh_planner_interfaces/PlanPathSendGoalRequest"} <= set(headers)
    assert not any("_" in h.split("/")[-1] for h in headers)
    assert text == full_definition(f"{ACTION_TYPE}_SendGoal_Event")
    result_text = schemas["cdh_planner_interfaces/msg/PlanPathGetResultEvent"]
    assert "\nMSG: cdh_planner_interfaces/PlanPathResult\n" in result_text
    assert "\nMSG: cdh_planner_interfaces/TensionEnvelope\n" in result_text
    from rclpy.serialization import deserialize_message
    [goal, result] = [deserialize_message(r.data, R.message_class(r.type_name))
                      for r in R.read_records(path)]
    assert bytes(goal.request[0].goal_id.uuid) == gid and goal.info.sequence_number == 7
    assert result.response[0].status == 4 and result.response[0].result.min_margin == 0.5


def test_what_is_sent_for_a_recorded_goal():
    goal = PlanPath.Goal(goal=_pose(9), use_current_start=True, strategy="gbf", timeout_s=4.0)
    plan = R.RecordedPlan(5, ACTION, goal, _result(3, x0=0.7), action=True)
    sent, note = R.goal_to_replay(plan)
    assert not sent.use_current_start and (sent.strategy, sent.timeout_s) == ("gbf", 4.0)
    _same_pose(plan.response.path.poses[0], sent.start)
    assert sent.start.pose.position.x == 0.7 and sent.goal.pose.position.x == 9
    assert note == ("use_current_start: replayed from the recorded path's first pose (the "
                    "measured start is not recorded)")
    failed = R.RecordedPlan(6, ACTION, goal, _result(0, error_code=293), action=True)
    sent, note = R.goal_to_replay(failed)
    assert sent is goal and "sent as recorded" in note
    ordinary = R.RecordedPlan(7, ACTION, PlanPath.Goal(goal=_pose(1)), _result(2), action=True)
    assert R.goal_to_replay(ordinary) == (ordinary.request, "")
    assert R.error_code_name(293) == "NO_CURRENT_STATE" and R.error_code_name(1) == "1"
