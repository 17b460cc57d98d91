"""Conversions between the planner's data and standard ROS 2 messages (no node, no graph).

Every function here is pure: planner data in, a message out (or back). Units are SI and
frames follow REP 103: positions in m in the base frame (``frame_id`` = the configured base
frame), quaternions (x, y, z, w), cable lengths in m, tensions in N, times in s.

    path_msg(path, frame_id, stamp)                      -> nav_msgs/Path
    cable_trajectory_msg(path, joint_names, frame_id)    -> trajectory_msgs/JointTrajectory
    tension_envelope_msg(path, names, frame_id, stamp)   -> cdh_planner_interfaces/TensionEnvelope
    plan_status(result, run_id, log_file)                -> diagnostic_msgs/DiagnosticStatus
    cable_command_msg(path, joint_names, t, stamp)       -> a winch command
    pose_from_msg(msg, base_frame, field) / pose_msg(pose, frame_id, stamp)
    path_arrays(path_msg) -> p, quaternion; trajectory_arrays(msg) -> t, positions

The winch command's message type is known here only (``WINCH_COMMAND_TYPE``): everything
else builds one with ``winch_command`` and reads one with ``winch_command_values``.
"""

import array

import numpy as np
from ...ports import Rotation
from builtin_interfaces.msg import Duration, Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from cdh_planner_interfaces.action import PlanPath
from cdh_planner_interfaces.msg import TensionEnvelope, TensionEnvelopePoint

from ...errors import InputError
from ...model.pose import Pose, check_quaternion, quaternion_from_tau, tau_from_quaternion
from ...model.robot_schema import MAX_CABLES, MIN_CABLES
from ...status import Status
from ...trajectory.sampling import check_timed_path, sample_cable_state

NS_PER_S = 1_000_000_000

# ----------------------------------------------------------------------------- time

