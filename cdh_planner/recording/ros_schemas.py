"""ROS 2 message definitions (``ros2msg`` schemas) and plain-data views of messages.

No rclpy here: definitions are read from the installed ``share/<pkg>/msg|srv|action`` files
through the ament index, and messages are handled by duck typing (rosidl-generated Python
classes have ``get_fields_and_field_types``), so the recording layer stays importable without a ROS
graph.

Schema text layout (rosbag2's ``LocalMessageDefinitionSource``, MCAP ``ros2msg``): the type's
own text, then for each nested type, sorted by name, depth first, each once::

    <own text>
    ================================================================================
    MSG: geometry_msgs/PoseStamped
    <its text>...

Service types have no .msg files. ``pkg/srv/S_Request`` and ``_Response`` are the two halves
of ``S.srv``; ``pkg/srv/S_Event`` is the introspection message rosidl generates for every
service (``service_msgs/ServiceEventInfo info``, ``S_Request[<=1] request``,
``S_Response[<=1] response``).

Service types are recorded under names without the underscore: ``pkg/msg/SEvent``, with
the halves nested as ``pkg/SRequest`` and ``pkg/SResponse`` (``recorded_type``; the CDR
bytes are those of ``pkg/srv/S_Event``). rosbag2 itself names them ``pkg/srv/S_Event``, but
no stock reader decodes that name:

- mcap_ros2's rosidl parser accepts only ``[A-Z][A-Za-z0-9]*`` message names, in the schema
  name, ``MSG:`` headers and field types alike (``InvalidResourceName``);
- rosbags files a ``pkg/srv/T`` definition under ``pkg/srv/msg/T`` and then looks the
  channel's ``pkg/srv/T`` up and fails (``KeyError``; ``rosbags-convert``: "Type ... is
  unknown", exit 1);
- rosbag2's current source writes the schema as the raw .srv text behind a ``SRV:`` header,
  which neither of them (nor Foxglove / Lichtblick: ros2/rosbag2#2365, open) parses.

``pkg/msg/SEvent`` with an ordinary message definition decodes in all of them (and in
Foxglove). The cost: tools that go by the type name alone (``ros2 bag play``) do not find a
``pkg/msg/SEvent`` type and skip those topics. ``rosidl_type`` maps the recorded name back;
files recorded before (``pkg/srv/S_Event``, halves ``pkg/S_Request``) are still read
(``mcap_ros2_alias``), and ``recording.mcap_log.recover_run`` rewrites them to the new names.

Actions have no .msg files either. rosidl splits ``pkg/action/A.action`` at its ``---``
lines into ``A_Goal``, ``A_Result`` and ``A_Feedback``, and derives the two services an
action runs on (``rosidl_parser.definition.Action``)::

    A_SendGoal_Request    unique_identifier_msgs/UUID goal_id, A_Goal goal
    A_SendGoal_Response   bool accepted, builtin_interfaces/Time stamp
    A_GetResult_Request   unique_identifier_msgs/UUID goal_id
    A_GetResult_Response  int8 status, A_Result result
    A_SendGoal_Event, A_GetResult_Event   (info, request[<=1], response[<=1], as any service)
    A_FeedbackMessage     unique_identifier_msgs/UUID goal_id, A_Feedback feedback

All of them are generated classes rclpy (de)serializes (``pkg.action.A.Impl.SendGoalService
.Event`` ...). A goal and its result are recorded as rosbag2 records actions (its action
recording design, ``rosbag2_record_replay_action.md``): service events of the two services,
on ``<action>/_action/send_goal/_service_event`` (the goal: a ``REQUEST_RECEIVED`` event
whose request carries goal_id and goal) and ``<action>/_action/get_result/_service_event``
(the result: a ``RESPONSE_SENT`` event whose response carries status and result). So each
goal and each result is one record of a real generated message, and a reader that knows
rosbag2's action topics finds them where it looks. Only those two of the four events
rosbag2 would hold: the node accepts every goal (send_goal's response says nothing), and
get_result's request holds only the goal_id. A goal and its result share the
``sequence_number`` (the node's call number), which pairs them; ``goal_id`` and ``status``
are recorded when the caller gives them, else zeros and STATUS_UNKNOWN. Their types are renamed as the services'
are, without underscores: ``pkg/msg/ASendGoalEvent`` (nesting ``pkg/ASendGoalRequest``,
``pkg/AGoal`` ...) and ``pkg/msg/AGetResultEvent`` (``pkg/AGetResultResponse``,
``pkg/AResult`` ...), with the same cost and the same way back (``rosidl_type``:
``pkg/action/A_SendGoal_Event``).

Not a single made-up ``pkg/msg/AGoalEvent`` holding ``AGoal[<=1] goal`` and
``AResult[<=1] result``: it would decode in the stock readers too, but rclpy has no class
for it, and rosbag2 does not record actions that way.
"""

