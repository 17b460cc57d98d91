"""An rclpy ActionClient whose futures always complete.

rclpy 7.1.6 (the Jazzy wheel) sends a goal, cancel or result request and only then files
the future under the request's sequence number. A response that an executor thread takes
in between finds no future, is dropped ("Ignoring unexpected ... response") and the future
never completes: a result lost this way left an execution "stopping" for good on a loaded
machine. The bug and the upstream fix (one lock over sending and filing, and over taking
responses) are ros2/rclpy#1123 and #1308, backported in #1519 after this wheel; this class
applies the same lock. Use it wherever an ActionClient would be made.

It also survives being destroyed while an executor gathers its wait set (a node's cleanup
releasing its controller client): rclpy's executors skip a waitable whose handle is
already invalid when they count the wait set's entities, then add it all the same, and
"Failed to add 'rcl_action_client_t' to wait set: action client pointer is invalid" stops
the executor (ros2/rclpy#1284, #1385; still so upstream). Here a destroyed client adds
nothing and is never ready.
"""

import threading

from rclpy.action import ActionClient
from rclpy.exceptions import InvalidHandle


class RaceFreeActionClient(ActionClient):
    """``rclpy.action.ActionClient`` with sending-and-filing of a request atomic with
    respect to taking responses (same constructor and methods)."""

    def __init__(self, *args, **kwargs):
        self._filing = threading.RLock()
        super().__init__(*args, **kwargs)

    def take_data(self):
        with self._filing:   # a response is taken only once its future is filed
            return super().take_data()

    def send_goal_async(self, *args, **kwargs):
        with self._filing:
            return super().send_goal_async(*args, **kwargs)

    def _cancel_goal_async(self, goal_handle):
        with self._filing:
            return super()._cancel_goal_async(goal_handle)

    def _get_result_async(self, goal_handle):
        with self._filing:
            return super()._get_result_async(goal_handle)

    def add_to_wait_set(self, wait_set):
        if not self._destroyed():
            super().add_to_wait_set(wait_set)

    def is_ready(self, wait_set):
        return not self._destroyed() and super().is_ready(wait_set)

    def _destroyed(self):
        """Whether the handle is destroyed or its destruction asked for (it is then in no
        wait set of ours: what an executor gathered before goes unused)."""
        try:
            with self._client_handle:
                return False
        except InvalidHandle:
            return True
