"""TEST DOUBLE: a stand-in for cdh_planner.planner.Planner used only by the node's plumbing
tests (bad frames, busy, streaming). It plans a straight line in the task coordinates and
checks it pointwise; it is NOT the planner. Tests that compare ROS answers with the offline
planner use the real Planner.

If the file named by ``FAKE_PLANNER_DELAY_FILE`` (environment) exists, every plan takes at
least the number of seconds written in it, reporting progress every 10 ms and honouring
``cancel``, so that "busy" and cancels can be provoked deterministically. Followed by the
word ``busy`` ("2 busy"), the plan computes in Python meanwhile instead of sleeping: it
holds the interpreter as the real planner's search does (the node's other callbacks must
still be served).
"""

import os
import sys
import time

import numpy as np

from cdh_planner.wrench import wrench_feasibility
from cdh_planner.model.pose import quaternion_from_tau
from cdh_planner.planner import PlanResult
from cdh_planner.status import Status
from cdh_planner.trajectory.path import PlannedPath
from cdh_planner.trajectory.timing import time_path
from cdh_planner.trajectory.dynamics import timed_path

WAYPOINTS = 40


def _compute(seconds):
    """Pure-Python arithmetic for ``seconds`` (s): the interpreter held as a search holds it."""
    end, x = time.perf_counter() + seconds, 0
    while time.perf_counter() < end:
        for k in range(200):
            x += k * k


class FakePlanner:
    def __init__(self, robot, task, settings, scene=None):
        self.robot, self.task, self.settings, self.scene = robot, task, settings, scene
        self.delay_file = os.environ.get("FAKE_PLANNER_DELAY_FILE", "")

    def _result(self, ok, reason, message, path=None, t0=0.0):
        return PlanResult(success=ok, reason=reason, message=message,
                          strategy=self.settings.strategy, n=len(self.task.names), variables=0,
                          charts=WAYPOINTS if ok else 0, time_s=time.perf_counter() - t0,
                          cost=path.length_m() if path is not None else float("nan"), path=path)

    def plan(self, start, goal, progress=None, cancel=None, tolerance=None, strategy=None,
             timeout_s=None):
        t0 = time.perf_counter()
        try:
            words = open(self.delay_file).read().split() if self.delay_file else ["0"]
        except OSError:
            words = ["0"]
        delay, busy = float(words[0]), words[1:] == ["busy"]
        while time.perf_counter() - t0 < delay:
            if cancel is not None and cancel.is_set():
                return self._result(False, Status.CANCELED, "canceled (test double)", t0=t0)
            if progress is not None:
                progress({"charts": 1, "time_s": time.perf_counter() - t0, "best_h": 1.0})
            if busy:
                _compute(0.01)
            else:
                time.sleep(0.01)
        a = self.task.coords(start.p[None], start.tau[None])[0]
        b = self.task.coords(goal.p[None], goal.tau[None])[0]
        for label, pose in (("start", start), ("goal", goal)):
            f = wrench_feasibility(self.robot, pose.p[None], pose.tau[None])
            if not f.feasible[0]:
                return self._result(False, Status.infeasible(label),
                                    f"{label} pose is not wrench-feasible", t0=t0)
        y = a + np.linspace(0.0, 1.0, WAYPOINTS)[:, None] * (b - a)
        p, tau = self.task.pose(y)
        f = wrench_feasibility(self.robot, p, tau)
        if not np.all(f.feasible):
            return self._result(False, Status.NO_PATH, "the straight line leaves C", t0=t0)
        zeros = np.zeros((WAYPOINTS, 6))
        path = PlannedPath(p=p, quaternion=quaternion_from_tau(tau), tau=tau, lengths=f.lengths,
                           tension_min=f.tension_min, tension_nominal=f.tension_nominal,
                           tension_max=f.tension_max, margin=f.margin, t=np.zeros(WAYPOINTS),
                           velocities=zeros, accelerations=zeros)
        path = time_path(path, self.settings.max_cable_speed, self.settings.max_cable_accel)
        # the real planner's output stage: the points a controller's quintic executes within
        # the limits (quasi-static: the C2 spline through them, slowed to the limits)
        path, _, _ = timed_path(self.robot, path, "quasi_static", self.settings.max_cable_speed,
                                self.settings.max_cable_accel)
        return self._result(True, Status.OK, "straight line (test double)", path, t0)


def main():
    """Run the real node with this test double: python -m test.ros_doubles.fake_planner
    --ros-args ..."""
    from cdh_planner.ros.node.main import main as node_main
    args = sys.argv[1:]
    if args[:1] == ["--ros-args"]:
        args = args[1:]
    return node_main(args, planner_factory=FakePlanner,
                     log=lambda line: print(line, file=sys.stderr))


if __name__ == "__main__":
    sys.exit(main())
