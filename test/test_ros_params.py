"""The node's parameters, request reading and streaming without a ROS graph: the robot file
read as ROS parameters gives the same robot and task as the offline reader; bad values are
refused naming the parameter; the stream samples the trajectory in time and holds."""

import math
from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("nav_msgs")

from nav_msgs.srv import GetPlan  # noqa: E402

from cdh_planner.commands.slice import task_in_yaml  # noqa: E402
from cdh_planner.errors import InputError  # noqa: E402
from cdh_planner.fields import REQUIRED  # noqa: E402
from cdh_planner.wrench import wrench_feasibility  # noqa: E402
from cdh_planner.model.pose import quaternion_from_tau  # noqa: E402
from cdh_planner.model.robot import load_robot  # noqa: E402
from cdh_planner.model.task import PivotTask, SliceTask  # noqa: E402
from cdh_planner.ros.core import plan_requests  # noqa: E402
from cdh_planner.model import robot_schema  # noqa: E402
from cdh_planner.model.robot import FIELDS as ROBOT_FIELDS, OPTIONAL_GROUPS  # noqa: E402
from cdh_planner.ros.core import params  # noqa: E402
from cdh_planner.ros.core.params import SPEC, SPECS, node_config  # noqa: E402
from cdh_planner.ros.core.streaming import Stream  # noqa: E402
from cdh_planner.status import Status  # noqa: E402
from cdh_planner.trajectory.path import PlannedPath  # noqa: E402
from cdh_planner.trajectory.timing import time_path  # noqa: E402
from ros_harness import Q1, Q2, REPO, ROBOT2, file_parameters, sphere_pose_msg  # noqa: E402


ROBOT2_PARAMS = file_parameters(ROBOT2)


@pytest.mark.parametrize("name", ["robot1.yaml", "robot2.yaml"])
def test_robot_file_as_parameters_is_the_offline_robot(name):
    path = REPO / "config" / name
    config = node_config(file_parameters(path))
    offline = load_robot(path)
    for field in ("winch_names", "base_anchors", "platform_anchors", "length_min", "length_max",
                  "tension_min", "tension_max", "force", "load_point", "moment",
                  "ellipsoid_offset", "ellipsoid_matrix", "ellipsoid_frame", "name"):
        np.testing.assert_array_equal(getattr(config.robot, field), getattr(offline, field))


def test_robot2_task_and_defaults():
    config = node_config(ROBOT2_PARAMS)
    assert config.task == task_in_yaml(ROBOT2)
    assert config.base_frame == "cdh_base"
    assert config.settings.strategy == "auto" and config.stream_rate_hz == 50.0


def test_pivot_task_from_parameters():
    values = dict(ROBOT2_PARAMS, **{"task.type": "pivot", "task.tool": [0.0, 0.0, 0.1],
                                    "task.center": [0, 0, 0.35]})
    assert node_config(values).task == PivotTask(tool=(0.0, 0.0, 0.1), center=(0.0, 0.0, 0.35))
    assert "platform frame" in SPEC["task.tool"].description
    with pytest.raises(InputError, match=r"task.tool = \[0.0, 0.1\]: expected 3 numbers"):
        node_config(dict(values, **{"task.tool": [0.0, 0.1]}))


def test_every_parameter_has_a_description_and_architecture_names_exist():
    names = {s.name for s in SPECS}
    for required in ("base_frame", "task.type", "task.center", "task.radius", "task.free_torsion",
                     "planner.strategy", "planner.timeout_s", "stream_rate_hz", "log_dir",
                     *(f"task.fixed.{n}" for n in ("x", "y", "z", "phi", "theta", "sigma"))):
        assert required in names
    assert all(s.description for s in SPECS)


def test_slice_from_fixed_coordinates_nan_is_free():
    values = dict(ROBOT2_PARAMS, **{"task.type": "slice", "task.fixed.x": 0.0,
                                    "task.fixed.y": 0, "task.fixed.z": 0.35,
                                    "task.fixed.sigma": 0.5})
    task = node_config(values).task
    assert task == SliceTask(fixed={"x": 0.0, "y": 0.0, "z": 0.35, "sigma": 0.5})
    assert task.names == ("phi", "theta")


