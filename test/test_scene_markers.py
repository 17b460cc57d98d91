"""A scene's obstacles in the plan markers: one per obstacle, of its shape, size and pose."""

import numpy as np
from visualization_msgs.msg import Marker

from cdh_planner.ros.msgs.markers import obstacle_markers
from cdh_planner.scene.schema import scene_from_dict

Q = [0.0, 0.0, 0.7071067811865476, 0.7071067811865476]


def test_obstacles_are_drawn_with_their_shape_size_and_pose(tmp_path):
    import trimesh
    trimesh.creation.box(extents=[0.1, 0.2, 0.3]).export(tmp_path / "b.stl")
    scene = scene_from_dict({"obstacles": [
        {"id": "ball", "type": "sphere", "radius": 0.02, "position": [0.1, 0.0, 0.3]},
        {"id": "post", "type": "box", "size": [0.02, 0.03, 0.2], "position": [0, 0.1, 0.3],
         "quaternion": Q},
        {"id": "pipe", "type": "cylinder", "radius": 0.01, "height": 0.3},
        {"id": "fix", "type": "mesh", "file": "b.stl"}]}, base_dir=tmp_path)
    ms = obstacle_markers(scene, "cdh_base", None)
    assert [m.type for m in ms] == [Marker.SPHERE, Marker.CUBE, Marker.CYLINDER,
                                    Marker.TRIANGLE_LIST]
    assert all(m.ns == "obstacles" and m.header.frame_id == "cdh_base" for m in ms)
    assert [m.id for m in ms] == [0, 1, 2, 3]
    assert (ms[0].scale.x, ms[0].pose.position.x) == (0.04, 0.1)
    assert (ms[1].scale.x, ms[1].scale.y, ms[1].scale.z) == (0.02, 0.03, 0.2)
    assert ms[1].pose.orientation.z == Q[2] and ms[1].pose.orientation.w == Q[3]
    assert (ms[2].scale.x, ms[2].scale.z) == (0.02, 0.3)
    pts = np.array([[p.x, p.y, p.z] for p in ms[3].points])
    assert len(pts) % 3 == 0 and len(pts) >= 36  # a box hull: 12 triangles
    assert np.allclose(np.abs(pts).max(axis=0), [0.05, 0.1, 0.15])
