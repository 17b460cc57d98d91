"""The node's scene (issue 22, item 4 in part): the parameter scene_file gives the scene
its plans keep clear of; changing it makes a new planner; a bad file is refused naming
the field. (The ~/obstacles topic and service are not there yet.)"""

import yaml
import pytest

from cdh_planner.errors import InputError
from cdh_planner.ros import params
from cdh_planner.ros.node import default_planner_factory

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
