"""How ``~/execute`` moves the winches: one registered class per ``execution.mode``, a
command outlet (``CommandOutlet``, ``register``; ``OUTLETS``: mode -> class).

A class gives its mode ``name``, its ``description`` (in ``execution.mode``'s, and so in
docs/parameters.md), the node parameters of its own (``specs``, ``param_spec.Spec``;
``start_only`` ones are topic or action names read once at configure) and ``check``, which
refuses values of them that do not fit the robot. That registry drives the mode parameter's
choices and description, the declared parameters and the node's execution
(``plan_execution.PlanExecution`` makes one instance of each at configure: a mode can be
switched while configured). Two kinds:

- ``StreamedOutlet``: the plan's cable state sampled in real time at ``stream_rate_hz``
  (``streaming.Stream``: a sensor_msgs/JointState per setpoint, lengths m, velocities m/s,
  effort N); ``message`` turns it into the command, published on ``publisher``. Built in:
  ``stream`` (the JointState itself on the node's ``~/cable_command``) and
  ``forward_command`` (std_msgs/Float64MultiArray lengths in ``execution.joint_order``).
- ``TrajectoryOutlet``: the whole cable trajectory handed to a controller that reports
  its end: ``follow_joint_trajectory`` (control_msgs/FollowJointTrajectory action).

A new message type is one registered ``StreamedOutlet`` (test/test_command_outlets.py).
No rclpy at import: message types and clients are imported where an outlet makes them.
"""

import abc
from dataclasses import dataclass
from typing import ClassVar

from ...errors import InputError
from ...model.elastic import is_elastic
from ...fields import TEXT, TEXTS
from ..core.param_spec import Spec

OUTLETS = {}  # execution.mode -> registered CommandOutlet class (``register``)
NODE_PARAMETERS = set()  # the node's own parameter names, no outlet's (``reserve``)
PREFIX = "execution."    # an outlet's parameters are execution.<name>
# as forward_command_controller's subscription (rclcpp::SystemDefaultsQoS): reliable,
# volatile; never latched (a controller that starts gets nothing old)
COMMAND_QOS = 10


def register(cls):
    """Class decorator: make ``cls`` an ``execution.mode`` (module doc). Refused (ValueError
    naming it): no name or description, a name registered by another class, a parameter
    not named execution.<name> or one of the node's own, or one another outlet declares
    otherwise (outlets may share one declared alike)."""
    for attr in ("name", "description"):
        if not isinstance(getattr(cls, attr), str) or not getattr(cls, attr):
            raise ValueError(f"command outlet {cls.__name__}: {attr} must be a non-empty string")
    if cls.name in OUTLETS and OUTLETS[cls.name] is not cls:
        raise ValueError(f"execution mode {cls.name!r} is already registered "
                         f"({OUTLETS[cls.name].__name__})")
    _check_names(cls, NODE_PARAMETERS)
    for spec in cls.specs:
        other = next((o for o in OUTLETS.values() if o is not cls
                      and any(s.name == spec.name and s != spec for s in o.specs)), None)
        if other is not None:
            raise ValueError(f"execution mode {cls.name!r}: parameter {spec.name} is declared "
                             f"otherwise by mode {other.name!r}")
    OUTLETS[cls.name] = cls
    return cls


def reserve(names):
    """Declare the node's own parameters ``names`` (params.py): no outlet, registered now or
    later, may declare one (ValueError naming it)."""
    for cls in OUTLETS.values():
        _check_names(cls, names)
    NODE_PARAMETERS.update(names)


def _check_names(cls, reserved):
    for spec in cls.specs:
        if not spec.name.startswith(PREFIX) or spec.name in reserved:
            why = "is the node's own" if spec.name in reserved else f"is not {PREFIX}<name>"
            raise ValueError(f"execution mode {cls.name!r}: parameter {spec.name} {why}")


def outlet_specs():
    """The parameters of every registered outlet, each once, in registry order."""
    out = {}
    for cls in OUTLETS.values():
        for spec in cls.specs:
            out.setdefault(spec.name, spec)
    return tuple(out.values())


