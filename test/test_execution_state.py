"""The execution's state machine (ros/core/execution_runs.py) and the node's executions under
injected failures: every run that starts ends exactly once, with one ``~/execution_result``,
and leaves the node ready to execute again, whatever fails inside.

In process: a PlannerNode around the TEST DOUBLE planner (test/doubles/fake_planner.py);
its controller replaced by a scripted stand-in (``ScriptedController``) where a failure must
be injected, or the real TrajectoryExecutor with no action server, the node spun by an
executor of this test.
"""

import threading
import time

import numpy as np
import pytest

from cdh_planner.ros.core.execution_runs import ExecutionRuns, Phase

# --------------------------------------------------------------------------- no ROS


def test_one_run_at_a_time_and_one_end_per_run():
    runs = ExecutionRuns()
    first = runs.begin("stream")
    assert first.phase == Phase.STARTING and runs.current is first
    assert runs.begin("stream") is None                      # busy
    assert runs.advance(first, Phase.RUNNING) and runs.phase == Phase.RUNNING
    assert runs.end(first, "completed", "done")
    assert runs.phase == Phase.IDLE and runs.last is first and first.outcome == "completed"
    assert not runs.end(first, "failed", "late")             # a second end changes nothing
    assert first.outcome == "completed" and first.message == "done"
    second = runs.begin("follow_joint_trajectory")
    assert second.number == first.number + 1
    assert not runs.end(first, "failed", "stale token")      # an old run never ends a new one
    assert not runs.advance(first, Phase.STOPPING)
    assert runs.current is second


def test_stopping_never_goes_back_to_running():
    runs = ExecutionRuns()
    run = runs.begin("follow_joint_trajectory")
    assert runs.advance(run, Phase.STOPPING)
    assert not runs.advance(run, Phase.RUNNING)              # a late acceptance
    assert run.phase == Phase.STOPPING
    with pytest.raises(ValueError):
        runs.advance(run, Phase.IDLE)                        # only end() goes to idle


def test_racing_ends_end_a_run_once():
    runs = ExecutionRuns()
    for _ in range(50):
        run = runs.begin("stream")
        wins = []
        barrier = threading.Barrier(4)

        def end(outcome):
            barrier.wait()
            wins.append(runs.end(run, outcome, outcome))

        threads = [threading.Thread(target=end, args=(o,))
                   for o in ("completed", "stopped", "failed", "stopped")]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert wins.count(True) == 1 and runs.phase == Phase.IDLE


def test_live_markers_come_at_their_rate_of_the_looks():
    """Looks at 20 Hz, markers at 10 Hz: every other look, with the looks late or early by
    up to a fifth of their period; markers at 20 Hz or more: every look; at 1 Hz: every
    20th."""
    from cdh_planner.ros.core.live_state import LiveRates
    looks = np.arange(200) / 20.0 + 0.01 * np.sin(np.arange(200))   # s

    def drawn(markers_hz):
        rates = LiveRates(20.0, markers_hz)
        return [k for k, t in enumerate(looks) if rates.markers_due(t)]

    assert drawn(10.0) == list(range(0, 200, 2))
    assert drawn(20.0) == drawn(40.0) == list(range(200))
    assert drawn(1.0) == list(range(0, 200, 20))


# --------------------------------------------------------------------------- the node

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("control_msgs")

from diagnostic_msgs.msg import DiagnosticStatus  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from cdh_planner.ros.execution import winches  # noqa: E402
from cdh_planner.ros.msgs import messages as M  # noqa: E402
from cdh_planner.ros.execution import plan_execution  # noqa: E402
from ros_harness import Q1, Q2, in_process_nodes, sphere_pose_msg, until  # noqa: E402

FOLLOW = [Parameter("execution.mode", value="follow_joint_trajectory")]
STREAM = [Parameter("execution.mode", value="stream")]


@pytest.fixture
def node(tmp_path):
    with in_process_nodes(tmp_path / "runs") as make:
        node = make()
        node.results = []
        real = node.pub_execution.publish
        node.pub_execution.publish = lambda msg: (node.results.append(msg), real(msg))
        yield node


def plan(node):
    from nav_msgs.srv import GetPlan
    response = node._plan(GetPlan.Request(start=sphere_pose_msg(Q1), goal=sphere_pose_msg(Q2)),
                          GetPlan.Response())
    assert response.plan.poses
    return response.plan


def execute(node):
    r = node._execute(Trigger.Request(), Trigger.Response())
    return r.success, r.message


def stop(node):
    return node._stop(Trigger.Request(), Trigger.Response()).message


def outcomes(node):
    return [M.status_values(s)["outcome"] for s in node.results]


def spin_until(node, condition, timeout_s=10.0):
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    try:
        end = time.monotonic() + timeout_s
        while not condition() and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.02)
    finally:
        executor.remove_node(node)
        executor.shutdown()
    return condition()


def finish_stream(node, monkeypatch):
    """Run the stream to its end: its clock moved past the duration, one tick."""
    stream = node._execution._stream
    later = stream.start + stream.duration + 1.0
    monkeypatch.setattr(plan_execution.time, "monotonic", lambda: later)
    node._execution._tick()
    monkeypatch.undo()


