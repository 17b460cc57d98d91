"""Declaring the node's parameters (``params.SPECS``) with ROS descriptors: descriptions,
ranges, choices, read-only names; a parameter given on the command line that the node does
not have is refused naming it."""

import sys

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, \
    SetParametersResult
from rclpy.parameter import Parameter

from ...errors import InputError
from ..core.params import PLANNER_PREFIXES, READ_ONLY, REQUIRED, SPECS

STATIC_TYPES = {"string": Parameter.Type.STRING, "bool": Parameter.Type.BOOL,
                "strings": Parameter.Type.STRING_ARRAY}


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
    if spec.type in STATIC_TYPES:
        unset = spec.default is REQUIRED or spec.default is None   # typed, no value
        return (STATIC_TYPES[spec.type] if unset else spec.default), descriptor
    # numbers: dynamically typed (ints accepted), ranges shown and checked
    descriptor.dynamic_typing = True
    low, high, _, _ = spec.bounds()
    if spec.type == "double" and low is not None:
        descriptor.floating_point_range = [FloatingPointRange(  # ROS ranges are closed
            from_value=float(low), to_value=float(high) if high is not None else sys.float_info.max)]
    if spec.type == "int" and low is not None:
        descriptor.integer_range = [IntegerRange(from_value=int(low), to_value=int(high))]
    if spec.type == "doubles" and spec.default is REQUIRED:
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
