"""The ROS 2 node ``cdh_planner``: a thin shell over the planner library.

    cdh-planner node --ros-args --params-file config/robot2.yaml [-p name:=value ...]

Interface (names relative to the node, all remappable; see docs/ros-node.md):

- ``~/plan`` nav_msgs/srv/GetPlan: start, goal -> path (empty: no plan; reason on
  ``~/plan_result``). Planned on a thread of a MultiThreadedExecutor (reentrant group), one
  at a time: a request while planning is refused at once (``busy``). ``tolerance`` is not
  used (the goal is reached exactly).
- ``~/execute``, ``~/stop`` std_srvs/srv/Trigger: stream the last successful plan on
  ``~/cable_command`` at ``stream_rate_hz``; stop at once and hold the last setpoint.
- latched (transient local, depth 1): ``~/path``, ``~/cable_trajectory``,
  ``~/tension_envelope``, ``~/markers`` (the last successful plan), ``~/plan_result``
  (the last answer, diagnostic_msgs/DiagnosticStatus, key/values in ``planning.py``).
- ``~/plan_progress`` diagnostic_msgs/DiagnosticStatus while planning, at most 10 Hz
  (values charts, time_s, best_h, run_id).
- ``~/cable_command`` the winch command (``messages.WINCH_COMMAND_TYPE``, sensor_msgs/JointState)
  while executing.

Parameters: ``ros/params.py``. Changes go through the standard parameter services and are
checked there (a bad value is refused with the reason); a change of robot.*, task.*,
planner.* or trajectory.* builds a new Planner for the next request.

Recording: ``ros/recording.py`` (MCAP files in ``log_dir``, from the node's start, rotated
by ``log_max_file_mb`` / ``log_max_file_s``): the parameters at start and every change, each
plan call's request and response events, every message published for it (progress
included), the execute / stop calls and every streamed command.
"""

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
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from ..errors import InputError
from ..io.mcap_log import REQUEST_RECEIVED, RESPONSE_SENT
from . import planning
from .messages import WINCH_COMMAND_TYPE
from .params import BOOL, DOUBLE, DOUBLES, INT, REQUIRED, SPECS, STRING, STRINGS, \
    PLANNER_PREFIXES, needs_new_planner, node_config, parameter_error
from .recording import RunLog, log_limits
from .streaming import Stream

NODE_NAME = "cdh_planner"
# The interface, relative to the node (module docstring); clients use these names too.
PLAN, EXECUTE, STOP = "plan", "execute", "stop"
PATH, CABLE_TRAJECTORY, TENSION_ENVELOPE = "path", "cable_trajectory", "tension_envelope"
MARKERS, PLAN_RESULT, PLAN_PROGRESS = "markers", "plan_result", "plan_progress"
CABLE_COMMAND = "cable_command"
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
PROGRESS_PERIOD_S = 0.1
SHUTDOWN_JOIN_S = 5.0
STATIC_TYPES = {STRING: Parameter.Type.STRING, BOOL: Parameter.Type.BOOL,
                STRINGS: Parameter.Type.STRING_ARRAY}


def default_planner_factory(robot, task, settings):
    from ..planner import Planner
    return Planner(robot, task, settings)


