"""Live state of the robot from the measured cable lengths (no rclpy, no graph): what the
node publishes beside the platform's TF for each new joint state, during an execution and
at rest.

- ``~/cable_state`` (sensor_msgs/JointState): the winches' names, the measured lengths (m)
  as positions, and the measured tensions (N) as efforts when the joint state carries one
  per winch (else none);
- ``~/least_margin`` (std_msgs/Float64): the normalised feasibility margin of the measured
  pose (cable_feasibility.feasibility_of: positive inside, the least over lengths and
  tensions; with m > 6 cables the facet test's);
- ``~/live_markers`` (visualization_msgs/MarkerArray): the platform and the cables at the
  measured pose, each cable coloured by its margin (ns ``platform_measured``,
  ``cables_measured``), beside the plan's markers (planned against measured).
"""

import numpy as np
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64
from visualization_msgs.msg import MarkerArray

from ...cable_feasibility import feasibility_of as evaluate
from ..msgs.markers import pose_markers

CABLE_STATE, LEAST_MARGIN, LIVE_MARKERS = "cable_state", "least_margin", "live_markers"


def measured_tensions(joint_state, winch_names):
    """The efforts (N) of ``joint_state`` by winch name, or None when it has none for some."""
    if len(joint_state.effort) != len(joint_state.name):
        return None
    by_name = dict(zip(joint_state.name, joint_state.effort))
    if not all(n in by_name for n in winch_names):
        return None
    return [float(by_name[n]) for n in winch_names]


def live_messages(robot, lengths, p, R, joint_state, frame_id, stamp):
    """(cable_state JointState, least_margin Float64, MarkerArray) of the measured lengths
    ``lengths`` (m, winch order) at the pose (p m, R) of their forward kinematics."""
    feasibility = evaluate(robot, np.asarray(p)[None], R=np.asarray(R)[None])
    state = JointState(name=list(robot.winch_names), position=[float(x) for x in lengths])
    state.header.stamp, state.header.frame_id = stamp, frame_id
    tensions = measured_tensions(joint_state, robot.winch_names)
    if tensions is not None:
        state.effort = tensions
    margin = Float64(data=float(feasibility.margin[0]))
    per_cable = feasibility.margins[0].min(axis=0)
    markers = MarkerArray(markers=pose_markers(robot, p, R, per_cable, frame_id, stamp,
                                               ns_suffix="_measured"))
    return state, margin, markers