def test_integers_are_accepted_for_numbers():
    config = node_config(dict(ROBOT2_PARAMS, **{"planner.timeout_s": 5, "task.center": [0, 0, 1]}))
    assert config.settings.timeout_s == 5.0 and config.task.center == (0.0, 0.0, 1.0)


@pytest.mark.parametrize("name,value,message", [
    ("robot.base_anchors", None, "robot.base_anchors = None: required parameter is not set"),
    ("robot.length_min", [0.2] * 5, "robot.length_min"),
    ("robot.winch_names", ["a"] * 6, "robot.winch_names"),
    ("robot.winch_names", 0.0, "robot.winch_names = 0.0: expected a list of strings"),
    ("robot.winch_names", ["w1", "w2"], "robot.winch_names = ['w1', 'w2']: expected 6 to 16 distinct"),
    ("robot.wrench_ellipsoid.frame", "world", "robot.wrench_ellipsoid.frame = 'world'"),
    ("task.type", "cube", "task.type = 'cube': expected one of free, slice, sphere, pivot"),
    ("task.radius", 0.0, "task.radius = 0.0: must be positive"),
    ("task.center", [0.0, 1.0], "task.center"),
    ("task.fixed.x", math.inf, "task.fixed.x = inf: expected a finite number"),
    ("planner.strategy", "bfs", "planner.strategy = 'bfs'"),
    ("planner.max_charts", 2.5, "planner.max_charts = 2.5: expected an integer"),
    ("planner.timeout_s", "long", "planner.timeout_s = 'long': expected a number"),
    ("stream_rate_hz", 0.5, "stream_rate_hz = 0.5: must be >= 1"),
    ("trajectory.max_cable_speed", -1.0, "trajectory.max_cable_speed"),
    ("base_frame", "", "base_frame = '': must not be empty"),
    ("base_frame", "bad frame!", "base_frame = 'bad frame!': not a TF frame id"),
    ("fixed_frame", "/world", "fixed_frame = '/world': not a TF frame id"),
    ("platform_frame", "1platform", "platform_frame = '1platform': not a TF frame id"),
    ("log_enabled", "yes", "log_enabled = 'yes': expected true or false"),
    ("planner.cost", "euclid", "planner.cost = 'euclid': expected one of auto, so3"),
    ("planner.cost", "so3", "planner.cost = 'so3': not a cost of the sphere task"),
    ("planner.margin_floor", 0.0, "planner.margin_floor = 0.0: must be > 0"),
    ("planner.margin_floor", 1.0, "planner.margin_floor = 1.0: must be < 1"),
    ("planner.max_charts", 1, "planner.max_charts = 1: must be >= 2"),
    ("execution.mode", "topic", "execution.mode = 'topic': expected one of stream, "
                                "forward_command, follow_joint_trajectory"),
    ("execution.joint_states_topic", "bad name", "execution.joint_states_topic = 'bad name': "
                                                 "not a ROS name"),
    ("execution.controller_action", "/1abc/follow", "execution.controller_action = "
                                                    "'/1abc/follow': not a ROS name"),
    ("execution.controller_action", "", "execution.controller_action = '': must not be empty"),
    ("execution.start_tolerance", 0.0, "execution.start_tolerance = 0.0: must be > 0"),
])
def test_bad_values_name_parameter_and_value(name, value, message):
    with pytest.raises(InputError) as err:
        node_config(dict(ROBOT2_PARAMS, **{name: value}))
    assert message in str(err.value)


def test_parameters_map_onto_the_planner_settings():
    """Every planner.* / trajectory.* parameter reaches its PlannerSettings field, and the
    settings the node builds are accepted by the Planner itself."""
    from cdh_planner.planner import Planner, PlannerSettings
    values = {"planner.strategy": "gbf", "planner.cost": "great_circle",
              "planner.radius": 0.15, "planner.timeout_s": 7, "planner.max_charts": 500,
              "planner.complete": True, "planner.margin_floor": 0.01,
              "trajectory.max_cable_speed": 0.02, "trajectory.max_cable_accel": 0.1}
    config = node_config(dict(ROBOT2_PARAMS, **values))
    assert config.settings == PlannerSettings(
        strategy="gbf", cost="great_circle", radius=0.15, timeout_s=7.0, max_charts=500,
        complete=True, margin_floor=0.01, max_cable_speed=0.02, max_cable_accel=0.1)
    Planner(config.robot, config.task, config.settings)   # no InputError
    assert node_config(ROBOT2_PARAMS).settings == PlannerSettings()   # same defaults


