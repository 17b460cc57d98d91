"""The node's parameters: names, types, defaults, descriptions, ranges, and the check that
turns a set of values into a robot, a task and planner settings.

The robot file is a ROS 2 parameters file (``robot:`` nested under ``ros__parameters``),
which ROS flattens to dotted names (``robot.load.force``). ``node_config(values)`` folds
the flat values back into the nested mapping and hands it to the same parsers the offline
CLI uses (``model.robot.robot_from_dict``, ``model.task.task_from_dict``), so the node and
the CLI accept and refuse exactly the same files, with the same messages (``InputError``
naming the parameter and the value).

No rclpy here: ``declare`` in ``ros/node/planner_node.py`` turns ``SPECS`` into declarations. Numeric
parameters are dynamically typed in ROS so that ``-p planner.timeout_s:=5`` (an integer) and
YAML integer lists work; ``node_config`` checks their types and ranges itself.

The parameters are ``SPECS``: the robot file's fields (``robot.*``, declared on
``model.robot.Robot``), the registered tasks' fields (``task.*``, ``model/task.py``), the
planner settings (``settings.py``), the node's own (below) and the registered command
outlets' (``execution.mode`` and its modes' parameters, ``execution/command_outlets.py``). Their
table, with units, defaults and ranges, is docs/parameters.md, generated from ``SPECS`` by
``python -m cdh_planner.ros.core.params > docs/parameters.md`` (test_ros_params checks it is
current).
"""

import math
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from ...errors import InputError
from ...fields import BOOL, CHOICE, INT, NUMBER, NUMBERS, REQUIRED, TEXT, TEXTS, default_text, \
    range_text, read, with_key
from ...model import robot_schema as rs
from ...model.robot import FIELDS as ROBOT_FIELDS, OPTIONAL_GROUPS, robot_from_dict
from ...model.task import TASKS, task_from_dict, task_parameters
from ...pipeline.metrics import task_cost
from ...scene.schema import default_scene, load_scene
from ...settings import SETTINGS, LiveChoices, PlannerSettings
from ..execution.command_outlets import OUTLETS, modes_description, outlet_specs, reserve
from ..msgs.scene_msgs import check_sendable
from .param_spec import ROS_TYPES, Spec

# the groups whose change means a new Planner (the others only affect the node)
PLANNER_PREFIXES = ("robot.", "task.", "planner.", "trajectory.", "scene_file")
INTERPOLATIONS = ("linear", "quintic")
EXECUTION_MODES = LiveChoices(lambda: tuple(OUTLETS))  # the registered command outlets
# read once at start, read-only afterwards: the subscription, publisher or action client
# they name are made then (Spec.start_only)
START_ONLY = LiveChoices(lambda: tuple(s.name for s in SPECS if s.start_only))
READ_ONLY = LiveChoices(lambda: tuple(START_ONLY) + ("autostart",))
FRAMES = ("base_frame", "fixed_frame", "platform_frame")
# a ROS 2 topic or action name: tokens of letters, digits and _ (not starting with a digit)
# between slashes, absolute or relative, or private (~/)
ROS_NAME = re.compile(r"(~/|/)?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*")
# a TF frame id: a ROS name without a leading slash (tf2 refuses "/world")
FRAME_ID = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*")


def _setting_spec(name):
    """The node parameter of a PlannerSettings field: its Setting (settings.py) under the
    parameter's name, the unit in the description."""
    s = SETTINGS[name]
    unit = f" ({s.unit})" if s.unit else ""
    return with_key(s, s.parameter, cls=Spec, description=s.description + unit)


def _robot_spec(f):
    """The node parameter robot.<key> of a robot file field, from its declaration
    (model/robot.py, ``Robot``): a required field of an optional group (the contact
    ellipsoid's matrix) is an optional parameter, empty for none."""
    default = f.default
    if default is None and ROS_TYPES[f.kind] == "string":
        default = ""  # a string parameter is typed: empty is "not set" (_robot_dict)
    elif default is REQUIRED:
        default = None if f.group in OPTIONAL_GROUPS else REQUIRED
    elif isinstance(default, tuple):
        default = list(default)
    return with_key(f, "robot." + f.key, cls=Spec, default=default, description=rs.describe(f))


