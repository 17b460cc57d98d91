"""``cdh-planner verify`` end to end, and the dense segment check it is built on."""
import json
import types

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from cdh_planner import cli
from cdh_planner.wrench import wrench_feasibility
from cdh_planner.model.pose import quaternion_from_tau, rotation_angle_between, rotation_from_quaternion
from cdh_planner.model.robot import load_robot
from cdh_planner.trajectory import path_check as tv

from conftest import REPO as ROOT
ROBOT1_FILE = ROOT / "config" / "robot1.yaml"
ROBOT2_FILE = ROOT / "config" / "robot2.yaml"
SIGMA = 17 * np.pi / 90
POSE_KEYS = {"feasible", "margin", "binding", "lengths", "tension_min", "tension_nominal", "tension_max"}
POINT_KEYS = {"s", "margin", "binding", "position", "quaternion"}


def run_verify(tmp_path, robot_file, poses, *extra):
    poses_file = tmp_path / "poses.json"
    poses_file.write_text(json.dumps(poses))
    out = tmp_path / "out.json"
    rc = cli.main(["verify", str(robot_file), str(poses_file), "--json", str(out), *extra])
    return rc, json.loads(out.read_text())


def test_feasible_poses_and_motion_exit_0(tmp_path, capsys):
    poses = [{"position": [0.0, 0.0, 0.176], "tau": [0.0, 0.0, 0.0]},
             {"position": [0.0, 0.0, 0.35], "quaternion": [0.0, 0.0, 0.0, 1.0]},
             {"position": [0.01, 0.0, 0.33], "tau": [0.3, 0.2, 0.1]}]
    rc, doc = run_verify(tmp_path, ROBOT1_FILE, poses)
    assert rc == 0
    assert doc["all_feasible"] is True
    assert doc["robot"] == "robot1"
    assert len(doc["poses"]) == 3 and len(doc["segments"]) == 2
    for row in doc["poses"]:
        assert POSE_KEYS <= set(row)
        assert row["feasible"] and row["margin"] > 0
        for key in ("lengths", "tension_min", "tension_nominal", "tension_max"):
            assert len(row[key]) == 6
        assert all(lo <= nom <= hi for lo, nom, hi in
                   zip(row["tension_min"], row["tension_nominal"], row["tension_max"]))
    for k, seg in enumerate(doc["segments"]):
        assert (seg["from"], seg["to"]) == (k, k + 1)
        assert seg["feasible"] and seg["first_unsafe"] is None
        assert POINT_KEYS <= set(seg["worst"])
        assert 0.0 <= seg["worst"]["s"] <= 1.0
        # The worst point of a segment is no better than its end poses.
        assert seg["worst"]["margin"] <= min(doc["poses"][k]["margin"], doc["poses"][k + 1]["margin"]) + 1e-12
    out = capsys.readouterr().out
    assert "ALL FEASIBLE" in out and "winch_6" in out and "segment 1 -> 2" in out


def test_json_values_agree_with_the_library(tmp_path):
    poses = [{"position": [0.0, 0.0, 0.35], "tau": [-2.3, 1.6, SIGMA]},
             {"position": [0.0, 0.0, 0.35], "tau": [1.7, 1.7, SIGMA]}]
    rc, doc = run_verify(tmp_path, ROBOT1_FILE, poses)
    robot = load_robot(ROBOT1_FILE)
    f = wrench_feasibility(robot, [[0, 0, 0.35]] * 2, tau=[p["tau"] for p in poses])
    for i, row in enumerate(doc["poses"]):
        assert row["margin"] == pytest.approx(f.margin[i])
        assert row["binding"] == f.binding[i]
        np.testing.assert_allclose(row["lengths"], f.lengths[i])
        np.testing.assert_allclose(row["tension_nominal"], f.tension_nominal[i])
        np.testing.assert_allclose(row["tension_min"], f.tension_min[i])
        np.testing.assert_allclose(row["tension_max"], f.tension_max[i])
    # Both poses are feasible (paper's q_s, q_g) but the slerp between them is not.
    assert all(row["feasible"] for row in doc["poses"])
    assert rc == 1 and doc["all_feasible"] is False
    seg = doc["segments"][0]
    assert seg["feasible"] is False
    bad = seg["first_unsafe"]
    assert POINT_KEYS <= set(bad)
    assert 0 < bad["s"] <= seg["worst"]["s"] and bad["margin"] <= 0
    assert seg["worst"]["margin"] <= bad["margin"]
    # The reported point is the pose at that fraction of the segment.
    p, q = tv.interpolate_segment([0, 0, 0.35], quaternion_from_tau(poses[0]["tau"]),
                                  [0, 0, 0.35], quaternion_from_tau(poses[1]["tau"]), [bad["s"]])
    np.testing.assert_allclose(bad["position"], p[0], atol=1e-12)
    np.testing.assert_allclose(bad["quaternion"], q[0], atol=1e-9)
    check = wrench_feasibility(robot, [bad["position"]], R=rotation_from_quaternion(np.array([bad["quaternion"]])))
    assert check.margin[0] <= 1e-9 and check.binding[0] == bad["binding"]


