"""Executing a plan on a ros2_control JointTrajectoryController, and reading where the
winches are (library code for the node: rclpy, no Node subclass).

    goal = fjt_goal(cable_trajectory)                 # control_msgs FollowJointTrajectory goal
    monitor = JointStateMonitor(node, "/joint_states", robot.winch_names)
    lengths, why = monitor.lengths(max_age_s=0.5)     # (m,) m, or None and why not
    problem = start_mismatch(lengths, planned_first, 0.005, robot.winch_names)
    p, R = current_pose(robot, lengths, guess=(p_last, R_last))
    executor = TrajectoryExecutor(node, "/cable_controller/follow_joint_trajectory")
    executor.start(cable_trajectory, on_done)         # on_done(outcome, message), once
    executor.cancel()                                 # -> on_done(STOPPED, ...)

Units: cable lengths in m, times in s, tensions in N. A winch's joint position is its cable
length (m), as in ``messages.cable_trajectory_msg``.

The controller gets positions, velocities and accelerations only: a stock Jazzy
JointTrajectoryController without an effort command interface rejects a trajectory with
effort fields (its ``validate_trajectory_msg``), so the nominal tensions stay on the tension
envelope topic.
"""

import threading
import time

import numpy as np
from action_msgs.msg import GoalStatus
from action_msgs.srv import CancelGoal
from control_msgs.action import FollowJointTrajectory
from ..actions import RaceFreeActionClient
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from ...errors import InputError, check_finite, exception_line
from ...wrench import wrench_feasibility
from ...model.forward_kinematics import current_pose as _current_pose
from ..interface import ACTION_QOS
from ..core.live_state import measured_tensions
from ..msgs.messages import check_joint_names, duration_msg
from ..polled import PolledSubscription

COMPLETED, STOPPED, FAILED = "completed", "stopped", "failed"

# s: how late the controller may reach the last point before it aborts the goal
# (GOAL_TOLERANCE_VIOLATED; only checked for joints with a goal tolerance). 0 leaves it to
# the controller's own constraints.goal_time.
GOAL_TIME_TOLERANCE_S = 0.5
# s: how long start() waits for the action server to appear (polled by a timer, so no
# executor thread ever waits): long enough for DDS discovery of a server that is up,
# short enough that "no controller" is answered at once.
SERVER_WAIT_S = 1.0
SERVER_POLL_S = 0.05
# s: how often a wait for joint states looks whether it was cancelled
CANCEL_POLL_S = 0.05
# beyond the trajectory's end and the goal time tolerance, how long (s) a result may take
# before the execution is given up as failed
RESULT_MARGIN_S = 5.0
# The joint state subscription: best effort matches both a reliable publisher
# (ros2_control's joint_state_broadcaster: reliable, volatile, depth 10) and a best-effort
# one (many drivers use the sensor data profile); a reliable subscription would not hear
# the latter at all. Only the latest message is used: depth 1, and a lost one does not matter.
JOINT_STATE_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                             durability=DurabilityPolicy.VOLATILE)

ERROR_NAMES = {getattr(FollowJointTrajectory.Result, name): name for name in (
    "SUCCESSFUL", "INVALID_GOAL", "INVALID_JOINTS", "OLD_HEADER_TIMESTAMP",
    "PATH_TOLERANCE_VIOLATED", "GOAL_TOLERANCE_VIOLATED")}
STATUS_NAMES = {getattr(GoalStatus, name): name[len("STATUS_"):].lower() for name in (
    "STATUS_UNKNOWN", "STATUS_ACCEPTED", "STATUS_EXECUTING", "STATUS_CANCELING",
    "STATUS_SUCCEEDED", "STATUS_CANCELED", "STATUS_ABORTED")}


# ----------------------------------------------------------------------------- messages

