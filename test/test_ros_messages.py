"""Message conversions (ros/msgs/messages.py): field by field against the planner's data, layouts
and strides by the std_msgs/MultiArrayLayout rule, frames, joint names, SI units, nav2 error
codes, interpolation mathematics and pose round trips. No ROS graph: messages only."""

import re

import numpy as np
import pytest

pytest.importorskip("nav_msgs")

from builtin_interfaces.msg import Duration, Time  # noqa: E402
from diagnostic_msgs.msg import DiagnosticStatus  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from nav_msgs.msg import Path  # noqa: E402
from visualization_msgs.msg import Marker  # noqa: E402

from cdh_planner.errors import InputError  # noqa: E402
from cdh_planner.wrench import wrench_feasibility  # noqa: E402
from cdh_planner.model.pose import quaternion_from_tau, rotation_from_quaternion, rotation_tt  # noqa: E402
from cdh_planner.model.robot import load_robot  # noqa: E402
from cdh_planner.planner import PlanResult, Pose  # noqa: E402
from cdh_planner.ros.msgs import markers as MK  # noqa: E402
from cdh_planner.trajectory import sampling as S  # noqa: E402
from cdh_planner.status import Status  # noqa: E402
from cdh_planner.ros.msgs import messages as M  # noqa: E402
from cdh_planner.trajectory.path import PlannedPath  # noqa: E402
from cdh_planner.trajectory.timing import time_path  # noqa: E402

from conftest import REPO
ROBOT = load_robot(REPO / "config" / "robot2.yaml")
FRAME = "cdh_base"
START = Time(sec=1_700_000_000, nanosec=999_000_000)  # close to a second: carries are tested
VMAX, AMAX = 0.05, 0.2


def planned_path(n=40):
    """Robot 2's platform on an arc while turning and tilting: a wrench-feasible path with
    lengths and tension envelopes from the feasibility module, time-parameterised."""
    s = np.linspace(0.0, 1.0, n)
    ang = 2 * np.pi * 0.2 * s
    p = np.column_stack([0.05 * np.cos(ang), 0.05 * np.sin(ang), 0.30 + 0.02 * s])
    tau = np.column_stack([ang, 0.1 + 0.1 * s, 0.2 * s])
    f = wrench_feasibility(ROBOT, p, tau)
    assert np.all(f.feasible)
    zeros = np.zeros((n, 6))
    path = PlannedPath(p=p, quaternion=quaternion_from_tau(tau), tau=tau, lengths=f.lengths,
                       tension_min=f.tension_min, tension_nominal=f.tension_nominal,
                       tension_max=f.tension_max, margin=f.margin, t=np.zeros(n),
                       velocities=zeros, accelerations=zeros)
    return time_path(path, VMAX, AMAX)


PATH = planned_path()


def ns(stamp):
    return stamp.sec * 1_000_000_000 + stamp.nanosec


# ----------------------------------------------------------------------------- time helpers

def test_time_and_duration_helpers():
    assert M.time_ns(M.time_msg(1_700_000_001_000_000_123)) == 1_700_000_001_000_000_123
    d = M.duration_msg(2.9999999996)
    assert (d.sec, d.nanosec) == (3, 0)  # rounds to the nearest ns, carries into sec
    d = M.duration_msg(1.25)
    assert (d.sec, d.nanosec) == (1, 250_000_000) and M.to_seconds(d) == 1.25
    with pytest.raises(InputError):
        M.duration_msg(float("nan"))


# ----------------------------------------------------------------------------- nav_msgs/Path

