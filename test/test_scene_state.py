"""The node's scene without ROS: obstacle messages <-> scene shapes
(the scene file's fields, a mesh as its convex hull), the version counter, refusals named
item by item, and a planner made for each scene a plan is made under (PlanService)."""

import math

import numpy as np
import pytest
from geometry_msgs.msg import Point
from shape_msgs.msg import MeshTriangle, SolidPrimitive

from cdh_planner.errors import InputError
from cdh_planner.ros.core import params
from cdh_planner.ros.msgs.scene_msgs import obstacle_msg, same, scene_change, scene_msg, \
    shape_of_obstacle
from cdh_planner.ros.core.scene_state import SceneState
from cdh_planner.scene.schema import scene_from_dict
from cdh_planner_interfaces.msg import Obstacle, ObstacleArray

from conftest import CONFIG
from ros_harness import file_parameters

FRAME = "cdh_base"


def sphere(oid, r=0.01, xyz=(0.0, 0.05, 0.2), op=Obstacle.ADD):
    msg = Obstacle(id=oid, operation=op,
                   primitive=SolidPrimitive(type=SolidPrimitive.SPHERE, dimensions=[r]))
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = xyz
    msg.pose.orientation.w = 1.0
    return msg


def array(*items, frame=FRAME):
    out = ObstacleArray(obstacles=list(items))
    out.header.frame_id = frame
    return out


def config(**values):
    return params.node_config(dict(file_parameters(CONFIG / "robot2.yaml"), **values))


def test_primitives_and_meshes_become_the_scene_files_shapes_and_back():
    box = Obstacle(id="post", primitive=SolidPrimitive(type=SolidPrimitive.BOX,
                                                       dimensions=[0.1, 0.2, 0.3]))
    c, s = math.cos(0.3), math.sin(0.3)
    box.pose.orientation.z, box.pose.orientation.w = s, c
    cyl = Obstacle(id="pipe", primitive=SolidPrimitive(type=SolidPrimitive.CYLINDER,
                                                       dimensions=[0.4, 0.02]))
    cyl.pose.orientation.w = 1.0
    shape = shape_of_obstacle(box, "o")
    assert shape.kind == "box" and np.allclose(shape.size, [0.1, 0.2, 0.3])
    assert np.allclose(shape.rotation[:2, :2], [[c * c - s * s, -2 * s * c], [2 * s * c, c * c - s * s]])
    pipe = shape_of_obstacle(cyl, "o")   # CYLINDER_HEIGHT = 0, CYLINDER_RADIUS = 1
    assert (pipe.height, pipe.radius) == (0.4, 0.02)
    # a mesh: a cube's 8 corners plus an inner point: the hull's 8 corners
    tet = Obstacle(id="cube")
    tet.pose.orientation.w = 1.0
    corners = [(x, y, z) for x in (0, 0.1) for y in (0, 0.1) for z in (0, 0.1)]
    tet.mesh.vertices = [Point(x=float(x), y=float(y), z=float(z))
                         for x, y, z in corners + [(0.05, 0.05, 0.05)]]
    tet.mesh.triangles = [MeshTriangle(vertex_indices=[0, 1, 2])]
    cube = shape_of_obstacle(tet, "o")
    assert cube.kind == "mesh" and len(cube.vertices) == 8
    for msg in (box, cyl, sphere("ball")):
        back = obstacle_msg(shape_of_obstacle(msg, "o"))
        assert back.primitive == msg.primitive and same(back, msg)
    assert not same(obstacle_msg(pipe), obstacle_msg(shape_of_obstacle(box, "o")))
    again = obstacle_msg(shape_of_obstacle(obstacle_msg(cube), "o"))
    assert same(again, obstacle_msg(cube)) and len(again.mesh.triangles) == 12


@pytest.mark.parametrize("change,field", [
    (lambda m: setattr(m.primitive, "dimensions", [0.0]), "o.primitive.radius"),
    (lambda m: setattr(m.primitive, "dimensions", [0.1, 0.1]), "o.primitive.dimensions"),
    (lambda m: setattr(m.primitive, "type", SolidPrimitive.CONE), "o.primitive.type"),
    (lambda m: setattr(m.pose.orientation, "w", 2.0), "o.pose.orientation"),
    (lambda m: setattr(m.pose.position, "x", math.nan), "o.pose.position[0]"),
    (lambda m: setattr(m, "id", "platform"), "o.id"),
    (lambda m: setattr(m.mesh, "vertices", [Point(), Point(x=1.0)]), "o"),   # both shapes
])
def test_a_bad_obstacle_is_refused_naming_the_field(change, field):
    msg = sphere("ball")
    change(msg)
    with pytest.raises(InputError) as info:
        shape_of_obstacle(msg, "o")
    assert info.value.field == field


