"""The node's frames on TF (``core/frames.py`` for the conventions) and the robot's live state:
the static transform fixed frame (z-up) -> base frame (the paper's, z-down) on /tf_static
and the URDF on ``robot_description`` (``description.py``), both latched; from the newest
measured JointState (stamped with it), the platform's pose from forward kinematics,
base frame -> platform frame, on /tf and ``~/platform_pose``, and ``core/live_state.py``'s
``~/cable_state``, ``~/least_margin`` and ``~/live_markers``; and a
``frames.TransformBook`` of /tf and /tf_static through which goals in other frames are
expressed in the base frame.

The live state is a thread of its own, not an executor callback: every 1 /
``live_state_rate_hz`` s it takes the newest joint state (``polled.PolledSubscription``: none
are handled in between) and, only when there is a new one, computes and publishes it
(markers at ``live_markers_rate_hz``). So joint states at 50 - 1000 Hz cost the executor
nothing, and the planner's thread the GIL for a few ms per look. /tf is read the same way
(``polled.py``), when a request needs a frame and at each look.

/tf and /tf_static carry tf2_msgs/TFMessage: the real package where ROS is installed, a
partial copy with the same type hash in the venv (interfaces/tf2_msgs).
"""

import threading
import time
import traceback

from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, String
from visualization_msgs.msg import MarkerArray
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

from ...errors import InputError, exception_line
from ..msgs import messages as M
from ..core import plan_requests
from ..core.description import urdf
from ..core.frames import Z_DOWN, TransformBook, pose_in_frame, transform_msg
from ..interface import LATCHED
from ..core.live_state import CABLE_STATE, LEAST_MARGIN, LIVE_MARKERS, LiveRates, live_markers, \
    live_messages
from ..polled import PolledSubscription

TF_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE)         # tf2_ros's
TF_STATIC_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)   # tf2_ros's
PLATFORM_POSE, ROBOT_DESCRIPTION = "platform_pose", "robot_description"
JOIN_S = 5.0     # s: how long closing waits for the live state's thread to end its look