def assert_ready(node, results):
    """``results`` execution results so far (one per run), not executing, and a stream
    execution starts again."""
    assert len(node.results) == results, outcomes(node)
    assert not node._execution.running and node._execution.runs.phase == Phase.IDLE
    node.set_parameters(STREAM)
    ok, message = execute(node)
    assert ok, message
    assert "stopped" in stop(node)


# ---- the defects the bad-input campaign met, as they were met: a failed run next to a completed one

def test_a_failed_controller_run_after_a_completed_stream_does_not_wedge(node, monkeypatch):
    """A stream completes; then follow_joint_trajectory with no controller: the run fails
    naming the action (rclpy refused the changed severity of one logging call site, which
    left the node executing forever), and the node executes again."""
    plan(node)
    assert execute(node)[0]
    finish_stream(node, monkeypatch)
    assert outcomes(node) == ["completed"]
    node.set_parameters(FOLLOW)
    node._execution.outlets["follow_joint_trajectory"].controller.server_wait_s = 0.2
    ok, message = execute(node)
    assert ok, message
    assert spin_until(node, lambda: len(node.results) == 2), node.results
    assert outcomes(node) == ["completed", "failed"]
    assert node.results[-1].level == DiagnosticStatus.ERROR
    assert "no action server" in node.results[-1].message
    assert "not executing" in stop(node)
    assert_ready(node, 2)


def test_a_completed_stream_after_a_failed_controller_run_keeps_the_node(node, monkeypatch):
    """The opposite order: the failed run ends, then the next stream run completes (its
    end used to raise in the executor and take the node down)."""
    plan(node)
    node.set_parameters(FOLLOW)
    node._execution.outlets["follow_joint_trajectory"].controller.server_wait_s = 0.2
    assert execute(node)[0]
    assert spin_until(node, lambda: len(node.results) == 1)
    node.set_parameters(STREAM)
    assert execute(node)[0]
    finish_stream(node, monkeypatch)
    assert outcomes(node) == ["failed", "completed"]
    assert_ready(node, 2)


# ---- fault injection at every step of a controller run

class ScriptedController:
    """Stands in for winches.TrajectoryExecutor: records on_done / on_accepted and does
    what the test scripts at start and cancel."""

    action_name = "/scripted/follow_joint_trajectory"

    def __init__(self, at_start=None, cancel_answer=True):
        self.at_start = at_start        # None, "raise", or (outcome, message) answered at once
        self.cancel_answer = cancel_answer
        self.on_done = self.on_accepted = None
        self.cancels = 0

    def start(self, trajectory_msg, on_done, on_accepted=None):
        self.on_done, self.on_accepted = on_done, on_accepted
        if self.at_start == "raise":
            raise RuntimeError("the action client fell over")
        if self.at_start is not None:
            on_done(*self.at_start)

    def cancel(self):
        self.cancels += 1
        return self.cancel_answer

    def destroy(self):
        pass


def scripted(node, **kwargs):
    controller = ScriptedController(**kwargs)
    node._execution.outlets["follow_joint_trajectory"].controller = controller
    node.set_parameters(FOLLOW)
    plan(node)
    return controller


def test_a_controller_that_raises_at_start_ends_the_run_failed(node):
    scripted(node, at_start="raise")
    ok, message = execute(node)
    assert not ok and "fell over" in message
    assert outcomes(node) == ["failed"]
    assert_ready(node, 1)


@pytest.mark.parametrize("why", ["rejected by the controller", "no action server"])
def test_a_run_refused_at_once_ends_failed_with_the_reason(node, why):
    scripted(node, at_start=(winches.FAILED, why))
    ok, message = execute(node)
    assert not ok and why in message
    assert outcomes(node) == ["failed"] and why in node.results[0].message
    assert_ready(node, 1)


@pytest.mark.parametrize("phase", ["starting", "running"])
def test_stop_in_a_phase_ends_when_the_controller_answers(node, phase):
    controller = scripted(node)
    assert execute(node)[0]
    if phase == "running":
        controller.on_accepted()
    assert node._execution.runs.phase.value == phase
    assert "cancel sent" in stop(node)
    assert node._execution.runs.phase == Phase.STOPPING and node.results == []
    assert "already executing" in execute(node)[1]
    controller.on_accepted and controller.on_accepted()   # a late acceptance: still stopping
    assert node._execution.runs.phase == Phase.STOPPING
    controller.on_done(winches.STOPPED, "canceled by the controller")
    assert outcomes(node) == ["stopped"]
    assert_ready(node, 1)


def test_stop_when_the_controller_has_nothing_running_ends_at_once(node):
    """The result was lost (the controller's run ended without telling): ~/stop ends it."""
    scripted(node, cancel_answer=False)
    assert execute(node)[0]
    assert "nothing was running" in stop(node)
    assert outcomes(node) == ["stopped"]
    assert_ready(node, 1)


