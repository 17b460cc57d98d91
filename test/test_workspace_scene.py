"""``cdh-planner workspace`` with a scene and on a robot of eight cables: each sample's
feasibility, margin and binding are ``verify``'s for the same poses (one validity, the
planner's: pipeline.validity), the scene only lowers margins, reach plans around it, and a
sweep takes a scene and an eight-cable robot."""

import json
import re

import numpy as np
import pytest
import yaml

from cdh_planner import cli
from cdh_planner.model.robot import load_robot
from cdh_planner.scene.schema import load_scene
from cdh_planner.studies import sweep as sw
from cdh_planner.studies import workspace as ws
from cdh_planner.studies.executors import SerialExecutor
from conftest import CONFIG

ROBOT2, ROBOT8 = CONFIG / "robot2.yaml", CONFIG / "robot2_8.yaml"
HOME2 = ["0", "0.07", "0.2", "0", "0", "0"]  # m, rad: feasible for robot2 (margin 0.11), clear of the ball
HOME8 = ["0", "0", "0.15", "0", "0", "0"]  # m, rad: feasible for robot2_8 (margin 0.11)


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    """A ball of 4 cm in the middle of Robot 2's default box, a platform sphere of 3 cm."""
    low, high = ws.default_box(load_robot(ROBOT2))
    centre = ((np.array(low) + np.array(high)) / 2).tolist()
    doc = {"scene": {"cable_radius": 0.001, "platform": {"type": "sphere", "radius": 0.03},
                     "obstacles": [{"id": "ball", "type": "sphere", "radius": 0.04, "position": centre}]}}
    path = tmp_path_factory.mktemp("scene") / "scene.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def workspace_json(tmp_path, robot, *extra, name="w.json"):
    out = tmp_path / name
    assert cli.main(["workspace", str(robot), "--no-ray", "--quiet", "--json", str(out), *extra]) == 0
    return json.loads(out.read_text())


def verify_json(tmp_path, robot, doc, *extra):
    poses = [{"position": p["position"], "quaternion": p["quaternion"]} for p in doc["poses"]]
    (tmp_path / "poses.json").write_text(json.dumps(poses))
    cli.main(["verify", str(robot), str(tmp_path / "poses.json"), "--json", str(tmp_path / "v.json"),
              "--step", "1", "--angle-step", "3", *extra])  # the poses matter here, not the motions
    return json.loads((tmp_path / "v.json").read_text())["poses"]


def assert_same_answers(doc, verified):
    assert [v["feasible"] for v in verified] == [p["feasible"] for p in doc["poses"]]
    assert np.allclose([v["margin"] for v in verified], [p["margin"] for p in doc["poses"]],
                       rtol=0, atol=1e-12)
    assert [v["binding"] for v in verified] == [p["binding"] for p in doc["poses"]]


def test_point_answers_with_a_scene_equal_verify_with_the_scene(tmp_path, scene_file, capsys):
    doc = workspace_json(tmp_path, ROBOT2, "--samples", "400", "--seed", "2", "--scene", str(scene_file),
                         "--home", *HOME2)
    verified = verify_json(tmp_path, ROBOT2, doc, "--scene", str(scene_file))
    capsys.readouterr()
    assert_same_answers(doc, verified)
    assert doc["scene"] == str(scene_file)
    # the scene binds somewhere, and only ever lowers a margin: same poses without it
    bare = workspace_json(tmp_path, ROBOT2, "--samples", "400", "--seed", "2", "--home", *HOME2,
                          name="bare.json")
    assert [p["position"] for p in bare["poses"]] == [p["position"] for p in doc["poses"]]
    with_scene = np.array([p["margin"] for p in doc["poses"]])
    without = np.array([p["margin"] for p in bare["poses"]])
    hit = np.array([p["binding"].startswith("collision") for p in doc["poses"]])
    assert hit.any() and np.all(with_scene <= without + 1e-12)
    assert np.array_equal(with_scene[~hit], without[~hit])  # elsewhere the wrench margin


def test_point_answers_of_an_eight_cable_robot_equal_verify(tmp_path, capsys):
    doc = workspace_json(tmp_path, ROBOT8, "--samples", "300", "--seed", "4", "--home", *HOME8)
    verified = verify_json(tmp_path, ROBOT8, doc)
    capsys.readouterr()
    assert_same_answers(doc, verified)
    assert doc["cables"] == 8 and 0 < doc["fractions"]["feasible"] < 1
    cables = {int(c) for p in doc["poses"] if p["binding"] and "[" in p["binding"]
              for c in re.findall(r"\d+", p["binding"].split("[")[1])}
    assert cables & {7, 8}  # the facet test's bindings name the cables beyond six