def test_settings_errors_name_the_node_parameter():
    from cdh_planner.ros.core.params import parameter_error
    err = parameter_error(InputError("max_cable_speed", 0.0, "must be positive"))
    assert str(err) == "trajectory.max_cable_speed = 0.0: must be positive"
    assert str(parameter_error(InputError("radius", -1.0, "x"))).startswith("planner.radius")


def test_a_parameter_set_to_its_value_keeps_the_planner():
    from cdh_planner.ros.core.params import needs_new_planner
    old = node_config(ROBOT2_PARAMS).values
    same = node_config(dict(ROBOT2_PARAMS, **{"planner.timeout_s": 60})).values
    assert not needs_new_planner(["planner.timeout_s"], old, same)
    assert not needs_new_planner(["task.fixed.x"], old, old)            # NaN == NaN here
    assert not needs_new_planner(["stream_rate_hz", "log_dir"])
    changed = node_config(dict(ROBOT2_PARAMS, **{"planner.timeout_s": 5.0})).values
    assert needs_new_planner(["planner.timeout_s"], old, changed)
    assert needs_new_planner(["robot.length_min"])                      # no values: assume so


# --------------------------------------------------------------------------- requests

def test_request_poses_take_the_azimuth_of_the_other_pose_at_the_pole():
    config = node_config(ROBOT2_PARAMS)
    request = GetPlan.Request(start=sphere_pose_msg(Q1), goal=sphere_pose_msg(Q2))
    start, goal = plan_requests.request_poses(request, "cdh_base")
    np.testing.assert_allclose(config.task.coords(start.p[None], start.tau[None]),
                               [[0.55, math.pi / 2]], atol=1e-9)
    np.testing.assert_allclose(config.task.coords(goal.p[None], goal.tau[None]), [Q2],
                               atol=1e-9)


def test_refusal_reasons_and_codes():
    request = GetPlan.Request(start=sphere_pose_msg(Q1, frame="map"), goal=sphere_pose_msg(Q2))
    with pytest.raises(InputError) as err:
        plan_requests.request_poses(request, "cdh_base")
    result = plan_requests.input_refusal(err.value)
    assert result.reason is Status.BAD_FRAME and result.reason == "bad_frame"
    assert not result.success
    robot = load_robot(ROBOT2)
    status = plan_requests.result_status(result, robot, "r#1", "", sphere_pose_msg(Q1).header.stamp)
    values = {kv.key: kv.value for kv in status.values}
    assert values["error_code"] == "202" and "map" in values["error_msg"]
    assert values["path_stamp"] == "0"


@pytest.mark.parametrize("fault, reason, code", [
    (None, None, None), ("frame", Status.BAD_FRAME, 202), ("strategy", Status.BAD_STRATEGY, 201),
    ("timeout", Status.INVALID, 292), ("nan", Status.INVALID, 292)])
def test_a_goals_own_faults_are_refused_with_their_member(fault, reason, code):
    from cdh_planner.ros.client import plan_path_goal
    from cdh_planner.ros.msgs import messages as M
    goal = plan_path_goal(None, sphere_pose_msg(Q2, frame="map" if fault == "frame"
                                                else "cdh_base"), use_current_start=True)
    goal.strategy = "dijkstra" if fault == "strategy" else ""
    goal.timeout_s = -1.0 if fault == "timeout" else 0.0
    goal.goal.pose.position.x = math.nan if fault == "nan" else goal.goal.pose.position.x
    refused = plan_requests.goal_refusal(goal, "cdh_base", "astar")
    if fault is None:
        assert refused is None
    else:
        assert refused.reason is reason and M.error_code(refused.reason) == code
        assert refused.message.startswith("invalid request: ") and refused.strategy == "astar"


class Exploding:
    settings = type("S", (), {"strategy": "astar"})

    def plan(self, start, goal, progress=None, **kwargs):
        raise ZeroDivisionError("boom")