def command_topic_parameters():
    """The names of the streamed outlets' start-only parameters: the topics their commands
    go to (``replay`` keeps recorded commands off a live system unless asked)."""
    return {s.name for cls in OUTLETS.values() if cls.streamed for s in cls.specs
            if s.start_only}


def modes_description():
    """``execution.mode``'s description, from the registry."""
    items = [f"{name} ({cls.description})" for name, cls in OUTLETS.items()]
    listed = ", ".join(items[:-1]) + " or " + items[-1] if len(items) > 1 else "".join(items)
    return "how ~/execute moves the winches: " + listed


@dataclass(frozen=True)
class OutletContext:
    """What outlets are made with: the ``node``, the node's ``~/cable_command`` publisher
    (sensor_msgs/JointState, made with the node), the ``callback_group`` of action clients."""

    node: object
    cable_command: object
    callback_group: object = None


class CommandOutlet(abc.ABC):
    """Base of every outlet (module doc); ``__init__`` makes what it publishes with."""

    name: ClassVar[str] = ""          # the value of execution.mode
    description: ClassVar[str] = ""   # in execution.mode's description
    specs: ClassVar[tuple] = ()       # its own node parameters (Spec)
    streamed: ClassVar[bool]          # sampled at stream_rate_hz (else the controller times it)
    length_only: ClassVar[bool] = False  # commands lengths alone, no tensions

    def __init__(self, context, config):
        self.context = context
        self.configure(config)

    @classmethod
    def check(cls, values, robot):
        """InputError naming a parameter of this outlet whose value (``values``: the checked
        flat parameter values) does not fit ``robot``; every mode's are checked whatever the
        mode, so that a switch of mode finds them good."""

    def configure(self, config):
        """New parameter values (NodeConfig; not the start-only ones, read once)."""

    @classmethod
    def refusal(cls, robot):
        """Why this mode cannot execute a plan of ``robot`` (one line), or "": with more
        than six rigid cables, lengths alone do not determine the tensions (any tensions in
        the null space of the structure matrix hold the same pose), so a length-only mode
        needs the cables' stiffness, which makes the commanded lengths carry the plan's."""
        m = len(robot.base_anchors)
        if cls.length_only and m > 6 and not is_elastic(robot):
            return (f"robot.cable_stiffness is not set: execution.mode {cls.name} commands "
                    f"lengths only, which do not determine the tensions of {m} rigid cables "
                    f"(give the cables' axial stiffness EA, N)")
        return ""

    @property
    @abc.abstractmethod
    def target(self):
        """The topic or action the commands go to (in answers)."""

    @abc.abstractmethod
    def release(self):
        """Destroy what ``__init__`` made (lifecycle cleanup)."""


class StreamedOutlet(CommandOutlet):
    """One command per streamed setpoint, on ``publisher`` (``make_publisher``)."""

    streamed = True

    def __init__(self, context, config):
        self.publisher = self.make_publisher(context, config.values)
        super().__init__(context, config)

    @abc.abstractmethod
    def make_publisher(self, context, values):
        """The publisher of the commands (``values``: the flat parameter values)."""

    @abc.abstractmethod
    def message(self, joint_state):
        """The command of one setpoint, a sensor_msgs/JointState in the robot's winch order
        (position: cable lengths m, velocity m/s, effort N)."""

    @property
    def target(self):
        return self.publisher.topic_name

    def release(self):
        self.context.node.destroy_publisher(self.publisher)


class TrajectoryOutlet(CommandOutlet):
    """The whole trajectory to a controller, which ends the run through ``on_done``."""

    streamed = False

    @abc.abstractmethod
    def start(self, trajectory, on_done, on_accepted):
        """Send ``trajectory`` (trajectory_msgs/JointTrajectory); ``on_done(outcome,
        message)`` once at its end, ``on_accepted()`` when the controller takes it."""

    @abc.abstractmethod
    def cancel(self):
        """Ask the controller to stop; False if it has nothing running."""


