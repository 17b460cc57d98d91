"""Executing the node's last good plan, in the configured ``execution.mode``, and saying
how it ended (the node's part behind ``~/execute``, ``~/stop`` and ``use_current_start``).

    run = PlanExecution(node, config, command_publisher, result_publisher, publish, lock,
                        on_end)
    ok, message = run.start(plan, config)     # plan: (PlannedPath, Robot, PlanOutputs)
    message = run.stop()                      # hold where the winches are
    run.running                               # executing now (either mode)
    start = run.current_start(config, plan, cancelled)  # PoseStamped of the measured
                                                         # lengths, or why not
    run.close()                               # shutting down: hold, end as stopped

- ``stream``: the plan's cable lengths sampled in real time (``streaming.Stream``) and sent
  on the command topic at ``stream_rate_hz`` from a node timer.
- ``follow_joint_trajectory``: the cable trajectory sent to a ros2_control controller's
  FollowJointTrajectory action (``execution.TrajectoryExecutor``); its result ends the run.

Either way ``start`` first compares the measured lengths (``execution.joint_states_topic``)
with the plan's first point, and every run ends exactly once: the result published latched
(diagnostic_msgs/DiagnosticStatus: completed, stopped or failed, and why), then ``on_end``.
``publish(publisher, msg, latched)`` is the node's (it records what it publishes); ``lock``
is the node's too, so that "executing" and the node's plan hand-over change together.
"""

import time
import traceback

from ..errors import InputError, exception_line
from ..model.pose import rotation_from_quaternion
from . import execution
from . import messages as M
from .streaming import Stream

STREAM, FOLLOW = "stream", "follow_joint_trajectory"


