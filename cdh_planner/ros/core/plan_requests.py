"""One plan call, without the graph: request -> poses -> PlanResult -> messages.

The node (``ros/node/planner_node.py``) only moves these values between ROS and this module:

    turn = queue.enter()                                      # None: full, answer busy
    call = PlanCall.of_get_plan(request)                      # or of_plan_path(goal, ...)
    queue.wait(turn, call.cancel)                             # False: closed or cancelled
                                                              # (refused before: drop(turn))
    start, goal = request_poses(call, base_frame)             # InputError: refuse
    result = run_planner(planner, start, goal, call, progress)  # never raises
    queue.leave()
    result = output_refusal(result) or result                 # too long / too many points
    outputs = plan_outputs(result, robot, base_frame, stamp)  # messages to publish
    status = result_status(result, robot, run_id, log_file, stamp, outputs=...)

Refusals before planning (bad frame, invalid pose, busy) and after it (outputs beyond the
bounds, internal errors) are PlanResults too (``refusal``), so every answer has one
``~/plan_result`` with an error code (``messages.ERROR_CODES``: PlanPath's, nav2's where
one fits).
"""

import collections
import math
import threading
import time
import traceback
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from nav_msgs.msg import Path

from cdh_planner_interfaces.action import PlanPath

from ...errors import InputError, exception_line
from ...model.pose import on_singular_set
from ...planner import PlanResult
from ...settings import check_setting
from ...status import Status
from ..msgs import messages as M
from ..msgs.markers import markers_msg

# keys that ``result_status`` adds to messages.plan_status's (strings; numbers by repr)
EXTRA_KEYS = ("path_stamp", "waypoints", "path_length_m", "duration_s", "min_margin",
              "min_tension_margin_n", "least_margin", "least_tension_margin_n", "outputs",
              "scene_version")   # the last: a call the planner answered (ros.scene_state)
PROGRESS_NAME = "cdh_planner: planning"
# ``outputs`` value of a successful result: the plan is on the latched topics now, or will be
# when the running execution ends (``docs/ros-node.md``, "Planning while executing")
PUBLISHED, DEFERRED = "published", "deferred until the running execution ends"

# The node's outputs of one plan are bounded (messages, recording, streaming): a plan beyond
# either bound is refused (OUTPUT_LIMIT), never published nor executable.
MAX_DURATION_S = 86_400.0   # one day of motion
MAX_WAYPOINTS = 50_000      # ~25 MB of messages (path, trajectory, envelope)
PLAN_QUEUE_DEPTH = 4        # requests waiting behind the one being planned; more: ``busy``
CANCEL_POLL_S = 0.05        # a cancelled request waiting its turn leaves within this (s)


@dataclass
class PlanOutputs:
    """The messages of a successful plan (all in the base frame, SI units)."""

    path: object               # nav_msgs/Path
    cable_trajectory: object   # trajectory_msgs/JointTrajectory (no effort)
    tension_envelope: object   # cdh_planner_interfaces/TensionEnvelope
    markers: object            # visualization_msgs/MarkerArray


@dataclass
class PlanCall:
    """One plan request, from ``~/plan`` (nav_msgs/GetPlan) or ``~/plan_path`` (the PlanPath
    action): start and goal (geometry_msgs/PoseStamped) and this call's overrides of the
    node's parameters (None: the parameter's)."""

    start: object
    goal: object
    tolerance: Optional[float] = None   # m or rad
    strategy: Optional[str] = None
    timeout_s: Optional[float] = None   # s
    cancel: object = None               # is_set(): stop the search (answer canceled)
    feedback: Optional[Callable] = None  # called with each progress report (a dict)
    scene: object = None   # scene_state.SceneVersion as of the call's arrival (None: the config's)

    @classmethod
    def of_get_plan(cls, request, scene=None):
        return cls(request.start, request.goal, tolerance=request_tolerance(request), scene=scene)

    @classmethod
    def of_plan_path(cls, goal, start=None, cancel=None, feedback=None, scene=None):
        """A PlanPath goal; ``start``: the measured start (use_current_start) instead of
        the goal's. Empty strategy and timeout_s 0 mean the node's parameters."""
        return cls(goal.start if start is None else start, goal.goal,
                   strategy=goal.strategy or None,
                   timeout_s=None if goal.timeout_s == 0.0 else float(goal.timeout_s),
                   cancel=cancel, feedback=feedback, scene=scene)


