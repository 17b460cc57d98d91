"""The node's run log: MCAP files of one node run (``recording.mcap_log.RunRecorder``).

The first file is opened when the node starts, named
``<log_dir>/cdh_planner_<YYYYmmdd-HHMMSS>_<pid>.mcap``; later ones (rotation, or after a
change of ``log_dir`` / ``log_enabled``) add ``_<n>`` to the name. The last one is closed
when the node shuts down (SIGINT / SIGTERM included). Every message is flushed as it is
written, so a killed node loses nothing already recorded; its file lacks the summary, and
``cdh-planner recover FILE`` completes it (``recording.mcap_log`` explains).

Parameters: every file begins with a ``rcl_interfaces/msg/ParameterEvent`` on
``/parameter_events`` (the topic and type ROS itself publishes them on) listing all the
node's parameters as ``new_parameters``, and each accepted change is recorded as one with
``changed_parameters``. So any one file says which parameters were in effect at each of its
requests (``replay --requests`` applies them). Then the node's current scene
(``~/scene``, written with ``snapshot``), so that each file also says which obstacles were.

Plan calls: a GetPlan call's request and response as service events
(``<service>/_service_event``), a PlanPath goal and its result as rosbag2 records actions
(``<action>/_action/send_goal/_service_event``, ``.../get_result/_service_event``;
``recording.mcap_log``). Both are numbered by the node's one call counter (``sequence_number``),
which pairs a goal with its result (the node gives ``action_event`` neither the goal's UUID
nor its final status: they are recorded as zeros and STATUS_UNKNOWN).

Rotation: with ``max_bytes`` or ``max_s`` (> 0), a file that has reached either limit is
closed before the next record and the record starts the next file. A plan call's request
and response (a goal and its result) stay in one file: an answer never starts a file, and
while a call is open the other records wait for rotation up to twice the limits. A file
thus holds at least one record after its parameter snapshot.

Pruning: each time a file is opened, older run files in ``log_dir`` beyond ``max_files``
or ``max_age_days`` are removed (``run_pruning``), each removal logged.

Recording never raises into the node. A failure of the file (disk full, directory gone) is
reported once through ``warn`` and recording stops until the configuration changes; a
message that cannot be encoded (e.g. a number beyond its field's type) is dropped with a
warning (once per topic) and recording goes on.
"""

import os
import threading
import time
from pathlib import Path

from rcl_interfaces.msg import ParameterEvent

from ...errors import exception_line
from ...recording.mcap_log import REQUEST_RECEIVED, REQUEST_SENT, RESPONSE_RECEIVED, RESPONSE_SENT, \
    RunRecorder
from .run_pruning import prune

PARAMETER_EVENTS = "/parameter_events"
MIB = 1024 * 1024
# while a call is open, a file may grow to this many times its limits before it rotates
OPEN_CALL_SLACK = 2.0


