"""Run recording: ROS 2 messages to MCAP files that rosbag2, Foxglove, mcap_ros2 and rosbags open.

File layout (MCAP ``ros2`` profile, as rosbag2's MCAP storage writes it): one ``ros2msg``
schema per type named ``pkg/msg/Type`` with the full definition (see ``ros_schemas``), one
``cdr`` channel per topic with ``offered_qos_profiles`` metadata, a statistics record. No
``rosbag2`` metadata record (optional, and if present it must be complete). Service calls
are recorded as rosbag2 records them (``<service>/_service_event``), and an action's goals
and results as rosbag2 records actions: events of its send_goal and get_result services
(``<action>/_action/send_goal/_service_event``, ``.../get_result/_service_event``). One
departure: their types are named ``pkg/msg/SEvent`` (``pkg/msg/ASendGoalEvent``), not
rosbag2's ``pkg/srv/S_Event`` (``pkg/action/A_SendGoal_Event``), which neither mcap_ros2
nor rosbags (nor ``rosbags-convert``) decodes (``ros_schemas`` explains).
Every record decodes with mcap_ros2's stock ``DecoderFactory`` and rosbags' ``AnyReader``,
and ``rosbags-convert`` turns a file into a rosbag2 directory.

Messages are CDR-encoded from the schema text by rosbags' public typestore (``recording/cdr.py``),
never by ``rclpy.serialization`` (its buffers can carry rmw's padding, which rosbags
rejects), nor by mcap_ros2's encoder (private: ``mcap_ros2._dynamic``). ``mcap_ros2.writer.Writer``
can neither attach channel metadata nor finish a chunk on demand, so the container is
written with ``mcap.writer.Writer``.

Durability: every ``write`` finishes its chunk (one message per chunk, uncompressed) and
flushes the file, so after ``write`` returns the message is in the OS page cache and survives
the process being killed (not a power cut: only ``close`` fsyncs). A killed run lacks the
summary and footer. What is left is still a valid MCAP data section:

- ``read_run`` (mcap ``NonSeekingReader`` + mcap_ros2 decoders, linear scan) returns every
  message whose ``write`` returned, and drops a torn last one;
- ``mcap.reader.make_reader(f)`` (a ``SeekingReader``) raises on it: it reads the tail of
  the file as a footer (e.g. RecordLengthLimitExceeded), before any fallback to a scan;
- rosbags ``AnyReader`` refuses it ("File end magic is invalid");
- rosbag2's MCAP plugin reads the summary with ``AllowFallbackScan`` and so should open it
  (from its source; not checked here, the ros2 CLI is not on PyPI);
- ``recover_run(src, dst)`` (``cdh-planner recover FILE``) rewrites it with a summary, after
  which all of them open it.

``check_recording`` refuses what is not a recording (empty, not MCAP) with the reason.

SIGTERM/SIGKILL leave such a truncated file; SIGINT raises KeyboardInterrupt, so a ``with``
block closes the file properly. Signal handling is the node's business: it calls ``close()``.
"""

import os
import struct
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from mcap.exceptions import EndOfFile, RecordLengthLimitExceeded
from mcap.reader import NonSeekingReader
from mcap.records import DataEnd, Schema
from mcap.stream_reader import CRCValidationError, StreamReader
from mcap.writer import CompressionType, Writer
from mcap_ros2.decoder import DecoderFactory

from ..errors import exception_line
from .cdr import CdrEncoders
from .ros_schemas import encodable, full_definition, mcap_ros2_alias, recorded_type, \
    rosidl_type, split_type_name, type_name_of

# service_msgs/msg/ServiceEventInfo event types
REQUEST_SENT, REQUEST_RECEIVED, RESPONSE_SENT, RESPONSE_RECEIVED = 0, 1, 2, 3
SERVICE_EVENT_SUFFIX = "/_service_event"
# an action's services, as rosbag2 records them: <action>/_action/<service>/_service_event
ACTION_INFIX = "/_action/"
SEND_GOAL, GET_RESULT = "send_goal", "get_result"
ACTION_SERVICES = {SEND_GOAL: "SendGoal", GET_RESULT: "GetResult"}   # topic -> type part
STATUS_UNKNOWN = 0   # action_msgs/msg/GoalStatus
LIBRARY = "cdh_planner mcap_log"
MAGIC = b"\x89MCAP0\r\n"     # starts and ends every MCAP file