def request_poses(request, base_frame):
    """(start, goal) planner Poses of a nav_msgs/GetPlan request; InputError naming the field
    (``start.header.frame_id``, ``goal.pose.position.x``, ``start.pose.orientation``).

    Where a pose's tilt theta is 0 or pi its azimuth phi is not determined by the
    orientation: it is taken from the other pose, so the planner starts (or ends) heading
    the way it has to go (for the sphere task, alpha1 of the pole pose = alpha1 of the other).
    """
    start = M.pose_from_msg(request.start, base_frame, "start")
    goal = M.pose_from_msg(request.goal, base_frame, "goal")
    if on_singular_set(start.tau) and not on_singular_set(goal.tau):
        start = M.pose_from_msg(request.start, base_frame, "start", phi_hint=goal.tau[0])
    elif on_singular_set(goal.tau) and not on_singular_set(start.tau):
        goal = M.pose_from_msg(request.goal, base_frame, "goal", phi_hint=start.tau[0])
    return start, goal


def request_tolerance(request):
    """GetPlan's ``tolerance`` (m or rad) when it is a positive finite number, else None (the
    node's ``task.tolerance``)."""
    t = float(request.tolerance)
    return t if math.isfinite(t) and 0.0 < t <= 0.1 else None


def refusal(reason, message, strategy=""):
    """A PlanResult for a request the node refuses (``reason``, a Status: BAD_FRAME, INVALID,
    BUSY, ...): no path, no charts, no time."""
    return PlanResult(success=False, reason=reason, message=message, strategy=strategy, n=0,
                      variables=0, charts=0, time_s=0.0, cost=math.nan, path=None)


def output_refusal(result):
    """The refusal (OUTPUT_LIMIT) for a successful PlanResult whose path the node must not
    publish: longer than MAX_DURATION_S, more than MAX_WAYPOINTS waypoints, or times that are
    not finite and increasing from 0. None when the path is within the bounds (or there is
    no path)."""
    path = result.path
    if not result.success or path is None:
        return None
    n = len(path)
    t = np.asarray(path.t, dtype=float)
    duration = float(t[-1]) if t.size else math.nan
    if n > MAX_WAYPOINTS:
        why = f"{n} waypoints, more than the node's bound of {MAX_WAYPOINTS}"
    elif not duration <= MAX_DURATION_S:   # NaN included
        why = (f"a trajectory of {duration:.4g} s, longer than the node's bound of "
               f"{MAX_DURATION_S:.0f} s (one day): check trajectory.max_cable_speed and "
               f"trajectory.max_cable_accel")
    elif t.shape != (n,) or not np.all(np.isfinite(t)) or t[0] != 0.0 or np.any(np.diff(t) < 0):
        why = "trajectory times that are not finite and increasing from 0"
    else:
        return None
    return refusal(Status.OUTPUT_LIMIT, f"refused: the plan has {why}", result.strategy)


class PlanQueue:
    """One plan computed at a time, at most ``depth`` more requests waiting their turn in
    arrival order; a request beyond that is not queued (the node answers ``busy`` at once).

        turn = queue.enter()        # None: full
        if queue.wait(turn):        # blocks until it is this request's turn; False: closed
            try: ...plan...
            finally: queue.leave()

    ``close`` (shutdown) wakes every waiting request (``wait`` returns False) and refuses
    later ones. Thread-safe."""

    def __init__(self, depth=PLAN_QUEUE_DEPTH):
        self.depth = int(depth)
        self._cond = threading.Condition()
        self._waiting = collections.deque()
        self._turns = 0
        self._running = False
        self.closed = False

    def __len__(self):
        """Requests in the queue: the one being planned and those waiting."""
        with self._cond:
            return len(self._waiting) + int(self._running)

    def enter(self):
        """A turn (int) for a new request, or None when ``depth`` requests already wait
        (or the queue is closed)."""
        with self._cond:
            if self.closed or len(self._waiting) + int(self._running) > self.depth:
                return None
            self._turns += 1
            self._waiting.append(self._turns)
            return self._turns

    def wait(self, turn, cancel=None, timeout_s=None):
        """Block until ``turn`` is first and nothing is planned; then it is running: True.
        False if the queue was closed, ``cancel`` (anything with ``is_set()``, polled every
        CANCEL_POLL_S) is set, or ``timeout_s`` passed: the turn is given up."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s

        def given_up():
            return (self.closed or (cancel is not None and cancel.is_set())
                    or (deadline is not None and time.monotonic() >= deadline))

        def wake_in():   # s until given_up() may change without a notify (None: never)
            waits = [CANCEL_POLL_S] if cancel is not None else []
            if deadline is not None:
                waits.append(max(deadline - time.monotonic(), 0.0))
            return min(waits, default=None)

        with self._cond:
            while not given_up() and (self._running or self._waiting[0] != turn):
                self._cond.wait(wake_in())
            if not self._running and self._waiting[0] == turn and not given_up():
                self._waiting.popleft()
                self._running = True
                return True
            self._waiting.remove(turn)
            self._cond.notify_all()
            return False

    def drop(self, turn):
        """Give up ``turn`` while it waits (a request refused before planning); nothing if it
        is not waiting (None, running, or gone)."""
        with self._cond:
            if turn in self._waiting:
                self._waiting.remove(turn)
                self._cond.notify_all()

    def leave(self):
        """The running request is answered: the next one's turn."""
        with self._cond:
            self._running = False
            self._cond.notify_all()

    def close(self):
        with self._cond:
            self.closed = True
            self._cond.notify_all()


