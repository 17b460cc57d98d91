"""Replaying a recorded run (an MCAP file of the node, or any ros2-profile MCAP).

- ``replay_topics``: republish the recorded messages with their original timing (scaled by
  ``rate``; no wait longer than ``max_gap_s``), each topic with its recorded type and QoS
  (latched topics stay latched). The CDR bytes are published as recorded
  (``Publisher.publish(bytes)``), so nothing is decoded and re-encoded on the way. Service
  event topics (``.../_service_event``, an action's ``.../_action/send_goal/_service_event``
  and ``.../get_result/_service_event`` included) are not republished: they are the
  recorded calls, which ``--requests`` re-sends; nor is ``/parameter_events`` unless asked
  for (it would tell every listener that the node's parameters changed).
- ``recorded_plans`` + ``ParameterSetter`` + ``compare_paths`` / ``compare_results``: the
  recorded GetPlan requests and responses and PlanPath goals and results, in recorded
  order, with the parameters in effect at each, to re-send to a live node (after applying
  the recorded parameter changes) and compare the answers pose by pose (and, for goals,
  by error code). ``goal_to_replay``: what is sent for a recorded goal (one with
  ``use_current_start`` starts from the recorded path's first pose).

Killed runs (no summary, torn tail) are read too (``recording.mcap_log``'s linear scan); what is
not a recording is refused (InputError, with the reason).
"""

import copy
import importlib
import math
import time
from dataclasses import dataclass, field
from typing import Optional

import numpy as np
from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message

from cdh_planner_interfaces.action import PlanPath

from ..errors import InputError, exception_line
from ..model.pose import rotation_angle_between, rotation_from_quaternion
from ..recording.mcap_log import ACTION_INFIX, GET_RESULT, REQUEST_RECEIVED, RESPONSE_SENT, \
    SEND_GOAL, SERVICE_EVENT_SUFFIX, NotARecording, check_recording
from ..recording.mcap_log import scan_records as scan_run  # raw records of a (possibly killed) run file
from ..recording.ros_schemas import rosidl_type
from .execution.command_outlets import command_topic_parameters
from .msgs.messages import path_arrays
from .interface import CABLE_COMMAND, OBSTACLES, SERVICE_QOS
from .core.run_log import PARAMETER_EVENTS


MATCH_SETTLE_S = 0.3   # s after the publisher sees its subscribers, before the first message
MAX_GAP_S = 5.0        # default longest wait between two republished messages (s)
# the parameters that decide a plan's answer (the others: streaming, recording)
ANSWER_PREFIXES = ("robot.", "task.", "planner.", "trajectory.")
ANSWER_PARAMETERS = ("base_frame", "scene_file")
SCENE_TYPE = "cdh_planner_interfaces/msg/Scene"   # the node's ~/scene (node/scene.py)


# the recorded PlanPath goals and results (recording.mcap_log.RunRecorder.write_action_event)
PLAN_PATH_TYPE = "cdh_planner_interfaces/action/PlanPath"
GOAL_SUFFIX = f"{ACTION_INFIX}{SEND_GOAL}{SERVICE_EVENT_SUFFIX}"
RESULT_SUFFIX = f"{ACTION_INFIX}{GET_RESULT}{SERVICE_EVENT_SUFFIX}"
ERROR_CODE_NAMES = {getattr(PlanPath.Result, n): n for n in dir(PlanPath.Result)
                    if n.isupper() and isinstance(getattr(PlanPath.Result, n), int)}
CANCELED, BUSY = PlanPath.Result.CANCELED, PlanPath.Result.BUSY


@dataclass(frozen=True)
class Record:
    topic: str
    type_name: str     # pkg/msg/Type (pkg/srv/S_Event, pkg/action/A_SendGoal_Event for events)
    data: bytes        # CDR, as recorded
    log_time_ns: int
    transient_local: bool
    encoding: str = "cdr"   # the channel's message encoding


