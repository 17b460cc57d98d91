"""The node's parameters: names, types, defaults, descriptions, ranges, and the check that
turns a set of values into a robot, a task and planner settings.

The robot file is a ROS 2 parameters file (``robot:`` nested under ``ros__parameters``),
which ROS flattens to dotted names (``robot.load.force``). ``node_config(values)`` folds
the flat values back into the nested mapping and hands it to the same parsers the offline
CLI uses (``model.robot.robot_from_dict``, ``model.task.task_from_dict``), so the node and
the CLI accept and refuse exactly the same files, with the same messages (``InputError``
naming the parameter and the value).

No rclpy here: ``declare`` in ``ros/node.py`` turns ``SPECS`` into declarations. Numeric
parameters are dynamically typed in ROS so that ``-p planner.timeout_s:=5`` (an integer) and
YAML integer lists work; ``node_config`` checks their types and ranges itself.

Parameters (SI units):

==============================  =========  ================================================
name                            default    meaning
==============================  =========  ================================================
base_frame                      cdh_base   frame_id requests must use and outputs carry
robot.*                         (file)     the robot (model/robot.py; from the robot file)
task.type                       free       free, slice, sphere or pivot
task.fixed.x .. task.fixed.sigma  NaN      slice: fixed coordinate (m, rad); NaN = free
task.center, task.radius        0 0 0, 0.1 sphere (paper Eq. 17), m; pivot: the point c
task.free_torsion               false      sphere: sigma free as well
task.tool                       0 0 0      pivot: tool point t, platform frame (m)
planner.strategy                auto       auto (astar up to 3-D, gbf above), astar or gbf
planner.cost                    auto       auto, so3, great_circle or se3
planner.timeout_s               60         give up after this long (answer TIMEOUT)
planner.radius                  0          chart radius (scaled units, about rad); 0: by
                                           the task's dimension (0.1 to 3-D, 0.5 in 6-D)
planner.max_charts              100000     give up after this many charts
planner.max_memory_mb           1024       give up when the atlas holds this much (MiB)
planner.complete                false      grow the whole atlas component
planner.margin_floor            0.001      least normalised feasibility margin kept
trajectory.max_cable_speed      0.05       per-winch speed limit (m/s)
trajectory.max_cable_accel      0.2        per-winch acceleration limit (m/s^2)
stream_rate_hz                  50         rate of ~/cable_command while executing (Hz)
stream_interpolation            quintic    quintic (as checked, a JTC's) or linear (not checked)
execution.mode                  stream     stream or follow_joint_trajectory (ros2_control)
execution.controller_action     /cable_controller/follow_joint_trajectory  (read-only)
execution.joint_states_topic    /joint_states  measured cable lengths (read-only)
execution.start_tolerance       0.005      ~/execute refuses beyond this start error (m)
execution.joint_states_max_age_s  1.0      older measurements are not used (s)
execution.joint_states_wait_s   5.0        use_current_start waits this long for one (s)
log_dir                         ~/.ros/cdh_planner  where run MCAP files go
log_enabled                     true       record plan calls to MCAP
log_max_file_mb                 100        next run file beyond this size (MiB); 0: none
log_max_file_s                  0          next run file after this long (s); 0: no limit
==============================  =========  ================================================
"""

import math
import os
import re
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..model.robot import robot_from_dict
from ..model.task import TASKS, task_from_dict
from ..planner import task_cost
from ..settings import SETTINGS, Bounds, PlannerSettings, check_range

STRING, BOOL, INT, DOUBLE, DOUBLES, STRINGS = "string", "bool", "int", "double", "doubles", \
    "strings"
REQUIRED = object()  # default of a parameter that must come from the robot file

# the groups whose change means a new Planner (the others only affect the node)
PLANNER_PREFIXES = ("robot.", "task.", "planner.", "trajectory.")
INTERPOLATIONS = ("linear", "quintic")
EXECUTION_MODES = ("stream", "follow_joint_trajectory")
# read once at start, read-only afterwards: the subscription and action client they name
# are made then
START_ONLY = ("execution.controller_action", "execution.joint_states_topic")
# a ROS 2 topic or action name: tokens of letters, digits and _ (not starting with a digit)
# between slashes, absolute or relative, or private (~/)
ROS_NAME = re.compile(r"(~/|/)?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*")


