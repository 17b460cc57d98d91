"""The planner's settings: one schema that every edge is generated from.

Each ``PlannerSettings`` field carries its declaration (``Setting``, a ``fields.Field`` with
the node parameter's name and the CLI flag: kind, unit, range or choices, description) and
``check_setting`` reads a value by it (``fields.read``). The node's parameter descriptors (``ros/core/params.py``), the problem file's keys
(``parsing/problem.py``) and the ``plan`` command's flags (``commands/plan.py``) are built from
``SETTINGS``, so a new setting is one field here. The strategy's choices are the search's
registry (``search.strategies.STRATEGIES``) read when used, so a strategy registered later is a
choice of every edge too.
"""

from collections.abc import Sequence
from dataclasses import dataclass, field, fields

from .fields import BOOL, CHOICE, INT, NUMBER, Field, declared, read
from .search.strategies import AUTO, STRATEGIES

COSTS = ("auto", "so3", "great_circle", "se3")


@dataclass(frozen=True, kw_only=True)
class Setting(Field):
    """The declaration of one setting (a Field: its key is the PlannerSettings field's name):
    ``parameter`` (the node's), ``flag`` (the CLI's); ``top_level``: a problem-file key
    beside ``planner:`` rather than inside it."""

    parameter: str
    flag: str
    top_level: bool = False


class LiveChoices(Sequence):
    """Choices read from a registry whenever they are used (``names()``: a tuple), so
    the schema, the node parameter and the CLI see what is registered now; equal to the
    tuple of the same names."""

    def __init__(self, names):
        self.names = names

    def __getitem__(self, k):
        return self.names()[k]

    def __len__(self):
        return len(self.names())

    def __iter__(self):  # one read of the registry per loop, not one per item
        return iter(self.names())

    def __eq__(self, other):
        return isinstance(other, Sequence) and tuple(self) == tuple(other)

    def __hash__(self):  # as the tuple it equals now
        return hash(tuple(self))

    def __repr__(self):
        return repr(self.names())


STRATEGY_CHOICES = LiveChoices(lambda: (AUTO,) + tuple(STRATEGIES))


def _strategy_description():
    """The strategy setting's description, from the registry (the strategies registered
    when this module is imported: the built-in ones)."""
    return ("search strategy, from both ends: auto (astar up to 3-D, gbf above or with a "
            "clearance weight), " + ", ".join(f"{name} ({cls.description})"
                                               for name, cls in STRATEGIES.items()))


def _setting(default, kind, **meta):
    """A PlannerSettings field of ``kind`` (fields.KINDS) declared by its Setting."""
    return field(default=default, metadata={"setting": Setting("", kind, **meta)})