def read_records(path):
    """Every message of the run file ``path``, in log-time order. InputError (naming the
    file, one line) if it is not a recording: missing, empty, not MCAP, damaged, no complete
    message, or a channel that is not CDR-encoded ROS 2."""
    try:
        check_recording(path)
        out = [Record(topic=c.topic, type_name=rosidl_type(s.name) if s is not None else "",
                      data=bytes(m.data), log_time_ns=m.log_time,
                      transient_local="durability: transient_local"
                      in c.metadata.get("offered_qos_profiles", ""),
                      encoding=c.message_encoding)
               for s, c, m, _ in scan_run(path, decode=False)]
    except FileNotFoundError:
        raise InputError("RUN", str(path), "file not found") from None
    except NotARecording as exc:
        raise InputError("RUN", str(path), str(exc)) from None
    except Exception as exc:  # noqa: BLE001 - mcap's many error types
        raise InputError("RUN", str(path), f"not a readable MCAP run file: "
                                           f"{exception_line(exc)}") from None
    if not out:
        raise InputError("RUN", str(path), "no complete message (an MCAP file cut off before "
                                           "its first message, or an empty recording)")
    other = next((r for r in out if r.encoding != "cdr" or not r.type_name), None)
    if other is not None:
        raise InputError("RUN", str(path), f"not a ROS 2 recording: topic {other.topic} is "
                                           f"{other.encoding!r} without a ros2msg schema"
                         if other.encoding == "cdr" else
                         f"not a ROS 2 recording: topic {other.topic} is encoded as "
                         f"{other.encoding!r}, not CDR")
    return sorted(out, key=lambda r: r.log_time_ns)


def message_class(type_name):
    """The rosidl Python class of ``pkg/msg/Type``, ``pkg/srv/S_Event`` or one of the types
    of an action (``pkg/action/A_Goal``, ``pkg/action/A_SendGoal_Event`` ...) (InputError if
    the package is not installed)."""
    parts = type_name.split("/")
    if len(parts) != 3:
        raise InputError("type", type_name, "expected pkg/msg/Type")
    pkg, kind, name = parts
    try:
        module = importlib.import_module(f"{pkg}.{kind}")
        if kind == "srv" and name.endswith("_Event"):
            return getattr(module, name[: -len("_Event")]).Event
        if kind == "action" and not hasattr(module, name) and "_" in name:
            action, part = name.split("_", 1)
            cls = getattr(module, action)
            if part in ("Goal", "Result", "Feedback"):
                return getattr(cls, part)
            if part == "FeedbackMessage":
                return cls.Impl.FeedbackMessage
            service, member = part.split("_", 1)
            return getattr(getattr(cls.Impl, f"{service}Service"), member)
        return getattr(module, name)
    except (ImportError, AttributeError, ValueError):
        raise InputError("type", type_name, "message type not installed here") from None


def is_service_event(record):
    return record.topic.endswith(SERVICE_EVENT_SUFFIX)


# topics that move the robot: the node's winch stream, and the latched trajectory of
# recordings made before it became display-only (a JointTrajectoryController executed it)
COMMAND_TOPICS = (CABLE_COMMAND, "cable_trajectory")


def is_command_topic(topic):
    """Does ``topic`` move the robot (``COMMAND_TOPICS``)?"""
    return topic.rsplit("/", 1)[-1] in COMMAND_TOPICS


def command_topics(records):
    """The topics of ``records`` that move the robot: ``is_command_topic``, and those the
    recorded parameters name as a streamed command outlet's topic (forward_command's
    ``execution.forward_command_topic``, any registered outlet's: its value in the
    parameter snapshot a run file begins with, or a later change), resolved as the node
    resolved them (relative: in the node's namespace; ``~/``: under the node)."""
    from rcl_interfaces.msg import ParameterEvent
    names, named = command_topic_parameters(), set()
    for r in records:
        if r.topic == PARAMETER_EVENTS and r.type_name == "rcl_interfaces/msg/ParameterEvent":
            event = deserialize_message(r.data, ParameterEvent)
            named |= {_resolved(p.value.string_value, event.node)
                      for p in (*event.new_parameters, *event.changed_parameters)
                      if p.name in names}
    return {r.topic for r in records if is_command_topic(r.topic) or r.topic in named}


def _resolved(name, node):
    """The topic ``name`` as the node ``node`` (/ns/node) resolves it."""
    if name.startswith("/"):
        return name
    if name.startswith("~/"):
        return f"{node.rstrip('/')}/{name[2:]}"
    return f"{node.rsplit('/', 1)[0]}/{name}"


