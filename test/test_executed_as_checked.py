"""Executed as checked (trajectory/executed.py): the JointTrajectory the node
publishes, executed here as a ros2_control JointTrajectoryController does (one quintic per
segment through positions, velocities and accelerations, solved here from its six end
conditions), driven through forward kinematics (Newton, its steps between samples shown to
be small), differentiated at 1 ms and its tensions recomputed with the inertial wrench and the
wrench ellipsoid, keeps every tension, length and winch limit: at fast winches (1 m/s,
20 m/s^2) and at the defaults (0.05 m/s, 0.2 m/s^2). The checker catches the sparse TOPP-RA
points that broke this, agrees with the dynamic timing on the motion it checked, and a plan
it cannot make executable within its bounds is refused with a reason."""

from dataclasses import replace

import numpy as np
import pytest

from conftest import PROBLEMS
from cdh_planner.commands.plan import result_dict
from cdh_planner.wrench import wrench_feasibility, screw_jacobian
from cdh_planner.parsing.problem import load_problem
from cdh_planner.model.forward_kinematics import forward_kinematics_many
from cdh_planner.model.kinematics import cable_lengths
from cdh_planner.planner import Planner
from cdh_planner.status import Status
from cdh_planner.trajectory import dynamics as D
from cdh_planner.trajectory import executed as E
from cdh_planner.trajectory.timing import time_path

INERTIA = np.diag([2e-3, 2e-3, 3.5e-3])  # kg m^2: the dynamic-timing study's load on Robot 2 (0.6 kg)
DT = 1e-3                                # s
FAST, DEFAULT = (1.0, 20.0), (0.05, 0.2)  # winch limits (m/s, m/s^2)


@pytest.fixture(scope="module")
def problem():
    """Robot 2 with rigid cables (no cable_stiffness): the published positions are the
    geometric lengths, which this module's rigid checker follows (elastic cables:
    test_elastic_execution.py)."""
    pr = load_problem(PROBLEMS / "robot2_q2_q3.yaml")
    return replace(pr, robot=replace(pr.robot, inertia=INERTIA, cable_stiffness=None))


@pytest.fixture(scope="module")
def route(problem):
    """One search: q2 -> q3 planned quasi-statically (at the fast limits)."""
    s = replace(problem.settings, dynamics="quasi_static", max_cable_speed=FAST[0],
                max_cable_accel=FAST[1])
    result = Planner(problem.robot, problem.task, s).plan(problem.start, problem.goal)
    assert result.success, result.message
    return result


@pytest.fixture(scope="module")
def outputs(problem, route):
    """limits -> the planner's output stage on that route (Planner.plan's last steps: the
    quasi-static timing, the dynamic timing, made executable): (path, note, check)."""
    return {limits: D.timed_path(problem.robot, time_path(route.path, *limits), "auto", *limits)
            for limits in (FAST, DEFAULT)}


# ----------------------------------------------------------------------------- an independent JTC

def jtc_quintic(t_wp, L, V, A, t):
    """Positions (M, J) of the JTC's quintic at times t, its coefficients solved per segment
    from p, p', p'' at both ends (a 6 x 6 system in the segment's own time)."""
    out = np.empty((len(t), L.shape[1]))
    k_of = np.clip(np.searchsorted(t_wp, t, side="right") - 1, 0, len(t_wp) - 2)
    for k in np.unique(k_of):
        h = t_wp[k + 1] - t_wp[k]
        M = np.array([[1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0], [0, 0, 2, 0, 0, 0],
                      [1, h, h ** 2, h ** 3, h ** 4, h ** 5],
                      [0, 1, 2 * h, 3 * h ** 2, 4 * h ** 3, 5 * h ** 4],
                      [0, 0, 2, 6 * h, 12 * h ** 2, 20 * h ** 3]])
        coef = np.linalg.solve(M, np.stack([L[k], V[k], A[k], L[k + 1], V[k + 1], A[k + 1]]))
        tau = t[k_of == k] - t_wp[k]
        out[k_of == k] = np.vander(tau, 6, increasing=True) @ coef
    return out