class PlanExecution:

    def __init__(self, node, config, command_publisher, result_publisher, publish, lock,
                 on_end, callback_group=None):
        self._node = node
        self._commands = command_publisher
        self._results = result_publisher
        self._publish = publish
        self._lock = lock
        self._on_end = on_end          # on_end(publish_pending), under lock, once per run
        self._stream = None            # the running execution in stream mode
        self._following = False        # the running execution in follow_joint_trajectory mode
        self._timer = None
        self._timer_period = None
        self._last_pose = None         # (p, R) of the last forward kinematics, its next guess
        self._ended_with = ""          # "execution <outcome>: <why>" of the last run
        values = config.values
        self.joints = execution.JointStateMonitor(
            node, values["execution.joint_states_topic"], config.robot.winch_names)
        self.controller = execution.TrajectoryExecutor(
            node, values["execution.controller_action"], callback_group=callback_group)

    @property
    def running(self):
        return self._stream is not None or self._following

    def configure(self, config):
        """A new configuration (parameters changed): the winch names to measure."""
        self.joints.winch_names = list(config.robot.winch_names)

    # ------------------------------------------------------------------ start, stop

    def start(self, plan, config):
        """(started, message): ``plan`` (PlannedPath, Robot, PlanOutputs) executed in
        ``execution.mode``, or why not (executing already, no plan, the winches away from
        its start). Measured lengths are checked when there are any. Call under ``lock``."""
        values = config.values
        if self.running:
            where = (f" (at {self._stream.t:.2f} s of {self._stream.duration:.2f} s)"
                     if self._stream is not None else "")
            return False, f"refused: already executing{where}; call ~/stop first"
        if plan is None:
            return False, "refused: no plan to execute; call ~/plan first"
        path, robot, out = plan
        lengths, why = self.joints.lengths(values["execution.joint_states_max_age_s"])
        if lengths is not None:
            mismatch = execution.start_mismatch(lengths, path.lengths[0],
                                                values["execution.start_tolerance"],
                                                robot.winch_names)
            if mismatch:
                return False, f"refused: {mismatch}"
        note = "" if lengths is not None else f" (start not checked: {why})"
        what = f"{len(path)} waypoints, {float(path.t[-1]):.3f} s"
        if values["execution.mode"] == FOLLOW:
            self._following = True
            self.controller.start(out.cable_trajectory, self._end)
            if not self._following:   # ended at once (no controller): the reason is logged
                return False, f"refused: {self._ended_with}"
            return True, f"executing: {what} through {self.controller.action_name}{note}"
        self._stream = Stream(path, robot.winch_names, config.stream_interpolation,
                              start=time.monotonic())
        self._start_timer(1.0 / config.stream_rate_hz)
        return True, (f"executing: {what} at {config.stream_rate_hz:g} Hz on "
                      f"{self._commands.topic_name}{note}")

    def stop(self):
        """Stop the running execution where it is; what happened (str). A stream holds its
        last setpoint and ends now; a controller is sent a cancel and its result ends it."""
        stream = self._stream
        if stream is not None:
            self._publish(self._commands, stream.hold(self._stamp()))
            message = (f"stopped at {stream.t:.3f} s of {stream.duration:.3f} s; "
                       f"holding the last setpoint")
            self._end(execution.STOPPED, message)
            return message
        if self._following:
            self.controller.cancel()   # the controller holds; its result ends the execution
            return (f"stopping: cancel sent to {self.controller.action_name} "
                    f"(the controller holds its position)")
        return "not executing: nothing to stop"

    def close(self):
        """Shutting down: hold (stream) or cancel (controller), and end as stopped without
        handing over a pending plan. Safe after the context has shut down."""
        if not self.running:
            return
        try:
            if self._stream is not None:
                self._publish(self._commands, self._stream.hold(self._stamp()))
            else:
                self.controller.cancel()
        except Exception:  # noqa: BLE001 - context already gone: nothing to tell
            pass
        self._end(execution.STOPPED, "shutting down while executing: held the last setpoint",
                  publish_pending=False)

    # ------------------------------------------------------------------ the stream

    def _start_timer(self, period):
        if self._timer is None or self._timer_period != period:
            if self._timer is not None:
                self._node.destroy_timer(self._timer)
            self._timer = self._node.create_timer(period, self._tick)
            self._timer_period = period
        else:
            self._timer.reset()
        self._tick()

    def _tick(self):
        stream = self._stream
        if stream is None:
            return
        try:
            msg, finished = stream.command(time.monotonic(), self._stamp())
        except Exception as exc:  # noqa: BLE001 - never take the node down
            self._node.get_logger().error(f"streaming failed: {traceback.format_exc()}")
            self._end(execution.FAILED,
                      f"streaming stopped after an error: {exception_line(exc)}")
            return
        self._publish(self._commands, msg)
        if finished:
            self._end(execution.COMPLETED, f"execution finished: {stream.sent} "
                                           f"commands over {stream.duration:.3f} s")

    # ------------------------------------------------------------------ the end

    def _end(self, outcome, message, publish_pending=True):
        """The run is over (``execution.COMPLETED``, ``STOPPED`` or ``FAILED``, and why):
        the result published latched, then ``on_end(publish_pending)``; once per run."""
        with self._lock:
            if not self.running:
                return   # ended already (stop and the last tick, shutdown and the controller)
            if self._timer is not None:
                self._timer.cancel()
            logger = self._node.get_logger()
            (logger.error if outcome == execution.FAILED else logger.info)(
                f"execution {outcome}: {message}")
            mode = STREAM if self._stream is not None else FOLLOW
            self._stream, self._following = None, False
            self._ended_with = f"execution {outcome}: {message}"
            try:
                self._publish(self._results, M.execution_status(outcome, message, mode),
                              latched=True)
            except Exception:  # noqa: BLE001 - a diagnostic: the execution is over anyway
                logger.error(f"publishing the execution result failed: "
                             f"{traceback.format_exc()}")
            self._on_end(publish_pending)

    # ------------------------------------------------------------------ where it is

    def current_start(self, config, plan=None, cancelled=lambda: False):
        """The measured start pose (PoseStamped in the base frame) by forward kinematics
        from the winches' lengths, Newton from the nearest known pose (the last forward
        kinematics, the ends of ``plan``); or why not (a str). Without recent lengths it
        waits up to ``execution.joint_states_wait_s`` for them, or until ``cancelled()``."""
        values = config.values
        lengths, why = self.joints.wait_lengths(values["execution.joint_states_max_age_s"],
                                                values["execution.joint_states_wait_s"],
                                                cancelled)
        if lengths is None:
            return why
        try:
            guess = execution.nearest_pose(config.robot, lengths, self._known_poses(plan))
            p, R = execution.current_pose(config.robot, lengths, guess)
        except InputError as exc:
            return str(exc)
        except Exception as exc:  # noqa: BLE001 - the goal still gets a result, with why
            self._node.get_logger().error(f"forward kinematics failed: {traceback.format_exc()}")
            return f"forward kinematics failed: {exception_line(exc)}"
        self._last_pose = (p, R)
        return M.pose_stamped_msg(p, R, config.base_frame, self._stamp())

    def _known_poses(self, plan):
        """Platform poses (p, R): the last forward kinematics and the ends of ``plan``."""
        known = [self._last_pose] if self._last_pose is not None else []
        if plan is not None:
            path = plan[0]
            known += [(path.p[k], rotation_from_quaternion(path.quaternion[k])) for k in (0, -1)]
        return known

    def _stamp(self):
        return self._node.get_clock().now().to_msg()