def select_topics(records, topics=None, commands=False):
    """The records to republish: no service events, no ``/parameter_events`` nor a node's
    ``~/obstacles`` unless named (each would change a live node), and no command topic
    (``command_topics``) unless ``commands``: on a live system a
    replayed command would move the robot. Only ``topics`` if given (InputError naming a
    topic that is not in the file, or a command topic without ``commands``)."""
    available = sorted({r.topic for r in records if not is_service_event(r)})
    moving = command_topics(records)
    if topics:
        missing = [t for t in topics if t not in available]
        if missing:
            raise InputError("--topics", missing[0],
                             f"not a recorded topic (recorded: {', '.join(available)})")
        blocked = [t for t in topics if t in moving and not commands]
        if blocked:
            raise InputError("--topics", blocked[0], "a command topic (it moves the robot): "
                                                     "add --commands to republish it")
        wanted = set(topics)
    else:
        wanted = {t for t in available if commands or t not in moving} - {PARAMETER_EVENTS}
        wanted = {t for t in wanted if not t.endswith(f"/{OBSTACLES}")}   # the node's input
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
    capped: int = 0     # waits cut to max_gap_s
    skipped_s: float = 0.0   # replay time those cuts saved (s)


def schedule(records, rate=1.0, max_gap_s=MAX_GAP_S):
    """(offsets, capped, skipped_s): when to publish each record, in s after the first: the
    recorded intervals / ``rate``, each cut to ``max_gap_s``; how many were cut, and by how
    much in all."""
    offsets, capped, skipped, t = [], 0, 0.0, 0.0
    previous = records[0].log_time_ns if records else 0
    for r in records:
        gap = (r.log_time_ns - previous) * 1e-9 / rate
        previous = r.log_time_ns
        if gap > max_gap_s:
            capped += 1
            skipped += gap - max_gap_s
            gap = max_gap_s
        t += max(gap, 0.0)
        offsets.append(t)
    return offsets, capped, skipped


def replay_topics(node, records, rate=1.0, delay_s=1.0, clock=time.monotonic,
                  sleep=time.sleep, max_gap_s=MAX_GAP_S):
    """Publish ``records`` on ``node`` at their recorded times / ``rate``, never waiting more
    than ``max_gap_s`` between two. The first goes out when every topic has a subscriber, or
    after ``delay_s`` (s) without; at the end, waits (up to 2 s) for subscribers to
    acknowledge. Returns ReplayStats."""
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
    offsets, capped, skipped = schedule(records, rate, max_gap_s)
    start = clock()
    late = 0.0
    first = last = None
    for r, offset in zip(records, offsets):
        due = start + offset
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
                       recorded_s=(records[-1].log_time_ns - records[0].log_time_ns) * 1e-9,
                       replay_s=last - first, late_s=late, capped=capped, skipped_s=skipped)


def decides_answers(name):
    """True for the parameters that decide a plan's answer (``replay --requests`` applies
    them); streaming and recording parameters do not."""
    return name in ANSWER_PARAMETERS or name.startswith(ANSWER_PREFIXES)


@dataclass
class RecordedPlan:
    """A recorded plan call: a GetPlan request and its response, or (``action``) a PlanPath
    goal and its result."""

    sequence: int               # the node's call number (GetPlan and PlanPath alike)
    service: str                # the GetPlan service, or the PlanPath action
    request: object             # nav_msgs/srv/GetPlan.Request, or PlanPath.Goal
    response: Optional[object]  # GetPlan.Response or PlanPath.Result; None: the run ended
    # the recorded parameter sets (each a list of rcl_interfaces/msg/Parameter, one per
    # accepted set call; the first may be the file's snapshot) since the previous request,
    # only those that decide answers
    parameter_sets: list = field(default_factory=list)
    # name -> rcl_interfaces/msg/Parameter in effect at this request (answer-deciding ones)
    parameters: dict = field(default_factory=dict)
    action: bool = False        # a PlanPath goal (through the action), not a GetPlan call
    scene: object = None        # the node's last recorded Scene before it (None: none recorded)

    @property
    def label(self):
        """"request 3" (GetPlan) or "goal 4" (PlanPath), as replay prints it."""
        return f"{'goal' if self.action else 'request'} {self.sequence}"


def node_of(service):
    """``/ns/node`` of a service ``/ns/node/plan``."""
    return service.rsplit("/", 1)[0] or "/"


