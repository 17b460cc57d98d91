"""Subscriptions that no executor serves: the middleware keeps what arrives (up to the QoS
history depth) and the node takes it when it needs it (rclpy, no Node subclass).

    sub = PolledSubscription(node, JointState, "/joint_states", qos)   # depth 1: the newest
    for msg, arrived in sub.take(): ...      # what came since the last take, oldest first
    sub.destroy()

A callback per message through rclpy's executor costs milliseconds of Python and the GIL
(68 % of a core for joint states at 500 Hz, measured on a loaded 2-core machine, against
1.4 % taken 20 times a second), and the node's own /tf at the live state's rate came
back to it the same way. rclpy has no public call for a subscription without a callback:
this is the C subscription ``Node.create_subscription`` makes, not registered with the node
(so no executor waits on it).
"""

import threading
import time

from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.type_support import check_is_valid_msg_type


class PolledSubscription:
    """Messages of ``msg_type`` on ``topic`` (a name as ``create_subscription`` takes it,
    remapped the same way), kept by the middleware per ``qos`` until ``take``. Thread-safe."""

    def __init__(self, node, msg_type, topic, qos):
        check_is_valid_msg_type(msg_type)       # imports the type support
        self.msg_type = msg_type
        self._lock = threading.Lock()
        with node.handle:
            self._handle = _rclpy.Subscription(node.handle, msg_type, topic,
                                               qos.get_c_qos_profile())
        self.topic_name = self._handle.get_topic_name()

    def take(self):
        """[(message, when it was received: time.monotonic() s)] of every message kept
        since the last take, oldest first; [] when none came."""
        taken = []
        with self._lock, self._handle:
            while (message := self._handle.take_message(self.msg_type, False)) is not None:
                taken.append(message)
        now_mono, now_ns = time.monotonic(), time.time_ns()
        out = []
        for msg, info in taken:
            received_ns = info.get("received_timestamp", 0)   # system clock; 0: not given
            age_s = max(0.0, (now_ns - received_ns) * 1e-9) if received_ns else 0.0
            out.append((msg, now_mono - age_s))
        return out

    def destroy(self):
        with self._lock:
            self._handle.destroy_when_not_in_use()