def executed_margins(robot, msg, p0, R0):
    """Execute the JointTrajectory ``msg`` as a JTC (every DT), forward kinematics of its
    lengths (from the poses p0 (N, 3), R0 (N, 3, 3) of its points), differences at DT: per
    interior sample the tension
    margin (N, ellipsoid around the dynamic wrench), lengths (m), winch speed and
    acceleration (m/s, m/s^2, differences of the lengths)."""
    t_wp = np.array([p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in msg.points])
    L, V, A = (np.array([getattr(pt, f) for pt in msg.points]) for f in
               ("positions", "velocities", "accelerations"))
    t = np.arange(0.0, t_wp[-1], DT)
    lengths = jtc_quintic(t_wp, L, V, A, t)
    # Newton from the nearest published point's pose: converged to rounding, and every step
    # between samples small, so each is the pose reached from the previous one
    k = np.clip(np.searchsorted(t_wp, t), 0, len(t_wp) - 1)
    fk = forward_kinematics_many(robot, lengths, p0[k], R0[k])
    assert np.all(fk.ok) and np.max(fk.residual) < 1e-12
    p, R = fk.p, fk.R
    assert np.max(np.linalg.norm(np.diff(p, axis=0), axis=1)) < 1e-3      # m per DT
    assert np.max(np.abs(np.diff(R, axis=0))) < 1e-2
    c = p + np.einsum("nij,j->ni", R, robot.load_point)
    acc = (c[2:] - 2 * c[1:-1] + c[:-2]) / DT ** 2
    Rt = np.swapaxes(R[1:-1], 1, 2)
    W = (R[2:] - R[:-2]) / (2 * DT) @ Rt                      # [w]x = R' R^T, base frame
    w = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
    Acc = (R[2:] - 2 * R[1:-1] + R[:-2]) / DT ** 2 @ Rt - W @ W  # R'' R^T = [alpha]x + [w]x^2
    alpha = 0.5 * np.stack([Acc[:, 2, 1] - Acc[:, 1, 2], Acc[:, 0, 2] - Acc[:, 2, 0],
                            Acc[:, 1, 0] - Acc[:, 0, 1]], axis=1)
    Rm = R[1:-1]
    I_w = Rm @ robot.inertia @ np.swapaxes(Rm, 1, 2)
    moment = (np.cross(c[1:-1], robot.mass * acc) + np.einsum("nij,nj->ni", I_w, alpha)
              + np.cross(w, np.einsum("nij,nj->ni", I_w, w)))
    f = wrench_feasibility(robot, p[1:-1], R=Rm)
    J = screw_jacobian(robot, f.unit_vectors)
    w_in = np.concatenate([robot.mass * acc, moment], axis=1)
    tension = f.tension_nominal - np.linalg.solve(J, w_in[..., None])[..., 0]
    margin = np.minimum(tension - f.tension_spread - robot.tension_min,
                        robot.tension_max - tension - f.tension_spread)
    speed = np.abs(lengths[2:] - lengths[:-2]) / (2 * DT)
    accel = np.abs(lengths[2:] - 2 * lengths[1:-1] + lengths[:-2]) / DT ** 2
    return margin, f.lengths, speed, accel


def published(path, robot):
    """The JointTrajectory the node publishes (FollowJointTrajectory goal and
    ~/planned_cable_trajectory) for ``path``."""
    M = pytest.importorskip("cdh_planner.ros.msgs.messages")
    return M.cable_trajectory_msg(path, robot.winch_names, "cdh_base")


# ----------------------------------------------------------------------------- the quintic