@register
class JointStateStream(StreamedOutlet):
    name = "stream"
    description = ("sensor_msgs/JointState setpoints on ~/cable_command at stream_rate_hz, "
                   "for a custom winch driver: no stock ros2_control controller reads it")

    def make_publisher(self, context, values):
        return context.cable_command

    def message(self, joint_state):
        return joint_state

    def release(self):
        pass  # the node's: it outlives configurations


@register
class ForwardCommand(StreamedOutlet):
    name = "forward_command"
    length_only = True
    description = ("std_msgs/Float64MultiArray cable lengths on execution.forward_command_topic "
                   "at stream_rate_hz, in execution.joint_order: a JointGroupPositionController")
    specs = (Spec("execution.forward_command_topic", TEXT, "/cable_controller/commands",
                  "forward_command mode: the JointGroupPositionController's ~/commands "
                  "(std_msgs/Float64MultiArray, set at start)", start_only=True),
             Spec("execution.joint_order", TEXTS, None,
                  "forward_command mode: the controller's joints parameter, the order of the "
                  "command's data; the robot's winch names, each once (empty: "
                  "robot.winch_names)"))

    @classmethod
    def check(cls, values, robot):
        check_joint_order(values["execution.joint_order"], robot.winch_names)

    def make_publisher(self, context, values):
        from std_msgs.msg import Float64MultiArray
        return context.node.create_publisher(
            Float64MultiArray, values["execution.forward_command_topic"], COMMAND_QOS)

    def configure(self, config):
        self.joint_order = check_joint_order(config.values["execution.joint_order"],
                                             config.robot.winch_names)

    def message(self, joint_state):
        return forward_command(joint_state, self.joint_order)


@register
class FollowJointTrajectory(TrajectoryOutlet):
    name = "follow_joint_trajectory"
    length_only = True
    description = ("the cable trajectory, without effort, to a JointTrajectoryController's "
                   "action")
    specs = (Spec("execution.controller_action", TEXT,
                  "/cable_controller/follow_joint_trajectory",
                  "follow_joint_trajectory mode: the controller's "
                  "control_msgs/FollowJointTrajectory action (set at start)", start_only=True),)

    def __init__(self, context, config):
        from . import winches
        self.controller = winches.TrajectoryExecutor(
            context.node, config.values["execution.controller_action"],
            callback_group=context.callback_group)
        super().__init__(context, config)

    @property
    def target(self):
        return self.controller.action_name

    def start(self, trajectory, on_done, on_accepted):
        self.controller.start(trajectory, on_done, on_accepted=on_accepted)

    def cancel(self):
        return self.controller.cancel()

    def release(self):
        self.controller.destroy()


def check_joint_order(order, winch_names, name="execution.joint_order"):
    """The command order of forward_command mode: ``order`` (None or empty:
    ``winch_names``), else every winch name exactly once; InputError naming ``name``."""
    if not order:
        return list(winch_names)
    if len(order) != len(winch_names) or set(order) != set(winch_names):
        missing = [n for n in winch_names if n not in order]
        unknown = [n for n in order if n not in winch_names]
        twice = sorted({n for n in order if list(order).count(n) > 1})
        why = "; ".join(f"{what} {', '.join(names)}" for what, names in
                        (("missing", missing), ("not a winch", unknown), ("twice", twice))
                        if names)
        raise InputError(name, list(order), f"must list robot.winch_names, each once: {why}")
    return list(order)


def forward_command(joint_state, order):
    """std_msgs/Float64MultiArray of a JointState's positions (m) in the joint ``order``
    (a JointGroupPositionController's ``joints``): data only, no layout (the controller
    reads data and checks its size)."""
    from std_msgs.msg import Float64MultiArray
    by_name = dict(zip(joint_state.name, joint_state.position))
    return Float64MultiArray(data=[float(by_name[n]) for n in order])
