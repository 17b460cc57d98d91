"""The task sequencer's side: call a running ``cdh_planner`` node (used by ``cdh-planner
call``, ``replay --requests``, the demo and the tests).

    with PlannerClient("/cdh_planner", args=ros_args) as client:
        client.wait_for_node(timeout_s=10)
        answer = client.plan(start_msg, goal_msg, timeout_s=60)   # PlanAnswer (~/plan)
        answer = client.plan_path(plan_path_goal(start_msg, goal_msg))  # the same, ~/plan_path
        run = client.execute_and_follow(answer)                   # Execution
        client.stop()

Spins its own node with ``spin_once`` (not ``spin_until_future_complete``, which slows down
call after call in rclpy 7.1 as installed from PyPI). Its subscription to ``~/plan_result`` is
volatile, so only answers published after it joined arrive; an answer is paired with its
result by the ``path_stamp`` key (= the response path's header stamp). ``execute_and_follow``
calls ``~/execute`` and follows the streamed ``~/cable_command`` to the last waypoint (used by
``cdh-planner call --execute`` and the demo). Names of services and topics: ``interface.py``.
"""

import math
import time
from dataclasses import dataclass, field
from typing import Optional

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from nav_msgs.srv import GetPlan
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from .actions import RaceFreeActionClient
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from cdh_planner_interfaces.action import PlanPath
from cdh_planner_interfaces.msg import TensionEnvelope

from ..errors import InputError
from ..parsing.poses import pose_values
from .msgs import messages as M
from .context import init_context
from .interface import ACTION_QOS, CABLE_COMMAND, EXECUTE, EXECUTION_RESULT, GET_SCENE, \
    LATCHED, NODE_NAME, OBSTACLES, OBSTACLES_QOS, PLAN, PLAN_PATH, PLAN_RESULT, \
    PLANNED_TRAJECTORY, SERVICE_QOS, STOP, TENSION_ENVELOPE

DEFAULT_NODE = "/" + NODE_NAME
RESULT_WAIT_S = 2.0  # after the response, how long to wait for its ~/plan_result
LATCHED_WAIT_S = 5.0  # before executing, how long to wait for the plan's latched messages
CANCEL_WAIT_S = 5.0  # after Ctrl-C, how long to wait for the cancelled goal's result
FOLLOW_MARGIN_S = 5.0  # how long to follow the stream beyond the path's duration
ARRIVAL_TOL_M = 1e-9  # the last command is the last waypoint within this (m)
COMMAND_DEPTH = 1000  # ~/cable_command queue: no command is dropped while spinning late
# After the services are seen, s of spinning before the first call: the node must also have
# discovered this client's reply reader, or a fast answer (a direct motion, 30 ms) is dropped
# by the middleware ("failed to send response (timeout)").
DISCOVERY_SETTLE_S = 0.3


@dataclass
class PlanAnswer:
    """A plan call's answer: the path (nav_msgs/Path, no poses: no plan) and the
    ``~/plan_result`` key/values (strings; empty if the result did not arrive within
    RESULT_WAIT_S); through ``~/plan_path`` also the PlanPath ``result``, its ``goal_status``
    (action_msgs/GoalStatus: SUCCEEDED, CANCELED, ABORTED), every ``feedback`` received and,
    if the client cancelled it, the s from the cancel request to the result (``cancel_s``)."""

    path: object                      # nav_msgs/Path
    status: Optional[object] = None   # diagnostic_msgs/DiagnosticStatus
    values: dict = field(default_factory=dict)
    seconds: float = 0.0              # round trip (s)
    result: Optional[object] = None   # cdh_planner_interfaces/action/PlanPath.Result
    goal_status: Optional[int] = None
    feedback: list = field(default_factory=list)
    cancel_s: float = math.nan

    @property
    def success(self):
        return len(self.path.poses) > 0

    def number(self, key, default=math.nan):
        try:
            return float(self.values[key])
        except (KeyError, ValueError):
            return default