def input_refusal(exc, strategy=""):
    """The refusal for an InputError about a request: a frame_id that is not the base frame
    is BAD_FRAME (nav2 TF_ERROR), the strategy BAD_STRATEGY, anything else INVALID."""
    if exc.field.endswith("frame_id"):
        reason = Status.BAD_FRAME
    else:
        reason = Status.BAD_STRATEGY if exc.field == "strategy" else Status.INVALID
    return refusal(reason, f"invalid request: {exc}", strategy)


def feedback_sender(goal_handle, period_s=0.1):
    """A progress callback sending PlanPath feedback (charts, time_s, best_h) on
    ``goal_handle`` at most every ``period_s``."""
    last = [0.0]

    def feedback(info):
        now = time.monotonic()
        if now - last[0] >= period_s:
            last[0] = now
            goal_handle.publish_feedback(PlanPath.Feedback(
                charts=int(info.get("charts", 0)), time_s=float(info.get("time_s", 0.0)),
                best_h=float(info.get("best_h", math.nan))))
    return feedback


def goal_refusal(goal, base_frame, strategy=""):
    """The refusal of a PlanPath goal for what is wrong with the goal itself (its goal pose:
    frame, NaN, quaternion; its strategy or timeout_s), checked before anything is waited
    for (``use_current_start`` waits for the winches' joint states); None when it is fine."""
    try:
        M.pose_from_msg(goal.goal, base_frame, "goal")
        if goal.strategy:
            check_setting("strategy", goal.strategy, "strategy")
        if goal.timeout_s != 0.0:
            check_setting("timeout_s", float(goal.timeout_s), "timeout_s")
    except InputError as exc:
        return input_refusal(exc, strategy)
    return None


def run_planner(planner, start, goal, call=None, progress=None, logger=None):
    """``planner.plan(start, goal, ...)`` with a PlanCall's overrides (None: none), never
    raising: an InputError becomes ``input_refusal``'s (INVALID, BAD_STRATEGY); any other
    exception INTERNAL_ERROR (error code UNKNOWN) with its message, the
    traceback going to ``logger`` (a callable taking a string) if given."""
    call = call or PlanCall(None, None)
    strategy = call.strategy or getattr(getattr(planner, "settings", None), "strategy", "")
    overrides = {k: v for k, v in (("strategy", call.strategy), ("timeout_s", call.timeout_s))
                 if v is not None}
    try:
        result = planner.plan(start, goal, progress=progress, cancel=call.cancel,
                              tolerance=call.tolerance, **overrides)
    except InputError as exc:
        return input_refusal(exc, strategy)
    except Exception as exc:  # noqa: BLE001 - the node must keep serving
        if logger is not None:
            logger(traceback.format_exc())
        return refusal(Status.INTERNAL_ERROR, f"internal error: {exception_line(exc)}",
                       strategy)
    if result.success and (result.path is None or len(result.path) == 0):
        return refusal(Status.INTERNAL_ERROR, "internal error: the planner reported success "
                                              "without a path", strategy)
    return result


def plan_outputs(result, robot, base_frame, stamp, scene=None):
    """The messages of a successful PlanResult: path (stamp = ``stamp``, poses at stamp +
    t), cable trajectory (header stamp 0: start on receipt), tension envelope (stamp =
    ``stamp``), markers (with the ``scene``'s obstacles, if any)."""
    path = result.path
    return PlanOutputs(
        path=M.path_msg(path, base_frame, stamp),
        cable_trajectory=M.cable_trajectory_msg(path, robot.winch_names, base_frame),
        tension_envelope=M.tension_envelope_msg(path, robot.winch_names, base_frame, stamp),
        markers=markers_msg(path, robot, base_frame, stamp, scene=scene))


