"""Dynamic timing (trajectory/dynamics.py): the timed motion, differentiated here
independently (finite differences at 1 ms), keeps every tension in range for every wrench
of the ellipsoid around the dynamic wrench, and the winch limits; 0.9 x its time breaks
something; a path with no feasible speed is answered as such."""

from dataclasses import replace

import numpy as np
import pytest

from conftest import PROBLEMS
from cdh_planner.wrench import wrench_feasibility, screw_jacobian
from cdh_planner.parsing.problem import load_problem
from cdh_planner.planner import Planner
from cdh_planner.trajectory.dynamics import dynamic_timing

MASS = 0.6                                   # kg: Robot 2's platform (its force is 0.6 g)
INERTIA = np.diag([0.0012, 0.0012, 0.0024])  # kg m^2: a 0.6 kg disc of radius 0.09 m
DT = 1e-3                                    # s


@pytest.fixture(scope="module")
def q2_q3():
    problem = load_problem(PROBLEMS / "robot2_q2_q3.yaml")
    result = Planner(problem.robot, problem.task, problem.settings).plan(problem.start, problem.goal)
    assert result.success
    timing = dynamic_timing(problem.robot, result.path, MASS, INERTIA,
                            problem.settings.max_cable_speed, problem.settings.max_cable_accel)
    return problem, result.path, timing


def _motion(timing, scale=1.0):
    """Positions, rotations and times of the timed motion run ``scale`` x as long, every DT."""
    t = np.arange(0.0, timing.duration * scale, DT)
    p, R = timing.pose_at(t / scale)
    return t, p, R


def _dynamic_check(robot, t, p, R):
    """Per sample (interior): tension margin (N) with the ellipsoid around the dynamic
    wrench, winch speed and acceleration (m/s, m/s^2), from finite differences."""
    c = p + np.einsum("nij,j->ni", R, robot.load_point)
    acc = (c[2:] - 2 * c[1:-1] + c[:-2]) / DT ** 2
    Rdot = (R[2:] - R[:-2]) / (2 * DT)
    W = Rdot @ np.swapaxes(R[1:-1], 1, 2)                       # [w]x, base frame
    w = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
    w_all = np.concatenate([w[:1], w, w[-1:]])
    alpha = (w_all[2:] - w_all[:-2]) / (2 * DT)
    Rm = R[1:-1]
    I_w = Rm @ INERTIA @ np.swapaxes(Rm, 1, 2)
    Iw = np.einsum("nij,nj->ni", I_w, w)
    moment = np.cross(c[1:-1], MASS * acc) + np.einsum("nij,nj->ni", I_w, alpha) + np.cross(w, Iw)
    w_in = np.concatenate([MASS * acc, moment], axis=1)
    f = wrench_feasibility(robot, p[1:-1], R=Rm)
    J = screw_jacobian(robot, f.unit_vectors)
    tension = f.tension_nominal - np.linalg.solve(J, w_in[..., None])[..., 0]
    margin = np.minimum(tension - f.tension_spread - robot.tension_min,
                        robot.tension_max - tension - f.tension_spread)
    L = np.linalg.norm(p[:, None, :] + np.einsum("nij,kj->nki", R, robot.platform_anchors)
                       - robot.base_anchors, axis=-1)
    speed = np.abs(L[2:] - L[:-2]) / (2 * DT)
    accel = np.abs(L[2:] - 2 * L[1:-1] + L[:-2]) / DT ** 2
    return margin, speed, accel, f.lengths


def test_dynamic_timing_keeps_tensions_and_winch_limits(q2_q3):
    problem, path, timing = q2_q3
    robot, s = problem.robot, problem.settings
    assert timing.feasible, timing.reason
    assert timing.slowdown <= 1.1
    t, p, R = _motion(timing)
    margin, speed, accel, lengths = _dynamic_check(robot, t, p, R)
    assert np.min(margin) > -2e-3          # N: finite differences of a bang-bang profile
    assert np.max(speed) <= s.max_cable_speed * 1.001
    assert np.max(accel) <= s.max_cable_accel * 1.02
    assert np.all(lengths > robot.length_min) and np.all(lengths < robot.length_max)
    # the waypoints of the returned path are samples of that motion
    p_wp, _ = timing.pose_at(timing.path.t)
    assert np.allclose(p_wp, path.p, atol=1e-9)
    assert np.all(np.diff(timing.path.t) > 0)
    env = timing.path
    assert np.all(env.tension_min >= robot.tension_min - 1e-6)
    assert np.all(env.tension_max <= robot.tension_max + 1e-6)


def test_faster_than_the_dynamic_timing_breaks_a_limit(q2_q3):
    problem, _, timing = q2_q3
    s = problem.settings
    t, p, R = _motion(timing, scale=0.9)
    margin, speed, accel, _ = _dynamic_check(problem.robot, t, p, R)
    assert (np.min(margin) < 0 or np.max(speed) > s.max_cable_speed * 1.01
            or np.max(accel) > s.max_cable_accel * 1.01)


def test_a_heavier_load_is_slower_and_still_safe(q2_q3):
    problem, path, light = q2_q3
    heavy = dynamic_timing(problem.robot, path, 30 * MASS, 30 * INERTIA,
                           problem.settings.max_cable_speed, problem.settings.max_cable_accel)
    assert heavy.feasible and heavy.duration > light.duration
    assert heavy.least_tension_margin_n >= 0


def test_no_feasible_speed_is_answered_not_raised(q2_q3):
    problem, path, _ = q2_q3
    # every waypoint over the limit: accelerating can unload a cable for a moment, not all the way
    limit = float(np.min(np.max(path.tension_max, axis=1))) - 0.01
    tight = replace(problem.robot, tension_max=np.full(6, limit))
    timing = dynamic_timing(tight, path, MASS, INERTIA, 0.05, 0.2)
    assert not timing.feasible and "no dynamically feasible timing" in timing.reason


def test_robot_file_mass_properties():
    from cdh_planner.errors import InputError
    from cdh_planner.model.robot import read_yaml, robot_from_dict, ros_parameters
    from conftest import CONFIG
    problem = load_problem(PROBLEMS / "robot2_q2_q3.yaml")
    assert problem.robot.mass == MASS and np.allclose(problem.robot.inertia, INERTIA)
    doc = ros_parameters(read_yaml(CONFIG / "robot2.yaml", "robot"), "robot2.yaml")["robot"]
    doc["load"]["inertia"] = [0.001, -0.001, 0.001]
    with pytest.raises(InputError, match="robot.load.inertia .*positive semi-definite"):
        robot_from_dict(doc)


def test_the_planner_times_dynamically_when_the_robot_has_a_mass(q2_q3):
    problem, _, timing = q2_q3
    result = Planner(problem.robot, problem.task, problem.settings).plan(problem.start, problem.goal)
    assert result.stats["timing"].startswith("dynamic timing")
    # the same timing, with points added where a controller's quintic needs them and slowed
    # where it still overshoots a winch limit (trajectory.executed; the fixture re-timed the
    # planner's output, points included)
    assert timing.duration * (1 - 1e-3) <= result.path.t[-1] <= 1.2 * timing.duration
    assert "points added" in result.stats["executed"]
    quasi = Planner(problem.robot, problem.task, replace(problem.settings, dynamics="quasi_static"))
    assert quasi.plan(problem.start, problem.goal).stats["timing"] == "quasi-static"
