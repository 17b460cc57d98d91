"""The commands of elastic cables where the centred tension rule turns fast (CoGiRo, eight
cables): the stretch L t0 / EA a length controller is sent (``PlannedPath.commanded``)
follows the rule's nominal t0, which near a change of its binding slack moves hundreds of
newtons over millimetres of platform motion. A timing that bounded only the geometric
lengths' rates left the stretch's to ``executable``, which slowed the whole trajectory many
times over or refused it (``not_executable``; a CoGiRo query of benchmarks/eight_cables.py:
slowed 50 times, a 787 s trajectory of 1.5 million checked samples). The commands now
average the tensions along the path too (``COMMAND_PATH_WINDOW_M``) and the dynamic timing
bounds the commanded lengths' rates (``dynamics._command_rates``, checked here by finite
differences). The centred nominal also left the elastic platform a soft (then unstable) tilt
there; the stiff nominal (``wrench.stiff_nominal``) keeps it stiff, and the motion executes
(test_platform_stiffness.py has the mathematics)."""

from dataclasses import replace

import numpy as np
import pytest

from conftest import CONFIG
from cdh_planner.model.robot import load_robot
from cdh_planner.ports import Rotation, Slerp
from cdh_planner.model.kinematics import cable_lengths
from cdh_planner.trajectory import dynamics as D
from cdh_planner.trajectory.dynamics import timed_path
from cdh_planner.trajectory.executed import _merged, check_path, slow_down
from cdh_planner.trajectory.path import (COMMAND_ACCEL_SHARE, COMMAND_PATH_WINDOW_M,
                                         COMMAND_WINDOW_S, PlannedPath, command_tensions,
                                         command_window, with_commands)
from cdh_planner.trajectory.timing import time_path
from cdh_planner.wrench import band_feasibility, rule_tensions

# 8 cm of a planned CoGiRo path (benchmarks/eight_cables.py, query 1): the centred nominal
# changes its binding slack in its middle
START = (np.array([1.047984, -1.939296, 4.927995]),
         np.array([0.233006, 0.752711, -0.022944, 0.615311]))
GOAL = (np.array([1.115362, -1.982235, 4.924133]),
        np.array([0.232084, 0.751918, -0.024812, 0.616555]))
LIMITS = (1.0, 2.0)  # m/s, m/s^2: the benchmark's winches


@pytest.fixture(scope="module")
def robot():
    return load_robot(CONFIG / "cogiro.yaml")


def straight(robot, n):
    """The PlannedPath of n waypoints from START to GOAL (position linear, orientation
    slerp), quasi-statically timed at LIMITS."""
    s = np.linspace(0.0, 1.0, n)
    p = (1 - s)[:, None] * START[0] + s[:, None] * GOAL[0]
    rot = Slerp([0.0, 1.0], Rotation.from_quat([START[1], GOAL[1]]))(s)
    f = band_feasibility(robot, p, R=rot.as_matrix())
    assert np.all(f.feasible)
    zeros = np.zeros(f.lengths.shape)
    path = PlannedPath(p=p, quaternion=rot.as_quat(), tau=np.zeros((n, 3)), lengths=f.lengths,
                       tension_min=f.tension_min, tension_nominal=f.tension_nominal,
                       tension_max=f.tension_max, margin=f.margin, t=np.zeros(n),
                       velocities=zeros, accelerations=zeros)
    return time_path(path, *LIMITS)


def test_the_stretch_of_the_nominal_outruns_the_geometry(robot):
    """Along these 8 cm the stretch L t0 / (EA + t0) of some cable changes more than
    five times as much as any geometric length (45 mm against 5 mm), in one 5 mm step (a
    fact of the rule, which the stiff nominal at CoGiRo's least_stiffness of 250 N/m keeps
    (at 893 N/m: 256 N and 12 mm a step); measured here so that a fix can be judged
    against it)."""
    path = straight(robot, 17)                                   # 5 mm steps
    t0 = rule_tensions(robot, path.p, Rotation.from_quat(path.quaternion).as_matrix())[0]
    stretch = path.lengths * t0 / (robot.cable_stiffness + t0)
    d_stretch = np.abs(np.diff(stretch, axis=0))
    d_length = np.abs(np.diff(path.lengths, axis=0))
    assert np.max(np.abs(np.diff(t0, axis=0))) > 500.0           # N in one step
    assert np.max(d_stretch) > 5 * np.max(d_length)


def _commanded_lengths(robot, geo, s):
    """L0 (M, m) at path parameters s (M,) as the commands define them: the geometric
    lengths under the static tensions averaged along the path, written out directly."""
    p, _, _, R, _, _ = geo.at(s)
    L = np.array([cable_lengths(robot, a, b) for a, b in zip(p, R)])
    arc = np.interp(s, geo.s_wp, geo.arc)
    f = command_tensions(geo.arc, geo.f0_wp, COMMAND_PATH_WINDOW_M, at=arc)[0]
    return L * robot.cable_stiffness / (robot.cable_stiffness + f)


