"""Declaring the node's parameters (``params.SPECS``) with ROS descriptors: descriptions,
ranges, choices, read-only names; a parameter given on the command line that the node does
not have is refused naming it."""

import sys

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, \
    SetParametersResult
from rclpy.parameter import Parameter

from ...errors import InputError
from ..core.params import BOOL, DOUBLE, DOUBLES, INT, PLANNER_PREFIXES, READ_ONLY, REQUIRED, SPECS, \
    STRING, STRINGS

STATIC_TYPES = {STRING: Parameter.Type.STRING, BOOL: Parameter.Type.BOOL,
                STRINGS: Parameter.Type.STRING_ARRAY}


def declare_parameters(node, overrides):
    """Declare every parameter of SPECS on ``node``; name -> value (None: not set).
    ``overrides``: the node's ``_parameter_overrides`` (InputError for an unknown one)."""
    names = {s.name for s in SPECS}
    unknown = sorted(n for n in overrides if n.startswith(PLANNER_PREFIXES) and n not in names)
    if unknown:
        raise InputError(unknown[0], overrides[unknown[0]].value,
                         "unknown parameter (see cdh_planner/ros/core/params.py)")
    return {spec.name: node.declare_parameter(spec.name, *_default_and_descriptor(spec)).value
            for spec in SPECS}


def _default_and_descriptor(spec):
    descriptor = ParameterDescriptor(description=spec.description,
                                     read_only=spec.name in READ_ONLY)
    if spec.choices:
        descriptor.additional_constraints = f"one of: {', '.join(spec.choices)}"
    if spec.kind in STATIC_TYPES:
        unset = spec.default is REQUIRED or spec.default is None   # typed, no value
        return (STATIC_TYPES[spec.kind] if unset else spec.default), descriptor
    # numbers: dynamically typed (ints accepted), ranges shown and checked
    descriptor.dynamic_typing = True
    if spec.kind == DOUBLE and spec.low is not None:
        descriptor.floating_point_range = [FloatingPointRange(  # ROS ranges are closed
            from_value=float(spec.low),
            to_value=float(spec.high) if spec.high is not None else sys.float_info.max)]
    if spec.kind == INT and spec.low is not None:
        descriptor.integer_range = [IntegerRange(from_value=int(spec.low),
                                                 to_value=int(spec.high))]
    if spec.kind == DOUBLES and spec.default is REQUIRED:
        descriptor.additional_constraints = "required (robot file)"
    return (None if spec.default in (REQUIRED, None) else spec.default), descriptor


def refuse_unknown(node, parameter_list):
    """SetParametersResult refusing the first parameter ``node`` does not have, naming it
    (rclpy 7.1 names none: "Invalid access to undeclared parameter(s): []"); None if all
    are known."""
    unknown = [p for p in parameter_list if not node.has_parameter(p.name)]
    if not unknown:
        return None
    return SetParametersResult(successful=False, reason=str(InputError(
        unknown[0].name, unknown[0].value,
        "not a parameter of this node (ros2 param list shows them)")))