def recorded_plans(records):
    """The recorded plan calls in recorded order: GetPlan calls (request, response) and
    PlanPath goals (goal, result), each paired by its sequence number (the node's call
    number), each with the parameters recorded for its node since the previous call
    (``/parameter_events``: the snapshot a file begins with, then each accepted change)."""
    from nav_msgs.srv import GetPlan
    from rcl_interfaces.msg import ParameterEvent
    calls = {}
    pending = {}     # node -> parameter sets recorded since its last request
    state = {}       # node -> name -> Parameter
    scenes = {}      # node -> its last recorded Scene
    for r in records:
        if r.type_name == SCENE_TYPE and r.topic.endswith("/scene"):
            from cdh_planner_interfaces.msg import Scene
            scenes[node_of(r.topic)] = deserialize_message(r.data, Scene)
            continue
        if r.topic == PARAMETER_EVENTS and r.type_name == "rcl_interfaces/msg/ParameterEvent":
            event = deserialize_message(r.data, ParameterEvent)
            params = [p for p in (*event.new_parameters, *event.changed_parameters)
                      if decides_answers(p.name)]
            if params:
                pending.setdefault(event.node, []).append(params)
                state.setdefault(event.node, {}).update({p.name: p for p in params})
            continue
        if not is_service_event(r):
            continue
        if r.type_name == "nav_msgs/srv/GetPlan_Event":
            event = deserialize_message(r.data, GetPlan.Event)
            service, action = r.topic[: -len(SERVICE_EVENT_SUFFIX)], False
            request, response = event.request, event.response
        elif r.type_name == f"{PLAN_PATH_TYPE}_SendGoal_Event" and r.topic.endswith(GOAL_SUFFIX):
            event = deserialize_message(r.data, PlanPath.Impl.SendGoalService.Event)
            service, action = r.topic[: -len(GOAL_SUFFIX)], True
            request, response = [q.goal for q in event.request], []
        elif r.type_name == f"{PLAN_PATH_TYPE}_GetResult_Event" and \
                r.topic.endswith(RESULT_SUFFIX):
            event = deserialize_message(r.data, PlanPath.Impl.GetResultService.Event)
            service, action = r.topic[: -len(RESULT_SUFFIX)], True
            request, response = [], [a.result for a in event.response]
        else:
            continue
        seq = int(event.info.sequence_number)
        key = (service, action, seq)
        if event.info.event_type == REQUEST_RECEIVED and request:
            node = node_of(service)
            calls[key] = RecordedPlan(seq, service, request[0], None, pending.pop(node, []),
                                      dict(state.get(node, {})), action=action,
                                      scene=scenes.get(node))
        elif event.info.event_type == RESPONSE_SENT and response and key in calls:
            calls[key].response = response[0]
    return list(calls.values())


def goal_to_replay(plan):
    """(PlanPath.Goal to send, note) for the recorded goal ``plan``: the goal as recorded,
    except that one with ``use_current_start`` (planned from the pose the recording's node
    measured, which the goal does not hold) starts from the recorded path's first pose, with
    use_current_start off: the start the recording's node planned from. Without a recorded
    path it is sent as recorded (the node then plans from its own measured lengths, if any).
    ``note`` says which, for the output line ("" for an ordinary goal)."""
    goal = plan.request
    if not goal.use_current_start:
        return goal, ""
    path = plan.response.path if plan.response is not None else None
    if path is None or not path.poses:
        return goal, ("use_current_start, sent as recorded: the measured start is not "
                      "recorded, and no recorded path to take it from")
    start = copy.deepcopy(path.poses[0])
    start.header.frame_id = path.header.frame_id or start.header.frame_id
    return (PlanPath.Goal(start=start, goal=goal.goal, use_current_start=False,
                          strategy=goal.strategy, timeout_s=goal.timeout_s),
            "use_current_start: replayed from the recorded path's first pose (the measured "
            "start is not recorded)")


def error_code_name(code):
    """``TF_ERROR`` for 202 (PlanPath.Result's constants), or the number."""
    return ERROR_CODE_NAMES.get(int(code), str(code))


def compare_results(recorded, new, tolerance_m=1e-6, tolerance_rad=1e-6):
    """(match, text): do two PlanPath results agree: the same error code, and paths pose by
    pose (``compare_paths``)?"""
    same_code = int(recorded.error_code) == int(new.error_code)
    ok, text = compare_paths(recorded.path, new.path, tolerance_m, tolerance_rad)
    code = (f"error code {error_code_name(new.error_code)} as recorded" if same_code else
            f"error code {error_code_name(recorded.error_code)} recorded, "
            f"{error_code_name(new.error_code)} now")
    return same_code and ok, f"{code}; {text}"