def test_the_default_home_is_clear_of_the_scene_and_a_home_in_it_is_refused(tmp_path, scene_file, capsys):
    robot = load_robot(ROBOT2)
    scene = load_scene(scene_file, robot)
    home = ws.default_home(robot, draws=5000, scene=scene)
    margin, _ = ws.pose_margins(ws.point_validity(robot, scene), np.array([home[0]]), np.array([home[1]]))
    assert margin[0] > 0
    ball = scene.obstacles[0].position
    assert cli.main(["workspace", str(ROBOT2), "--no-ray", "--quiet", "--scene", str(scene_file),
                     "--home", *map(str, ball), "0", "0", "0"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--home" in err and "collision" in err


def test_reach_with_a_scene_plans_around_it(tmp_path, scene_file, capsys):
    """Every sample a plan reached is feasible with the scene; the planner was given it (a
    goal in the ball is not even planned: infeasible)."""
    doc = workspace_json(tmp_path, ROBOT2, "--samples", "60", "--seed", "7", "--scene", str(scene_file),
                         "--reach", "--timeout", "20")
    capsys.readouterr()
    c = doc["counts"]
    assert c["planned"] == c["feasible"] and c["reachable"] > 0
    assert all(p["feasible"] for p in doc["poses"] if p["reachable"])


def test_a_reach_call_plans_in_the_jobs_scene(scene_file, monkeypatch):
    """The worker's planner is built with the job's scene (and none without one)."""
    robot = load_robot(ROBOT2)
    scene = load_scene(scene_file, robot)
    seen = []

    class Recorder(ws.Planner):
        def __init__(self, *args, scene=None, **kw):
            seen.append(scene)
            super().__init__(*args, scene=scene, **kw)

    monkeypatch.setattr(ws, "Planner", Recorder)
    home = ws.default_home(robot, draws=5000, scene=scene)
    low, high = ws.default_box(robot)
    spec = ws.WorkspaceSpec(samples=1, seed=0, box_low=tuple(np.array(home[0]) - 1e-6),
                            box_high=tuple(np.array(home[0]) + 1e-6), home_position=home[0],
                            home_quaternion=home[1], tilt=0.0, reach=True).check()
    res = ws.run_workspace(robot, spec, SerialExecutor(), scene=scene)
    assert seen == [scene] and res.reachable == [True]


def test_reach_on_eight_cables_plans_and_every_reachable_sample_is_feasible(tmp_path):
    """robot2_8 (8 cables): --reach plans from the home to each feasible sample; a sample
    reached is feasible, and at least one is reached."""
    args = ["--no-ray", "--quiet", "--samples", "20", "--seed", "3", "--reach", "--timeout", "10",
            "--home", *HOME8]  # a few plans, each bounded
    doc = workspace_json(tmp_path, ROBOT8, *args)
    assert len(doc["poses"]) == 20
    assert all(p["feasible"] for p in doc["poses"] if p["reachable"])
    assert any(p["reachable"] for p in doc["poses"])


def test_a_sweep_takes_a_scene_and_an_eight_cable_robot(tmp_path, scene_file, capsys):
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump({
        "robot": str(ROBOT8), "vary": {"robot.load.mass": [0.4, 0.6]},
        "workspace": {"samples": 200, "seed": 1, "scene": str(scene_file)}}))
    sweep = sw.load_sweep(path)
    assert sweep.settings()["workspace"]["scene"] == str(scene_file)
    assert cli.main(["sweep", str(path), "--out", str(tmp_path / "out"), "--no-ray", "--quiet"]) == 0
    capsys.readouterr()
    docs = [json.loads((tmp_path / "out" / f"design_{k:04d}.json").read_text()) for k in range(2)]
    for doc in docs:
        w = doc["workspace"]
        assert w["scene"] == str(scene_file) and w["cables"] == 8
        assert any(p["binding"] and p["binding"].startswith("collision") for p in w["poses"])
    # a bad scene file is refused naming its field
    bad = yaml.safe_load(scene_file.read_text())
    bad["scene"]["obstacles"][0]["radius"] = -1
    (tmp_path / "bad_scene.yaml").write_text(yaml.safe_dump(bad))
    path.write_text(yaml.safe_dump({"robot": str(ROBOT8), "vary": {"robot.load.mass": [0.4]},
                                    "workspace": {"scene": "bad_scene.yaml"}}))
    assert cli.main(["sweep", str(path), "--out", str(tmp_path / "out2"), "--no-ray", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "scene.obstacles[0].radius" in err
