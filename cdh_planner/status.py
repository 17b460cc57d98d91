"""How a plan ended: one closed vocabulary shared by the search, the planner, the node and the CLI.

``Status`` is a ``StrEnum``, so its members are the strings that files and messages carry
(``"no_path"`` in the plan JSON's ``reason``, the reason on ``~/plan_result``) and compare
equal to them; those strings are a contract. The planner answers the first group; the node
adds its refusals (before planning, or of a plan it must not publish). Each member has one
PlanPath error code (``ros/messages.ERROR_CODES``) and one exit code of ``cdh-planner plan``
(``commands/plan.EXIT_CODES``); tests check that both maps are complete.
"""

from enum import StrEnum


class Status(StrEnum):
    # the planner's answers
    OK = "ok"                              # a path, densely verified
    START_INFEASIBLE = "start_infeasible"  # start not wrench-feasible, or under the margin floor
    GOAL_INFEASIBLE = "goal_infeasible"    # goal not wrench-feasible, or under the margin floor
    START_IN_COLLISION = "start_in_collision"  # start hits an obstacle or cables touch (scene)
    GOAL_IN_COLLISION = "goal_in_collision"    # goal hits an obstacle or cables touch (scene)
    NO_PATH = "no_path"                    # a component was exhausted: no path at resolution r
    TIMEOUT = "timeout"                    # the deadline passed
    CHART_LIMIT = "chart_limit"            # the atlas reached its chart limit
    RESOURCE_LIMIT = "resource_limit"      # the atlas reached its memory limit
    CANCELED = "canceled"                  # the caller cancelled the plan
    INVALID = "invalid"                    # a pose off the task beyond the tolerance, or malformed
    NOT_EXECUTABLE = "not_executable"      # a path, but no trajectory that executes as checked
    # the node's refusals
    BAD_FRAME = "bad_frame"                # a pose's frame_id is not the node's base frame
    BAD_STRATEGY = "bad_strategy"          # a search strategy the planner does not have
    BUSY = "busy"                          # the plan queue is full
    NO_CURRENT_STATE = "no_current_state"  # use_current_start without a usable measured pose
    OUTPUT_LIMIT = "output_limit"          # the plan is beyond the node's output bounds
    INTERNAL_ERROR = "internal_error"      # an exception while answering (a bug)

    @property
    def is_limit(self):
        """A bound was hit: the answer says nothing about whether a path exists."""
        return self in (Status.TIMEOUT, Status.CHART_LIMIT, Status.RESOURCE_LIMIT, Status.CANCELED)

    @classmethod
    def infeasible(cls, end):
        """START_INFEASIBLE or GOAL_INFEASIBLE: the status of an ``end`` ("start" or "goal")
        that is not wrench-feasible."""
        return {"start": cls.START_INFEASIBLE, "goal": cls.GOAL_INFEASIBLE}[end]

    @classmethod
    def in_collision(cls, end):
        """START_IN_COLLISION or GOAL_IN_COLLISION: the status of an ``end`` ("start" or
        "goal") closer to an obstacle or another cable than the scene's clearance."""
        return {"start": cls.START_IN_COLLISION, "goal": cls.GOAL_IN_COLLISION}[end]
