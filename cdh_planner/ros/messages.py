"""Conversions between the planner's data and standard ROS 2 messages (no node, no graph).

Every function here is pure: planner data in, a message out (or back). Units are SI and
frames follow REP 103: positions in m in the base frame (``frame_id`` = the configured base
frame), quaternions (x, y, z, w), cable lengths in m, tensions in N, times in s.

    path_msg(path, frame_id, stamp)                      -> nav_msgs/Path
    cable_trajectory_msg(path, joint_names, frame_id)    -> trajectory_msgs/JointTrajectory
    tension_envelope_msg(path)                           -> std_msgs/Float64MultiArray
    markers_msg(path, robot, frame_id, stamp)            -> visualization_msgs/MarkerArray
    plan_status(result, run_id, log_file)                -> diagnostic_msgs/DiagnosticStatus
    sample_cable_state(path, t)                          -> CableSample (lengths, velocities,
                                                            effort)
    cable_command_msg(path, joint_names, t, stamp)       -> sensor_msgs/JointState
    pose_from_msg(msg, base_frame, field) / pose_msg(pose, frame_id, stamp)
"""

from dataclasses import dataclass

import numpy as np
from builtin_interfaces.msg import Duration, Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, PoseStamped
from nav_msgs.msg import Path
from sensor_msgs.msg import JointState
from std_msgs.msg import ColorRGBA, Float64MultiArray, MultiArrayDimension
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from visualization_msgs.msg import Marker, MarkerArray

from ..errors import InputError
from ..model.pose import check_quaternion, quaternion_from_tau, rotation_from_quaternion, \
    tau_from_quaternion
from ..model.robot import N_CABLES
from ..planner import Pose
from ..status import Status

NS_PER_S = 1_000_000_000

# ----------------------------------------------------------------------------- time

