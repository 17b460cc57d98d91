"""Scene files: the format of schema.py read and refused by field; hypothesis over scene
files (random structures, mutations of a valid scene, random text): a Scene or an
InputError of one line, never another exception."""

import copy
import math
import os
from datetime import timedelta

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cdh_planner.errors import MAX_MESSAGE_CHARS, InputError
from cdh_planner.scene.schema import DEFAULT_EXEMPTION_M, load_scene, scene_from_dict

SCALE = int(os.environ.get("CDH_PROPERTY_SCALE", "1"))

VALID = {
    "cable_radius": 0.001,
    "clearance": 0.002,
    "platform": {"type": "box", "size": [0.14, 0.14, 0.01], "position": [0, 0, 0],
                 "quaternion": [0, 0, 0, 1]},
    "obstacles": [
        {"id": "ball", "type": "sphere", "radius": 0.02, "position": [0.1, 0.0, 0.3]},
        {"id": "post", "type": "box", "size": [0.02, 0.02, 0.2], "position": [0.0, 0.1, 0.3],
         "quaternion": [0.0, 0.0, 0.7071067811865476, 0.7071067811865476]},
        {"id": "pipe", "type": "cylinder", "radius": 0.01, "height": 0.3,
         "position": [-0.1, 0.0, 0.3]},
    ],
}


def bounded(n):
    return settings(max_examples=n * SCALE, deadline=timedelta(seconds=5), derandomize=SCALE == 1,
                    database=None, suppress_health_check=list(HealthCheck))


def reads_or_refuses(d, **kw):
    try:
        return scene_from_dict(d, **kw)
    except InputError as exc:
        text = str(exc)
        assert "\n" not in text and len(text) <= MAX_MESSAGE_CHARS, text
        return exc


def test_a_valid_scene_reads_as_given():
    s = scene_from_dict(VALID)
    assert (s.cable_radius, s.clearance, s.shared_anchor_exemption) == \
        (0.001, 0.002, DEFAULT_EXEMPTION_M)
    assert [o.id for o in s.obstacles] == ["ball", "post", "pipe"]
    post = s.obstacle("post")
    assert np.allclose(post.rotation @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])  # 90 deg about z
    assert s.platform.kind == "box" and s.platform.id == "platform"
    assert post.bounding_radius() == pytest.approx(0.5 * math.sqrt(0.02**2 * 2 + 0.2**2))


def test_the_robot_file_declares_a_cable_radius(config_dir):
    from cdh_planner.model.robot import load_robot, robot_from_dict, FIELDS
    import dataclasses
    robot = load_robot(config_dir / "robot2.yaml")
    assert robot.cable_radius == 0.0
    assert "cable_radius" in [f.key for f in FIELDS]
    assert scene_from_dict({}, robot=dataclasses.replace(robot, cable_radius=0.002)).cable_radius \
        == 0.002
    d = yaml.safe_load((config_dir / "robot2.yaml").read_text())["cdh_planner"]["ros__parameters"]
    d["robot"]["cable_radius"] = -1.0
    with pytest.raises(InputError, match="robot.cable_radius"):
        robot_from_dict(d["robot"])


def test_defaults_come_from_the_robot_then_zero():
    class Robot:
        cable_radius = 0.003

    assert scene_from_dict({}, robot=Robot()).cable_radius == 0.003
    assert scene_from_dict({}).cable_radius == 0.0
    assert scene_from_dict({"cable_radius": 0.0}, robot=Robot()).cable_radius == 0.0
    assert scene_from_dict({}).obstacles == () and scene_from_dict({}).platform is None


@pytest.mark.parametrize("path, value, field", [
    (("cable_radius",), -0.001, "scene.cable_radius"),
    (("cable_radius",), "0.001", "scene.cable_radius"),
    (("clearance",), float("nan"), "scene.clearance"),
    (("colour",), "red", "scene.colour"),
    (("obstacles", 0, "radius"), 0.0, "scene.obstacles[0].radius"),
    (("obstacles", 1, "size"), [0.1, 0.1], "scene.obstacles[1].size"),
    (("obstacles", 1, "size"), [0.1, -0.1, 0.1], "scene.obstacles[1].size[1]"),
    (("obstacles", 1, "quaternion"), [0, 0, 1, 1], "scene.obstacles[1].quaternion"),
    (("obstacles", 2, "type"), "cone", "scene.obstacles[2].type"),
    (("obstacles", 2, "size"), [1, 1, 1], "scene.obstacles[2].size"),
    (("obstacles", 2, "id"), "ball", "scene.obstacles[2].id"),
    (("obstacles", 2, "id"), "", "scene.obstacles[2].id"),
    (("obstacles", 0, "position"), [0, 0, 1e9], "scene.obstacles[0].position[2]"),
    (("platform", "type"), None, "scene.platform.type"),
    (("obstacles",), {"id": "x"}, "scene.obstacles"),
])
def test_bad_fields_are_refused_by_name(path, value, field):
    d = copy.deepcopy(VALID)
    target = d
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value
    with pytest.raises(InputError) as info:
        scene_from_dict(d)
    assert info.value.field == field