def test_quintic_matches_its_ends_and_its_derivatives():
    rng = np.random.default_rng(7)
    t_wp = np.cumsum(rng.uniform(0.05, 0.4, 6)) - 0.05
    L, V, A = rng.normal(size=(6, 3)), rng.normal(size=(6, 3)), rng.normal(size=(6, 3))
    pos, vel, acc = E.quintic(t_wp, L, V, A, t_wp)   # at the points: the points
    assert np.allclose(pos, L, atol=1e-12) and np.allclose(vel, V, atol=1e-10)
    assert np.allclose(acc, A, atol=1e-9)
    end = t_wp[1:] - 1e-13                            # the left limit at each point too
    pos, vel, acc = E.quintic(t_wp, L, V, A, end)
    assert np.allclose(pos, L[1:], atol=1e-9) and np.allclose(vel, V[1:], atol=1e-8)
    assert np.allclose(acc, A[1:], atol=1e-6)
    t = np.linspace(t_wp[0] + 0.01, t_wp[-1] - 0.01, 200)
    h = 1e-6
    p_plus, v_plus, _ = E.quintic(t_wp, L, V, A, t + h)
    p_minus, v_minus, _ = E.quintic(t_wp, L, V, A, t - h)
    pos, vel, acc = E.quintic(t_wp, L, V, A, t)
    assert np.allclose((p_plus - p_minus) / (2 * h), vel, atol=1e-6)
    assert np.allclose((v_plus - v_minus) / (2 * h), acc, atol=1e-5)
    assert np.allclose(pos, jtc_quintic(t_wp, L, V, A, t), atol=1e-12)
    held, v_held, _ = E.quintic(t_wp, L, V, A, np.array([t_wp[-1] + 1.0]))
    assert np.allclose(held, L[-1]) and np.all(v_held == 0)
    around = np.concatenate([[t_wp[0] - 1.0], t, [t_wp[-1] + 1.0]])  # the positions alone:
    only, none, _ = E.quintic(t_wp, L, V, A, around, rates=False)   # the same bits
    assert none is None and np.array_equal(only, E.quintic(t_wp, L, V, A, around)[0])


def test_many_poses_forward_kinematics_agrees_with_one_at_a_time(problem):
    robot = problem.robot
    rng = np.random.default_rng(3)
    p = np.array([0.0, 0.0, 0.3]) + rng.uniform(-0.03, 0.03, (20, 3))
    R = np.array([E.Rotation.from_rotvec(w).as_matrix() for w in rng.uniform(-0.2, 0.2, (20, 3))])
    L = np.array([cable_lengths(robot, a, b) for a, b in zip(p, R)])
    p_seed = p + rng.uniform(-2e-3, 2e-3, p.shape)
    fk = forward_kinematics_many(robot, L, p_seed, R)
    assert np.all(fk.ok) and np.max(fk.residual) < 1e-12
    assert np.allclose(fk.p, p, atol=1e-9) and np.allclose(fk.R, R, atol=1e-9)


# ----------------------------------------------------------------------------- what leaves

def poses(path):
    return path.p, E.Rotation.from_quat(path.quaternion).as_matrix()


@pytest.mark.parametrize("limits", [FAST, DEFAULT], ids=["fast-1mps-20mps2", "default"])
def test_the_published_trajectory_executes_within_every_limit(problem, outputs, limits):
    robot, (path, note, check) = problem.robot, outputs[limits]
    assert check.ok and note.startswith("dynamic timing")
    margin, lengths, speed, accel = executed_margins(robot, published(path, robot), *poses(path))
    assert np.min(margin) > 0, f"{np.min(margin):.4g} N"
    assert np.all(lengths > robot.length_min) and np.all(lengths < robot.length_max)
    assert np.max(speed) <= limits[0] * (1 + 1e-6)
    assert np.max(accel) <= limits[1] * (1 + 1e-3)  # second differences of a quintic: O(DT^2)
    # points added; at the defaults also slowed a little (the winch limits near TOPP-RA's
    # acceleration switches, module docstring of trajectory.executed)
    assert check.added > 0 and check.slowdown < 1.2


def test_the_checker_catches_the_sparse_points_and_agrees_with_this_test(problem, route):
    robot = problem.robot
    timing = D.dynamic_timing(robot, time_path(route.path, *FAST), robot.mass, robot.inertia, *FAST)
    assert timing.feasible and timing.least_tension_margin_n > 0  # the spline motion: inside
    check = E.check_path(robot, timing.path, robot.mass, robot.inertia, *FAST)
    assert not check.ok and check.least_margin < -0.01 and "tension margin" in check.reason
    assert check.bad_segments.size > 0
    margin, *_ = executed_margins(robot, published(timing.path, robot), *poses(timing.path))
    assert np.min(margin) < -0.1                                 # N: this test sees it too
    # the checker samples 4 times as often, each with its own 1 ms stencil: never more lenient
    assert check.least_tension_margin_n <= np.min(margin) + 1e-3
    # the checked motion itself, sampled densely, checks as the dynamic timing says
    t = np.linspace(0.0, timing.duration, 10001)
    rows = D.motion_rows(robot, timing, t, robot.mass, robot.inertia)
    dense = E.check_path(robot, rows, robot.mass, robot.inertia, *FAST)
    assert dense.ok
    assert abs(dense.least_tension_margin_n - timing.least_tension_margin_n) < 2e-4


