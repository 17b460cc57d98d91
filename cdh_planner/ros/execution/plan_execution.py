"""Executing the node's last good plan, in the configured ``execution.mode``, and saying
how it ended (the node's part behind ``~/execute``, ``~/stop`` and ``use_current_start``).

    run = PlanExecution(node, config, command_publisher, result_publisher, publish, on_end)
    ok, message = run.start(plan, config)     # plan: (PlannedPath, Robot, PlanOutputs)
    message = run.stop()                      # hold where the winches are
    run.running                               # executing now (either mode)
    start = run.current_start(config, plan, cancelled)  # MeasuredStart: the pose of the
                                                         # measured lengths, or why not
    run.close()                               # shutting down: hold, end as stopped
    run.release()                             # lifecycle cleanup: close, then destroy

The modes are the registered command outlets (``execution/command_outlets.py``), one of each made at
configure: a streamed one (``stream``, ``forward_command``) gets the plan's cable state
sampled in real time (``streaming.Stream``) at ``stream_rate_hz`` from a node timer, one
command per sample; a trajectory one (``follow_joint_trajectory``) gets the cable
trajectory, and the controller's result ends the run.

Every mode ``start`` first compares the measured lengths (``execution.joint_states_topic``)
with the plan's first point; with none it refuses unless ``execution.allow_unchecked_start``. Each run is a token of the state machine ``runs``
(``execution_runs.ExecutionRuns``: starting, running, stopping, idle) and ends exactly once,
whatever fails inside: the transition to idle first, then the result published latched
(diagnostic_msgs/DiagnosticStatus: completed, stopped or failed, and why) and ``on_end``.
``publish(publisher, msg, latched)`` is the node's (it records what it publishes).
"""

import time
import traceback
from dataclasses import dataclass

import numpy as np

from ...accuracy import has_accuracy, pose_accuracy
from ...errors import InputError, exception_line
from ...model.elastic import is_elastic
from ...model.forward_kinematics import measured_cable_lengths, nearest_waypoint
from ...model.kinematics import cable_lengths
from ...model.pose import rotation_from_quaternion
from . import winches
from ..msgs import messages as M
from .command_outlets import OUTLETS, OutletContext
from ..core.execution_runs import ExecutionRuns, Phase
from ..core.streaming import Stream


@dataclass
class MeasuredStart:
    """``use_current_start``'s start: the pose (geometry_msgs/PoseStamped, base frame) of
    the measured cable lengths, or why there is none."""

    pose: object = None
    why: str = ""