def fjt_goal(trajectory_msg, goal_time_tolerance_s=GOAL_TIME_TOLERANCE_S):
    """control_msgs/FollowJointTrajectory goal of a trajectory_msgs/JointTrajectory (one
    joint per winch: positions m, velocities m/s, accelerations m/s^2, time_from_start s):
    the same joint names and points WITHOUT effort, header stamp zero ("start on receipt":
    a plan's stamp is when it was made, and a past start would be rejected or skipped),
    ``goal_time_tolerance_s`` (s, >= 0; 0: the controller's default). No path or goal
    tolerances: the controller's configured ones apply."""
    if not isinstance(trajectory_msg, JointTrajectory):
        raise InputError("trajectory", type(trajectory_msg).__name__,
                         "expected a trajectory_msgs/JointTrajectory")
    tolerance = check_finite("goal_time_tolerance_s", goal_time_tolerance_s)
    if tolerance < 0:
        raise InputError("goal_time_tolerance_s", tolerance, "must be >= 0 s")
    goal = FollowJointTrajectory.Goal()
    goal.goal_time_tolerance = duration_msg(tolerance)
    trajectory = goal.trajectory
    trajectory.header.frame_id = trajectory_msg.header.frame_id
    trajectory.joint_names = list(trajectory_msg.joint_names)
    # new points rather than copies: effort stays empty whatever the source holds
    trajectory.points = [JointTrajectoryPoint(
        positions=pt.positions, velocities=pt.velocities, accelerations=pt.accelerations,
        time_from_start=pt.time_from_start) for pt in trajectory_msg.points]
    return goal


def measured_lengths(joint_state, winch_names):
    """Cable lengths (6,) m of a sensor_msgs/JointState in the order of ``winch_names``;
    the message's joints may come in any order, other joints are ignored. InputError naming
    the winch that is missing (or has no position, or is named twice) or whose length is not
    a finite number > 0."""
    names = check_joint_names(winch_names, "winch_names")
    index = {}
    for k, name in enumerate(joint_state.name):
        if name in index and name in names:
            raise InputError("joint_states.name", name, "winch named twice in one message")
        index.setdefault(name, k)
    positions = joint_state.position
    lengths = np.empty(len(names))
    for i, name in enumerate(names):
        k = index.get(name)
        if k is None:
            raise InputError("joint_states.name", name,
                             "winch missing from the joint state message")
        if k >= len(positions):
            raise InputError(f"joint_states.position[{name}]", None,
                             f"no position for this winch ({len(positions)} positions for "
                             f"{len(joint_state.name)} names)")
        value = float(positions[k])
        if not np.isfinite(value) or value <= 0:
            raise InputError(f"joint_states.position[{name}]", value,
                             "cable length must be a finite number > 0 (m)")
        lengths[i] = value
    return lengths


def start_mismatch(measured, planned_first, tolerance_m, winch_names):
    """None when every measured cable length (m) is within ``tolerance_m`` (m) of the plan's
    first point, else one line naming the largest distance (m), its winch and the
    tolerance: the controller would jump there, or interpolate from where it is at a speed
    the plan never checked."""
    measured = np.asarray(measured, dtype=float).reshape(-1)
    planned = np.asarray(planned_first, dtype=float).reshape(-1)
    names = list(winch_names)
    if not measured.shape == planned.shape == (len(names),):
        raise InputError("measured", measured.tolist(),
                         f"expected {len(names)} lengths like planned_first "
                         f"({planned.size})")
    tolerance = check_finite("tolerance_m", tolerance_m)
    distance = np.abs(measured - planned)
    if not np.all(np.isfinite(distance)):
        raise InputError("measured", measured.tolist(), "cable lengths must be finite (m)")
    i = int(np.argmax(distance))
    if distance[i] <= tolerance:
        return None
    return (f"the winches are not at the plan's start: {names[i]} is {distance[i]:.4f} m "
            f"from it (measured {measured[i]:.4f} m, planned {planned[i]:.4f} m; "
            f"tolerance {tolerance:g} m)")


# ----------------------------------------------------------------------------- pose

def current_pose(robot, lengths, guess=None, known=()):
    """``model.forward_kinematics.current_pose``, wrench-feasible solutions preferred."""
    return _current_pose(robot, lengths, guess, feasible=lambda p, R: bool(
        wrench_feasibility(robot, p[None], R=R[None]).feasible[0]), known=known)


# ----------------------------------------------------------------------------- joint states