def test_path_message_field_by_field():
    msg = M.path_msg(PATH, FRAME, START)
    assert msg.header.frame_id == FRAME and ns(msg.header.stamp) == ns(START)
    assert len(msg.poses) == len(PATH)
    for k, pose in enumerate(msg.poses):
        assert pose.header.frame_id == FRAME
        assert ns(pose.header.stamp) == ns(START) + round(PATH.t[k] * 1e9)
        pos, o = pose.pose.position, pose.pose.orientation
        assert [pos.x, pos.y, pos.z] == PATH.p[k].tolist()
        assert [o.x, o.y, o.z, o.w] == PATH.quaternion[k].tolist()
    stamps = [ns(p.header.stamp) for p in msg.poses]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))


def test_untimed_path_is_refused():
    bad = PlannedPath(**{**PATH.__dict__, "t": np.zeros(len(PATH))})
    with pytest.raises(InputError) as err:
        M.path_msg(bad, FRAME, START)
    assert err.value.field == "path.t"


# ----------------------------------------------------------------------------- JointTrajectory

def test_cable_trajectory_field_by_field():
    msg = M.cable_trajectory_msg(PATH, ROBOT.winch_names, FRAME)
    assert msg.header.frame_id == FRAME
    assert ns(msg.header.stamp) == 0  # start on receipt
    assert list(msg.joint_names) == list(ROBOT.winch_names)
    assert len(msg.points) == len(PATH)
    for k, pt in enumerate(msg.points):
        assert list(pt.positions) == PATH.lengths[k].tolist()  # m
        assert list(pt.velocities) == PATH.velocities[k].tolist()  # m/s
        assert list(pt.accelerations) == PATH.accelerations[k].tolist()  # m/s^2
        assert list(pt.effort) == PATH.tension_nominal[k].tolist()  # N, for tension control
        assert M.to_seconds(pt.time_from_start) == pytest.approx(PATH.t[k], abs=1e-9)
    times = [ns(Time(sec=p.time_from_start.sec, nanosec=p.time_from_start.nanosec)) for p in msg.points]
    assert times[0] == 0 and all(b > a for a, b in zip(times, times[1:]))
    # the lengths are those of the poses: |p + R b_i - a_i|
    R = rotation_from_quaternion(PATH.quaternion)
    ends = PATH.p[:, None] + np.einsum("nij,kj->nki", R, ROBOT.platform_anchors)
    np.testing.assert_allclose([list(p.positions) for p in msg.points],
                               np.linalg.norm(ends - ROBOT.base_anchors, axis=2), rtol=1e-12)
    # velocities within the winch limits, start and end at rest
    v = np.array([list(p.velocities) for p in msg.points])
    assert np.abs(v).max() <= VMAX * (1 + 1e-9) and not v[[0, -1]].any()


def test_cable_trajectory_commands_unstretched_lengths():
    """With elastic cables the positions are the unstretched lengths that carry the nominal
    tensions at the planned pose (L0 (1 + t / EA) = L), their rates those of L0; a rigid
    robot gets the geometric lengths and rates themselves; the FollowJointTrajectory goal
    drops the effort (a JTC without an effort interface refuses it)."""
    from dataclasses import replace
    from cdh_planner.trajectory.path import with_commands
    winches = pytest.importorskip("cdh_planner.ros.execution.winches")
    elastic = with_commands(ROBOT, PATH)
    msg = M.cable_trajectory_msg(elastic, ROBOT.winch_names, FRAME)
    L0 = np.array([list(p.positions) for p in msg.points])
    np.testing.assert_allclose(L0 * (1 + PATH.tension_nominal / ROBOT.cable_stiffness),
                               PATH.lengths, rtol=1e-3)  # the averaged tension: near t_nom
    assert np.all(L0 < PATH.lengths)
    np.testing.assert_array_equal(L0, elastic.commanded()[0])
    np.testing.assert_array_equal([list(p.velocities) for p in msg.points],
                                  elastic.commanded()[1])
    goal = winches.fjt_goal(msg)
    assert all(len(p.effort) == 0 for p in goal.trajectory.points)
    rigid = replace(ROBOT, cable_stiffness=None)
    msg = M.cable_trajectory_msg(with_commands(rigid, PATH), ROBOT.winch_names, FRAME)
    assert [list(p.positions) for p in msg.points] == PATH.lengths.tolist()
    assert [list(p.accelerations) for p in msg.points] == PATH.accelerations.tolist()