def test_versions_count_updates_and_refusals_are_named_item_by_item():
    state = SceneState()
    state.configure(config())
    assert state.current().version == 0 and state.current().scene is None
    up = state.update(array(sphere("a"), sphere("b", r=-1.0), sphere("c")), FRAME)
    assert up.version == 1 and up.taken == ("add a", "add c")
    assert len(up.refused) == 1 and up.refused[0].startswith("obstacles[1] (b): ")
    assert "radius" in up.refused[0]
    scene = state.current().scene
    assert [o.id for o in scene.obstacles] == ["a", "c"]
    assert scene.cable_radius == 0.0 and scene.clearance == 0.0   # the robot's defaults
    up = state.update(array(sphere("zz", op=Obstacle.REMOVE)), FRAME)
    assert up.version == 1 and not up.taken and "no obstacle of this id" in up.refused[0]
    up = state.update(array(sphere("a", op=Obstacle.REMOVE), sphere("c", r=0.02)), FRAME)
    assert up.version == 2 and up.taken == ("remove a", "replace c")
    assert [(o.id, o.radius) for o in state.current().scene.obstacles] == [("c", 0.02)]
    wrong = state.update(array(sphere("d"), frame="world"), FRAME)
    assert wrong.version == 2 and "header.frame_id 'world'" in wrong.refused[0]


def test_parameters_keep_the_obstacles_and_a_new_scene_file_replaces_them(tmp_path):
    f = tmp_path / "scene.yaml"
    f.write_text("scene:\n  cable_radius: 0.002\n  obstacles:\n"
                 "    - {id: post, type: box, size: [0.1, 0.1, 0.1], position: [0, 0, 0.5]}\n")
    state = SceneState()
    state.configure(config())
    state.update(array(sphere("a")), FRAME)
    same = state.current()
    assert state.configure(config(**{"log_enabled": False})) is same   # not a scene change
    with_file = config(scene_file=str(f))
    preview = state.effective(with_file)
    now = state.configure(with_file)
    assert now.scene is preview and now.version == 2
    assert [o.id for o in now.scene.obstacles] == ["post"] and now.scene.cable_radius == 0.002
    state.update(array(sphere("a")), FRAME)
    robot = config(scene_file=str(f), **{"robot.cable_radius": 0.003})
    kept = state.configure(robot).scene
    assert [o.id for o in kept.obstacles] == ["post", "a"] and kept.cable_radius == 0.002


def test_the_scene_message_and_the_change_that_reaches_another():
    scene = scene_from_dict({"cable_radius": 0.001, "obstacles": [
        {"id": "a", "type": "sphere", "radius": 0.01},
        {"id": "b", "type": "box", "size": [0.1, 0.1, 0.1]}]})
    msg = scene_msg(4, scene, FRAME)
    assert (msg.version, msg.checked, msg.cable_radius) == (4, True, 0.001)
    assert [o.id for o in msg.obstacles] == ["a", "b"] and not msg.platform
    assert not scene_msg(0, None, FRAME).checked
    other = scene_from_dict({"obstacles": [{"id": "b", "type": "box", "size": [0.1, 0.1, 0.2]},
                                           {"id": "c", "type": "sphere", "radius": 0.01}]})
    change = scene_change(msg, scene_msg(5, other, FRAME))
    assert [(o.id, o.operation) for o in change.obstacles] == [
        ("a", Obstacle.REMOVE), ("b", Obstacle.ADD), ("c", Obstacle.ADD)]
    state = SceneState()
    state.configure(config())
    state.update(array(*[o for o in msg.obstacles]), FRAME)
    state.update(change, FRAME)
    assert scene_change(scene_msg(0, state.current().scene, FRAME),
                        scene_msg(5, other, FRAME)).obstacles == []


