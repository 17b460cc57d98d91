"""``/diagnostics``: the node's health once a second, as a diagnostic aggregator (and
``rqt_robot_monitor``) expects it: one diagnostic_msgs/DiagnosticStatus in a
DiagnosticArray, named ``<node>: planner``, hardware_id the robot's name.

Level: OK while active; WARN when not active (unconfigured or inactive: plans refused),
when recording has failed, or while executing without fresh joint states. A failed plan is
an answer (on ~/plan_result), not a fault of the node: it shows in the values only.
Values (strings): state (lifecycle), activity (idle, planning, executing), queued (plan
calls waiting), last_plan (its message, or "none"), last_plan_ok ("none" before the
first plan), last_plan_age_s (s) (the last plan stays through cleanup and shutdown),
recording (the run file, "off" or "failed"), joint_states_age_s (s since the last
JointState, or "none"), position_error_m (m) and orientation_error_rad (rad): the accuracy
of the last measured pose over the winches' length errors (``accuracy.pose_accuracy``;
"none" before a pose, "not given" without robot.length_error), obstacle_updates_received /
_applied / _refused / _dropped (ObstacleArrays so far). No rclpy: the node fills ``Health``
and publishes the message.
"""

from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

TOPIC = "/diagnostics"
PERIOD_S = 1.0
ACTIVE = "active"


@dataclass(frozen=True)
class Health:
    """What /diagnostics reports. Ages in seconds; None: never."""

    state: str                       # lifecycle state label: unconfigured, inactive, active
    activity: str = "idle"           # idle, planning, executing
    queued: int = 0
    last_plan: str = ""              # the last plan's status message ("" none yet)
    last_plan_ok: bool = None        # None: no plan yet
    last_plan_age_s: float = None
    recording: str = "off"           # RunLog.state: the run file, "off", "failed", ...
    joint_states_age_s: float = None
    joint_states_max_age_s: float = 1.0
    # the largest cable length error (m) of the last forward kinematics: rounding with six
    # cables; with more, how far the measured lengths are from any one pose (least squares)
    forward_kinematics_residual_m: float = None
    # the last measured pose's accuracy (m, rad); None: no pose yet; accuracy_given False:
    # the robot has no length_error
    accuracy: tuple = None
    accuracy_given: bool = False
    # ObstacleArrays on ~/obstacles: {received, applied, refused, dropped} (node/scene.py)
    obstacle_updates: dict = None


def _level_and_message(h):
    if h.state != ACTIVE:
        return DiagnosticStatus.WARN, f"{h.state}: not serving plans"
    if h.recording == "failed":  # RunLog.state
        return DiagnosticStatus.WARN, f"{h.activity}; recording failed"
    stale = h.joint_states_age_s is None or h.joint_states_age_s > h.joint_states_max_age_s
    if h.activity == "executing" and stale:
        return DiagnosticStatus.WARN, "executing without fresh joint states"
    return DiagnosticStatus.OK, h.activity


def _age(seconds):
    return "none" if seconds is None else f"{seconds:.3f}"


def _accuracy_values(h):
    """position_error_m and orientation_error_rad of Health ``h`` as strings."""
    if not h.accuracy_given:
        return {"position_error_m": "not given", "orientation_error_rad": "not given"}
    if h.accuracy is None:
        return {"position_error_m": "none", "orientation_error_rad": "none"}
    return {"position_error_m": f"{h.accuracy[0]:.4g}", "orientation_error_rad": f"{h.accuracy[1]:.4g}"}


def health_status(h, name, hardware_id=""):
    """diagnostic_msgs/DiagnosticStatus of Health ``h``."""
    level, message = _level_and_message(h)
    values = {"state": h.state, "activity": h.activity, "queued": str(h.queued),
              "last_plan": h.last_plan or "none",
              "last_plan_ok": "none" if h.last_plan_ok is None else str(h.last_plan_ok).lower(),
              "last_plan_age_s": _age(h.last_plan_age_s), "recording": h.recording,
              "joint_states_age_s": _age(h.joint_states_age_s),
              "forward_kinematics_residual_m": "none" if h.forward_kinematics_residual_m is None
              else f"{h.forward_kinematics_residual_m:.3g}",
              **_accuracy_values(h)}
    for k, v in (h.obstacle_updates or {}).items():
        values[f"obstacle_updates_{k}"] = str(v)
    return DiagnosticStatus(level=level, name=name, message=message, hardware_id=hardware_id,
                            values=[KeyValue(key=k, value=v) for k, v in values.items()])


def diagnostic_array(h, name, hardware_id, stamp):
    """DiagnosticArray of one status (``health_status``), header stamped ``stamp``."""
    msg = DiagnosticArray(status=[health_status(h, name, hardware_id)])
    msg.header.stamp = stamp
    return msg
