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


def test_slice_colours_collision_apart_where_a_cable_meets_the_ball(tmp_path, capsys):
    """``slice --scene``: a cell is COLLISION iff one of its pose's cables (capsules of
    1 mm) meets the ball of config/scenes/robot2_ball.yaml, by the closed-form point-segment
    distance (no collision library); the other cells keep their wrench classes; the PNG is
    written with the collision legend."""
    from cdh_planner.commands.slice import task_in_yaml
    from cdh_planner.pictures.slices import COLLISION, SliceView, classify, compute_slice
    from cdh_planner.wrench import wrench_feasibility
    from cdh_planner.model.pose import rotation_tt
    from cdh_planner.model.robot import load_robot
    from cdh_planner.scene.collision import CollisionModel
    from cdh_planner.scene.schema import load_scene
    from test_scene_distances import point_segment

    robot = load_robot(CONFIG / "robot2.yaml")
    scene = load_scene(CONFIG / "scenes" / "robot2_ball.yaml", robot)
    view = SliceView(task=task_in_yaml(CONFIG / "robot2.yaml"), axes=("alpha1", "alpha2"),
                     ranges=((0.0, 3.0), (0.2, 1.4)))
    grid = compute_slice(robot, view, 30, CollisionModel(robot, scene))
    A, B = np.meshgrid(grid.xs, grid.ys)
    p, tau = view.task.pose(view.coords(A, B))
    R = rotation_tt(tau)
    ball = scene.obstacles[0]
    ends = p[:, None] + np.einsum("nij,kj->nki", R, robot.platform_anchors)
    hit = np.array([min(point_segment(ball.position, robot.base_anchors[i], e[i])
                        for i in range(6)) < ball.radius + scene.cable_radius for e in ends])
    classes = grid.classes.ravel()
    assert 0 < hit.sum() < hit.size
    assert np.array_equal(classes == COLLISION, hit)
    wrench = classify(wrench_feasibility(robot, p, R=R))
    assert np.array_equal(classes[~hit], wrench[~hit])
    out = tmp_path / "slice.png"
    rc = cli.main(["slice", str(CONFIG / "robot2.yaml"), "--sphere", "0,0,0.306,0.13",
                   "--range", "alpha1=0:3", "alpha2=0.2:1.4", "--resolution", "30",
                   "--scene", str(CONFIG / "scenes" / "robot2_ball.yaml"), "-o", str(out)])
    assert rc == 0 and out.stat().st_size > 10_000
