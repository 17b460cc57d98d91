"""Adapters between the node and the plan service: ``NodePlanOutlet``, the plan service's
``PlanOutlet`` (core/plan_service.py) on ROS (record, then publish; log; the last plan's
status kept for ``/diagnostics``), and ``GoalCancel``, a PlanPath goal's cancel as the
planner's ``is_set``."""

import time


class GoalCancel:
    """``is_set``: a cancel of this PlanPath goal was requested."""

    def __init__(self, goal_handle):
        self.goal_handle = goal_handle

    def is_set(self):
        return self.goal_handle.is_cancel_requested


class NodePlanOutlet:
    """``node``: the PlannerNode (its publishers, its recording, its logger)."""

    def __init__(self, node):
        self._node = node
        self.last_result = None   # (DiagnosticStatus of the last plan, time.monotonic() s)

    def publish_outputs(self, out):
        n = self._node
        for publisher, msg in ((n.pub_path, out.path), (n.pub_trajectory, out.cable_trajectory),
                               (n.pub_envelope, out.tension_envelope),
                               (n.pub_markers, out.markers)):
            n.record.publish(publisher, msg, latched=True)

    def publish_result(self, status):
        self.last_result = (status, time.monotonic())
        self._node.record.publish(self._node.pub_result, status, latched=True)

    def publish_progress(self, status):
        self._node.record.publish(self._node.pub_progress, status)

    def stamp(self):
        return self._node.get_clock().now().to_msg()

    def error(self, text):
        self._node.get_logger().error(text)

    def answered(self, ok, line):
        if ok:
            self._node.get_logger().info(line)
        else:
            self._node.get_logger().warning(line)


def run_stem(path):
    """The run file's name without folder and ``.mcap``."""
    name = path.rsplit("/", 1)[-1]
    return name[:-5] if name.endswith(".mcap") else name
