"""Time parameterisation of cable-space paths (trajectory/timing.py): the analytic trapezoid
and triangle on straight lines, winch limits on reported values and on finite differences,
rest at the ends and at duplicated waypoints, scaling laws, errors naming the field.

Tolerance. The bounds are exact in real arithmetic: the reported accelerations are the
second finite differences of the returned (t, lengths) and the reported velocities convex
combinations of the first differences (both checked below), and the timing accepts a value
within limit * (1 + 1e-9) (timing.REL_TOL). What floating point adds: t_k is a cumulative
sum, so a difference t_{k+1} - t_k recomputed from it is off by a few ulp of t_end
(< 1e-14 s here) on segments lasting >= 1e-3 s, i.e. a relative error < 1e-11 on a first
difference and, on second differences, < 1e-9 of the limit for the paths used here. So
limits are checked as |x| <= limit * (1 + 1e-9) + 1e-12 (m/s or m/s^2).

Against analytic profiles, times agree to 1e-9 relative: the waypoints themselves are
rounded to an ulp of the lengths (~6e-17 m at 0.5 m), which on the 1e-5 m segments of the
densest line below changes segment lengths and directions by ~1e-11 relative, and the
analytic reference computes s from the same rounded points.
"""

import dataclasses

import numpy as np
import pytest

from cdh_planner.errors import InputError
from cdh_planner.model.pose import rotation_tt
from cdh_planner.model.robot import load_robot
from cdh_planner.trajectory.path import PlannedPath
from cdh_planner.trajectory.timing import (DWELL_S, REL_TOL, limit_ratio, time_parameterize,
                                           time_path, trapezoid_durations)

from conftest import REPO
RTOL = REL_TOL
ATOL = 1e-12
VMAX = np.array([0.05, 0.04, 0.06, 0.05, 0.03, 0.05])   # m/s
AMAX = np.array([0.2, 0.25, 0.15, 0.2, 0.3, 0.2])       # m/s^2
L_A = np.array([0.30, 0.40, 0.50, 0.35, 0.45, 0.55])      # m
STEP = np.array([0.10, -0.05, 0.02, 0.0, 0.03, -0.08])    # m


# ----------------------------------------------------------------------------- helpers

def line(n, step=STEP, spacing=None):
    """n waypoints from L_A to L_A + step; ``spacing`` optional fractions in [0, 1]."""
    f = np.linspace(0.0, 1.0, n) if spacing is None else np.asarray(spacing)
    return L_A + f[:, None] * step


def line_profile(step, vmax, amax):
    """Analytic rest-to-rest profile of a straight line: length S (m), path limits W, A
    (of the binding winches), and the time law t(s) (s) of the trapezoid / triangle."""
    S = np.linalg.norm(step)
    u = np.abs(step) / S
    nz = u > 0
    W, A = np.min(vmax[nz] / u[nz]), np.min(amax[nz] / u[nz])
    peak = min(W, np.sqrt(S * A))  # triangle if the cruise speed is never reached
    s_acc = peak ** 2 / (2 * A)
    t_acc = peak / A
    T = 2 * t_acc + (S - 2 * s_acc) / peak

    def t_of_s(s):
        s = np.asarray(s, dtype=float)
        up = np.sqrt(2 * np.clip(s, 0, s_acc) / A)
        cruise = np.clip(s - s_acc, 0, S - 2 * s_acc) / peak
        down_s = np.clip(s - (S - s_acc), 0, s_acc)
        down = t_acc - np.sqrt(np.maximum(peak ** 2 - 2 * A * down_s, 0)) / A
        return up + cruise + down

    return S, W, A, T, t_of_s


def finite_differences(L, t):
    """First differences (N-1, 6) and second divided differences x 2 at interior waypoints."""
    h = np.diff(t)
    D = np.diff(L, axis=0) / h[:, None]
    second = 2 * (D[1:] - D[:-1]) / (h[:-1] + h[1:])[:, None]
    return D, second


def assert_within(x, limit):
    over = np.abs(x) - (limit * (1 + RTOL) + ATOL)
    assert np.all(over <= 0), f"limit exceeded by {over.max():.3g} at {np.unravel_index(over.argmax(), over.shape)}"


