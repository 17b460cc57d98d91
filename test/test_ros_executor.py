"""The node's executor survives a subscription destroyed while it gathers a wait set
(cdh_planner/ros/executors.py; ros2/rclpy#1284): provoked, not waited for, by destroying it
right after the executor gathered its event handlers and before it entered them, the
moment a lifecycle cleanup on another thread can hit."""

import pytest

rclpy = pytest.importorskip("rclpy")

from rclpy.exceptions import InvalidHandle  # noqa: E402
from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from cdh_planner.ros.executors import NodeExecutor  # noqa: E402
from ros_harness import spun_node  # noqa: E402

LIMIT_S = 60.0  # a bound for a hang, not a timing


def _destroying(base):
    class Destroying(base):
        """Destroys ``victim`` (a subscription) once its first event handler is gathered."""
        victim = None

        def can_execute(self, entity):
            victim = self.victim
            if victim is not None and entity in victim.event_handlers:
                self.victim = None
                victim.node.destroy_subscription(victim)
            return super().can_execute(entity)
    return Destroying


@pytest.mark.parametrize("base", [MultiThreadedExecutor, NodeExecutor])
def test_a_subscription_destroyed_while_the_wait_set_is_gathered(base):
    """rclpy's executor stops on InvalidHandle; the node's gathers again and goes on (a
    timer still fires)."""
    with spun_node("destroyed_subscription", _destroying(base), num_threads=2) as (
            node, executor, ticked):
        victim = node.create_subscription(String, "joint_states_like", lambda _: None, 10)
        victim.node = node
        assert victim.event_handlers, "rclpy makes a subscription's event handlers"
        executor.victim = victim
        if base is MultiThreadedExecutor:
            with pytest.raises(InvalidHandle):
                executor.spin_once(timeout_sec=LIMIT_S)
        else:
            while not ticked.is_set():
                executor.spin_once(timeout_sec=LIMIT_S)
            assert executor.victim is None  # destroyed mid-gather
