"""The node's plan service without the graph: the queue of calls, the configuration and
planner in force, the last good plan and a plan made while executing, and the commit of a
plan's outputs (all of them or none). It owns its lock and imports no rclpy: the node
(``node/planner_node.py``) maps ROS callbacks onto it, and the tests drive it directly.

    plans = PlanService(config, planner, outlet)
    turn = plans.enter()                          # first: the queue's order is arrival order
    answer = plans.answer(call, run_id, log_file, turn)   # Answer: result, outputs, path
    plans.with_last(lambda plan: execution.start(plan, config))
    plans.execution_ended(publish_pending=True)   # a plan made meanwhile goes out now

``outlet`` is the node's side (a ``PlanOutlet``): it records and publishes what it is given.
"""

import threading
import time
import traceback
from dataclasses import dataclass
from typing import Optional, Protocol

from ...errors import InputError, exception_line
from ...planner import PlanResult
from ...status import Status
from . import plan_requests

PROGRESS_PERIOD_S = 0.1   # ~/plan_progress at most this often


class PlanOutlet(Protocol):
    """What the plan service hands to ROS (the node records, then publishes)."""

    def publish_outputs(self, out):
        """The latched path, cable trajectory, tension envelope and markers; raises."""

    def publish_result(self, status):
        """``~/plan_result`` (latched)."""

    def publish_progress(self, status):
        """``~/plan_progress``."""

    def stamp(self):
        """Now, as builtin_interfaces/Time."""

    def error(self, text):
        """Log at error severity."""

    def answered(self, ok, line):
        """Log the one line of an answer (info when ``ok``, else warning)."""


@dataclass
class Answer:
    result: PlanResult
    outputs: Optional[plan_requests.PlanOutputs]   # the messages of a successful plan
    path: object                              # nav_msgs/Path: the plan's, or empty


class Cancel:
    """A plan's stop signal (``is_set``): shutting down, every call cancelled since this
    signal was made (``PlanService.cancel_all``: deactivate), or the caller's own cancel."""

    def __init__(self, plans, caller=None):
        self.plans, self.caller, self.epoch = plans, caller, plans.epoch

    def is_set(self):
        return (self.plans.shutting_down or self.plans.epoch != self.epoch
                or (self.caller is not None and self.caller.is_set()))


class StepCancel(Cancel):
    """The running plan's Cancel: the search asks it between its steps, so it also does the
    node's work that must not wait for the plan (``PlanService.between_steps``: the
    obstacle updates), at most every STEP_WORK_PERIOD_S."""

    def is_set(self):
        self.plans.step_work()
        return super().is_set()


STEP_WORK_PERIOD_S = 0.005