def time_msg(ns):
    """builtin_interfaces/Time of an integer number of nanoseconds (>= 0)."""
    ns = int(ns)
    if ns < 0:
        raise InputError("stamp", ns, "a ROS time cannot be negative")
    return Time(sec=ns // NS_PER_S, nanosec=ns % NS_PER_S)


def time_ns(stamp):
    """Integer nanoseconds of a builtin_interfaces/Time."""
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


def duration_s(duration):
    """Seconds (float) of a builtin_interfaces/Duration."""
    return duration.sec + duration.nanosec * 1e-9


def _stamp_plus(stamp, seconds):
    return time_msg(time_ns(stamp) + seconds_ns(seconds))


# ----------------------------------------------------------------------------- checks

def check_joint_names(names, field="joint_names"):
    """Six distinct non-empty strings (the robot's winch_names) -> list."""
    names = list(names)
    if len(names) != N_CABLES or not all(isinstance(n, str) and n for n in names) \
            or len(set(names)) != N_CABLES:
        raise InputError(field, names, f"expected {N_CABLES} distinct non-empty names")
    return names


def _check_path(path):
    n = len(path)
    for name in ("lengths", "velocities", "accelerations", "tension_min", "tension_nominal",
                 "tension_max"):
        shape = np.shape(getattr(path, name))
        if shape != (n, N_CABLES):
            raise InputError(f"path.{name}", f"shape {shape}", f"expected ({n}, {N_CABLES})")
    if np.shape(path.t) != (n,):
        raise InputError("path.t", f"shape {np.shape(path.t)}", f"expected ({n},)")
    if n and (not np.all(np.isfinite(path.t)) or path.t[0] < 0 or np.any(np.diff(path.t) <= 0)):
        raise InputError("path.t", np.asarray(path.t).tolist()[:8],
                         "must start >= 0 and strictly increase (time-parameterise the path)")


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


def _fill_pose(pose, p, q):
    pose.position.x, pose.position.y, pose.position.z = (float(v) for v in p)
    o = pose.orientation
    o.x, o.y, o.z, o.w = (float(v) for v in q)


# ----------------------------------------------------------------------------- path, trajectory

def path_msg(path, frame_id, stamp):
    """nav_msgs/Path of a PlannedPath: header (frame_id, stamp = start), one PoseStamped per
    waypoint in ``frame_id`` with stamp = start + t_k."""
    _check_path(path)
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
    winch_names): positions = cable lengths (m), velocities (m/s), accelerations (m/s^2),
    effort = nominal tensions (N), time_from_start = t (s).

    ``stamp`` None (zero) means "start on receipt" to a ros2_control
    JointTrajectoryController; a non-zero stamp is an absolute start time.
    """
    _check_path(path)
    msg = JointTrajectory()
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp if stamp is not None else Time()
    msg.joint_names = check_joint_names(joint_names)
    for k in range(len(path)):
        pt = JointTrajectoryPoint()
        pt.positions = path.lengths[k].astype(float)
        pt.velocities = path.velocities[k].astype(float)
        pt.accelerations = path.accelerations[k].astype(float)
        pt.effort = path.tension_nominal[k].astype(float)
        pt.time_from_start = duration_msg(path.t[k])
        msg.points.append(pt)
    return msg


ENVELOPE_DIMS = ("waypoint", "cable", "bound")


def tension_envelope_msg(path):
    """std_msgs/Float64MultiArray of the tension envelope (N): element (k, i, j) = bound j
    (min, nominal, max) of cable i at waypoint k, at data[k*18 + i*3 + j]. Layout dims
    ``waypoint`` (size N, stride 18 N), ``cable`` (6, 18), ``bound`` (3, 3), data_offset 0,
    per std_msgs/MultiArrayLayout (stride = size of the dimension and all inner ones)."""
    _check_path(path)
    env = np.stack([path.tension_min, path.tension_nominal, path.tension_max], axis=-1)
    msg = Float64MultiArray()
    sizes = env.shape
    for d, label in enumerate(ENVELOPE_DIMS):
        msg.layout.dim.append(MultiArrayDimension(label=label, size=int(sizes[d]),
                                                  stride=int(np.prod(sizes[d:]))))
    msg.layout.data_offset = 0
    msg.data = env.astype(float).ravel()
    return msg


def envelope_from_msg(msg):
    """(N, 6, 3) array back from a tension envelope message, read through its strides."""
    dims = {d.label: d for d in msg.layout.dim}
    if tuple(d.label for d in msg.layout.dim) != ENVELOPE_DIMS:
        raise InputError("layout.dim", [d.label for d in msg.layout.dim],
                         f"expected labels {ENVELOPE_DIMS}")
    data = np.asarray(msg.data, dtype=float)
    w, c, b = np.meshgrid(*(np.arange(dims[label].size) for label in ENVELOPE_DIMS),
                          indexing="ij")
    # multiarray(w, c, b) = data[data_offset + dim[1].stride * w + dim[2].stride * c + b]
    index = msg.layout.data_offset + dims["cable"].stride * w + dims["bound"].stride * c + b
    return data[index]


# ----------------------------------------------------------------------------- markers

LINE_WIDTH_M = 0.002
MARGIN_FULL = 0.2  # normalised tension margin drawn fully green (0 or less: red)
PATH_COLOR = (0.2, 0.5, 1.0, 1.0)
PLATFORM_COLORS = ((0.3, 0.3, 0.3, 1.0), (0.0, 0.0, 0.0, 1.0))  # first, last pose


def cable_margins(path, robot):
    """Per waypoint and cable, the normalised tension margin (N, 6): distance of the envelope
    to the robot's tension limits over the limit range, as in feasibility (positive inside)."""
    span = robot.tension_max - robot.tension_min
    low = (np.asarray(path.tension_min) - robot.tension_min) / span
    high = (robot.tension_max - np.asarray(path.tension_max)) / span
    return np.minimum(low, high)


def margin_color(margin, full=MARGIN_FULL):
    """RGBA of a normalised margin: red at <= 0, yellow at full/2, green at >= full
    (not finite: red)."""
    m = float(margin)
    x = float(np.clip(m / full, 0.0, 1.0)) if np.isfinite(m) else 0.0
    red = min(1.0, 2.0 * (1.0 - x))
    green = min(1.0, 2.0 * x) * 0.8
    return ColorRGBA(r=red, g=green, b=0.0, a=1.0)


def markers_msg(path, robot, frame_id, stamp, *, line_width=LINE_WIDTH_M, delete_all=True):
    """visualization_msgs/MarkerArray for RViz / Foxglove, all in ``frame_id`` (m):

    - ns ``path`` id 0: LINE_STRIP through the platform positions p;
    - ns ``platform`` ids 0, 1: the platform at the first / last pose, a closed LINE_STRIP
      through its anchor points p + R b_i (distinct points, by angle around their centre);
    - ns ``cables`` ids 0, 1: at the first / last pose, LINE_LIST of the six cables from the
      base anchor a_i to p + R b_i, each coloured by its tension margin (``margin_color``).

    With ``delete_all`` a DELETEALL marker comes first, so a new plan replaces the old one.
    """
    _check_path(path)
    out = MarkerArray()
    if delete_all:
        clear = Marker(action=Marker.DELETEALL)
        clear.header.frame_id, clear.header.stamp = frame_id, stamp
        out.markers.append(clear)
    if len(path) == 0:
        return out
    line = _marker(frame_id, stamp, "path", 0, Marker.LINE_STRIP, line_width, PATH_COLOR)
    line.points = [_point(p) for p in path.p]
    out.markers.append(line)
    margins = cable_margins(path, robot)
    for ident, k in enumerate((0, len(path) - 1)):
        R = rotation_from_quaternion(path.quaternion[k])
        attach = path.p[k] + robot.platform_anchors @ R.T
        out.markers.append(_platform_marker(frame_id, stamp, ident, attach, robot, line_width))
        out.markers.append(_cables_marker(frame_id, stamp, ident, robot.base_anchors, attach,
                                          margins[k], line_width))
    return out