def test_joint_names_are_checked():
    with pytest.raises(InputError) as err:
        M.cable_trajectory_msg(PATH, ["a", "b", "c", "d", "e", "e"], FRAME)
    assert err.value.field == "joint_names"
    with pytest.raises(InputError):
        M.cable_trajectory_msg(PATH, ROBOT.winch_names[:5], FRAME)


# ----------------------------------------------------------------------------- tension envelope

def test_tension_envelope_field_by_field():
    msg = M.tension_envelope_msg(PATH, ROBOT.winch_names, FRAME, START)
    assert msg.header.frame_id == FRAME and ns(msg.header.stamp) == ns(START)
    assert list(msg.winch_names) == list(ROBOT.winch_names)
    assert len(msg.points) == len(PATH)
    traj = M.cable_trajectory_msg(PATH, ROBOT.winch_names, FRAME)
    for k, pt in enumerate(msg.points):
        # the same times as the trajectory's waypoints
        assert pt.time_from_start == traj.points[k].time_from_start
        assert list(pt.tension_min) == PATH.tension_min[k].tolist()          # N
        assert list(pt.tension_nominal) == PATH.tension_nominal[k].tolist()
        assert list(pt.tension_max) == PATH.tension_max[k].tolist()
    env = M.envelope_from_msg(msg)
    bounds = (PATH.tension_min, PATH.tension_nominal, PATH.tension_max)
    np.testing.assert_array_equal(env, np.stack(bounds, axis=-1))
    assert np.all(env[..., 0] < env[..., 1]) and np.all(env[..., 1] < env[..., 2])
    assert np.all(env[..., 0] > ROBOT.tension_min) and np.all(env[..., 2] < ROBOT.tension_max)


def test_tension_envelope_names_are_checked():
    with pytest.raises(InputError) as err:
        M.tension_envelope_msg(PATH, ROBOT.winch_names[:5], FRAME)
    assert err.value.field == "winch_names"


# ----------------------------------------------------------------------------- markers

def test_markers_geometry_frames_and_colours():
    msg = MK.markers_msg(PATH, ROBOT, FRAME, START)
    markers = msg.markers
    assert markers[0].action == Marker.DELETEALL
    assert all(m.header.frame_id == FRAME for m in markers)
    by = {(m.ns, m.id): m for m in markers[1:]}
    drawn = MK.drawn_waypoints(len(PATH))
    assert drawn[0] == 0 and drawn[-1] == len(PATH) - 1 and len(drawn) == min(MK.POSES_DRAWN, len(PATH))
    assert set(by) == {("path", 0)} | {(ns_, i) for ns_ in ("platform", "cables") for i in range(len(drawn))}
    for m in markers[1:]:
        assert m.action == Marker.ADD and ns(m.header.stamp) == ns(START)
        assert m.pose.orientation.w == 1.0 and m.scale.x == MK.LINE_WIDTH_M
        assert (m.lifetime.sec, m.lifetime.nanosec) == (0, 0)
    line = by[("path", 0)]
    assert line.type == Marker.LINE_STRIP
    np.testing.assert_array_equal([[q.x, q.y, q.z] for q in line.points], PATH.p)
    margins = MK.cable_margins(PATH, ROBOT)
    # the tension part of the feasibility margin: never below the overall margin
    assert np.all(margins.min(axis=1) >= PATH.margin - 1e-12)
    assert len(line.colors) == len(line.points)
    for c, m in zip(line.colors, margins.min(axis=1)):
        assert (c.r, c.g) == (MK.margin_color(m).r, MK.margin_color(m).g)
    for ident, k in enumerate(drawn):
        cables = by[("cables", ident)]
        assert cables.type == Marker.LINE_LIST and len(cables.points) == 12 == len(cables.colors)
        pts = np.array([[q.x, q.y, q.z] for q in cables.points])
        np.testing.assert_array_equal(pts[0::2], ROBOT.base_anchors)  # a_i
        # the drawn cables have the path's lengths at that waypoint
        np.testing.assert_allclose(np.linalg.norm(pts[1::2] - pts[0::2], axis=1), PATH.lengths[k], rtol=1e-12)
        for i in range(6):
            expected = MK.margin_color(margins[k, i])
            for c in cables.colors[2 * i:2 * i + 2]:
                assert (c.r, c.g, c.b, c.a) == (expected.r, expected.g, expected.b, expected.a)
        outline = by[("platform", ident)]
        ring = np.array([[q.x, q.y, q.z] for q in outline.points])
        assert outline.type == Marker.LINE_STRIP
        np.testing.assert_array_equal(ring[0], ring[-1])  # closed
        assert len(ring) == 4  # Robot 2: three distinct platform anchor points
        # every outline point is a platform anchor p + R b_i of the pose
        attach = pts[1::2]
        assert all(np.min(np.linalg.norm(attach - q, axis=1)) < 1e-15 for q in ring)


