"""Replaying a recorded run (an MCAP file of the node, or any ros2-profile MCAP).

- ``replay_topics``: republish the recorded messages with their original timing (scaled by
  ``rate``), each topic with its recorded type and QoS (latched topics stay latched). The
  CDR bytes are published as recorded (``Publisher.publish(bytes)``), so nothing is decoded
  and re-encoded on the way. Service event topics (``.../_service_event``) are not
  republished: they are the recorded calls, which ``--requests`` re-sends.
- ``recorded_plans`` + ``compare_paths``: the recorded GetPlan requests and responses, to
  re-send to a live node and compare the answers pose by pose.

Killed runs (no summary, torn tail) are read too (``io.mcap_log``'s linear scan).
"""

import importlib
import math
import time
from dataclasses import dataclass
from typing import Optional

import numpy as np
from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message

from ..errors import InputError
from ..model.pose import rotation_angle_between, rotation_from_quaternion
from ..io.mcap_log import REQUEST_RECEIVED, RESPONSE_SENT, SERVICE_EVENT_SUFFIX
from ..io.mcap_log import scan_records as scan_run  # raw records of a (possibly killed) run file
from ..io.ros_schemas import rosidl_type
from .messages import path_arrays


MATCH_SETTLE_S = 0.3   # s after the publisher sees its subscribers, before the first message


@dataclass(frozen=True)
class Record:
    topic: str
    type_name: str     # pkg/msg/Type (pkg/srv/S_Event for service events)
    data: bytes        # CDR, as recorded
    log_time_ns: int
    transient_local: bool


def read_records(path):
    """Every message of the run file ``path``, in log-time order; InputError if it is not a
    readable MCAP file."""
    try:
        out = [Record(topic=c.topic, type_name=rosidl_type(s.name) if s is not None else "",
                      data=bytes(m.data), log_time_ns=m.log_time,
                      transient_local="durability: transient_local"
                      in c.metadata.get("offered_qos_profiles", ""))
               for s, c, m, _ in scan_run(path, decode=False)]
    except FileNotFoundError:
        raise InputError("RUN", str(path), "file not found") from None
    except Exception as exc:  # noqa: BLE001 - mcap's many error types
        raise InputError("RUN", str(path), f"not a readable MCAP run file: {exc}") from None
    out.sort(key=lambda r: r.log_time_ns)
    return out


def message_class(type_name):
    """The rosidl Python class of ``pkg/msg/Type`` or ``pkg/srv/S_Event`` (InputError if the
    package is not installed)."""
    parts = type_name.split("/")
    if len(parts) != 3:
        raise InputError("type", type_name, "expected pkg/msg/Type")
    pkg, kind, name = parts
    try:
        module = importlib.import_module(f"{pkg}.{kind}")
        if kind == "srv" and name.endswith("_Event"):
            return getattr(module, name[: -len("_Event")]).Event
        return getattr(module, name)
    except (ImportError, AttributeError):
        raise InputError("type", type_name, "message type not installed here") from None


def is_service_event(record):
    return record.topic.endswith(SERVICE_EVENT_SUFFIX)


def select_topics(records, topics=None):
    """The records to republish: no service events; only ``topics`` if given (InputError
    naming a topic that is not in the file)."""
    available = sorted({r.topic for r in records if not is_service_event(r)})
    if topics:
        missing = [t for t in topics if t not in available]
        if missing:
            raise InputError("--topics", missing[0],
                             f"not a recorded topic (recorded: {', '.join(available)})")
        wanted = set(topics)
    else:
        wanted = set(available)
    return [r for r in records if r.topic in wanted]


def qos_of(record):
    if record.transient_local:
        return QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                          reliability=ReliabilityPolicy.RELIABLE)
    return QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


@dataclass
class ReplayStats:
    messages: int
    topics: int
    recorded_s: float   # span of the recorded log times
    replay_s: float     # wall time from the first to the last publish
    late_s: float       # worst lateness of a publish behind its schedule


