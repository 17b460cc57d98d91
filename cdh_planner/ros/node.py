"""The ROS 2 node ``cdh_planner``: a thin shell over the planner library.

    cdh-planner node --ros-args --params-file config/robot2.yaml [-p name:=value ...]

Interface (names relative to the node, all remappable; see docs/ros-node.md):

- ``~/plan_path`` cdh_planner_interfaces/action/PlanPath: start (or the measured pose,
  ``use_current_start``), goal, strategy, timeout_s -> feedback (charts, time_s, best_h) and
  a result (error code, path, cable trajectory, tension envelope). Every goal is accepted
  and ends with a result; a cancel stops the search within about 0.1 s (CANCELED).
- ``~/plan`` nav_msgs/srv/GetPlan, the same for plain clients: start, goal, tolerance ->
  path (empty: no plan; reason on ``~/plan_result``). Every call is answered.
  Both are taken at once on a thread of a MultiThreadedExecutor (reentrant group) and
  planned one at a time in arrival order, with at most ``planning.PLAN_QUEUE_DEPTH``
  waiting: beyond that, refused at once (``busy``). Starts and goals within the tolerance
  (``task.tolerance``, or GetPlan's) of the task are projected onto it.
- ``~/execute``, ``~/stop`` std_srvs/srv/Trigger: execute the last good plan
  (``execution.mode``: stream it on ``~/cable_command`` at ``stream_rate_hz``, or send it to
  a ros2_control controller's FollowJointTrajectory action); stop (hold). ``~/execute``
  refuses when the measured lengths (``execution.joint_states_topic``) are away from the
  trajectory's start. How it ended: ``~/execution_result``. (``ros/plan_execution.py``)
- latched (transient local, depth 1), for display and late joiners, never a command:
  ``~/path``, ``~/planned_cable_trajectory``, ``~/tension_envelope``, ``~/markers`` (the
  last good plan), ``~/plan_result`` (the last answer, diagnostic_msgs/DiagnosticStatus,
  key/values in ``planning.py``), ``~/execution_result`` (the last execution's end).
- ``~/plan_progress`` diagnostic_msgs/DiagnosticStatus while planning, at most 10 Hz
  (values charts, time_s, best_h, run_id).
- ``~/cable_command`` the winch command (``messages.WINCH_COMMAND_TYPE``, sensor_msgs/JointState)
  while executing in stream mode; volatile, so a restarted controller gets nothing old.

A plan becomes the last good plan (latched, executable) only once all its outputs are built
(within ``planning.MAX_DURATION_S`` / ``MAX_WAYPOINTS``), recorded and published; anything
failing before leaves the previous one and answers an error. A plan made while executing is
answered at once, but published (and made executable) only when the execution ends.
Recording never decides an answer: a failure is logged.

Parameters: ``ros/params.py``. Changes go through the standard parameter services and are
checked there (a bad value is refused with the reason); a change of robot.*, task.*,
planner.* or trajectory.* builds a new Planner for the next request.

Recording: ``ros/recording.py`` (MCAP files in ``log_dir``, from the node's start, rotated
by ``log_max_file_mb`` / ``log_max_file_s``): the parameters at start and every change, each
plan call's request and response events, every message published for it (progress
included), the execute / stop calls and every streamed command.
"""

import math
import os
import signal
import sys
import threading
import time
import traceback

import rclpy
import rclpy.signals
from diagnostic_msgs.msg import DiagnosticStatus
from nav_msgs.msg import Path
from nav_msgs.srv import GetPlan
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, \
    SetParametersResult
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from cdh_planner_interfaces.action import PlanPath
from cdh_planner_interfaces.msg import TensionEnvelope

from ..errors import InputError, clip, exception_line
from ..io.mcap_log import REQUEST_RECEIVED, RESPONSE_SENT
from ..status import Status
from . import planning
from .interface import ACTION_QOS, CABLE_COMMAND, EXECUTE, EXECUTION_RESULT, LATCHED, MARKERS, \
    NODE_NAME, PATH, PLAN, PLAN_PATH, PLAN_PROGRESS, PLAN_RESULT, PLANNED_TRAJECTORY, \
    SERVICE_QOS, STOP, TENSION_ENVELOPE