@dataclass(frozen=True)
class Spec(Bounds):
    """One parameter: ``kind`` (STRING, BOOL, INT, DOUBLE, DOUBLES, STRINGS), ``default``
    (REQUIRED: no default; None for an optional array left empty), a description, and its
    Bounds (settings.py)."""

    name: str
    kind: str
    default: object
    description: str


_KINDS = {str: STRING, bool: BOOL, int: INT, float: DOUBLE}


def _setting_spec(name):
    """The node parameter of a PlannerSettings field, from its schema (settings.py)."""
    kind, default, s = SETTINGS[name]
    unit = f" ({s.unit})" if s.unit else ""
    return Spec(s.parameter, _KINDS[kind], default, s.description + unit, low=s.low, high=s.high,
                open_low=s.open_low, open_high=s.open_high, choices=s.choices)


def _robot_specs():
    r = "robot."
    six = "6 numbers, one per cable (or a single number for all)"
    return [
        Spec(r + "name", STRING, "", "robot name (for messages)"),
        Spec(r + "winch_names", STRINGS, [f"winch_{i + 1}" for i in range(6)],
             "6 distinct joint names, one per winch (JointState / JointTrajectory names)"),
        Spec(r + "base_anchors", DOUBLES, REQUIRED,
             "A_1..A_6 in the base frame: 18 numbers (m), x y z per anchor"),
        Spec(r + "platform_anchors", DOUBLES, REQUIRED,
             "B_1..B_6 in the platform frame: 18 numbers (m), x y z per anchor"),
        Spec(r + "length_min", DOUBLES, REQUIRED, f"least cable length (m): {six}"),
        Spec(r + "length_max", DOUBLES, REQUIRED, f"greatest cable length (m): {six}"),
        Spec(r + "tension_min", DOUBLES, REQUIRED, f"least cable tension (N): {six}"),
        Spec(r + "tension_max", DOUBLES, REQUIRED, f"greatest cable tension (N): {six}"),
        Spec(r + "load.force", DOUBLES, REQUIRED, "load force, base frame (N): 3 numbers"),
        Spec(r + "load.point", DOUBLES, [0.0, 0.0, 0.0],
             "where the load force acts, platform frame (m): 3 numbers"),
        Spec(r + "load.moment", DOUBLES, [0.0, 0.0, 0.0], "load moment, base frame (N m)"),
        Spec(r + "load.mass", DOUBLE, None, "load mass (kg; optional: enables the dynamic "
             "timing; load.force must then be its weight)", low=0.0, high=1e7, open_low=True),
        Spec(r + "load.inertia", DOUBLES, None, "load inertia about its centre of mass, "
             "platform frame (kg m^2): 9 numbers row-major or 3 for a diagonal; empty: 0"),
        Spec(r + "wrench_ellipsoid.frame", STRING, "load",
             "frame of the wrench ellipsoid: load (F3, parallel to base at the load point) "
             "or base", choices=("load", "base")),
        Spec(r + "wrench_ellipsoid.matrix", DOUBLES, REQUIRED,
             "ellipsoid shape E (SPD): 36 numbers row-major or 6 for a diagonal "
             "(force rows 1/N^2, moment rows 1/(N m)^2)"),
        Spec(r + "wrench_ellipsoid.offset", DOUBLES, [0.0] * 6,
             "ellipsoid centre offset from the load wrench: 6 numbers (N, N m)"),
        Spec(r + "contact_ellipsoid.matrix", DOUBLES, None,
             "optional contact wrench ellipsoid (paper Eqs. 22-23): 36 or 6 numbers; empty "
             "for none"),
        Spec(r + "contact_ellipsoid.center", DOUBLES, [0.0] * 6,
             "contact ellipsoid centre: 6 numbers (N, N m)"),
    ]


