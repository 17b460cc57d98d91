"""Streaming a planned trajectory as cable commands in real time (no graph: the node's
timer calls ``command``, its stop service ``hold``).

    stream = Stream(path, joint_names, method="linear", start=time.monotonic())
    msg, finished = stream.command(time.monotonic(), stamp)   # each timer tick
    msg = stream.hold(stamp)                                   # on stop

The command at wall-clock time ``now`` is the trajectory sampled at ``now - start`` s
(``trajectory.sampling.sample_cable_state``: linear or quintic between waypoints). Past the end the
last waypoint is sent with zero velocity and the stream is finished. ``hold`` repeats the
last command sent with zero velocity: the winches stay where they were last told to be.
"""

import numpy as np

from . import messages as M


class Stream:
    """One execution of a PlannedPath (``path.t`` from 0 to its duration, s)."""

    def __init__(self, path, joint_names, method="linear", start=0.0):
        self.path = path
        self.joint_names = M.check_joint_names(joint_names)
        self.method = method
        self.start = float(start)
        self.duration = float(path.t[-1])
        self.sent = 0
        self.last = None  # last JointState sent
        self.t = 0.0      # trajectory time of the last command (s)

    def command(self, now, stamp):
        """(JointState at trajectory time ``now - start``, finished): finished when that
        time has reached the end (the command is then the last waypoint, velocity 0)."""
        t = min(max(float(now) - self.start, 0.0), self.duration)
        finished = t >= self.duration
        msg = M.cable_command_msg(self.path, self.joint_names, t, stamp, method=self.method)
        if finished:
            msg.velocity = np.zeros(len(self.joint_names))
        self.t = t
        self.sent += 1
        self.last = msg
        return msg, finished

    def hold(self, stamp):
        """The last command again (or the start, if none was sent), velocity 0, now."""
        if self.last is None:
            msg = M.cable_command_msg(self.path, self.joint_names, 0.0, stamp,
                                      method=self.method)
        else:
            msg = M.JointState()
            msg.header.frame_id = self.last.header.frame_id
            msg.header.stamp = stamp
            msg.name = list(self.last.name)
            msg.position = np.asarray(self.last.position, dtype=float)
            msg.effort = np.asarray(self.last.effort, dtype=float)
        msg.velocity = np.zeros(len(self.joint_names))
        self.last = msg
        self.sent += 1
        return msg
