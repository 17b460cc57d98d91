"""Live state of the robot from the measured cable lengths (no rclpy, no graph): what the
node publishes beside the platform's TF, during an execution and at rest, from the newest
joint state only, at the rates ``LiveRates`` says (``live_state_rate_hz``,
``live_markers_rate_hz``): a controller publishing at 1 kHz costs no more than one at 50 Hz.

- ``~/cable_state`` (sensor_msgs/JointState): the winches' names, the measured lengths (m)
  as positions, and the measured tensions (N) as efforts when the joint state carries one
  per winch (else none);
- ``~/least_margin`` (std_msgs/Float64): the normalised feasibility margin of the measured
  pose (wrench.wrench_feasibility: positive inside, the least over lengths and
  tensions; with m > 6 cables the facet test's);
- ``~/live_markers`` (visualization_msgs/MarkerArray): the platform and the cables at the
  measured pose, each cable coloured by its margin (ns ``platform_measured``,
  ``cables_measured``), beside the plan's markers (planned against measured).
"""

import numpy as np
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64
from visualization_msgs.msg import MarkerArray

from ...wrench import wrench_feasibility
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
    """(cable_state JointState, least_margin Float64, the margin of each cable (m,)) of the
    measured lengths ``lengths`` (m, winch order) at the pose (p m, R) of their forward
    kinematics; ``live_markers`` draws them."""
    feasibility = wrench_feasibility(robot, np.asarray(p)[None], R=np.asarray(R)[None])
    state = JointState(name=list(robot.winch_names), position=[float(x) for x in lengths])
    state.header.stamp, state.header.frame_id = stamp, frame_id
    tensions = measured_tensions(joint_state, robot.winch_names)
    if tensions is not None:
        state.effort = tensions
    margin = Float64(data=float(feasibility.margin[0]))
    return state, margin, feasibility.margins[0].min(axis=0)


def live_markers(robot, p, R, per_cable, frame_id, stamp):
    """The MarkerArray of the platform and cables at the measured pose (p m, R), each cable
    coloured by its margin ``per_cable`` (m,)."""
    return MarkerArray(markers=pose_markers(robot, p, R, per_cable, frame_id, stamp,
                                            ns_suffix="_measured"))


class LiveRates:
    """When the live state is computed: a worker looks every ``period_s`` (1 /
    ``live_state_rate_hz``) for a joint state newer than the last it computed, and draws
    the markers of one at most every 1 / ``live_markers_rate_hz`` s. Times in s."""

    def __init__(self, state_hz, markers_hz):
        self.period_s = 1.0 / float(state_hz)
        self._markers_s = 1.0 / float(markers_hz)
        self._last_markers = None

    def markers_due(self, now_s):
        """True (and remembered) when markers were last drawn ``1 / markers_hz`` s or more
        before ``now_s``, or never."""
        # half a look's period early: markers at 10 Hz of states at 20 Hz come every other one
        if self._last_markers is not None and \
                now_s - self._last_markers < self._markers_s - 0.5 * self.period_s:
            return False
        self._last_markers = now_s
        return True
