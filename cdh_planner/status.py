"""How a plan ended: one enum shared by the search, the planner, the CLI and the node.

``Status`` is a ``StrEnum``, so its members are the strings that files and messages carry
(``"no_path"`` in the plan JSON, ``error_msg`` on ROS) and compare equal to them.
"""

from enum import StrEnum


class Status(StrEnum):
    OK = "ok"                              # a path, densely verified
    START_INFEASIBLE = "start_infeasible"  # start pose not wrench-feasible (or off the task)
    GOAL_INFEASIBLE = "goal_infeasible"    # goal pose not wrench-feasible (or off the task)
    NO_PATH = "no_path"                    # a component was exhausted: no path at resolution r
    TIMEOUT = "timeout"                    # the deadline passed
    CHART_LIMIT = "chart_limit"            # the atlas reached its chart limit
    RESOURCE_LIMIT = "resource_limit"      # the atlas reached its memory limit
    CANCELED = "canceled"                  # the caller cancelled the plan
    INVALID = "invalid"                    # request inconsistent with the task
    NOT_EXECUTABLE = "not_executable"      # a path, but no trajectory that executes as checked

    @property
    def is_limit(self):
        """A bound was hit: the answer says nothing about whether a path exists."""
        return self in (Status.TIMEOUT, Status.CHART_LIMIT, Status.RESOURCE_LIMIT, Status.CANCELED)
