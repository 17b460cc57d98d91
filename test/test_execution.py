"""Executing a plan on a trajectory controller (cdh_planner/ros/execution/winches.py).

In process: the FollowJointTrajectory goal of a cable trajectory (no effort, stamp zero),
measured cable lengths of a JointState, the start check, and the pose of measured lengths
(forward kinematics against inverse kinematics on the problem files' poses). The test
double's goal checks (test/doubles/follow_joint_trajectory_server.py) against the rules of
the Jazzy JointTrajectoryController. Over real DDS, in a ROS domain of its own: the double
in its own process, and TrajectoryExecutor / JointStateMonitor on a node spun by a
MultiThreadedExecutor as the planner node spins its own.
"""

import functools
import os
import threading
import time

import numpy as np
import pytest

pytest.importorskip("control_msgs")

from builtin_interfaces.msg import Duration, Time  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint  # noqa: E402

from cdh_planner.errors import InputError  # noqa: E402
from cdh_planner.wrench import wrench_feasibility  # noqa: E402
from cdh_planner.parsing.problem import load_problem  # noqa: E402
from cdh_planner.model.kinematics import (cable_lengths, forward_kinematics,  # noqa: E402
                                          rotation_vector_exp)
from cdh_planner.model.pose import rotation_angle_between, rotation_tt  # noqa: E402
from cdh_planner.model.forward_kinematics import nearest_waypoint  # noqa: E402
from cdh_planner.model.robot import load_robot  # noqa: E402
from cdh_planner.ros.execution import winches as X  # noqa: E402
from cdh_planner.ros.msgs.messages import cable_trajectory_msg, to_seconds  # noqa: E402

from conftest import CONFIG, PROBLEMS  # noqa: E402
from ros_harness import ControllerDouble, claimed_domain, until  # noqa: E402

ACTION = "/cable_controller/follow_joint_trajectory"
FRAME = "cdh_base"
ROBOT2 = load_robot(CONFIG / "robot2.yaml")
WINCHES = list(ROBOT2.winch_names)
TIME_SCALE = 4.0          # the double runs trajectories this many times faster


@functools.lru_cache(maxsize=None)
def planned():
    """A real plan: Robot 2, q1 -> q2 on the sphere (the direct motion, 49 waypoints,
    2.18 s), planned by the library."""
    from cdh_planner.planner import Planner
    pr = load_problem(PROBLEMS / "robot2_q1_q2.yaml")
    result = Planner(pr.robot, pr.task, pr.settings).plan(pr.start, pr.goal)
    assert result.success, result.message
    return result.path


def trajectory(stamp=None):
    """The plan's cable trajectory as the node publishes it."""
    return cable_trajectory_msg(planned(), WINCHES, FRAME, stamp)


def with_effort(msg):
    """``msg`` with effort = the plan's nominal tensions (N) in every point, as a sender
    that puts the tensions in the trajectory would send it."""
    for pt, tension in zip(msg.points, planned().tension_nominal):
        pt.effort = tension.astype(float)
    return msg


def ends():
    msg = trajectory()
    return np.array(msg.points[0].positions), np.array(msg.points[-1].positions)


# ----------------------------------------------------------------------------- fjt_goal

def test_goal_has_the_trajectory_without_effort_and_starts_on_receipt():
    msg = with_effort(trajectory(stamp=Time(sec=1_700_000_000, nanosec=5)))
    assert all(len(p.effort) == 6 for p in msg.points)
    goal = X.fjt_goal(msg)
    t = goal.trajectory
    assert (t.header.stamp.sec, t.header.stamp.nanosec) == (0, 0)
    assert t.header.frame_id == FRAME and list(t.joint_names) == WINCHES
    assert len(t.points) == len(msg.points) == len(planned())
    for a, b in zip(t.points, msg.points):
        assert len(a.effort) == 0
        assert list(a.positions) == list(b.positions)
        assert list(a.velocities) == list(b.velocities)
        assert list(a.accelerations) == list(b.accelerations)
        assert (a.time_from_start.sec, a.time_from_start.nanosec) == (
            b.time_from_start.sec, b.time_from_start.nanosec)
    assert all(len(p.effort) == 6 for p in msg.points)          # the source is left alone
    assert to_seconds(goal.goal_time_tolerance) == X.GOAL_TIME_TOLERANCE_S
    assert not goal.path_tolerance and not goal.goal_tolerance  # the controller's own
    assert to_seconds(X.fjt_goal(msg, 0).goal_time_tolerance) == 0.0


@pytest.mark.parametrize("value", [-0.1, float("nan"), "1"])
def test_goal_time_tolerance_must_be_a_number_ge_zero(value):
    with pytest.raises(InputError) as err:
        X.fjt_goal(trajectory(), value)
    assert err.value.field == "goal_time_tolerance_s"


def test_goal_of_something_else_is_refused():
    with pytest.raises(InputError) as err:
        X.fjt_goal(JointState())
    assert err.value.field == "trajectory" and "JointTrajectory" in str(err.value)


# ----------------------------------------------------------------------------- measured lengths

def joint_state(names, positions):
    return JointState(name=list(names), position=[float(v) for v in positions])