class RunLog:
    """Thread-safe: the planning thread and the executor both record.

    ``warn(text)``: failures; ``info(text)``: each file opened on its own (rotation, new
    ``log_dir``), with the command that completes it if the node is killed.
    """

    def __init__(self, log_dir, enabled, warn=print, info=print, max_bytes=0, max_s=0.0,
                 node_name="/cdh_planner", max_files=0, max_age_days=0.0):
        self._lock = threading.Lock()
        self._recorder = None
        self._dir = log_dir
        self._enabled = enabled
        self._max_bytes = max_bytes
        self._max_s = max_s
        self._keep = (max_files, max_age_days)    # run_pruning's limits
        self._failed = False
        self._warn = warn
        self._info = info
        self._node = node_name
        self._files = 0
        self._stem = f"cdh_planner_{time.strftime('%Y%m%d-%H%M%S')}_{os.getpid()}"
        self._parameters = {}       # name -> rcl_interfaces/msg/Parameter: current values
        self._snapshots = {}        # topic -> (msg, transient_local): the node's current scene
        self._open_calls = set()    # (service, sequence) requested, not yet answered
        self._dropped = set()       # topics whose undecodable message was reported
        self._written = 0           # records in the current file after its snapshot
        self._rotated = ""          # why the last file was closed by rotation
        self.closed = False

    @property
    def path(self):
        """The open file (str), or "" when none is open."""
        recorder = self._recorder
        return str(recorder.path) if recorder is not None else ""

    @property
    def state(self):
        """The open file, or "failed", "off", "on, no file open" (for /diagnostics)."""
        return self.path or ("failed" if self._failed else
                             "on, no file open" if self._enabled else "off")

    def configure(self, log_dir, enabled, max_bytes=None, max_s=None, max_files=None,
                  max_age_days=None):
        """New settings: a change of directory or on/off closes the current file; new limits
        apply to it from the next record, new pruning limits from the next file opened
        (``None``: unchanged)."""
        with self._lock:
            if max_files is not None or max_age_days is not None:
                self._keep = (self._keep[0] if max_files is None else max_files,
                              self._keep[1] if max_age_days is None else max_age_days)
            if max_bytes is not None:
                self._max_bytes = max_bytes
            if max_s is not None:
                self._max_s = max_s
            if (log_dir, enabled) != (self._dir, self._enabled):
                self._close_locked()
                self._dir, self._enabled, self._failed = log_dir, enabled, False

    def open(self):
        """Open the file now if recording is on and none is open; return its path or ""."""
        with self._lock:
            return self._open_locked(announce=False)

    def parameters(self, params, initial=False, log_time_ns=None):
        """The node's parameters (rcl_interfaces/msg/Parameter): ``initial``, all of them (the
        snapshot each file begins with; nothing is written now), else the ones just changed
        (recorded as a ParameterEvent with ``changed_parameters``)."""
        with self._lock:
            if initial:
                self._parameters = {p.name: p for p in params}
                return
            self._parameters.update({p.name: p for p in params})
        event = ParameterEvent(node=self._node, changed_parameters=list(params))
        self._call("write", PARAMETER_EVENTS, _stamped(event, log_time_ns), log_time_ns,
                   at=log_time_ns)

    def write(self, topic, msg, log_time_ns=None, transient_local=False, snapshot=False):
        """Record ``msg``; with ``snapshot``, every later file also begins with it (after
        the parameters) until the topic's next snapshot: the node's current scene."""
        self._call("write", topic, msg, log_time_ns, transient_local=transient_local,
                   at=log_time_ns)
        if snapshot:   # after: a file this write opens does not begin with it twice
            with self._lock:
                self._snapshots[topic] = (msg, transient_local)

    def service_event(self, service, srv_type, event_type, request=None, response=None,
                      sequence_number=0, log_time_ns=None):
        self._call_event("write_service_event", service, srv_type, event_type,
                         sequence_number, log_time_ns, request=request, response=response)

    def action_event(self, action, action_type, event_type, goal=None, result=None,
                     sequence_number=0, log_time_ns=None, **kwargs):
        """An action's goal (REQUEST_RECEIVED / REQUEST_SENT, ``goal``) or result
        (RESPONSE_SENT / RESPONSE_RECEIVED, ``result``), paired by ``sequence_number``
        (``RunRecorder.write_action_event``; ``kwargs``: its ``goal_id``, ``status``). Kept
        together as a service call's request and response are: the result joins its goal's
        file."""
        self._call_event("write_action_event", action, action_type, event_type,
                         sequence_number, log_time_ns, goal=goal, result=result, **kwargs)

    def _call_event(self, method, name, type_name, event_type, sequence_number, log_time_ns,
                    **kwargs):
        """A call's request (it opens the call) or answer (it closes it, in the request's
        file: no rotation in between), by the recorder's ``method``."""
        call = (name, sequence_number)
        answer = event_type in (RESPONSE_SENT, RESPONSE_RECEIVED)
        opens = call if event_type in (REQUEST_RECEIVED, REQUEST_SENT) else None
        self._call(method, name, type_name, event_type, sequence_number=sequence_number,
                   log_time_ns=log_time_ns, at=log_time_ns, opens=opens,
                   closes=call if answer else None,
                   rotate=not answer, **kwargs)   # an answer joins its request

    def close(self):
        """Close the file (summary, footer, fsync); later records are dropped."""
        with self._lock:
            self._close_locked()
            self.closed = True

    def _call(self, method, *args, at=None, rotate=True, opens=None, closes=None, **kwargs):
        """``method`` of the recorder; ``at``: the record's log time (a file it opens begins
        with the parameters at that time); ``opens`` / ``closes``: the call it begins / ends."""
        with self._lock:
            if rotate:
                self._rotate_locked()
            if opens is not None:
                self._open_calls.add(opens)
            self._open_calls.discard(closes)
            if not self._open_locked(announce=True, log_time_ns=at):
                return
            recorder = self._recorder
            try:
                getattr(recorder, method)(*args, **kwargs)
                self._written += 1
            except OSError as exc:
                self._fail(f"recording to {recorder.path} failed: {exc}")
            except Exception as exc:  # noqa: BLE001 - encoding: drop this message, go on
                topic = args[0]
                if topic not in self._dropped:
                    self._dropped.add(topic)
                    self._warn(f"not recorded: a message on {topic} that cannot be encoded "
                               f"({exception_line(exc)}); later ones on this topic "
                               f"that fail are dropped silently")

    def _rotate_locked(self):
        """Close the current file if it has reached a limit (module docstring)."""
        r = self._recorder
        if r is None or self._written == 0 or not (self._max_bytes or self._max_s):
            return
        slack = OPEN_CALL_SLACK if self._open_calls else 1.0
        age = time.monotonic() - r.opened
        if self._max_bytes and r.size >= slack * self._max_bytes:
            reason = f"reached {r.size / MIB:.3g} MiB (log_max_file_mb {self._max_bytes / MIB:g})"
        elif self._max_s and age >= slack * self._max_s:
            reason = f"open for {age:.3g} s (log_max_file_s {self._max_s:g})"
        else:
            return
        self._close_locked()
        self._rotated = f"{r.path.name} {reason}"

    def _open_locked(self, announce, log_time_ns=None):
        if self.closed or not self._enabled or self._failed:
            return ""
        if self._recorder is None:
            self._files += 1
            suffix = "" if self._files == 1 else f"_{self._files}"
            path = Path(self._dir) / f"{self._stem}{suffix}.mcap"
            try:
                self._recorder = RunRecorder(path)
                if self._parameters:
                    event = ParameterEvent(node=self._node,
                                           new_parameters=list(self._parameters.values()))
                    self._recorder.write(PARAMETER_EVENTS, _stamped(event, log_time_ns),
                                         log_time_ns)
                for topic, (msg, latched) in self._snapshots.items():
                    self._recorder.write(topic, msg, log_time_ns, transient_local=latched)
            except OSError as exc:
                self._fail(f"cannot record to {path}: {exc}")
                return ""
            except Exception as exc:  # noqa: BLE001 - never into the node
                self._warn(f"the parameters could not be recorded in {path}: "
                           f"{exception_line(exc)}")
            self._written = 0
            self._prune(path)
            rotated, self._rotated = self._rotated, ""
            if announce:
                self._info(f"recording to {path}" + (f" ({rotated})" if rotated else "")
                           + f"; if the node is killed: cdh-planner recover {path}")
        return str(self._recorder.path)

    def _prune(self, current):
        """Old run files beyond the limits removed (never ``current``), each said."""
        removed, failed = prune(self._dir, *self._keep, current=current)
        if removed:
            self._info(f"removed {len(removed)} old run file(s) (log_max_files "
                       f"{self._keep[0]}, log_max_age_days {self._keep[1]:g}): "
                       + ", ".join(p.name for p in removed[:5])
                       + (", ..." if len(removed) > 5 else ""))
        for path, exc in failed[:1]:
            self._warn(f"cannot remove old run file {path}: {exc}")

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