def test_slowing_down_scales_the_winch_ratios_exactly(problem, outputs):
    robot, (path, _, _) = problem.robot, outputs[FAST]
    before = E.check_path(robot, path, None, None, *FAST)
    slow = E.slow_down(robot, path, 2.0)
    after = E.check_path(robot, slow, None, None, *FAST)
    assert after.speed_ratio == pytest.approx(before.speed_ratio / 2, rel=1e-3)
    assert after.accel_ratio == pytest.approx(before.accel_ratio / 4, rel=1e-2)
    f0 = wrench_feasibility(robot, path.p, R=poses(path)[1]).tension_nominal
    assert np.allclose(slow.tension_nominal - f0, (path.tension_nominal - f0) / 4)


def test_beyond_its_bounds_the_plan_is_refused_with_a_reason(problem, monkeypatch):
    monkeypatch.setattr(E, "MAX_ROUNDS", 0)
    monkeypatch.setattr(E, "SLOWDOWNS", 0)
    s = replace(problem.settings, max_cable_speed=FAST[0], max_cable_accel=FAST[1])
    result = Planner(problem.robot, problem.task, s).plan(problem.start, problem.goal)
    assert not result.success and result.reason == Status.NOT_EXECUTABLE
    assert "JointTrajectoryController" in result.message and "tension margin" in result.message
    assert result.path is None


def test_a_cancel_or_the_time_limit_stops_the_executed_check_between_its_rounds(
        problem, monkeypatch):
    """The executed check is part of the call's time: a cancel that comes while it runs (or
    the deadline passing) ends it after the round in progress, as CANCELED (TIMEOUT) with
    the check's reason, and no path; at the fast limits its first check fails (points are
    added), so there is a second round to skip."""
    class CancelOnceChecking:
        checking = False

        def is_set(self):
            return self.checking

    cancel = CancelOnceChecking()
    check_path = E.check_path

    def checking(*args, **kwargs):
        cancel.checking = True
        return check_path(*args, **kwargs)
    monkeypatch.setattr(E, "check_path", checking)
    s = replace(problem.settings, max_cable_speed=FAST[0], max_cable_accel=FAST[1])
    result = Planner(problem.robot, problem.task, s).plan(problem.start, problem.goal,
                                                          cancel=cancel)
    assert not result.success and result.reason == Status.CANCELED, result.message
    assert "executed check was stopped by a cancel" in result.message
    assert "after 0 rounds of added points" in result.message and result.path is None


def test_the_stop_reports_the_deadline_without_an_atlas():
    from cdh_planner.search.strategies import Stop
    assert Stop(deadline=0.0).expired() == Status.TIMEOUT
    assert Stop(deadline=None).expired() is None


# ----------------------------------------------------------------------------- JSON and stream

def test_the_plan_and_its_json_carry_what_was_checked(problem):
    s = replace(problem.settings, max_cable_speed=FAST[0], max_cable_accel=FAST[1])
    result = Planner(problem.robot, problem.task, s).plan(problem.start, problem.goal)
    assert result.success and "points added" in result.stats["executed"]
    path = result.path
    assert E.check_path(problem.robot, path, problem.robot.mass, problem.robot.inertia, *FAST).ok
    doc = result_dict(result)
    keys = {"p", "quaternion", "tau", "lengths", "tension_min", "tension_nominal",
            "tension_max", "margin", "t", "commanded_lengths", "velocities", "accelerations"}
    assert all(set(w) == keys for w in doc["path"])
    # rigid cables: the commanded lengths are the geometric ones
    assert all(w["commanded_lengths"] == w["lengths"] for w in doc["path"])
    assert np.array_equal([w["velocities"] for w in doc["path"]], path.velocities)
    assert np.array_equal([w["accelerations"] for w in doc["path"]], path.accelerations)
    assert doc["executed"] == result.stats["executed"]


def test_the_stream_sends_the_checked_quintic(problem, outputs):
    streaming = pytest.importorskip("cdh_planner.ros.core.streaming")
    robot, (path, _, _) = problem.robot, outputs[FAST]
    stream = streaming.Stream(path, robot.winch_names, start=0.0)
    stamp = published(path, robot).header.stamp
    t = np.linspace(0.0, path.t[-1], 97)
    pos, vel, _ = E.quintic(path.t, path.lengths, path.velocities, path.accelerations, t)
    for j, now in enumerate(t[:-1]):
        msg, finished = stream.command(now, stamp)
        assert not finished
        assert np.allclose(msg.position, pos[j], atol=1e-12)
        assert np.allclose(msg.velocity, vel[j], atol=1e-12)