def assert_timing_valid(L, tm, vmax, amax):
    """Everything the timing promises, checked from positions and times."""
    t = tm.t
    assert t[0] == 0.0
    assert np.all(np.diff(t) > 0)
    assert tm.velocities.shape == tm.accelerations.shape == L.shape
    assert np.all(tm.velocities[[0, -1]] == 0)
    assert_within(tm.velocities, vmax)
    assert_within(tm.accelerations, amax)
    if len(t) >= 2:
        D, second = finite_differences(L, t)
        assert_within(D, vmax)
        assert_within(second, amax)


def robot_arc_lengths(n=300, radius=0.06, turns=0.75, twist=0.4):
    """Cable lengths of Robot 2's platform moving on a horizontal arc while turning and
    tilting: lengths |p + R b_i - a_i| (m), a curved path in cable space."""
    robot = load_robot(REPO / "config" / "robot2.yaml")
    s = np.linspace(0.0, 1.0, n)
    ang = 2 * np.pi * turns * s
    p = np.column_stack([radius * np.cos(ang), radius * np.sin(ang), 0.30 + 0.02 * s])
    tau = np.column_stack([ang, 0.1 + 0.1 * s, twist * s])
    R = rotation_tt(tau)
    ends = p[:, None, :] + np.einsum("nij,kj->nki", R, robot.platform_anchors)
    return np.linalg.norm(ends - robot.base_anchors[None], axis=2)


# ----------------------------------------------------------------------------- straight lines

@pytest.mark.parametrize("n", [2, 3, 10, 101, 1000])
def test_straight_line_trapezoid_matches_the_analytic_profile(n):
    S, W, A, T, t_of_s = line_profile(STEP, VMAX, AMAX)
    assert S > W ** 2 / A  # long enough to cruise
    L = line(n)
    tm = time_parameterize(L, VMAX, AMAX)
    assert tm.duration == pytest.approx(T, rel=1e-9)
    s = np.linalg.norm(L - L[0], axis=1)
    np.testing.assert_allclose(tm.t, t_of_s(s), rtol=1e-9, atol=1e-12)
    to_go = np.maximum(np.minimum(s, S - s), 0.0)
    np.testing.assert_allclose(tm.path_speed, np.minimum(W, np.sqrt(2 * A * to_go)),
                               rtol=1e-9, atol=1e-9)
    assert tm.repairs == 0
    assert_timing_valid(L, tm, VMAX, AMAX)


def test_straight_line_triangle_matches_the_analytic_profile():
    step = STEP * 0.02  # too short to reach the cruise speed
    S, W, A, T, t_of_s = line_profile(step, VMAX, AMAX)
    assert S < W ** 2 / A
    assert T == pytest.approx(2 * np.sqrt(S / A), rel=1e-14)
    for n in (2, 5, 201):
        L = line(n, step)
        tm = time_parameterize(L, VMAX, AMAX)
        assert tm.duration == pytest.approx(T, rel=1e-9)
        np.testing.assert_allclose(tm.t, t_of_s(np.linalg.norm(L - L[0], axis=1)), rtol=1e-9)
        assert_timing_valid(L, tm, VMAX, AMAX)
    # odd n: the middle waypoint is the peak, at speed sqrt(S A)
    assert tm.path_speed[100] == pytest.approx(np.sqrt(S * A), rel=1e-9)


def test_irregular_sampling_of_a_line_gives_the_same_time_law():
    rng = np.random.default_rng(3)
    spacing = np.concatenate([[0.0], np.sort(rng.uniform(0, 1, 60)), [1.0]])
    L = line(len(spacing), spacing=spacing)
    S, W, A, T, t_of_s = line_profile(STEP, VMAX, AMAX)
    tm = time_parameterize(L, VMAX, AMAX)
    np.testing.assert_allclose(tm.t, t_of_s(spacing * S), rtol=1e-9, atol=1e-12)
    assert_timing_valid(L, tm, VMAX, AMAX)


