"""One node parameter's declaration (``Spec``): small and rclpy-free, so the parameter table
(``params.py``) and the modules that bring their own parameters (the command outlets,
``execution/command_outlets.py``) share it without importing each other."""

from dataclasses import dataclass

from ...fields import BOOL, CHOICE, INT, MATRIX, NAME, NAMES, NUMBER, NUMBERS, TEXT, TEXTS, Field

# the ROS parameter type of each kind of field (the "type" of docs/parameters.md)
ROS_TYPES = {BOOL: "bool", INT: "int", NUMBER: "double", NUMBERS: "doubles", MATRIX: "doubles",
             TEXT: "string", NAME: "string", CHOICE: "string", NAMES: "strings", TEXTS: "strings"}


@dataclass(frozen=True, kw_only=True)
class Spec(Field):
    """One parameter: a ``fields.Field`` whose key is the parameter's name (default
    REQUIRED: from the robot file; None for an optional list left empty). ``start_only``: a
    topic or action name read once at start (the subscription, publisher or client it names
    is made then): read-only, a ROS name."""

    start_only: bool = False

    @property
    def name(self):
        return self.key

    @property
    def type(self):
        """Its ROS parameter type: bool, int, double, doubles, string or strings."""
        return ROS_TYPES[self.kind]
