"""The node's ``/diagnostics`` publisher: a 1 Hz timer that gathers ``diagnostics.Health``
from the node (lifecycle state, plan service, execution, recording) in every lifecycle
state, so that an aggregator sees an unconfigured node too."""

import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

from ...accuracy import has_accuracy
from ..core.diagnostics import PERIOD_S, TOPIC, Health, diagnostic_array


class NodeDiagnostics:

    def __init__(self, node, callback_group=None):
        self._node = node
        self.publisher = node.create_publisher(DiagnosticArray, TOPIC, 10)
        self.timer = node.create_timer(PERIOD_S, self.publish, callback_group=callback_group)

    def publish(self):
        node = self._node
        config = node.config if node.configured else None
        msg = diagnostic_array(self.health(), f"{node.get_fully_qualified_name()}: planner",
                               config.robot.name if config is not None else "",
                               node.get_clock().now().to_msg())
        self.publisher.publish(msg)

    def health(self):
        """diagnostics.Health of the node now."""
        node = self._node
        state, now = node.lifecycle_state, time.monotonic()
        outlet = getattr(node, "outlet", None)   # made by the first configure
        last = outlet.last_result if outlet is not None else None
        plan = {} if not last else dict(     # kept through cleanup and shutdown
            last_plan=last[0].message, last_plan_ok=last[0].level == DiagnosticStatus.OK,
            last_plan_age_s=now - last[1])
        plan["obstacle_updates"] = node.scene.counts()
        if not node.configured:
            return Health(state=state, **plan)
        plans, execution = node.plans, node.execution
        activity = ("executing" if execution.running else
                    "planning" if plans.planning else "idle")
        latest = execution.joints.latest
        return Health(state=state, activity=activity, queued=plans.queued(), **plan,
                      recording=node.runlog.state,
                      joint_states_age_s=now - latest[1] if latest else None,
                      joint_states_max_age_s=node.config.values["execution.joint_states_max_age_s"],
                      forward_kinematics_residual_m=execution.forward_kinematics_residual_m,
                      accuracy=execution.pose_accuracy(node.config.robot),
                      accuracy_given=has_accuracy(node.config.robot))
