"""The node's scene over ROS: ``~/obstacles`` (cdh_planner_interfaces/ObstacleArray: ADD /
REMOVE by id, in the base frame), ``~/get_scene`` (GetScene: the current Scene and its
version) and the latched ``~/scene`` (Scene) and ``~/scene_markers`` (MarkerArray: the
obstacles, ns ``obstacles``), both published after each change. The logic is in
``scene_state.SceneState`` (no rclpy).

Each ObstacleArray received is recorded as it arrived (on ``~/obstacles``), then applied;
the Scene that results is recorded as published. A refused item is named in one warning
line and the node goes on. Updates are taken while the node is configured (inactive too,
as parameters are); a plan uses the scene as of its arrival (``current``).

The arrays are a queue of their own, not an executor's callback: the executor never takes
them (``Drained``); ``drain()`` takes every array waiting and applies them in arrival order,
one thread at a time. The plan running calls it between its planning steps (a search
holds the interpreter: an executor thread would take the arrays too late, and DDS would
drop what its reader queue cannot hold), a timer calls it otherwise. ``~/get_scene`` has
a callback group of its own: it never waits behind updates. Counts (``counts``: received,
applied, refused, dropped: lost by the middleware or taken while unconfigured) go to
/diagnostics; a drop or a refusal is logged.
"""

import threading

from rclpy.callback_groups import CallbackGroup, MutuallyExclusiveCallbackGroup
from rclpy.event_handler import SubscriptionEventCallbacks
from visualization_msgs.msg import Marker, MarkerArray

from cdh_planner_interfaces.msg import ObstacleArray, Scene
from cdh_planner_interfaces.srv import GetScene

from ...errors import exception_line
from ..interface import GET_SCENE, LATCHED, OBSTACLES, OBSTACLES_QOS, SCENE, SCENE_MARKERS, \
    SERVICE_QOS
from ..msgs.markers import obstacle_markers
from ..msgs.scene_msgs import scene_msg
from ..core.scene_state import SceneState


DRAIN_PERIOD_S = 0.02   # s: the timer that drains the arrays while no plan does


class Drained(CallbackGroup):
    """A callback group the executor never runs (nor waits on): its subscription is taken
    by ``NodeScene.drain``."""

    def can_execute(self, entity):
        return False

    def beginning_execution(self, entity):
        return False

    def ending_execution(self, entity):
        pass


class NodeScene:

    def __init__(self, node):
        self._node = node
        self.state = SceneState()
        self._draining = threading.Lock()   # one drain at a time: arrival order kept
        self._applying = threading.Lock()   # one array applied and published: ~/get_scene
        # answers a version once its ~/scene and ~/scene_markers are out
        self._counts_lock = threading.Lock()
        self._counts = dict.fromkeys(("received", "applied", "refused", "dropped"), 0)
        self.pub_scene = node.create_publisher(Scene, f"~/{SCENE}", LATCHED)
        self.pub_markers = node.create_publisher(MarkerArray, f"~/{SCENE_MARKERS}", LATCHED)
        self.subscription = node.create_subscription(
            ObstacleArray, f"~/{OBSTACLES}", self.received, OBSTACLES_QOS,
            callback_group=Drained(),
            event_callbacks=SubscriptionEventCallbacks(message_lost=self._lost))
        self.timer = node.create_timer(DRAIN_PERIOD_S, self.drain,
                                       callback_group=MutuallyExclusiveCallbackGroup())
        self.service = node.create_service(GetScene, f"~/{GET_SCENE}", self.get_scene,
                                           qos_profile=SERVICE_QOS,
                                           callback_group=MutuallyExclusiveCallbackGroup())

    def drain(self):
        """Take every array waiting and apply each (``received``), in arrival order; a call
        while another thread drains returns at once (that one takes them)."""
        if not self._draining.acquire(blocking=False):
            return
        try:
            sub = self.subscription
            while True:
                with sub.handle:
                    taken = sub.handle.take_message(sub.msg_type, sub.raw)
                if taken is None:
                    return
                self.received(taken[0])
        finally:
            self._draining.release()

    def counts(self):
        """{received, applied, refused, dropped}: ObstacleArrays so far."""
        with self._counts_lock:
            return dict(self._counts)

    def _count(self, **more):
        with self._counts_lock:
            for k, v in more.items():
                self._counts[k] += v

    def _lost(self, info):
        """The middleware lost arrays (its reader queue was full): counted and logged."""
        self._count(dropped=info.total_count_change)
        self._node.get_logger().error(
            f"~/{OBSTACLES}: {info.total_count_change} obstacle update(s) lost before the "
            f"node took them ({info.total_count} in all)")

    def current(self):
        """The SceneVersion a plan arriving now is made under."""
        return self.state.current()

    def effective(self, config):
        return self.state.effective(config)

    def configure(self, config):
        """The scene of ``config`` (after a parameter change); published if it is new."""
        before = self.state.current()
        now = self.state.configure(config)
        if now is not before:
            self._publish(now)

    def received(self, msg):
        node = self._node
        self._count(received=1)
        if not node.configured:
            self._count(dropped=1)
            node.get_logger().warning(f"~/{OBSTACLES} ignored: the node is not configured")
            return
        config = node.config
        node.record(node.runlog.write, self.subscription.topic_name, msg, node.record.now())
        with self._applying:
            try:
                update = self.state.update(msg, config.base_frame, config.robot)
            except Exception as exc:  # noqa: BLE001 - never take the node down
                self._count(refused=1)
                node.get_logger().error(f"~/{OBSTACLES} failed: {exception_line(exc)}")
                return
            if update.taken:
                self._publish(self.state.current())
        self._count(applied=int(bool(update.taken)), refused=int(bool(update.refused)))
        if update.refused:   # rclpy: one severity per call site
            node.get_logger().warning(f"~/{OBSTACLES}: {update.line()}")
        else:
            node.get_logger().info(f"~/{OBSTACLES}: {update.line()}")

    def get_scene(self, request, response):
        config = self._node.config if self._node.configured else None
        with self._applying:
            now = self.state.current()
        response.scene = scene_msg(now.version, now.scene, config.base_frame if config else "",
                                   self._node.get_clock().now().to_msg())
        return response

    def _publish(self, now):
        """The latched ~/scene and ~/scene_markers of ``now`` (recorded as published)."""
        node = self._node
        frame, stamp = node.config.base_frame, node.get_clock().now().to_msg()
        try:
            node.record.publish(self.pub_scene, scene_msg(now.version, now.scene, frame, stamp),
                                latched=True, snapshot=True)   # every run file begins with it
            markers = MarkerArray(markers=[Marker(action=Marker.DELETEALL, ns="obstacles")])
            if now.scene is not None:
                markers.markers += obstacle_markers(now.scene, frame, stamp)
            node.record.publish(self.pub_markers, markers, latched=True)
        except Exception as exc:  # noqa: BLE001 - a display: the scene itself is in force
            node.get_logger().error(f"publishing the scene failed: {exception_line(exc)}")
