"""One node parameter's declaration (``Spec``) and its kinds: small and rclpy-free, so the
parameter table (``params.py``) and the modules that bring their own parameters (the
command outlets, ``execution/command_outlets.py``) share it without importing each other."""

from dataclasses import dataclass

from ...model import robot_schema as rs
from ...settings import Bounds

STRING, BOOL, INT, DOUBLE, DOUBLES, STRINGS = "string", "bool", "int", "double", "doubles", \
    "strings"
REQUIRED = rs.REQUIRED  # default of a parameter that must come from the robot file


@dataclass(frozen=True)
class Spec(Bounds):
    """One parameter: ``kind`` (STRING, BOOL, INT, DOUBLE, DOUBLES, STRINGS), ``default``
    (REQUIRED: no default; None for an optional array left empty), a description, and its
    Bounds (settings.py). ``start_only``: a topic or action name read once at start (the
    subscription, publisher or client it names is made then): read-only, a ROS name."""

    name: str
    kind: str
    default: object
    description: str
    start_only: bool = False