class PlanExecution:

    def __init__(self, node, config, command_publisher, result_publisher, publish, on_end,
                 callback_group=None):
        self._node = node
        self._results = result_publisher
        self._publish = publish
        self._on_end = on_end          # on_end(publish_pending), once per run
        self.runs = ExecutionRuns()    # the state machine: one run at a time, one end each
        self._stream = None            # the Stream of the current run in stream mode
        self._timer = None
        self._timer_period = None
        self._last_pose = None         # (p, R) of the last forward kinematics, its next guess
        self._waypoints = None         # (p (N, 3), R (N, 3, 3)) of the path executing now
        self.forward_kinematics_residual_m = None  # its largest cable length error, m
        self._said_rigid = False       # logged that joint states without efforts are rigid
        values = config.values
        self.joints = winches.JointStateMonitor(
            node, values["execution.joint_states_topic"], config.robot.winch_names)
        context = OutletContext(node, command_publisher, callback_group)
        self.outlets = {mode: cls(context, config) for mode, cls in OUTLETS.items()}
        self._warn_refusal(config)

    @property
    def running(self):
        return self.runs.current is not None

    def configure(self, config):
        """A new configuration (parameters changed): the winch names to measure and the
        outlets' parameters."""
        self.joints.winch_names = list(config.robot.winch_names)
        for outlet in self.outlets.values():
            outlet.configure(config)
        self._warn_refusal(config)

    def _warn_refusal(self, config):
        """Say at configure when execution.mode cannot execute the robot's plans
        (``CommandOutlet.refusal``); an execution then refuses with the same line."""
        mode = config.values["execution.mode"]
        refusal = self.outlets[mode].refusal(config.robot) if mode in self.outlets else ""
        if refusal:
            self._node.get_logger().warning(f"plans will not be executed: {refusal}")

    # ------------------------------------------------------------------ start, stop

    def start(self, plan, config):
        """(started, message): ``plan`` (PlannedPath, Robot, PlanOutputs) executed in
        ``execution.mode``, or why not (executing already, no plan, the winches away from
        its start, or not measured unless allowed: ``_check_start``). A refusal here is
        only in the answer: ``~/execution_result`` reports runs that started."""
        values = config.values
        if self.running:
            return False, f"refused: already executing{self._where()}; call ~/stop first"
        if plan is None:
            return False, "refused: no plan to execute; call ~/plan first"
        path, robot, out = plan
        refusal = self._outlet(values["execution.mode"]).refusal(robot)
        if refusal:
            return False, f"refused: {refusal}"
        refused, note = self._check_start(values, path, robot)
        if refused:
            return False, refused
        what = f"{len(path)} waypoints, {float(path.t[-1]):.3f} s"
        run = self.runs.begin(values["execution.mode"])
        if run is None:
            return False, f"refused: already executing{self._where()}; call ~/stop first"
        self._waypoints = (path.p, rotation_from_quaternion(path.quaternion))
        try:
            outlet = self._outlet(run.mode)
            if not outlet.streamed:
                return self._start_following(run, outlet, out,
                                             f"{what} through {outlet.target}{note}")
            self._stream = Stream(path, robot.winch_names, config.stream_interpolation,
                                  start=time.monotonic())
            self.runs.advance(run, Phase.RUNNING)
            self._start_timer(1.0 / config.stream_rate_hz)
        except Exception as exc:  # noqa: BLE001 - the run ends, the node stays ready
            self._node.get_logger().error(f"starting the execution failed: "
                                          f"{traceback.format_exc()}")
            self._end(run, winches.FAILED, f"could not start: {exception_line(exc)}")
            return False, f"refused: {run.message}"
        if run.outcome:    # ended already: the first tick failed
            return False, f"refused: execution {run.outcome}: {run.message}"
        return True, (f"executing: {what} at {config.stream_rate_hz:g} Hz on "
                      f"{outlet.target}{note}")

    def _outlet(self, mode):
        """The outlet made at configure for ``mode``."""
        if mode not in self.outlets:
            raise RuntimeError(f"execution mode {mode!r} was registered after the node was "
                               f"configured: configure it again")
        return self.outlets[mode]

    def _check_start(self, values, path, robot):
        """(refusal or "", note): the measured lengths against the path's first commanded
        point (the winches' lengths: unstretched with elastic cables); with
        none, refused unless ``execution.allow_unchecked_start`` (then noted)."""
        lengths, why = self.joints.lengths(values["execution.joint_states_max_age_s"])
        if lengths is not None:
            mismatch = winches.start_mismatch(lengths, path.commanded()[0][0],
                                                values["execution.start_tolerance"],
                                                robot.winch_names)
            return (f"refused: {mismatch}" if mismatch else ""), ""
        if not values["execution.allow_unchecked_start"]:
            return (f"refused: the start is not measured ({why}); set "
                    f"execution.allow_unchecked_start to execute unchecked"), ""
        return "", f" (start not checked: {why})"

    def _start_following(self, run, outlet, out, what):
        outlet.start(out.cable_trajectory,
                     lambda outcome, message: self._end(run, outcome, message),
                     lambda: self.runs.advance(run, Phase.RUNNING))
        if run.outcome:   # ended at once (no controller, a bad goal): the reason is logged
            return False, f"refused: execution {run.outcome}: {run.message}"
        return True, f"executing: {what}"

    def _where(self):
        stream, run = self._stream, self.runs.current
        if stream is not None:
            return f" (at {stream.t:.2f} s of {stream.duration:.2f} s)"
        return f" ({self.runs.phase.value} on {self.outlets[run.mode].target})" if run else ""

    def stop(self):
        """Stop the running execution where it is; what happened (str). A stream holds its
        last setpoint and ends now; a controller is sent a cancel and its result ends it
        (at once when the controller has nothing running)."""
        run = self.runs.current
        if run is None:
            return "not executing: nothing to stop"
        stream, outlet = self._stream, self.outlets[run.mode]
        if outlet.streamed:
            if stream is not None:
                self._send(run, stream.hold(self._stamp()))
            message = (f"stopped at {stream.t:.3f} s of {stream.duration:.3f} s; "
                       f"holding the last setpoint" if stream is not None else "stopped")
            self._end(run, winches.STOPPED, message)
            return message
        self.runs.advance(run, Phase.STOPPING)
        if not outlet.cancel():   # nothing on the controller: end here
            message = f"stopped: nothing was running on {outlet.target}"
            self._end(run, winches.STOPPED, message)
            return message
        return (f"stopping: cancel sent to {outlet.target} "
                f"(the controller holds its position)")

    def close(self):
        """Shutting down: hold (stream) or cancel (controller), and end as stopped without
        handing over a pending plan. Safe after the context has shut down."""
        run = self.runs.current
        if run is None:
            return
        outlet = self.outlets[run.mode]
        try:
            if outlet.streamed and self._stream is not None:
                self._send(run, self._stream.hold(self._stamp()))
            elif not outlet.streamed:
                outlet.cancel()
        except Exception:  # noqa: BLE001 - context already gone: nothing to tell
            pass
        self._end(run, winches.STOPPED, "shutting down while executing: held the last setpoint",
                  publish_pending=False)

    def release(self):
        """Lifecycle cleanup: ``close``, then the joint-state subscription, the outlets'
        publishers and clients and the stream timer destroyed (a new configure makes new
        ones)."""
        self.close()
        steps = [("the joint-state subscription", self.joints.destroy)]
        steps += [(f"the {mode} outlet", outlet.release) for mode, outlet in self.outlets.items()]
        steps += [("the stream timer", lambda: self._timer is not None
                   and self._node.destroy_timer(self._timer))]
        for what, step in steps:
            self._quietly(f"destroying {what}", step)
        self._timer = None

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
        run, stream = self.runs.current, self._stream
        if run is None or not self.outlets[run.mode].streamed or stream is None:
            return
        try:
            msg, finished = stream.command(time.monotonic(), self._stamp())
            self._send(run, msg)
        except Exception as exc:  # noqa: BLE001 - never take the node down
            self._node.get_logger().error(f"streaming failed: {traceback.format_exc()}")
            self._end(run, winches.FAILED,
                      f"streaming stopped after an error: {exception_line(exc)}")
            return
        if finished:
            self._end(run, winches.COMPLETED, f"execution finished: {stream.sent} "
                                                f"commands over {stream.duration:.3f} s")

    def _send(self, run, joint_state):
        """Publish (and record) one streamed setpoint as the run's outlet's command."""
        outlet = self.outlets[run.mode]
        self._publish(outlet.publisher, outlet.message(joint_state))

    # ------------------------------------------------------------------ the end

    def _end(self, run, outcome, message, publish_pending=True):
        """End ``run`` (``winches.COMPLETED``, ``STOPPED`` or ``FAILED``, and why): the
        state machine's one terminal transition first, then, each on its own so that no
        failure can undo it, the stream's timer cancelled, a log line, the result published
        latched and ``on_end(publish_pending)``. Later calls for the same run do nothing."""
        if not self.runs.end(run, outcome, message):
            return   # ended already (stop and the last tick, shutdown and the controller)
        self._stream, self._waypoints = None, None
        self._quietly("cancelling the stream timer",
                      lambda: self._timer is not None and self._timer.cancel())
        self._quietly("logging the end", lambda: self._log_end(outcome, message))
        self._quietly("publishing the execution result",
                      lambda: self._publish(self._results, M.execution_status(
                          outcome, message, run.mode), latched=True))
        self._quietly("handing over the plan made while executing",
                      lambda: self._on_end(publish_pending))

    def _log_end(self, outcome, message):
        # one call site per severity: rclpy refuses a call site whose severity changes
        logger = self._node.get_logger()
        if outcome == winches.FAILED:
            logger.error(f"execution {outcome}: {message}")
        else:
            logger.info(f"execution {outcome}: {message}")

    def _quietly(self, what, step):
        """Run one side effect of an end; what it raises is logged (if logging still
        works), never passed on: the run has ended whatever happens here."""
        try:
            step()
        except Exception:  # noqa: BLE001
            try:
                self._node.get_logger().error(f"{what} failed: {traceback.format_exc()}")
            except Exception:  # noqa: BLE001 - nothing left to tell it with
                pass

    # ------------------------------------------------------------------ where it is

    def current_start(self, config, plan=None, cancelled=lambda: False):
        """The MeasuredStart: the pose by forward kinematics from the winches' lengths
        (``forward_kinematics``: from the last pose and the ends of ``plan``), or why not;
        what it started from and found is logged. Without recent lengths it waits up to
        ``execution.joint_states_wait_s`` for them, or until ``cancelled()``."""
        values = config.values
        lengths, tensions, why = self.joints.wait_measured(
            values["execution.joint_states_max_age_s"], values["execution.joint_states_wait_s"],
            cancelled)
        if lengths is None:
            return MeasuredStart(why=why)
        had_last = self._last_pose is not None
        try:
            p, R = self.forward_kinematics(config.robot, lengths, plan, tensions)
        except InputError as exc:
            return MeasuredStart(why=str(exc))
        except Exception as exc:  # noqa: BLE001 - the goal still gets a result, with why
            self._node.get_logger().error(f"forward kinematics failed: {traceback.format_exc()}")
            return MeasuredStart(why=f"forward kinematics failed: {exception_line(exc)}")
        # m > 6 has least-squares local minima: what a wrong start was made of, in the log
        self._node.get_logger().info(
            f"measured start: p {np.round(p, 5).tolist()} m, tilt "
            f"{float(np.arccos(np.clip(R[2, 2], -1.0, 1.0))):.4f} rad, residual "
            f"{self.forward_kinematics_residual_m:.3g} m; from the last pose: {had_last}, the "
            f"plan's ends: {plan is not None}, efforts: {tensions is not None}; lengths "
            f"{np.round(lengths, 6).tolist()} m")
        return MeasuredStart(pose=M.pose_stamped_msg(p, R, config.base_frame, self._stamp()))

    def forward_kinematics(self, robot, lengths, plan=None, tensions=None):
        """The pose (p (3,) m, R (3, 3)) of the winches' cable lengths ``lengths`` (m),
        stretched by the measured ``tensions`` (N) when the cables are elastic (without
        them: taken as rigid, said once in the log): Newton from the last forward
        kinematics, the ends of ``plan`` and, while a path executes, its waypoint nearest in
        lengths (``winches.current_pose``: of the ends that explain the lengths alike, the
        one from the start nearest in lengths; a wrong last pose, a least-squares local
        minimum with more than six cables, is left as soon as a waypoint explains the
        lengths better), kept as the next one's guess.
        InputError when Newton finds none."""
        if is_elastic(robot):
            if tensions is None and not self._said_rigid:
                self._said_rigid = True
                self._node.get_logger().warning(
                    "the joint states carry no efforts (measured tensions): forward kinematics "
                    "takes the cables as rigid, not stretched by robot.cable_stiffness")
            lengths = measured_cable_lengths(robot, lengths, tensions)
        known = self._plan_ends(plan)
        waypoints = self._waypoints   # while executing: the path's waypoint nearest in lengths
        if waypoints is not None:
            known.append(nearest_waypoint(robot, lengths, *waypoints))
        p, R = winches.current_pose(robot, lengths, self._last_pose, known)
        self._last_pose = (p, R)
        # m > 6: least squares; the residual (m) tells how consistent the lengths are
        self.forward_kinematics_residual_m = float(np.max(np.abs(cable_lengths(robot, p, R) - lengths)))
        return p, R

    def pose_accuracy(self, robot):
        """(position error m, orientation error rad) of the last forward kinematics' pose
        (``accuracy.pose_accuracy``: the worst over the winches' length errors), None
        before any pose or without robot.length_error."""
        if self._last_pose is None or not has_accuracy(robot):
            return None
        p, R = self._last_pose
        acc = pose_accuracy(robot, p[None], R=R[None])
        return float(acc.position_m[0]), float(acc.orientation_rad[0])

    @staticmethod
    def _plan_ends(plan):
        """The platform poses (p, R) at the ends of ``plan`` (none without one)."""
        if plan is None:
            return []
        path = plan[0]
        return [(path.p[k], rotation_from_quaternion(path.quaternion[k])) for k in (0, -1)]

    def _stamp(self):
        return self._node.get_clock().now().to_msg()

