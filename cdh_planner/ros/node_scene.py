"""The node's scene over ROS: ``~/obstacles`` (cdh_planner_interfaces/ObstacleArray: ADD /
REMOVE by id, in the base frame), ``~/get_scene`` (GetScene: the current Scene and its
version) and the latched ``~/scene`` (Scene) and ``~/scene_markers`` (MarkerArray: the
obstacles, ns ``obstacles``), both published after each change. The logic is in
``scene_state.SceneState`` (no rclpy).

Each ObstacleArray received is recorded as it arrived (on ``~/obstacles``), then applied;
the Scene that results is recorded as published. A refused item is named in one warning
line and the node goes on. Updates are taken while the node is configured (inactive too,
as parameters are); a plan uses the scene as of its arrival (``current``).
"""

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from visualization_msgs.msg import Marker, MarkerArray

from cdh_planner_interfaces.msg import ObstacleArray, Scene
from cdh_planner_interfaces.srv import GetScene

from ..errors import exception_line
from .interface import GET_SCENE, LATCHED, OBSTACLES, OBSTACLES_DEPTH, SCENE, SCENE_MARKERS, \
    SERVICE_QOS
from .markers import obstacle_markers
from .scene_msgs import scene_msg
from .scene_state import SceneState


class NodeScene:

    def __init__(self, node):
        self._node = node
        self.state = SceneState()
        group = MutuallyExclusiveCallbackGroup()   # updates one at a time, in arrival order
        self.pub_scene = node.create_publisher(Scene, f"~/{SCENE}", LATCHED)
        self.pub_markers = node.create_publisher(MarkerArray, f"~/{SCENE_MARKERS}", LATCHED)
        self.subscription = node.create_subscription(
            ObstacleArray, f"~/{OBSTACLES}", self.received, OBSTACLES_DEPTH,
            callback_group=group)
        self.service = node.create_service(GetScene, f"~/{GET_SCENE}", self.get_scene,
                                           qos_profile=SERVICE_QOS, callback_group=group)

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
        if not node.configured:
            node.get_logger().warning(f"~/{OBSTACLES} ignored: the node is not configured")
            return
        config = node.config
        node.record(node.runlog.write, self.subscription.topic_name, msg, node.record.now())
        try:
            update = self.state.update(msg, config.base_frame, config.robot)
        except Exception as exc:  # noqa: BLE001 - never take the node down
            node.get_logger().error(f"~/{OBSTACLES} failed: {exception_line(exc)}")
            return
        if update.refused:   # rclpy: one severity per call site
            node.get_logger().warning(f"~/{OBSTACLES}: {update.line()}")
        else:
            node.get_logger().info(f"~/{OBSTACLES}: {update.line()}")
        if update.taken:
            self._publish(self.state.current())

    def get_scene(self, request, response):
        config = self._node.config if self._node.configured else None
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
