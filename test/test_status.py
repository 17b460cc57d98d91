"""The one closed vocabulary of how a plan ends (cdh_planner/status.py): its strings are the
plan JSON's and ``~/plan_result``'s contract, a PlanResult carries a member and nothing
else, and every member has its exit code of ``cdh-planner plan`` (the PlanPath error codes
are checked in test_ros_messages.py). No ROS."""

import json
import math

import pytest

from cdh_planner import cli
from cdh_planner.commands import plan as plan_command
from cdh_planner.planner import PlanResult
from cdh_planner.status import Status

# the contract: these strings are in plan JSON files and recordings already written
CONTRACT = {"ok", "start_infeasible", "goal_infeasible", "start_in_collision",
            "goal_in_collision", "no_path", "timeout", "chart_limit",
            "resource_limit", "canceled", "invalid", "bad_frame", "bad_strategy", "busy",
            "no_current_state", "output_limit", "internal_error", "not_executable"}


def _result(reason):
    return PlanResult(success=reason is Status.OK, reason=reason, message="m", strategy="gbf",
                      n=2, variables=90, charts=0, time_s=0.0, cost=math.nan)


def test_the_strings_are_the_contract_and_compare_equal_to_the_members():
    assert {s.value for s in Status} == CONTRACT
    assert all(s == s.value and str(s) == s.value and Status(s.value) is s for s in Status)


def test_a_plan_result_carries_a_member_never_a_loose_string():
    assert _result(Status.BUSY).reason is Status.BUSY
    for loose in ("busy", "no plan", None):
        with pytest.raises(TypeError, match="must be a Status"):
            _result(loose)


def test_infeasible_names_the_end():
    assert Status.infeasible("start") is Status.START_INFEASIBLE
    assert Status.infeasible("goal") is Status.GOAL_INFEASIBLE
    with pytest.raises(KeyError):
        Status.infeasible("middle")


def test_every_member_has_an_exit_code_of_the_cli_contract():
    codes = plan_command.EXIT_CODES
    assert set(codes) == set(Status)
    assert (plan_command.EXIT_OK, plan_command.EXIT_NO_PLAN, plan_command.EXIT_INTERNAL) == (
        cli.EXIT_OK, cli.EXIT_NO, cli.EXIT_INTERNAL)
    assert [s for s, code in codes.items() if code == cli.EXIT_OK] == [Status.OK]
    assert [s for s, code in codes.items() if code == cli.EXIT_INTERNAL] == [Status.INTERNAL_ERROR]
    assert set(codes.values()) == {cli.EXIT_OK, cli.EXIT_NO, cli.EXIT_INTERNAL}


@pytest.mark.parametrize("status", list(Status))
def test_the_json_reason_is_the_members_string(status):
    text = json.dumps(plan_command.result_dict(_result(status)))
    assert f'"reason": "{status.value}"' in text
    assert json.loads(text)["reason"] == status.value