def test_singular_pose_gives_nulls_not_nan(tmp_path):
    poses = [{"position": [0.0, 0.0, 0.35], "tau": [0.0, 0.0, 0.0]},
             {"position": [0.0, 0.0, 0.0], "tau": [0.0, 0.0, 0.0]}]  # in the base plane
    rc, doc = run_verify(tmp_path, ROBOT1_FILE, poses)
    assert rc == 1
    row = doc["poses"][1]
    assert row["feasible"] is False and row["binding"] == "singular"
    assert row["margin"] is None and row["tension_nominal"] == [None] * 6
    assert doc["segments"][0]["worst"]["margin"] is None
    text = (tmp_path / "out.json").read_text()
    assert "NaN" not in text and "Infinity" not in text


def test_single_pose_and_poses_mapping(tmp_path):
    rc, doc = run_verify(tmp_path, ROBOT2_FILE, {"poses": [{"position": [0, 0, 0.176], "tau": [0, 0, 0]}]})
    assert rc == 0 and doc["segments"] == [] and doc["all_feasible"] is True


def test_step_options_change_the_sampling(tmp_path):
    poses = [{"position": [0.0, 0.0, 0.30], "tau": [0.0, 0.0, 0.0]},
             {"position": [0.0, 0.0, 0.35], "tau": [0.0, 0.0, 0.0]}]
    _, fine = run_verify(tmp_path, ROBOT2_FILE, poses, "--step", "0.5mm")
    _, coarse = run_verify(tmp_path, ROBOT2_FILE, poses, "--step", "0.01")
    assert fine["segments"][0]["samples"] >= 101 > coarse["segments"][0]["samples"]
    assert fine["max_step_m"] == pytest.approx(5e-4)
    assert cli.main(["verify", str(ROBOT2_FILE), str(tmp_path / "poses.json"), "--step", "0"]) == 2
    assert cli.main(["verify", str(ROBOT2_FILE), str(tmp_path / "poses.json"), "--angle-step", "x"]) == 2


# --- the library under the command ----------------------------------------------------------

def test_interpolate_segment_is_scipy_slerp():
    rng = np.random.default_rng(3)
    q = Rotation.random(2, random_state=4).as_quat()
    p0, p1 = rng.normal(size=3), rng.normal(size=3)
    s = np.linspace(0, 1, 11)
    p, qs = tv.interpolate_segment(p0, q[0], p1, q[1], s)
    np.testing.assert_allclose(p, p0 + s[:, None] * (p1 - p0))
    expected = Slerp([0, 1], Rotation.from_quat(q))(s).as_matrix()
    np.testing.assert_allclose(Rotation.from_quat(qs).as_matrix(), expected, atol=1e-12)
    assert np.all(qs[:, 3] >= 0)


def test_sampling_respects_the_steps():
    robot = load_robot(ROBOT2_FILE)
    p = np.array([[0.0, 0.0, 0.25], [0.02, 0.01, 0.3]])
    q = quaternion_from_tau(np.array([[0.0, 0.2, 0.0], [1.0, 0.4, 0.3]]))
    path = tv.SlerpPath(p, q)
    seg, s = tv._initial_grid(path, 1e-3, np.deg2rad(0.2))
    pos, R = path(seg, s)
    assert s[0] == 0 and s[-1] == 1
    assert np.linalg.norm(np.diff(pos, axis=0), axis=1).max() <= 1e-3 + 1e-12
    assert rotation_angle_between(R[:-1], R[1:]).max() <= np.deg2rad(0.2) + 1e-9
    (check,) = tv.check_motion(robot, p, q)
    assert check.samples >= s.size