def test_measured_lengths_follow_the_winch_order_and_ignore_other_joints():
    lengths = {w: 0.3 + 0.01 * i for i, w in enumerate(WINCHES)}
    names = ["gripper", *reversed(WINCHES), "camera_pan"]
    msg = joint_state(names, [9.0] + [lengths[n] for n in reversed(WINCHES)] + [-1.0])
    np.testing.assert_array_equal(X.measured_lengths(msg, WINCHES),
                                  [lengths[w] for w in WINCHES])


@pytest.mark.parametrize("case,field,words", [
    ("missing", "joint_states.name", "winch_4"),
    ("nan", "joint_states.position[winch_2]", "finite"),
    ("negative", "joint_states.position[winch_2]", "> 0"),
    ("short", "joint_states.position[winch_6]", "no position"),
    ("twice", "joint_states.name", "twice"),
])
def test_measured_lengths_name_the_winch_at_fault(case, field, words):
    names, values = list(WINCHES), [0.4] * 6
    if case == "missing":
        names[3] = "elbow"
    elif case == "nan":
        values[1] = float("nan")
    elif case == "negative":
        values[1] = -0.4
    elif case == "short":
        values = values[:5]
    elif case == "twice":
        names, values = names + ["winch_1"], values + [0.5]
    with pytest.raises(InputError) as err:
        X.measured_lengths(joint_state(names, values), WINCHES)
    assert err.value.field == field and words in str(err.value)


# ----------------------------------------------------------------------------- start check

def test_start_mismatch_names_the_largest_distance_its_winch_and_the_tolerance():
    first = np.full(6, 0.4)
    assert X.start_mismatch(first + 0.004, first, 0.005, WINCHES) is None
    measured = first + np.array([0.004, -0.003, 0.0, -0.0123, 0.006, 0.0])
    text = X.start_mismatch(measured, first, 0.005, WINCHES)
    assert "\n" not in text
    assert "winch_4" in text and "0.0123 m" in text and "tolerance 0.005 m" in text
    with pytest.raises(InputError):
        X.start_mismatch(first[:5], first, 0.005, WINCHES)


# ----------------------------------------------------------------------------- current pose

def _problem_poses():
    out = []
    for path in sorted(PROBLEMS.glob("robot*.yaml")):
        pr = load_problem(path)
        for which, pose in (("start", pr.start), ("goal", pr.goal)):
            out.append(pytest.param(pr.robot, pose.p, rotation_tt(pose.tau),
                                    id=f"{path.stem}-{which}"))
    return out


POSES = _problem_poses()


@pytest.mark.parametrize("robot,p,R", POSES)
def test_current_pose_from_a_nearby_guess_recovers_the_pose(robot, p, R):
    rng = np.random.default_rng(7)
    L = cable_lengths(robot, p, R)
    axis = rng.normal(size=3)
    guess = (p + rng.normal(size=3) / np.sqrt(3) * 0.01,               # ~1 cm
             rotation_vector_exp(axis / np.linalg.norm(axis) * 0.05) @ R)   # 0.05 rad
    q, Q = X.current_pose(robot, L, guess)
    assert np.max(np.abs(q - p)) < 1e-9 and rotation_angle_between(Q, R) < 1e-9


@pytest.mark.parametrize("robot,p,R", POSES)
def test_current_pose_without_a_guess_finds_the_problem_poses(robot, p, R):
    q, Q = X.current_pose(robot, cable_lengths(robot, p, R))
    assert np.max(np.abs(q - p)) < 1e-9 and rotation_angle_between(Q, R) < 1e-9


def test_current_pose_without_a_guess_picks_the_level_one_of_two_feasible_solutions():
    """Robot 2's free-flight goal has a feasible twin nearly upside down (same lengths):
    without a guess the less tilted one is returned, with a guess the one near it."""
    pr = load_problem(PROBLEMS / "robot2_q2_q3_free_flight.yaml")
    p, R = pr.goal.p, rotation_tt(pr.goal.tau)
    L = cable_lengths(pr.robot, p, R)
    twin = forward_kinematics(pr.robot, L, [-0.018, 0.0097, 0.188],
                              rotation_tt([-0.537, 3.059, -0.024]))
    assert twin.ok and wrench_feasibility(pr.robot, twin.p[None], R=twin.R[None]).feasible[0]
    assert rotation_angle_between(twin.R, R) > 2.0
    q, Q = X.current_pose(pr.robot, L)
    assert rotation_angle_between(Q, R) < 1e-9
    q, Q = X.current_pose(pr.robot, L, guess=(twin.p + 0.005, twin.R))
    assert rotation_angle_between(Q, twin.R) < 1e-9


def test_nearest_known_pose_chooses_newtons_start_between_twins():
    """Of the poses the node knows (``current_pose(..., known=)``), the one whose cable
    lengths are nearest the measured: from it Newton lands on that pose, not on its twin of
    the same lengths (both explain the lengths alike)."""
    pr = load_problem(PROBLEMS / "robot2_q2_q3_free_flight.yaml")
    p, R = pr.goal.p, rotation_tt(pr.goal.tau)
    L = cable_lengths(pr.robot, p, R)
    twin = forward_kinematics(pr.robot, L, [-0.018, 0.0097, 0.188],
                              rotation_tt([-0.537, 3.059, -0.024]))
    near_twin = (twin.p + 0.005, twin.R)
    near_goal = (p + 0.01, R)
    far = (pr.start.p, rotation_tt(pr.start.tau))
    assert nearest_waypoint(pr.robot, L, np.empty((0, 3)), np.empty((0, 3, 3))) is None
    for known, nearest, expected in (([far, near_goal], near_goal, R),
                                     ([near_twin, far], near_twin, twin.R)):
        q, Q = nearest_waypoint(pr.robot, L, *map(np.array, zip(*known)))
        assert np.array_equal(q, nearest[0]) and np.array_equal(Q, nearest[1])
        _, Q = X.current_pose(pr.robot, L, known=known)
        assert rotation_angle_between(Q, expected) < 1e-9


