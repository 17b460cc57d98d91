"""A burst of PlanPath goals over real DDS: 100 goals sent at once from 5 clients, a
random fifth of them cancelled at a random moment. Every goal gets a goal response, every
accepted goal a result (succeeded, canceled, or aborted with BUSY beyond the node's queue),
and the node records each goal and its result. Before the action's queues were deepened
(``interface.ACTION_QOS``), 4 to 10 goals of a burst of 20 never got a goal response.

The node plans with the TEST DOUBLE planner (test/doubles/fake_planner.py), each plan
taking at least 50 ms, so that the queue fills and cancels meet goals in every state.
"""

import random

import pytest

rclpy = pytest.importorskip("rclpy")

from action_msgs.msg import GoalStatus  # noqa: E402
from cdh_planner.ros.actions import RaceFreeActionClient  # noqa: E402

from cdh_planner_interfaces.action import PlanPath  # noqa: E402

from cdh_planner.recording.mcap_log import read_run  # noqa: E402
from cdh_planner.ros.client import PlannerClient, plan_path_goal  # noqa: E402
from cdh_planner.ros.interface import ACTION_QOS  # noqa: E402
from ros_harness import Q1, Q2, NodeProcess, claimed_domain, sphere_pose_msg  # noqa: E402

CLIENTS, GOALS_EACH, CANCEL_SHARE = 5, 20, 0.2
SEND_GOAL_EVENTS = "/cdh_planner/plan_path/_action/send_goal/_service_event"
GET_RESULT_EVENTS = "/cdh_planner/plan_path/_action/get_result/_service_event"
ENDED = {GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_CANCELED, GoalStatus.STATUS_ABORTED}


def spin_all(clients, condition, timeout_s, also=lambda: None):
    import time
    end = time.monotonic() + timeout_s
    while not condition() and time.monotonic() < end:
        also()
        for c in clients:
            c.executor.spin_once(timeout_sec=0.002)
    return condition()


def test_a_burst_of_goals_with_random_cancels_is_answered_in_full(tmp_path):
    rng = random.Random(19)
    delay = tmp_path / "delay"
    delay.write_text("0.05")
    with claimed_domain() as domain, \
            NodeProcess(domain, tmp_path / "runs", fake=True,
                        env={"FAKE_PLANNER_DELAY_FILE": str(delay)}) as node:
        clients = [PlannerClient(domain_id=domain, name=f"burst{i}") for i in range(CLIENTS)]
        try:
            actions = [RaceFreeActionClient(c.node, PlanPath, c.topic("plan_path"),
                                            **ACTION_QOS) for c in clients]
            for c, a in zip(clients, actions):
                c.wait_for_node(30.0)
                assert a.wait_for_server(timeout_sec=10.0)
            goal = plan_path_goal(sphere_pose_msg(Q1), sphere_pose_msg(Q2))
            sent = [(c, a.send_goal_async(goal)) for _ in range(GOALS_EACH)
                    for c, a in zip(clients, actions)]
            cancel_at = {i: rng.randrange(0, 400) for i in range(len(sent))
                         if rng.random() < CANCEL_SHARE}   # after this many spin rounds
            results, cancels, rounds = {}, {}, [0]

            def step():
                rounds[0] += 1
                for i, (c, f) in enumerate(sent):
                    if i not in results and f.done() and f.result().accepted:
                        results[i] = f.result().get_result_async()
                    if (i in cancel_at and i not in cancels and rounds[0] >= cancel_at[i]
                            and f.done() and f.result().accepted):
                        cancels[i] = f.result().cancel_goal_async()

            def answered():
                return (all(f.done() for _, f in sent) and len(results) == sum(
                    f.result().accepted for _, f in sent) and all(r.done() for r in
                                                                    results.values()))

            done = spin_all(clients, answered, 120.0, also=step)
            no_response = [i for i, (_, f) in enumerate(sent) if not f.done()]
            assert done and not no_response, (no_response, node.log()[-3000:])
            assert all(f.result().accepted for _, f in sent)   # every goal is accepted
            statuses = [results[i].result().status for i in range(len(sent))]
            assert set(statuses) <= ENDED, statuses
            codes = {i: results[i].result().result.error_code for i in results}
            for i, status in enumerate(statuses):
                if status == GoalStatus.STATUS_CANCELED:
                    assert i in cancels and codes[i] == PlanPath.Result.CANCELED
                elif status == GoalStatus.STATUS_ABORTED:
                    assert codes[i] in (PlanPath.Result.BUSY, PlanPath.Result.CANCELED), codes[i]
                else:
                    assert codes[i] == PlanPath.Result.NONE
            assert statuses.count(GoalStatus.STATUS_SUCCEEDED) >= 1
            assert spin_all(clients, lambda: all(f.done() for f in cancels.values()), 10.0)
        finally:
            for c in clients:
                c.close()
        assert node.stop() == 0, node.log()
    events = {SEND_GOAL_EVENTS: 0, GET_RESULT_EVENTS: 0}
    for path in node.run_files():
        for topic, _, _, _ in read_run(path):
            if topic in events:
                events[topic] += 1
    assert events[SEND_GOAL_EVENTS] == events[GET_RESULT_EVENTS] == CLIENTS * GOALS_EACH