def action_result(result, out=None, path=None, scene_version=0):
    """cdh_planner_interfaces/action/PlanPath's Result of a PlanResult and, on success, its
    PlanOutputs (path, cable trajectory, tension envelope); without them ``path`` (the
    empty answer: its stamp pairs the result with its ``~/plan_result``, as GetPlan's).
    min_margin: the least normalised margin over the path and the motion between its
    waypoints (NaN without a path). ``scene_version``: the scene it was planned under."""
    msg = PlanPath.Result(error_code=M.NONE if result.success else M.error_code(result.reason),
                          scene_version=int(scene_version),
                          error_msg="" if result.success else (result.message or result.reason),
                          planning_time_s=float(result.time_s), charts=int(result.charts),
                          min_margin=float(result.least_margin) if result.success else math.nan)
    if out is not None:
        msg.path, msg.cable_trajectory = out.path, out.cable_trajectory
        msg.tension_envelope = out.tension_envelope
    elif path is not None:
        msg.path = path
    return msg


def empty_path(base_frame, stamp):
    """The answer's path when there is no plan: no poses, header in the base frame."""
    msg = Path()
    msg.header.frame_id = base_frame
    msg.header.stamp = stamp
    return msg


def path_summary(path, robot):
    """Numbers a task sequencer wants about a PlannedPath: waypoints, platform path length
    (m), duration (s), least normalised feasibility margin, least tension margin (N: the
    least distance of any cable's tension envelope to its tension limits)."""
    low = np.asarray(path.tension_min) - robot.tension_min
    high = robot.tension_max - np.asarray(path.tension_max)
    return {"waypoints": len(path), "path_length_m": path.length_m(),
            "duration_s": float(path.t[-1]), "min_margin": float(np.min(path.margin)),
            "min_tension_margin_n": float(np.min(np.minimum(low, high)))}


def result_status(result, robot, run_id, log_file, stamp, outputs=PUBLISHED):
    """diagnostic_msgs/DiagnosticStatus for ``~/plan_result``: ``messages.plan_status`` plus
    ``path_stamp`` (the answered path's header stamp, integer ns: pairs this result with its
    service response) and, on success, the ``path_summary`` numbers (at the waypoints),
    ``least_margin`` and ``least_tension_margin_n`` (the PlanResult's, as in the plan JSON:
    over the waypoints and the motion between them) and ``outputs`` (PUBLISHED or DEFERRED)."""
    msg = M.plan_status(result, run_id=run_id, log_file=log_file)
    extra = {"path_stamp": str(M.time_ns(stamp))}
    if result.success and result.path is not None:
        extra.update({k: repr(v) if isinstance(v, float) else str(v)
                      for k, v in path_summary(result.path, robot).items()})
        extra["least_margin"] = repr(float(result.least_margin))
        extra["least_tension_margin_n"] = repr(float(result.least_tension_margin))
        extra["outputs"] = outputs
    if "scene_version" in result.stats:   # planned under this scene (ros.scene_state)
        extra["scene_version"] = str(result.stats["scene_version"])
    msg.values.extend(KeyValue(key=k, value=v) for k, v in extra.items())
    return msg


def progress_status(info, run_id):
    """diagnostic_msgs/DiagnosticStatus for ``~/plan_progress`` while planning: level OK,
    message "<charts> charts, <time> s", values charts, time_s, best_h (the heuristic's least
    remaining distance, task units), run_id."""
    msg = DiagnosticStatus(level=DiagnosticStatus.OK, name=PROGRESS_NAME)
    charts = int(info.get("charts", 0))
    time_s = float(info.get("time_s", 0.0))
    best_h = float(info.get("best_h", math.nan))
    msg.message = f"planning: {charts} charts, {time_s:.1f} s, best h {best_h:.4g}"
    msg.values = [KeyValue(key="charts", value=str(charts)),
                  KeyValue(key="time_s", value=repr(time_s)),
                  KeyValue(key="best_h", value=repr(best_h)),
                  KeyValue(key="run_id", value=str(run_id))]
    return msg


def result_line(result) -> Optional[str]:
    """One line for the node's log."""
    if result.success:
        return (f"plan ok: {len(result.path)} waypoints, {result.charts} charts, "
                f"{result.time_s:.3f} s")
    return f"no plan ({result.reason}): {result.message}"


def warm_up(planner):
    """``planner`` after one evaluation of its constraint's compiled kernel (numba loads
    its cached machine code on the first call, about 0.4 s: at configure, not in the first
    plan). A planner without a constraint (a test double) is returned as it is."""
    constraint = getattr(planner, "constraint", None)
    try:
        if constraint is not None:
            constraint.residual_and_jacobian(constraint.lift(np.array([0.0, 0.0, 0.2]),
                                                             np.zeros(3)))
    except Exception:  # noqa: BLE001 - best effort: the first plan then pays the load
        pass
    return planner