def _marker(frame_id, stamp, ns, ident, kind, line_width, color=(1.0, 1.0, 1.0, 1.0)):
    """A line marker (LINE_STRIP / LINE_LIST) with identity pose: points are in frame_id."""
    m = Marker()
    m.header.frame_id = frame_id
    m.header.stamp = stamp
    m.ns, m.id, m.type, m.action = ns, ident, kind, Marker.ADD
    m.pose.orientation.w = 1.0
    m.scale.x = float(line_width)
    m.color = ColorRGBA(r=color[0], g=color[1], b=color[2], a=color[3])
    return m


def _point(p):
    return Point(x=float(p[0]), y=float(p[1]), z=float(p[2]))


def _platform_marker(frame_id, stamp, ident, attach, robot, line_width):
    """Closed outline through the distinct platform anchors, ordered by angle in the
    platform's own x-y plane."""
    local = robot.platform_anchors
    _, first = np.unique(np.round(local, 9), axis=0, return_index=True)
    idx = np.sort(first)
    centre = local[idx].mean(axis=0)
    angle = np.arctan2(local[idx, 1] - centre[1], local[idx, 0] - centre[0])
    ring = idx[np.argsort(angle)]
    m = _marker(frame_id, stamp, "platform", ident, Marker.LINE_STRIP, line_width,
                PLATFORM_COLORS[ident])
    m.points = [_point(attach[i]) for i in list(ring) + [ring[0]]]
    return m


def _cables_marker(frame_id, stamp, ident, anchors, attach, margins, line_width):
    m = _marker(frame_id, stamp, "cables", ident, Marker.LINE_LIST, line_width)
    for a, b, margin in zip(anchors, attach, margins):
        color = margin_color(margin)
        m.points.extend([_point(a), _point(b)])
        m.colors.extend([color, color])
    return m


# ----------------------------------------------------------------------------- plan result

# nav2_msgs/action/ComputePathToPose (Jazzy) result error codes.
NONE, UNKNOWN, INVALID_PLANNER, TF_ERROR = 0, 200, 201, 202
START_OUTSIDE_MAP, GOAL_OUTSIDE_MAP, START_OCCUPIED, GOAL_OCCUPIED = 203, 204, 205, 206
TIMEOUT, NO_VALID_PATH = 207, 208

ERROR_CODES = {
    Status.OK: NONE,
    Status.START_INFEASIBLE: START_OCCUPIED,  # start not wrench-feasible (or off the task)
    Status.GOAL_INFEASIBLE: GOAL_OCCUPIED,    # goal not wrench-feasible (or off the task)
    Status.NO_PATH: NO_VALID_PATH,            # a component exhausted
    Status.TIMEOUT: TIMEOUT,
    Status.CHART_LIMIT: NO_VALID_PATH,        # no path found within max_charts
    Status.RESOURCE_LIMIT: NO_VALID_PATH,     # no path found within max_memory_mb
    Status.CANCELED: UNKNOWN,                 # the caller cancelled the plan
    Status.INVALID: UNKNOWN,                  # request inconsistent with the task / malformed
    # refusals by the node, before planning:
    "bad_frame": TF_ERROR,                # frame_id is not the base frame
    "busy": UNKNOWN,                      # a plan is already running
}

STATUS_NAME = "cdh_planner: plan"
STATUS_KEYS = ("error_code", "error_msg", "planning_time_s", "charts", "cost", "strategy",
               "run_id", "log_file")


def error_code(reason):
    """nav2 ComputePathToPose error code of a planner reason (a Status) or of a node
    refusal (``bad_frame``, ``busy``); UNKNOWN for anything else."""
    return ERROR_CODES.get(reason, UNKNOWN)


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


def status_values(msg):
    """The key/values of a DiagnosticStatus as a dict of strings."""
    return {kv.key: kv.value for kv in msg.values}


# ----------------------------------------------------------------------------- sampling

