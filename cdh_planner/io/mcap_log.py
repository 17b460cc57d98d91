"""Run recording: ROS 2 messages to MCAP files that rosbag2, Foxglove, mcap_ros2 and rosbags open.

File layout (MCAP ``ros2`` profile, as rosbag2's MCAP storage writes it): one ``ros2msg``
schema per type named ``pkg/msg/Type`` with the full definition (see ``ros_schemas``), one
``cdr`` channel per topic with ``offered_qos_profiles`` metadata, a statistics record. No
``rosbag2`` metadata record (optional, and if present it must be complete).

Messages are CDR-encoded from the schema text by mcap_ros2's encoder, never by
``rclpy.serialization`` (its buffers can carry rmw's padding, which rosbags rejects).
``mcap_ros2.writer.Writer`` wraps that same encoder but can neither attach channel metadata
nor finish a chunk on demand, so the container is written with ``mcap.writer.Writer``.

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
- ``recover_run(src, dst)`` rewrites it with a summary, after which all of them open it.

SIGTERM/SIGKILL leave such a truncated file; SIGINT raises KeyboardInterrupt, so a ``with``
block closes the file properly. Signal handling is the node's business: it calls ``close()``.
"""

import os
import struct
import threading
import time
from pathlib import Path

from mcap.exceptions import EndOfFile
from mcap.reader import NonSeekingReader
from mcap.records import Schema
from mcap.stream_reader import CRCValidationError
from mcap.writer import CompressionType, Writer
from mcap_ros2._dynamic import serialize_dynamic
from mcap_ros2.decoder import DecoderFactory

from .ros_schemas import encodable, full_definition, mcap_ros2_alias, split_type_name, \
    type_name_of

# service_msgs/msg/ServiceEventInfo event types
REQUEST_SENT, REQUEST_RECEIVED, RESPONSE_SENT, RESPONSE_RECEIVED = 0, 1, 2, 3
SERVICE_EVENT_SUFFIX = "/_service_event"
LIBRARY = "cdh_planner mcap_log"
MAGIC = b"\x89MCAP0\r\n"     # starts and ends every MCAP file


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
    executor and from the planning thread.
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
        self._channels: dict[str, tuple[int, str]] = {}     # topic -> (channel id, type)
        self._lock = threading.Lock()
        self._closed = False

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
        if len(client_gid) != 16:
            raise ValueError(f"client_gid must be 16 bytes, got {len(client_gid)}")
        log_time_ns = time.time_ns() if log_time_ns is None else log_time_ns
        stamp_ns = log_time_ns if stamp_ns is None else stamp_ns
        event = {
            "info": {"event_type": event_type,
                     "stamp": {"sec": stamp_ns // 10**9, "nanosec": stamp_ns % 10**9},
                     "client_gid": bytes(client_gid), "sequence_number": sequence_number},
            "request": [] if request is None else [request],
            "response": [] if response is None else [response],
        }
        self._write(service_name.rstrip("/") + SERVICE_EVENT_SUFFIX,
                    f"{pkg}/srv/{name}_Event", event, log_time_ns, False)

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
            data = encoder(encodable(msg, type_name))
            self._writer.add_message(channel_id=channel_id, log_time=log_time_ns,
                                     data=data, publish_time=log_time_ns)
            self._writer.flush()     # finishes the chunk and flushes the file: kill-safe

    def _channel(self, topic, type_name, transient_local):
        """(channel id, encoder) for ``topic``, registering schema and channel on first use."""
        if topic in self._channels:
            channel_id, known = self._channels[topic]
            if known != type_name:
                raise ValueError(f"topic {topic!r} is {known}, cannot record {type_name} on it")
            return channel_id, self._schemas[type_name][1]
        if type_name not in self._schemas:
            text = full_definition(type_name)
            schema_id = self._writer.register_schema(type_name, "ros2msg", text.encode())
            alias = mcap_ros2_alias(type_name)
            encoder = serialize_dynamic(alias, mcap_ros2_alias(text))[alias]
            self._schemas[type_name] = (schema_id, encoder)
        schema_id, encoder = self._schemas[type_name]
        channel_id = self._writer.register_channel(
            topic, "cdr", schema_id,
            metadata={"offered_qos_profiles": offered_qos_yaml(transient_local)})
        self._channels[topic] = (channel_id, type_name)
        return channel_id, encoder


class _DecoderFactory(DecoderFactory):
    """mcap_ros2's decoders, fed aliased schemas so that service types parse (see
    ``mcap_ros2_alias``); decoded classes are named after the alias (``GetPlanEvent``)."""

    def decoder_for(self, message_encoding, schema):
        if schema is not None and schema.encoding == "ros2msg":
            schema = Schema(id=schema.id, name=mcap_ros2_alias(schema.name),
                            encoding=schema.encoding,
                            data=mcap_ros2_alias(schema.data.decode()).encode())
        return super().decoder_for(message_encoding, schema)


def scan_records(path, decode: bool):
    """(schema, channel, message, decoded or None) in file order, by linear scan.

    A killed writer leaves a torn last record: the scan stops there quietly (chunk CRCs are
    checked, so a torn chunk is dropped whole, never half-decoded). The same errors in a
    complete file (one that ends with the MCAP magic) are real damage and are raised.
    """
    with open(path, "rb") as f:
        reader = NonSeekingReader(f, validate_crcs=True, decoder_factories=[_DecoderFactory()])
        records = (reader.iter_decoded_messages(log_time_order=False) if decode else
                   (r + (None,) for r in reader.iter_messages(log_time_order=False)))
        try:
            yield from records
        except (EndOfFile, CRCValidationError, struct.error):
            if _ends_with_magic(f):
                raise


def _ends_with_magic(f) -> bool:
    """True if the file is complete: a finished MCAP ends with the magic that starts it."""
    if f.seek(0, os.SEEK_END) < 2 * len(MAGIC):
        return False
    f.seek(-len(MAGIC), os.SEEK_END)
    return f.read() == MAGIC


def read_run(path) -> list[tuple[str, str, object, int]]:
    """All messages of a run file as (topic, type name, decoded message, log time ns), in
    log-time order (stable). Also reads files of killed runs (no summary, torn tail).

    Messages are mcap_ros2's decoded objects (attributes named like the fields; nested
    messages as objects, arrays as lists; ``char`` decoded as int8 by mcap_ros2).
    """
    out = [(c.topic, s.name, m, msg.log_time) for s, c, msg, m in scan_records(path, decode=True)]
    out.sort(key=lambda item: item[3])
    return out


def recover_run(src, dst) -> int:
    """Copy the readable messages of ``src`` (e.g. a killed run) to a complete file ``dst``
    (summary, indexes, footer) that rosbag2 and rosbags open. Returns the message count."""
    count = 0
    schema_ids, channel_ids = {}, {}
    with open(dst, "wb") as out:
        writer = Writer(out, compression=CompressionType.NONE)
        writer.start(profile="ros2", library=LIBRARY)
        for schema, channel, message, _ in scan_records(src, decode=False):
            if schema is not None and schema.id not in schema_ids:
                schema_ids[schema.id] = writer.register_schema(
                    schema.name, schema.encoding, schema.data)
            if channel.id not in channel_ids:
                channel_ids[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding,
                    schema_ids[schema.id] if schema is not None else 0,
                    metadata=dict(channel.metadata))
            writer.add_message(channel_id=channel_ids[channel.id], log_time=message.log_time,
                               data=message.data, publish_time=message.publish_time,
                               sequence=message.sequence)
            count += 1
        writer.finish()
    return count