class NotARecording(ValueError):
    """The file is not an MCAP recording (empty, another format, no message); the message
    says why, on one line, without the file's name."""


def offered_qos_yaml(transient_local: bool = False) -> str:
    """``offered_qos_profiles`` channel metadata: one reliable keep-last publisher, in the
    YAML rosbag2 writes since Jazzy (metadata version 9: policies as strings).

    rosbag2 reads MCAP files without a ``rosbag2`` metadata record as version 9, and
    ``ros2 bag play`` republishes with this profile, so latched topics (``transient_local``)
    stay latched on replay. Durations 0/0 mean "unspecified" (the rmw default).
    """
    zero = "\n    sec: 0\n    nsec: 0"
    return (f"- history: keep_last\n"
            f"  depth: {1 if transient_local else 10}\n"
            f"  reliability: reliable\n"
            f"  durability: {'transient_local' if transient_local else 'volatile'}\n"
            f"  deadline:{zero}\n"
            f"  lifespan:{zero}\n"
            f"  liveliness: automatic\n"
            f"  liveliness_lease_duration:{zero}\n"
            f"  avoid_ros_namespace_conventions: false")


class RunRecorder:
    """Records ROS 2 messages to one MCAP file; a context manager (``close`` on exit).

    ``write`` takes rosidl message instances (``nav_msgs.msg.Path()`` ...) and registers the
    schema and channel of a topic on first use. Thread-safe: the node may record from its
    executor and from the planning thread. ``size`` (bytes written), ``messages`` and
    ``opened`` (time.monotonic() at open) let the caller rotate files.
    """

    def __init__(self, path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb")
        # chunking stays on (indexed readers need chunk indexes); write() closes each chunk
        self._writer = Writer(self._file, compression=CompressionType.NONE)
        self._writer.start(profile="ros2", library=LIBRARY)
        self._writer.flush()
        self._schemas: dict[str, tuple[int, object]] = {}   # type -> (schema id, encoder)
        self._cdr = CdrEncoders()
        self._channels: dict[str, tuple[int, str]] = {}     # topic -> (channel id, type)
        self._lock = threading.Lock()
        self._closed = False
        self.opened = time.monotonic()
        self.messages = 0

    @property
    def size(self) -> int:
        """Bytes in the file so far (everything written has been flushed)."""
        return self._file.tell()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def write(self, topic: str, msg, log_time_ns: int | None = None, *,
              transient_local: bool = False) -> None:
        """Record ``msg`` on ``topic`` at ``log_time_ns`` (default: now, ns since the epoch).

        ``transient_local`` marks the topic latched in its QoS metadata; it is read on the
        topic's first write only.
        """
        self._write(topic, type_name_of(msg), msg, log_time_ns, transient_local)

    def write_service_event(self, service_name: str, srv_type: str, event_type: int,
                            request=None, response=None, *, sequence_number: int = 0,
                            stamp_ns: int | None = None, client_gid: bytes = bytes(16),
                            log_time_ns: int | None = None) -> None:
        """Record a service call the way rosbag2 records services: a ``pkg/srv/S_Event`` on
        ``<service_name>/_service_event`` (``event_type``: REQUEST_SENT, REQUEST_RECEIVED,
        RESPONSE_SENT, RESPONSE_RECEIVED). ``stamp_ns`` defaults to the log time; requests and
        responses of one call share ``sequence_number`` and ``client_gid``.
        """
        pkg, kind, name = split_type_name(srv_type)
        if kind != "srv":
            raise ValueError(f"not a service type: {srv_type!r} (expected pkg/srv/Name)")
        if request is not None and response is not None:
            raise ValueError("a service event holds a request or a response, not both")
        log_time_ns = time.time_ns() if log_time_ns is None else log_time_ns
        event = _service_event(event_type, request, response, sequence_number,
                               log_time_ns if stamp_ns is None else stamp_ns, client_gid)
        self._write(service_name.rstrip("/") + SERVICE_EVENT_SUFFIX,
                    f"{pkg}/srv/{name}_Event", event, log_time_ns, False)

    def write_action_event(self, action_name: str, action_type: str, event_type: int,
                           goal=None, result=None, *, sequence_number: int = 0,
                           goal_id: bytes = bytes(16), status: int = STATUS_UNKNOWN,
                           stamp_ns: int | None = None, client_gid: bytes = bytes(16),
                           log_time_ns: int | None = None) -> None:
        """Record an action's goal or result the way rosbag2 records actions: as events of
        the action's services (``ros_schemas`` explains). A ``goal`` (``pkg/action/A_Goal``,
        with REQUEST_RECEIVED or REQUEST_SENT) is a ``pkg/action/A_SendGoal_Event`` whose
        request holds ``goal_id`` and the goal, on ``<action>/_action/send_goal/
        _service_event``; a ``result`` (with RESPONSE_SENT or RESPONSE_RECEIVED) is a
        ``pkg/action/A_GetResult_Event`` whose response holds ``status``
        (action_msgs/GoalStatus; default unknown) and the result, on
        ``<action>/_action/get_result/_service_event``. A goal and its result share
        ``sequence_number`` (and ``goal_id``, 16 bytes); ``stamp_ns`` defaults to the log
        time.
        """
        pkg, kind, name = split_type_name(action_type)
        if kind != "action":
            raise ValueError(f"not an action type: {action_type!r} (expected pkg/action/Name)")
        if (goal is None) == (result is None):
            raise ValueError("an action event holds a goal or a result (one of them)")
        requests = (REQUEST_SENT, REQUEST_RECEIVED)
        if (goal is not None) != (event_type in requests):
            raise ValueError(f"event type {event_type}: a goal goes with REQUEST_RECEIVED "
                             f"or REQUEST_SENT, a result with RESPONSE_SENT or "
                             f"RESPONSE_RECEIVED")
        if len(goal_id) != 16:
            raise ValueError(f"goal_id must be 16 bytes, got {len(goal_id)}")
        log_time_ns = time.time_ns() if log_time_ns is None else log_time_ns
        stamp_ns = log_time_ns if stamp_ns is None else stamp_ns
        if goal is not None:
            service, request, response = SEND_GOAL, {"goal_id": {"uuid": bytes(goal_id)},
                                                     "goal": goal}, None
        else:
            service, request, response = GET_RESULT, None, {"status": int(status),
                                                            "result": result}
        event = _service_event(event_type, request, response, sequence_number, stamp_ns,
                               client_gid)
        self._write(f"{action_name.rstrip('/')}{ACTION_INFIX}{service}{SERVICE_EVENT_SUFFIX}",
                    f"{pkg}/action/{name}_{ACTION_SERVICES[service]}_Event", event,
                    log_time_ns, False)

    def close(self) -> None:
        """Write the summary and footer, fsync and close. Idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            try:
                self._writer.finish()
                self._file.flush()
                os.fsync(self._file.fileno())
            finally:
                self._file.close()

    def _write(self, topic, type_name, msg, log_time_ns, transient_local) -> None:
        log_time_ns = time.time_ns() if log_time_ns is None else int(log_time_ns)
        with self._lock:
            if self._closed:
                raise ValueError(f"recorder for {self.path} is closed")
            channel_id, encoder = self._channel(topic, type_name, transient_local)
            data = encoder(encodable(msg, type_name))   # raises before anything is written
            self._writer.add_message(channel_id=channel_id, log_time=log_time_ns,
                                     data=data, publish_time=log_time_ns)
            self._writer.flush()     # finishes the chunk and flushes the file: kill-safe
            self.messages += 1

    def _channel(self, topic, type_name, transient_local):
        """(channel id, encoder) for ``topic``, registering schema and channel on first use."""
        type_name = recorded_type(type_name)
        if topic in self._channels:
            channel_id, known = self._channels[topic]
            if known != type_name:
                raise ValueError(f"topic {topic!r} is {known}, cannot record {type_name} on it")
            return channel_id, self._schemas[type_name][1]
        if type_name not in self._schemas:
            text = full_definition(type_name)
            encoder = self._cdr.encoder(type_name, text)   # before registering
            schema_id = self._writer.register_schema(type_name, "ros2msg", text.encode())
            self._schemas[type_name] = (schema_id, encoder)
        schema_id, encoder = self._schemas[type_name]
        channel_id = self._writer.register_channel(
            topic, "cdr", schema_id,
            metadata={"offered_qos_profiles": offered_qos_yaml(transient_local)})
        self._channels[topic] = (channel_id, type_name)
        return channel_id, encoder


def _service_event(event_type, request, response, sequence_number, stamp_ns, client_gid):
    """A service event (``pkg/srv/S_Event``, or an action's service's) as plain data."""
    if len(client_gid) != 16:
        raise ValueError(f"client_gid must be 16 bytes, got {len(client_gid)}")
    return {
        "info": {"event_type": event_type,
                 "stamp": {"sec": stamp_ns // 10**9, "nanosec": stamp_ns % 10**9},
                 "client_gid": bytes(client_gid), "sequence_number": sequence_number},
        "request": [] if request is None else [request],
        "response": [] if response is None else [response],
    }


class _DecoderFactory(DecoderFactory):
    """mcap_ros2's decoders; schemas of files recorded with rosbag2's service names
    (``pkg/srv/S_Event``) are fed to them aliased (``mcap_ros2_alias``); for files recorded
    since, the alias changes nothing."""

    def decoder_for(self, message_encoding, schema):
        if schema is not None and schema.encoding == "ros2msg":
            schema = Schema(id=schema.id, name=mcap_ros2_alias(schema.name),
                            encoding=schema.encoding,
                            data=mcap_ros2_alias(schema.data.decode()).encode())
        return super().decoder_for(message_encoding, schema)


def check_recording(path) -> tuple[int, bool]:
    """(size in bytes, complete) of the MCAP file ``path``; NotARecording if it is empty, not
    a regular file or does not start with the MCAP magic (FileNotFoundError if missing).
    ``complete``: it also ends with the magic (closed properly; a killed run's does not)."""
    path = Path(path)
    if path.is_dir():
        raise NotARecording("a directory, not an MCAP file")
    with open(path, "rb") as f:
        head = f.read(len(MAGIC))
        size = f.seek(0, os.SEEK_END)
        if size == 0:
            raise NotARecording("empty (0 bytes): not a recording")
        if head != MAGIC:
            raise NotARecording(f"not an MCAP file (it does not start with the MCAP magic; "
                                f"first bytes {head[:8]!r})")
        return size, _ends_with_magic(f)


def scan_records(path, decode: bool):
    """(schema, channel, message, decoded or None) in file order, by linear scan.

    A killed writer leaves a torn last record: the scan stops there quietly (chunk CRCs are
    checked, so a torn chunk is dropped whole, never half-decoded). The same errors in a
    complete file (one that ends with the MCAP magic) are real damage, raised as
    NotARecording ("damaged MCAP data: ..."), as is any other error of mcap or mcap_ros2
    reading the file's bytes (the file is the cause, whatever the type). No record is read
    beyond the file's size (a corrupt length cannot make it allocate more).
    """
    with open(path, "rb") as f:
        size = f.seek(0, os.SEEK_END)
        f.seek(0)
        yield from _scan_file(f, size, decode)


def _scan_file(f, size, decode):
    reader = NonSeekingReader(f, validate_crcs=True, decoder_factories=[_DecoderFactory()],
                              record_size_limit=max(size, 1))
    records = (reader.iter_decoded_messages(log_time_order=False) if decode else
               (r + (None,) for r in reader.iter_messages(log_time_order=False)))
    try:
        yield from records
    except (EndOfFile, CRCValidationError, RecordLengthLimitExceeded, struct.error) as exc:
        if _ends_with_magic(f):   # not a torn tail: damage
            raise NotARecording(f"damaged MCAP data: {exception_line(exc, 120)}") from exc
    except Exception as exc:  # noqa: BLE001 - mcap's and mcap_ros2's many error types
        raise NotARecording(f"damaged MCAP data: {exception_line(exc, 120)}") from exc


def _ends_with_magic(f) -> bool:
    """True if the file is complete: a finished MCAP ends with the magic that starts it."""
    if f.seek(0, os.SEEK_END) < 2 * len(MAGIC):
        return False
    f.seek(-len(MAGIC), os.SEEK_END)
    return f.read() == MAGIC


def read_run(path) -> list[tuple[str, str, object, int]]:
    """All messages of a run file as (topic, type name, decoded message, log time ns), in
    log-time order (stable). Also reads files of killed runs (no summary, torn tail). Type
    names are rosidl's (``nav_msgs/srv/GetPlan_Event``,
    ``pkg/action/A_SendGoal_Event``, whatever the file calls them).

    Messages are mcap_ros2's decoded objects (attributes named like the fields; nested
    messages as objects, arrays as lists; ``char`` decoded as int8 by mcap_ros2).
    """
    out = [(c.topic, rosidl_type(s.name), m, msg.log_time)
           for s, c, msg, m in scan_records(path, decode=True)]
    out.sort(key=lambda item: item[3])
    return out


@dataclass(frozen=True)
class Recovery:
    """What ``recover`` did: messages and topics copied, whether the source was complete
    already, bytes of the source after its last readable message (a torn tail, or the
    summary of a complete file), schemas renamed to the current service names, and for
    an incomplete source whether its writer had begun the summary (``summary_begun``: a
    DataEnd record follows the messages, so the recording was being closed when a write
    failed, e.g. a full disk; without it the file just stops: a kill, a power cut, or a
    write that failed earlier)."""

    messages: int
    topics: int
    complete: bool
    dropped_bytes: int
    renamed_schemas: tuple
    summary_begun: bool = False


def recover(src, dst) -> Recovery:
    """Copy the readable messages of ``src`` (e.g. a killed run) to a complete file ``dst``
    (summary, indexes, footer) that rosbag2, rosbags and mcap's indexed reader open. Schemas
    of older files named as rosbag2 names service events (``pkg/srv/S_Event``) are renamed
    (``ros_schemas.recorded_type``; same bytes). ``dst`` is written in full or not at all (a
    temporary file renamed at the end). NotARecording if ``src`` is not an MCAP recording
    or holds no readable message."""
    size, complete = check_recording(src)
    src, dst = Path(src), Path(dst)
    if dst.exists() and dst.resolve() == src.resolve():
        raise NotARecording(f"the output {dst} is the file being recovered")
    count, end = 0, len(MAGIC)
    schema_ids, channel_ids, renamed = {}, {}, []
    tmp = dst.with_name(f".{dst.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as out:
            writer = Writer(out, compression=CompressionType.NONE)
            writer.start(profile="ros2", library=LIBRARY)
            with open(src, "rb") as f:
                for schema, channel, message, _ in _scan_file(f, size, decode=False):
                    if schema is not None and schema.id not in schema_ids:
                        name, data = schema.name, schema.data
                        if schema.encoding == "ros2msg" and recorded_type(name) != name:
                            try:
                                name = recorded_type(schema.name)
                                data = full_definition(name).encode()
                                renamed.append(schema.name)
                            except (LookupError, OSError, ValueError):
                                name, data = schema.name, schema.data  # not installed here
                        schema_ids[schema.id] = writer.register_schema(name, schema.encoding,
                                                                       data)
                    if channel.id not in channel_ids:
                        channel_ids[channel.id] = writer.register_channel(
                            channel.topic, channel.message_encoding,
                            schema_ids[schema.id] if schema is not None else 0,
                            metadata=dict(channel.metadata))
                    writer.add_message(channel_id=channel_ids[channel.id],
                                       log_time=message.log_time, data=message.data,
                                       publish_time=message.publish_time,
                                       sequence=message.sequence)
                    count += 1
                    end = f.tell()
                begun = not complete and _data_end_after(f, end, size)
            if count == 0:
                raise NotARecording("no complete message (an MCAP file cut off before its "
                                    "first message, or an empty recording): nothing to recover")
            writer.finish()
            out.flush()
            os.fsync(out.fileno())
        os.replace(tmp, dst)
    finally:
        tmp.unlink(missing_ok=True)
    return Recovery(messages=count, topics=len(channel_ids), complete=complete,
                    dropped_bytes=max(0, size - end), renamed_schemas=tuple(renamed),
                    summary_begun=begun)


def _data_end_after(f, offset, size) -> bool:
    """Whether a DataEnd record follows ``offset`` in ``f`` (before the torn end, if any):
    the writer's ``finish`` had begun."""
    f.seek(offset)
    try:
        for record in StreamReader(f, skip_magic=True, emit_chunks=True,
                                   record_size_limit=max(size, 1)).records:
            if isinstance(record, DataEnd):
                return True
    except Exception:  # noqa: BLE001 - the torn end, whatever mcap makes of it
        pass
    return False


def recover_run(src, dst) -> int:
    """``recover(src, dst)``; the number of messages copied."""
    return recover(src, dst).messages