def _task_specs():
    """task.type and every registered task's parameters (model/task.py); a parameter that
    two tasks share (task.center) is declared once."""
    kinds = {"double": DOUBLE, "point": DOUBLES, "bool": BOOL}
    specs = {"task.type": Spec("task.type", STRING, "free", "task constraint: "
                               + ", ".join(TASKS), choices=tuple(TASKS))}
    for task in TASKS.values():
        for name, meta, default in task.parameters():
            unit = f" ({meta.unit})" if meta.unit else ""
            specs.setdefault(name, Spec(name, kinds[meta.kind], list(default) if meta.kind == "point"
                                        else default, meta.description + unit,
                                        low=0.0 if meta.positive else None, open_low=meta.positive))
    return list(specs.values())


SPECS = (
    [Spec("base_frame", STRING, "cdh_base",
          "frame_id that plan requests must use and every output carries (REP 103, m)")]
    + _robot_specs()
    + _task_specs()
    + [_setting_spec(name) for name in SETTINGS]
    + [Spec("stream_rate_hz", DOUBLE, 50.0,
            "rate of ~/cable_command while executing (Hz)", low=1.0, high=1000.0),
       Spec("stream_interpolation", STRING, "quintic",
            "between waypoints while streaming: quintic (as a JointTrajectoryController "
            "interpolates the same points: the motion the planner checked) or linear "
            "(straight in cable space at the mean speed; its velocity steps at every point, "
            "which the check does not cover)", choices=INTERPOLATIONS),
       Spec("execution.mode", STRING, "stream",
            "how ~/execute moves the winches: stream (sensor_msgs/JointState setpoints on "
            "~/cable_command at stream_rate_hz) or follow_joint_trajectory (the cable "
            "trajectory, without effort, to a ros2_control controller's action)",
            choices=EXECUTION_MODES),
       Spec("execution.controller_action", STRING, "/cable_controller/follow_joint_trajectory",
            "follow_joint_trajectory mode: the controller's control_msgs/FollowJointTrajectory "
            "action (set at start)"),
       Spec("execution.joint_states_topic", STRING, "/joint_states",
            "sensor_msgs/JointState of the winches (cable lengths, m, by winch name): the "
            "start state of ~/execute and of use_current_start (set at start)"),
       Spec("execution.start_tolerance", DOUBLE, 0.005,
            "~/execute refuses when a measured cable length is farther than this from the "
            "trajectory's first point (m)", low=0.0, open_low=True),
       Spec("execution.joint_states_max_age_s", DOUBLE, 1.0,
            "measured lengths older than this (s) are not used", low=0.0, open_low=True),
       Spec("execution.joint_states_wait_s", DOUBLE, 5.0,
            "use_current_start with no measured lengths recent enough waits this long (s) "
            "for a joint state before answering NO_CURRENT_STATE (DDS discovery of a "
            "controller started at the same time can take about 3 s); 0: no wait",
            low=0.0, high=60.0),
       Spec("log_dir", STRING, "~/.ros/cdh_planner",
            "directory of the run MCAP files (one file per node run; created when needed)"),
       Spec("log_enabled", BOOL, True, "record plan calls, published messages and streamed "
            "commands to MCAP in log_dir"),
       Spec("log_max_file_mb", DOUBLE, 100.0, "rotation: a run file that has reached this "
            "size (MiB) is closed and the next record starts a new one; 0: no limit", low=0.0),
       Spec("log_max_file_s", DOUBLE, 0.0, "rotation: a run file open this long (s) is "
            "closed and the next record starts a new one; 0: no limit", low=0.0)]
)
SPEC = {s.name: s for s in SPECS}


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


