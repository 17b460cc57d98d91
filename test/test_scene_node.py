"""The node's scene: the parameter scene_file gives the scene
its plans keep clear of; changing it makes a new planner; a bad file is refused naming
the field. (The ~/obstacles topic and service are not there yet.)"""

import numpy as np
import pytest
import yaml

from cdh_planner.errors import InputError
from cdh_planner.ros.core import params
from cdh_planner.ros.node.planner_node import default_planner_factory

from ros_harness import file_parameters  # noqa: E402
from conftest import CONFIG

BALL = {"id": "ball", "type": "sphere", "radius": 0.01, "position": [0.0, 0.048, 0.217]}


def config_with(tmp_path, scene):
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump({"scene": scene}))
    values = dict(file_parameters(CONFIG / "robot2.yaml"), scene_file=str(path))
    return params.node_config(values)


def test_scene_file_gives_the_planners_scene(tmp_path):
    config = config_with(tmp_path, {"cable_radius": 0.001, "obstacles": [BALL]})
    assert [o.id for o in config.scene.obstacles] == ["ball"]
    planner = default_planner_factory(config.robot, config.task, config.settings,
                                      scene=config.scene)
    assert planner.collision is not None and planner.scene is config.scene
    assert params.needs_new_planner(["scene_file"], {"scene_file": ""}, {"scene_file": "x"})
    no_scene = params.node_config(file_parameters(CONFIG / "robot2.yaml"))
    assert no_scene.scene is None


def test_a_bad_scene_file_is_refused_naming_the_field(tmp_path):
    with pytest.raises(InputError) as info:
        config_with(tmp_path, {"obstacles": [dict(BALL, radius=0)]})
    assert info.value.field == "scene.obstacles[0].radius"
    with pytest.raises(InputError, match="file not found"):
        params.node_config(dict(file_parameters(CONFIG / "robot2.yaml"),
                                scene_file=str(tmp_path / "missing.yaml")))


def test_a_scene_set_over_the_parameter_service_changes_the_next_plan(tmp_path):
    """The node with the real planner (Robot 2 free flight, Q2 -> Q3 of the sphere task: the
    direct motion): a 3 mm bead put on cable 3 of the path's middle pose through
    scene_file makes the next plan go around it (checked at every waypoint and densely
    between with the closed-form capsule-sphere distance); clearing scene_file brings the
    first plan back."""
    from rclpy.parameter import Parameter
    from test_ros_reliability import plan
    from cdh_planner.model.pose import rotation_from_quaternion
    from cdh_planner.ros.msgs.messages import path_arrays
    from test_ros_obstacles import least_distance
    from cdh_planner.model.robot import load_robot
    from ros_harness import Q2, Q3, in_process_nodes

    robot = load_robot(CONFIG / "robot2.yaml")

    with in_process_nodes(tmp_path / "runs") as make:
        node = make(factory=default_planner_factory,
                    params=["task.type:=free", "planner.radius:=0.5"])
        first, values = plan(node, Q2, Q3)
        assert values["error_code"] == "0"
        p, q = path_arrays(first)
        k = len(p) // 2
        b = p[k] + rotation_from_quaternion(q[k]) @ robot.platform_anchors[2]
        bead = {"id": "bead", "type": "sphere", "radius": 0.003,
                "position": (0.5 * (robot.base_anchors[2] + b)).tolist()}
        assert least_distance(robot, first, bead["position"], bead["radius"], 0.001) < 0
        scene = tmp_path / "scene.yaml"
        scene.write_text(yaml.safe_dump({"scene": {"cable_radius": 0.001, "obstacles": [bead]}}))
        node.set_parameters([Parameter("scene_file", value=str(scene))])
        around, values = plan(node, Q2, Q3)
        assert values["error_code"] == "0", values
        assert least_distance(robot, around, bead["position"], bead["radius"], 0.001) > 0
        node.set_parameters([Parameter("scene_file", value="")])
        again, _ = plan(node, Q2, Q3)
        assert np.allclose(path_arrays(again)[0], path_arrays(first)[0])


def test_a_shape_without_an_obstacle_message_is_refused_when_the_node_loads_it(tmp_path):
    """A registered shape type with no ROS primitive (and no mesh vertices) could not be
    published on ~/scene: the node refuses the scene file naming the shape and the reason
    its class gives, rather than failing later. A scratch type, registered for the test."""
    from cdh_planner.model import shapes
    from cdh_planner.ros.msgs.scene_msgs import check_sendable

    @shapes.register
    class Cone(shapes.ShapeType):
        type, markers = "cone", ("SPHERE",)
        keys = (shapes.RADIUS, shapes.length("height", "height along z"))
        no_primitive = "no SolidPrimitive nor Obstacle constant for a cone"
        bounding_radius = staticmethod(lambda s: s.radius + s.height)
        coal_geometry = staticmethod(lambda s: None)
        marker_parts = staticmethod(lambda s: [(np.zeros(3), np.full(3, 2.0 * s.radius))])
        mjcf = staticmethod(lambda s: ("sphere", [s.radius]))

    cone = {"id": "cone", "type": "cone", "radius": 0.01, "height": 0.02}
    try:
        with pytest.raises(InputError) as info:
            config_with(tmp_path, {"obstacles": [BALL, cone]})
        assert str(info.value) == ("scene.obstacles[1].type = 'cone': has no Obstacle message for "
                                   "the node: no SolidPrimitive nor Obstacle constant for a cone")
        # a scene of shapes that have a message passes as it is
        scene = config_with(tmp_path, {"obstacles": [BALL]}).scene
        assert check_sendable(scene) is scene
    finally:
        del shapes.SHAPES["cone"]
