"""recording/cdr.py (rosbags' public typestore) encodes what rclpy decodes back to the same message,
with no byte beyond the message (rclpy's own serializer may pad, with uninitialised bytes:
rosbags rejects that), empty messages (std_srvs/Trigger's request) included."""

import pytest
from rclpy.serialization import deserialize_message, serialize_message

from cdh_planner.recording.cdr import CdrEncoders
from cdh_planner.recording.mcap_log import _service_event
from cdh_planner.recording.ros_schemas import encodable, full_definition, recorded_type


def _messages():
    from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
    from geometry_msgs.msg import PoseStamped
    from rcl_interfaces.msg import Parameter, ParameterEvent, ParameterValue
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
    from visualization_msgs.msg import Marker, MarkerArray
    pose = PoseStamped()
    pose.pose.position.x, pose.pose.orientation.w, pose.header.frame_id = 0.25, 1.0, "cdh_base"
    return [
        JointState(name=["a", "b"], position=[1.0, 2.0], effort=[3.0, 4.0]),
        DiagnosticStatus(level=b"\x02", name="n", message="m",
                         values=[KeyValue(key="k", value="v")]),
        JointTrajectory(joint_names=["a"],
                        points=[JointTrajectoryPoint(positions=[1.0], velocities=[0.5])]),
        pose,
        ParameterEvent(node="/x", new_parameters=[Parameter(name="a", value=ParameterValue(
            type=9, string_array_value=["x", "y"], byte_array_value=[b"\x01", b"\xff"],
            bool_array_value=[True, False], integer_array_value=[1, -2]))]),
        MarkerArray(markers=[Marker(type=5, text="t", mesh_use_embedded_materials=True)]),
        Float64MultiArray(data=[1.0, 2.5]),
    ]


@pytest.mark.parametrize("msg", _messages(), ids=lambda m: type(m).__name__)
def test_rclpy_decodes_the_bytes_to_the_same_message(msg):
    module = type(msg).__module__.split(".")[0]
    type_name = f"{module}/msg/{type(msg).__name__}"
    data = CdrEncoders().encoder(type_name, full_definition(type_name))(
        encodable(msg, type_name))
    assert deserialize_message(data, type(msg)) == msg
    assert len(data) <= len(serialize_message(msg))   # rclpy's may end with padding


def test_an_empty_request_encodes():
    from std_srvs.srv import Trigger
    type_name = recorded_type("std_srvs/srv/Trigger_Event")
    event = _service_event(0, Trigger.Request(), None, 1, 5, bytes(16))
    data = CdrEncoders().encoder(type_name, full_definition(type_name))(
        encodable(event, type_name))
    assert list(deserialize_message(data, Trigger.Event).request) == [Trigger.Request()]


def test_a_service_event_with_chars_above_127_round_trips():
    from nav_msgs.srv import GetPlan
    type_name = recorded_type("nav_msgs/srv/GetPlan_Event")
    gid = bytes(range(120, 136))                       # char[16], values up to 135
    event = _service_event(0, GetPlan.Request(), None, 3, 123456789, gid)
    data = CdrEncoders().encoder(type_name, full_definition(type_name))(
        encodable(event, type_name))
    decoded = deserialize_message(data, GetPlan.Event)
    assert bytes(decoded.info.client_gid) == gid and decoded.info.sequence_number == 3