def test_margin_colours():
    red, green, mid = MK.margin_color(-0.1), MK.margin_color(1.0), MK.margin_color(MK.MARGIN_FULL / 2)
    assert (red.r, red.g, red.a) == (1.0, 0.0, 1.0)
    assert green.r == 0.0 and green.g > 0.5
    assert mid.r == 1.0 and mid.g > 0.5  # yellow half way
    assert MK.margin_color(float("-inf")).r == 1.0


# ----------------------------------------------------------------------------- plan result

def _result(reason, success=False, message="what happened"):
    return PlanResult(success=success, reason=Status(reason), message=message, strategy="astar",
                      n=2, variables=8, charts=123, time_s=0.1 + 0.2,
                      cost=float("inf") if not success else 0.4321)


@pytest.mark.parametrize("reason, code", [
    ("start_infeasible", 205), ("goal_infeasible", 206), ("start_in_collision", 205),
    ("goal_in_collision", 206), ("no_path", 208), ("timeout", 207),
    ("chart_limit", 208), ("resource_limit", 208), ("invalid", 292), ("canceled", 290),
    ("busy", 291), ("output_limit", 294), ("no_current_state", 293), ("bad_strategy", 201),
    ("bad_frame", 202), ("internal_error", 200)])
def test_plan_status_failure_codes(reason, code):
    msg = M.plan_status(_result(reason), run_id="run-7", log_file="/tmp/run-7.mcap")
    assert msg.level == DiagnosticStatus.ERROR
    assert msg.message == "what happened"
    values = M.status_values(msg)
    assert [kv.key for kv in msg.values] == list(M.STATUS_KEYS)
    assert values["error_code"] == str(code) and values["error_msg"] == "what happened"
    assert float(values["planning_time_s"]) == 0.1 + 0.2  # repr: exact round trip
    assert values["charts"] == "123" and values["strategy"] == "astar"
    assert float(values["cost"]) == float("inf")
    assert values["run_id"] == "run-7" and values["log_file"] == "/tmp/run-7.mcap"


def test_plan_status_success_and_code_table():
    msg = M.plan_status(_result("ok", success=True, message="plan found"))
    values = M.status_values(msg)
    assert msg.level == DiagnosticStatus.OK and msg.message == "plan found"
    assert values["error_code"] == "0" and values["error_msg"] == ""
    assert float(values["cost"]) == 0.4321
    # the constants are nav2 ComputePathToPose's (Jazzy)
    assert (M.NONE, M.UNKNOWN, M.TF_ERROR, M.START_OCCUPIED, M.GOAL_OCCUPIED, M.TIMEOUT,
            M.NO_VALID_PATH) == (0, 200, 202, 205, 206, 207, 208)
    assert M.error_code("bad_frame") == M.error_code(Status.BAD_FRAME) == 202
    with pytest.raises(ValueError, match="something else"):   # the vocabulary is closed
        M.error_code("something else")