def _task_specs():
    """task.type and every registered task's parameters (model/task.py: ``register`` has
    checked that tasks sharing a parameter, task.center, declare it alike)."""
    specs = [Spec("task.type", CHOICE, "free", "task constraint: " + ", ".join(TASKS),
                  choices=tuple(TASKS))]
    for f, _ in task_parameters().values():
        unit = f" ({f.unit})" if f.unit else ""
        specs.append(with_key(f, f.key, cls=Spec, description=f.description + unit,
                              default=list(f.default) if f.kind == NUMBERS else f.default))
    return specs


_HEAD = tuple(
    [Spec("autostart", BOOL, True,
          "configure and activate at start, as nav2's lifecycle_manager autostart; false: "
          "the node waits unconfigured for lifecycle calls (~/change_state)"),
     Spec("base_frame", TEXT, "cdh_base",
          "the paper's frame (z down, gravity +z; m): every output carries it; a request in "
          "another frame is transformed into it through TF"),
     Spec("fixed_frame", TEXT, "world",
          "the z-up fixed frame (REP 103 / 105); base_frame is its child, turned by pi "
          "about x (a static transform on /tf_static)"),
     Spec("platform_frame", TEXT, "cdh_platform",
          "the platform's frame: base_frame -> platform_frame on /tf, from the forward "
          "kinematics of the measured cable lengths"),
     Spec("live_state_rate_hz", NUMBER, 20.0,
          "the live state (platform pose on /tf and ~/platform_pose, ~/cable_state, "
          "~/least_margin) is computed at most this often (Hz), from the newest joint state "
          "only, and not at all while none arrives", low=0.1, high=1000.0),
     Spec("live_markers_rate_hz", NUMBER, 10.0,
          "~/live_markers is drawn at most this often (Hz; at most live_state_rate_hz)",
          low=0.1, high=1000.0)]
    + [_robot_spec(f) for f in ROBOT_FIELDS]
    + _task_specs()
    + [_setting_spec(name) for name in SETTINGS]
    + [Spec("stream_rate_hz", NUMBER, 50.0,
            "rate of ~/cable_command while executing (Hz)", low=1.0, high=1000.0),
       Spec("stream_interpolation", CHOICE, "quintic",
            "between waypoints while streaming: quintic (as a JointTrajectoryController "
            "interpolates the same points: the motion the planner checked) or linear "
            "(straight in cable space at the mean speed; its velocity steps at every point, "
            "which the check does not cover)", choices=INTERPOLATIONS)])