@dataclass
class PlannerSettings:
    """How a plan is searched and timed. Units in each field's ``Setting``."""

    strategy: str = _setting(
        "auto", CHOICE, parameter="planner.strategy", flag="--strategy", unit="",
        description=_strategy_description(), choices=STRATEGY_CHOICES, top_level=True)
    cost: str = _setting(
        "auto", CHOICE, parameter="planner.cost", flag="--cost", unit="",
        description="path cost: auto (the paper's for the task), so3 (rad; slices fixing x, y, "
                    "z), great_circle (m; sphere task) or se3 (m)",
        choices=COSTS, top_level=True)
    radius: float = _setting(
        0.0, NUMBER, parameter="planner.radius", flag="--radius", unit="scaled units, about rad",
        description="chart radius in the atlas' scaled units (about rad of platform motion); 0: "
                    "by the task's dimension (0.1 up to 3-D, 0.5 for free flight)",
        low=0.0, high=10.0)
    timeout_s: float = _setting(
        60.0, NUMBER, parameter="planner.timeout_s", flag="--timeout", unit="s",
        description="give up after this many seconds (answer timeout)",
        low=0.0, high=86400.0, open_low=True)
    max_charts: int = _setting(
        100_000, INT, parameter="planner.max_charts", flag="--max-charts", unit="charts",
        description="give up after this many charts (answer chart_limit)", low=2, high=100_000_000)
    max_memory_mb: float = _setting(
        1024.0, NUMBER, parameter="planner.max_memory_mb", flag="--max-memory", unit="MiB",
        description="give up when the atlas holds this much memory (answer resource_limit)",
        low=0.0, high=1_000_000.0, open_low=True)
    complete: bool = _setting(
        False, BOOL, parameter="planner.complete", flag="--complete", unit="",
        description="keep growing the atlas to the whole component after reaching the goal")
    margin_floor: float = _setting(
        1e-3, NUMBER, parameter="planner.margin_floor", flag="--margin-floor", unit="normalised",
        description="least normalised feasibility margin of a planned waypoint",
        low=0.0, high=1.0, open_low=True, open_high=True)
    clearance_weight: float = _setting(
        0.0, NUMBER, parameter="planner.clearance_weight", flag="--clearance-weight", unit="",
        description="trade length for clearance: a path costs its length times "
                    "1 + w ln(0.5 / margin) along it, so doubling the margin along a stretch "
                    "saves 0.69 w per unit of its length, at any margin (0: the shortest path, "
                    "the paper's cost)",
        low=0.0, high=1000.0)
    accuracy_position_m: float = _setting(
        0.0, NUMBER, parameter="planner.accuracy_position_m", flag="--accuracy-position", unit="m",
        description="largest platform position error the winches' length errors "
                    "(robot.length_error, required) may cause at every pose of the path, "
                    "waypoints and the motion between them (0: off)",
        low=0.0, high=1.0)
    accuracy_orientation_rad: float = _setting(
        0.0, NUMBER, parameter="planner.accuracy_orientation_rad", flag="--accuracy-orientation",
        unit="rad", description="largest platform rotation error the winches' length errors "
                                "(robot.length_error, required) may cause at every pose of the "
                                "path (0: off)",
        low=0.0, high=3.141592653589793)
    max_cable_speed: float = _setting(
        0.05, NUMBER, parameter="trajectory.max_cable_speed", flag="--max-cable-speed", unit="m/s",
        description="per-winch cable speed limit of the trajectory",
        low=1e-4, high=100.0)
    max_cable_accel: float = _setting(
        0.2, NUMBER, parameter="trajectory.max_cable_accel", flag="--max-cable-accel", unit="m/s^2",
        description="per-winch cable acceleration limit of the trajectory",
        low=1e-4, high=1000.0)
    task_tolerance: float = _setting(
        1e-3, NUMBER, parameter="task.tolerance", flag="--task-tolerance", unit="m or rad",
        description="how far a start or goal may be off the task (m for positions, rad for "
                    "angles; a GetPlan request's tolerance > 0 overrides it): within it the "
                    "pose is projected onto the task and planned from there",
        low=1e-9, high=0.1)
    dynamics: str = _setting(
        "auto", CHOICE, parameter="trajectory.dynamics", flag="--dynamics", unit="",
        description="time parameterisation: quasi_static (winch limits, static tensions), "
                    "dynamic (TOPP-RA: tensions in range under the motion's own accelerations; "
                    "needs robot.load.mass) or auto (dynamic when the robot has a load mass)",
        choices=("auto", "quasi_static", "dynamic"))

    def check(self, name_of=lambda f: f):
        """Validate every field; the InputError names ``name_of(field)``."""
        for f in fields(self):
            check_setting(f.name, getattr(self, f.name), name_of(f.name))
        return self


SETTINGS = {s.key: s for s in declared(PlannerSettings, "setting")}  # name -> Setting


def check_setting(name, value, label=None):
    """``value`` of setting ``name`` read by its Setting (ints to floats for numbers);
    InputError naming ``label`` (or ``name``)."""
    return read(SETTINGS[name], value, label or name)