def test_a_planner_is_made_for_each_scene_a_plan_is_made_under():
    """PlanService: a call carries the scene of its arrival; the planner in force serves it
    if it was made for that scene, else make_planner makes one (and it stays)."""
    from cdh_planner.ros.core.plan_service import PlanService
    from cdh_planner.ros.core.scene_state import SceneVersion

    class Planner:
        def __init__(self, scene):
            self.scene = scene

    made = []
    plans = PlanService(config(), Planner(None), outlet=None,
                        make_planner=lambda cfg, scene: made.append(scene) or Planner(scene))

    class Call:
        scene = None

    call, cfg = Call(), plans.config
    assert plans._for_scene(call, cfg, plans._planner)[0].scene is None and not made
    s1 = scene_from_dict({})
    call.scene = SceneVersion(1, s1)
    planner, scene = plans._for_scene(call, cfg, plans._planner)
    assert scene is s1 and planner.scene is s1 and made == [s1] and plans._planner is planner
    assert plans._for_scene(call, cfg, plans._planner)[0] is planner and made == [s1]
    ball = {"obstacles": [{"id": "ball", "type": "sphere", "radius": 0.01, "position": [0, 0, 0.2]}]}
    call.scene = SceneVersion(2, scene_from_dict(ball))
    with_ball = plans._for_scene(call, cfg, plans._planner)[0]
    assert with_ball is not planner and len(made) == 2
    call.scene = SceneVersion(3, scene_from_dict({}))   # the ball removed: s1's geometry again
    assert plans._for_scene(call, cfg, plans._planner)[0] is not with_ball and len(made) == 3
    call.scene = SceneVersion(4, scene_from_dict({}))   # another version, the same geometry
    assert len(made) == 3 and plans._for_scene(call, cfg, plans._planner)[0] is plans._planner
    assert len(made) == 3


def test_same_geometry_is_the_shapes_and_distances_not_the_objects():
    one = {"cable_radius": 0.001, "obstacles": [
        {"id": "post", "type": "box", "size": [0.01, 0.02, 0.03], "position": [0, 0.1, 0.2],
         "quaternion": [0, 0, 0, 1]}]}
    assert scene_from_dict(one).same_geometry(scene_from_dict(one, source="elsewhere.yaml"))
    moved = {**one, "obstacles": [{**one["obstacles"][0], "position": [0, 0.1, 0.2001]}]}
    assert not scene_from_dict(one).same_geometry(scene_from_dict(moved))
    assert not scene_from_dict(one).same_geometry(scene_from_dict({**one, "cable_radius": 0.002}))
    assert not scene_from_dict(one).same_geometry(scene_from_dict({}))
    assert not scene_from_dict(one).same_geometry(None)


# ----------------------------------------------------------------- hypothesis

from datetime import timedelta  # noqa: E402

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

NUMBERS = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                    st.sampled_from([0.0, -0.01, 0.01, 1e-9, 2e3, 1.0]))


@st.composite
def obstacles(draw):
    msg = Obstacle(id=draw(st.sampled_from(["a", "b", "", "platform", "x" * 70])),
                   operation=draw(st.integers(0, 3)))
    msg.primitive.type = draw(st.integers(0, 6))
    msg.primitive.dimensions = draw(st.lists(NUMBERS, max_size=3))
    if draw(st.booleans()):
        msg.mesh.vertices = [Point(x=draw(NUMBERS), y=draw(NUMBERS), z=draw(NUMBERS))
                             for _ in range(draw(st.integers(0, 6)))]
    for k in "xyz":
        setattr(msg.pose.position, k, draw(NUMBERS))
    for k in "xyzw":
        setattr(msg.pose.orientation, k, draw(st.sampled_from([0.0, 1.0, 0.5, math.nan])))
    return msg


@settings(max_examples=150, deadline=timedelta(seconds=5), derandomize=True, database=None,
          suppress_health_check=list(HealthCheck))
@given(items=st.lists(obstacles(), max_size=5), frame=st.sampled_from([FRAME, "", "world"]))
def test_any_obstacle_array_is_taken_or_refused_item_by_item_never_raising(items, frame):
    """Random ObstacleArrays: every item is taken or refused with a one-line reason naming
    it; the scene holds exactly the ids taken, and the version counts the updates."""
    state = SceneState()
    state.configure(config())
    up = state.update(array(*items, frame=frame), FRAME)
    assert len(up.taken) + len(up.refused) == (len(items) if frame == FRAME else 1)
    assert all("\n" not in r for r in up.refused)
    assert up.version == (1 if up.taken else 0)
    scene = state.current().scene
    ids = [] if scene is None else [o.id for o in scene.obstacles]
    assert len(ids) == len(set(ids)) and all(0 < len(i) <= 64 and i != "platform" for i in ids)