def test_a_missing_required_key_and_a_missing_id_are_named():
    d = copy.deepcopy(VALID)
    del d["obstacles"][2]["height"]
    with pytest.raises(InputError, match=r"scene.obstacles\[2\].height"):
        scene_from_dict(d)
    del d["obstacles"][0]["id"]
    with pytest.raises(InputError, match=r"scene.obstacles\[0\].id"):
        scene_from_dict(d)


def test_mesh_files_are_read_by_trimesh_and_bad_ones_refused(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    trimesh.creation.icosphere(radius=0.05).export(tmp_path / "ball.stl")
    (tmp_path / "junk.stl").write_bytes(b"solid x\nfacet nonsense\n")
    d = {"obstacles": [{"id": "m", "type": "mesh", "file": "ball.stl", "scale": 2.0}]}
    s = scene_from_dict(d, base_dir=tmp_path)
    assert np.max(np.linalg.norm(s.obstacles[0].vertices, axis=1)) == pytest.approx(0.1, rel=1e-6)
    for name, reason in (("junk.stl", "not a mesh"), ("none.stl", "cannot read"),
                         (".", "not a regular file")):
        d["obstacles"][0]["file"] = name
        with pytest.raises(InputError, match=reason) as info:
            scene_from_dict(d, base_dir=tmp_path)
        assert info.value.field == "scene.obstacles[0].file"


def test_scene_files_have_a_scene_key(tmp_path):
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump({"scene": VALID}))
    assert len(load_scene(path).obstacles) == 3
    path.write_text(yaml.safe_dump({"obstacles": []}))
    with pytest.raises(InputError, match="obstacles"):
        load_scene(path)


# ----------------------------------------------------------------- hypothesis

SCALARS = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6),
                    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=8))
VALUES = st.recursive(SCALARS, lambda inner: st.one_of(
    st.lists(inner, max_size=5), st.dictionaries(st.text(max_size=8), inner, max_size=5)),
    max_leaves=20)
KEYS = st.sampled_from(["id", "type", "radius", "height", "size", "position", "quaternion",
                        "file", "scale", "cable_radius", "clearance", "platform", "obstacles",
                        "shared_anchor_exemption"])


def _paths(d, prefix=()):
    yield prefix
    if isinstance(d, dict):
        for k, v in d.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(d, list):
        for i, v in enumerate(d):
            yield from _paths(v, prefix + (i,))


@bounded(150)
@given(data=st.data())
def test_mutated_scenes_read_or_are_refused_cleanly(data, tmp_path_factory):
    d = copy.deepcopy(VALID)
    for _ in range(data.draw(st.integers(1, 3))):
        paths = [p for p in _paths(d) if p]
        path = data.draw(st.sampled_from(paths)) if paths else ()
        target = d
        for key in path[:-1]:
            target = target[key]
        action = data.draw(st.sampled_from(["replace", "delete", "add"]))
        if not path:
            break
        if action == "replace":
            target[path[-1]] = data.draw(VALUES)
        elif action == "delete":
            del target[path[-1]]
        elif isinstance(target[path[-1]], dict):
            target[path[-1]][data.draw(KEYS)] = data.draw(VALUES)
    reads_or_refuses(d)


@bounded(100)
@given(d=VALUES)
def test_random_structures_read_or_are_refused_cleanly(d):
    reads_or_refuses(d)
    reads_or_refuses({"obstacles": [d]})
    reads_or_refuses({"platform": d})


@bounded(60)
@given(text=st.text(max_size=200))
def test_random_scene_file_text_reads_or_is_refused_cleanly(text, tmp_path_factory):
    path = tmp_path_factory.mktemp("scene") / "scene.yaml"
    path.write_text(text)
    try:
        load_scene(path)
    except InputError as exc:
        assert "\n" not in str(exc)


@bounded(80)
@given(scene=VALUES)
def test_a_problem_files_scene_reads_or_is_refused_cleanly(scene, tmp_path_factory):
    from cdh_planner.parsing.problem import problem_from_dict
    from conftest import CONFIG, PROBLEMS

    doc = yaml.safe_load((PROBLEMS / "robot2_q2_q3_free_flight.yaml").read_text())
    doc["robot"] = str(CONFIG / "robot2.yaml")
    for value in (scene, {"obstacles": [scene]}, {"platform": scene}):
        doc["scene"] = value
        try:
            problem_from_dict(doc, base_dir=tmp_path_factory.getbasetemp())
        except InputError as exc:
            assert "\n" not in str(exc) and len(str(exc)) <= MAX_MESSAGE_CHARS


def _robot2_with(**platform_shape):
    from conftest import CONFIG
    from cdh_planner import files
    from cdh_planner.model.robot import robot_from_dict
    doc = files.read_yaml(CONFIG / "robot2.yaml", "robot")
    (node,) = doc.values()
    d = copy.deepcopy(node["ros__parameters"]["robot"])
    d["platform_shape"] = platform_shape
    return robot_from_dict(d, source="robot2.yaml")