def _stamped(event, log_time_ns):
    """``event`` with its stamp set to ``log_time_ns`` (default: now)."""
    t = time.time_ns() if log_time_ns is None else int(log_time_ns)
    event.stamp.sec, event.stamp.nanosec = t // 10**9, t % 10**9
    return event


def log_limits(values):
    """RunLog's rotation limits (``max_bytes``, ``max_s``) and pruning limits
    (``max_files``, ``max_age_days``) from the node's parameter values ``log_max_file_mb``,
    ``log_max_file_s``, ``log_max_files`` and ``log_max_age_days``."""
    return {"max_bytes": int(float(values.get("log_max_file_mb") or 0.0) * MIB),
            "max_s": float(values.get("log_max_file_s") or 0.0),
            "max_files": int(values.get("log_max_files") or 0),
            "max_age_days": float(values.get("log_max_age_days") or 0.0)}


class NodeRecording:
    """The node's recording calls over its RunLog, none of them ever raising: a failure is
    logged (at most once every ``ERROR_PERIOD_S``) and the answer goes on. ``publish``
    records before it publishes: whatever a subscriber got is in the run file, even if the
    process is killed right after."""

    ERROR_PERIOD_S = 10.0

    def __init__(self, node, runlog):
        self._node, self.runlog = node, runlog

    def __call__(self, method, *args, **kwargs):
        """``method(*args, **kwargs)`` (a RunLog method); None if it raised."""
        try:
            return method(*args, **kwargs)
        except Exception as exc:  # noqa: BLE001
            self._node.get_logger().error(
                f"recording failed ({getattr(method, '__name__', method)}): "
                f"{exception_line(exc)}", throttle_duration_sec=self.ERROR_PERIOD_S)
            return None

    def publish(self, publisher, msg, latched=False, snapshot=False):
        self(self.runlog.write, publisher.topic_name, msg, self.now(), transient_local=latched,
             snapshot=snapshot)
        publisher.publish(msg)

    def trigger(self, service, event, request=None, response=None):
        """A std_srvs/Trigger call of ``service`` (a Service) as it arrived or was answered."""
        self(self.runlog.service_event, self._node.resolve_service_name(service.srv_name),
             "std_srvs/srv/Trigger", event, request=request, response=response,
             log_time_ns=self.now())

    def plan(self, service, event, seq, request=None, response=None):
        self(self.runlog.service_event, self._node.resolve_service_name(service.srv_name),
             "nav_msgs/srv/GetPlan", event, request=request, response=response,
             sequence_number=seq, log_time_ns=self.now())

    def goal(self, action, event, seq, goal_handle, goal=None, result=None):
        """A PlanPath goal as it arrived (REQUEST_RECEIVED) or its result as sent
        (RESPONSE_SENT, with the goal's final status), paired by ``seq``."""
        self(self.runlog.action_event, action, "cdh_planner_interfaces/action/PlanPath", event,
             goal=goal, result=result, sequence_number=seq, log_time_ns=self.now(),
             goal_id=bytes(goal_handle.goal_id.uuid), status=goal_handle.status)

    def parameters(self, params, **kwargs):
        self(self.runlog.parameters, [p.to_parameter_msg() for p in params], **kwargs)

    def now(self):
        return self._node.get_clock().now().nanoseconds
