"""The node's frames on TF (``core/frames.py`` for the conventions) and the robot's live state:
the static transform fixed frame (z-up) -> base frame (the paper's, z-down) on /tf_static
and the URDF on ``robot_description`` (``description.py``), both latched; for each new
measured JointState (stamped with it), the platform's pose from forward kinematics,
base frame -> platform frame, on /tf and ``~/platform_pose``, and ``core/live_state.py``'s
``~/cable_state``, ``~/least_margin`` and ``~/live_markers``; and a
``frames.TransformBook`` of /tf and /tf_static through which goals in other frames are
expressed in the base frame.

/tf and /tf_static carry tf2_msgs/TFMessage: the real package where ROS is installed, a
partial copy with the same type hash in the venv (interfaces/tf2_msgs).
"""

import traceback

from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, String
from visualization_msgs.msg import MarkerArray
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

from ...errors import InputError, exception_line
from ..msgs import messages as M
from ..core import plan_requests
from ..core.description import urdf
from ..core.frames import Z_DOWN, TransformBook, pose_in_frame, transform_msg
from ..interface import LATCHED
from ..core.live_state import CABLE_STATE, LEAST_MARGIN, LIVE_MARKERS, live_messages

TF_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE)         # tf2_ros's
TF_STATIC_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)   # tf2_ros's
PLATFORM_POSE, ROBOT_DESCRIPTION = "platform_pose", "robot_description"
PERIOD_S = 0.02          # looks for a new joint state at 50 Hz (joint_state_broadcaster's)


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
        for topic, qos in (("/tf", TF_QOS), ("/tf_static", TF_STATIC_QOS)):
            node.create_subscription(TFMessage, topic, self._received, qos,
                                     callback_group=callback_group)
        self._seen = None        # the JointState last turned into a pose
        # one update at a time: in a reentrant group a slow forward kinematics (loaded
        # machine, Newton from seeds) started a new update every period on another executor
        # thread until none was left for plan goals, joint states and results
        self.timer = node.create_timer(PERIOD_S, self.update,
                                       callback_group=MutuallyExclusiveCallbackGroup())

    def _received(self, msg):
        for transform in msg.transforms:
            self.book.add(transform)

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

    def to_base(self, request, fields, base_frame):
        """Replace each PoseStamped ``request.<field>`` by the same pose in ``base_frame``;
        None, or the refusal (BAD_FRAME, naming the field and frame) of the first one TF
        cannot resolve."""
        try:
            for field in fields:
                setattr(request, field,
                        pose_in_frame(self.book, getattr(request, field), base_frame, field))
        except InputError as exc:
            return plan_requests.input_refusal(exc)
        return None

    def update(self):
        """Each new measured JointState: the platform's pose on /tf and ~/platform_pose."""
        node = self._node
        if not node.configured:
            return
        latest = node.execution.joints.latest
        if latest is None or latest[0] is self._seen:
            return
        self._seen = msg = latest[0]
        config = node.config
        lengths, _ = node.execution.joints.lengths(
            config.values["execution.joint_states_max_age_s"])
        if lengths is None:
            return
        try:
            p, R = node.execution.forward_kinematics(config.robot, lengths,
                                                     tensions=node.execution.joints.tensions)
        except InputError:
            return              # no pose for these lengths: nothing to show
        except Exception as exc:  # noqa: BLE001 - never take the node down
            node.get_logger().error(f"platform pose failed: {exception_line(exc)}\n"
                                    f"{traceback.format_exc()}")
            return
        stamp = msg.header.stamp if (msg.header.stamp.sec or msg.header.stamp.nanosec) \
            else node.get_clock().now().to_msg()
        self.publish_pose(M.pose_stamped_msg(p, R, config.base_frame, stamp),
                          config.values["platform_frame"])
        state, margin, markers = live_messages(config.robot, lengths, p, R, msg,
                                               config.base_frame, stamp)
        if state.effort:    # measured tensions (load cells): the run file records them
            node.record.publish(self.pub_cables, state)
        else:
            self.pub_cables.publish(state)
        self.pub_margin.publish(margin)
        self.pub_markers.publish(markers)

    def publish_pose(self, pose, platform_frame):
        o, q = pose.pose.position, pose.pose.orientation
        transform = transform_msg(pose.header.frame_id, platform_frame,
                                  ([q.x, q.y, q.z, q.w], [o.x, o.y, o.z]), pose.header.stamp)
        self.pub_tf.publish(TFMessage(transforms=[transform]))
        self.pub_pose.publish(pose)
