"""Obstacles over ROS, the real planner in `cdh-planner node` processes
of their own ROS domain: an obstacle added on ``~/obstacles`` changes the next plan (which
keeps clear of it, checked densely by the closed-form capsule-sphere distance), its
removal brings the first plan back, every answer names its scene version (PlanPath's
``scene_version``, ``~/plan_result``); the obstacles and the scene are recorded, and
``replay --requests`` on a fresh node reproduces every answer; a refused item is named in
the node's log and the node goes on."""

import numpy as np
import pytest

pytest.importorskip("rclpy")

from cdh_planner.model.pose import rotation_from_quaternion  # noqa: E402
from cdh_planner.model.robot import load_robot  # noqa: E402
from cdh_planner.ros.client import ClientError, plan_path_goal  # noqa: E402
from cdh_planner.ros.msgs.messages import path_arrays  # noqa: E402
from cdh_planner.ros.replay import SCENE_TYPE, read_records  # noqa: E402
from cdh_planner_interfaces.msg import Obstacle  # noqa: E402

from cdh_planner.ros.interface import LATCHED  # noqa: E402
from visualization_msgs.msg import Marker, MarkerArray  # noqa: E402
from ros_harness import FRAME, Q2, Q3, ROBOT2, Collector, NodeProcess, run_cli, \
    sphere_pose_msg  # noqa: E402
from test_scene_distances import point_segment  # noqa: E402
from test_scene_state import array, sphere  # noqa: E402

FREE = ["task.type:=free", "planner.radius:=0.5"]   # Robot 2 free flight: Q2 -> Q3 direct
CABLE_RADIUS = 0.0   # no scene_file: the robot's (robot2.yaml has none: 0)


def least_distance(robot, path_msg, centre, radius, cable_radius=CABLE_RADIUS, steps=20):
    """Least distance (m) of the cables' capsules (``cable_radius`` m) to a sphere along
    the nav_msgs/Path: at every waypoint and ``steps`` points between (closed form, no
    collision library)."""
    p, q = path_arrays(path_msg)
    t = np.linspace(0.0, 1.0, steps + 1)[:, None]
    pp = np.concatenate([p[k] + t * (p[k + 1] - p[k]) for k in range(len(p) - 1)])
    qq = np.concatenate([q[k] + t * (q[k + 1] - q[k]) for k in range(len(q) - 1)])
    R = rotation_from_quaternion(qq / np.linalg.norm(qq, axis=1, keepdims=True))
    ends = pp[:, None] + np.einsum("nij,kj->nki", R, robot.platform_anchors)
    return min(point_segment(centre, robot.base_anchors[i], b[i]) for b in ends
               for i in range(len(robot.base_anchors))) - radius - cable_radius


def test_obstacles_over_dds_change_the_next_plan_and_replay_reproduces_them(
        domain, client, tmp_path):
    robot = load_robot(ROBOT2)
    start, goal = sphere_pose_msg(Q2), sphere_pose_msg(Q3)
    node = NodeProcess(domain, tmp_path / "recorded", params=FREE)
    try:
        client.wait_for_node(60.0)
        assert client.get_scene().version == 0 and not client.get_scene().checked
        first = client.plan(start, goal, timeout_s=60)
        assert first.success and first.values["scene_version"] == "0", first.values
        # a 3 mm bead on cable 3, half way along it, at the path's middle pose
        p, q = path_arrays(first.path)
        k = len(p) // 2
        b = p[k] + rotation_from_quaternion(q[k]) @ robot.platform_anchors[2]
        centre, radius = 0.5 * (robot.base_anchors[2] + b), 0.003
        assert least_distance(robot, first.path, centre, radius) < 0
        scene = client.update_scene(array(sphere("bead", radius, centre)))
        assert scene.version == 1 and scene.checked and [o.id for o in scene.obstacles] == ["bead"]
        # the latched ~/scene_markers: DELETEALL, then the bead as a 6 mm SPHERE there
        drawn = Collector(client.node, MarkerArray, "/cdh_planner/scene_markers", LATCHED)
        assert client.spin_until(lambda: drawn.messages, 10.0)
        deleteall, bead = drawn.messages[-1].markers
        assert deleteall.action == Marker.DELETEALL and bead.type == Marker.SPHERE
        assert bead.ns == "obstacles" and bead.scale.x == pytest.approx(2 * radius)
        assert np.allclose([bead.pose.position.x, bead.pose.position.y, bead.pose.position.z],
                           centre)
        around = client.plan_path(plan_path_goal(start, goal), timeout_s=60)
        assert around.result.error_code == 0, around.result.error_msg
        assert around.result.scene_version == 1
        assert least_distance(robot, around.path, centre, radius) > 0
        # refused items are named, the others taken; the node goes on
        with pytest.raises(ClientError, match="did not change"):
            client.update_scene(array(sphere("ghost", 0.01, centre, Obstacle.REMOVE)), 3.0)
        scene = client.update_scene(array(sphere("bead", radius, centre, Obstacle.REMOVE),
                                          sphere("bad", -1.0, centre)))
        assert scene.version == 2 and scene.checked and not scene.obstacles
        again = client.plan(start, goal, timeout_s=60)
        assert again.values["scene_version"] == "2"
        assert np.allclose(path_arrays(again.path)[0], path_arrays(first.path)[0], atol=1e-6)
    finally:
        assert node.stop() == 0, node.log()
    log = node.log()
    assert "obstacles[0] (ghost): obstacles[0].id = 'ghost': no obstacle of this id" in log, log
    assert "obstacles[1] (bad): " in log and "remove bead" in log
    files = node.run_files()
    records = [r for f in files for r in read_records(f)]
    received = [r for r in records if r.topic == "/cdh_planner/obstacles"]
    scenes = [r for r in records if r.type_name == SCENE_TYPE]
    assert len(received) == 3 and len(scenes) == 3    # the first scene: at configure
    with NodeProcess(domain, tmp_path / "fresh", params=FREE + ["log_enabled:=false"]):
        client.wait_for_node(60.0)
        r = run_cli(domain, "replay", *map(str, files), "--requests", timeout=300)
        assert r.returncode == 0, r.stdout + r.stderr
        assert "3 of 3 answers match the recording" in r.stdout, r.stdout
        assert "goal 2: obstacles as recorded (scene version 1): 1 added or removed" \
            in r.stdout, r.stdout
        assert "request 3: obstacles as recorded (scene version 2): 1 added or removed" \
            in r.stdout, r.stdout


def test_every_rotated_run_file_begins_with_the_current_scene(tmp_path):
    """RunLog: a message written as a snapshot (the node's ~/scene) opens every later file
    (after the parameters), so a replay of any one file knows the obstacles."""
    from cdh_planner.ros.core.run_log import RunLog
    from cdh_planner.ros.msgs.scene_msgs import scene_msg
    from cdh_planner.scene.schema import scene_from_dict
    from std_msgs.msg import String

    log = RunLog(tmp_path, True, warn=print, info=lambda text: None, max_bytes=4000)
    ball = scene_from_dict({"obstacles": [{"id": "ball", "type": "sphere", "radius": 0.01}]})
    log.write("/cdh_planner/scene", scene_msg(1, ball, FRAME), transient_local=True,
              snapshot=True)
    for k in range(40):
        log.write("/cdh_planner/chatter", String(data="x" * 400))
    log.close()
    files = sorted(tmp_path.glob("*.mcap"))
    assert len(files) >= 3
    for f in files:
        records = read_records(f)
        assert records[0].type_name == SCENE_TYPE and records[0].transient_local, f
        assert sum(r.type_name == SCENE_TYPE for r in records) == 1