def test_reported_values_are_exact_inside_the_acceleration_phase():
    """Where three consecutive waypoints lie in the constant-acceleration phase the motion
    is a parabola in t: the reported velocity and acceleration are its exact ones."""
    S, W, A, T, t_of_s = line_profile(STEP, VMAX, AMAX)
    L = line(1001)
    tm = time_parameterize(L, VMAX, AMAX)
    u = STEP / S
    s = np.linalg.norm(L - L[0], axis=1)
    inner = np.flatnonzero((s > 0) & (s < W ** 2 / (2 * A) - 2 * S / 1000))
    assert inner.size > 10
    np.testing.assert_allclose(tm.velocities[inner], np.outer(A * tm.t[inner], u), rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(tm.accelerations[inner], np.broadcast_to(A * u, (inner.size, 6)),
                               rtol=1e-6, atol=1e-9)
    # and in the cruise phase: constant velocity W u, no acceleration
    cruise = np.flatnonzero((s > W ** 2 / (2 * A) + 2 * S / 1000) & (s < S - W ** 2 / (2 * A) - 2 * S / 1000))
    np.testing.assert_allclose(tm.velocities[cruise], np.broadcast_to(W * u, (cruise.size, 6)), rtol=1e-9)
    np.testing.assert_allclose(tm.accelerations[cruise], 0, atol=1e-8)


def test_the_binding_winch_sets_the_path_limits():
    """A line along one cable only: duration set by that winch's limits alone."""
    step = np.zeros(6)
    step[4] = -0.2
    S, W, A, T, _ = line_profile(step, VMAX, AMAX)
    assert W == VMAX[4] and A == AMAX[4]
    tm = time_parameterize(line(50, step), VMAX, AMAX)
    assert tm.duration == pytest.approx(S / VMAX[4] + VMAX[4] / AMAX[4], rel=1e-12)


def test_trapezoid_durations_closed_form():
    # from 0.01 to 0.02 m/s over 0.1 m, a = 0.1, cap 0.05: accelerate, cruise, decelerate
    h = trapezoid_durations(0.01 ** 2, 0.02 ** 2, 0.1, 0.1, 0.05)
    up, down = (0.05 - 0.01) / 0.1, (0.05 - 0.02) / 0.1
    d_up, d_down = (0.05 ** 2 - 0.01 ** 2) / 0.2, (0.05 ** 2 - 0.02 ** 2) / 0.2
    assert h == pytest.approx(up + down + (0.1 - d_up - d_down) / 0.05, rel=1e-14)
    # constant acceleration between the end speeds: time = 2 l / (v0 + v1)
    b0, a, ell = 0.01 ** 2, 0.1, 0.002
    b1 = b0 + 2 * a * ell
    assert trapezoid_durations(b0, b1, ell, a, 1.0) == pytest.approx(2 * ell / (0.01 + np.sqrt(b1)), rel=1e-12)
    # no acceleration allowed: cruise at the (equal) end speeds
    assert trapezoid_durations(0.03 ** 2, 0.03 ** 2, 0.06, 0.0, 0.05) == pytest.approx(2.0, rel=1e-14)


# ----------------------------------------------------------------------------- curved paths

def test_curved_robot_path_respects_limits_and_is_consistent():
    L = robot_arc_lengths()
    tm = time_parameterize(L, VMAX, AMAX)
    assert_timing_valid(L, tm, VMAX, AMAX)
    # reported values are what positions and times say (module docstring formulas)
    D, second = finite_differences(L, tm.t)
    h = np.diff(tm.t)
    np.testing.assert_allclose(tm.accelerations[1:-1], second, rtol=1e-12, atol=1e-15)
    w = (h[:-1] / (h[:-1] + h[1:]))[:, None]
    np.testing.assert_allclose(tm.velocities[1:-1], w * D[1:] + (1 - w) * D[:-1], rtol=1e-12, atol=1e-15)
    # ends: the parabola with zero slope through the neighbour
    np.testing.assert_allclose(tm.accelerations[0], 2 * (L[1] - L[0]) / h[0] ** 2, rtol=1e-12)
    np.testing.assert_allclose(tm.accelerations[-1], 2 * (L[-2] - L[-1]) / h[-1] ** 2, rtol=1e-12)


def test_dense_smooth_path_needs_no_repair_and_converges():
    """On a smooth path the vertex model already passes the discrete check (no corner speed
    lowered afterwards), and the duration converges as the sampling is refined."""
    durations = []
    for n in (100, 300, 1000):
        L = robot_arc_lengths(n)
        tm = time_parameterize(L, VMAX, AMAX)
        assert tm.repairs == 0
        assert_timing_valid(L, tm, VMAX, AMAX)
        durations.append(tm.duration)
    assert abs(durations[2] - durations[1]) < 2e-3 * durations[2]
    assert abs(durations[2] - durations[1]) < abs(durations[1] - durations[0])


def test_time_optimality_signs():
    """Time-optimal: never slower than the speed limit allows on every segment, and no
    slack everywhere (running the same timing faster by 0.1 % breaks a limit)."""
    L = robot_arc_lengths()
    tm = time_parameterize(L, VMAX, AMAX)
    ell = np.linalg.norm(np.diff(L, axis=0), axis=1)
    u = np.diff(L, axis=0) / ell[:, None]
    lower_bound = np.sum(ell / np.min(VMAX / np.abs(u), axis=1))
    assert tm.duration > lower_bound
    ratio = limit_ratio(tm.velocities, tm.accelerations, VMAX, AMAX)
    assert ratio.max() > 1 - 1e-6
    faster = limit_ratio(tm.velocities / 0.999, tm.accelerations / 0.999 ** 2, VMAX, AMAX)
    assert faster.max() > 1 + 1e-4


def test_scaling_limits_scales_time():
    """Speeds x k and accelerations x k^2 give the same motion k times faster."""
    L = robot_arc_lengths(200)
    tm = time_parameterize(L, VMAX, AMAX)
    k = 3.0
    fast = time_parameterize(L, k * VMAX, k * k * AMAX, dwell_s=DWELL_S / k)
    np.testing.assert_allclose(fast.t, tm.t / k, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(fast.velocities, k * tm.velocities, rtol=1e-8, atol=1e-13)
    np.testing.assert_allclose(fast.accelerations, k * k * tm.accelerations, rtol=1e-7, atol=1e-12)


def test_right_angle_corner_is_taken_at_the_curvature_speed():
    """A 90 degree corner between dense straight runs (two cables): the corner speed is
    sqrt(a l) (turn term |c| b = a with |c| = 1/l), reached at constant speed, so the
    reported acceleration there is exactly (u_out - u_in) a."""
    ell, amax, vmax = 1e-3, 0.2, 0.05
    run = np.arange(0, 101) * ell
    P = np.concatenate([np.column_stack([run, 0 * run]), np.column_stack([0 * run[1:] + 0.1, run[1:]])])
    L = 0.4 + np.column_stack([P, np.zeros((len(P), 4))])
    tm = time_parameterize(L, vmax, amax)
    assert_timing_valid(L, tm, np.full(6, vmax), np.full(6, amax))
    corner = 100
    assert tm.path_speed[corner] == pytest.approx(np.sqrt(amax * ell), rel=1e-12)
    np.testing.assert_allclose(tm.accelerations[corner], [-amax, amax, 0, 0, 0, 0], rtol=1e-9, atol=1e-12)
    assert tm.path_speed.max() == pytest.approx(vmax, rel=1e-12)


def test_random_paths_always_within_limits():
    """Random walks with large turns, uneven steps and duplicated points: the discrete check
    (and its repairs) keeps every reported value and finite difference within limits."""
    rng = np.random.default_rng(7)
    repaired = 0
    for trial in range(150):
        n = int(rng.integers(2, 40))
        steps = rng.normal(size=(n - 1, 6)) * rng.choice([1e-3, 1e-2, 0.1]) * rng.random((n - 1, 1)) ** 2
        if trial % 3 == 0:
            steps[rng.integers(0, n - 1)] = 0.0
        L = 0.4 + np.concatenate([np.zeros((1, 6)), np.cumsum(steps, axis=0)])
        vmax, amax = rng.uniform(0.01, 0.1, 6), rng.uniform(0.05, 0.5, 6)
        tm = time_parameterize(L, vmax, amax)
        assert_timing_valid(L, tm, vmax, amax)
        repaired += tm.repairs > 0
    assert repaired > 10  # the repair path is exercised


# ----------------------------------------------------------------------------- rest points, small N

def test_duplicate_waypoint_is_a_stop_and_splits_the_timing():
    """Two motions joined at a duplicated waypoint: the platform stops there for dwell_s,
    and the total time is the sum of the two motions' times plus the dwell."""
    first = robot_arc_lengths(120)
    second = first[-1] + np.linspace(0, 1, 80)[:, None] * STEP * 0.3
    joined = np.concatenate([first, second])  # second[0] == first[-1]: a zero-length segment
    tm = time_parameterize(joined, VMAX, AMAX, dwell_s=0.01)
    a, b = time_parameterize(first, VMAX, AMAX), time_parameterize(second, VMAX, AMAX)
    k = len(first) - 1
    assert tm.t[k + 1] - tm.t[k] == pytest.approx(0.01, rel=1e-12)
    assert tm.duration == pytest.approx(a.duration + 0.01 + b.duration, rel=1e-12)
    assert np.all(tm.velocities[[k, k + 1]] == 0) and tm.rest[k] and tm.rest[k + 1]
    np.testing.assert_allclose(tm.t[:k + 1], a.t, rtol=1e-12, atol=1e-15)
    assert_timing_valid(joined, tm, VMAX, AMAX)


def test_single_waypoint_and_repeated_points():
    one = time_parameterize(L_A[None], VMAX, AMAX)
    assert one.t.tolist() == [0.0]
    assert np.all(one.velocities == 0) and np.all(one.accelerations == 0)
    same = time_parameterize(np.repeat(L_A[None], 4, axis=0), VMAX, AMAX, dwell_s=0.02)
    np.testing.assert_allclose(same.t, [0, 0.02, 0.04, 0.06], rtol=1e-15)
    assert np.all(same.velocities == 0) and np.all(same.accelerations == 0)


def test_two_waypoints_start_and_end_at_rest():
    L = line(2)
    tm = time_parameterize(L, VMAX, AMAX)
    assert np.all(tm.velocities == 0)
    assert tm.path_speed.tolist() == [0.0, 0.0]
    assert_timing_valid(L, tm, VMAX, AMAX)


# ----------------------------------------------------------------------------- PlannedPath

def _planned(L):
    n = len(L)
    zeros3, zeros6 = np.zeros((n, 3)), np.zeros((n, 6))
    quat = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    return PlannedPath(p=zeros3 + [0, 0, 0.3], quaternion=quat, tau=zeros3, lengths=L.copy(),
                       tension_min=zeros6 + 1, tension_nominal=zeros6 + 2, tension_max=zeros6 + 3,
                       margin=np.ones(n), t=np.zeros(n), velocities=zeros6, accelerations=zeros6)


def test_time_path_fills_timing_and_leaves_the_rest_unchanged():
    L = robot_arc_lengths(100)
    path = _planned(L)
    timed = time_path(path, 0.05, 0.2)
    tm = time_parameterize(L, 0.05, 0.2)
    assert timed is not path
    np.testing.assert_array_equal(timed.lengths, L)
    np.testing.assert_array_equal(timed.t, tm.t)
    np.testing.assert_array_equal(timed.velocities, tm.velocities)
    np.testing.assert_array_equal(timed.accelerations, tm.accelerations)
    for f in dataclasses.fields(PlannedPath):
        if f.name not in ("t", "velocities", "accelerations"):
            assert getattr(timed, f.name) is getattr(path, f.name)
    assert np.all(path.t == 0)  # the input is not modified


# ----------------------------------------------------------------------------- errors

@pytest.mark.parametrize("speed, accel, field", [
    (0.0, 0.2, "max_cable_speed"),
    (-0.05, 0.2, "max_cable_speed"),
    (float("nan"), 0.2, "max_cable_speed"),
    (float("inf"), 0.2, "max_cable_speed"),
    (0.05, 0.0, "max_cable_accel"),
    (0.05, float("nan"), "max_cable_accel"),
    ([0.05, 0.05, 0.05, 0.0, 0.05, 0.05], 0.2, "max_cable_speed[3]"),
    (0.05, [0.2, 0.2, float("nan"), 0.2, 0.2, 0.2], "max_cable_accel[2]"),
    ([0.05, 0.05], 0.2, "max_cable_speed"),
    ("fast", 0.2, "max_cable_speed"),
])
def test_bad_limits_name_the_field(speed, accel, field):
    with pytest.raises(InputError) as err:
        time_parameterize(line(5), speed, accel)
    assert err.value.field == field
    assert field in str(err.value)


def test_bad_lengths_name_the_entry():
    L = line(5)
    L[2, 4] = np.nan
    with pytest.raises(InputError) as err:
        time_parameterize(L, 0.05, 0.2)
    assert err.value.field == "lengths[2][4]"
    with pytest.raises(InputError) as err:
        time_parameterize(np.zeros((4, 5)), 0.05, 0.2)
    assert err.value.field == "lengths"
    with pytest.raises(InputError) as err:
        time_parameterize(np.zeros((0, 6)), 0.05, 0.2)
    assert err.value.field == "lengths"
    with pytest.raises(InputError) as err:
        time_parameterize(line(3), 0.05, 0.2, dwell_s=0.0)
    assert err.value.field == "dwell_s"