def test_current_pose_without_a_guess_may_return_a_feasible_twin():
    """Lengths alone do not decide: a feasible Robot 2 pose whose twin (same lengths, 9 cm
    higher, less tilted) is what the search finds; a guess near the pose gives it back."""
    p, R = np.array([0.02, -0.01, 0.30]), rotation_tt([0.3, 0.4, 0.1])
    L = cable_lengths(ROBOT2, p, R)
    assert wrench_feasibility(ROBOT2, p[None], R=R[None]).feasible[0]
    q, Q = X.current_pose(ROBOT2, L)
    np.testing.assert_allclose(cable_lengths(ROBOT2, q, Q), L, rtol=0, atol=1e-12)
    assert wrench_feasibility(ROBOT2, q[None], R=Q[None]).feasible[0]
    assert np.linalg.norm(q - p) > 0.08
    q, Q = X.current_pose(ROBOT2, L, guess=(p + 0.01, R))
    assert np.max(np.abs(q - p)) < 1e-9 and rotation_angle_between(Q, R) < 1e-9


def test_current_pose_searches_when_newton_fails_from_the_guess():
    pr = load_problem(PROBLEMS / "robot2_q2_q3.yaml")
    p, R = pr.goal.p, rotation_tt(pr.goal.tau)
    L = cable_lengths(pr.robot, p, R)
    singular = (np.zeros(3), np.eye(3))     # platform in the base plane: J singular
    assert not forward_kinematics(pr.robot, L, *singular).ok
    q, Q = X.current_pose(pr.robot, L, guess=singular)
    assert np.max(np.abs(q - p)) < 1e-9 and rotation_angle_between(Q, R) < 1e-9


@pytest.mark.parametrize("guess", [False, True])
def test_current_pose_of_unreachable_lengths_says_why(guess):
    # cables 1 and 2 share a platform anchor; their base anchors are 0.46 m apart
    L = np.array([0.1, 0.7, 0.4, 0.4, 0.4, 0.4])
    start = (np.array([0.0, 0.0, 0.306]), np.eye(3)) if guess else None
    with pytest.raises(InputError) as err:
        X.current_pose(ROBOT2, L, start)
    assert err.value.field == "joint_states" and "forward kinematics" in str(err.value)
    assert ("no pose near the last known one nor from" in str(err.value)) == guess
    with pytest.raises(InputError) as err:
        X.current_pose(ROBOT2, [0.4] * 5 + [float("nan")])
    assert err.value.field == "joint_states"


# ----------------------------------------------------------------------------- the double's checks

@functools.lru_cache(maxsize=None)
def double_module():
    from cdh_planner.ros.execution import simulated_controller
    return simulated_controller


def _raw(change=None):
    """A two-point trajectory on WINCHES that the controller accepts, then ``change``d."""
    msg = JointTrajectory(joint_names=list(WINCHES))
    msg.points = [JointTrajectoryPoint(positions=[0.4] * 6, velocities=[0.0] * 6,
                                       time_from_start=Duration(sec=0)),
                  JointTrajectoryPoint(positions=[0.41] * 6, velocities=[0.0] * 6,
                                       time_from_start=Duration(sec=1))]
    if change is not None:
        change(msg)
    return msg


def _set(attr, value, point=None):
    """A change of ``msg`` (or of its point ``point``): attribute ``attr`` = ``value``."""
    return lambda msg: setattr(msg if point is None else msg.points[point], attr, value)


END_VELOCITY = _set("velocities", [0.0] * 5 + [1e-3], point=-1)
EFFORT = _set("effort", [1.0] * 6, point=0)
# id, change, the double's options, the controller's log message (None: accepted)
JTC_RULES = [
    ("valid", None, {}, None),
    ("too-few-joints", _set("joint_names", WINCHES[:5]), {}, "don't match the controller"),
    ("no-joint-names", _set("joint_names", []), {}, "don't match the controller"),
    ("no-points", _set("points", []), {}, "Empty trajectory received."),
    ("unknown-joint", _set("joint_names", WINCHES[:5] + ["cable_6"]), {},
     "Incoming joint cable_6 doesn't match the controller's joints."),
    ("joint-twice", _set("joint_names", WINCHES[:5] + ["winch_1"]), {}, "more than once"),
    ("moving-at-the-end", END_VELOCITY, {},
     "Velocity of last trajectory point of joint winch_6 is not zero: 0.001000000000000"),
    ("moving-at-the-end-allowed", END_VELOCITY, {"nonzero_end_velocity": True}, None),
    ("end-velocity-below-float-eps", _set("velocities", [1e-9] * 6, point=-1), {}, None),
    ("stamp-ends-in-the-past", lambda m: setattr(m.header, "stamp", Time(sec=100)), {},
     "Received trajectory with non-zero start time (100.000000) that ends in the past"),
    ("stamp-in-the-future", lambda m: setattr(m.header, "stamp", Time(sec=10_000)), {}, None),
    ("time-not-increasing", _set("time_from_start", Duration(sec=0), point=1), {},
     "Time between points 0 and 1 is not strictly increasing"),
    ("positions-size", _set("positions", [0.4] * 5, point=1), {},
     "Mismatch between joint_names size (6) and positions (5) at point #1."),
    ("no-velocities", _set("velocities", [], point=0), {}, None),
    ("accelerations-size", _set("accelerations", [0.0] * 7, point=0), {},
     "Mismatch between joint_names size (6) and accelerations (7) at point #0."),
    ("effort", EFFORT, {}, "Trajectories with effort fields are only supported for "
                           "controllers using the 'effort' command interface."),
    ("effort-with-effort-interface", EFFORT, {"effort_interface": True}, None),
]


