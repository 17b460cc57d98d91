"""The node as a lifecycle node, driven over DDS by the standard lifecycle services (what
nav2's lifecycle_manager calls), and its /diagnostics.

The node runs in its own process around the TEST DOUBLE planner (test/doubles/fake_planner.py):
these tests are about the node's states, not the planner's answers.
"""

import signal

import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState

from cdh_planner.ros.client import PlannerClient
from cdh_planner.ros.core.diagnostics import Health, health_status
from cdh_planner.ros.interface import SERVICE_QOS

from ros_harness import Q1, Q2, Collector, NodeProcess, claimed_domain, sphere_pose_msg

NODE = "/cdh_planner"


class Lifecycle:
    """change_state / get_state clients on the client's node (as a lifecycle manager has)."""

    def __init__(self, client):
        self.client = client
        make = client.node.create_client
        self.change = make(ChangeState, f"{NODE}/change_state", qos_profile=SERVICE_QOS)
        self.get = make(GetState, f"{NODE}/get_state", qos_profile=SERVICE_QOS)
        assert self.change.wait_for_service(timeout_sec=60.0)

    def state(self):
        return self.client.call(self.get, GetState.Request(), 60.0).current_state.label

    def transition(self, transition_id):
        request = ChangeState.Request(transition=Transition(id=transition_id))
        return self.client.call(self.change, request, 60.0).success


def plans(client):
    """Whether ~/plan answers with a path (the test double's straight line)."""
    return len(client.plan(sphere_pose_msg(Q1), sphere_pose_msg(Q2), timeout_s=60).path.poses) > 0


def test_the_lifecycle_transitions_work_by_service_calls(tmp_path):
    with claimed_domain() as domain, \
            NodeProcess(domain, tmp_path, params=["autostart:=false"], fake=True) as node, \
            PlannerClient(domain_id=domain) as client:
        client.wait_for_node(timeout_s=60)
        life = Lifecycle(client)
        assert life.state() == "unconfigured"
        assert not plans(client), "an unconfigured node must not plan"
        assert node.run_files() == [], "the run file is opened by configure"
        assert life.transition(Transition.TRANSITION_CONFIGURE)
        assert life.state() == "inactive" and len(node.run_files()) == 1
        assert not plans(client), "an inactive node must not plan"
        ok, message = client.execute()
        assert not ok and "inactive" in message
        assert life.transition(Transition.TRANSITION_ACTIVATE) and life.state() == "active"
        assert plans(client)
        assert life.transition(Transition.TRANSITION_DEACTIVATE) and life.state() == "inactive"
        assert not plans(client)
        assert life.transition(Transition.TRANSITION_CLEANUP) and life.state() == "unconfigured"
        assert life.transition(Transition.TRANSITION_CONFIGURE)       # again, from scratch
        assert life.transition(Transition.TRANSITION_ACTIVATE) and plans(client)
        assert life.transition(Transition.TRANSITION_ACTIVE_SHUTDOWN)
        assert life.state() == "finalized"
        assert node.stop() == 0, node.log()


def test_a_bad_parameter_fails_configure_naming_it_and_the_node_stays_up(tmp_path):
    with claimed_domain() as domain, \
            NodeProcess(domain, tmp_path, params=["autostart:=false", "log_dir:=''"],
                        fake=True) as node, \
            PlannerClient(domain_id=domain) as client:
        client.wait_for_node(timeout_s=60)
        life = Lifecycle(client)
        assert not life.transition(Transition.TRANSITION_CONFIGURE)
        assert life.state() == "unconfigured"
        assert "log_dir" in node.log()
        client.set_parameters({"log_dir": str(tmp_path / "runs")})
        assert life.transition(Transition.TRANSITION_CONFIGURE)
        assert life.state() == "inactive"