def test_quintic_bounds_are_the_extremes_of_the_quintic():
    rng = np.random.default_rng(11)
    t_wp = np.concatenate([[0.0], np.cumsum(rng.uniform(1e-3, 0.3, 30))])
    L, V, A = (rng.normal(size=(31, 6)) * x for x in (0.1, 0.5, 5.0))
    V[3] = A[3] = 0.0                      # a segment of lower degree
    lo, hi, vel, acc = E.quintic_bounds(t_wp, L, V, A)
    for k in range(30):
        t = np.linspace(t_wp[k], t_wp[k + 1], 20001)
        p, v, a = E.quintic(t_wp, L, V, A, t)
        assert np.all(lo[k] <= p.min(axis=0) + 1e-12) and np.all(hi[k] >= p.max(axis=0) - 1e-12)
        assert np.allclose(lo[k], p.min(axis=0), rtol=1e-6, atol=1e-9)
        assert np.allclose(hi[k], p.max(axis=0), rtol=1e-6, atol=1e-9)
        assert np.allclose(vel[k], np.abs(v).max(axis=0), rtol=1e-6)
        assert np.allclose(acc[k], np.abs(a).max(axis=0), rtol=1e-6)


def test_the_bernstein_hull_holds_the_quintic_and_the_limits_give_the_same_verdict():
    """The hull of a segment's Bernstein coefficients holds its positions (sampled), and
    with limits the bounds say within / not within exactly where the exact extremes do
    (limits through the middle of the positions' range, at its edges and beyond)."""
    rng = np.random.default_rng(12)
    t_wp = np.concatenate([[0.0], np.cumsum(rng.uniform(1e-3, 0.3, 30))])
    L, V, A = (rng.normal(size=(31, 6)) * x for x in (0.1, 0.5, 5.0))
    k = np.arange(30)
    b = np.stack(E._coefficients(t_wp, L, V, A, k), axis=-1)
    hull = b @ E.BERNSTEIN_5.T
    s = np.linspace(0.0, 1.0, 2001)
    p = np.polynomial.polynomial.polyval(s, np.moveaxis(b, -1, 0))  # (30, 6, 2001)
    assert np.all(hull.min(-1)[..., None] <= p + 1e-12) and np.all(p <= hull.max(-1)[..., None] + 1e-12)
    lo, hi, vel, acc = E.quintic_bounds(t_wp, L, V, A)
    for low, high in ((lo.min(0) - 1e-3, hi.max(0) + 1e-3), (lo.min(0), hi.max(0)),
                      (np.median(lo, 0), np.median(hi, 0)), (lo.max(0) + 1, hi.min(0) - 1)):
        got = E.quintic_bounds(t_wp, L, V, A, limits=(low, high))
        assert np.array_equal((got[0] >= low) & (got[1] <= high), (lo >= low) & (hi <= high))
        assert np.array_equal(got[2], vel) and np.array_equal(got[3], acc)


def test_a_quasi_static_timing_is_handed_out_as_its_spline_and_slowed_to_the_limits(problem, route):
    robot = replace(problem.robot, mass=None, inertia=None)   # no load mass: quasi-static
    timed = time_path(route.path, *DEFAULT)
    path, note, check = D.timed_path(robot, timed, "auto", *DEFAULT)
    assert note == "" and check.ok and check.added == 0 and 1 < check.slowdown < 1.2
    assert np.allclose(path.t, timed.t * check.slowdown) and np.array_equal(path.lengths, timed.lengths)
    # the JTC's quintic through these points is the clamped cubic spline through them
    from scipy.interpolate import CubicSpline
    spline = CubicSpline(path.t, path.lengths, bc_type="clamped")
    t = np.linspace(0.0, path.t[-1], 5001)
    pos, vel, acc = E.quintic(path.t, path.lengths, path.velocities, path.accelerations, t)
    assert np.allclose(pos, spline(t), atol=1e-12) and np.allclose(acc, spline(t, 2), atol=1e-9)
    assert np.max(np.abs(vel)) <= DEFAULT[0] * (1 + 1e-6)
    assert np.max(np.abs(acc)) <= DEFAULT[1] * (1 + 1e-6)