def test_the_timings_command_rates_by_finite_differences(robot):
    """dynamics._command_rates is d L0 / ds and d^2 L0 / ds^2 of the commanded lengths
    (between waypoints, where the arc is smooth in s); at the waypoints L0 is what
    ``PlannedPath.commanded`` sends for the path slowed 100 times (its time average then
    spans 2 % of a segment: 0.25 mm of its 45 mm of stretch change allowed)."""
    path = straight(robot, 17)
    geo = D._Geometry(robot, path)
    rng = np.random.default_rng(1)
    k = rng.integers(0, len(geo.s_wp) - 1, 12)
    s = geo.s_wp[k] + rng.uniform(0.2, 0.8, 12) * np.diff(geo.s_wp)[k]
    L, L_s, L_ss, *_ = D._terms(robot, geo, s, robot.mass, robot.inertia)
    C_s, C_ss = D._command_rates(robot, geo, s, L, L_s, L_ss)
    h = 1e-5
    up, mid, down = (_commanded_lengths(robot, geo, s + d) for d in (h, 0.0, -h))
    np.testing.assert_allclose((up - down) / (2 * h), C_s, rtol=1e-5,
                               atol=1e-6 * np.abs(C_s).max())
    np.testing.assert_allclose((up - 2 * mid + down) / h ** 2, C_ss, rtol=1e-3,
                               atol=1e-3 * np.abs(C_ss).max())
    assert np.abs(C_s - L_s).max() > np.abs(L_s).max()      # the stretch dominates here
    sent = with_commands(robot, replace(path, t=path.t * 100)).commanded()[0]
    np.testing.assert_allclose(_commanded_lengths(robot, geo, geo.s_wp), sent, rtol=0, atol=2.5e-4)


def test_the_dynamic_timing_keeps_the_commanded_winch_rates(robot):
    """The dynamic timing's own points, executed: the winch speeds within their limit, the
    accelerations within the quintic's overshoot of it (the geometric-rate timing: 2.1 x
    and 20 x the limits; with the centred nominal 0.44 x and 1.46 x, with the stiff one
    0.31 x and 1.79 x: its turn ends in a bend that the quintic overshoots more)."""
    timing = D.dynamic_timing(robot, straight(robot, 17), robot.mass, robot.inertia, *LIMITS)
    assert timing.feasible, timing.reason
    check = check_path(robot, timing.path, robot.mass, robot.inertia, *LIMITS)
    assert check.speed_ratio <= 1.0 and check.accel_ratio < 1.8, (check.speed_ratio,
                                                                 check.accel_ratio)


def test_the_timed_motion_executes_without_slowing_it_down_many_times(robot):
    """The dynamic timing's motion through the turn, made executable, is at most twice as
    slow as the timing: what the planner timed is what executes."""
    path, note, check = timed_path(robot, straight(robot, 17), "auto", *LIMITS)
    assert "dynamic timing" in note, note
    assert check.ok and check.slowdown <= 2.0, (check.reason, check.slowdown)


# ----------------------------------------------------------------------------- the window

@pytest.mark.parametrize("jump", [5.0, 100.0, 400.0])
def test_the_command_window_keeps_a_jumps_stretch_within_its_share_of_the_limit(jump):
    """A jump J of the dynamic tensions (where the timing's acceleration switches), tent-
    averaged over the window w: its second rate is J / w^2 at most (reached), so its
    stretch's L J / (EA w^2) is within COMMAND_ACCEL_SHARE of the winch acceleration limit,
    and at the window command_window gives, equal to it (or below it at the least
    window)."""
    t = np.linspace(0.0, 2.0, 2001)
    L = np.full((len(t), 2), [10.0, 6.0])                           # m
    dynamic = np.where(t[:, None] < 1.0, 0.0, [jump, 0.5 * jump])   # N: a step at 1 s
    EA, amax = np.array([2e5, 1e5]), 2.0
    w = command_window(L, dynamic, EA, amax)
    ddf = command_tensions(t, dynamic, w)[2]
    stretch = np.max(np.abs(L * ddf / EA))                          # m/s^2
    assert stretch <= COMMAND_ACCEL_SHARE * amax * (1 + 1e-6)
    bound = np.max(L[0] * np.abs(dynamic[-1]) / EA) / w ** 2        # L J / (EA w^2)
    assert stretch == pytest.approx(bound, rel=2e-3)
    if w > COMMAND_WINDOW_S:
        assert stretch == pytest.approx(COMMAND_ACCEL_SHARE * amax, rel=2e-3)


def test_the_command_window_is_the_least_one_for_rigid_cables_and_small_jumps():
    L = np.ones((3, 8))
    assert command_window(L, np.zeros((3, 8)), None, 2.0) == COMMAND_WINDOW_S
    assert command_window(L, np.zeros((3, 8)), np.full(8, 1e3), 2.0) == COMMAND_WINDOW_S
    assert command_window(L[:1], np.zeros((1, 8)), np.full(8, 1e3), 2.0) == COMMAND_WINDOW_S


def test_the_timed_path_carries_its_command_window_into_its_commands(robot):
    """The dynamic timing sets the window from its own tension jumps; the commands (and
    a slowed or merged path's) use it."""
    timing = D.dynamic_timing(robot, straight(robot, 17), robot.mass, robot.inertia, *LIMITS)
    path = with_commands(robot, timing.path)
    assert path.command_window_s >= COMMAND_WINDOW_S
    for a, b in zip(path.commanded(), path.commanded(window_s=path.command_window_s)):
        np.testing.assert_array_equal(a, b)
    slowed = slow_down(robot, path, 1.5)
    merged = _merged(path, path, np.arange(len(path)))
    assert slowed.command_window_s == merged.command_window_s == path.command_window_s