@pytest.mark.parametrize("change,options,reason",
                         [pytest.param(*case[1:], id=case[0]) for case in JTC_RULES])
def test_double_rejects_what_the_jazzy_controller_rejects(change, options, reason):
    got = double_module().rejection(_raw(change), WINCHES, now_s=1000.0, **options)
    assert (got is None) if reason is None else (reason in got), got


# ----------------------------------------------------------------------------- over DDS

class DoubleProcess(ControllerDouble):
    """The double in its own process on WINCHES, TIME_SCALE times real time, the joints at
    the plan's first point; its JSON events collected from stdout."""

    def __init__(self, domain, *args):
        first, _ = ends()
        super().__init__(domain, *WINCHES, "--kinematic", "--time-scale", TIME_SCALE,
                         "--initial", *map(repr, first.tolist()), *args)

    def event(self, kind, index, timeout_s=2.0):
        """The ``index``-th event of ``kind``, waiting for the reader thread to get it (a
        line printed before the double answers may be read after the answer arrives)."""
        assert until(lambda: len(self.events(kind)) > index, timeout_s), (kind, self.lines)
        return self.events(kind)[index]


class Side:
    """Our side: a node in its own rclpy context, spun by a MultiThreadedExecutor on a
    thread; a TrajectoryExecutor on ACTION and a JointStateMonitor on /joint_states."""

    def __init__(self, domain):
        import rclpy
        from cdh_planner.ros.actions import RaceFreeActionClient
        from rclpy.callback_groups import ReentrantCallbackGroup
        from rclpy.executors import MultiThreadedExecutor
        from control_msgs.action import FollowJointTrajectory
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node("execution_test", context=self.context)
        self.group = ReentrantCallbackGroup()
        self.executor = X.TrajectoryExecutor(self.node, ACTION, self.group)
        self.monitor = X.JointStateMonitor(self.node, "/joint_states", WINCHES)
        self.raw = RaceFreeActionClient(self.node, FollowJointTrajectory, ACTION,
                                        callback_group=self.group)
        self._retired = []
        self.spinner = MultiThreadedExecutor(num_threads=4, context=self.context)
        self.spinner.add_node(self.node)
        self.thread = threading.Thread(target=self.spinner.spin, daemon=True)
        self.thread.start()

    def retire(self, *entities):
        """Entities a test is done with (anything with ``destroy()``), destroyed by close()
        once nothing spins: destroying a subscription or publisher while the executor
        builds its wait set can end the executor's thread (rclpy 7.1: InvalidHandle in
        the event handler), and every later test in the module would hear nothing."""
        self._retired.extend(entities)

    def close(self):
        # rclpy 7.1's MultiThreadedExecutor.shutdown does not wait for callbacks in flight
        # and destroys its guard condition under them ("exception never retrieved"):
        # take the node out first and let them end
        self.spinner.remove_node(self.node)
        time.sleep(0.2)
        self.spinner.shutdown(timeout_sec=2.0)
        self.thread.join(5.0)
        for entity in self._retired:
            entity.destroy()
        self.node.destroy_node()
        self.context.try_shutdown()


class Done:
    """An on_done callback that keeps every call and its thread. There must be exactly one:
    ``wait`` checks there is one so far, and the ``ros`` fixture checks every Done made
    again once the executor has stopped (no callback can come after that), rather than
    sleeping a while after the first call and assuming a second one would have come."""

    made = []

    def __init__(self):
        self.calls, self.event = [], threading.Event()
        self.test = os.environ.get("PYTEST_CURRENT_TEST", "?")
        Done.made.append(self)

    def __call__(self, outcome, message):
        self.calls.append((outcome, message, threading.current_thread().name, time.monotonic()))
        self.event.set()

    def wait(self, timeout_s=10.0):
        assert self.event.wait(timeout_s), "on_done was not called"
        assert len(self.calls) == 1, self.calls
        return self.calls[0][:2]


@pytest.fixture(scope="module")
def ros():
    with claimed_domain() as domain:
        double = DoubleProcess(domain)
        side = None
        try:
            assert double.ready.wait(30.0), "the double did not start:\n" + "\n".join(double.lines)
            side = Side(domain)
            assert until(side.raw.server_is_ready, 20.0), "the action server was not discovered"
            assert until(lambda: side.monitor.latest is not None, 10.0), "no joint states"
            yield side, double
        finally:
            if side is not None:
                side.close()
            # the executor has stopped: every on_done call that will ever come has come
            twice = [(d.test, d.calls) for d in Done.made if len(d.calls) > 1]
            assert not twice, f"on_done called more than once: {twice}"
            rc, log = double.stop()
            assert rc == 0, f"double exit code {rc}:\n{log}"
            assert "Traceback" not in log, log