def test_current_pose_prefers_what_the_feasibility_hook_accepts():
    """model.forward_kinematics.current_pose (no ROS, no wrenches): of Robot 2's free-flight
    goal and its nearly upside-down twin (same lengths), the hook decides which one a search
    without a guess returns; both have the measured lengths."""
    from cdh_planner.model.forward_kinematics import current_pose, nearest_waypoint
    from cdh_planner.model.kinematics import forward_kinematics as fk1
    from cdh_planner.model.pose import rotation_angle_between, rotation_tt
    pr = load_problem(PROBLEMS / "robot2_q2_q3_free_flight.yaml")
    p, R = pr.goal.p, rotation_tt(pr.goal.tau)
    L = cable_lengths(pr.robot, p, R)
    twin = fk1(pr.robot, L, [-0.018, 0.0097, 0.188], rotation_tt([-0.537, 3.059, -0.024]))
    assert twin.ok and rotation_angle_between(twin.R, R) > 2.0
    _, Q = current_pose(pr.robot, L)                      # no hook: the least tilted
    assert rotation_angle_between(Q, R) < 1e-9
    q, Q = current_pose(pr.robot, L, feasible=lambda p_, R_: rotation_angle_between(R_, twin.R) < 1e-6)
    assert rotation_angle_between(Q, twin.R) < 1e-9
    np.testing.assert_allclose(cable_lengths(pr.robot, q, Q), L, rtol=0, atol=1e-12)
    q, _ = nearest_waypoint(pr.robot, L, np.array([twin.p, p + 0.01]), np.array([twin.R, R]))
    assert np.array_equal(q, twin.p)


def test_unique_sorted_is_np_unique():
    from cdh_planner.trajectory.executed import unique_sorted
    rng = np.random.default_rng(4)
    for a in (rng.integers(0, 20, 50), rng.normal(size=30).round(1), np.zeros(0), np.array([3.0])):
        np.testing.assert_array_equal(unique_sorted(a), np.unique(a))


def test_the_whole_check_after_added_points_reuses_the_unchanged_samples_exactly(problem, route):
    """``executable``'s last whole check takes the previous whole check's margins outside
    the intervals where points were added: the same answer, number for number, as checking
    everything again."""
    robot = problem.robot
    timing = D.dynamic_timing(robot, time_path(route.path, *FAST), robot.mass, robot.inertia, *FAST)
    first = E.check_path(robot, timing.path, robot.mass, robot.inertia, *FAST)
    assert not first.ok and first.per_sample is not None
    k = first.bad_segments
    path = timing.path
    t = 0.5 * (path.t[k] + path.t[k + 1])
    windows = np.column_stack([path.t[k] - E.CHECK_DT, path.t[k + 1] + E.CHECK_DT])
    added = E._merged(path, D.motion_rows(robot, timing, t, robot.mass, robot.inertia), k + 1)
    whole = E.check_path(robot, added, robot.mass, robot.inertia, *FAST)
    reused = E.check_path(robot, added, robot.mass, robot.inertia, *FAST, reuse=(first, windows))
    changed = E._reusable((first, windows), None, np.arange(len(first.per_sample[1])) +
                          min(E.PHASES, 4), np.linspace(path.t[0], path.t[-1], whole.samples))
    assert 0 < changed[0].sum() < changed[0].size / 2                  # most samples reused
    for name in ("ok", "reason", "least_tension_margin_n", "least_margin", "worst_t",
                 "speed_ratio", "accel_ratio", "samples"):
        assert getattr(reused, name) == getattr(whole, name), name
    assert np.array_equal(reused.bad_segments, whole.bad_segments)
    assert np.array_equal(reused.per_sample[0], whole.per_sample[0])
    assert np.array_equal(reused.per_sample[1], whole.per_sample[1])


