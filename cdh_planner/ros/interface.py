"""The node's ROS interface as constants: names (relative to the node), QoS profiles, and
what every server and client of ours is built with. The node, its clients (``client.py``,
``cdh-planner call``, replay, the demo) and the tests import these; nothing here starts ROS.

Queues: rclpy's default for services and actions keeps 10 requests (and 10 replies on a
client's reader) and drops older ones silently, so a burst of goals lost some without an
answer. Every service, action server and client of ours is built with ``SERVICE_QOS`` or
``ACTION_QOS`` instead (test_ros_interfaces checks that none is left on the default).
"""

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

NODE_NAME = "cdh_planner"
PLAN, PLAN_PATH, EXECUTE, STOP = "plan", "plan_path", "execute", "stop"
PATH, PLANNED_TRAJECTORY = "path", "planned_cable_trajectory"
TENSION_ENVELOPE, MARKERS = "tension_envelope", "markers"
PLAN_RESULT, PLAN_PROGRESS, EXECUTION_RESULT = "plan_result", "plan_progress", "execution_result"
CABLE_COMMAND = "cable_command"
# the scene: obstacles in (ADD / REMOVE), the current scene out (service; latched topics)
OBSTACLES, GET_SCENE, SCENE, SCENE_MARKERS = "obstacles", "get_scene", "scene", "scene_markers"
OBSTACLES_DEPTH = 100   # ObstacleArray updates not yet taken (each is applied at once)
# ~/obstacles, both ends: reliable, every array kept until taken (KEEP_ALL: a reader that
# keeps the last N drops arrays in a burst of retransmissions); OBSTACLES_DEPTH bounds it
OBSTACLES_QOS = QoSProfile(depth=OBSTACLES_DEPTH, history=HistoryPolicy.KEEP_ALL,
                           reliability=ReliabilityPolicy.RELIABLE)

# latched outputs: for display and late joiners, never a command
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
# Requests (and replies) not yet taken by an executor: the node takes a plan request at
# once (busy beyond its own queue), so this only holds what arrives in one burst.
SERVICE_DEPTH = 1000
SERVICE_QOS = QoSProfile(depth=SERVICE_DEPTH, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
# keyword arguments of rclpy.action.ActionServer and ActionClient: the goal, cancel and
# result services with deep queues (feedback and status keep rclpy's defaults)
ACTION_QOS = dict(goal_service_qos_profile=SERVICE_QOS,
                  result_service_qos_profile=SERVICE_QOS,
                  cancel_service_qos_profile=SERVICE_QOS)