# then execution.mode and the command outlets' own parameters (_specs), then these
_TAIL = tuple(
    [Spec("execution.allow_unchecked_start", BOOL, False,
            "~/execute without measured cable lengths to compare with the trajectory's "
            "start: refused when false (the default), executed unchecked when true"),
       Spec("execution.joint_states_topic", TEXT, "/joint_states",
            "sensor_msgs/JointState of the winches (cable lengths, m, by winch name): the "
            "start state of ~/execute and of use_current_start (set at start)",
            start_only=True),
       Spec("execution.start_tolerance", NUMBER, 0.005,
            "~/execute refuses when a measured cable length is farther than this from the "
            "trajectory's first point (m)", low=0.0, open_low=True),
       Spec("execution.joint_states_max_age_s", NUMBER, 1.0,
            "measured lengths older than this (s) are not used", low=0.0, open_low=True),
       Spec("execution.joint_states_wait_s", NUMBER, 5.0,
            "use_current_start with no measured lengths recent enough waits this long (s) "
            "for a joint state before answering NO_CURRENT_STATE (DDS discovery of a "
            "controller started at the same time can take about 3 s); 0: no wait",
            low=0.0, high=60.0),
       Spec("scene_file", TEXT, "",
            "scene file (YAML, scene: obstacles in the base frame, cable radius, platform "
            "shape; cdh_planner/scene/schema.py): plans keep clear of it; empty: no scene. "
            "Read when set: edit the file, then set the parameter again"),
       Spec("log_dir", TEXT, "~/.ros/cdh_planner",
            "directory of the run MCAP files (one file per node run; created when needed); "
            "while log_enabled, one the node cannot create or write is refused"),
       Spec("log_enabled", BOOL, True, "record plan calls, published messages and streamed "
            "commands to MCAP in log_dir"),
       Spec("log_max_file_mb", NUMBER, 100.0, "rotation: a run file that has reached this "
            "size (MiB) is closed and the next record starts a new one; 0: no limit", low=0.0),
       Spec("log_max_file_s", NUMBER, 0.0, "rotation: a run file open this long (s) is "
            "closed and the next record starts a new one; 0: no limit", low=0.0),
       Spec("log_max_files", INT, 100, "pruning: when a run file is opened, only the newest "
            "this many run files (cdh_planner_*.mcap) in log_dir are kept; 0: no limit",
            low=0, high=1_000_000),
       Spec("log_max_age_days", NUMBER, 0.0, "pruning: when a run file is opened, run files "
            "in log_dir last written longer ago than this (days) are removed; 0: no limit",
            low=0.0)]
)
reserve({s.name for s in _HEAD + _TAIL} | {"execution.mode"})
_BUILT = {}  # the registered outlets -> the specs (rebuilt when an outlet is registered)


def _built():
    """(every parameter: _HEAD, execution.mode and the outlets' parameters, _TAIL; name ->
    its Spec), for the outlets registered now."""
    key = tuple(OUTLETS.values())
    if key not in _BUILT:
        mode = Spec("execution.mode", CHOICE, "stream", modes_description(),
                    choices=EXECUTION_MODES)
        specs = _HEAD + (mode,) + outlet_specs() + _TAIL
        _BUILT.clear()
        _BUILT[key] = specs, {s.name: s for s in specs}
    return _BUILT[key]


def _specs():
    return _built()[0]


class _SpecsByName(Mapping):
    """name -> Spec of SPECS, as registered now."""

    def __getitem__(self, name):
        return _built()[1][name]

    def __iter__(self):
        return iter([s.name for s in _specs()])

    def __len__(self):
        return len(_specs())


# the parameters (Spec), read from the command outlets' registry whenever used
SPECS = LiveChoices(_specs)
SPEC = _SpecsByName()


@dataclass(frozen=True)
class NodeConfig:
    """Everything the node needs, checked: ``robot`` (Robot), ``task``, ``settings``
    (PlannerSettings) and the node's own settings."""

    robot: object
    task: object
    settings: PlannerSettings
    base_frame: str
    stream_rate_hz: float
    stream_interpolation: str
    log_dir: str
    log_enabled: bool
    values: dict = field(default_factory=dict, compare=False, repr=False)
    scene: object = None  # scene.schema.Scene of scene_file, or None


def check_value(spec, value):
    """The value of ``spec`` as plain Python (ints to floats for numbers, sequences to
    lists), a scalar read by its Field (``fields.read``: kind, choices, range) and the
    node's own rules (frames, ROS names); a list is read by its consumer (the robot, a task,
    an outlet), whose sizes may depend on other parameters (m). InputError naming the
    parameter."""
    name = spec.name
    if value is None:
        if spec.default is REQUIRED:
            raise InputError(name, None, "required parameter is not set: give the robot file "
                                         "(--ros-args --params-file config/robot2.yaml)")
        if spec.default is None:
            return None
        raise InputError(name, None, "must be set")
    if spec.type == "strings":
        return read(replace(spec, kind=TEXTS), value, name)
    if spec.type == "doubles":
        return _numbers(spec, value)
    if spec.type == "string" and value == "" and spec.default == "":
        return value  # a typed string parameter left empty: not set
    if spec.kind == NUMBER and _is_nan(value) and _is_nan(spec.default):
        return float(value)  # NaN means "not set" where that is the default
    value = read(spec, value, name)
    if spec.type == "string":
        _check_name(spec, value)
    return value