def parameter_value(msg):
    """The Python value of a rcl_interfaces/msg/Parameter (lists for arrays)."""
    from rclpy.parameter import parameter_value_to_python
    value = parameter_value_to_python(msg.value)
    return list(value) if hasattr(value, "__len__") and not isinstance(value, str) else value


def parameter_differences(recorded, live, limit=3):
    """Text naming the parameters whose ``live`` value (name -> Python value) differs from
    the ``recorded`` one (name -> rcl_interfaces/msg/Parameter); "" if none."""
    from ..errors import short_repr
    from .core.params import _same
    diffs = [f"{name} is {short_repr(live.get(name), 40)} here, "
             f"{short_repr(parameter_value(msg), 40)} in the recording"
             for name, msg in sorted(recorded.items())
             if not _same(parameter_value(msg), _plain(live.get(name)))]
    if len(diffs) > limit:
        diffs = diffs[:limit] + [f"and {len(diffs) - limit} more"]
    return "; ".join(diffs)


def _plain(value):
    return list(value) if hasattr(value, "__len__") and not isinstance(value, str) else value


def settable(params):
    """The parameters of ``params`` that can be set on a node (a NOT_SET value would
    undeclare the parameter instead), and the names of the others."""
    from rcl_interfaces.msg import ParameterType
    ok = [p for p in params if p.value.type != ParameterType.PARAMETER_NOT_SET]
    return ok, [p.name for p in params if p.value.type == ParameterType.PARAMETER_NOT_SET]


class ParameterSetter:
    """Sets recorded parameters on the node ``client`` (a PlannerClient) talks to: each
    recorded set in one atomic call, as the recording node accepted it, so that the node
    rebuilds its planner exactly where the recording's did. Parameters the node does not
    declare, or recorded as not set (setting that would undeclare them), are left out."""

    def __init__(self, client, timeout_s):
        from rclpy.parameter_client import AsyncParameterClient
        self._client = client
        self._params = AsyncParameterClient(client.node, client.target, qos_profile=SERVICE_QOS)
        self._timeout = timeout_s
        self._names = None

    def _wait(self, future, what):
        from .client import ClientError
        if not self._client.spin_until(future.done, self._timeout):
            raise ClientError(f"{self._client.target}: {what} timed out")
        return future.result()

    def declared(self):
        """The names of the node's parameters."""
        from .client import ClientError
        if self._names is None:
            if not self._params.wait_for_services(timeout_sec=self._timeout):
                raise ClientError(f"no parameter services on {self._client.target}")
            result = self._wait(self._params.list_parameters(), "list_parameters")
            self._names = set(result.result.names)
        return self._names

    def set(self, params):
        """(names set, problems): set ``params`` (rcl_interfaces/msg/Parameter) in one atomic
        call; ``problems`` says what was left out or refused ("" if nothing)."""
        declared = self.declared()
        ok, unset = settable([p for p in params if p.name in declared])
        problems = []
        missing = sorted(p.name for p in params if p.name not in declared)
        if missing:
            problems.append(f"not on this node: {', '.join(missing[:3])}"
                            + (f" and {len(missing) - 3} more" if len(missing) > 3 else ""))
        unset = [n for n, v in self.get(unset).items() if v is not None] if unset else []
        if unset:       # not set in the recording, set on the node: ROS cannot unset them
            problems.append(f"recorded as not set, cannot be unset: {', '.join(unset[:3])}")
        if not ok:
            return [], "; ".join(problems)
        result = self._wait(self._params.set_parameters_atomically(ok),
                            "set_parameters_atomically").result
        if not result.successful:
            return [], "; ".join(problems + [f"refused: {result.reason or 'no reason given'}"])
        return [p.name for p in ok], "; ".join(problems)

    def get(self, names):
        """name -> Python value of the node's parameters ``names``."""
        from rclpy.parameter import parameter_value_to_python
        names = [n for n in names if n in self.declared()]
        result = self._wait(self._params.get_parameters(names), "get_parameters")
        return {n: parameter_value_to_python(v) for n, v in zip(names, result.values)}


def call_number(values):
    """The node's call counter in a ``~/plan_result``'s ``run_id`` (``stem#7`` or ``7``), or
    None."""
    tail = str(values.get("run_id", "")).rsplit("#", 1)[-1]
    return int(tail) if tail.isdigit() else None


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