def next_positions(monitor, t):
    """(lengths, arrival) of a joint state that arrived after monotonic time ``t``."""
    assert until(lambda: monitor.latest[1] > t, 2.0), "no joint state after the event"
    msg, arrived = monitor.latest
    return X.measured_lengths(msg, monitor.winch_names), arrived


def latest_positions_after(monitor, t):
    """The first joint state lengths that arrived after monotonic time ``t``."""
    return next_positions(monitor, t)[0]


def test_planned_trajectory_runs_to_completion_and_ends_at_its_last_point(ros):
    side, double = ros
    first, last = ends()
    accepted = len(double.events("accepted"))
    succeeded = len(double.events("succeeded"))
    done = Done()
    side.executor.start(trajectory(), done)
    returned = time.monotonic()
    assert side.executor.busy
    outcome, message = done.wait()
    assert returned < done.calls[0][3]           # start() did not wait for the result
    # COMPLETED carries the double's own words, which it sends only at the trajectory's
    # end; the double says where that end was
    assert (outcome, message) == (X.COMPLETED, f"completed on {ACTION}: Goal successfully reached!")
    np.testing.assert_allclose(double.event("succeeded", succeeded)["positions"], last,
                               rtol=0, atol=1e-12)
    assert not side.executor.busy
    assert done.calls[0][2] != threading.current_thread().name   # from an executor thread
    event = double.event("accepted", accepted)
    assert event == {"event": "accepted", "joint_names": WINCHES, "points": len(planned()),
                     "has_effort": False, "duration_s": pytest.approx(planned().t[-1], abs=1e-9)}
    np.testing.assert_allclose(latest_positions_after(side.monitor, done.calls[0][3]), last,
                               rtol=0, atol=1e-6)


def test_trajectory_with_effort_is_rejected_by_the_controller_and_the_goal_is_not(ros):
    from control_msgs.action import FollowJointTrajectory
    side, double = ros
    raw = FollowJointTrajectory.Goal(trajectory=with_effort(trajectory()))
    rejected = len(double.events("rejected"))
    future = side.raw.send_goal_async(raw)
    assert until(future.done, 10.0)
    assert not future.result().accepted
    assert "effort fields are only supported" in double.event("rejected", rejected)["reason"]
    done = Done()
    side.executor.start(with_effort(trajectory()), done)
    assert done.wait()[0] == X.COMPLETED


@pytest.mark.parametrize("case,reason", [
    ("joint names", "Incoming joint cable_1 doesn't match the controller's joints."),
    ("times", "Time between points 1 and 2 is not strictly increasing"),
])
def test_a_goal_the_controller_rejects_fails_naming_the_rejection(ros, case, reason):
    side, double = ros
    msg = trajectory()
    if case == "joint names":
        msg.joint_names = [w.replace("winch", "cable") for w in WINCHES]
    else:
        msg.points[2].time_from_start = msg.points[1].time_from_start
    rejected = len(double.events("rejected"))
    done = Done()
    side.executor.start(msg, done)
    outcome, message = done.wait()
    assert outcome == X.FAILED and message.startswith(f"rejected by {ACTION}")
    assert reason in double.event("rejected", rejected)["reason"]
    assert not side.executor.busy