class LinePath:
    """s -> position (s, 0, 0), identity orientation: lets a fake margin be a function of s."""

    n_segments = 1

    def __call__(self, seg, s):
        return np.column_stack([s, np.zeros_like(s), np.zeros_like(s)]), np.broadcast_to(np.eye(3), (s.size, 3, 3))

    def speeds(self):
        return np.array([1.0]), np.array([0.0])


def fake_evaluate(margin_of_s):
    def evaluate_(robot, p, tau=None, R=None):
        m = margin_of_s(p[:, 0])
        return types.SimpleNamespace(margin=m, binding=np.where(m > 0, "ok", "violated"))
    return evaluate_


def test_refinement_catches_a_dip_between_coarse_samples(monkeypatch):
    # V-shaped margin dipping below zero on [0.5025, 0.5035]: samples every 0.1 all see
    # positive margins, but the steep secants around s = 0.5 trigger refinement.
    monkeypatch.setattr(tv, "wrench_margin", fake_evaluate(lambda s: 2 * np.abs(s - 0.503) - 0.001))
    (check,) = tv.check_path(None, LinePath(), max_step_m=0.1)
    assert not check.feasible
    assert check.first_unsafe.s == pytest.approx(0.5025, abs=1e-9)
    assert check.worst.margin < 0 and check.unresolved == 0


def test_no_refinement_where_the_margin_is_comfortable(monkeypatch):
    monkeypatch.setattr(tv, "wrench_margin", fake_evaluate(lambda s: 0.5 + 0.1 * np.sin(3 * s)))
    (check,) = tv.check_path(None, LinePath(), max_step_m=0.1)
    assert check.feasible and check.first_unsafe is None
    assert check.samples == 11


def test_first_unsafe_at_the_start(monkeypatch):
    monkeypatch.setattr(tv, "wrench_margin", fake_evaluate(lambda s: s - 0.5))
    (check,) = tv.check_path(None, LinePath(), max_step_m=0.1)
    assert check.first_unsafe.s == 0.0 and check.worst.s == 0.0


def test_margin_grazing_zero_is_reported_unresolved(monkeypatch):
    # Tangent to zero at s = 0.5037 (between samples): sampling cannot decide; refinement
    # stops at its limits and says so in ``unresolved`` instead of looping.
    monkeypatch.setattr(tv, "wrench_margin", fake_evaluate(lambda s: (s - 0.5037) ** 2))
    monkeypatch.setattr(tv, "MAX_SAMPLES", 5000)
    (check,) = tv.check_path(None, LinePath(), max_step_m=0.01)
    assert check.unresolved > 0
    assert check.samples <= 5000
    assert check.worst.s == pytest.approx(0.5037, abs=1e-6)


def test_margin_close_to_zero_is_resolved_by_refinement(monkeypatch):
    monkeypatch.setattr(tv, "wrench_margin", fake_evaluate(lambda s: (s - 0.5037) ** 2 + 1e-10))
    (check,) = tv.check_path(None, LinePath(), max_step_m=0.01)
    assert check.feasible and check.unresolved == 0
    assert check.worst.margin == pytest.approx(1e-10, rel=0.5)


def test_task_motion_first_unsafe_is_at_the_boundary():
    from cdh_planner.model.task import SphereTask

    robot = load_robot(ROBOT2_FILE)
    task = SphereTask(center=(0.0, 0.0, 0.306), radius=0.13)
    (check,) = tv.check_task_motion(robot, task, np.array([[0.55, 0.75], [2.63, 0.75]]))
    s = check.first_unsafe.s
    a1 = 0.55 + np.array([s - 1e-6, s]) * (2.63 - 0.55)
    p, tau = task.pose(np.column_stack([a1, [0.75, 0.75]]))
    f = wrench_feasibility(robot, p, tau)
    assert f.feasible[0] and not f.feasible[1]