import array
import os
import re
import sys
from functools import lru_cache
from pathlib import Path

import numpy as np

SEPARATOR = "=" * 80
PRIMITIVES = frozenset({
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string", "wstring"})
SERVICE_PARTS = ("Request", "Response", "Event")
# the types rosidl generates for an action A, named A_<part> (module docstring)
ACTION_PARTS = ("SendGoal_Request", "SendGoal_Response", "SendGoal_Event",
                "GetResult_Request", "GetResult_Response", "GetResult_Event",
                "FeedbackMessage", "Feedback", "Result", "Goal")


def type_name_of(msg) -> str:
    """``pkg/msg/Type`` (or ``pkg/srv/S_Request`` ...) of a rosidl-generated message instance.

    The generated module is ``pkg.msg._type`` / ``pkg.srv._service``, so the first two module
    parts are the package and the interface kind.
    """
    cls = type(msg)
    parts = cls.__module__.split(".")
    if len(parts) < 2 or not hasattr(cls, "get_fields_and_field_types"):
        raise TypeError(f"not a ROS 2 message instance: {cls.__module__}.{cls.__name__}")
    return f"{parts[0]}/{parts[1]}/{cls.__name__}"


def split_type_name(type_name: str) -> tuple[str, str, str]:
    """``pkg/Type`` or ``pkg/ns/Type`` -> (pkg, ns, Type); two-part names are messages."""
    parts = type_name.split("/")
    if len(parts) == 2:
        return parts[0], "msg", parts[1]
    if len(parts) == 3:
        return parts[0], parts[1], parts[2]
    raise ValueError(f"bad ROS type name {type_name!r}")


@lru_cache(maxsize=None)
def _share_dir(pkg: str) -> Path:
    """``share/<pkg>`` through the ament index, as rosbag2 looks definitions up; without
    AMENT_PREFIX_PATH (a venv with ROS 2 from PyPI often has none) the venv's own share/."""
    if os.environ.get("AMENT_PREFIX_PATH"):
        from ament_index_python.packages import get_package_share_directory
        return Path(get_package_share_directory(pkg))
    return Path(sys.prefix) / "share" / pkg


def _srv_halves(pkg: str, service: str) -> tuple[str, str]:
    """Request and response texts of ``pkg/srv/service.srv`` (split on the ``---`` line)."""
    text = (_share_dir(pkg) / "srv" / f"{service}.srv").read_text()
    halves = re.split(r"^---[ \t]*\r?\n?", text, maxsplit=1, flags=re.MULTILINE)
    if len(halves) != 2:
        raise ValueError(f"{pkg}/srv/{service}.srv has no '---' separator")
    return halves[0], halves[1]


def _field_types(text: str, pkg: str) -> set[str]:
    """Non-primitive field types of a .msg text, as ``pkg/Type`` (relative names get ``pkg``).

    Constants (``uint8 A = 1``) are always primitive, so only the first token matters.
    """
    deps = set()
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        base = re.split(r"[\[<]", line.split()[0], maxsplit=1)[0]
        if base in PRIMITIVES:
            continue
        if "/" not in base:
            base = f"{pkg}/{base}"
        p, _, t = split_type_name(base)
        deps.add(f"{p}/{t}")        # 'pkg/msg/T' in a field type means the same as 'pkg/T'
    return deps


@lru_cache(maxsize=None)
def _service_part(pkg: str, name: str) -> tuple[str, str] | None:
    """(S, part) if ``name`` is ``S_Request``, ``S_Response`` or ``S_Event`` (or the same
    without the underscore) of an installed service ``pkg/srv/S``, else None."""
    for part in SERVICE_PARTS:
        service = name[: -len(part)]
        service = service[:-1] if service.endswith("_") else service
        if name.endswith(part) and service and \
                (_share_dir(pkg) / "srv" / f"{service}.srv").is_file():
            return service, part
    return None


@lru_cache(maxsize=None)
def _action_part(pkg: str, name: str) -> tuple[str, str] | None:
    """(A, part) if ``name`` is one of the types rosidl generates for an installed action
    ``pkg/action/A`` (``A_Goal``, ``A_SendGoal_Event`` ...: ``ACTION_PARTS``; also spelled
    without underscores), else None."""
    for part in ACTION_PARTS:
        for spelled in (part, part.replace("_", "")):
            if not name.endswith(spelled):
                continue
            action = name[: -len(spelled)]
            action = action[:-1] if action.endswith("_") else action
            if action and (_share_dir(pkg) / "action" / f"{action}.action").is_file():
                return action, part
    return None


def _is_msg(pkg: str, name: str) -> bool:
    return (_share_dir(pkg) / "msg" / f"{name}.msg").is_file()


def _generated_part(pkg: str, name: str) -> tuple[str, str, str] | None:
    """("srv" or "action", interface, part) if ``name`` is a type rosidl generates for an
    installed service or action of ``pkg`` (not a .msg of its own), else None."""
    if _is_msg(pkg, name):
        return None
    if (found := _service_part(pkg, name)) is not None:
        return ("srv", *found)
    if (found := _action_part(pkg, name)) is not None:
        return ("action", *found)
    return None


def recorded_type(type_name: str) -> str:
    """The name ``type_name`` is recorded under: itself, except the parts of a service or an
    action (``nav_msgs/srv/GetPlan_Event`` -> ``nav_msgs/msg/GetPlanEvent``,
    ``pkg/action/A_SendGoal_Event`` -> ``pkg/msg/ASendGoalEvent``; module docstring)."""
    pkg, ns, name = split_type_name(type_name)
    found = _generated_part(pkg, name)
    if found is None:
        return type_name
    _, interface, part = found
    return f"{pkg}/msg/{interface}{part.replace('_', '')}"


def rosidl_type(recorded: str) -> str:
    """The rosidl name of a recorded type name (``nav_msgs/msg/GetPlanEvent`` ->
    ``nav_msgs/srv/GetPlan_Event``, ``pkg/msg/ASendGoalEvent`` ->
    ``pkg/action/A_SendGoal_Event``; ``pkg/srv/S_Event`` of older files stays). Names of
    packages not installed here stay as they are."""
    pkg, ns, name = split_type_name(recorded)
    if ns != "msg" or (found := _generated_part(pkg, name)) is None:
        return recorded
    kind, interface, part = found
    return f"{pkg}/{kind}/{interface}_{part}"


def _service_text(pkg: str, name: str) -> str | None:
    """Text of ``name`` if it is a part of an installed service ``pkg/srv/S`` (``S_Request``,
    ``SRequest`` ...; ``_service_part``), else None. The Event's own text names the halves
    ``pkg/SRequest`` and ``pkg/SResponse``."""
    found = _service_part(pkg, name)
    if found is None:
        return None
    service, part = found
    if part == "Event":      # rosidl's generated introspection message, as .msg text
        return (f"service_msgs/ServiceEventInfo info\n"
                f"{pkg}/{service}Request[<=1] request\n"
                f"{pkg}/{service}Response[<=1] response\n")
    return _srv_halves(pkg, service)[0 if part == "Request" else 1]


def _action_thirds(pkg: str, action: str) -> list[str]:
    """Goal, result and feedback texts of ``pkg/action/action.action`` (split on the ``---``
    lines, as rosidl does)."""
    text = (_share_dir(pkg) / "action" / f"{action}.action").read_text()
    thirds = re.split(r"^---[ \t]*\r?\n?", text, maxsplit=2, flags=re.MULTILINE)
    if len(thirds) != 3:
        raise ValueError(f"{pkg}/action/{action}.action has not two '---' separators")
    return thirds


def _action_text(pkg: str, name: str) -> str | None:
    """Text of ``name`` if it is a type generated for an installed action ``pkg/action/A``
    (``_action_part``; the members rosidl_parser's ``Action`` gives them), else None. Nested
    generated types are named without underscores (``pkg/ASendGoalRequest``)."""
    found = _action_part(pkg, name)
    if found is None:
        return None
    action, part = found
    own = f"{pkg}/{action}"
    uuid = "unique_identifier_msgs/UUID goal_id\n"
    if part in ("Goal", "Result", "Feedback"):
        return _action_thirds(pkg, action)[("Goal", "Result", "Feedback").index(part)]
    if part.endswith("_Event"):
        service = own + part[: -len("_Event")]
        return (f"service_msgs/ServiceEventInfo info\n"
                f"{service}Request[<=1] request\n"
                f"{service}Response[<=1] response\n")
    return {"SendGoal_Request": f"{uuid}{own}Goal goal\n",
            "SendGoal_Response": "bool accepted\nbuiltin_interfaces/Time stamp\n",
            "GetResult_Request": uuid,
            "GetResult_Response": f"int8 status\n{own}Result result\n",
            "FeedbackMessage": f"{uuid}{own}Feedback feedback\n"}[part]


@lru_cache(maxsize=None)
def own_definition(type_name: str) -> tuple[str, tuple[str, ...]]:
    """(text, sorted nested type names) of one type, without its dependencies' texts.

    Nested names are as they appear in ``MSG:`` headers (``pkg/Type``). A name may be a
    service or action part in either spelling (``nav_msgs/GetPlanRequest``,
    ``nav_msgs/srv/GetPlan_Event``, ``pkg/action/A_SendGoal_Event``, ``pkg/AGoal``).
    """
    pkg, ns, name = split_type_name(type_name)
    if ns == "msg" and _is_msg(pkg, name):
        text = (_share_dir(pkg) / "msg" / f"{name}.msg").read_text()
    elif (text := _service_text(pkg, name)) is None and \
            (text := _action_text(pkg, name)) is None:
        raise LookupError(f"no definition of {type_name} under {_share_dir(pkg)}")
    return text, tuple(sorted(_field_types(text, pkg)))


@lru_cache(maxsize=None)
def full_definition(type_name: str) -> str:
    """Complete ``ros2msg`` schema text of ``type_name`` in rosbag2's layout (see module doc)."""
    seen: set[str] = set()

    def append(name: str) -> str:
        text, deps = own_definition(name)
        for dep in deps:
            if dep not in seen:
                seen.add(dep)
                text += f"\n{SEPARATOR}\nMSG: {dep}\n" + append(dep)
        return text

    return append(type_name)


# a type name with an underscore in its last part: nav_msgs/GetPlan_Request, pkg/srv/S_Event
_UNDERSCORED_TYPE = re.compile(
    r"(?<![\w/])([a-z][a-z0-9_]*/(?:[a-z]+/)?)([A-Z][A-Za-z0-9]*(?:_[A-Za-z0-9]+)+)")


def mcap_ros2_alias(text: str) -> str:
    """``text`` (a type name or schema) with underscores dropped from type names: to decode
    files recorded with rosbag2's service names (``pkg/srv/S_Event``, ``pkg/S_Request``) with
    mcap_ros2, which refuses them. CDR does not depend on names: the bytes decode the same.
    """
    return _UNDERSCORED_TYPE.sub(lambda m: m[1] + m[2].replace("_", ""), text)


@lru_cache(maxsize=None)
def _char_paths(type_name: str) -> tuple[tuple[str, str | None], ...]:
    """Fields of ``type_name`` that are, or lead to, ``char`` fields: (field, nested type or
    None for the char field itself). Empty for the vast majority of types."""
    pkg, _, _ = split_type_name(type_name)
    text, _ = own_definition(type_name)
    out = []
    for line in text.splitlines():
        tokens = line.split("#", 1)[0].split()
        if len(tokens) < 2 or "=" in tokens[1] or (len(tokens) > 2 and tokens[2][0] == "="):
            continue                                   # blank, or a constant
        base = re.split(r"[\[<]", tokens[0], maxsplit=1)[0]
        if base == "char":
            out.append((tokens[1], None))
        elif base not in PRIMITIVES:
            p, _, t = split_type_name(base if "/" in base else f"{pkg}/{base}")
            if _char_paths(f"{p}/{t}"):
                out.append((tokens[1], f"{p}/{t}"))
    return tuple(out)


def _sign_chars(plain, type_name: str):
    """Turn ``char`` values into int8 in place: ROS 2 ``char`` is an unsigned byte (rclpy gives
    0..255) but mcap_ros2 encodes and decodes it as int8 and rejects values above 127. The
    bytes on the wire are the same either way."""
    for name, nested in _char_paths(type_name):
        value = plain.get(name)
        if nested is not None:
            for item in value if isinstance(value, list) else [value]:
                _sign_chars(item, nested)
        elif isinstance(value, (bytes, list)):
            plain[name] = [v - 256 if v > 127 else v for v in value]
        elif isinstance(value, int):
            plain[name] = value - 256 if value > 127 else value
    return plain


def encodable(msg, type_name: str) -> dict:
    """``msg`` (rosidl instance or dict) as plain data mcap_ros2's encoder writes exactly."""
    return _sign_chars(to_plain(msg), type_name)


def to_plain(value):
    """A rosidl message (or field value) as dicts, lists, bytes and Python scalars.

    mcap_ros2's CDR encoder reads fields by name and accepts lists / tuples / bytes /
    ``array.array`` for arrays, but rclpy hands out numpy arrays for fixed-size arrays
    (``float64[36]``, ``char[16]``) and one-byte ``bytes`` for ``byte`` (octet) values, which
    it rejects or cannot coerce to int. Converting the whole tree also keeps the encoder from
    padding the caller's lists in place.
    """
    if hasattr(value, "get_fields_and_field_types"):
        return {f: to_plain(getattr(value, f)) for f in value.get_fields_and_field_types()}
    if isinstance(value, dict):
        return {k: to_plain(v) for k, v in value.items()}
    if isinstance(value, (bytes, bytearray)):
        # rclpy: a scalar 'byte' is bytes of length 1; uint8[] comes as array('B')
        return value[0] if len(value) == 1 else bytes(value)
    if isinstance(value, array.array):
        return value.tobytes() if value.typecode == "B" else value.tolist()
    if isinstance(value, np.ndarray):
        return value.tobytes() if value.dtype == np.uint8 else value.tolist()
    if isinstance(value, (list, tuple)):
        return [to_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value