def test_diagnostics_arrive_with_the_state(tmp_path):
    with claimed_domain() as domain, \
            NodeProcess(domain, tmp_path, fake=True) as node, \
            PlannerClient(domain_id=domain) as client:
        got = Collector(client.node, DiagnosticArray, "/diagnostics", 10)
        client.wait_for_node(timeout_s=60)
        assert plans(client)
        assert client.spin_until(lambda: len(got.items) >= 3, 60.0), node.log()
        status = got.messages[-1].status[0]
        values = {kv.key: kv.value for kv in status.values}
        assert status.name == "/cdh_planner: planner" and status.hardware_id == "robot2"
        assert status.level == DiagnosticStatus.OK
        assert values["state"] == "active" and values["activity"] == "idle"
        assert values["queued"] == "0" and values["last_plan_ok"] == "true"
        assert values["last_plan"] == "straight line (test double)"
        assert float(values["last_plan_age_s"]) >= 0.0
        assert values["recording"].endswith(".mcap")
        assert values["joint_states_age_s"] == "none"


@pytest.mark.parametrize("health, level, words", [
    (Health(state="unconfigured"), DiagnosticStatus.WARN, "not serving"),
    (Health(state="inactive"), DiagnosticStatus.WARN, "not serving"),
    (Health(state="active"), DiagnosticStatus.OK, "idle"),
    (Health(state="active", recording="failed"), DiagnosticStatus.WARN, "recording failed"),
    (Health(state="active", activity="executing"), DiagnosticStatus.WARN, "without fresh"),
    (Health(state="active", activity="executing", joint_states_age_s=2.0,
            joint_states_max_age_s=1.0), DiagnosticStatus.WARN, "without fresh"),
    (Health(state="active", activity="executing", joint_states_age_s=0.1),
     DiagnosticStatus.OK, "executing"),
    (Health(state="active", last_plan="no path", last_plan_ok=False), DiagnosticStatus.OK,
     "idle"),   # a failed plan is an answer, not a fault of the node
])
def test_diagnostic_levels(health, level, words):
    status = health_status(health, "n")
    assert status.level == level and words in status.message


def test_configure_warms_the_planners_kernel():
    """plan_requests.warm_up (called on every planner the node makes: configure, new parameters)
    evaluates the constraint's compiled kernel once; a planner without one is left as is."""
    from cdh_planner.ros.core.plan_requests import warm_up
    calls = []

    class Constraint:
        def lift(self, p, tau):
            calls.append(("lift", tuple(p), tuple(tau)))
            return "x"

        def residual_and_jacobian(self, x):
            calls.append(("F", x))

    class Planner:
        constraint = Constraint()

    planner = Planner()
    assert warm_up(planner) is planner and [c[0] for c in calls] == ["lift", "F"]
    double = object()
    assert warm_up(double) is double


def test_an_invalid_transition_by_id_is_refused_and_the_node_keeps_serving(tmp_path):
    """ChangeState by id with a transition the current state does not have (configure or
    activate to an active node, an unknown id): refused (success false, logged naming it);
    the node stays active and keeps planning. Before: rclpy raised in its change_state
    callback, the executor stopped and the process exited 0."""
    with claimed_domain() as domain, \
            NodeProcess(domain, tmp_path, fake=True) as node, \
            PlannerClient(domain_id=domain) as client:
        client.wait_for_node(timeout_s=60)
        life = Lifecycle(client)
        assert life.state() == "active"
        for bad in (Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE, 99):
            assert not life.transition(bad), bad
            assert life.state() == "active", (bad, node.log())
            assert plans(client), node.log()
        assert node.proc.poll() is None, node.log()
        assert "transition 99 refused" in node.log()
        assert node.stop() == 0, node.log()


def test_an_executor_that_stops_on_an_error_exits_non_zero(tmp_path, monkeypatch):
    """node_main: an exception out of the executor (a callback that raised) is a crash:
    logged naming it, exit 1 (before: exit 0, as a clean stop)."""
    from rclpy.executors import MultiThreadedExecutor

    from cdh_planner.ros.node import main as node_main
    from ros_harness import ROBOT2, fake_planner_class

    def crash(self, *args, **kwargs):
        raise RuntimeError("a callback raised")

    monkeypatch.setattr(MultiThreadedExecutor, "spin", crash)
    lines = []
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with claimed_domain() as domain:
            monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
            rc = node_main.main(["--params-file", str(ROBOT2), "-p", f"log_dir:={tmp_path}",
                                 "-p", "autostart:=false"], fake_planner_class(), lines.append)
    finally:   # main() takes SIGINT / SIGTERM over: give them back to pytest
        for s, handler in handlers.items():
            signal.signal(s, handler)
    assert rc == 1, lines
    assert any("executor stopped: a callback raised" in line for line in lines), lines