def _action_result_codes():
    """{name: (value, comment)} of the int32 constants of PlanPath.action's result."""
    text = (REPO / "interfaces" / "cdh_planner_interfaces" / "action" / "PlanPath.action")
    result = text.read_text().split("---")[1]
    found = re.findall(r"^int32 ([A-Z_]+)=(\d+)[ \t]*(?:#(.*))?$", result, flags=re.M)
    return {name: (int(value), comment) for name, value, comment in found}


def test_every_status_has_an_action_code_and_every_code_is_used_or_reserved():
    """Both directions: each Status member has one PlanPath error code, only OK has NONE,
    and each code of the action is some member's or reserved with a reason, the .action
    file saying "not used" for exactly the reserved ones."""
    from cdh_planner_interfaces.action import PlanPath
    declared = _action_result_codes()
    generated = {k: getattr(PlanPath.Result, k) for k in dir(PlanPath.Result)
                 if k.isupper() and isinstance(getattr(PlanPath.Result, k), int)}
    assert {k: v for k, (v, _) in declared.items()} == generated and len(generated) == 15
    assert set(M.ERROR_CODES) == set(Status)
    assert [s for s, code in M.ERROR_CODES.items() if code == M.NONE] == [Status.OK]
    used, reserved = set(M.ERROR_CODES.values()), set(M.RESERVED_CODES)
    assert used.isdisjoint(reserved) and used | reserved == set(generated.values())
    assert all(M.RESERVED_CODES.values())                    # each with its reason
    assert {v for v, comment in declared.values() if "not used" in comment} == reserved


def test_the_docs_table_of_reasons_is_error_codes():
    """docs/ros-node.md's table (reason | code NAME | when) says what ERROR_CODES says."""
    text = (REPO / "docs" / "ros-node.md").read_text()
    rows = re.findall(r"^\| `([a-z_]+)` \| (\d+) ([A-Z_]+) \|", text, flags=re.M)
    assert {Status(r): int(code) for r, code, _ in rows} == M.ERROR_CODES
    assert len(rows) == len(Status) and all(getattr(M, name) == int(code)
                                            for _, code, name in rows)


# ----------------------------------------------------------------------------- sampling

def test_sample_at_waypoints_and_clamped_ends():
    for k in (0, 1, 17, len(PATH) - 1):
        s = S.sample_cable_state(PATH, PATH.t[k])
        np.testing.assert_allclose(s.lengths, PATH.lengths[k], rtol=1e-12)
        np.testing.assert_allclose(s.velocities, PATH.velocities[k], atol=1e-12)
        np.testing.assert_allclose(s.effort, PATH.tension_nominal[k], rtol=1e-12)
    before, after = S.sample_cable_state(PATH, -3.0), S.sample_cable_state(PATH, PATH.t[-1] + 5)
    np.testing.assert_array_equal(before.lengths, PATH.lengths[0])
    np.testing.assert_array_equal(after.lengths, PATH.lengths[-1])
    assert not before.velocities.any() and not after.velocities.any()
    with pytest.raises(InputError) as err:
        S.sample_cable_state(PATH, float("nan"))
    assert err.value.field == "t"