def test_a_lost_result_ends_failed_when_the_executor_gives_up(node):
    controller = scripted(node)
    assert execute(node)[0]
    controller.on_accepted()
    controller.on_done(winches.FAILED, "no result within 7.2 s of acceptance")
    assert outcomes(node) == ["failed"]
    assert_ready(node, 1)


def test_a_late_answer_of_an_old_run_does_not_end_the_next(node):
    controller = scripted(node)
    assert execute(node)[0]
    old_done = controller.on_done
    old_done(winches.COMPLETED, "completed")
    assert execute(node)[0]
    old_done(winches.FAILED, "a late duplicate of the old run")
    assert node._execution.running and outcomes(node) == ["completed"]
    controller.on_done(winches.COMPLETED, "completed")
    assert outcomes(node) == ["completed", "completed"]


@pytest.mark.parametrize("broken", ["logger", "result publisher", "hand-over"])
def test_an_end_whose_side_effects_raise_still_ends(node, monkeypatch, broken):
    controller = scripted(node)
    assert execute(node)[0]
    if broken == "logger":
        class Broken:
            def __getattr__(self, name):
                def fail(*a, **k):
                    raise ValueError("Logger severity cannot be changed between calls.")
                return fail
        monkeypatch.setattr(node, "get_logger", lambda: Broken())
    elif broken == "result publisher":
        monkeypatch.setattr(node.pub_execution, "publish",
                            lambda msg: (node.results.append(msg), 1 / 0))
    else:
        monkeypatch.setattr(node._execution, "_on_end", lambda pending: 1 / 0)
    controller.on_done(winches.COMPLETED, "completed")
    monkeypatch.undo()
    assert not node._execution.running
    assert_ready(node, 1)


def test_a_stream_whose_command_fails_ends_failed(node, monkeypatch):
    plan(node)
    assert execute(node)[0]
    monkeypatch.setattr(node.pub_command, "publish", lambda msg: 1 / 0)
    node._execution._tick()
    monkeypatch.undo()
    assert outcomes(node) == ["failed"] and "ZeroDivisionError" in node.results[0].message
    assert_ready(node, 1)


def test_a_stream_that_fails_on_its_first_tick_is_refused(node, monkeypatch):
    plan(node)
    monkeypatch.setattr(node.pub_command, "publish", lambda msg: 1 / 0)
    ok, message = execute(node)
    monkeypatch.undo()
    assert not ok and "streaming stopped" in message
    assert outcomes(node) == ["failed"]
    assert_ready(node, 1)


def test_shutdown_while_following_ends_stopped(node):
    controller = scripted(node)
    assert execute(node)[0]
    node._execution.close()
    assert controller.cancels == 1 and outcomes(node) == ["stopped"]
    assert not node._execution.running


def test_the_live_state_runs_on_one_thread_of_its_own(node):
    """The live state (forward kinematics, feasibility, markers) is computed on a thread of
    its own, one look at a time, and joint states are never executor callbacks: a slow
    forward kinematics (loaded machine) once took every executor thread from goals and
    results (CI: accepted use_current_start goals whose result never came), and joint
    states at 500 Hz as callbacks took most of a core. Closing ends the thread."""
    from sensor_msgs.msg import JointState
    worker = node.frames.worker
    assert worker.is_alive() and worker is not threading.current_thread()
    assert not [s for s in node.subscriptions if s.msg_type is JointState]
    assert not [t for t in node.timers if getattr(t.callback, "__self__", None) is node.frames]
    node.close()
    assert not worker.is_alive() and node.frames.worker is None


def test_the_live_state_is_computed_once_per_new_joint_state(node, monkeypatch):
    """Many looks of the live state's thread, one joint state: one ~/cable_state, and the
    pose (with its forward kinematics residual, what /diagnostics reports) of that state;
    a second joint state: one more. Counted by looks, not by time."""
    from sensor_msgs.msg import JointState
    from test_ros_execution import _lengths
    looks, published = [], []
    real_update, real_publish = node.frames.update, node.frames.pub_cables.publish
    monkeypatch.setattr(node.frames, "update", lambda: (real_update(), looks.append(1)))
    monkeypatch.setattr(node.frames.pub_cables, "publish",
                        lambda msg: (published.append(msg), real_publish(msg)))
    winch_state = node.create_publisher(JointState, "/joint_states", 10)
    lengths = _lengths(Q1)
    for k in (1, 2):
        msg = JointState(name=list(node.config.robot.winch_names), position=list(lengths))
        msg.header.stamp.sec = k
        assert until(lambda: winch_state.get_subscription_count() == 1, 10.0)
        winch_state.publish(msg)
        assert until(lambda: len(published) == k, 10.0), "the joint state was not turned " \
                                                         "into a live state"
        seen = len(looks)
        assert until(lambda: len(looks) >= seen + 5, 10.0)    # five more looks: nothing new
        assert len(published) == k and published[-1].header.stamp.sec == k
    assert node.execution.forward_kinematics_residual_m < 1e-9
    p, _ = node.execution._last_pose
    expected = sphere_pose_msg(Q1).pose.position
    np.testing.assert_allclose(p, [expected.x, expected.y, expected.z], rtol=0, atol=1e-9)
