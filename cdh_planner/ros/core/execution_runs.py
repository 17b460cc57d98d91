"""The execution's state machine, without ROS: at most one run at a time, and exactly one
end per run whatever fails inside it.

    IDLE --begin(mode)--> STARTING --advance(run, RUNNING)--> RUNNING
    STARTING or RUNNING --advance(run, STOPPING)--> STOPPING
    STARTING, RUNNING or STOPPING --end(run, outcome, message)--> IDLE

``end`` is the one terminal transition: the first call for a run takes the machine back to
IDLE and returns True; every later call for that run (a late controller answer, a stop
racing the last stream tick) returns False and changes nothing. A run is a token: a
callback holding an old run can never end a newer one. The side effects of an end
(logging, the latched result, handing over a plan made meanwhile) come after the
transition, so none of them can leave the machine executing.
"""

import enum
import threading
from dataclasses import dataclass


class Phase(str, enum.Enum):
    IDLE = "idle"
    STARTING = "starting"      # begun: the trajectory not yet running (server not found...)
    RUNNING = "running"
    STOPPING = "stopping"      # a stop was asked; the controller's answer ends the run


@dataclass(eq=False)
class Run:
    number: int                # 1, 2, ... in this process
    mode: str                  # execution.mode of the run
    phase: Phase = Phase.STARTING
    outcome: str = ""          # once ended: completed, stopped or failed
    message: str = ""          # once ended: why


class ExecutionRuns:
    """One execution at a time (thread-safe); ``last`` is the last run that ended."""

    def __init__(self):
        self._lock = threading.Lock()
        self._run = None
        self._count = 0
        self.last = None

    @property
    def current(self):
        """The run in progress, or None (IDLE)."""
        return self._run

    @property
    def phase(self):
        run = self._run
        return Phase.IDLE if run is None else run.phase

    def begin(self, mode):
        """A new Run in STARTING, or None when one is in progress already."""
        with self._lock:
            if self._run is not None:
                return None
            self._count += 1
            self._run = Run(self._count, mode)
            return self._run

    def advance(self, run, phase):
        """``run`` to RUNNING or STOPPING; False (nothing changed) when ``run`` has ended
        or the step goes backwards (STOPPING never returns to RUNNING)."""
        if phase not in (Phase.RUNNING, Phase.STOPPING):
            raise ValueError(f"advance to {phase!r}: only running or stopping")
        with self._lock:
            if self._run is not run or (run.phase == Phase.STOPPING and phase == Phase.RUNNING):
                return False
            run.phase = phase
            return True

    def end(self, run, outcome, message):
        """The terminal transition: True the first time for the current ``run`` (now IDLE),
        False after (ended already, or not the current run)."""
        with self._lock:
            if run is None or self._run is not run:
                return False
            run.phase, run.outcome, run.message = Phase.IDLE, outcome, message
            self._run, self.last = None, run
            return True
