"""Property-based tests of GetPlan requests (hypothesis), in process: whatever a request
holds (any frame, NaN, inf or huge coordinates, zero or unnormalised quaternions, any
tolerance), the node's request check either gives two poses or an InputError naming a
field in one short line, and planning them answers a PlanResult with a known reason: it
never raises. The same for a PlanPath goal's own fields (strategy, timeout_s). Bounded: few
examples, a deadline, derandomized."""

import math
from dataclasses import replace
from datetime import timedelta

import pytest

pytest.importorskip("rclpy")

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from nav_msgs.srv import GetPlan  # noqa: E402

from conftest import PROBLEMS  # noqa: E402
from cdh_planner.errors import MAX_MESSAGE_CHARS, InputError  # noqa: E402
from cdh_planner.parsing.problem import load_problem  # noqa: E402
from cdh_planner.planner import Planner  # noqa: E402
from cdh_planner.ros.core.plan_requests import PlanCall, request_poses, run_planner  # noqa: E402
from cdh_planner.settings import STRATEGY_CHOICES  # noqa: E402
from cdh_planner.status import Status  # noqa: E402

FRAME = "cdh_base"
PROBLEM = load_problem(PROBLEMS / "robot2_q1_q2.yaml")
PLANNER = Planner(PROBLEM.robot, PROBLEM.task, replace(PROBLEM.settings, timeout_s=2.0))
KNOWN = set(Status)  # the one closed vocabulary (status.py)

numbers = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                    st.floats(-1.0, 1.0), st.sampled_from([0.0, 1e308, -1e308, 1e-320]))
frames = st.one_of(st.just(FRAME), st.text(max_size=20))


def _pose(msg, frame, values):
    msg.header.frame_id = frame
    p, q = msg.pose.position, msg.pose.orientation
    p.x, p.y, p.z, q.x, q.y, q.z, q.w = values
    return msg


@settings(max_examples=40, deadline=timedelta(seconds=10), derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(frames, st.lists(numbers, min_size=7, max_size=7), frames,
       st.lists(numbers, min_size=7, max_size=7), numbers)
def test_any_getplan_request_is_answered_or_refused_in_one_line(f0, v0, f1, v1, tolerance):
    request = GetPlan.Request()
    _pose(request.start, f0, v0)
    _pose(request.goal, f1, v1)
    request.tolerance = float(tolerance) if math.isfinite(tolerance) and abs(tolerance) < 3e38 else 0.0
    try:
        start, goal = request_poses(request, FRAME)
    except InputError as exc:
        text = str(exc)
        assert "\n" not in text and len(text) <= MAX_MESSAGE_CHARS
        assert exc.field.startswith(("start", "goal"))
        return
    result = run_planner(PLANNER, start, goal, PlanCall.of_get_plan(request))
    assert result.reason in KNOWN and result.reason != "internal_error", result.message
    assert "\n" not in result.message


def test_the_paper_request_still_plans():
    from cdh_planner.model.pose import quaternion_from_tau
    request = GetPlan.Request()
    for msg, pose in ((request.start, PROBLEM.start), (request.goal, PROBLEM.goal)):
        _pose(msg, FRAME, [*pose.p, *quaternion_from_tau(pose.tau)])
    start, goal = request_poses(request, FRAME)
    assert run_planner(PLANNER, start, goal).success


@settings(max_examples=40, deadline=timedelta(seconds=10), derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(st.sampled_from(("",) + tuple(STRATEGY_CHOICES)), st.text(max_size=20)),
       numbers)
def test_any_plan_path_goal_strategy_and_timeout_is_planned_or_refused_in_one_line(
        strategy, timeout_s):
    """PlanPath's own fields (any strategy text, any timeout_s: NaN, inf, negative, huge)
    on the paper's q1 -> q2: planned, or refused naming the field, never raised."""
    from cdh_planner.model.pose import quaternion_from_tau
    from cdh_planner_interfaces.action import PlanPath
    goal = PlanPath.Goal(strategy=strategy, timeout_s=timeout_s)
    for msg, pose in ((goal.start, PROBLEM.start), (goal.goal, PROBLEM.goal)):
        _pose(msg, FRAME, [*pose.p, *quaternion_from_tau(pose.tau)])
    call = PlanCall.of_plan_path(goal)
    start, goal_pose = request_poses(call, FRAME)
    result = run_planner(PLANNER, start, goal_pose, call)
    assert "\n" not in result.message and len(result.message) <= 2 * MAX_MESSAGE_CHARS
    valid_strategy = strategy in ("",) + tuple(STRATEGY_CHOICES)
    valid_timeout = timeout_s == 0.0 or _valid_setting("timeout_s", timeout_s)
    if valid_strategy and valid_timeout:
        assert result.reason in (Status.OK, Status.TIMEOUT), result.message
    else:
        assert result.reason in ("bad_strategy", "invalid"), result.message
        assert ("strategy" if not valid_strategy else "timeout_s") in result.message


def _valid_setting(name, value):
    from cdh_planner.settings import check_setting
    try:
        check_setting(name, value)
        return True
    except InputError:
        return False