from .messages import WINCH_COMMAND_TYPE
from .params import BOOL, DOUBLE, DOUBLES, INT, REQUIRED, SPECS, START_ONLY, STRING, \
    STRINGS, PLANNER_PREFIXES, needs_new_planner, node_config, parameter_error
from .plan_execution import PlanExecution
from .recording import RunLog, log_limits

# executor threads: the plan being computed, the requests waiting their turn, and spare ones
# (busy answers, execute / stop, the stream timer, parameters) that are never all blocked
EXECUTOR_THREADS = 1 + planning.PLAN_QUEUE_DEPTH + 3
RECORD_ERROR_PERIOD_S = 10.0  # at most one log line per this many s about failed recording
PROGRESS_PERIOD_S = 0.1
SHUTDOWN_JOIN_S = 5.0
STATIC_TYPES = {STRING: Parameter.Type.STRING, BOOL: Parameter.Type.BOOL,
                STRINGS: Parameter.Type.STRING_ARRAY}


def default_planner_factory(robot, task, settings):
    from ..planner import Planner
    return Planner(robot, task, settings)


class _Cancel:
    """A plan's stop signal (``is_set``): the node shutting down, or the caller's cancel."""

    def __init__(self, node, caller=None):
        self.node, self.caller = node, caller

    def is_set(self):
        return self.node._shutting_down or (self.caller is not None and self.caller.is_set())


class _GoalCancel:
    """``is_set``: a cancel of this PlanPath goal was requested."""

    def __init__(self, goal_handle):
        self.goal_handle = goal_handle

    def is_set(self):
        return self.goal_handle.is_cancel_requested