class JointStateMonitor:
    """The latest sensor_msgs/JointState on ``topic`` and when it arrived (monotonic),
    read when asked (``polled.PolledSubscription``: no executor work per message).

    ``measured(max_age_s)`` gives the winches' cable lengths (m,) m in the order of
    ``winch_names`` and the efforts (measured tensions, N, or None) of the same message, or
    None and why not: nothing received yet, the last message older than ``max_age_s`` (s),
    or a winch missing or not a length in it. ``wait_measured`` also waits, a bounded time,
    for a message when there is none recent enough; ``lengths`` / ``wait_lengths`` are
    those without the efforts. Lengths and efforts come from one message read once: the
    live state and a plan's measured start read it from two threads.
    """

    def __init__(self, node, topic, winch_names):
        self._node = node
        self.winch_names = check_joint_names(winch_names, "winch_names")
        self._lock = threading.Lock()
        self._latest = None          # (JointState, time.monotonic() of arrival)
        self.subscription = PolledSubscription(node, JointState, topic, JOINT_STATE_QOS)
        self.topic = self.subscription.topic_name

    @property
    def latest(self):
        """(the last JointState, its arrival time.monotonic() s), or None."""
        with self._lock:
            taken = self.subscription.take()
            if taken:
                self._latest = taken[-1]
            return self._latest

    def wait_lengths(self, max_age_s, wait_s, cancelled=lambda: False):
        """``wait_measured`` without the efforts: (lengths, why)."""
        lengths, _, why = self.wait_measured(max_age_s, wait_s, cancelled)
        return lengths, why

    def wait_measured(self, max_age_s, wait_s, cancelled=lambda: False):
        """``measured(max_age_s)``, waiting up to ``wait_s`` (s) for a message while none is
        recent enough (processes started together can take a DDS announcement period,
        about 3 s, to find each other), looking every CANCEL_POLL_S, and no longer once
        ``cancelled()`` is true. A message that names the winches wrongly is answered at once."""
        end = time.monotonic() + wait_s
        while True:
            latest = self.latest
            recent = latest is not None and time.monotonic() - latest[1] <= max_age_s
            left = end - time.monotonic()
            if recent or left <= 0 or cancelled():
                return self.measured(max_age_s)
            time.sleep(min(left, CANCEL_POLL_S))

    def lengths(self, max_age_s):
        """``measured`` without the efforts: (cable lengths (m,) m, "") or (None, why)."""
        lengths, _, why = self.measured(max_age_s)
        return lengths, why

    def measured(self, max_age_s):
        """(cable lengths (m,) m, efforts (m,) N or None, "") of the latest message, or
        (None, None, the reason)."""
        latest = self.latest
        if latest is None:
            # Which of the two: a name or discovery problem, or a publisher that is silent.
            seen = self._node.count_publishers(self.topic)
            return None, None, (f"nothing received on {self.topic} "
                                f"({'no' if seen == 0 else seen} publisher{'s' * (seen != 1)} seen)")
        msg, arrived = latest
        age = time.monotonic() - arrived
        if age > max_age_s:
            return None, None, (f"the last joint state on {self.topic} is {age:.2f} s old "
                                f"(at most {max_age_s:g} s)")
        try:
            return (measured_lengths(msg, self.winch_names),
                    measured_tensions(msg, self.winch_names), "")
        except InputError as exc:
            return None, None, f"joint state on {self.topic}: {exc}"

    def destroy(self):
        self.subscription.destroy()


# ----------------------------------------------------------------------------- execution

class _Run:
    """One start() call: its goal, where it is, and whether on_done has been called."""

    def __init__(self, on_done):
        self.on_done = on_done
        self.goal = None
        self.handle = None           # ClientGoalHandle once accepted
        self.timer = None            # polls for the server before sending; then bounds the
                                     # wait for the result
        self.deadline = 0.0
        self.cancel_requested = False
        self.sent = False            # send_goal_async called (once: timer callbacks may overlap)
        self.done = False
        self.on_accepted = None