def test_the_executed_poses_keep_the_scenes_clearance():
    """With a scene, the executed motion (forward kinematics of the quintic) is checked
    against it too: the ball plan's trajectory passes as planned, and the same trajectory
    fails, naming the clearance, once a bead sits on a cable at a pose it executes."""
    from cdh_planner.model.pose import rotation_from_quaternion
    from cdh_planner.scene.collision import CollisionModel
    from cdh_planner.scene.schema import scene_from_dict
    pr = load_problem(PROBLEMS / "robot2_q2_q3_ball.yaml")
    result = Planner(pr.robot, pr.task, pr.settings, scene=pr.scene).plan(pr.start, pr.goal)
    assert result.success
    path, robot = result.path, pr.robot
    clear = E.check_path(robot, path, robot.mass, robot.inertia, collision=CollisionModel(robot, pr.scene))
    assert clear.ok, clear.reason
    k = len(path) // 2
    anchor = path.p[k] + rotation_from_quaternion(path.quaternion[k]) @ robot.platform_anchors[0]
    bead = scene_from_dict({"obstacles": [{"id": "bead", "type": "sphere", "radius": 0.002,
                                           "position": (0.5 * (robot.base_anchors[0] + anchor)).tolist()}]})
    hit = E.check_path(robot, path, robot.mass, robot.inertia, collision=CollisionModel(robot, bead))
    assert not hit.ok and "clearance" in hit.reason and hit.bad_segments.size
    assert E.check_path(robot, path, robot.mass, robot.inertia).ok   # the tensions alone pass


# ----------------------------------------------------------------------------- futile rounds

def _stub_check(path0, fails):
    """check_path stand-in: the segments of the path that ``fails(path, scale)`` marks
    (bool per segment; scale = the path's slow-down from path0) fail with a tension margin
    of -1 N, the rest pass."""
    def check(robot, path, *args, **kwargs):
        bad = np.flatnonzero(fails(path, path.t[-1] / path0.t[-1]))
        return E.ExecutionCheck(ok=bad.size == 0, reason="tension margin -1 N" if bad.size else "",
                                least_tension_margin_n=-1.0 if bad.size else 1.0,
                                least_margin=0.0, worst_t=0.0, speed_ratio=0.5, accel_ratio=0.5,
                                bad_segments=bad, samples=len(path))
    return check


def _window(path, lo=0.3, hi=0.4):
    """Segments overlapping the fraction [lo, hi] of the path's duration."""
    T = path.t[-1]
    return (path.t[1:] > lo * T) & (path.t[:-1] < hi * T)


def _motion(path0, calls):
    """motion(t, scale): rows of path0 at the waypoints before times t (a stand-in: the
    stubbed check reads only their times); appends t to ``calls`` (one per round)."""
    def motion(t, scale):
        calls.append(t)
        k = np.clip(np.searchsorted(path0.t * scale, t, side="right") - 1, 0, len(path0) - 1)
        fields = {name: getattr(path0, name)[k] for name in ("p", "quaternion", "tau", "lengths",
                  "tension_min", "tension_nominal", "tension_max", "margin", "velocities",
                  "accelerations")}
        return type(path0)(**fields, t=np.asarray(t, dtype=float))
    return motion


def test_points_stop_being_added_where_the_motion_itself_fails(problem, outputs, monkeypatch):
    """A failure that points do not shrink (the same stretch of time fails however dense:
    the motion's own, until it is slowed 1.5 x) is given two rounds of points before each
    slow-down (two: 1.25^2), each doubling the window's segments: not MAX_ROUNDS of them
    (2^12 times the segments)."""
    path0 = outputs[FAST][0]
    monkeypatch.setattr(E, "check_path", _stub_check(path0, lambda p, s: _window(p) & (s < 1.5)))
    rounds = []
    path, check = E.executable(problem.robot, path0, _motion(path0, rounds), None, None, *FAST)
    assert check.ok and check.slowdown == pytest.approx(E.TENSION_SLOWDOWN ** 2, rel=1e-5)
    assert len(rounds) == 2 + 2 and len(path) - len(path0) == sum(map(len, rounds))


def test_points_are_added_while_they_shrink_the_failure(problem, outputs, monkeypatch):
    """A failure of long segments (the quintic between sparse points) shrinks with every
    round: points are added until it passes, and nothing is slowed."""
    path0 = outputs[FAST][0]
    h = 0.3 * float(np.max(np.diff(path0.t)[_window(path0)]))  # two rounds for the longest
    monkeypatch.setattr(E, "check_path",
                        _stub_check(path0, lambda p, s: _window(p) & (np.diff(p.t) > h)))
    rounds = []
    path, check = E.executable(problem.robot, path0, _motion(path0, rounds), None, None, *FAST)
    assert check.ok and check.slowdown == 1.0 and len(rounds) >= 2