@dataclass
class Execution:
    """What ``execute_and_follow`` saw: the ``~/execute`` answer (``accepted``, ``message``),
    the plan's latched ``trajectory`` (JointTrajectory) and ``envelope`` (TensionEnvelope;
    None if they did not arrive), the winch ``commands`` streamed after the call (stream
    mode), in arrival order, how the node says it ended (``end``: ``~/execution_result``,
    None if it did not come), whether it completed (and, streamed, the last command is the
    last waypoint (``goal``, m) at rest: ``arrived``), and ``~/stop``'s answer when Ctrl-C
    ended the following (``stopped``)."""

    accepted: bool = False
    message: str = ""
    trajectory: object = None
    envelope: object = None
    goal: Optional[np.ndarray] = None
    commands: list = field(default_factory=list)
    end: Optional[object] = None      # diagnostic_msgs/DiagnosticStatus
    called_at: float = math.nan       # time.monotonic() of the ~/execute call
    arrived: bool = False
    stopped: str = ""

    @property
    def outcome(self):
        """completed, stopped, failed, or "" (no ~/execution_result received)."""
        return M.status_values(self.end).get("outcome", "") if self.end is not None else ""

    def values(self):
        """(stamps (M,) s, positions (M, joints) m) of the streamed commands."""
        values = [M.winch_command_values(m) for m in self.commands]
        return (np.array([v[0] for v in values]),
                np.array([v[1] for v in values]).reshape(len(values), -1))

    def rate(self):
        """(span s from the first command's stamp to the last's, commands per s)."""
        t, _ = self.values()
        span = float(t[-1] - t[0]) if len(t) else 0.0
        return span, (len(t) - 1) / span if span > 0 else 0.0

    def error_m(self):
        """Largest distance (m) of the last command from the last waypoint (nan if none)."""
        _, positions = self.values()
        if self.goal is None or not len(positions):
            return math.nan
        return float(np.max(np.abs(positions[-1] - self.goal)))


def plan_path_goal(start, goal, use_current_start=False, strategy="", timeout_s=0.0):
    """A PlanPath goal (PoseStamped ``start``, ``goal``; ``start`` may be None with
    ``use_current_start``; empty strategy and timeout_s 0: the node's parameters)."""
    msg = PlanPath.Goal(goal=goal, use_current_start=bool(use_current_start),
                        strategy=strategy, timeout_s=float(timeout_s))
    if start is not None:
        msg.start = start
    return msg


class ClientError(RuntimeError):
    """The node did not answer (not running, wrong name, timeout)."""


def check_node_name(name, field="--node"):
    """The absolute name of the node ``name`` (``cdh_planner`` -> ``/cdh_planner``), if its
    services can have names (letters, digits, ``_``, ``/``; a part not starting with a
    digit); InputError naming ``field`` otherwise (rclpy would raise
    InvalidServiceNameException on creating the first client)."""
    from rclpy.exceptions import NameValidationException
    from rclpy.validate_full_topic_name import validate_full_topic_name
    target = "/" + str(name).strip("/")
    try:
        validate_full_topic_name(f"{target}/{PLAN}", is_service=True)
    except NameValidationException:
        raise InputError(field, name, "not a valid ROS node name (letters, digits, '_' and "
                                      "'/', a part not starting with a digit)") from None
    return target


def pose_stamped(values, frame_id, field="pose"):
    """PoseStamped of "x y z qx qy qz qw" (a string or 7 numbers; m, quaternion x y z w),
    checked as a pose file's pose is (``parsing.poses.pose_values``: finite, within +-1e3 m, a
    unit quaternion); InputError naming ``field`` if not. The quaternion is sent as given."""
    values = pose_values(values, field)
    msg = PoseStamped()
    msg.header.frame_id = frame_id
    p, o = msg.pose.position, msg.pose.orientation
    p.x, p.y, p.z, o.x, o.y, o.z, o.w = (float(v) for v in values)
    return msg


