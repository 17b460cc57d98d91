"""Robots with more than six cables: the config robots, forward kinematics by
least squares, and the robot file choosing the tension rule."""

import dataclasses

import numpy as np
import pytest
from scipy.optimize import least_squares

from cdh_planner import wrench as fz
from cdh_planner.errors import InputError
from cdh_planner.model.kinematics import cable_lengths, forward_kinematics, length_jacobian, \
    rotation_vector_exp
from cdh_planner.model.pose import rotation_tt
from cdh_planner.model.robot import GRAVITY, load_robot

from conftest import CONFIG

COGIRO = load_robot(CONFIG / "cogiro.yaml")
ROBOT2_8 = load_robot(CONFIG / "robot2_8.yaml")


def test_cogiro_is_casprs_robot_z_up():
    """8 cables, CASPR's numbers (CoGiRo_cables.xml, CoGiRo_bodies.xml), gravity along -z."""
    assert len(COGIRO.winch_names) == 8 and COGIRO.base_anchors.shape == (8, 3)
    np.testing.assert_array_equal(COGIRO.base_anchors[0], [-7.1775, -5.4361, 5.3911])
    np.testing.assert_array_equal(COGIRO.platform_anchors[7], [-0.5045, -0.3463, 0.9976])
    assert np.all(COGIRO.tension_min == 100.0) and np.all(COGIRO.tension_max == 5000.0)
    np.testing.assert_allclose(COGIRO.force, [0.0, 0.0, -91.058 * GRAVITY])
    np.testing.assert_array_equal(COGIRO.load_point, [-0.034, -0.013, 0.264])


def test_the_8_cable_robots_hold_a_central_pose_with_a_usable_band():
    """Hanging level at the middle of the room (CoGiRo: CASPR's q_initial, z = 2 m; Robot 2
    with 8 cables: 0.3 m below the base), both wrench-feasible, the rule's band inside the
    limits, J t0 = w0."""
    for robot, p in ((COGIRO, [0.0, 0.0, 2.0]), (ROBOT2_8, [0.0, 0.0, 0.3])):
        f = fz.wrench_feasibility(robot, np.array([p]), np.zeros((1, 3)))
        assert f.feasible[0] and f.tension_status[0] == fz.STATUS_OK, (robot.name, f.binding)
        assert np.all(f.tension_min[0] > robot.tension_min) and np.all(f.tension_max[0] < robot.tension_max)
        J = fz.screw_jacobian(robot, f.unit_vectors)[0]
        w0 = fz.nominal_wrench(robot, fz.load_point(robot, np.array([p]), np.eye(3)[None]))[0]
        np.testing.assert_allclose(J @ f.tension_nominal[0], w0, rtol=0, atol=1e-9 * np.abs(w0).max())


def test_the_robot_file_chooses_the_tension_rule_by_name():
    """``tension_rule`` defaults to the centred rule; an unknown name is one line naming
    robot.tension_rule and the known rules, not a traceback."""
    assert COGIRO.tension_rule == fz.DEFAULT_RULE == "centred" and "centred" in fz.RULES
    robot = dataclasses.replace(COGIRO, tension_rule="greedy")
    with pytest.raises(InputError, match=r"robot.tension_rule = .*greedy.*expected one of \['centred'"):
        fz.wrench_feasibility(robot, np.array([[0.0, 0.0, 2.0]]), np.zeros((1, 3)))


def _pose(rng):
    p = np.array([0.5, -1.0, 2.0]) + rng.uniform(-1.0, 1.0, 3)
    return p, rotation_tt(np.array([[rng.uniform(-np.pi, np.pi), rng.uniform(0, 0.3), rng.uniform(-0.3, 0.3)]]))[0]


def test_forward_kinematics_of_exact_lengths_finds_the_pose():
    rng = np.random.default_rng(1)
    for _ in range(5):
        p, R = _pose(rng)
        fk = forward_kinematics(COGIRO, cable_lengths(COGIRO, p, R), p + 0.05, rotation_vector_exp([0.05, -0.03, 0.04]) @ R)
        assert fk.ok and fk.residual < 1e-11, fk.message
        np.testing.assert_allclose(fk.p, p, atol=1e-10)
        np.testing.assert_allclose(fk.R, R, atol=1e-10)


