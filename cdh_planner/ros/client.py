"""The task sequencer's side: call a running ``cdh_planner`` node (used by ``cdh-planner
call``, ``replay --requests``, the demo and the tests).

    with PlannerClient("/cdh_planner", args=ros_args) as client:
        client.wait_for_node(timeout_s=10)
        answer = client.plan(start_msg, goal_msg, timeout_s=60)   # PlanAnswer
        client.execute(); client.stop()

Spins its own node with ``spin_once`` (not ``spin_until_future_complete``, which slows down
call after call in rclpy 7.1 as installed from PyPI). Its subscription to ``~/plan_result`` is
volatile, so only answers published after it joined arrive; an answer is paired with its
result by the ``path_stamp`` key (= the response path's header stamp).
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
from std_srvs.srv import Trigger

from ..errors import InputError
from . import messages as M

DEFAULT_NODE = "/cdh_planner"
RESULT_WAIT_S = 2.0  # after the response, how long to wait for its ~/plan_result
# After the services are seen, s of spinning before the first call: the node must also have
# discovered this client's reply reader, or a fast answer (a direct motion, 30 ms) is dropped
# by the middleware ("failed to send response (timeout)").
DISCOVERY_SETTLE_S = 0.3


@dataclass
class PlanAnswer:
    """A plan call's answer: the response path and the ``~/plan_result`` key/values (strings;
    empty if the result did not arrive within RESULT_WAIT_S)."""

    path: object                      # nav_msgs/Path
    status: Optional[object] = None   # diagnostic_msgs/DiagnosticStatus
    values: dict = field(default_factory=dict)
    seconds: float = 0.0              # round trip (s)

    @property
    def success(self):
        return len(self.path.poses) > 0

    def number(self, key, default=math.nan):
        try:
            return float(self.values[key])
        except (KeyError, ValueError):
            return default


class ClientError(RuntimeError):
    """The node did not answer (not running, wrong name, timeout)."""


def pose_stamped(values, frame_id, field="pose"):
    """PoseStamped of "x y z qx qy qz qw" (a string or 7 numbers; m, quaternion x y z w);
    InputError naming ``field`` if malformed (finite / normalised are checked by the node)."""
    if isinstance(values, str):
        parts = values.replace(",", " ").split()
        try:
            values = [float(v) for v in parts]
        except ValueError:
            raise InputError(field, " ".join(parts), "expected 7 numbers: x y z qx qy qz qw "
                                                     "(m, quaternion)") from None
    values = list(values)
    if len(values) != 7:
        raise InputError(field, values, "expected 7 numbers: x y z qx qy qz qw (m, quaternion)")
    msg = PoseStamped()
    msg.header.frame_id = frame_id
    p, o = msg.pose.position, msg.pose.orientation
    p.x, p.y, p.z, o.x, o.y, o.z, o.w = (float(v) for v in values)
    return msg


class PlannerClient:
    """A small rclpy node talking to one planner node (``node_name``, absolute)."""

    def __init__(self, node_name=DEFAULT_NODE, args=None, name="cdh_planner_client",
                 context=None, domain_id=None):
        self.target = "/" + node_name.strip("/")
        self._own_context = context is None
        self.context = context if context is not None else rclpy.Context()
        if self._own_context:
            rclpy.init(args=args, context=self.context, domain_id=domain_id)
        self.node = Node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.plan_client = self.node.create_client(GetPlan, f"{self.target}/plan")
        self.execute_client = self.node.create_client(Trigger, f"{self.target}/execute")
        self.stop_client = self.node.create_client(Trigger, f"{self.target}/stop")
        self.results = []
        self.node.create_subscription(
            DiagnosticStatus, f"{self.target}/plan_result", self.results.append,
            QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))

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
        self.spin_until(lambda: self.node.count_publishers(f"{self.target}/plan_result") > 0,
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
        answer = PlanAnswer(path=response.plan, seconds=time.monotonic() - t0)
        stamp = str(M.time_ns(response.plan.header.stamp))

        def find():
            for msg in reversed(self.results):
                values = M.status_values(msg)
                if values.get("path_stamp") == stamp:
                    answer.status, answer.values = msg, values
                    return True
            return False

        self.spin_until(find, RESULT_WAIT_S)
        return answer

    def _parameters(self):
        if getattr(self, "_param_client", None) is None:
            from rclpy.parameter_client import AsyncParameterClient
            self._param_client = AsyncParameterClient(self.node, self.target)
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

    def execute(self, timeout_s=10.0):
        """Call ``~/execute``: (success, message)."""
        r = self.call(self.execute_client, Trigger.Request(), timeout_s)
        return r.success, r.message

    def stop(self, timeout_s=10.0):
        """Call ``~/stop``: (success, message)."""
        r = self.call(self.stop_client, Trigger.Request(), timeout_s)
        return r.success, r.message


def path_length(path_msg):
    """Length (m) of the platform positions of a nav_msgs/Path."""
    p = np.array([[q.pose.position.x, q.pose.position.y, q.pose.position.z]
                  for q in path_msg.poses]).reshape(-1, 3)
    return float(np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1)))


def path_duration(path_msg):
    """Duration (s) of a nav_msgs/Path from its pose stamps (the node stamps pose k at
    header.stamp + t_k)."""
    if not path_msg.poses:
        return 0.0
    return (M.time_ns(path_msg.poses[-1].header.stamp)
            - M.time_ns(path_msg.header.stamp)) / M.NS_PER_S