def check_value(spec, value):
    """The value of ``spec`` converted (ints to floats for doubles, sequences to lists) and
    checked against its kind, choices and range; InputError naming the parameter."""
    name = spec.name
    if value is None:
        if spec.default is REQUIRED:
            raise InputError(name, None, "required parameter is not set: give the robot file "
                                         "(--ros-args --params-file config/robot2.yaml)")
        if spec.default is None:
            return None
        raise InputError(name, None, "must be set")
    if spec.kind == STRING:
        if not isinstance(value, str):
            raise InputError(name, value, "expected a string")
        if spec.choices and value not in spec.choices:
            raise InputError(name, value, f"expected one of {', '.join(spec.choices)}")
        if name in ("base_frame",) + START_ONLY and not value:
            raise InputError(name, value, "must not be empty")
        if name in START_ONLY and not ROS_NAME.fullmatch(value):
            raise InputError(name, value, "not a ROS name: letters, digits and _ between "
                                          "slashes, no token starting with a digit")
        return value
    if spec.kind == BOOL:
        if not isinstance(value, bool):
            raise InputError(name, value, "expected true or false")
        return value
    if spec.kind == STRINGS:
        if isinstance(value, str) or not all(isinstance(v, str) for v in value):
            raise InputError(name, value, "expected a list of strings")
        return list(value)
    if spec.kind == DOUBLES:
        if isinstance(value, (str, bytes)):
            raise InputError(name, value, "expected a list of numbers")
        if not hasattr(value, "__len__"):  # one number: the parsers broadcast it or refuse
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
    # INT, DOUBLE
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputError(name, value, "expected a number")
    if spec.kind == INT:
        if not math.isfinite(value) or float(value) != int(value):
            raise InputError(name, value, "expected an integer")
        value = int(value)
    else:
        value = float(value)
        if math.isnan(value) and math.isnan(spec.default if spec.default is not REQUIRED
                                             else 0.0):
            return value  # NaN means "not set" where that is the default
        if not math.isfinite(value):
            raise InputError(name, value, "must be a finite number")
    return check_range(name, value, spec)


def node_config(values, source="ROS parameters"):
    """NodeConfig of the flat parameter values ``values`` (name -> value; a missing name
    takes its default). Raises InputError naming the first bad parameter."""
    checked = {}
    for spec in SPECS:
        raw = values.get(spec.name, None if spec.default is REQUIRED else spec.default)
        checked[spec.name] = check_value(spec, raw)
    robot = robot_from_dict(_robot_dict(checked), source=source)
    task = task_from_dict(_task_dict(checked), where="task")
    settings = PlannerSettings(**{name: checked[s.parameter] for name, (_, _, s) in SETTINGS.items()})
    try:
        task_cost(robot, task, settings.cost)   # e.g. great_circle needs the sphere task
    except InputError as exc:
        raise InputError("planner.cost", settings.cost, exc.reason) from None
    log_dir = checked["log_dir"]
    if not log_dir and checked["log_enabled"]:
        raise InputError("log_dir", log_dir, "must name a directory while log_enabled is true")
    return NodeConfig(robot=robot, task=task, settings=settings,
                      base_frame=checked["base_frame"],
                      stream_rate_hz=checked["stream_rate_hz"],
                      stream_interpolation=checked["stream_interpolation"],
                      log_dir=os.path.expanduser(log_dir), log_enabled=checked["log_enabled"],
                      values=checked)


def _robot_dict(checked):
    """The nested ``robot:`` mapping of the robot file from the flat values."""
    out = {}
    for name, value in checked.items():
        if not name.startswith("robot.") or value is None:
            continue
        if name == "robot.name" and not value:
            continue
        keys = name.split(".")[1:]
        node = out
        for key in keys[:-1]:
            node = node.setdefault(key, {})
        node[keys[-1]] = value
    contact = out.get("contact_ellipsoid", {})
    if "matrix" not in contact:
        out.pop("contact_ellipsoid", None)
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
SETTING_PARAMETERS = {name: s.parameter for name, (_, _, s) in SETTINGS.items()}


def parameter_error(exc):
    """An InputError of the planner's settings check, naming the node parameter instead of
    the PlannerSettings field (``margin_floor`` -> ``planner.margin_floor``)."""
    name = SETTING_PARAMETERS.get(exc.field)
    return exc if name is None else InputError(name, exc.value, exc.reason)
