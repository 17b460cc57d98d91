"""An rclpy Context for a command (``call``, ``replay``; the node may use it too): rcl's
refusal of the ROS arguments or of the ROS environment is bad input (an InputError: one
line, exit 2), not an internal error, and rcl's own log line about it stays off stderr."""

import os
import re

import rclpy

from ..errors import InputError, clip
from ..progress import stderr_held


def init_context(args=None, domain_id=None, **init_options):
    """A new rclpy Context initialised with ``args`` (``[prog, "--ros-args", ...]``).
    rcl's refusal of the arguments (a bad remap rule, ``-p`` value, a ROS_DOMAIN_ID that is
    not a number) is an InputError naming ``--ros-args``: bad input, not a bug; rcl's own
    log line about it is kept off stderr (the error says it), shown when init succeeds.
    ``init_options``: more keywords of rclpy.init (the node's signal handler options)."""
    context = rclpy.Context()
    try:
        with stderr_held():
            rclpy.init(args=args, context=context, domain_id=domain_id, **init_options)
    except Exception as exc:  # noqa: BLE001 - rclpy's RCLError, not importable by name
        given = list(args or [])
        shown = given[given.index("--ros-args") + 1:] if "--ros-args" in given else given
        if not shown:  # then the environment is the cause (ROS_DOMAIN_ID=abc)
            raise InputError("ROS environment", " ".join(
                f"{k}={v}" for k, v in sorted(os.environ.items()) if k.startswith("ROS_")),
                f"ROS 2 cannot start: {_rcl_text(exc)}") from None
        raise InputError("--ros-args", " ".join(shown), f"ROS 2 cannot start with them: "
                                                        f"{_rcl_text(exc)}") from None
    return context


def _rcl_text(exc):
    """rcl's message without its source locations (``, at /project/src/rcl/x.c:12``)."""
    return clip(re.sub(r",? at \S+\.c(pp)?:\d+", "", str(exc)), 300)