class _Cancelled(Exception):
    """Raised from the progress callback to end a plan when the node shuts down."""


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
        self.runlog.parameters([p.to_parameter_msg() for p in
                                self.get_parameters_by_prefix("").values()], initial=True)
        log_file = self.runlog.open()

        pub = self.create_publisher
        self.pub_path = pub(Path, f"~/{PATH}", LATCHED)
        self.pub_trajectory = pub(JointTrajectory, f"~/{CABLE_TRAJECTORY}", LATCHED)
        self.pub_envelope = pub(Float64MultiArray, f"~/{TENSION_ENVELOPE}", LATCHED)
        self.pub_markers = pub(MarkerArray, f"~/{MARKERS}", LATCHED)
        self.pub_result = pub(DiagnosticStatus, f"~/{PLAN_RESULT}", LATCHED)
        self.pub_progress = pub(DiagnosticStatus, f"~/{PLAN_PROGRESS}", 10)
        self.pub_command = pub(WINCH_COMMAND_TYPE, f"~/{CABLE_COMMAND}", 10)

        self._busy = threading.Lock()
        self._calls = 0
        self._shutting_down = False
        self.planning = False
        self._last = None            # (PlannedPath, Robot) of the last successful plan
        self._stream = None
        self._timer = None
        self._timer_period = None
        self.srv_plan = self.create_service(GetPlan, f"~/{PLAN}", self._plan,
                                            callback_group=ReentrantCallbackGroup())
        self.srv_execute = self.create_service(Trigger, f"~/{EXECUTE}", self._execute)
        self.srv_stop = self.create_service(Trigger, f"~/{STOP}", self._stop)
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
            descriptor = ParameterDescriptor(description=spec.description)
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
        self.runlog.configure(config.log_dir, config.log_enabled, **log_limits(config.values))
        self.runlog.parameters([p.to_parameter_msg() for p in params], log_time_ns=self._now())
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
        try:
            return self._answer_plan(request, response)
        except Exception as exc:  # noqa: BLE001 - never take the node down; answer "no plan"
            self.get_logger().error(f"plan call failed: {traceback.format_exc()}")
            response.plan = planning.empty_path(self.config.base_frame,
                                                self.get_clock().now().to_msg())
            try:
                self._publish(self.pub_result, planning.result_status(
                    planning.refusal("internal_error", f"internal error: {exc}"),
                    self.config.robot, "", "", response.plan.header.stamp), latched=True)
            except Exception:  # noqa: BLE001
                pass
            return response

    def _answer_plan(self, request, response):
        with self._config_lock:
            config, planner = self.config, self._planner
            self._calls += 1
            seq = self._calls
        log_file = self.runlog.open()
        run_id = f"{_stem(log_file)}#{seq}" if log_file else str(seq)
        service = self.resolve_service_name(self.srv_plan.srv_name)
        self.runlog.service_event(service, "nav_msgs/srv/GetPlan", REQUEST_RECEIVED,
                                  request=request, sequence_number=seq, log_time_ns=self._now())
        strategy = config.settings.strategy
        if not self._busy.acquire(blocking=False):
            result = planning.refusal("busy", "busy: another plan is being computed; "
                                              "call again when it is answered", strategy)
        else:
            try:
                result = self._compute(request, planner, config, run_id)
            finally:
                self._busy.release()
        stamp = self.get_clock().now().to_msg()
        if result.success:
            out = planning.plan_outputs(result, config.robot, config.base_frame, stamp)
            self._last = (result.path, config.robot)
            self._publish(self.pub_path, out.path, latched=True)
            self._publish(self.pub_trajectory, out.cable_trajectory, latched=True)
            self._publish(self.pub_envelope, out.tension_envelope, latched=True)
            self._publish(self.pub_markers, out.markers, latched=True)
            response.plan = out.path
        else:
            response.plan = planning.empty_path(config.base_frame, stamp)
        status = planning.result_status(result, config.robot, run_id, log_file, stamp)
        self._publish(self.pub_result, status, latched=True)
        self.runlog.service_event(service, "nav_msgs/srv/GetPlan", RESPONSE_SENT,
                                  response=response, sequence_number=seq,
                                  log_time_ns=self._now())
        line = f"[{run_id}] {planning.result_line(result)}"
        if result.success:
            self.get_logger().info(line)
        else:
            self.get_logger().warning(line)
        return response

    def _compute(self, request, planner, config, run_id):
        try:
            start, goal = planning.request_poses(request, config.base_frame)
        except InputError as exc:
            return planning.input_refusal(exc, config.settings.strategy)
        self.planning = True
        last = [0.0]

        def progress(info):
            if self._shutting_down:
                raise _Cancelled("the node is shutting down")
            now = time.monotonic()
            if now - last[0] >= PROGRESS_PERIOD_S:
                last[0] = now
                self._publish(self.pub_progress, planning.progress_status(info, run_id))

        try:
            return planning.run_planner(planner, start, goal, progress,
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
            response.message = f"internal error: {type(exc).__name__}: {exc}"
            return response

    def _answer_execute(self, request, response):
        self._record_trigger(self.srv_execute, request, None, REQUEST_RECEIVED)
        response.success = False
        if self._stream is not None:
            response.message = (f"refused: already executing (at {self._stream.t:.2f} s of "
                                f"{self._stream.duration:.2f} s); call ~/stop first")
        elif self._last is None:
            response.message = "refused: no plan to execute; call ~/plan first"
        else:
            path, robot = self._last
            config = self.config
            self._stream = Stream(path, robot.winch_names, config.stream_interpolation,
                                  start=time.monotonic())
            period = 1.0 / config.stream_rate_hz
            if self._timer is None or self._timer_period != period:
                if self._timer is not None:
                    self.destroy_timer(self._timer)
                self._timer = self.create_timer(period, self._tick)
                self._timer_period = period
            else:
                self._timer.reset()
            self._tick()
            response.success = True
            response.message = (f"executing: {len(path)} waypoints, {self._stream.duration:.3f} s "
                                f"at {config.stream_rate_hz:g} Hz on {self.pub_command.topic_name}")
        self._record_trigger(self.srv_execute, None, response, RESPONSE_SENT)
        self.get_logger().info(f"execute: {response.message}")
        return response

    def _tick(self):
        stream = self._stream
        if stream is None:
            return
        try:
            msg, finished = stream.command(time.monotonic(), self.get_clock().now().to_msg())
        except Exception:  # noqa: BLE001 - never take the node down
            self.get_logger().error(f"streaming failed: {traceback.format_exc()}")
            self._end_stream("streaming stopped after an error")
            return
        self._publish(self.pub_command, msg)
        if finished:
            self._end_stream(f"execution finished: {stream.sent} commands over "
                             f"{stream.duration:.3f} s")

    def _answer_stop(self, request, response):
        self._record_trigger(self.srv_stop, request, None, REQUEST_RECEIVED)
        stream = self._stream
        response.success = True
        if stream is None:
            response.message = "not executing: nothing to stop"
        else:
            self._publish(self.pub_command, stream.hold(self.get_clock().now().to_msg()))
            response.message = (f"stopped at {stream.t:.3f} s of {stream.duration:.3f} s; "
                                f"holding the last setpoint")
            self._end_stream(response.message)
        self._record_trigger(self.srv_stop, None, response, RESPONSE_SENT)
        return response

    def _end_stream(self, message):
        if self._timer is not None:
            self._timer.cancel()
        self._stream = None
        self.get_logger().info(message)

    def _record_trigger(self, srv, request, response, event):
        self.runlog.service_event(self.resolve_service_name(srv.srv_name), "std_srvs/srv/Trigger", event, request=request,
                                  response=response, log_time_ns=self._now())

    # ------------------------------------------------------------------ helpers

    def _publish(self, publisher, msg, latched=False):
        """Record, then publish: whatever a subscriber got is in the run file, even if the
        process is killed right after."""
        self.runlog.write(publisher.topic_name, msg, self._now(), transient_local=latched)
        publisher.publish(msg)

    def _now(self):
        return self.get_clock().now().nanoseconds

    def begin_shutdown(self):
        """From now on a running plan is ended at its next progress report."""
        self._shutting_down = True

    def close(self):
        """Stop streaming (holding), end a running plan at its next progress report, and
        close the run file. Safe to call after the context has shut down."""
        self._shutting_down = True
        if self._stream is not None:
            try:
                self._publish(self.pub_command, self._stream.hold(
                    self.get_clock().now().to_msg()))
            except Exception:  # noqa: BLE001 - context already gone: nothing to tell
                pass
            self._end_stream("shutting down while executing: held the last setpoint")
        self.runlog.close()


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
        log(f"cdh-planner node: error: bad --ros-args: {_one_line(exc)}")
        return 2
    try:
        node = PlannerNode(planner_factory, context=context)
    except Exception as exc:  # noqa: BLE001 - InputError, or a parameter of the wrong type
        log(f"cdh-planner node: error: {exc if isinstance(exc, InputError) else _one_line(exc)}")
        rclpy.try_shutdown(context=context)
        return 2
    executor = MultiThreadedExecutor(num_threads=4, context=context)
    executor.add_node(node)

    def spin():
        try:
            executor.spin()
        except Exception as exc:  # noqa: BLE001 - e.g. the context shut down under it
            if not stop.is_set():
                log(f"cdh-planner node: executor stopped: {_one_line(exc)}")
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


def _one_line(exc):
    text = " ".join(str(exc).split())
    return text if len(text) < 400 else text[:400] + " ..."