def test_the_robots_platform_shape_is_the_scenes_default_platform():
    robot = _robot2_with(type="cylinder", size=[0.18, 0.18, 0.01], position=[0, 0, 0.005])
    scene = scene_from_dict({"obstacles": []}, robot=robot)
    p = scene.platform
    assert (p.id, p.kind, p.radius, p.height) == ("platform", "cylinder", 0.09, 0.01)
    assert np.allclose(p.position, [0, 0, 0.005]) and np.allclose(p.rotation, np.eye(3))
    own = scene_from_dict({"platform": VALID["platform"]}, robot=robot).platform
    assert own.kind == "box"                                 # the scene's own wins
    box = scene_from_dict({}, robot=_robot2_with(type="box", size=[0.1, 0.2, 0.01])).platform
    assert np.allclose(box.size, [0.1, 0.2, 0.01])
    assert scene_from_dict({}, robot=_robot2_with(type="none")).platform is None
    # without a scene file, a robot with a platform shape is checked against itself
    from cdh_planner.scene.schema import default_scene
    assert default_scene(_robot2_with(type="none")) is None
    own = default_scene(robot)
    assert own.platform.kind == "cylinder" and own.obstacles == ()


def test_a_platform_shape_parameter_gives_the_nodes_scene_without_a_scene_file():
    from conftest import CONFIG
    from cdh_planner.ros.core import params
    from ros_harness import file_parameters
    values = dict(file_parameters(CONFIG / "robot2.yaml"),
                  **{"robot.platform_shape.type": "box",
                     "robot.platform_shape.size": [0.12, 0.12, 0.01]})
    scene = params.node_config(values).scene
    assert scene.platform.kind == "box" and np.allclose(scene.platform.size, [0.12, 0.12, 0.01])
    with pytest.raises(InputError) as info:
        params.node_config(dict(values, **{"robot.platform_shape.size": [0.1, 0.2, 0.01],
                                           "robot.platform_shape.type": "cylinder"}))
    assert info.value.field == "robot.platform_shape.size"


@pytest.mark.parametrize("shape,field", [
    ({"type": "box"}, "robot.platform_shape.size"),
    ({"type": "cylinder", "size": [0.1, 0.2, 0.01]}, "robot.platform_shape.size"),
    ({"type": "sphere", "size": [0.1, 0.1, 0.2]}, "robot.platform_shape.size"),
    ({"type": "cone", "size": [0.1, 0.1, 0.1]}, "robot.platform_shape.type"),
    ({"type": "box", "size": [0.1, 0.0, 0.1]}, "robot.platform_shape.size[1]"),
])
def test_a_bad_platform_shape_is_refused_naming_the_field(shape, field):
    with pytest.raises(InputError) as info:
        _robot2_with(**shape)
    assert info.value.field == field, str(info.value)


@pytest.mark.parametrize("text, held", [("", "the file is empty"), ("# nothing\n", "the file is empty"),
                                        ("[1, 2]\n", "the file holds a list")])
def test_an_empty_or_listed_scene_file_is_refused_naming_the_file(tmp_path, capsys, text, held):
    """verify --scene, a problem's ``scene:``, and the loader the node's scene_file uses:
    the error names the field and the file (before: ``= None: expected a mapping``)."""
    from cdh_planner import cli
    from cdh_planner.parsing.problem import load_problem
    from conftest import CONFIG
    path = tmp_path / "empty.yaml"
    path.write_text(text)
    with pytest.raises(InputError) as err:
        load_scene(path)
    assert str(err.value).startswith(f"scene = '{path}': {held}; expected a mapping with 'scene:'")
    problem = tmp_path / "problem.yaml"
    problem.write_text((CONFIG / "problems" / "robot2_q2_q3.yaml").read_text()
                       .replace("robot: ../robot2.yaml", f"robot: {CONFIG / 'robot2.yaml'}")
                       + f"scene: {path.name}\n")
    with pytest.raises(InputError, match=f"scene = '{path}': {held}"):
        load_problem(problem)
    poses = tmp_path / "poses.json"
    poses.write_text('[{"position": [0, 0, 0.2], "tau": [0, 0, 0]}]')
    assert cli.main(["verify", str(CONFIG / "robot2.yaml"), str(poses), "--scene",
                     str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"scene = '{path}': {held}" in err, err


def test_ten_thousand_obstacles_are_refused_by_the_obstacle_bound(tmp_path):
    """A scene file of 10,000 obstacles: the error says a scene has at most 1000 obstacles
    (before: the generic 'more than 100000 values' of any YAML file)."""
    from cdh_planner.scene.schema import MAX_OBSTACLES
    path = tmp_path / "many.yaml"
    items = [{"id": f"b{k}", "type": "sphere", "radius": 0.01, "position": [0.0, 0.0, 0.1]}
             for k in range(10_000)]
    path.write_text(yaml.safe_dump({"scene": {"obstacles": items}}))
    with pytest.raises(InputError) as err:
        load_scene(path)
    assert f"at most {MAX_OBSTACLES} obstacles" in str(err.value), err.value
    assert str(err.value).startswith(f"scene = '{path}'")
    path.write_text(yaml.safe_dump({"scene": {"obstacles": items[:MAX_OBSTACLES]}}))
    assert len(load_scene(path).obstacles) == MAX_OBSTACLES