class PlannerNode(Node):

    def __init__(self, planner_factory=default_planner_factory, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self._factory = planner_factory
        self._values = self._declare()
        self.config = node_config(self._values)          # InputError: the node cannot start
        self._planner = self._new_planner(self.config)
        self._config_lock = threading.Lock()
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.runlog = RunLog(self.config.log_dir, self.config.log_enabled,
                             warn=self.get_logger().warning, info=self.get_logger().info,
                             node_name=self.get_fully_qualified_name(),
                             **log_limits(self.config.values))
        self._record(self.runlog.parameters, [p.to_parameter_msg() for p in
                     self.get_parameters_by_prefix("").values()], initial=True)
        log_file = self._record(self.runlog.open) or ""

        pub = self.create_publisher
        self.pub_path = pub(Path, f"~/{PATH}", LATCHED)
        self.pub_trajectory = pub(JointTrajectory, f"~/{PLANNED_TRAJECTORY}", LATCHED)
        self.pub_envelope = pub(TensionEnvelope, f"~/{TENSION_ENVELOPE}", LATCHED)
        self.pub_markers = pub(MarkerArray, f"~/{MARKERS}", LATCHED)
        self.pub_result = pub(DiagnosticStatus, f"~/{PLAN_RESULT}", LATCHED)
        self.pub_progress = pub(DiagnosticStatus, f"~/{PLAN_PROGRESS}", 10)
        self.pub_execution = pub(DiagnosticStatus, f"~/{EXECUTION_RESULT}", LATCHED)
        self.pub_command = pub(WINCH_COMMAND_TYPE, f"~/{CABLE_COMMAND}", 10)  # never latched

        self._queue = planning.PlanQueue(planning.PLAN_QUEUE_DEPTH)
        self._calls = 0
        self._shutting_down = False
        self.planning = False
        # _lock guards the execution's state, _last, _pending and the latched plan outputs
        self._lock = threading.RLock()
        self._last = None            # (PlannedPath, Robot, PlanOutputs) of the last good plan
        self._pending = None         # the same, of a plan made while executing
        self._execution = PlanExecution(self, self.config, self.pub_command, self.pub_execution,
                                        self._publish, self._lock, self._execution_ended,
                                        callback_group=ReentrantCallbackGroup())
        self.srv_plan = self.create_service(GetPlan, f"~/{PLAN}", self._plan,
                                            qos_profile=SERVICE_QOS,
                                            callback_group=ReentrantCallbackGroup())
        self.plan_path_server = ActionServer(
            self, PlanPath, f"~/{PLAN_PATH}", execute_callback=self._plan_path,
            goal_callback=lambda goal: GoalResponse.ACCEPT,   # busy goals end with BUSY
            cancel_callback=lambda handle: CancelResponse.ACCEPT,
            callback_group=ReentrantCallbackGroup(), **ACTION_QOS)
        self.srv_execute = self.create_service(Trigger, f"~/{EXECUTE}", self._execute,
                                               qos_profile=SERVICE_QOS)
        self.srv_stop = self.create_service(Trigger, f"~/{STOP}", self._stop,
                                            qos_profile=SERVICE_QOS)
        c = self.config
        self.get_logger().info(
            f"ready: robot {c.robot.name}, task {c.task.type}, strategy "
            f"{c.settings.strategy}, base frame {c.base_frame}, "
            + (f"recording to {log_file}; if the node is killed: cdh-planner recover {log_file}"
               if log_file else "recording " + ("off" if not c.log_enabled else "failed")))

    # ------------------------------------------------------------------ parameters

    def _declare(self):
        """Declare every parameter of params.SPECS; return name -> value (None: not set)."""
        unknown = sorted(n for n in self._parameter_overrides
                         if n.startswith(PLANNER_PREFIXES) and n not in {s.name for s in SPECS})
        if unknown:
            raise InputError(unknown[0], self._parameter_overrides[unknown[0]].value,
                             "unknown parameter (see cdh_planner/ros/params.py)")
        values = {}
        for spec in SPECS:
            descriptor = ParameterDescriptor(description=spec.description,
                                             read_only=spec.name in START_ONLY)
            if spec.choices:
                descriptor.additional_constraints = f"one of: {', '.join(spec.choices)}"
            if spec.kind in STATIC_TYPES:
                default = spec.default if spec.default is not REQUIRED else STATIC_TYPES[spec.kind]
            else:  # numbers: dynamically typed (ints accepted), ranges shown and checked
                descriptor.dynamic_typing = True
                default = None if spec.default in (REQUIRED, None) else spec.default
                if spec.kind == DOUBLE and spec.low is not None:
                    descriptor.floating_point_range = [FloatingPointRange(  # ROS ranges are closed
                        from_value=float(spec.low),
                        to_value=float(spec.high) if spec.high is not None else sys.float_info.max)]
                if spec.kind == INT and spec.low is not None:
                    descriptor.integer_range = [IntegerRange(
                        from_value=int(spec.low), to_value=int(spec.high))]
                if spec.kind == DOUBLES and spec.default is REQUIRED:
                    descriptor.additional_constraints = "required (robot file)"
            param = self.declare_parameter(spec.name, default, descriptor)
            values[spec.name] = param.value
        return values

    def set_parameters_atomically(self, parameter_list):
        """rclpy's, but a parameter this node does not have is refused naming it (rclpy 7.1
        names none: "Invalid access to undeclared parameter(s): []")."""
        unknown = [p for p in parameter_list if not self.has_parameter(p.name)]
        if unknown:
            return SetParametersResult(successful=False, reason=str(InputError(
                unknown[0].name, unknown[0].value,
                "not a parameter of this node (ros2 param list shows them)")))
        return super().set_parameters_atomically(parameter_list)

    def _on_set_parameters(self, params):
        values = dict(self._values)
        values.update({p.name: p.value for p in params})
        try:
            config = node_config(values)
            planner = self._planner
            if needs_new_planner([p.name for p in params], self.config.values, config.values):
                planner = self._new_planner(config)
        except InputError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        with self._config_lock:
            self._values, self.config, self._planner = values, config, planner
        self._execution.configure(config)
        self._record(self.runlog.configure, config.log_dir, config.log_enabled,
                     **log_limits(config.values))
        self._record(self.runlog.parameters, [p.to_parameter_msg() for p in params],
                     log_time_ns=self._now())
        self.get_logger().info(f"parameters set: {', '.join(p.name for p in params)}")
        return SetParametersResult(successful=True)

    def _new_planner(self, config):
        """A Planner for ``config`` (a fresh atlas); InputError naming the parameter."""
        try:
            return self._factory(config.robot, config.task, config.settings)
        except InputError as exc:
            raise parameter_error(exc) from None

    # ------------------------------------------------------------------ plan

    def _plan(self, request, response):
        """~/plan: every call is answered, and its request and response are recorded,
        whatever happens in between (an exception: ``internal_error``)."""
        turn = self._queue.enter()   # first: the queue's order is the order calls are taken
        seq, run_id, log_file = self._new_call()
        self._record_plan(REQUEST_RECEIVED, seq, request=request)
        result, _, response.plan = self._answer(planning.PlanCall.of_get_plan(request),
                                                run_id, log_file, turn)
        self._record_plan(RESPONSE_SENT, seq, response=response)
        return response

    def _plan_path(self, goal_handle):
        """~/plan_path: every goal ends with a result (succeeded, canceled or aborted with
        the error code and reason); feedback at most every PROGRESS_PERIOD_S."""
        turn = self._queue.enter()
        seq, run_id, log_file = self._new_call()
        goal = goal_handle.request
        self._record_goal(REQUEST_RECEIVED, seq, goal_handle, goal=goal)
        last = [0.0]

        def feedback(info):
            now = time.monotonic()
            if now - last[0] >= PROGRESS_PERIOD_S:
                last[0] = now
                goal_handle.publish_feedback(PlanPath.Feedback(
                    charts=int(info.get("charts", 0)), time_s=float(info.get("time_s", 0.0)),
                    best_h=float(info.get("best_h", math.nan))))

        cancel = _GoalCancel(goal_handle)
        refused = (planning.goal_refusal(goal, self.config.base_frame,
                                         self.config.settings.strategy)
                   if goal.use_current_start else None)   # not worth waiting for a start
        start = (self._execution.current_start(self.config, self._last,
                                               _Cancel(self, cancel).is_set)
                 if goal.use_current_start and refused is None else None)
        if refused is not None:
            call = None
        elif isinstance(start, str) and cancel.is_set():
            call = None
            refused = planning.refusal(Status.CANCELED, "canceled while waiting for the "
                                                        "winches' joint states")
        elif isinstance(start, str):   # no measured start: why
            call = None
            refused = planning.refusal("no_current_state", f"use_current_start: {start}")
        else:
            call = planning.PlanCall.of_plan_path(goal, start, cancel, feedback)
            refused = None
        result, out, path = self._answer(call, run_id, log_file, turn, refused)
        if result.success:
            goal_handle.succeed()
        elif goal_handle.is_cancel_requested and result.reason == Status.CANCELED:
            goal_handle.canceled()
        else:
            goal_handle.abort()
        answer = planning.action_result(result, out, path)
        self._record_goal(RESPONSE_SENT, seq, goal_handle, result=answer)
        return answer

    def _new_call(self):
        """(sequence number, run id, run file) of a new plan call."""
        with self._config_lock:
            self._calls += 1
            seq = self._calls
        log_file = self._record(self.runlog.open) or ""
        return seq, (f"{_stem(log_file)}#{seq}" if log_file else str(seq)), log_file

    def _answer(self, call, run_id, log_file, turn, refused=None):
        """(PlanResult, PlanOutputs or None, the answer's nav_msgs/Path) of one PlanCall
        holding ``turn`` in the queue (None: the queue was full), never raising (an
        exception: ``internal_error``, published on ~/plan_result); ``refused``: a refusal
        made before planning, answered as it is."""
        config = self.config
        try:
            result, out, path = self._serve(call, run_id, log_file, turn, refused)
        except Exception as exc:  # noqa: BLE001 - never take the node down: answer no plan
            self._queue.drop(turn)
            self.get_logger().error(f"[{run_id}] plan call failed: {traceback.format_exc()}")
            result = planning.refusal(
                "internal_error", f"internal error: {exception_line(exc)}",
                config.settings.strategy)
            out, path = None, self._no_path(config)
            self._publish_result(result, config, run_id, log_file, path)
        line = f"[{run_id}] {planning.result_line(result)}"
        if result.success:
            self.get_logger().info(line)
        else:
            self.get_logger().warning(line)
        return result, out, path

    def _serve(self, call, run_id, log_file, turn, refused=None):
        """(PlanResult, PlanOutputs or None, path) of one call: wait for its ``turn`` in
        the queue (or be refused: busy, shutting down, cancelled meanwhile), plan, bound and
        build the outputs, commit them (``_commit``); ``~/plan_result`` published."""
        config = self.config
        if refused:
            self._queue.drop(turn)
            result = refused
        elif turn is None:
            result = planning.refusal(
                "busy", f"busy: {len(self._queue)} plan requests are being computed or wait "
                        f"(at most 1 + {self._queue.depth}); call again when one is answered",
                config.settings.strategy)
        elif not self._queue.wait(turn, call.cancel):
            why = "the node is shutting down" if self._shutting_down else "cancelled while queued"
            result = planning.refusal(Status.CANCELED, f"canceled: {why}", config.settings.strategy)
        else:
            try:
                with self._config_lock:
                    config, planner = self.config, self._planner
                result = self._compute(call, planner, config, run_id)
                result = planning.output_refusal(result) or result
                if result.success:
                    out = planning.plan_outputs(result, config.robot, config.base_frame,
                                                self.get_clock().now().to_msg())
                    self._commit(result, config, out, run_id, log_file)
                    return result, out, out.path
            finally:
                self._queue.leave()
        path = self._no_path(config)
        self._publish_result(result, config, run_id, log_file, path)
        return result, None, path

    def _commit(self, result, config, out, run_id, log_file):
        """Make a successful plan the last good plan: its status built, its outputs recorded
        and published (``_publish_outputs``), then ``_last`` set and the status published.
        While executing, the outputs wait in ``_pending`` for the end of the stream. Raises
        (and leaves the previous last good plan) if building or publishing fails."""
        with self._lock:
            deferred = self._execution.running
            status = planning.result_status(
                result, config.robot, run_id, log_file, out.path.header.stamp,
                outputs=planning.DEFERRED if deferred else planning.PUBLISHED)
            plan = (result.path, config.robot, out)
            if deferred:
                self._pending = plan
            else:
                self._publish_outputs(out)
                self._last, self._pending = plan, None
        self._publish_result(result, config, run_id, log_file, out.path, status)

    def _publish_outputs(self, out, restore=True):
        """Publish a plan's latched outputs; if one fails, put the last good plan's back
        (as far as possible) and raise."""
        try:
            for publisher, msg in ((self.pub_path, out.path),
                                   (self.pub_trajectory, out.cable_trajectory),
                                   (self.pub_envelope, out.tension_envelope),
                                   (self.pub_markers, out.markers)):
                self._publish(publisher, msg, latched=True)
        except Exception:
            if restore and self._last is not None:
                try:
                    self._publish_outputs(self._last[2], restore=False)
                except Exception:  # noqa: BLE001 - the error raised below says what failed
                    pass
            raise

    def _publish_result(self, result, config, run_id, log_file, path, status=None):
        """Publish ``~/plan_result`` (``status``, or that of ``result`` answered with
        ``path``); a failure is logged: the service answer stands."""
        try:
            if status is None:
                status = planning.result_status(result, config.robot, run_id, log_file,
                                                path.header.stamp)
            self._publish(self.pub_result, status, latched=True)
        except Exception:  # noqa: BLE001 - a diagnostic, never the answer
            self.get_logger().error(f"[{run_id}] publishing the plan result failed: "
                                    f"{traceback.format_exc()}")

    def _no_path(self, config):
        return planning.empty_path(config.base_frame, self.get_clock().now().to_msg())

    def _compute(self, call, planner, config, run_id):
        try:
            start, goal = planning.request_poses(call, config.base_frame)
        except InputError as exc:
            return planning.input_refusal(exc, config.settings.strategy)
        self.planning = True
        last = [0.0]
        call.cancel = _Cancel(self, call.cancel)

        def progress(info):
            now = time.monotonic()
            if now - last[0] >= PROGRESS_PERIOD_S:
                last[0] = now
                self._publish(self.pub_progress, planning.progress_status(info, run_id))
            if call.feedback is not None:
                call.feedback(info)

        try:
            return planning.run_planner(planner, start, goal, call, progress,
                                        logger=self.get_logger().error)
        finally:
            self.planning = False

    # ------------------------------------------------------------------ execute, stop

    def _execute(self, request, response):
        return self._guarded(self._answer_execute, request, response)

    def _stop(self, request, response):
        return self._guarded(self._answer_stop, request, response)

    def _guarded(self, method, request, response):
        try:
            return method(request, response)
        except Exception as exc:  # noqa: BLE001 - never take the node down
            self.get_logger().error(f"{method.__name__} failed: {traceback.format_exc()}")
            response.success = False
            response.message = f"internal error: {exception_line(exc)}"
            return response

    def _answer_execute(self, request, response):
        self._record_trigger(self.srv_execute, request, None, REQUEST_RECEIVED)
        with self._lock:
            response.success, response.message = self._execution.start(self._last,
                                                                        self.config)
        self._record_trigger(self.srv_execute, None, response, RESPONSE_SENT)
        self.get_logger().info(f"execute: {response.message}")
        return response

    def _answer_stop(self, request, response):
        self._record_trigger(self.srv_stop, request, None, REQUEST_RECEIVED)
        response.success = True
        response.message = self._execution.stop()
        self._record_trigger(self.srv_stop, None, response, RESPONSE_SENT)
        return response

    def _execution_ended(self, publish_pending):
        """(under ``_lock``, once per execution) A plan made while executing is published
        and becomes the last good plan now, unless shutting down."""
        pending, self._pending = self._pending, None
        if pending is None or not publish_pending:
            return
        try:
            self._publish_outputs(pending[2])
        except Exception:  # noqa: BLE001 - the previous last good plan stays
            self.get_logger().error(f"publishing the plan made while executing failed "
                                    f"(it cannot be executed): {traceback.format_exc()}")
            return
        self._last = pending
        self.get_logger().info("published the plan made while executing: ~/execute runs it")

    def _record_trigger(self, srv, request, response, event):
        self._record(self.runlog.service_event, self.resolve_service_name(srv.srv_name),
                     "std_srvs/srv/Trigger", event, request=request, response=response,
                     log_time_ns=self._now())

    def _record_plan(self, event, seq, request=None, response=None):
        self._record(self.runlog.service_event, self.resolve_service_name(self.srv_plan.srv_name),
                     "nav_msgs/srv/GetPlan", event, request=request, response=response,
                     sequence_number=seq, log_time_ns=self._now())

    def _record_goal(self, event, seq, goal_handle, goal=None, result=None):
        """Record a ~/plan_path goal as it arrived (REQUEST_RECEIVED) or its result as sent
        (RESPONSE_SENT, with the goal's final status), paired by ``seq``."""
        self._record(self.runlog.action_event,
                     self.get_fully_qualified_name() + "/" + PLAN_PATH,
                     "cdh_planner_interfaces/action/PlanPath", event, goal=goal, result=result,
                     sequence_number=seq, log_time_ns=self._now(),
                     goal_id=bytes(goal_handle.goal_id.uuid), status=goal_handle.status)

    # ------------------------------------------------------------------ helpers

    def _record(self, method, *args, **kwargs):
        """Call a recording method; what it raises is logged (at most once every
        RECORD_ERROR_PERIOD_S), never passed on: recording does not decide an answer."""
        try:
            return method(*args, **kwargs)
        except Exception as exc:  # noqa: BLE001
            self.get_logger().error(
                f"recording failed ({getattr(method, '__name__', method)}): "
                f"{exception_line(exc)}",
                throttle_duration_sec=RECORD_ERROR_PERIOD_S)
            return None

    def _publish(self, publisher, msg, latched=False):
        """Record, then publish: whatever a subscriber got is in the run file, even if the
        process is killed right after."""
        self._record(self.runlog.write, publisher.topic_name, msg, self._now(),
                     transient_local=latched)
        publisher.publish(msg)

    def _now(self):
        return self.get_clock().now().nanoseconds

    def begin_shutdown(self):
        """From now on a running plan is ended at its next progress report, and waiting
        requests are answered (canceled)."""
        self._shutting_down = True
        self._queue.close()

    def close(self):
        """Stop streaming (holding), end a running plan at its next progress report, and
        close the run file. Safe to call after the context has shut down."""
        self.begin_shutdown()
        self._execution.close()
        self._record(self.runlog.close)


def _stem(path):
    name = path.rsplit("/", 1)[-1]
    return name[:-5] if name.endswith(".mcap") else name


def main(ros_args=(), planner_factory=default_planner_factory, log=print):
    """Run the node until SIGINT / SIGTERM; return the exit code: 0 after a clean shutdown
    (run file closed), 2 when it cannot start (bad parameters: one line naming the parameter
    and value). ``ros_args``: what follows ``--ros-args``.

    The executor spins on a thread; the main thread waits for a signal (rclpy 7.1's own
    SIGTERM handler does not wake a waiting executor, so we handle both signals here).
    """
    from rclpy.executors import MultiThreadedExecutor

    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    context = rclpy.Context()
    try:
        rclpy.init(args=["cdh-planner", "--ros-args", *ros_args], context=context,
                   signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    except Exception as exc:  # noqa: BLE001 - rcl's argument errors
        log(f"cdh-planner node: error: bad --ros-args: {clip(exc, 400)}")
        return 2
    try:
        node = PlannerNode(planner_factory, context=context)
    except Exception as exc:  # noqa: BLE001 - InputError, or a parameter of the wrong type
        log(f"cdh-planner node: error: {exc if isinstance(exc, InputError) else clip(exc, 400)}")
        rclpy.try_shutdown(context=context)
        return 2
    executor = MultiThreadedExecutor(num_threads=EXECUTOR_THREADS, context=context)
    executor.add_node(node)

    def spin():
        try:
            executor.spin()
        except Exception as exc:  # noqa: BLE001 - e.g. the context shut down under it
            if not stop.is_set():
                log(f"cdh-planner node: executor stopped: {clip(exc, 400)}")
        finally:
            stop.set()

    spinner = threading.Thread(target=spin, name="executor", daemon=True)
    spinner.start()
    while not stop.wait(1.0):
        pass
    node.get_logger().info("shutting down")
    node.begin_shutdown()                 # a running plan ends at its next progress report
    executor.shutdown(timeout_sec=2.0)
    # Wait for the executor thread to leave spin(): a thread still inside rclpy's wait when
    # the interpreter exits aborts the process ("terminate called without an active
    # exception", exit 134 instead of 0).
    spinner.join(timeout=SHUTDOWN_JOIN_S)
    node.close()                          # hold the winches, close the run file
    abandoned = node.planning
    stuck = spinner.is_alive()
    node.destroy_node()
    rclpy.try_shutdown(context=context)
    if abandoned or stuck:  # a thread that cannot be joined: leave without waiting for it
        log("cdh-planner node: " + ("a plan was still running at shutdown; abandoned"
                                    if abandoned else "the executor did not stop; left"))
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(0)
    return 0
