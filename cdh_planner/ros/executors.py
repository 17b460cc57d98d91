"""rclpy's MultiThreadedExecutor, surviving an entity destroyed while it gathers a wait set.

rclpy (the Jazzy wheel's 7.1.6, and upstream still) gathers a node's waitables (the event
handlers of every publisher and subscription, action clients and servers), then enters
each: one destroyed in between, as a lifecycle cleanup on another thread destroys the
joint-state subscription and the outlets' publishers, is left out of the count but added
all the same, and the InvalidHandle raised there ends ``spin()``: the node stops answering
(ros2/rclpy#1284, #1385). Gathering again leaves the destroyed entity out. An action client
fails there with an RCLError instead, which is what a loaded test run met (a get_state
never answered after cleanup): ``actions.RaceFreeActionClient`` keeps itself out of the
wait set.
"""

from rclpy.exceptions import InvalidHandle
from rclpy.executors import MultiThreadedExecutor

REGATHERS = 100  # an entity invalid in every gather is a bug: raised after this many


class NodeExecutor(MultiThreadedExecutor):
    """``MultiThreadedExecutor`` (same constructor) whose wait for ready callbacks gathers
    its wait set again when an entity in it was destroyed meanwhile."""

    def wait_for_ready_callbacks(self, *args, **kwargs):
        for attempt in range(REGATHERS):
            try:
                return super().wait_for_ready_callbacks(*args, **kwargs)
            except InvalidHandle:
                if attempt == REGATHERS - 1:
                    raise