def test_forward_kinematics_of_noisy_lengths_is_the_least_squares_pose():
    """1 mm of noise on 8 lengths: converged, residual reported (the inconsistency), and the
    pose is the one scipy's least_squares (independent: trust-region on a rotation vector)
    finds, to 1e-6 m / rad."""
    rng = np.random.default_rng(2)
    for _ in range(5):
        p, R = _pose(rng)
        L = cable_lengths(COGIRO, p, R) + 1e-3 * rng.normal(size=8)
        fk = forward_kinematics(COGIRO, L, p + 0.05, rotation_vector_exp([0.05, -0.03, 0.04]) @ R)
        assert fk.ok, fk.message
        e = cable_lengths(COGIRO, fk.p, fk.R) - L
        assert fk.residual == pytest.approx(np.abs(e).max()) and 1e-5 < fk.residual < 5e-3
        ref = least_squares(lambda x: cable_lengths(COGIRO, x[:3], rotation_vector_exp(x[3:]) @ R) - L,
                            np.r_[p, 0.0, 0.0, 0.0], xtol=1e-15, ftol=1e-15, gtol=1e-15)
        np.testing.assert_allclose(fk.p, ref.x[:3], atol=1e-6)
        np.testing.assert_allclose(fk.R, rotation_vector_exp(ref.x[3:]) @ R, atol=1e-6)
        J = length_jacobian(COGIRO, fk.p, fk.R)
        assert np.linalg.norm(J.T @ e) <= 1e-6 * np.linalg.norm(J) * np.linalg.norm(e)


def test_forward_kinematics_wants_one_length_per_cable():
    with pytest.raises(InputError, match=r"lengths = .*expected shape \(8,\)"):
        forward_kinematics(COGIRO, np.ones(6), np.zeros(3), np.eye(3))


def test_slice_of_cogiro(tmp_path, capsys):
    """`cdh-planner slice` on the 8-cable robot (the facet test per cell): the level
    platform at z = 2.5 m is feasible over the middle of the room, not at its walls."""
    from cdh_planner import cli
    out = tmp_path / "cogiro.png"
    rc = cli.main(["slice", str(CONFIG / "cogiro.yaml"), "--fixed", "z=2.5", "phi=0", "theta=0", "sigma=0",
                   "--free", "x", "y", "--range", "x=-7.5:7.5", "y=-5.5:5.5", "--resolution", "21",
                   "-o", str(out)])
    text = capsys.readouterr().out
    assert rc == 0 and out.stat().st_size > 0, text
    share = float(text.split("classified in")[1].split(";")[1].split("%")[0])
    assert 30.0 < share < 90.0, text
    inside = fz.wrench_feasibility(COGIRO, np.array([[0.0, 0.0, 2.5], [7.0, 5.0, 2.5]]), np.zeros((2, 3)))
    assert inside.feasible.tolist() == [True, False]


def test_verify_an_8_cable_robot(tmp_path, capsys):
    """`cdh-planner verify` on CoGiRo: per-pose answers, 8 lengths and tensions, the
    envelope's status in the JSON, and the dense check of the segments (the straight motion
    toward the corner leaves the feasible set: exit 1)."""
    import json
    from cdh_planner import cli
    poses = tmp_path / "poses.json"
    poses.write_text(json.dumps([{"position": p, "quaternion": [1, 0, 0, 0]}
                                 for p in ([0, 0, 2], [3, 1, 2.5], [7, 5, 2.5])]))
    out = tmp_path / "v.json"
    assert cli.main(["verify", str(CONFIG / "cogiro.yaml"), str(poses), "--json", str(out)]) == 1
    doc = json.loads(out.read_text())
    assert [p["feasible"] for p in doc["poses"]] == [True, True, False]
    assert [p["tension_status"] for p in doc["poses"]] == ["ok", "ok", "infeasible"]
    assert all(len(p["lengths"]) == len(p["tension_nominal"]) == 8 for p in doc["poses"])
    assert [s["feasible"] for s in doc["segments"]] == [True, False]
    assert 0 < doc["segments"][1]["first_unsafe"]["s"] < 1
    capsys.readouterr()