def replay_topics(node, records, rate=1.0, delay_s=1.0, clock=time.monotonic,
                  sleep=time.sleep):
    """Publish ``records`` on ``node`` at their recorded times / ``rate``. The first goes out
    when every topic has a subscriber, or after ``delay_s`` (s) without; at the end, waits
    (up to 2 s) for subscribers to acknowledge. Returns ReplayStats."""
    if not records:
        return ReplayStats(0, 0, 0.0, 0.0, 0.0)
    publishers = {}
    for r in records:
        if r.topic not in publishers:
            publishers[r.topic] = node.create_publisher(message_class(r.type_name), r.topic,
                                                        qos_of(r))
    # wait (up to delay_s) until every topic has a subscriber, so the first messages reach them
    end = clock() + delay_s
    while clock() < end and not all(p.get_subscription_count() for p in publishers.values()):
        sleep(0.02)
    if any(p.get_subscription_count() for p in publishers.values()):
        # discovery is not symmetric: the subscriber may not know this publisher yet when
        # the publisher sees it, and would drop the first (volatile) messages
        sleep(MATCH_SETTLE_S)
    t_first = records[0].log_time_ns
    start = clock()
    late = 0.0
    first = last = None
    for r in records:
        due = start + (r.log_time_ns - t_first) * 1e-9 / rate
        wait = due - clock()
        if wait > 0:
            sleep(wait)
        now = clock()
        late = max(late, now - due)
        publishers[r.topic].publish(r.data)
        first = now if first is None else first
        last = now
    for p in publishers.values():   # reliable delivery of the last ones before we leave
        p.wait_for_all_acked(Duration(seconds=2.0))
    return ReplayStats(messages=len(records), topics=len(publishers),
                       recorded_s=(records[-1].log_time_ns - t_first) * 1e-9,
                       replay_s=last - first, late_s=late)


@dataclass
class RecordedPlan:
    sequence: int
    service: str
    request: object             # nav_msgs/srv/GetPlan.Request
    response: Optional[object]  # GetPlan.Response, None if the run ended before it


def recorded_plans(records):
    """The recorded GetPlan calls (request, response) in order, paired by sequence number."""
    from nav_msgs.srv import GetPlan
    calls = {}
    for r in records:
        if not (is_service_event(r) and r.type_name == "nav_msgs/srv/GetPlan_Event"):
            continue
        event = deserialize_message(r.data, GetPlan.Event)
        seq = int(event.info.sequence_number)
        service = r.topic[: -len(SERVICE_EVENT_SUFFIX)]
        if event.info.event_type == REQUEST_RECEIVED and event.request:
            calls[(service, seq)] = RecordedPlan(seq, service, event.request[0], None)
        elif event.info.event_type == RESPONSE_SENT and event.response \
                and (service, seq) in calls:
            calls[(service, seq)].response = event.response[0]
    return list(calls.values())


def compare_paths(recorded, new, tolerance_m=1e-6, tolerance_rad=1e-6):
    """(match, text): do two nav_msgs/Path agree pose by pose (same count, positions within
    ``tolerance_m``, orientations within ``tolerance_rad``, same frame)? Two empty paths
    agree (both "no plan")."""
    n_old, n_new = len(recorded.poses), len(new.poses)
    if n_old == 0 and n_new == 0:
        return True, "both no plan"
    if (n_old == 0) != (n_new == 0):
        return False, (f"recorded {'no plan' if n_old == 0 else f'{n_old} poses'}, now "
                       f"{'no plan' if n_new == 0 else f'{n_new} poses'}")
    if recorded.header.frame_id != new.header.frame_id:
        return False, f"frame {recorded.header.frame_id!r} then, {new.header.frame_id!r} now"
    if n_old != n_new:
        return False, f"{n_old} poses recorded, {n_new} now"
    p0, q0 = path_arrays(recorded)
    p1, q1 = path_arrays(new)
    dp = float(np.max(np.linalg.norm(p1 - p0, axis=1)))
    da = float(np.max(rotation_angle_between(rotation_from_quaternion(q0), rotation_from_quaternion(q1))))
    ok = dp <= tolerance_m and da <= tolerance_rad
    return ok, (f"{n_new} poses, max deviation {dp:.3g} m, {math.degrees(da):.3g} deg "
                f"({'within' if ok else 'beyond'} {tolerance_m:g} m / {tolerance_rad:g} rad)")
