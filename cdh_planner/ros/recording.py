"""The node's run log: one MCAP file per node run (``io.mcap_log.RunRecorder``).

The file is opened when the first thing is recorded (the first plan call), named
``<log_dir>/cdh_planner_<YYYYmmdd-HHMMSS>_<pid>.mcap``, and closed when the node shuts down
(SIGINT / SIGTERM included). Changing ``log_dir`` or turning ``log_enabled`` off closes it;
the next record opens a new file (``..._<n>.mcap``). Every message is flushed as it is
written, so a killed node loses nothing already recorded (``io.mcap_log`` explains what a
killed file looks like and how to read it).

Recording never raises into the node: a failure (disk full, directory gone) is reported
once through ``warn`` and recording stops until the configuration changes.
"""

import os
import threading
import time
from pathlib import Path

from ..io.mcap_log import RunRecorder


class RunLog:
    """Thread-safe: the planning thread and the executor both record."""

    def __init__(self, log_dir, enabled, warn=print):
        self._lock = threading.Lock()
        self._recorder = None
        self._dir = log_dir
        self._enabled = enabled
        self._failed = False
        self._warn = warn
        self._files = 0
        self._stem = f"cdh_planner_{time.strftime('%Y%m%d-%H%M%S')}_{os.getpid()}"
        self.closed = False

    @property
    def path(self):
        """The open file (str), or "" when none is open."""
        recorder = self._recorder
        return str(recorder.path) if recorder is not None else ""

    def configure(self, log_dir, enabled):
        """New settings: a change closes the current file."""
        with self._lock:
            if (log_dir, enabled) != (self._dir, self._enabled):
                self._close_locked()
                self._dir, self._enabled, self._failed = log_dir, enabled, False

    def open(self):
        """Open the file now if recording is on and none is open; return its path or ""."""
        with self._lock:
            return self._open_locked()

    def write(self, topic, msg, log_time_ns=None, transient_local=False):
        self._call("write", topic, msg, log_time_ns, transient_local=transient_local)

    def service_event(self, service, srv_type, event_type, request=None, response=None,
                      sequence_number=0, log_time_ns=None):
        self._call("write_service_event", service, srv_type, event_type, request=request,
                   response=response, sequence_number=sequence_number,
                   log_time_ns=log_time_ns)

    def close(self):
        """Close the file (summary, footer, fsync); later records are dropped."""
        with self._lock:
            self._close_locked()
            self.closed = True

    def _call(self, method, *args, **kwargs):
        with self._lock:
            if not self._open_locked():
                return
            try:
                getattr(self._recorder, method)(*args, **kwargs)
            except (OSError, ValueError) as exc:
                self._fail(f"recording to {self._recorder.path} failed: {exc}")

    def _open_locked(self):
        if self.closed or not self._enabled or self._failed:
            return ""
        if self._recorder is None:
            self._files += 1
            suffix = "" if self._files == 1 else f"_{self._files}"
            path = Path(self._dir) / f"{self._stem}{suffix}.mcap"
            try:
                self._recorder = RunRecorder(path)
            except OSError as exc:
                self._fail(f"cannot record to {path}: {exc}")
                return ""
        return str(self._recorder.path)

    def _close_locked(self):
        if self._recorder is not None:
            try:
                self._recorder.close()
            except OSError as exc:
                self._warn(f"closing {self._recorder.path} failed: {exc}")
            self._recorder = None

    def _fail(self, message):
        self._failed = True
        self._warn(message + " (recording off until log_dir or log_enabled changes)")
        try:
            if self._recorder is not None:
                self._recorder.close()
        except (OSError, ValueError):
            pass
        self._recorder = None
