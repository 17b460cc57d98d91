"""The simulated robot in (scaled) real time, for a controller double (no rclpy).

    live = LivePlant(robot, initial_lengths, time_scale=1.0)   # settled, not yet running
    live.start()
    live.follow(times, L, V, A)        # a JointTrajectoryController's goal, from now
    live.setpoint(L)                   # a streamed / forwarded command (reached in a line)
    live.hold()                        # stop where the winches are
    live.state()                       # (time s, winch positions m, tensions N, p, quaternion)
    live.stop()

A thread steps the plant (``plant.SimulatedRobot``, 1 kHz of simulated time) so that its
clock follows the wall clock times ``time_scale``, under the current command source
(``commands.Trajectory``). The platform starts at the pose whose cable lengths are the
initial winch lengths (forward kinematics, wrench-feasible solutions preferred) and
settles there for SETTLE_S before ``start``.
"""

import threading
import time

import numpy as np

from .commands import Trajectory, hold, ramp
from .mjcf import TIMESTEP_S

SETTLE_S = 1.0          # s of simulated time at the initial lengths before running
TICK_S = 0.005          # s: the thread's wall-clock period
MAX_CHUNK = 500         # steps per tick at most (a stalled machine falls behind, not apart)
SETPOINT_PERIOD_S = (0.001, 0.1, 0.02)   # s: least, largest, first setpoint interval


class LivePlant:
    def __init__(self, robot, initial, time_scale=1.0, scene=None):
        from ..wrench import wrench_feasibility
        from ..model.forward_kinematics import current_pose
        from ..ports import Rotation
        from .plant import SimulatedRobot
        self.plant = SimulatedRobot(robot, scene)
        L = np.asarray(initial, dtype=float)
        p, R = current_pose(robot, L, feasible=lambda p, R: bool(
            wrench_feasibility(robot, p[None], R=R[None]).feasible[0]))
        self.plant.reset(p, Rotation.from_matrix(R).as_quat(), L)
        self.source = hold(L, 0.0)
        self.scale = float(time_scale)
        self.lock = threading.Lock()
        self._last_setpoint = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)
        for _ in range(int(round(SETTLE_S / TIMESTEP_S))):
            self.plant.step()
        self.plant.time = 0.0

    # ------------------------------------------------------------------ commands

    def follow(self, times, L, V=None, A=None):
        """Run a trajectory (points at ``times`` s from now); from where the winches are to
        its first point when that is later than now. Returns (start, end) plant times (s)."""
        with self.lock:
            t0 = self.plant.time
            times = np.asarray(times, dtype=float)
            L = np.asarray(L, dtype=float)
            if times[0] > 0:
                here = self.plant.winch_positions[None]
                times, L = np.concatenate([[0.0], times]), np.vstack([here, L])
                if V is not None:
                    V = np.vstack([np.zeros_like(here), V])
                    A = None if A is None else np.vstack([np.zeros_like(here), A])
            self.source = Trajectory(t0 + times, L, V, A)
            return t0, t0 + float(times[-1])

    def setpoint(self, L):
        """Move to ``L`` (m,) m in a straight line over the interval since the previous
        setpoint (clipped to SETPOINT_PERIOD_S), then hold."""
        least, most, first = SETPOINT_PERIOD_S
        with self.lock:
            now = self.plant.time
            period = first if self._last_setpoint is None else \
                min(most, max(least, now - self._last_setpoint))
            self._last_setpoint = now
            self.source = ramp(self.plant.winch_positions.copy(), L, now, period)

    def hold(self):
        """Hold the winches where they are."""
        with self.lock:
            self.source = hold(self.plant.winch_positions.copy(), self.plant.time)

    def desired(self):
        """The command source's lengths (m,) m now."""
        with self.lock:
            return self.source.sample([self.plant.time])[0][0]

    def state(self):
        """(plant time s, winch positions (m,) m, tensions (m,) N, p (3,) m, quaternion)."""
        with self.lock:
            p, q = self.plant.pose()
            return (self.plant.time, self.plant.winch_positions.copy(),
                    self.plant.tensions.copy(), p, q)

    # ------------------------------------------------------------------ running

    def start(self):
        self._wall0 = time.monotonic()
        self._thread.start()

    def stop(self):
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2.0)

    def _loop(self):
        while not self._stop.wait(TICK_S):
            target = (time.monotonic() - self._wall0) * self.scale
            with self.lock:
                n = min(MAX_CHUNK, int((target - self.plant.time) / TIMESTEP_S))
                if n <= 0:
                    continue
                ts = self.plant.time + TIMESTEP_S * np.arange(n)
                L0, rate = self.source.sample(ts)
                for k in range(n):
                    self.plant.command(L0[k], rate[k])
                    self.plant.step()
                self.plant.time = float(ts[-1] + TIMESTEP_S)
