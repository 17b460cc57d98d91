"""The node at its edges: every plan request is answered (a bounded queue, ``busy`` beyond
it, never silence); a plan becomes the last good (executable, latched) plan only once all
its outputs are built and published; outputs beyond the node's bounds are refused; recording
never decides an answer; a plan made while executing is published only when the stream ends;
an internal error still leaves a response record.

Most tests drive a PlannerNode in this process around the TEST DOUBLE planner
(test/doubles/fake_planner.py), calling its service callbacks directly (no executor, no
DDS), so that failures can be injected. The concurrency test runs the real node over DDS.
"""

import dataclasses
import struct
import threading
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rclpy")

from nav_msgs.srv import GetPlan  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from cdh_planner.recording.mcap_log import REQUEST_RECEIVED, RESPONSE_SENT, read_run  # noqa: E402
from cdh_planner.ros.msgs import messages as M  # noqa: E402
from cdh_planner.ros.core import plan_requests  # noqa: E402
from cdh_planner.ros.client import PlannerClient, path_duration  # noqa: E402
from ros_harness import (Q1, Q2, ROBOT2, NodeProcess, claimed_domain, fake_planner_class,  # noqa: E402
                         in_process_nodes, sphere_pose_msg, until)

FakePlanner = fake_planner_class()
PLAN_EVENTS = "/cdh_planner/plan/_service_event"


# --------------------------------------------------------------------------- in process

@pytest.fixture
def make_node(tmp_path):
    """make_node(factory=FakePlanner, params=()) -> a PlannerNode in this process
    (ros_harness.in_process_nodes)."""
    with in_process_nodes(tmp_path / "runs") as make:
        yield make


def plan(node, start=Q1, goal=Q2):
    """(response path, ~/plan_result values) of one ~/plan call."""
    statuses = []
    real = node.pub_result.publish
    node.pub_result.publish = lambda msg: (statuses.append(msg), real(msg))
    try:
        response = node._plan(GetPlan.Request(start=sphere_pose_msg(start),
                                              goal=sphere_pose_msg(goal)), GetPlan.Response())
    finally:
        node.pub_result.publish = real
    [status] = statuses
    values = M.status_values(status)
    assert values["path_stamp"] == str(M.time_ns(response.plan.header.stamp))
    return response.plan, values


def execute(node):
    r = node._execute(Trigger.Request(), Trigger.Response())
    return r.success, r.message


def stop(node):
    r = node._stop(Trigger.Request(), Trigger.Response())
    return r.success, r.message


def executing_s(message):
    """The duration (s) in ``executing: N waypoints, D s at ...``."""
    return float(message.split(", ")[1].split(" s")[0])


def spy(monkeypatch, publisher):
    sent = []
    real = publisher.publish
    monkeypatch.setattr(publisher, "publish", lambda msg: (sent.append(msg), real(msg)))
    return sent


def plan_events(log_dir):
    """(event type, sequence number, request or response) of every recorded ~/plan event."""
    out = []
    for path in sorted(Path(log_dir).glob("*.mcap")):
        for topic, _, msg, _ in read_run(path):
            if topic == PLAN_EVENTS:
                body = msg.request[0] if msg.request else msg.response[0]
                out.append((msg.info.event_type, msg.info.sequence_number, body))
    return out


def test_failed_outputs_leave_nothing_to_execute(make_node, monkeypatch):
    node = make_node()

    def broken(*args, **kwargs):
        raise struct.error("'i' format requires -2147483648 <= number <= 2147483647")

    monkeypatch.setattr(plan_requests, "plan_outputs", broken)
    path, values = plan(node)
    assert not path.poses and values["error_code"] == "200"
    assert values["error_msg"].startswith("internal error: struct.error: 'i' format"), values
    ok, message = execute(node)
    assert not ok and "no plan" in message


def test_failed_outputs_keep_the_previous_plan(make_node, monkeypatch):
    node = make_node()
    good, _ = plan(node)
    assert good.poses
    trajectories = spy(monkeypatch, node.pub_trajectory)
    node.set_parameters([Parameter("trajectory.max_cable_speed", value=0.1)])
    monkeypatch.setattr(node.plans, "_publish_outputs", lambda *a, **k: 1 / 0)
    path, values = plan(node)
    assert not path.poses and "ZeroDivisionError" in values["error_msg"]
    assert not trajectories
    ok, message = execute(node)           # the previous plan, not the failed one
    assert ok and executing_s(message) == pytest.approx(path_duration(good), abs=1e-3)
    assert stop(node)[0]


