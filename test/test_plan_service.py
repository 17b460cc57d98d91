"""The node's plan service without a ROS graph (ros/core/plan_service.py): no rclpy node, no
context; an outlet that keeps what it is handed, the TEST DOUBLE planner. Commit, rollback,
the plan made while executing, the queue's refusals and an internal error's answer."""

import threading

import pytest

pytest.importorskip("nav_msgs")

from nav_msgs.srv import GetPlan  # noqa: E402

from cdh_planner.ros.core import plan_requests  # noqa: E402
from cdh_planner.ros.core.params import node_config  # noqa: E402
from cdh_planner.ros.core.plan_service import PlanService  # noqa: E402
from ros_harness import (Q1, Q2, ROBOT2, fake_planner_class, file_parameters,  # noqa: E402
                         sphere_pose_msg)
from builtin_interfaces.msg import Time  # noqa: E402

CONFIG = node_config(file_parameters(ROBOT2))


class KeepingOutlet:
    def __init__(self):
        self.outputs, self.results, self.errors, self.fail_outputs = [], [], [], 0

    def publish_outputs(self, out):
        if self.fail_outputs:
            self.fail_outputs -= 1
            raise OSError("the publisher is gone")
        self.outputs.append(out)

    def publish_result(self, status):
        self.results.append(status)

    def publish_progress(self, status):
        pass

    def stamp(self):
        return Time(sec=1, nanosec=0)

    def error(self, text):
        self.errors.append(text)

    def answered(self, ok, line):
        pass


@pytest.fixture
def plans():
    outlet = KeepingOutlet()
    service = PlanService(CONFIG, fake_planner_class()(CONFIG.robot, CONFIG.task,
                                                      CONFIG.settings), outlet)
    service.outlet = outlet
    return service


def ask(plans):
    call = plan_requests.PlanCall.of_get_plan(GetPlan.Request(start=sphere_pose_msg(Q1),
                                                         goal=sphere_pose_msg(Q2)))
    return plans.answer(call, "run#1", "", plans.enter())


def last(plans):
    return plans.with_last(lambda plan: plan)


def test_a_plan_is_committed_with_all_its_outputs(plans):
    answer = ask(plans)
    assert answer.result.success and plans.outlet.outputs == [answer.outputs]
    assert last(plans)[2] is answer.outputs and len(plans.outlet.results) == 1


def test_a_failed_publication_keeps_and_republishes_the_previous_plan(plans):
    first = ask(plans)
    plans.outlet.fail_outputs = 1
    second = ask(plans)
    assert not second.result.success and "internal error" in second.result.message
    assert last(plans)[2] is first.outputs
    assert plans.outlet.outputs == [first.outputs, first.outputs]   # put back


def test_a_plan_made_while_executing_waits_for_the_end(plans):
    first = ask(plans)
    plans.executing = lambda: True
    second = ask(plans)
    assert second.result.success and last(plans)[2] is first.outputs
    assert plans.outlet.outputs == [first.outputs]
    plans.executing = lambda: False
    assert plans.execution_ended(publish_pending=True)
    assert last(plans)[2] is second.outputs and plans.outlet.outputs[-1] is second.outputs
    assert not plans.execution_ended(publish_pending=True)          # handed over once


def test_at_shutdown_a_pending_plan_is_dropped(plans):
    first = ask(plans)
    plans.executing = lambda: True
    ask(plans)
    assert not plans.execution_ended(publish_pending=False)
    assert last(plans)[2] is first.outputs


def test_beyond_the_queue_the_answer_is_busy_and_shutdown_cancels_the_waiting(plans):
    turns = [plans.enter() for _ in range(1 + plan_requests.PLAN_QUEUE_DEPTH)]
    assert all(t is not None for t in turns) and plans.enter() is None
    busy = plans.answer(plan_requests.PlanCall(None, None), "run#2", "", None)
    assert busy.result.reason == "busy" and not busy.path.poses
    assert plans._queue.wait(turns[0])          # the first one plans ...
    answers = []
    waiter = threading.Thread(target=lambda: answers.append(plans.answer(
        plan_requests.PlanCall(None, None), "run#3", "", turns[1])))
    waiter.start()
    plans.begin_shutdown()                      # ... the second is answered canceled
    waiter.join(5.0)
    assert answers and answers[0].result.reason == "canceled"
    assert "shutting down" in answers[0].result.message


def test_an_internal_error_is_an_answer(plans, monkeypatch):
    monkeypatch.setattr(plans, "compute", lambda *a: 1 / 0)
    answer = ask(plans)
    assert answer.result.reason == "internal_error" and "ZeroDivisionError" in answer.result.message
    assert plans.outlet.errors and len(plans.outlet.results) == 1
    assert plans.enter() is not None            # the queue moved on