class PlannerClient:
    """A small rclpy node talking to one planner node (``node_name``, absolute)."""

    def __init__(self, node_name=DEFAULT_NODE, args=None, name="cdh_planner_client",
                 context=None, domain_id=None, node_field="node"):
        self.target = check_node_name(node_name, node_field)
        self._own_context = context is None
        self.context = context if context is not None else init_context(args, domain_id)
        self.node = Node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        # deep queues, as the node's: every client's reply reader receives the replies to
        # all clients of the service, and rclpy's default (10) drops them in a burst
        create = self.node.create_client
        self.plan_client = create(GetPlan, self.topic(PLAN), qos_profile=SERVICE_QOS)
        self.execute_client = create(Trigger, self.topic(EXECUTE), qos_profile=SERVICE_QOS)
        self.stop_client = create(Trigger, self.topic(STOP), qos_profile=SERVICE_QOS)
        self.plan_path_client = RaceFreeActionClient(self.node, PlanPath,
                                                     self.topic(PLAN_PATH), **ACTION_QOS)
        self.results = []
        self.node.create_subscription(
            DiagnosticStatus, self.topic(PLAN_RESULT), self.results.append,
            QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))
        # every message received since watch_execution(), in arrival order
        self.commands, self.trajectories, self.envelopes = None, None, None
        self._results_settled = False   # the latched ~/execution_result has had its time
        self._param_client = None
        self._scene_client = self._obstacles = None

    def topic(self, name):
        """The absolute name of the node's topic or service ``name`` (interface.py's names)."""
        return f"{self.target}/{name}"

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        self.executor.shutdown(timeout_sec=0)
        self.node.destroy_node()
        if self._own_context:
            rclpy.try_shutdown(context=self.context)

    def spin(self, seconds):
        """Process callbacks for ``seconds``."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=min(0.05, max(0.0, end - time.monotonic())))

    def spin_until(self, condition, timeout_s):
        """Spin until ``condition()`` holds; return whether it did within ``timeout_s``."""
        end = time.monotonic() + timeout_s
        while not condition():
            left = end - time.monotonic()
            if left <= 0:
                return False
            self.executor.spin_once(timeout_sec=min(0.05, left))
        return True

    def wait_for_node(self, timeout_s=10.0):
        """Wait until the node's three services are there; ClientError if not."""
        end = time.monotonic() + timeout_s
        for client in (self.plan_client, self.execute_client, self.stop_client):
            if not client.wait_for_service(timeout_sec=max(0.0, end - time.monotonic())):
                raise ClientError(f"no service {client.srv_name} after {timeout_s:g} s: is "
                                  f"`cdh-planner node` running (same ROS_DOMAIN_ID)?")
        # let the plan_result subscription match the node's publisher
        self.spin_until(lambda: self.node.count_publishers(self.topic(PLAN_RESULT)) > 0,
                        max(0.0, end - time.monotonic()))
        self.spin_until(lambda: False, DISCOVERY_SETTLE_S)

    def call(self, client, request, timeout_s):
        """The response of one service call, spinning meanwhile; ClientError on timeout."""
        future = client.call_async(request)
        if not self.spin_until(future.done, timeout_s):
            client.remove_pending_request(future)
            raise ClientError(f"{client.srv_name}: no answer within {timeout_s:g} s")
        return future.result()

    def plan(self, start, goal, timeout_s=120.0, tolerance=0.0):
        """Call ``~/plan`` with PoseStamped ``start`` and ``goal``; a PlanAnswer."""
        request = GetPlan.Request(start=start, goal=goal, tolerance=float(tolerance))
        t0 = time.monotonic()
        response = self.call(self.plan_client, request, timeout_s)
        return self._with_result(PlanAnswer(path=response.plan, seconds=time.monotonic() - t0))

    def _with_result(self, answer):
        """``answer`` with its ``~/plan_result`` (paired by the path's stamp), waiting at most
        RESULT_WAIT_S for it."""
        stamp = str(M.time_ns(answer.path.header.stamp))

        def find():
            for msg in reversed(self.results):
                values = M.status_values(msg)
                if values.get("path_stamp") == stamp:
                    answer.status, answer.values = msg, values
                    return True
            return False

        self.spin_until(find, RESULT_WAIT_S)
        return answer

    def plan_path(self, goal, timeout_s=120.0, cancel_after_s=None, on_feedback=None):
        """Send a PlanPath goal (``plan_path_goal``) to ``~/plan_path`` and wait for its
        result, spinning meanwhile (``on_feedback`` gets each feedback); with
        ``cancel_after_s``, request a cancel once that long has passed and a feedback has
        arrived (the plan is running); Ctrl-C requests one too. A PlanAnswer; ClientError if
        the server is not there or the result does not come in time."""
        if not self.plan_path_client.wait_for_server(timeout_sec=min(timeout_s, 10.0)):
            raise ClientError(f"no action server {self.topic(PLAN_PATH)}")
        feedback = []

        def received(msg):
            feedback.append(msg.feedback)
            if on_feedback is not None:
                on_feedback(msg.feedback)

        t0 = time.monotonic()
        sent = self.plan_path_client.send_goal_async(goal, feedback_callback=received)
        if not self.spin_until(sent.done, timeout_s):
            raise ClientError(f"{self.topic(PLAN_PATH)}: the goal was not answered")
        handle = sent.result()
        if not handle.accepted:   # the node accepts every goal: not this node
            raise ClientError(f"{self.topic(PLAN_PATH)} rejected the goal")
        done = handle.get_result_async()
        t_cancel = None
        try:
            if cancel_after_s is not None:
                self.spin_until(lambda: done.done() or (
                    feedback and time.monotonic() - t0 >= cancel_after_s), timeout_s)
                if not done.done():
                    t_cancel = time.monotonic()
                    handle.cancel_goal_async()
            finished = self.spin_until(done.done, max(0.0, t0 + timeout_s - time.monotonic()))
        except KeyboardInterrupt:
            t_cancel = time.monotonic()
            handle.cancel_goal_async()
            finished = self.spin_until(done.done, CANCEL_WAIT_S)
        if not finished:
            raise ClientError(f"{self.topic(PLAN_PATH)}: no result within {timeout_s:g} s")
        end = time.monotonic()
        result = done.result().result
        return self._with_result(PlanAnswer(
            path=result.path, seconds=end - t0, result=result, goal_status=done.result().status,
            feedback=feedback, cancel_s=end - t_cancel if t_cancel is not None else math.nan))

    def _parameters(self):
        if self._param_client is None:
            from rclpy.parameter_client import AsyncParameterClient
            self._param_client = AsyncParameterClient(self.node, self.target,
                                                      qos_profile=SERVICE_QOS)
        return self._param_client

    def get_parameters(self, names, timeout_s=5.0):
        """name -> value (Python) of the node's parameters ``names``."""
        from rclpy.parameter import parameter_value_to_python
        client = self._parameters()
        if not client.wait_for_services(timeout_sec=timeout_s):
            raise ClientError(f"no parameter services on {self.target}")
        future = client.get_parameters(list(names))
        if not self.spin_until(future.done, timeout_s):
            raise ClientError(f"{self.target}: get_parameters timed out")
        return {n: parameter_value_to_python(v) for n, v in zip(names, future.result().values)}

    def set_parameters(self, values, timeout_s=5.0):
        """Set the node's parameters (name -> value); a list of (successful, reason)."""
        from rclpy.parameter import Parameter
        client = self._parameters()
        if not client.wait_for_services(timeout_sec=timeout_s):
            raise ClientError(f"no parameter services on {self.target}")
        future = client.set_parameters([Parameter(n, value=v) for n, v in values.items()])
        if not self.spin_until(future.done, timeout_s):
            raise ClientError(f"{self.target}: set_parameters timed out")
        return [(r.successful, r.reason) for r in future.result().results]

    def get_scene(self, timeout_s=5.0):
        """The node's current cdh_planner_interfaces/Scene (``~/get_scene``)."""
        from cdh_planner_interfaces.srv import GetScene
        if self._scene_client is None:
            self._scene_client = self.node.create_client(GetScene, self.topic(GET_SCENE),
                                                         qos_profile=SERVICE_QOS)
        if not self._scene_client.wait_for_service(timeout_sec=timeout_s):
            raise ClientError(f"no service {self._scene_client.srv_name}")
        return self.call(self._scene_client, GetScene.Request(), timeout_s).scene

    def update_scene(self, array, timeout_s=5.0):
        """Publish an ObstacleArray on the node's ``~/obstacles`` and wait until the node's
        scene version has changed: the new Scene. ClientError if it has not (nothing
        taken: the node's log names the refused items)."""
        from cdh_planner_interfaces.msg import ObstacleArray
        before = self.get_scene(timeout_s).version
        if self._obstacles is None:
            self._obstacles = self.node.create_publisher(ObstacleArray, self.topic(OBSTACLES),
                                                         OBSTACLES_QOS)
        if not self.spin_until(lambda: self._obstacles.get_subscription_count() > 0, timeout_s):
            raise ClientError(f"no subscriber on {self.topic(OBSTACLES)}")
        self._obstacles.publish(array)
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            scene = self.get_scene(timeout_s)
            if scene.version != before:
                return scene
            self.spin(0.05)
        raise ClientError(f"{self.topic(OBSTACLES)}: the scene did not change within "
                          f"{timeout_s:g} s (refused items are named in the node's log)")

    def execute(self, timeout_s=10.0):
        """Call ``~/execute``: (success, message)."""
        r = self.call(self.execute_client, Trigger.Request(), timeout_s)
        return r.success, r.message

    def stop(self, timeout_s=10.0):
        """Call ``~/stop``: (success, message)."""
        r = self.call(self.stop_client, Trigger.Request(), timeout_s)
        return r.success, r.message

    def watch_execution(self):
        """Subscribe (once) to ``~/cable_command``, ``~/planned_cable_trajectory``,
        ``~/tension_envelope`` and ``~/execution_result``: from now on ``commands``,
        ``trajectories``, ``envelopes`` and ``execution_results`` keep every message
        received. Call it early to miss none of the first commands."""
        if self.commands is not None:
            return
        self.commands, self.trajectories, self.envelopes = [], [], []
        self.execution_results = []
        subscribe = self.node.create_subscription
        subscribe(M.WINCH_COMMAND_TYPE, self.topic(CABLE_COMMAND), self.commands.append,
                  COMMAND_DEPTH)
        subscribe(JointTrajectory, self.topic(PLANNED_TRAJECTORY), self.trajectories.append,
                  LATCHED)
        subscribe(TensionEnvelope, self.topic(TENSION_ENVELOPE), self.envelopes.append,
                  LATCHED)
        subscribe(DiagnosticStatus, self.topic(EXECUTION_RESULT), self.execution_results.append,
                  LATCHED)

    def wait_execution_result(self, after=0, timeout_s=10.0):
        """The first ``~/execution_result`` (DiagnosticStatus) beyond the first ``after``
        received since ``watch_execution``, or None within ``timeout_s``."""
        self.watch_execution()
        self.spin_until(lambda: len(self.execution_results) > after, timeout_s)
        return self.execution_results[after] if len(self.execution_results) > after else None

    def execute_and_follow(self, answer, margin_s=FOLLOW_MARGIN_S):
        """Call ``~/execute`` for the plan ``answer`` (a PlanAnswer) and follow it (the
        streamed ``~/cable_command``, if any) until ``~/execution_result`` says it ended, or
        the path's duration + ``margin_s`` has passed; Ctrl-C calls ``~/stop``. An
        Execution."""
        self.watch_execution()
        n = len(answer.path.poses)
        self.spin_until(lambda: self.trajectories and len(self.trajectories[-1].points) == n
                        and self.envelopes and len(self.envelopes[-1].points) == n  # this plan's
                        and self.node.count_publishers(self.topic(CABLE_COMMAND)) > 0
                        and self.node.count_publishers(self.topic(EXECUTION_RESULT)) > 0,
                        LATCHED_WAIT_S)
        if not self._results_settled:   # once: the latched last execution result arrives,
            self.spin(DISCOVERY_SETTLE_S)  # and is not taken for this execution's end
            self._results_settled = True
        run = Execution()
        if self.trajectories and len(self.trajectories[-1].points) == n:
            run.trajectory = self.trajectories[-1]
            run.envelope = (self.envelopes[-1] if self.envelopes
                            and len(self.envelopes[-1].points) == n else None)
            run.goal = np.asarray(run.trajectory.points[-1].positions, dtype=float)
        first, ends = len(self.commands), len(self.execution_results)
        run.called_at = time.monotonic()
        run.accepted, run.message = self.execute()

        def streamed_to_the_goal():
            if len(self.commands) == first:
                return True    # not streamed (follow_joint_trajectory): the controller's word
            _, positions, velocities = M.winch_command_values(self.commands[-1])
            return not np.any(velocities) and np.allclose(positions, run.goal, rtol=0,
                                                          atol=ARRIVAL_TOL_M)

        def ended():
            return len(self.execution_results) > ends

        if run.accepted:
            try:
                self.spin_until(ended, path_duration(answer.path) + margin_s)
            except KeyboardInterrupt:
                run.stopped = self.stop()[1]
                self.spin_until(ended, LATCHED_WAIT_S)
            run.end = self.execution_results[ends] if len(self.execution_results) > ends \
                else None
            # the result and the stream are two topics: its last commands may come after
            run.arrived = (run.outcome == "completed" and run.goal is not None
                           and self.spin_until(streamed_to_the_goal, LATCHED_WAIT_S))
        run.commands = self.commands[first:]
        return run


def path_length(path_msg):
    """Length (m) of the platform positions of a nav_msgs/Path."""
    p, _ = M.path_arrays(path_msg)
    return float(np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1)))


def path_duration(path_msg):
    """Duration (s) of a nav_msgs/Path from its pose stamps (the node stamps pose k at
    header.stamp + t_k)."""
    if not path_msg.poses:
        return 0.0
    return (M.time_ns(path_msg.poses[-1].header.stamp)
            - M.time_ns(path_msg.header.stamp)) / M.NS_PER_S