def test_a_publishing_failure_midway_puts_the_previous_outputs_back(make_node, monkeypatch):
    node = make_node()
    good, _ = plan(node)
    paths = spy(monkeypatch, node.pub_path)
    real = node.pub_envelope.publish
    calls = []

    def fail_once(msg):
        calls.append(msg)
        if len(calls) == 1:
            raise RuntimeError("publisher gone")
        real(msg)

    monkeypatch.setattr(node.pub_envelope, "publish", fail_once)
    node.set_parameters([Parameter("trajectory.max_cable_speed", value=0.1)])
    path, values = plan(node)
    assert not path.poses and "publisher gone" in values["error_msg"]
    assert len(paths) == 2 and paths[-1] is node.plans.with_last(lambda p: p)[2].path    # the previous path again
    assert M.time_ns(paths[-1].header.stamp) == M.time_ns(good.header.stamp)
    ok, message = execute(node)
    assert ok and executing_s(message) == pytest.approx(path_duration(good), abs=1e-3)
    stop(node)


class SlowTimedPlanner(FakePlanner):
    """The test double, its trajectory stretched: 10^8 times longer than it should be."""

    def plan(self, start, goal, progress=None, **kwargs):
        result = super().plan(start, goal, progress)
        path = dataclasses.replace(result.path, t=result.path.t * 1e8)
        return dataclasses.replace(result, path=path)


def test_outputs_beyond_the_bounds_are_refused_with_the_reason(make_node):
    node = make_node(SlowTimedPlanner)
    path, values = plan(node)
    assert not path.poses and values["error_code"] == str(M.OUTPUT_LIMIT)
    assert "longer than the node's bound of 86400 s" in values["error_msg"], values
    assert "trajectory.max_cable_speed" in values["error_msg"]
    ok, message = execute(node)
    assert not ok and "no plan" in message


@pytest.mark.parametrize("change,why", [
    (lambda p: dict(t=p.t * 1e8), "longer than the node's bound"),
    (lambda p: dict(t=np.where(np.arange(len(p)) == 3, np.nan, p.t)), "not finite"),
    (lambda p: dict(t=p.t[::-1].copy()), "not finite and increasing from 0"),
])
def test_output_refusal(change, why):
    result = FakePlanner(*_robot_task_settings()).plan(*_poses())
    assert plan_requests.output_refusal(result) is None
    bad = dataclasses.replace(result, path=dataclasses.replace(result.path, **change(result.path)))
    refused = plan_requests.output_refusal(bad)
    assert refused.reason == "output_limit" and why in refused.message, refused.message
    many = dataclasses.replace(result, path=_repeat(result.path, plan_requests.MAX_WAYPOINTS + 1))
    assert f"more than the node's bound of {plan_requests.MAX_WAYPOINTS}" in \
        plan_requests.output_refusal(many).message


def _robot_task_settings():
    from cdh_planner.ros.core.params import node_config
    from ros_harness import file_parameters
    config = node_config(file_parameters(ROBOT2))
    return config.robot, config.task, config.settings


def _poses():
    from cdh_planner.ros.core.params import node_config
    from ros_harness import file_parameters
    base = node_config(file_parameters(ROBOT2)).base_frame
    return plan_requests.request_poses(GetPlan.Request(start=sphere_pose_msg(Q1),
                                                  goal=sphere_pose_msg(Q2)), base)