def time_msg(ns):
    """builtin_interfaces/Time of an integer number of nanoseconds (>= 0)."""
    ns = int(ns)
    if ns < 0:
        raise InputError("stamp", ns, "a ROS time cannot be negative")
    return Time(sec=ns // NS_PER_S, nanosec=ns % NS_PER_S)


def time_ns(stamp):
    """Integer nanoseconds of a builtin_interfaces/Time (or Duration)."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def seconds_ns(seconds, field="t"):
    """Seconds (float) -> integer nanoseconds, rounded to nearest; InputError if not finite."""
    s = float(seconds)
    if not np.isfinite(s):
        raise InputError(field, s, "must be a finite number of seconds")
    return int(round(s * NS_PER_S))


def duration_msg(seconds):
    """builtin_interfaces/Duration of ``seconds`` (s), nanosec in [0, 1e9) as the type requires."""
    ns = seconds_ns(seconds, "time_from_start")
    return Duration(sec=ns // NS_PER_S, nanosec=ns % NS_PER_S)


def to_seconds(stamp):
    """Seconds (float) of a builtin_interfaces/Time (a header stamp) or Duration."""
    return time_ns(stamp) / NS_PER_S


def _stamp_plus(stamp, seconds):
    return time_msg(time_ns(stamp) + seconds_ns(seconds))


# ----------------------------------------------------------------------------- checks

def check_joint_names(names, field="joint_names"):
    """MIN_CABLES to MAX_CABLES distinct non-empty strings (the robot's winch_names) -> list."""
    names = list(names)
    if not MIN_CABLES <= len(names) <= MAX_CABLES or len(set(names)) != len(names) \
            or not all(isinstance(n, str) and n for n in names):
        raise InputError(field, names, f"expected {MIN_CABLES} to {MAX_CABLES} distinct "
                                       "non-empty names")
    return names


# ----------------------------------------------------------------------------- poses

def pose_from_msg(msg, base_frame, field="pose", phi_hint=0.0):
    """Planner Pose (p m, tau rad) of a geometry_msgs/PoseStamped in ``base_frame``.

    Raises InputError naming the field (``<field>.header.frame_id``,
    ``<field>.pose.position.x``, ``<field>.pose.orientation``) when the frame is not the
    base frame, a coordinate is not finite, or the quaternion is zero or not normalised
    within 1e-3. ``phi_hint`` (rad) is the azimuth used where theta = 0 or pi.
    """
    if msg.header.frame_id != base_frame:
        raise InputError(f"{field}.header.frame_id", msg.header.frame_id,
                         f"must be the base frame '{base_frame}'")
    pos = msg.pose.position
    p = np.array([pos.x, pos.y, pos.z], dtype=float)
    for axis, value in zip("xyz", p):
        if not np.isfinite(value):
            raise InputError(f"{field}.pose.position.{axis}", float(value),
                             "must be a finite number (m)")
    o = msg.pose.orientation
    q = check_quaternion([o.x, o.y, o.z, o.w], field=f"{field}.pose.orientation", tol=1e-3)
    return Pose(p=p, tau=tau_from_quaternion(q, phi_hint))


def pose_msg(pose, frame_id, stamp=None):
    """geometry_msgs/PoseStamped of a planner Pose (quaternion from tau, w >= 0)."""
    msg = PoseStamped()
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp if stamp is not None else Time()
    _fill_pose(msg.pose, np.asarray(pose.p, dtype=float), quaternion_from_tau(pose.tau))
    return msg


def pose_stamped_msg(p, R, frame_id, stamp=None):
    """geometry_msgs/PoseStamped of a position ``p`` (m) and rotation matrix ``R``."""
    msg = PoseStamped()
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp if stamp is not None else Time()
    _fill_pose(msg.pose, np.asarray(p, dtype=float), Rotation.from_matrix(R).as_quat())
    return msg


def _fill_pose(pose, p, q):
    pose.position.x, pose.position.y, pose.position.z = (float(v) for v in p)
    o = pose.orientation
    o.x, o.y, o.z, o.w = (float(v) for v in q)


def path_arrays(msg):
    """(positions (N, 3) m, quaternions (N, 4) x y z w) of a nav_msgs/Path's poses."""
    poses = [q.pose for q in msg.poses]
    p = np.array([[q.position.x, q.position.y, q.position.z] for q in poses]).reshape(-1, 3)
    o = np.array([[q.orientation.x, q.orientation.y, q.orientation.z, q.orientation.w]
                  for q in poses]).reshape(-1, 4)
    return p, o


# ----------------------------------------------------------------------------- path, trajectory

def path_msg(path, frame_id, stamp):
    """nav_msgs/Path of a PlannedPath: header (frame_id, stamp = start), one PoseStamped per
    waypoint in ``frame_id`` with stamp = start + t_k."""
    check_timed_path(path)
    msg = Path()
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp
    for p, q, t in zip(path.p, path.quaternion, path.t):
        pose = PoseStamped()
        pose.header.frame_id = frame_id
        pose.header.stamp = _stamp_plus(stamp, t)
        _fill_pose(pose.pose, p, q)
        msg.poses.append(pose)
    return msg


def cable_trajectory_msg(path, joint_names, frame_id, stamp=None):
    """trajectory_msgs/JointTrajectory, one joint per winch (``joint_names`` = the robot's
    winch_names): positions = the commanded cable lengths (m; ``PlannedPath.commanded``:
    unstretched with elastic cables), their velocities (m/s) and accelerations (m/s^2),
    effort = the nominal tensions (N, for tension-aware controllers), time_from_start = t
    (s). The FollowJointTrajectory goal drops the effort (``winches.fjt_goal``): a
    JointTrajectoryController without an effort command interface refuses it.

    ``stamp`` None (zero) means "start on receipt" to a ros2_control
    JointTrajectoryController; a non-zero stamp is an absolute start time.
    """
    check_timed_path(path)
    msg = JointTrajectory()
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp if stamp is not None else Time()
    msg.joint_names = check_joint_names(joint_names)
    L, V, A = path.commanded()
    for k in range(len(path)):
        pt = JointTrajectoryPoint()
        pt.positions, pt.velocities = _doubles(L[k]), _doubles(V[k])
        pt.accelerations, pt.effort = _doubles(A[k]), _doubles(path.tension_nominal[k])
        pt.time_from_start = duration_msg(path.t[k])
        msg.points.append(pt)
    return msg


def trajectory_arrays(msg):
    """(t (N,) s from the start, positions (N, joints)) of a trajectory_msgs/JointTrajectory."""
    t = np.array([to_seconds(pt.time_from_start) for pt in msg.points])
    return t, np.array([pt.positions for pt in msg.points], dtype=float).reshape(len(t), -1)


def tension_envelope_msg(path, winch_names, frame_id, stamp=None):
    """cdh_planner_interfaces/TensionEnvelope (N): per waypoint k of ``path`` its
    time_from_start (= path.t[k], the cable trajectory's) and, per cable i (``winch_names``
    order), tension_min, tension_nominal, tension_max. ``stamp``: when the plan was made."""
    check_timed_path(path)
    msg = TensionEnvelope()
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp if stamp is not None else Time()
    msg.winch_names = check_joint_names(winch_names, "winch_names")
    for k in range(len(path)):
        msg.points.append(TensionEnvelopePoint(
            time_from_start=duration_msg(path.t[k]),
            tension_min=_doubles(path.tension_min[k]),
            tension_nominal=_doubles(path.tension_nominal[k]),
            tension_max=_doubles(path.tension_max[k])))
    return msg


def _doubles(values):
    """A float64[] field's value: array.array("d"), which the message takes as it is (a
    numpy array is checked number by number, 3x slower for a plan's trajectory)."""
    return array.array("d", np.ascontiguousarray(values, dtype=float).tobytes())


def envelope_from_msg(msg):
    """(N, 6, 3) array back from a TensionEnvelope: [k, i] = (min, nominal, max) of cable i
    at waypoint k (N)."""
    return np.array([np.stack([p.tension_min, p.tension_nominal, p.tension_max], axis=-1)
                     for p in msg.points], dtype=float).reshape(len(msg.points), -1, 3)


# ----------------------------------------------------------------------------- plan result

# Error codes: cdh_planner_interfaces/action/PlanPath's (nav2_msgs/action/ComputePathToPose's
# where one fits, the planner's own from 290 on); ~/plan_result uses the same.
_R = PlanPath.Result
NONE, UNKNOWN, INVALID_PLANNER, TF_ERROR = _R.NONE, _R.UNKNOWN, _R.INVALID_PLANNER, _R.TF_ERROR
START_OUTSIDE_MAP, GOAL_OUTSIDE_MAP = _R.START_OUTSIDE_MAP, _R.GOAL_OUTSIDE_MAP
START_OCCUPIED, GOAL_OCCUPIED = _R.START_OCCUPIED, _R.GOAL_OCCUPIED
TIMEOUT, NO_VALID_PATH, CANCELED, BUSY = _R.TIMEOUT, _R.NO_VALID_PATH, _R.CANCELED, _R.BUSY
INVALID_REQUEST, NO_CURRENT_STATE, OUTPUT_LIMIT = (_R.INVALID_REQUEST, _R.NO_CURRENT_STATE,
                                                    _R.OUTPUT_LIMIT)

# Every way a plan ends (status.Status, closed) has one code; every code of PlanPath is one
# of these or reserved: nav2's *_OUTSIDE_MAP ("not used" in the .action file), as a pose off
# the task is INVALID_REQUEST. test_ros_messages checks both directions.
ERROR_CODES = {
    Status.OK: NONE,
    Status.START_INFEASIBLE: START_OCCUPIED,  # start not wrench-feasible
    Status.GOAL_INFEASIBLE: GOAL_OCCUPIED,    # goal not wrench-feasible
    Status.START_IN_COLLISION: START_OCCUPIED,  # start in collision (the scene)
    Status.GOAL_IN_COLLISION: GOAL_OCCUPIED,    # goal in collision (the scene)
    Status.NO_PATH: NO_VALID_PATH,            # a component exhausted
    Status.TIMEOUT: TIMEOUT,
    Status.CHART_LIMIT: NO_VALID_PATH,        # no path found within max_charts
    Status.RESOURCE_LIMIT: NO_VALID_PATH,     # no path found within max_memory_mb
    Status.CANCELED: CANCELED,                # the caller cancelled the plan
    Status.INVALID: INVALID_REQUEST,          # request inconsistent with the task / malformed
    Status.NOT_EXECUTABLE: NO_VALID_PATH,     # no trajectory executes as checked (bounded)
    # refusals by the node, before or after planning:
    Status.BAD_FRAME: TF_ERROR,               # frame_id is not the base frame
    Status.BAD_STRATEGY: INVALID_PLANNER,     # a strategy the planner does not have
    Status.BUSY: BUSY,                        # too many plans queued
    Status.NO_CURRENT_STATE: NO_CURRENT_STATE,  # use_current_start without measured lengths
    Status.OUTPUT_LIMIT: OUTPUT_LIMIT,        # the plan is beyond the node's output bounds
    Status.INTERNAL_ERROR: UNKNOWN,           # an exception while answering
}
RESERVED_CODES = {START_OUTSIDE_MAP: "nav2's; a start pose off the task is INVALID_REQUEST",
                  GOAL_OUTSIDE_MAP: "nav2's; a goal pose off the task is INVALID_REQUEST"}

STATUS_NAME = "cdh_planner: plan"
STATUS_KEYS = ("error_code", "error_msg", "planning_time_s", "charts", "cost", "strategy",
               "run_id", "log_file")


def error_code(reason):
    """PlanPath error code of a plan's reason: a Status, or its string (``"busy"``); a
    ValueError for anything else (the vocabulary is closed)."""
    return ERROR_CODES[Status(reason)]


def plan_status(result, run_id="", log_file="", name=STATUS_NAME, hardware_id=""):
    """diagnostic_msgs/DiagnosticStatus of a PlanResult: level OK on success, ERROR
    otherwise; message = the result's message (or its reason); values (strings) error_code,
    error_msg ("" on success), planning_time_s (s), charts, cost, strategy, run_id, log_file.
    Numbers are written with repr, so float(value) gives them back exactly."""
    ok = bool(result.success)
    values = {
        "error_code": str(NONE if ok else error_code(result.reason)),
        "error_msg": "" if ok else (result.message or result.reason),
        "planning_time_s": repr(float(result.time_s)),
        "charts": str(int(result.charts)),
        "cost": repr(float(result.cost)),
        "strategy": str(result.strategy),
        "run_id": str(run_id),
        "log_file": str(log_file),
    }
    msg = DiagnosticStatus()
    msg.level = DiagnosticStatus.OK if ok else DiagnosticStatus.ERROR
    msg.name = name
    msg.hardware_id = hardware_id
    msg.message = result.message or result.reason
    msg.values = [KeyValue(key=k, value=values[k]) for k in STATUS_KEYS]
    return msg


EXECUTION_NAME = "cdh_planner: execution"
EXECUTION_LEVELS = {"completed": DiagnosticStatus.OK, "stopped": DiagnosticStatus.WARN,
                    "failed": DiagnosticStatus.ERROR}


def execution_status(outcome, message, mode):
    """diagnostic_msgs/DiagnosticStatus of how an execution ended: level OK (completed),
    WARN (stopped) or ERROR (failed); values outcome and mode (stream or
    follow_joint_trajectory)."""
    return DiagnosticStatus(level=EXECUTION_LEVELS[outcome], name=EXECUTION_NAME,
                            message=f"execution {outcome}: {message}",
                            values=[KeyValue(key="outcome", value=outcome),
                                    KeyValue(key="mode", value=mode)])


def status_values(msg):
    """The key/values of a DiagnosticStatus as a dict of strings."""
    return {kv.key: kv.value for kv in msg.values}


# ----------------------------------------------------------------------------- winch command

WINCH_COMMAND_TYPE = JointState


def winch_command(names, positions, velocities, stamp, effort=(), frame_id=""):
    """The winch command (``WINCH_COMMAND_TYPE``): per winch ``names``, cable length
    ``positions`` (m), ``velocities`` (m/s) and ``effort`` (nominal tensions, N);
    ``stamp`` (builtin_interfaces/Time) is when it is sent."""
    msg = WINCH_COMMAND_TYPE()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.name = list(names)
    msg.position = np.asarray(positions, dtype=float)
    msg.velocity = np.asarray(velocities, dtype=float)
    msg.effort = np.asarray(effort, dtype=float)
    return msg


def winch_command_values(msg):
    """(t s of the stamp, positions (n,) m, velocities (n,) m/s) of a winch command."""
    return (to_seconds(msg.header.stamp), np.asarray(msg.position, dtype=float),
            np.asarray(msg.velocity, dtype=float))


def cable_command_msg(path, joint_names, t, stamp, frame_id="", method="quintic"):
    """The winch command at ``t`` (s from the start) of a timed path: one name per winch,
    position = cable length (m), velocity (m/s), effort = nominal tension (N)."""
    sample = sample_cable_state(path, t, method)
    return winch_command(check_joint_names(joint_names), sample.lengths, sample.velocities,
                         stamp, sample.effort, frame_id)