def test_planner_exception_becomes_an_answer():
    lines = []
    result = plan_requests.run_planner(Exploding(), None, None, logger=lines.append)
    assert not result.success and result.reason is Status.INTERNAL_ERROR
    assert result.reason == "internal_error"
    assert "ZeroDivisionError: boom" in result.message and "Traceback" in lines[0]


# --------------------------------------------------------------------------- streaming

def _path():
    robot = load_robot(ROBOT2)
    task = task_in_yaml(ROBOT2)
    y = np.array(Q1) + np.linspace(0, 1, 20)[:, None] * (np.array(Q2) - np.array(Q1))
    p, tau = task.pose(y)
    f = wrench_feasibility(robot, p, tau)
    z = np.zeros((20, 6))
    path = PlannedPath(p=p, quaternion=quaternion_from_tau(tau), tau=tau, lengths=f.lengths,
                       tension_min=f.tension_min, tension_nominal=f.tension_nominal,
                       tension_max=f.tension_max, margin=f.margin, t=np.zeros(20),
                       velocities=z, accelerations=z)
    return robot, time_path(path, 0.05, 0.2)


def test_stream_samples_in_time_finishes_and_holds():
    robot, path = _path()
    stamp = sphere_pose_msg(Q1).header.stamp
    stream = Stream(path, robot.winch_names, "linear", start=100.0)
    first, done = stream.command(100.0, stamp)
    assert not done
    np.testing.assert_array_equal(first.position, path.lengths[0])
    mid, done = stream.command(100.0 + path.t[5], stamp)
    np.testing.assert_allclose(mid.position, path.lengths[5], atol=1e-12)
    held = stream.hold(stamp)
    np.testing.assert_array_equal(held.position, mid.position)
    assert np.all(np.asarray(held.velocity) == 0)
    last, done = stream.command(100.0 + path.t[-1] + 1.0, stamp)
    assert done and np.all(np.asarray(last.velocity) == 0)
    np.testing.assert_array_equal(last.position, path.lengths[-1])
    assert list(last.name) == list(robot.winch_names)


def test_stream_refuses_wrong_joint_names():
    robot, path = _path()
    with pytest.raises(InputError):
        Stream(replace(path), ["a", "b"])


def test_the_parameter_table_in_the_docs_is_generated_from_the_specs():
    text = (REPO / "docs" / "parameters.md").read_text()
    assert text == params.parameters_markdown(), \
        "docs/parameters.md is stale: python -m cdh_planner.ros.core.params > docs/parameters.md"
    assert all(f"| `{s.name}` |" in text for s in SPECS)


def test_robot_parameters_are_the_declared_robot_fields():
    """robot.* is exactly Robot's declaration: one parameter per field, required where the
    file must give it (the contact ellipsoid's matrix: only with its group, so optional)."""
    assert [s.name for s in SPECS if s.name.startswith("robot.")] == \
        [f"robot.{f.key}" for f in ROBOT_FIELDS]
    for f in ROBOT_FIELDS:
        spec = SPEC[f"robot.{f.key}"]
        required = f.default is REQUIRED and f.group not in OPTIONAL_GROUPS
        assert (spec.default is params.REQUIRED) == required, f.key
        assert spec.choices == f.choices and robot_schema.describe(f) == spec.description


def test_contact_ellipsoid_as_parameters_is_the_file_robot(tmp_path):
    import yaml
    doc = yaml.safe_load((REPO / "config" / "robot2.yaml").read_text())
    robot = doc["cdh_planner"]["ros__parameters"]["robot"]
    robot["contact_ellipsoid"] = {"matrix": [2e4, 2e4, 2e4, 3e10, 3e10, 3e10],
                                  "center": [0.0, 0.0, 1.0, 0.0, 0.0, 0.0]}
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(doc))
    offline, node = load_robot(path), node_config(file_parameters(path)).robot
    for name in ("ellipsoid_matrix", "ellipsoid_offset", "contact_matrix", "contact_center"):
        np.testing.assert_array_equal(getattr(node, name), getattr(offline, name))
    assert not np.allclose(offline.ellipsoid_matrix, load_robot(REPO / "config" / "robot2.yaml")
                           .ellipsoid_matrix)
    values = dict(file_parameters(path), **{"robot.contact_ellipsoid.matrix": None})
    assert node_config(values).robot.contact_matrix is None  # center alone: no contact ellipsoid
