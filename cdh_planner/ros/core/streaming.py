"""Streaming a planned trajectory as cable commands in real time (no graph: the node's
timer calls ``command``, its stop service ``hold``).

    stream = Stream(path, joint_names, method="quintic", start=time.monotonic())
    msg, finished = stream.command(time.monotonic(), stamp)   # each timer tick
    msg = stream.hold(stamp)                                   # on stop

The command at wall-clock time ``now`` is the trajectory sampled at ``now - start`` s
(``trajectory.sampling.sample_cable_state``): by default the quintic a JointTrajectoryController
interpolates between the same points, the motion the planner checked
(``trajectory.executed``); ``linear`` is kept for winches that want straight segments
(not checked: its velocity steps at every point). Past the end the
last waypoint is sent with zero velocity and the stream is finished. ``hold`` repeats the
last command sent with zero velocity: the winches stay where they were last told to be.
Commands are built by ``messages.winch_command``.
"""

import numpy as np

from ...trajectory.sampling import sample_cable_state
from ..msgs import messages as M


class Stream:
    """One execution of a PlannedPath (``path.t`` from 0 to its duration, s)."""

    def __init__(self, path, joint_names, method="quintic", start=0.0):
        self.path = path
        self.joint_names = M.check_joint_names(joint_names)
        self.method = method
        self.start = float(start)
        self.duration = float(path.t[-1])
        self.sent = 0
        self.last = None  # last command sent
        self.t = 0.0      # trajectory time of the last command (s)
        self._held = None  # (lengths, effort) of the last command

    def command(self, now, stamp):
        """(command at trajectory time ``now - start``, finished): finished when that
        time has reached the end (the command is then the last waypoint, velocity 0)."""
        t = min(max(float(now) - self.start, 0.0), self.duration)
        finished = t >= self.duration
        sample = sample_cable_state(self.path, t, self.method)
        self.t = t
        velocities = np.zeros(len(self.joint_names)) if finished else sample.velocities
        return self._send(sample.lengths, velocities, sample.effort, stamp), finished

    def hold(self, stamp):
        """The last command again (or the start, if none was sent), velocity 0, now."""
        if self._held is None:
            sample = sample_cable_state(self.path, 0.0, self.method)
            self._held = (sample.lengths, sample.effort)
        lengths, effort = self._held
        return self._send(lengths, np.zeros(len(self.joint_names)), effort, stamp)

    def _send(self, lengths, velocities, effort, stamp):
        self._held = (lengths, effort)
        self.last = M.winch_command(self.joint_names, lengths, velocities, stamp, effort)
        self.sent += 1
        return self.last