def slow_trajectory(factor=20):
    """The plan's trajectory ``factor`` times slower (~11 s at the double's time scale: it
    is canceled or preempted long before its end, even on a loaded machine)."""
    slow = trajectory()
    for pt in slow.points:
        ns = (pt.time_from_start.sec * 1_000_000_000 + pt.time_from_start.nanosec) * factor
        pt.time_from_start = Duration(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
    return slow


def go_to(side, lengths):
    """Move the joints to ``lengths`` (0.1 s) and wait until that has completed."""
    done = Done()
    side.executor.start(JointTrajectory(joint_names=WINCHES, points=[JointTrajectoryPoint(
        positions=list(map(float, lengths)), velocities=[0.0] * len(WINCHES),
        time_from_start=Duration(nanosec=100_000_000))]), done)
    assert done.wait(5.0)[0] == X.COMPLETED


def start_moving(side, double, done, msg):
    """Start ``msg`` (a motion from the plan's first point) with the joints at that first
    point, and return once the double has accepted it and the joints left that point: then
    it is this motion that moved them, whatever the tests before left."""
    first, _ = ends()
    go_to(side, first)
    accepted = len(double.events("accepted"))
    side.executor.start(msg, done)
    assert until(lambda: len(double.events("accepted")) > accepted
                 and not np.allclose(side.monitor.lengths(1.0)[0], first, atol=1e-4), 5.0)


def test_cancel_mid_way_stops_and_the_joints_hold(ros):
    side, double = ros
    first, last = ends()
    slow = slow_trajectory()
    assert side.executor.cancel() is False       # nothing running
    done = Done()
    start_moving(side, double, done, slow)
    second = Done()
    side.executor.start(slow, second)            # refused at once: one at a time
    assert second.wait(1.0) == (X.FAILED, f"refused: already executing a trajectory on {ACTION}")
    assert side.executor.cancel() is True
    assert done.wait(5.0) == (X.STOPPED, f"stopped on request: canceled by {ACTION}")
    # stopped mid-way (neither end of an ~11 s motion), then five more joint states (50 Hz
    # from the double) all at the same place
    held, t = next_positions(side.monitor, done.calls[0][3])
    for _ in range(5):
        later, t = next_positions(side.monitor, t)
        np.testing.assert_array_equal(later, held)
    assert not np.allclose(held, last, atol=1e-4) and not np.allclose(held, first, atol=1e-4)
    assert until(lambda: double.events()[-1] == {"event": "canceled"}, 2.0), double.lines


def test_a_goal_preempted_by_another_client_fails_with_the_controllers_error(ros):
    side, double = ros
    first, _ = ends()
    done = Done()
    start_moving(side, double, done, slow_trajectory())
    back = JointTrajectory(joint_names=WINCHES, points=[JointTrajectoryPoint(
        positions=first.tolist(), time_from_start=Duration(nanosec=100_000_000))])
    other = side.raw.send_goal_async(X.fjt_goal(back))
    outcome, message = done.wait(5.0)
    assert outcome == X.FAILED
    assert message == (f"aborted by {ACTION}: INVALID_GOAL (-1): Current goal preempted by "
                       f"new incoming action.")
    assert until(other.done, 5.0) and other.result().accepted
    result = other.result().get_result_async()
    assert until(result.done, 5.0) and result.result().result.error_code == 0


def test_no_server_fails_quickly_naming_the_action_and_cancel_before_sending_stops(ros):
    side, _ = ros
    nobody = X.TrajectoryExecutor(side.node, "/nobody/follow_joint_trajectory", side.group)
    done = Done()
    nobody.start(trajectory(), done)
    returned = time.monotonic()
    outcome, message = done.wait(5.0)            # 5 s: only a hang; the wait is 1 s
    assert returned < done.calls[0][3]           # start() did not wait for the server
    assert outcome == X.FAILED and "/nobody/follow_joint_trajectory" in message
    assert "within 1 s" in message               # it ended because the server wait did
    done = Done()
    nobody.start(trajectory(), done)
    assert nobody.cancel()
    assert done.wait(2.0) == (X.STOPPED, "stopped before the trajectory was sent")
    assert not nobody.busy
    side.retire(nobody)


def test_a_server_that_never_answers_fails_after_the_duration_and_a_margin(ros):
    """A controller that accepts and then goes silent (its process died): the execution
    fails at the trajectory's duration + goal time tolerance + margin, and the executor is
    free again."""
    from control_msgs.action import FollowJointTrajectory
    from rclpy.action import ActionServer, GoalResponse
    side, _ = ros
    release, entered = threading.Event(), threading.Event()

    def silent(handle):
        entered.set()
        release.wait(30.0)
        handle.abort()
        return FollowJointTrajectory.Result()

    server = ActionServer(side.node, FollowJointTrajectory, "/silent/follow_joint_trajectory",
                          execute_callback=silent, goal_callback=lambda g: GoalResponse.ACCEPT,
                          callback_group=side.group)
    silent_executor = X.TrajectoryExecutor(side.node, "/silent/follow_joint_trajectory",
                                           side.group, result_margin_s=0.2)
    try:
        done = Done()
        silent_executor.start(trajectory(), done)
        outcome, message = done.wait(planned().t[-1] + 10.0)
        # accepted and still running (its result held back) when the wait ran out, and the
        # wait was the duration + tolerance + margin
        assert entered.is_set() and not release.is_set()
        wait_s = planned().t[-1] + X.GOAL_TIME_TOLERANCE_S + 0.2
        assert outcome == X.FAILED and message.startswith(
            f"no result from /silent/follow_joint_trajectory within {wait_s:.1f} s of "
            f"acceptance"), message
        assert not silent_executor.busy
    finally:
        release.set()
        side.retire(silent_executor, server)


def test_joint_state_monitor_reports_lengths_or_why_not(ros):
    side, double = ros
    lengths, why = side.monitor.lengths(1.0)
    assert why == "" and lengths.shape == (6,) and np.all(lengths > 0)
    assert side.monitor.lengths(1e-9)[0] is None
    assert "s old (at most 1e-09 s)" in side.monitor.lengths(1e-9)[1]
    shuffled = WINCHES[::-1]
    other = X.JointStateMonitor(side.node, "/joint_states", shuffled)
    nothing = X.JointStateMonitor(side.node, "/nobody/joint_states", WINCHES)
    missing = X.JointStateMonitor(side.node, "/joint_states", WINCHES[:5] + ["winch_7"])
    assert until(lambda: other.latest is not None and missing.latest is not None, 5.0)
    mine, _ = side.monitor.lengths(1.0)
    theirs, _ = other.lengths(1.0)
    assert theirs is not None
    # the same message or the next one; the double holds still between goals
    np.testing.assert_allclose(theirs[::-1], mine, rtol=0, atol=1e-12)
    assert nothing.lengths(1.0) == (None, "nothing received on /nobody/joint_states "
                                          "(no publishers seen)")
    silent = side.node.create_publisher(X.JointState, "/nobody/joint_states", 10)
    assert until(lambda: side.node.count_publishers("/nobody/joint_states") == 1, 5.0)
    assert nothing.lengths(1.0) == (None, "nothing received on /nobody/joint_states "
                                          "(1 publisher seen)")
    side.retire(silent)
    lengths, why = missing.lengths(1.0)
    assert lengths is None and "winch_7" in why and "missing" in why
    side.retire(other, nothing, missing)


class Polls:
    """A ``cancelled`` callback for wait_lengths that counts its calls (wait_lengths polls it
    before each wait of at most CANCEL_POLL_S) and runs ``on_call(n)`` at the n-th: the
    test acts while the monitor is known to be waiting. True from call ``cancel_at`` on."""

    def __init__(self, on_call=lambda n: None, cancel_at=None):
        self.calls, self.on_call, self.cancel_at = 0, on_call, cancel_at

    def __call__(self):
        self.calls += 1
        self.on_call(self.calls)
        return self.cancel_at is not None and self.calls >= self.cancel_at


def age_in(why):
    """The age (s) in "the last joint state on T is AGE s old (at most M s)"."""
    return float(why.split(" is ")[1].split(" s old")[0])


def test_joint_state_monitor_waits_a_bounded_time_for_a_message(ros):
    """wait_lengths: at once when a recent message is there, or when the message names the
    winches wrongly; until the first message of a publisher that starts later; the whole
    wait (then why not) when none comes; and no longer once cancelled. Each shown by what
    was answered and by the polls of ``cancelled``, not by how long it took."""
    side, double = ros
    missing = X.JointStateMonitor(side.node, "/joint_states", WINCHES[:5] + ["winch_7"])
    assert until(lambda: missing.latest is not None, 5.0)
    polls = Polls()
    lengths, why = missing.wait_lengths(30.0, 60.0, cancelled=polls)
    assert lengths is None and "winch_7" in why and polls.calls == 0   # never waited

    late = X.JointStateMonitor(side.node, "/late/joint_states", WINCHES)
    publisher = side.node.create_publisher(X.JointState, "/late/joint_states", 10)
    msg = X.JointState(name=WINCHES, position=[0.3] * 6)
    assert until(lambda: publisher.get_subscription_count() == 1, 5.0)
    # nothing yet; the message is published at the second poll, after a wait that timed out
    assert late.latest is None
    polls = Polls(on_call=lambda n: n == 2 and publisher.publish(msg))
    lengths, why = late.wait_lengths(30.0, 60.0, cancelled=polls)
    assert why == "" and np.all(lengths == 0.3)
    # answered on the message: had the wait run out (60 s), it would be too old (30 s)
    assert polls.calls >= 2

    polls = Polls()                                   # a recent message: answered at once
    lengths, why = late.wait_lengths(30.0, 60.0, cancelled=polls)
    assert why == "" and np.all(lengths == 0.3) and polls.calls == 0

    # none recent enough (at most 0 s old) and none coming: the whole wait, then why not.
    # The age in the reason is at least the wait, as the message arrived before it began
    lengths, why = late.wait_lengths(0.0, 0.3)
    assert lengths is None and "s old (at most 0 s)" in why and age_in(why) >= 0.3, why

    polls = Polls(cancel_at=3)                        # cancelled at the third poll: no later
    lengths, why = late.wait_lengths(0.0, 60.0, cancelled=polls)
    assert lengths is None and "s old" in why and polls.calls == 3, (why, polls.calls)
    assert age_in(why) < 60.0                         # not the whole wait
    side.retire(publisher, missing, late)


def test_eight_cables_prefer_the_pose_that_explains_the_lengths():
    """With more than six cables a converged forward kinematics may be a least-squares
    local minimum: CoGiRo's lengths with 5 mm of noise are explained to 2.5 mm by the
    pose, and to 0.20 m by a point 2.3 rad tilted that a wrench check calls feasible.
    Feasibility and tilt choose only among solutions that explain the lengths alike
    (``likeliest_pose``): of the two it returns the pose even where a caller's hook says
    only the far point hangs (feasibility first, the order before, returned that point);
    so does the seed search."""
    robot = load_robot(CONFIG / "cogiro.yaml")
    p, R = np.array([0.3, -0.2, 2.4]), rotation_tt([0.2, 0.1, -0.1])
    L = cable_lengths(robot, p, R) + [0.00305, 0.00308, 0.00015, -0.00214, -0.00446,
                                      -0.00117, -0.00092, -0.00455]
    true = forward_kinematics(robot, L, p, R)
    far = forward_kinematics(robot, L, [1.423, 2.252, 2.809], rotation_tt([-1.062, 0.348, 1.897]))
    assert true.ok and far.ok and true.residual < 3e-3 and far.residual > 0.19
    assert rotation_angle_between(far.R, R) > 2.0
    assert wrench_feasibility(robot, far.p[None], R=far.R[None]).feasible[0]
    only_far = lambda q, Q: rotation_angle_between(Q, far.R) < 1e-3  # noqa: E731
    from cdh_planner.model.forward_kinematics import current_pose, likeliest_pose
    assert likeliest_pose([far, true], np.max(L), only_far) is true
    q, Q = current_pose(robot, L, feasible=only_far)
    assert np.linalg.norm(q - p) < 0.02 and rotation_angle_between(Q, R) < 0.02


def test_a_guess_whose_newton_turns_far_is_not_trusted():
    """From a guess far from the platform (a stale last pose) Newton may converge to a
    least-squares local minimum 2.3 rad away (CoGiRo, noisy lengths); a result turned more
    than GUESS_TURN_RAD from its guess goes to the seed search, which finds the pose. A
    guess near the pose is trusted as before."""
    from cdh_planner.model.forward_kinematics import GUESS_TURN_RAD, current_pose
    robot = load_robot(CONFIG / "cogiro.yaml")
    p, R = np.array([0.3, -0.2, 2.4]), rotation_tt([0.2, 0.1, -0.1])
    L = cable_lengths(robot, p, R) + [0.00305, 0.00308, 0.00015, -0.00214, -0.00446,
                                      -0.00117, -0.00092, -0.00455]
    stale = (np.array([1.423, 2.252, 2.809]), rotation_tt([-1.062, 0.348, 1.897]))
    far = forward_kinematics(robot, L, *stale)
    assert far.ok and rotation_angle_between(far.R, stale[1]) > GUESS_TURN_RAD
    assert rotation_angle_between(far.R, R) > 2.0
    q, Q = current_pose(robot, L, guess=stale)
    assert np.linalg.norm(q - p) < 0.02 and rotation_angle_between(Q, R) < 0.02
    near = forward_kinematics(robot, L, p + 0.01, R)
    q, Q = current_pose(robot, L, guess=(p + 0.01, R))
    assert np.array_equal(q, near.p) and np.array_equal(Q, near.R)


def test_a_wrong_last_pose_does_not_outvote_the_plans_ends():
    """robot2_8 (8 cables) at a pose with exact lengths; the node's last pose a least-squares
    local minimum of them (11 mm residual, turned > 0.5 rad; Newton from it stays there) and
    nearer in cable lengths than the plan's end it knows (3 cm off the pose). Newton runs
    from each known pose (``current_pose(..., known=)``) and the ends that explain the
    lengths worse are dropped: the pose, not the last one (choosing the start nearest in
    lengths first, as before, kept the wrong pose)."""
    robot = load_robot(CONFIG / "robot2_8.yaml")
    p, R = np.array([0.02, -0.01, 0.30]), rotation_tt([0.3, 0.2, 0.1])
    L = cable_lengths(robot, p, R)
    wrong = forward_kinematics(robot, L, [-0.1298, 0.0803, 0.3828],
                               rotation_tt([-0.1743, 1.0773, 1.3407]))
    assert wrong.ok and wrong.residual > 0.01 and rotation_angle_between(wrong.R, R) > 0.5
    stays = forward_kinematics(robot, L, wrong.p, wrong.R)
    assert rotation_angle_between(stays.R, wrong.R) < 1e-9
    end = (p + [0.03, 0.0, 0.0], R)
    assert np.array_equal(nearest_waypoint(robot, L, np.array([wrong.p, end[0]]),
                                           np.array([wrong.R, end[1]]))[0], wrong.p)
    q, Q = X.current_pose(robot, L, (wrong.p, wrong.R), known=[end])
    assert np.max(np.abs(q - p)) < 1e-9 and rotation_angle_between(Q, R) < 1e-9


def test_the_nearest_waypoint_is_the_nearest_in_lengths():
    """``nearest_waypoint`` (all poses at once) picks the pose whose cable lengths differ
    least (largest difference) from the measured, as one by one."""
    robot = load_robot(CONFIG / "robot2_8.yaml")
    rng = np.random.default_rng(9)
    p = np.array([0.0, 0.0, 0.3]) + rng.uniform(-0.05, 0.05, (40, 3))
    R = rotation_tt(rng.uniform(-0.3, 0.3, (40, 3)) + [0.0, 0.3, 0.0])
    for k in (0, 17, 39):
        L = cable_lengths(robot, p[k], R[k]) + 1e-4
        q, Q = nearest_waypoint(robot, L, p, R)
        assert np.array_equal(q, p[k]) and np.array_equal(Q, R[k])
        one_by_one = min(range(len(p)), key=lambda j: np.max(np.abs(cable_lengths(robot, p[j], R[j]) - L)))
        assert one_by_one == k
    assert nearest_waypoint(robot, L, p[:0], R[:0]) is None


def test_lengths_and_efforts_come_from_one_message(ros):
    """``measured``: the lengths and the efforts (measured tensions) of the same message,
    read once. The efforts were a shared attribute set by every read: the live state's read
    of a newer message could pair a plan's lengths with other tensions (the stretched
    lengths of neither; an 8-cable measured start then fitted a wrong least-squares pose)."""
    side, double = ros
    monitor = X.JointStateMonitor(side.node, "/paired/joint_states", WINCHES)
    publisher = side.node.create_publisher(X.JointState, "/paired/joint_states", 10)
    assert until(lambda: publisher.get_subscription_count() == 1, 5.0)
    for k in range(3):
        sent = X.JointState(name=WINCHES, position=[0.3 + k] * 6, effort=[1.0 + k] * 6)
        publisher.publish(sent)
        assert until(lambda: monitor.latest is not None and monitor.latest[0].position[0] == 0.3 + k, 5.0)
        lengths, tensions, why = monitor.measured(30.0)
        assert why == "" and np.all(lengths == 0.3 + k) and np.all(np.asarray(tensions) == 1.0 + k)
    side.retire(publisher, monitor)