class NodeFrames:

    def __init__(self, node, callback_group=None):
        self._node = node
        self.book = TransformBook()
        self.pub_tf = node.create_publisher(TFMessage, "/tf", TF_QOS)
        self.pub_static = node.create_publisher(TFMessage, "/tf_static", TF_STATIC_QOS)
        pub = node.create_publisher
        self.pub_pose = pub(PoseStamped, f"~/{PLATFORM_POSE}", 10)
        self.pub_cables = pub(JointState, f"~/{CABLE_STATE}", 10)
        self.pub_margin = pub(Float64, f"~/{LEAST_MARGIN}", 10)
        self.pub_markers = pub(MarkerArray, f"~/{LIVE_MARKERS}", 10)
        # robot_state_publisher's name and QoS (relative: it follows the namespace)
        self.pub_description = pub(String, ROBOT_DESCRIPTION, LATCHED)
        # /tf taken when a request needs it and at each look of the live state, not a
        # callback per message: the node's own platform pose at live_state_rate_hz comes
        # back on it (the rare /tf_static ones are callbacks)
        self.tf = PolledSubscription(node, TFMessage, "/tf", TF_QOS)
        node.create_subscription(TFMessage, "/tf_static", self._received, TF_STATIC_QOS,
                                 callback_group=callback_group)
        self._seen = None        # the JointState last turned into a pose
        self.rates = None        # LiveRates of the configured parameters
        # one update at a time, never on an executor thread: a slow forward kinematics
        # (loaded machine, Newton from seeds) cannot take the threads of plan goals and results
        self.worker = None
        self._stop = threading.Event()

    def _received(self, msg):
        for transform in msg.transforms:
            self.book.add(transform)

    def read_tf(self):
        """Every /tf message that came since the last read into the book."""
        for msg, _ in self.tf.take():
            self._received(msg)

    def configure(self, config):
        """Publish (latched) the static frames of ``config`` (fixed -> base, z-down) and the
        robot description."""
        values = config.values
        self.pub_description.publish(String(data=urdf(
            config.robot, values["fixed_frame"], config.base_frame, values["platform_frame"])))
        static = [transform_msg(values["fixed_frame"], config.base_frame, Z_DOWN,
                                self._node.get_clock().now().to_msg())]
        for transform in static:
            self.book.add(transform)
        self.pub_static.publish(TFMessage(transforms=static))
        self.rates = LiveRates(values["live_state_rate_hz"], values["live_markers_rate_hz"])
        if self.worker is None:
            self._stop.clear()
            self.worker = threading.Thread(target=self._live, name="cdh_planner live state",
                                           daemon=True)
            self.worker.start()

    def close(self):
        """End the live state's thread (after its current look); configure starts it again."""
        worker, self.worker = self.worker, None
        if worker is not None:
            self._stop.set()
            worker.join(JOIN_S)

    def destroy(self):
        """``close``, and the /tf subscription (the node is being destroyed)."""
        self.close()
        self.tf.destroy()

    def _live(self):
        while not self._stop.wait(self.rates.period_s):
            try:
                self.update()
            except Exception as exc:  # noqa: BLE001 - never take the node down
                if not self._node.context.ok():
                    return              # shut down under the look
                self._node.get_logger().error(f"live state failed: {exception_line(exc)}\n"
                                              f"{traceback.format_exc()}")

    def to_base(self, request, fields, base_frame):
        """Replace each PoseStamped ``request.<field>`` by the same pose in ``base_frame``;
        None, or the refusal (BAD_FRAME, naming the field and frame) of the first one TF
        cannot resolve."""
        self.read_tf()
        try:
            for field in fields:
                setattr(request, field,
                        pose_in_frame(self.book, getattr(request, field), base_frame, field))
        except InputError as exc:
            return plan_requests.input_refusal(exc)
        return None

    def update(self):
        """The newest measured JointState, when new: the platform's pose on /tf and
        ~/platform_pose, the live state, the markers when due. Nothing when none is new."""
        node = self._node
        if not node.configured:
            return
        self.read_tf()     # kept short: the middleware keeps the last 100 messages
        latest = node.execution.joints.latest
        if latest is None or latest[0] is self._seen:
            return
        self._seen = msg = latest[0]
        config = node.config
        lengths, tensions, _ = node.execution.joints.measured(
            config.values["execution.joint_states_max_age_s"])
        if lengths is None:
            return
        try:
            p, R = node.execution.forward_kinematics(config.robot, lengths, tensions=tensions)
        except InputError:
            return              # no pose for these lengths: nothing to show
        stamp = msg.header.stamp if (msg.header.stamp.sec or msg.header.stamp.nanosec) \
            else node.get_clock().now().to_msg()
        self.publish_pose(M.pose_stamped_msg(p, R, config.base_frame, stamp),
                          config.values["platform_frame"])
        state, margin, per_cable = live_messages(config.robot, lengths, p, R, msg,
                                                 config.base_frame, stamp)
        if state.effort:    # measured tensions (load cells): the run file records them
            node.record.publish(self.pub_cables, state)
        else:
            self.pub_cables.publish(state)
        self.pub_margin.publish(margin)
        if self.rates.markers_due(time.monotonic()):
            self.pub_markers.publish(live_markers(config.robot, p, R, per_cable,
                                                  config.base_frame, stamp))

    def publish_pose(self, pose, platform_frame):
        o, q = pose.pose.position, pose.pose.orientation
        transform = transform_msg(pose.header.frame_id, platform_frame,
                                  ([q.x, q.y, q.z, q.w], [o.x, o.y, o.z]), pose.header.stamp)
        self.pub_tf.publish(TFMessage(transforms=[transform]))
        self.pub_pose.publish(pose)