def _repeat(path, n):
    fields = {f.name: getattr(path, f.name) for f in dataclasses.fields(path)}
    k = -(-n // len(path))
    out = {name: np.concatenate([v] * k)[:n] if isinstance(v, np.ndarray) and v.shape[:1] ==
           (len(path),) else v for name, v in fields.items()}
    out["t"] = np.arange(n, dtype=float)
    return dataclasses.replace(path, **out)


def test_a_recording_failure_does_not_decide_the_answer(make_node, monkeypatch):
    node = make_node()

    def full_disk(*args, **kwargs):
        raise struct.error("'i' format requires -2147483648 <= number <= 2147483647")

    monkeypatch.setattr(node.runlog, "write", full_disk)
    monkeypatch.setattr(node.runlog, "service_event", full_disk)
    trajectories = spy(monkeypatch, node.pub_trajectory)
    path, values = plan(node)
    assert path.poses and values["error_code"] == "0" and values["outputs"] == "published"
    assert len(trajectories) == 1
    ok, message = execute(node)
    assert ok, message
    assert stop(node)[0]


def test_a_plan_made_while_executing_is_published_when_the_stream_ends(make_node, monkeypatch):
    node = make_node()
    first, _ = plan(node)
    ok, message = execute(node)
    assert ok and executing_s(message) == pytest.approx(path_duration(first), abs=1e-3)
    trajectories, paths = spy(monkeypatch, node.pub_trajectory), spy(monkeypatch, node.pub_path)
    node.set_parameters([Parameter("trajectory.max_cable_speed", value=0.1)])
    second, values = plan(node)
    assert second.poses and values["outputs"] == plan_requests.DEFERRED
    assert path_duration(second) < 0.9 * path_duration(first)
    assert not trajectories and not paths          # the controller's topic is left alone
    ok, message = execute(node)
    assert not ok and "already executing" in message
    ok, message = stop(node)                        # the stream ends: the new plan is out
    assert ok and "stopped" in message
    assert len(trajectories) == 1 and len(paths) == 1
    assert M.time_ns(paths[0].header.stamp) == M.time_ns(second.header.stamp)
    assert len(trajectories[0].points) == len(second.poses)
    ok, message = execute(node)
    assert ok and executing_s(message) == pytest.approx(path_duration(second), abs=1e-3)
    stop(node)
    third, values = plan(node)                     # not executing: published at once
    assert values["outputs"] == plan_requests.PUBLISHED and len(trajectories) == 2


def test_a_plan_that_fails_while_executing_changes_nothing(make_node, monkeypatch):
    node = make_node()
    first, _ = plan(node)
    assert execute(node)[0]
    monkeypatch.setattr(plan_requests, "plan_outputs", lambda *a, **k: 1 / 0)
    path, values = plan(node)
    assert not path.poses and "internal error" in values["error_msg"]
    monkeypatch.undo()
    assert stop(node)[0]
    ok, message = execute(node)
    assert ok and executing_s(message) == pytest.approx(path_duration(first), abs=1e-3)
    stop(node)


def test_an_internal_error_still_records_the_response(make_node, monkeypatch):
    node = make_node()
    plan(node)

    def crash(*args, **kwargs):
        raise RuntimeError("the planner thread fell over")

    monkeypatch.setattr(node.plans, "compute", crash)
    path, values = plan(node)
    assert not path.poses and "fell over" in values["error_msg"]
    monkeypatch.undo()
    node.close()
    events = plan_events(node.config.log_dir)
    assert [(e, s) for e, s, _ in events] == [(REQUEST_RECEIVED, 1), (RESPONSE_SENT, 1),
                                              (REQUEST_RECEIVED, 2), (RESPONSE_SENT, 2)]
    assert len(events[1][2].plan.poses) > 0 and len(events[3][2].plan.poses) == 0
    assert events[3][2].plan.header.frame_id == "cdh_base"


# --------------------------------------------------------------------------- the queue

class Polled:
    """A ``cancel`` for PlanQueue.wait that counts how often it was polled (once per look at
    the queue, at least every CANCEL_POLL_S while waiting), before and after ``set()``."""

    def __init__(self):
        self.polls, self.polls_after_set, self._set = 0, 0, False

    def set(self):
        self._set = True

    def is_set(self):
        self.polls += 1
        self.polls_after_set += self._set
        return self._set


def test_plan_queue_runs_in_order_and_refuses_beyond_its_depth():
    queue = plan_requests.PlanQueue(depth=2)
    first = queue.enter()
    assert queue.wait(first, timeout_s=0.1)            # runs at once
    waiting = [queue.enter(), queue.enter()]
    assert None not in waiting and queue.enter() is None and len(queue) == 3
    order, polled = [], {t: Polled() for t in waiting}

    def take(turn):
        if queue.wait(turn, polled[turn], timeout_s=5.0):
            order.append(turn)
            queue.leave()

    threads = [threading.Thread(target=take, args=(t,)) for t in reversed(waiting)]
    for t in threads:
        t.start()
    # each waiter has looked at the queue, waited and looked again (two polls), or has
    # returned: either way a turn taken while the first runs would be in ``order`` now
    assert until(lambda: all(p.polls >= 2 or not t.is_alive()
                             for p, t in zip(map(polled.get, reversed(waiting)), threads)))
    assert not order                                   # the first is still running
    queue.leave()
    for t in threads:
        t.join(5.0)
    assert order == waiting and len(queue) == 0


def test_plan_queue_close_answers_the_waiting():
    queue = plan_requests.PlanQueue(depth=1)
    assert queue.wait(queue.enter(), timeout_s=0.1)
    turn = queue.enter()
    got = []
    thread = threading.Thread(target=lambda: got.append(queue.wait(turn)))
    thread.start()
    queue.close()
    thread.join(2.0)
    assert got == [False] and queue.enter() is None


def test_plan_queue_drop_and_cancel_give_a_waiting_turn_up():
    """A request refused before planning drops its turn, one cancelled while it waits
    leaves within CANCEL_POLL_S: the next one runs, and their places are free."""
    queue = plan_requests.PlanQueue(depth=2)
    assert queue.wait(queue.enter(), timeout_s=0.1)
    dropped, cancelled = queue.enter(), queue.enter()
    assert queue.enter() is None
    queue.drop(dropped)
    queue.drop(dropped)                                # idempotent
    cancel = Polled()
    got = []
    thread = threading.Thread(target=lambda: got.append(queue.wait(cancelled, cancel)))
    thread.start()
    assert until(lambda: cancel.polls >= 2)            # waiting (looked, waited, looked)
    cancel.set()
    thread.join(10.0)                                  # 10 s: only a hang
    # it left at the first poll after the cancel (at most CANCEL_POLL_S later), not later
    assert got == [False] and cancel.polls_after_set == 1
    assert len(queue) == 1                             # only the running one
    nxt = queue.enter()
    queue.leave()
    assert queue.wait(nxt, timeout_s=0.1)


def test_depth_zero_is_one_plan_at_a_time():
    queue = plan_requests.PlanQueue(depth=0)
    assert queue.wait(queue.enter(), timeout_s=0.1)
    assert queue.enter() is None
    queue.leave()
    assert queue.enter() is not None


# --------------------------------------------------------------------------- over DDS

CLIENTS, CALLS = 5, 10


def test_every_concurrent_request_is_answered(tmp_path):
    """50 GetPlan calls in flight at once from 5 clients (the real planner, a direct motion
    q1 -> q2): 50 answers, each a plan or an explicit ``busy``; all 50 requests and
    responses recorded."""
    with claimed_domain() as domain, NodeProcess(domain, tmp_path / "runs") as node:
        clients = [PlannerClient(domain_id=domain, name=f"burst{i}") for i in range(CLIENTS)]
        try:
            for c in clients:
                c.wait_for_node(30.0)
            request = GetPlan.Request(start=sphere_pose_msg(Q1), goal=sphere_pose_msg(Q2))
            calls = [(c, c.plan_client.call_async(request)) for c in clients
                     for _ in range(CALLS)]
            end = time.monotonic() + 60.0       # only a hang: how long it takes is not tested
            while time.monotonic() < end and not all(f.done() for _, f in calls):
                for c in clients:
                    c.executor.spin_once(timeout_sec=0.005)
            answered = [(c, f.result()) for c, f in calls if f.done()]
            assert len(answered) == CLIENTS * CALLS, (len(answered), node.log()[-3000:])
            outcomes = {"plan": 0, "busy": 0}
            for c, response in answered:        # each answer's ~/plan_result
                stamp = str(M.time_ns(response.plan.header.stamp))

                def result():
                    return [v for v in map(M.status_values, c.results)
                            if v["path_stamp"] == stamp]

                assert c.spin_until(result, 5.0), stamp
                [values] = result()
                if response.plan.poses:
                    assert values["error_code"] == "0"
                    outcomes["plan"] += 1
                else:
                    assert values["error_msg"].startswith("busy: "), values
                    outcomes["busy"] += 1
            assert outcomes["plan"] >= 1 + plan_requests.PLAN_QUEUE_DEPTH, outcomes
        finally:
            for c in clients:
                c.close()
        assert node.stop() == 0, node.log()
        events = []
        for path in node.run_files():
            events += [m.info.event_type for t, _, m, _ in read_run(path) if t == PLAN_EVENTS]
        assert events.count(REQUEST_RECEIVED) == events.count(RESPONSE_SENT) == CLIENTS * CALLS


def test_an_undeclared_parameter_is_refused_naming_it(make_node):
    """Through the parameter service's own path (set_parameters_atomically), as
    ``ros2 param set`` reaches it: the name and value, not rclpy's empty list."""
    node = make_node()
    result = node.set_parameters_atomically([Parameter("planner.radius_typo", value=0.25)])
    assert not result.successful
    assert "planner.radius_typo" in result.reason and "0.25" in result.reason, result.reason
    assert node.set_parameters_atomically(
        [Parameter("planner.radius", value=0.25)]).successful


@pytest.mark.parametrize("bad", ["/proc/nope", "FILE"])
def test_a_log_dir_the_node_cannot_record_in_is_refused_as_a_parameter(make_node, tmp_path, bad):
    """log_dir set at run time to a directory that cannot be made (/proc/nope) or is a
    file: the parameter is refused naming it (before: accepted, only the log said recording
    was off); the node keeps its directory and records there."""
    node = make_node()
    if bad == "FILE":
        bad = str(tmp_path / "a_file")
        Path(bad).write_text("x")
    before = node.get_parameter("log_dir").value
    result = node.set_parameters_atomically([Parameter("log_dir", value=bad)])
    assert not result.successful
    assert result.reason.startswith(f"log_dir = '{bad}': cannot record there"), result.reason
    assert node.get_parameter("log_dir").value == before
    plan(node)
    assert list(Path(before).glob("*.mcap")), "still recording where it was"
    good = tmp_path / "new" / "runs"
    assert node.set_parameters_atomically([Parameter("log_dir", value=str(good))]).successful


def test_deactivate_cancels_the_running_plan(tmp_path, monkeypatch):
    """A plan call running when the node is deactivated ends (canceled: an empty path)
    within its next progress reports, not when the planner would have finished (60 s);
    the node, activated again, plans. Before: only cleanup ended it."""
    delay = tmp_path / "delay"
    delay.write_text("60")
    monkeypatch.setenv("FAKE_PLANNER_DELAY_FILE", str(delay))
    with in_process_nodes(tmp_path / "runs") as make:
        node = make()
        answers = []
        caller = threading.Thread(target=lambda: answers.append(node._plan(
            GetPlan.Request(start=sphere_pose_msg(Q1), goal=sphere_pose_msg(Q2)),
            GetPlan.Response())))
        caller.start()
        assert until(lambda: node.plans.planning, 30.0)
        node.trigger_deactivate()
        caller.join(30.0)
        assert not caller.is_alive(), "deactivate did not end the running plan"
        assert len(answers[0].plan.poses) == 0
        assert node.lifecycle_state == "inactive"
        delay.write_text("0")
        node.trigger_activate()
        plan_path, values = plan(node)
        assert len(plan_path.poses) > 0, values


def test_diagnostics_keep_the_last_plan_after_finalize(make_node):
    """After shutdown (finalized) /diagnostics still names the last plan beside its
    last_plan_ok (before: last_plan 'none' beside last_plan_ok 'true'); before any plan
    both are 'none'."""
    from cdh_planner.ros.core.diagnostics import health_status
    node = make_node()
    values = M.status_values(health_status(node.diagnostics.health(), "n"))
    assert (values["last_plan"], values["last_plan_ok"]) == ("none", "none")
    plan(node)
    node.trigger_shutdown()
    health = node.diagnostics.health()
    values = M.status_values(health_status(health, "n"))
    assert values["state"] == "finalized"
    assert values["last_plan"] == "straight line (test double)" and values["last_plan_ok"] == "true"
    assert float(values["last_plan_age_s"]) >= 0.0
