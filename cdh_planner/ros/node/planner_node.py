"""The ROS 2 node ``cdh_planner``: a thin shell over the planner library.

    cdh-planner node --ros-args --params-file config/robot2.yaml [-p name:=value ...]

It maps ROS callbacks onto the parts that hold the logic: ``plan_service.PlanService``
(plan calls' queue, the last good plan, the commit of outputs; no rclpy),
``plan_execution.PlanExecution`` (``~/execute``, ``~/stop``, ``use_current_start``),
``scene.NodeScene`` (``~/obstacles``, ``~/get_scene``: a plan uses the scene of its
arrival), ``run_log.NodeRecording`` (the run file). Names, QoS: ``interface.py``;
parameters: ``core/params.py``; the interface: docs/ros-node.md; the process: ``main.py``.

A lifecycle node (``rclpy.lifecycle``): configure checks the parameters, loads the robot,
warms the planner, opens the run file; activate serves (inactive: plan calls, goals and
``~/execute`` refused); deactivate stops an execution (holding); cleanup and shutdown close
the run file; ``autostart`` (default) configures and activates at start (as nav2 does).
"""

from diagnostic_msgs.msg import DiagnosticStatus
from nav_msgs.msg import Path
from nav_msgs.srv import GetPlan
from rcl_interfaces.msg import SetParametersResult
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.lifecycle import LifecycleNode
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from cdh_planner_interfaces.action import PlanPath
from cdh_planner_interfaces.msg import TensionEnvelope

from ...errors import InputError, exception_line
from ...recording.mcap_log import REQUEST_RECEIVED, RESPONSE_SENT
from ...status import Status
from ..core import plan_requests
from ..interface import ACTION_QOS, CABLE_COMMAND, EXECUTE, EXECUTION_RESULT, LATCHED, MARKERS, \
    NODE_NAME, PATH, PLAN, PLAN_PATH, PLAN_PROGRESS, PLAN_RESULT, PLANNED_TRAJECTORY, \
    SERVICE_QOS, STOP, TENSION_ENVELOPE
from ..msgs.messages import WINCH_COMMAND_TYPE
from .diagnostics import NodeDiagnostics
from .frames import NodeFrames
from .lifecycle import LifecycleMixin
from .plan_outlet import GoalCancel, NodePlanOutlet, run_stem
from .parameters import declare_parameters, refuse_unknown
from .scene import NodeScene
from ..core.params import needs_new_planner, node_config, parameter_error
from ..execution.plan_execution import PlanExecution
from ..core.plan_service import PlanService
from ..core.run_log import NodeRecording, RunLog, log_limits

# executor threads: the plan being computed, the requests waiting their turn, and spare ones
# (busy answers, execute / stop, the stream timer, parameters) that are never all blocked
EXECUTOR_THREADS = 1 + plan_requests.PLAN_QUEUE_DEPTH + 3


def default_planner_factory(robot, task, settings, scene=None):
    from ...planner import Planner
    return Planner(robot, task, settings, scene=scene)