class TrajectoryExecutor:
    """Runs a cable trajectory on a FollowJointTrajectory action server (a ros2_control
    JointTrajectoryController) without ever blocking an executor thread: every step
    continues in a future's done callback or a timer.

    ``start(trajectory_msg, on_done)`` calls ``on_done(outcome, message)`` exactly once
    (from an executor thread, or before start returns when it is refused at once):

    - COMPLETED: the server succeeded with error_code SUCCESSFUL;
    - STOPPED: ended by ``cancel()`` (before it was sent, or canceled by the server);
    - FAILED: a bad trajectory, already busy, no server within ``server_wait_s`` (s),
      the goal rejected (the controller logs why: joint names, effort fields, times, a
      non-zero final velocity), aborted or failed with an error code (its name and
      error_string: INVALID_GOAL, PATH_TOLERANCE_VIOLATED, ...), canceled by someone else,
      or no result within the trajectory's duration + goal time tolerance +
      ``result_margin_s`` (s) of acceptance (the goal is then cancelled).

    The node must be spun by an executor (timers and action responses).
    """

    def __init__(self, node, action_name, callback_group=None, server_wait_s=SERVER_WAIT_S,
                 goal_time_tolerance_s=GOAL_TIME_TOLERANCE_S, result_margin_s=RESULT_MARGIN_S):
        self._node = node
        self._group = callback_group
        self._client = RaceFreeActionClient(node, FollowJointTrajectory, action_name,
                                            callback_group=callback_group, **ACTION_QOS)
        self.action_name = action_name
        self.server_wait_s = float(server_wait_s)
        self.goal_time_tolerance_s = goal_time_tolerance_s
        self.result_margin_s = float(result_margin_s)
        self._lock = threading.Lock()
        self._run = None

    @property
    def busy(self):
        """True from start() until on_done has been called."""
        with self._lock:
            return self._run is not None

    def start(self, trajectory_msg, on_done, on_accepted=None):
        """Send ``trajectory_msg`` (trajectory_msgs/JointTrajectory) as a goal
        (``fjt_goal``); ``on_done(outcome, message)`` is called exactly once, and
        ``on_accepted()`` (if given) when the controller accepts the goal."""
        run = _Run(on_done)
        run.on_accepted = on_accepted
        with self._lock:
            busy = self._run is not None
            if not busy:
                self._run = run
        if busy:
            _call(self._node, on_done, FAILED,
                  f"refused: already executing a trajectory on {self.action_name}")
            return
        try:
            run.goal = fjt_goal(trajectory_msg, self.goal_time_tolerance_s)
        except InputError as exc:
            self._finish(run, FAILED, f"not sent: {exc}")
            return
        if self._client.server_is_ready():
            self._send(run)
            return
        # Not there yet (or not yet discovered): poll from a timer rather than wait here,
        # since start() is typically called from a service callback on an executor thread.
        run.deadline = time.monotonic() + self.server_wait_s
        with self._lock:
            if not run.done:
                run.timer = self._node.create_timer(SERVER_POLL_S, lambda: self._poll(run),
                                                    callback_group=self._group)

    def cancel(self):
        """Ask the server to cancel the running goal (on_done then gets STOPPED once the
        server has canceled it). False when nothing is running."""
        with self._lock:
            run = self._run
            if run is None:
                return False
            run.cancel_requested = True
            handle = run.handle
        if handle is not None:
            self._request_cancel(run, handle)
        # else: the server poll or the goal response sees cancel_requested
        return True

    def destroy(self):
        """Destroy the action client (a running goal is not canceled)."""
        self._client.destroy()

    # -------------------------------------------------------------- steps

    def _poll(self, run):
        if run.done:
            self._drop_timer(run)
        elif run.cancel_requested:
            self._finish(run, STOPPED, "stopped before the trajectory was sent")
        elif self._client.server_is_ready():
            self._drop_timer(run)
            self._send(run)
        elif time.monotonic() >= run.deadline:
            self._finish(run, FAILED,
                         f"no action server {self.action_name} within {self.server_wait_s:g} s "
                         f"(is the trajectory controller loaded and active?)")

    def _send(self, run):
        with self._lock:
            first, run.sent = not run.sent, True
        if not first:
            return
        if run.cancel_requested:
            self._finish(run, STOPPED, "stopped before the trajectory was sent")
            return
        try:
            future = self._client.send_goal_async(run.goal)
        except Exception as exc:  # noqa: BLE001 - e.g. the context shut down: tell the caller
            self._finish(run, FAILED, f"sending the goal to {self.action_name} failed: "
                                      f"{exception_line(exc)}")
            return
        future.add_done_callback(lambda f: self._goal_response(run, f))

    def _answer(self, run, future, what):
        """(True, the future's value), or (False, None) once the run has ended as failed:
        no ``what`` from the action server, and why."""
        try:
            return True, future.result()
        except Exception as exc:  # noqa: BLE001
            self._finish(run, FAILED, f"no {what} from {self.action_name}: "
                                      f"{exception_line(exc)}")
            return False, None

    def _goal_response(self, run, future):
        answered, handle = self._answer(run, future, "goal response")
        if not answered:
            return
        if handle is None or not handle.accepted:
            self._finish(run, FAILED,
                         f"rejected by {self.action_name} (the controller's log says why: "
                         f"joint names, effort fields, times or a non-zero final velocity)")
            return
        with self._lock:
            run.handle = handle
            cancel = run.cancel_requested
            if not run.done:   # a server that dies mid-goal must not leave us busy forever
                run.timer = self._node.create_timer(self._result_wait_s(run.goal),
                                                    lambda: self._no_result(run),
                                                    callback_group=self._group)
        if run.on_accepted is not None:
            _call(self._node, run.on_accepted)
        handle.get_result_async().add_done_callback(lambda f: self._result(run, f))
        if cancel:
            self._request_cancel(run, handle)

    def _result_wait_s(self, goal):
        """How long (s) after acceptance a result may take: the trajectory's duration, the
        goal time tolerance and ``result_margin_s``."""
        end = goal.trajectory.points[-1].time_from_start
        return end.sec + end.nanosec * 1e-9 + self.goal_time_tolerance_s + self.result_margin_s

    def _no_result(self, run):
        handle = run.handle
        self._finish(run, FAILED, f"no result from {self.action_name} within "
                                  f"{self._result_wait_s(run.goal):.1f} s of acceptance (the "
                                  f"controller went away?); its goal is cancelled")
        if handle is not None:
            self._request_cancel(run, handle)

    def _request_cancel(self, run, handle):
        def answered(future):
            response = future.result() if future.exception() is None else None
            if response is None or response.return_code not in (
                    CancelGoal.Response.ERROR_NONE, CancelGoal.Response.ERROR_GOAL_TERMINATED):
                code = "no answer" if response is None else f"code {response.return_code}"
                self._node.get_logger().warning(
                    f"cancel of the trajectory on {self.action_name} refused ({code}); "
                    f"it runs on")
        handle.cancel_goal_async().add_done_callback(answered)

    def _result(self, run, future):
        answered, response = self._answer(run, future, "result")
        if not answered:
            return
        status, result = response.status, response.result
        code = result.error_code
        code_text = f"{ERROR_NAMES.get(code, 'error_code')} ({code})"
        detail = f": {result.error_string}" if result.error_string else ""
        succeeded = code == FollowJointTrajectory.Result.SUCCESSFUL
        if status == GoalStatus.STATUS_SUCCEEDED and succeeded:
            self._finish(run, COMPLETED, f"completed on {self.action_name}{detail}")
        elif status == GoalStatus.STATUS_CANCELED and run.cancel_requested:
            self._finish(run, STOPPED, f"stopped on request: canceled by {self.action_name}")
        elif status == GoalStatus.STATUS_CANCELED:
            self._finish(run, FAILED, f"canceled by {self.action_name}, not by this node: "
                                      f"{code_text}{detail}")
        else:
            self._finish(run, FAILED, f"{STATUS_NAMES.get(status, status)} by "
                                      f"{self.action_name}: {code_text}{detail}")

    def _finish(self, run, outcome, message):
        """on_done, once per run; the executor is free for the next start() before it runs."""
        with self._lock:
            if run.done:
                return
            run.done = True
            if self._run is run:
                self._run = None
        self._drop_timer(run)
        _call(self._node, run.on_done, outcome, message)

    def _drop_timer(self, run):
        with self._lock:
            timer, run.timer = run.timer, None
        if timer is not None:
            timer.cancel()
            self._node.destroy_timer(timer)


def _call(node, callback, *args):
    """The caller's callback; what it raises is logged, never passed into the executor."""
    try:
        callback(*args)
    except Exception as exc:  # noqa: BLE001
        node.get_logger().error(f"trajectory callback failed: {exception_line(exc)}")