def _is_nan(value):
    return isinstance(value, (float, np.floating)) and math.isnan(value)


def _numbers(spec, value):
    """A list of floats (a single number as a float: the parsers broadcast it or refuse
    it; an empty list as None where the default is empty)."""
    name = spec.name
    if isinstance(value, (str, bytes)):
        raise InputError(name, value, "expected a list of numbers")
    if not hasattr(value, "__len__"):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(name, value, "expected a list of numbers")
        return float(value)
    if any(isinstance(v, (bool, str)) for v in value):
        raise InputError(name, list(value), "expected a list of numbers")
    try:
        arr = [float(v) for v in value]
    except (TypeError, ValueError):
        raise InputError(name, list(value), "expected a list of numbers") from None
    return arr if arr or spec.default is not None else None


def _check_name(spec, value):
    """A frame or a start-only topic or action: a non-empty TF frame id or ROS name."""
    name = spec.name
    if (name in FRAMES or spec.start_only) and not value:
        raise InputError(name, value, "must not be empty")
    if name in FRAMES and not FRAME_ID.fullmatch(value):
        raise InputError(name, value, "not a TF frame id: letters, digits and _ between "
                                      "slashes, no leading slash, no token starting with "
                                      "a digit")
    if spec.start_only and not ROS_NAME.fullmatch(value):
        raise InputError(name, value, "not a ROS name: letters, digits and _ between "
                                      "slashes, no token starting with a digit")


def node_config(values, source="ROS parameters"):
    """NodeConfig of the flat parameter values ``values`` (name -> value; a missing name
    takes its default). Raises InputError naming the first bad parameter."""
    checked = {}
    for spec in SPECS:
        raw = values.get(spec.name, None if spec.default is REQUIRED else spec.default)
        checked[spec.name] = check_value(spec, raw)
    robot = robot_from_dict(_robot_dict(checked), source=source)
    task = task_from_dict(_task_dict(checked), where="task")
    settings = PlannerSettings(**{name: checked[s.parameter] for name, s in SETTINGS.items()})
    for outlet in OUTLETS.values():   # every mode's: a switch of mode finds them good
        outlet.check(checked, robot)
    _check_frames(checked)
    try:
        task_cost(robot, task, settings.cost)   # e.g. great_circle needs the sphere task
    except InputError as exc:
        raise InputError("planner.cost", settings.cost, exc.reason) from None
    scene = check_sendable(load_scene(os.path.expanduser(checked["scene_file"]), robot)
                           if checked["scene_file"] else default_scene(robot))
    log_dir = checked["log_dir"]
    if not log_dir and checked["log_enabled"]:
        raise InputError("log_dir", log_dir, "must name a directory while log_enabled is true")
    if checked["log_enabled"]:
        _check_log_dir(log_dir)
    return NodeConfig(robot=robot, task=task, settings=settings,
                      base_frame=checked["base_frame"],
                      stream_rate_hz=checked["stream_rate_hz"],
                      stream_interpolation=checked["stream_interpolation"],
                      log_dir=os.path.expanduser(log_dir), log_enabled=checked["log_enabled"],
                      values=checked, scene=scene)