class PlannerNode(LifecycleMixin, LifecycleNode):

    def __init__(self, planner_factory=default_planner_factory, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self.guard_change_state()
        self._factory = planner_factory
        self._values = declare_parameters(self, self._parameter_overrides)
        self.configured = self.active = False
        self.plans = None
        self._configure_error = None
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._make_publishers()
        self._make_servers()
        self.diagnostics = NodeDiagnostics(self, ReentrantCallbackGroup())
        self.frames = NodeFrames(self, ReentrantCallbackGroup())
        self.scene = NodeScene(self)
        if self._values["autostart"]:
            self.start()

    @property
    def config(self):
        return self.plans.config

    @property
    def execution(self):
        return self._execution

    def _make_publishers(self):
        pub = self.create_publisher
        self.pub_path = pub(Path, f"~/{PATH}", LATCHED)
        self.pub_trajectory = pub(JointTrajectory, f"~/{PLANNED_TRAJECTORY}", LATCHED)
        self.pub_envelope = pub(TensionEnvelope, f"~/{TENSION_ENVELOPE}", LATCHED)
        self.pub_markers = pub(MarkerArray, f"~/{MARKERS}", LATCHED)
        self.pub_result = pub(DiagnosticStatus, f"~/{PLAN_RESULT}", LATCHED)
        self.pub_progress = pub(DiagnosticStatus, f"~/{PLAN_PROGRESS}", 10)
        self.pub_execution = pub(DiagnosticStatus, f"~/{EXECUTION_RESULT}", LATCHED)
        self.pub_command = pub(WINCH_COMMAND_TYPE, f"~/{CABLE_COMMAND}", 10)  # never latched

    def _make_servers(self):
        self.srv_plan = self.create_service(GetPlan, f"~/{PLAN}", self._plan,
                                            qos_profile=SERVICE_QOS,
                                            callback_group=ReentrantCallbackGroup())
        self.plan_path_server = ActionServer(
            self, PlanPath, f"~/{PLAN_PATH}", execute_callback=self._plan_path,
            goal_callback=self._goal_response,   # busy goals end with BUSY
            cancel_callback=lambda handle: CancelResponse.ACCEPT,
            callback_group=ReentrantCallbackGroup(), **ACTION_QOS)
        self.srv_execute = self.create_service(Trigger, f"~/{EXECUTE}", self._execute,
                                               qos_profile=SERVICE_QOS)
        self.srv_stop = self.create_service(Trigger, f"~/{STOP}", self._stop,
                                            qos_profile=SERVICE_QOS)

    # ------------------------------------------------------------------ lifecycle

    def _configure(self, config):
        planner = self._new_planner(config, self.scene.effective(config))   # first: nothing to undo
        self.runlog = RunLog(config.log_dir, config.log_enabled,
                             warn=self.get_logger().warning, info=self.get_logger().info,
                             node_name=self.get_fully_qualified_name(), **log_limits(config.values))
        self.record = NodeRecording(self, self.runlog)
        self.record.parameters(self.get_parameters_by_prefix("").values(), initial=True)
        log_file = self.record(self.runlog.open) or ""
        self.outlet = NodePlanOutlet(self)
        self.plans = PlanService(config, planner, self.outlet, make_planner=self._new_planner)
        self.plans.between_steps = self.scene.drain   # obstacle updates while a plan runs
        self.scene.configure(config)
        self._execution = PlanExecution(self, config, self.pub_command, self.pub_execution,
                                        self.record.publish, self.plans.execution_ended,
                                        callback_group=ReentrantCallbackGroup())
        self.plans.executing = lambda: self._execution.running
        self.frames.configure(config)
        self.configured = True
        self.get_logger().info(
            f"configured: robot {config.robot.name}, task {config.task.type}, strategy "
            f"{config.settings.strategy}, base frame {config.base_frame}, "
            + (f"recording to {log_file}; if the node is killed: cdh-planner recover {log_file}"
               if log_file else "recording " + ("off" if not config.log_enabled else "failed")))

    # ------------------------------------------------------------------ parameters

    def set_parameters_atomically(self, parameter_list):
        """rclpy's, but a parameter this node does not have is refused naming it."""
        return (refuse_unknown(self, parameter_list)
                or super().set_parameters_atomically(parameter_list))

    def _on_set_parameters(self, params):
        values = dict(self._values)
        values.update({p.name: p.value for p in params})
        try:
            config = node_config(values)
            planner = None
            if self.configured and needs_new_planner([p.name for p in params],
                                                     self.config.values, config.values):
                planner = self._new_planner(config, self.scene.effective(config))
        except InputError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        self._values = values
        if not self.configured:   # configure uses them
            return SetParametersResult(successful=True)
        self.plans.configure(config, planner)
        self.scene.configure(config)
        self.frames.configure(config)
        self._execution.configure(config)
        self.record(self.runlog.configure, config.log_dir, config.log_enabled,
                    **log_limits(config.values))
        self.record.parameters(params, log_time_ns=self.record.now())
        self.get_logger().info(f"parameters set: {', '.join(p.name for p in params)}")
        return SetParametersResult(successful=True)

    def _new_planner(self, config, scene):
        """A Planner for ``config`` and ``scene`` (a fresh atlas, its kernel warm);
        InputError naming the parameter."""
        try:
            return plan_requests.warm_up(self._factory(config.robot, config.task,
                                                       config.settings, scene=scene))
        except InputError as exc:
            raise parameter_error(exc) from None

    # ------------------------------------------------------------------ plan

    def _plan(self, request, response):
        """~/plan: every call is answered, and its request and response are recorded
        (not active: an empty path, logged)."""
        if not self.active:
            self.get_logger().warning(f"~/plan refused: the node is {self.lifecycle_state}")
            return response
        turn = self.plans.enter()   # first: the queue's order is the order calls are taken
        seq, run_id, log_file, scene = self._new_call()
        self.record.plan(self.srv_plan, REQUEST_RECEIVED, seq, request=request)
        refused = self.frames.to_base(request, ("start", "goal"), self.config.base_frame)
        call = plan_requests.PlanCall.of_get_plan(request, scene)
        response.plan = self.plans.answer(call, run_id, log_file, turn, refused).path
        self.record.plan(self.srv_plan, RESPONSE_SENT, seq, response=response)
        return response

    def _goal_response(self, goal):
        """Accept every goal while active (as nav2's servers, reject when not)."""
        if self.active:
            return GoalResponse.ACCEPT
        self.get_logger().warning(f"~/plan_path goal rejected: the node is {self.lifecycle_state}")
        return GoalResponse.REJECT

    def _plan_path(self, goal_handle):
        """~/plan_path: every goal ends with a result (succeeded, canceled or aborted with
        the error code and reason); feedback at most every 0.1 s."""
        turn = self.plans.enter()
        seq, run_id, log_file, scene = self._new_call()
        action = f"{self.get_fully_qualified_name()}/{PLAN_PATH}"
        self.record.goal(action, REQUEST_RECEIVED, seq, goal_handle, goal=goal_handle.request)
        call, refused = self._plan_path_call(goal_handle, scene)
        answer = self.plans.answer(call, run_id, log_file, turn, refused)
        result = answer.result
        if result.success:
            goal_handle.succeed()
        elif goal_handle.is_cancel_requested and result.reason == Status.CANCELED:
            goal_handle.canceled()
        else:
            goal_handle.abort()
        msg = plan_requests.action_result(result, answer.outputs, answer.path, scene.version)
        self.record.goal(action, RESPONSE_SENT, seq, goal_handle, result=msg)
        return msg

    def _plan_path_call(self, goal_handle, scene):
        """(PlanCall, None) of a goal, or (None, its refusal): a bad goal, or no measured
        start for ``use_current_start`` (after waiting for one, unless cancelled)."""
        goal, config, cancel = goal_handle.request, self.config, GoalCancel(goal_handle)
        start, refused = None, self.frames.to_base(
            goal, ("goal",) if goal.use_current_start else ("start", "goal"), config.base_frame)
        if refused is not None:
            return None, refused
        if goal.use_current_start:
            refused = plan_requests.goal_refusal(goal, config.base_frame, config.settings.strategy)
            if refused is not None:       # not worth waiting for a start
                return None, refused
            measured = self._execution.current_start(config, self.plans.with_last(lambda p: p),
                                                     self.plans.cancel_of(cancel).is_set)
            if measured.pose is None:
                if cancel.is_set():
                    return None, plan_requests.refusal(Status.CANCELED, "canceled while waiting "
                                                  "for the winches' joint states")
                return None, plan_requests.refusal(Status.NO_CURRENT_STATE,
                                              f"use_current_start: {measured.why}")
            start = measured.pose
        return plan_requests.PlanCall.of_plan_path(
            goal, start, cancel, plan_requests.feedback_sender(goal_handle), scene), None

    def _new_call(self):
        """(sequence number, run id, run file, SceneVersion as of now) of a new plan call."""
        seq, scene = self.plans.new_call(), self.scene.current()
        log_file = self.record(self.runlog.open) or ""
        return seq, (f"{run_stem(log_file)}#{seq}" if log_file else str(seq)), log_file, scene

    # ------------------------------------------------------------------ execute, stop

    def _execute(self, request, response):
        if not self.active:
            response.message = f"refused: the node is {self.lifecycle_state}, not active"
            return response
        self.record.trigger(self.srv_execute, REQUEST_RECEIVED, request=request)
        try:
            response.success, response.message = self.plans.with_last(
                lambda plan: self._execution.start(plan, self.config))
        except Exception as exc:  # noqa: BLE001 - never take the node down
            self.get_logger().error(f"execute failed: {exception_line(exc)}")
            response.success, response.message = False, f"internal error: {exception_line(exc)}"
        self.record.trigger(self.srv_execute, RESPONSE_SENT, response=response)
        self.get_logger().info(f"execute: {response.message}")
        return response

    def _stop(self, request, response):
        if not self.configured:
            response.success, response.message = True, "not executing: nothing to stop"
            return response
        self.record.trigger(self.srv_stop, REQUEST_RECEIVED, request=request)
        try:
            response.success, response.message = True, self._execution.stop()
        except Exception as exc:  # noqa: BLE001 - never take the node down
            self.get_logger().error(f"stop failed: {exception_line(exc)}")
            response.success, response.message = False, f"internal error: {exception_line(exc)}"
        self.record.trigger(self.srv_stop, RESPONSE_SENT, response=response)
        return response

    # ------------------------------------------------------------------ shutdown

    def begin_shutdown(self):
        """From now on a running plan is ended at its next progress report, and waiting
        requests are answered (canceled)."""
        if self.plans is not None:
            self.plans.begin_shutdown()

    def destroy_node(self):
        """rclpy's, after the subscriptions no executor serves (``polled.py``)."""
        self.close()
        self.frames.destroy()
        super().destroy_node()

    def close(self):
        """Stop executing (holding), end a running plan at its next progress report, close
        the run file, release the subscriptions (lifecycle cleanup). Safe to call twice, and
        after the context has shut down."""
        if not self.configured:
            return
        self.configured = self.active = False
        self.begin_shutdown()
        self.frames.close()        # the live state's thread reads the joint states: first
        self._execution.release()
        self.record(self.runlog.close)