def test_quintic_sampling_reproduces_a_quintic():
    """Waypoints taken from a degree-5 polynomial per cable: the quintic interpolation of
    position, velocity and acceleration at the ends of each segment is that polynomial."""
    rng = np.random.default_rng(5)
    coeffs = rng.normal(size=(6, 6)) * 0.01
    poly = [np.polynomial.Polynomial(c) for c in coeffs]
    t = np.concatenate([[0.0], np.cumsum(rng.uniform(0.05, 0.3, 9))])
    ev = lambda f, x: np.array([f(p)(x) for p in poly]).T  # noqa: E731
    n = len(t)
    zeros = np.zeros((n, 6))
    path = PlannedPath(p=np.zeros((n, 3)), quaternion=np.tile([0, 0, 0, 1.0], (n, 1)), tau=np.zeros((n, 3)),
                       lengths=ev(lambda p: p, t), tension_min=zeros, tension_nominal=np.outer(t, np.ones(6)),
                       tension_max=zeros, margin=np.ones(n), t=t, velocities=ev(lambda p: p.deriv(), t),
                       accelerations=ev(lambda p: p.deriv(2), t))
    for x in rng.uniform(0, t[-1], 50):
        s = S.sample_cable_state(path, x)
        np.testing.assert_allclose(s.lengths, ev(lambda p: p, x), atol=1e-13)
        np.testing.assert_allclose(s.velocities, ev(lambda p: p.deriv(), x), atol=1e-12)
        np.testing.assert_allclose(s.effort, x, rtol=1e-12)  # linear effort of a linear ramp


def test_linear_sampling_stays_on_the_segment_within_the_speed_limit():
    for x in np.linspace(0, PATH.t[-1], 333):
        s = S.sample_cable_state(PATH, x, method="linear")
        k = min(int(np.searchsorted(PATH.t, x, side="right") - 1), len(PATH) - 2)
        f = (x - PATH.t[k]) / (PATH.t[k + 1] - PATH.t[k])
        np.testing.assert_allclose(s.lengths, (1 - f) * PATH.lengths[k] + f * PATH.lengths[k + 1], atol=1e-14)
        assert np.abs(s.velocities).max() <= VMAX * (1 + 1e-9)


def test_cable_command_message():
    x = 0.5 * PATH.t[-1]
    msg = M.cable_command_msg(PATH, ROBOT.winch_names, x, START)
    s = S.sample_cable_state(PATH, x)
    assert list(msg.name) == list(ROBOT.winch_names)
    assert list(msg.position) == s.lengths.tolist()
    assert list(msg.velocity) == s.velocities.tolist()
    assert list(msg.effort) == s.effort.tolist()
    assert ns(msg.header.stamp) == ns(START)


def test_winch_command_adapter_round_trip():
    """winch_command -> (wire) -> winch_command_values gives the stamp in s, the positions
    and the velocities back exactly: the only code that knows the message type."""
    from rclpy.serialization import deserialize_message, serialize_message
    positions, velocities = np.linspace(0.2, 0.45, 6), np.linspace(-0.05, 0.05, 6)
    msg = M.winch_command(ROBOT.winch_names, positions, velocities, START, effort=np.full(6, 1.5))
    assert isinstance(msg, M.WINCH_COMMAND_TYPE)
    for m in (msg, deserialize_message(serialize_message(msg), M.WINCH_COMMAND_TYPE)):
        t, p, v = M.winch_command_values(m)
        assert t == ns(START) / 1e9 == 1_700_000_000.999
        np.testing.assert_array_equal(p, positions)
        np.testing.assert_array_equal(v, velocities)
    t, p, v = M.winch_command_values(M.winch_command(ROBOT.winch_names, positions, np.zeros(6), START))
    assert not np.any(v) and p.shape == v.shape == (6,)


def test_path_and_trajectory_arrays_round_trip():
    p, q = M.path_arrays(M.path_msg(PATH, FRAME, START))
    np.testing.assert_array_equal(p, PATH.p)
    np.testing.assert_array_equal(q, PATH.quaternion)
    t, lengths = M.trajectory_arrays(M.cable_trajectory_msg(PATH, ROBOT.winch_names, FRAME))
    np.testing.assert_allclose(t, PATH.t, atol=1e-9)
    np.testing.assert_array_equal(lengths, PATH.lengths)
    p, q = M.path_arrays(Path())  # no plan
    assert p.shape == (0, 3) and q.shape == (0, 4)