def _check_log_dir(log_dir):
    """InputError naming log_dir unless the directory exists or can be made and a file can
    be written in it (a probe file, removed): a parameter that cannot work is refused, not
    accepted and then only logged at the first recording."""
    import tempfile
    path = os.path.expanduser(log_dir)
    try:
        os.makedirs(path, exist_ok=True)
        with tempfile.TemporaryFile(dir=path, prefix=".cdh_planner_probe_"):
            pass
    except OSError as exc:
        raise InputError("log_dir", log_dir, f"cannot record there: {exc.strerror or exc}"
                                             f"{f' ({exc.filename})' if exc.filename else ''}"
                                             ) from None


def _check_frames(checked):
    """The three frames are three: InputError naming the second of two alike."""
    seen = {}
    for name in FRAMES:
        if checked[name] in seen:
            raise InputError(name, checked[name], f"must differ from {seen[checked[name]]}")
        seen[checked[name]] = name


def _robot_dict(checked):
    """The nested ``robot:`` mapping of the robot file from the flat values."""
    out = {}
    for name, value in checked.items():
        if not name.startswith("robot.") or value is None:
            continue
        if SPEC[name].type == "string" and not value:
            continue  # not set
        keys = name.split(".")[1:]
        node = out
        for key in keys[:-1]:
            node = node.setdefault(key, {})
        node[keys[-1]] = value
    for f in ROBOT_FIELDS:  # an optional group without its required fields is not given
        if f.group in OPTIONAL_GROUPS and f.default is rs.REQUIRED and f.leaf not in out.get(f.group, {}):
            out.pop(f.group, None)
    return out


def _task_dict(checked):
    return TASKS[checked["task.type"]].dict_of_parameters(checked)


def needs_new_planner(names, old=None, new=None):
    """True if a change of the parameters ``names`` changes the robot, task or planner.
    With the values before and after (``old``, ``new``: name -> value), a parameter set to
    the value it already has changes nothing (the planner keeps its atlas)."""
    return any(n.startswith(PLANNER_PREFIXES)
               and (old is None or new is None or not _same(old.get(n), new.get(n)))
               for n in names)


def _same(a, b):
    if isinstance(a, (list, tuple)) or isinstance(b, (list, tuple)):
        if not (isinstance(a, (list, tuple)) and isinstance(b, (list, tuple))):
            return False
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return type(a) is type(b) and a == b or (
        isinstance(a, (int, float)) and isinstance(b, (int, float))
        and not isinstance(a, bool) and not isinstance(b, bool) and float(a) == float(b))


# PlannerSettings field -> the node parameter that sets it (to name it in errors)
SETTING_PARAMETERS = {name: s.parameter for name, s in SETTINGS.items()}


def parameter_error(exc):
    """An InputError of the planner's settings check, naming the node parameter instead of
    the PlannerSettings field (``margin_floor`` -> ``planner.margin_floor``)."""
    name = SETTING_PARAMETERS.get(exc.field)
    return exc if name is None else InputError(name, exc.value, exc.reason)


DOCS_HEADER = """# The node's parameters

Generated from `cdh_planner/ros/core/params.py` (`SPECS`) by
`python -m cdh_planner.ros.core.params > docs/parameters.md`; `test/test_ros_params.py` checks
that it is current. The `robot.*` parameters are the robot file's `robot:` block (keys
nested in the file: `load: {force: ...}` is `robot.load.force`), declared on
`cdh_planner/model/robot.py`'s `Robot`; `task.*` are the registered tasks' fields (the
problem file's `task:` keys); `planner.*` and `trajectory.*` the planner settings
(`cdh_planner/settings.py`). SI units. Default "required": the robot file must give it;
"empty": not set.
"""


def parameters_markdown():
    """docs/parameters.md: a Markdown table of every parameter of ``SPECS``."""
    rows = ["| parameter | type | default | range | description |", "|---|---|---|---|---|"]
    for spec in SPECS:
        cells = (f"`{spec.name}`", spec.type, default_text(spec.default), range_text(spec),
                 spec.description)
        rows.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return DOCS_HEADER + "\n" + "\n".join(rows) + "\n"


if __name__ == "__main__":
    print(parameters_markdown(), end="")