@dataclass(frozen=True)
class CableSample:
    """Cable command at one instant: ``lengths`` (6,) m, ``velocities`` (6,) m/s,
    ``effort`` (6,) N (nominal tensions)."""

    lengths: np.ndarray
    velocities: np.ndarray
    effort: np.ndarray


def sample_cable_state(path, t, method="quintic"):
    """Cable lengths, velocities and nominal tensions at time ``t`` (s from the start).

    ``method``: ``quintic`` interpolates each segment with the quintic through position,
    velocity and acceleration at both ends, as ros2_control's JointTrajectoryController
    does with the same points (so streaming and the controller agree; at a waypoint it
    returns that waypoint); ``linear`` moves on the straight cable-space segment at its mean
    velocity (L_{k+1} - L_k) / h_k, which never exceeds the speed limit. Effort is linear in
    t. Outside [t_0, t_end] the path is clamped to its end and held (velocity 0).
    """
    _check_path(path)
    t = float(t)
    if not np.isfinite(t):
        raise InputError("t", t, "must be a finite number of seconds")
    if method not in ("quintic", "linear"):
        raise InputError("method", method, "expected 'quintic' or 'linear'")
    n, T = len(path), np.asarray(path.t, dtype=float)
    if n == 1 or t <= T[0] or t >= T[-1]:
        k = 0 if (n == 1 or t <= T[0]) else n - 1
        inside = n > 1 and t == T[k]
        vel = path.velocities[k] if inside else np.zeros(N_CABLES)
        return CableSample(lengths=np.array(path.lengths[k], dtype=float),
                           velocities=np.array(vel, dtype=float),
                           effort=np.array(path.tension_nominal[k], dtype=float))
    k = int(np.searchsorted(T, t, side="right") - 1)
    h = T[k + 1] - T[k]
    s = (t - T[k]) / h
    effort = (1 - s) * path.tension_nominal[k] + s * path.tension_nominal[k + 1]
    if method == "linear":
        rate = (path.lengths[k + 1] - path.lengths[k]) / h
        return CableSample(lengths=path.lengths[k] + rate * (t - T[k]), velocities=rate,
                           effort=np.asarray(effort, dtype=float))
    pos, vel = quintic_hermite(s, h, path.lengths[k], path.velocities[k], path.accelerations[k],
                               path.lengths[k + 1], path.velocities[k + 1],
                               path.accelerations[k + 1])
    return CableSample(lengths=pos, velocities=vel, effort=np.asarray(effort, dtype=float))


def quintic_hermite(s, h, p0, v0, a0, p1, v1, a1):
    """Position and velocity at fraction ``s`` in [0, 1] of a segment of duration ``h`` (s)
    of the quintic matching position, velocity and acceleration at both ends."""
    s2, s3, s4, s5 = s * s, s ** 3, s ** 4, s ** 5
    basis = np.array([1 - 10 * s3 + 15 * s4 - 6 * s5,            # p0
                      s - 6 * s3 + 8 * s4 - 3 * s5,               # v0 h
                      0.5 * s2 - 1.5 * s3 + 1.5 * s4 - 0.5 * s5,  # a0 h^2
                      0.5 * s3 - s4 + 0.5 * s5,                   # a1 h^2
                      -4 * s3 + 7 * s4 - 3 * s5,                  # v1 h
                      10 * s3 - 15 * s4 + 6 * s5])                # p1
    slope = np.array([-30 * s2 + 60 * s3 - 30 * s4,
                      1 - 18 * s2 + 32 * s3 - 15 * s4,
                      s - 4.5 * s2 + 6 * s3 - 2.5 * s4,
                      1.5 * s2 - 4 * s3 + 2.5 * s4,
                      -12 * s2 + 28 * s3 - 15 * s4,
                      30 * s2 - 60 * s3 + 30 * s4])
    terms = np.array([p0, v0 * h, a0 * h * h, a1 * h * h, v1 * h, p1], dtype=float)
    return basis @ terms, (slope @ terms) / h


def cable_command_msg(path, joint_names, t, stamp, frame_id="", method="quintic"):
    """sensor_msgs/JointState of the cable command at ``t`` (s from the start): one name
    per winch, position = cable length (m), velocity (m/s), effort = nominal tension (N);
    header.stamp = ``stamp`` (when the command is sent)."""
    sample = sample_cable_state(path, t, method)
    msg = JointState()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.name = check_joint_names(joint_names)
    msg.position = sample.lengths.astype(float)
    msg.velocity = sample.velocities.astype(float)
    msg.effort = sample.effort.astype(float)
    return msg