class PlanService:

    def __init__(self, config, planner, outlet, depth=plan_requests.PLAN_QUEUE_DEPTH,
                 make_planner=None):
        self._lock = threading.RLock()    # the plans, the configuration and the counter
        self._queue = plan_requests.PlanQueue(depth)
        self._config, self._planner = config, planner
        self._outlet = outlet
        self._calls = 0
        self._last = None      # (PlannedPath, Robot, PlanOutputs) of the last good plan
        self._pending = None   # the same, of a plan made while executing
        self.executing = lambda: False   # the node's: is an execution running
        # make_planner(config, scene) -> a planner for another scene (None: the planner in
        # force serves every scene)
        self.make_planner = make_planner
        self.shutting_down = False
        self.planning = False
        self.epoch = 0   # cancel_all: the calls that arrived before it are cancelled
        self.between_steps = lambda: None   # the node's: work done between planning steps
        self._last_step_work = 0.0

    @property
    def config(self):
        return self._config

    def configure(self, config, planner=None):
        """The configuration for the calls whose turn comes next, with ``planner`` (None:
        the planner in force, when the change does not need a new one)."""
        with self._lock:
            self._config = config
            self._planner = self._planner if planner is None else planner

    def new_call(self):
        """The sequence number of a new call (1, 2, ...)."""
        with self._lock:
            self._calls += 1
            return self._calls

    def enter(self):
        """A turn in the queue (None: full, the answer will be busy)."""
        return self._queue.enter()

    def cancel_of(self, caller=None):
        return Cancel(self, caller)

    def queued(self):
        return len(self._queue)

    # ------------------------------------------------------------------ one call

    def answer(self, call, run_id, log_file, turn, refused=None):
        """The Answer to one PlanCall holding ``turn`` (None: the queue was full), never
        raising (an exception: INTERNAL_ERROR); ``refused``: a PlanResult refusing the
        call before planning, answered as it is. ``~/plan_result`` is published."""
        config = self._config
        try:
            answer = self._serve(call, run_id, log_file, turn, refused)
        except Exception as exc:  # noqa: BLE001 - never take the node down: answer no plan
            self._queue.drop(turn)
            self._outlet.error(f"[{run_id}] plan call failed: {traceback.format_exc()}")
            result = plan_requests.refusal(Status.INTERNAL_ERROR, f"internal error: "
                                      f"{exception_line(exc)}", config.settings.strategy)
            answer = Answer(result, None, self._no_path(config))
            self._publish_result(result, config, run_id, log_file, answer.path)
        self._outlet.answered(answer.result.success,
                              f"[{run_id}] {plan_requests.result_line(answer.result)}")
        return answer

    def _serve(self, call, run_id, log_file, turn, refused):
        config = self._config
        epoch = self.epoch
        if call is not None:
            call.cancel = Cancel(self, call.cancel)
        if refused:
            self._queue.drop(turn)
            result = refused
        elif turn is None:
            result = plan_requests.refusal(
                Status.BUSY, f"busy: {len(self._queue)} plan requests are being computed or "
                             f"wait (at most 1 + {self._queue.depth}); call again when one is "
                             f"answered", config.settings.strategy)
        elif not self._queue.wait(turn, call.cancel):
            why = ("the node is shutting down" if self.shutting_down else
                   "the node was deactivated" if self.epoch != epoch else "cancelled while queued")
            result = plan_requests.refusal(Status.CANCELED, f"canceled: {why}", config.settings.strategy)
        else:
            try:
                return self._plan(call, run_id, log_file)
            finally:
                self._queue.leave()
        path = self._no_path(config)
        self._publish_result(result, config, run_id, log_file, path)
        return Answer(result, None, path)

    def _plan(self, call, run_id, log_file):
        """Plan a call whose turn it is; a success is committed (``_commit``)."""
        with self._lock:
            config, planner = self._config, self._planner
        planner, scene = self._for_scene(call, config, planner)
        result = self.compute(call, planner, config, run_id)
        result = plan_requests.output_refusal(result) or result
        if call.scene is not None:
            result.stats["scene_version"] = call.scene.version
        if result.success:
            out = plan_requests.plan_outputs(result, config.robot, config.base_frame,
                                             self._outlet.stamp(), scene)
            self._commit(result, config, out, run_id, log_file)
            return Answer(result, out, out.path)
        path = self._no_path(config)
        self._publish_result(result, config, run_id, log_file, path)
        return Answer(result, None, path)

    def _for_scene(self, call, config, planner):
        """(planner, scene) for the call's scene (as of its arrival): the planner in force
        if it was made for a scene of the same geometry, else a new one (a fresh atlas),
        which stays in force while the configuration does. Geometry, not the version: an
        obstacle added then removed keeps the atlas, on the recorded node as on a replaying
        one that never saw the two changes."""
        if call.scene is None or self.make_planner is None:
            return planner, getattr(config, "scene", None)
        scene = call.scene.scene
        current = getattr(planner, "scene", None)
        if current is not scene and not (current is not None and current.same_geometry(scene)):
            planner = self.make_planner(config, scene)
            with self._lock:
                if self._config is config:
                    self._planner = planner
        return planner, scene

    def compute(self, call, planner, config, run_id):
        """The PlanResult of one call (never raising but for bugs)."""
        try:
            start, goal = plan_requests.request_poses(call, config.base_frame)
        except InputError as exc:
            return plan_requests.input_refusal(exc, config.settings.strategy)
        call.cancel = StepCancel(self, call.cancel)
        last = [0.0]

        def progress(info):
            self.step_work()
            now = time.monotonic()
            if now - last[0] >= PROGRESS_PERIOD_S:
                last[0] = now
                self._outlet.publish_progress(plan_requests.progress_status(info, run_id))
            if call.feedback is not None:
                call.feedback(info)

        self.planning = True
        try:
            return plan_requests.run_planner(planner, start, goal, call, progress,
                                        logger=self._outlet.error)
        finally:
            self.planning = False

    def step_work(self):
        """``between_steps()``, at most every STEP_WORK_PERIOD_S (s); never raising."""
        now = time.monotonic()
        if now - self._last_step_work < STEP_WORK_PERIOD_S:
            return
        self._last_step_work = now
        try:
            self.between_steps()
        except Exception:  # noqa: BLE001 - the plan goes on; the error is the node's
            self._outlet.error(f"work between planning steps failed: {traceback.format_exc()}")

    # ------------------------------------------------------------------ commit

    def _commit(self, result, config, out, run_id, log_file):
        """Make a successful plan the last good plan: its status built, its outputs
        published, then ``_last`` set and the status published. While executing, the
        outputs wait in ``_pending`` for the end of the execution. Raises (and leaves the
        previous last good plan) if building or publishing fails."""
        with self._lock:
            deferred = self.executing()
            status = plan_requests.result_status(
                result, config.robot, run_id, log_file, out.path.header.stamp,
                outputs=plan_requests.DEFERRED if deferred else plan_requests.PUBLISHED)
            plan = (result.path, config.robot, out)
            if deferred:
                self._pending = plan
            else:
                self._publish_outputs(out)
                self._last, self._pending = plan, None
        self._publish_result(result, config, run_id, log_file, out.path, status)

    def _publish_outputs(self, out, restore=True):
        """Publish a plan's latched outputs; if that fails, put the last good plan's back
        (as far as possible) and raise."""
        try:
            self._outlet.publish_outputs(out)
        except Exception:
            if restore and self._last is not None:
                try:
                    self._publish_outputs(self._last[2], restore=False)
                except Exception:  # noqa: BLE001 - the error raised below says what failed
                    pass
            raise

    def _publish_result(self, result, config, run_id, log_file, path, status=None):
        """``~/plan_result`` (``status``, or that of ``result`` answered with ``path``); a
        failure is logged: the answer stands."""
        try:
            if status is None:
                status = plan_requests.result_status(result, config.robot, run_id, log_file,
                                                path.header.stamp)
            self._outlet.publish_result(status)
        except Exception:  # noqa: BLE001 - a diagnostic, never the answer
            self._outlet.error(f"[{run_id}] publishing the plan result failed: "
                               f"{traceback.format_exc()}")

    def _no_path(self, config):
        return plan_requests.empty_path(config.base_frame, self._outlet.stamp())

    # ------------------------------------------------------------------ execution

    def with_last(self, use):
        """``use(the last good plan or None)`` under the lock: no plan is committed or
        handed over meanwhile."""
        with self._lock:
            return use(self._last)

    def execution_ended(self, publish_pending):
        """An execution ended: a plan made meanwhile is published and becomes the last good
        plan, unless ``publish_pending`` is False (shutting down)."""
        with self._lock:
            pending, self._pending = self._pending, None
            if pending is None or not publish_pending:
                return False
            try:
                self._publish_outputs(pending[2])
            except Exception:  # noqa: BLE001 - the previous last good plan stays
                self._outlet.error(f"publishing the plan made while executing failed (it "
                                   f"cannot be executed): {traceback.format_exc()}")
                return False
            self._last = pending
            return True

    def cancel_all(self):
        """End the running plan at its next progress report and answer the waiting calls
        (canceled); calls arriving later are served (lifecycle deactivate)."""
        with self._lock:
            self.epoch += 1

    def begin_shutdown(self):
        """A running plan ends at its next progress report; waiting calls are answered
        (canceled), later ones refused."""
        self.shutting_down = True
        self._queue.close()