# ----------------------------------------------------------------------------- poses

def _pose_stamped(p, q, frame=FRAME):
    msg = PoseStamped()
    msg.header.frame_id = frame
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in p)
    o = msg.pose.orientation
    o.x, o.y, o.z, o.w = (float(v) for v in q)
    return msg


def test_pose_round_trips():
    rng = np.random.default_rng(11)
    for _ in range(20):
        tau = np.array([rng.uniform(-np.pi, np.pi), rng.uniform(0.05, 3.0), rng.uniform(-np.pi, np.pi)])
        pose = Pose(p=rng.normal(size=3) * 0.1, tau=tau)
        msg = M.pose_msg(pose, FRAME, START)
        assert msg.header.frame_id == FRAME and ns(msg.header.stamp) == ns(START)
        back = M.pose_from_msg(msg, FRAME, "goal")
        np.testing.assert_array_equal(back.p, pose.p)
        np.testing.assert_allclose(back.tau, tau, atol=1e-9)
        np.testing.assert_allclose(rotation_tt(back.tau), rotation_tt(tau), atol=1e-12)
    # msg -> pose -> msg: the same rotation, as a unit quaternion up to sign
    q = np.array([0.1, -0.2, 0.3, 0.9])
    q /= np.linalg.norm(q)
    again = M.pose_msg(M.pose_from_msg(_pose_stamped([0.1, 0.2, 0.3], q), FRAME), FRAME)
    o = again.pose.orientation
    assert abs(abs(np.dot([o.x, o.y, o.z, o.w], q)) - 1) < 1e-12


def test_pose_at_theta_zero_keeps_position_and_rotation():
    msg = _pose_stamped([0.0, 0.0, 0.3], [0.0, 0.0, np.sin(0.35), np.cos(0.35)])
    pose = M.pose_from_msg(msg, FRAME)
    assert pose.tau[1] == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(rotation_tt(pose.tau), rotation_from_quaternion(
        np.array([0.0, 0.0, np.sin(0.35), np.cos(0.35)])), atol=1e-12)


@pytest.mark.parametrize("p, q, frame, field", [
    ([0, 0, 0.3], [0, 0, 0, 1], "world", "start.header.frame_id"),
    ([0, 0, 0.3], [0, 0, 0, 1], "", "start.header.frame_id"),
    ([0, float("nan"), 0.3], [0, 0, 0, 1], FRAME, "start.pose.position.y"),
    ([float("inf"), 0, 0.3], [0, 0, 0, 1], FRAME, "start.pose.position.x"),
    ([0, 0, 0.3], [0, 0, 0, 0], FRAME, "start.pose.orientation"),
    ([0, 0, 0.3], [0, 0, 0, 1.01], FRAME, "start.pose.orientation"),
    ([0, 0, 0.3], [0, 0, float("nan"), 1], FRAME, "start.pose.orientation"),
])
def test_bad_pose_messages_name_the_field(p, q, frame, field):
    with pytest.raises(InputError) as err:
        M.pose_from_msg(_pose_stamped(p, q, frame), FRAME, "start")
    assert err.value.field == field
    assert field in str(err.value)


def test_nearly_normalised_quaternion_is_accepted():
    q = np.array([0.0, 0.0, 0.0, 1.0005])  # within 1e-3
    pose = M.pose_from_msg(_pose_stamped([0, 0, 0.3], q), FRAME)
    np.testing.assert_allclose(rotation_tt(pose.tau), np.eye(3), atol=1e-12)


def test_duration_type_used_for_time_from_start():
    pt = M.cable_trajectory_msg(PATH, ROBOT.winch_names, FRAME).points[-1]
    assert isinstance(pt.time_from_start, Duration)
    assert 0 <= pt.time_from_start.nanosec < 1_000_000_000
