"""The scene on the command line: ``verify --scene FILE`` and a problem file's ``scene:``
(start in collision: exit 1 naming the obstacle; a bad scene: exit 2 naming the field)."""

import json

import numpy as np
import yaml

from cdh_planner import cli
from cdh_planner.model.pose import quaternion_from_tau

from conftest import CONFIG, PROBLEMS

FREE = yaml.safe_load((PROBLEMS / "robot2_q2_q3_free_flight.yaml").read_text())
MID = (0.5 * (np.array(FREE["start"]["position"]) + np.array(FREE["goal"]["position"]))).tolist()
BALL = {"id": "ball", "type": "sphere", "radius": 0.01, "position": MID}
PLATFORM = {"type": "sphere", "radius": 0.03}


def write_scene(tmp_path, obstacles):
    path = tmp_path / "scene.yaml"
    doc = {"scene": {"cable_radius": 0.001, "platform": PLATFORM, "obstacles": obstacles}}
    path.write_text(yaml.safe_dump(json.loads(json.dumps(doc))))
    return path


def verify(tmp_path, scene):
    poses = [{"position": FREE[k]["position"],
              "quaternion": quaternion_from_tau(np.array(FREE[k]["tau"])).tolist()}
             for k in ("start", "goal")]
    (tmp_path / "poses.json").write_text(json.dumps(poses))
    out = tmp_path / "out.json"
    rc = cli.main(["verify", str(CONFIG / "robot2.yaml"), str(tmp_path / "poses.json"),
                   "--json", str(out), "--scene", str(scene)])
    return rc, json.loads(out.read_text())


def test_verify_with_a_scene_finds_the_obstacle_on_the_straight_motion(tmp_path, capsys):
    rc, doc = verify(tmp_path, write_scene(tmp_path, [BALL]))
    assert rc == 1 and not doc["all_feasible"]
    assert all(p["feasible"] for p in doc["poses"])  # the ends are clear
    seg = doc["segments"][0]
    assert not seg["feasible"] and seg["first_unsafe"]["binding"] == "collision platform / ball"
    assert "collision platform / ball" in capsys.readouterr().out
    rc, doc = verify(tmp_path, write_scene(tmp_path, []))
    assert rc == 0 and doc["all_feasible"]  # the same motion without it: feasible


def test_verify_refuses_a_bad_scene_file_by_field(tmp_path, capsys):
    bad = dict(BALL, radius=-1.0)
    (tmp_path / "poses.json").write_text(json.dumps([{"position": MID, "tau": [0, 0, 0]}]))
    assert cli.main(["verify", str(CONFIG / "robot2.yaml"), str(tmp_path / "poses.json"),
                     "--scene", str(write_scene(tmp_path, [bad]))]) == 2
    err = capsys.readouterr().err
    assert "scene.obstacles[0].radius" in err and "Traceback" not in err


def problem(tmp_path, scene):
    doc = json.loads(json.dumps(dict(FREE, robot=str(CONFIG / "robot2.yaml"), scene=scene)))
    path = tmp_path / "problem.yaml"  # (a JSON round trip: no shared lists, no YAML anchors)
    path.write_text(yaml.safe_dump(doc))
    return path


def test_plan_refuses_a_start_in_collision_with_exit_1_naming_the_obstacle(tmp_path, capsys):
    snag = dict(BALL, id="snag", position=FREE["start"]["position"])  # inside the platform
    path = problem(tmp_path, {"platform": PLATFORM, "obstacles": [snag]})
    assert cli.main(["plan", str(path), "--quiet", "--json", str(tmp_path / "plan.json")]) == 1
    out = capsys.readouterr()
    assert "snag" in out.out + out.err and "Traceback" not in out.err
    doc = json.loads((tmp_path / "plan.json").read_text())
    assert doc["reason"] == "start_in_collision"


def test_a_problem_files_bad_scene_exits_2_naming_the_field(tmp_path, capsys):
    path = problem(tmp_path, {"obstacles": [dict(BALL, type="cone")]})
    assert cli.main(["plan", str(path), "--quiet"]) == 2
    assert "scene.obstacles[0].type" in capsys.readouterr().err


def test_plan_reports_the_least_clearance_and_what_binds(tmp_path, capsys):
    path = problem(tmp_path, {"cable_radius": 0.001, "platform": PLATFORM, "obstacles": [BALL]})
    assert cli.main(["plan", str(path), "--quiet", "--json", str(tmp_path / "plan.json")]) == 0
    doc = json.loads((tmp_path / "plan.json").read_text())
    assert doc["least_clearance_m"] > 0 and " / " in doc["clearance_binding"]
    assert "least clearance" in capsys.readouterr().out
