"""Tasks as plug-ins (model/task.py): each registered task's equations against finite
differences and its own pose map, the registry reaching problem files and node parameters,
a new task as one class, and the pivot task (p + R t = c) end to end: plan, slice, refusals
and the node."""

import json
import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pytest

from conftest import CONFIG, PROBLEMS
from cdh_planner.cli import main
from cdh_planner.fields import NUMBERS
from cdh_planner.errors import InputError
from cdh_planner.parsing.problem import load_problem
from cdh_planner.manifold.constraint import TaskConstraint
from cdh_planner.model import task as T
from cdh_planner.model.pose import rotation_tt
from cdh_planner.model.robot import load_robot
from cdh_planner.planner import Planner, task_cost
from cdh_planner.trajectory.path_check import check_motion

ROBOT2 = load_robot(CONFIG / "robot2.yaml")
PIVOT = T.PivotTask(tool=(0.0, 0.0, 0.1), center=(0.0, 0.0, 0.35))
PIVOT_FILE = PROBLEMS / "robot2_pivot.yaml"
# the contract tests run over the registry: each task's own example(), and a variant the
# examples do not cover
VARIANTS = {"sphere-fixed-torsion": T.SphereTask(center=(0.0, 0.0, 0.306), radius=0.13)}
TASKS = {**{name: cls.example() for name, cls in T.TASKS.items()}, **VARIANTS}


def _y(task, rng):
    """Random task coordinates inside the coordinates' bounds (x, y, z in [-0.3, 0.3] m)."""
    cols = []
    for name in task.names:
        lo, hi = T.COORDINATES[name].bounds or (-0.3, 0.3)
        cols.append(rng.uniform(lo + 0.1, hi - 0.1))
    return np.array(cols)


def test_every_registered_task_has_an_example_of_its_own():
    assert {"free", "slice", "sphere", "pivot"} <= set(T.TASKS)
    for name, cls in T.TASKS.items():
        task = cls.example()
        assert type(task) is cls and task.type == name
        assert len(task.names) == 6 + task.n_vars - task.n_equations


@pytest.mark.parametrize("name", TASKS)
def test_equations_vanish_on_the_task_and_match_finite_differences(name):
    check_task_contract(TASKS[name])


def check_task_contract(task):
    """C = 0 and residual 0 on the task, pose and coords inverse maps, dC/d(q, v) equal to
    central differences off the task (5 random task coordinates)."""
    rng, name = np.random.default_rng(3), task.type
    for _ in range(5):
        y = _y(task, rng)
        p, tau = task.pose(y[None])
        q = np.concatenate([p[0], tau[0]])
        v = task.variables(p, tau)[0]
        C, J = task.equations(q, v)
        assert C.shape == (task.n_equations,) == (len(task.length_rows),)
        assert J.shape == (task.n_equations, 6 + task.n_vars)
        assert np.allclose(C, 0.0, atol=1e-12) and task.residual(p, tau)[0] < 1e-12
        assert np.allclose(task.coords(p, tau)[0], y, atol=1e-12)  # pose and coords invert
        qv = np.concatenate([q, v]) + 0.01 * rng.standard_normal(6 + task.n_vars)  # off the task
        h, J0 = 1e-6, task.equations(qv[:6], qv[6:])[1]
        fd = np.array([(task.equations(*_split(qv + h * e))[0] - task.equations(*_split(qv - h * e))[0])
                       / (2 * h) for e in np.eye(6 + task.n_vars)]).T
        assert np.allclose(fd, J0, atol=1e-7), name


def _split(qv):
    return qv[:6], qv[6:]


@pytest.mark.parametrize("name", TASKS)
def test_constraint_dimension_is_six_minus_the_task_equations(name):
    task = TASKS[name]
    c = TaskConstraint(ROBOT2, task)
    assert c.dim == 6 + task.n_vars - task.n_equations == len(task.names)


def test_pivot_keeps_the_tool_point_at_the_centre():
    y = np.array([[0.3, 0.4, -0.2], [2.9, 1.1, 3.0]])
    p, tau = PIVOT.pose(y)
    tip = p + rotation_tt(tau) @ np.array(PIVOT.tool)
    assert np.allclose(tip, PIVOT.center, atol=1e-15)
    assert PIVOT.residual(p + [0.0, 0.002, 0.0], tau) == pytest.approx([0.002, 0.002])
    assert PIVOT.periodic == (True, False, True)
    assert task_cost(ROBOT2, PIVOT)(p[0], tau[0], p[1], tau[1]) > 0  # auto: so3
    with pytest.raises(InputError, match="not a cost of the pivot task"):
        task_cost(ROBOT2, PIVOT, "great_circle")


@pytest.mark.parametrize("doc,field", [
    ({"type": "pivot", "tool": [0.0, 0.1]}, "task.tool"),
    ({"type": "pivot", "tool": [0.0, 0.0, math.inf]}, "task.tool[2]"),
    ({"type": "pivot", "center": "origin"}, "task.center"),
    ({"type": "pivot", "radius": 0.1}, "task.radius"),
    ({"type": "pivot", "tool": [0, 0, True]}, "task.tool[2]"),
    ({"type": "cylinder"}, "task.type"),
    ({"type": "sphere", "radius": -0.1}, "task.radius"),
])
def test_bad_task_mappings_name_the_field(doc, field):
    with pytest.raises(InputError) as err:
        T.task_from_dict(doc)
    assert err.value.field == field


def test_pivot_problem_file_plans_a_dense_feasible_path_on_the_task(tmp_path, capsys):
    problem = load_problem(PIVOT_FILE)
    assert problem.task == PIVOT
    result = Planner(problem.robot, problem.task, problem.settings).plan(problem.start, problem.goal)
    assert result.success and result.charts > 0, result.message  # the straight line leaves C
    path = result.path
    tip = path.p + np.einsum("nij,j->ni", rotation_tt(path.tau), np.array(PIVOT.tool))
    assert np.max(np.linalg.norm(tip - PIVOT.center, axis=1)) < 1e-6
    assert all(seg.feasible and seg.unresolved == 0 for seg in check_motion(problem.robot, path.p, path.quaternion))
    assert np.allclose(path.tau[0], problem.start.tau) and np.allclose(path.tau[-1], problem.goal.tau)
    out = tmp_path / "plan.json"
    assert main(["plan", str(PIVOT_FILE), "--quiet", "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["success"] and doc["n"] == 3 and len(doc["path"]) == len(path)


def test_pivot_slice_draws(tmp_path, capsys):
    out = tmp_path / "pivot.png"
    rc = main(["slice", str(CONFIG / "robot2.yaml"), "--task-file", str(PIVOT_FILE), "--free", "phi",
               "sigma", "--fixed", "theta=0.3", "--resolution", "60", "-o", str(out)])
    text = capsys.readouterr().out
    assert rc == 0 and out.stat().st_size > 10_000
    assert "grid over phi x sigma" in text and "% feasible" in text


def test_every_task_field_is_a_node_parameter_with_its_default():
    from cdh_planner.ros.core.params import SPEC
    assert SPEC["task.type"].choices == tuple(T.TASKS)
    for cls in T.TASKS.values():
        for f in cls.parameters():
            spec = SPEC[f.key]
            expected = list(f.default) if f.kind == NUMBERS else f.default
            assert spec.default == expected or (math.isnan(spec.default) and math.isnan(f.default)), f.key


@dataclass(frozen=True)
class PlaneTask(T.Task):
    """A new task in one class: the platform centre on the plane z = height (m), the
    orientation free, n = 5."""

    height: float = T._field(0.3, unit="m", description="plane task: height of the plane")
    type: ClassVar[str] = "plane"
    n_equations: ClassVar[int] = 1
    length_rows: ClassVar[tuple] = (True,)

    @property
    def names(self):
        return ("x", "y", "phi", "theta", "sigma")

    def equations(self, q, v):
        return np.array([q[2] - self.height]), np.eye(6)[2:3]

    def pose(self, y):
        y = np.atleast_2d(y)
        return np.column_stack([y[:, :2], np.full(len(y), self.height)]), y[:, 2:].copy()

    def coords(self, p, tau):
        return np.column_stack([np.atleast_2d(p)[:, :2], np.atleast_2d(tau)])

    def residual(self, p, tau):
        return np.abs(np.atleast_2d(p)[:, 2] - self.height)


@pytest.fixture
def plane_registered():
    T.register(PlaneTask)
    yield
    del T.TASKS["plane"]


def test_a_new_task_is_one_class(plane_registered):
    from cdh_planner.ros.core import params
    task = T.task_from_dict({"type": "plane", "height": 0.25})
    assert task == PlaneTask(height=0.25)
    specs = {s.name: s for s in params._task_specs()}
    assert "plane" in specs["task.type"].choices and specs["task.height"].default == 0.3
    assert T.task_from_dict(PlaneTask.dict_of_parameters({"task.height": 0.2})).height == 0.2
    c = TaskConstraint(ROBOT2, task)
    assert c.dim == 5
    x = c.lift(np.array([0.0, 0.0, 0.25]), np.array([0.0, 0.2, 3.0]))
    F, _ = c.residual_and_jacobian(x)
    assert np.max(np.abs(F)) < 1e-9
    check_task_contract(PlaneTask.example())  # registered: the contract tests cover it


@dataclass(frozen=True)
class RingTask(PlaneTask):
    """A task whose task.center is a number, where the sphere and pivot tasks have a point."""

    center: float = T._field(0.0, unit="m", description="ring task: its height")
    type: ClassVar[str] = "ring"


def test_a_task_declaring_a_shared_parameter_otherwise_is_refused_at_registration():
    before = dict(T.TASKS)
    with pytest.raises(ValueError, match=r"task 'ring': parameter task.center \(number, default "
                                         r"0.0\) is declared otherwise by task 'sphere' \(numbers"):
        T.register(RingTask)
    with pytest.raises(ValueError, match="task type 'pivot' is already registered"):
        T.register(dataclass(frozen=True)(type("OtherPivot", (T.PivotTask,), {})))
    alpha = T.Coordinate("alpha1", "m")  # the sphere's alpha1 is an angle
    with pytest.raises(ValueError, match="task 'arc': coordinate alpha1 \\(m\\) is declared otherwise"):
        T.register(dataclass(frozen=True)(type("ArcTask", (PlaneTask,), {
            "type": "arc", "coordinates": (alpha,), "__annotations__": {}})))
    assert T.TASKS == before and T.COORDINATES["alpha1"].unit == "rad"
    assert T.register(T.PivotTask) is T.PivotTask  # the same class again: nothing changes
    # declared alike (sphere and pivot share task.center) is one parameter
    params = T.task_parameters()
    assert params["task.center"] == (T.SphereTask.parameters()[0], "sphere")
    assert params["task.center"][0].default == (0.0, 0.0, 0.0)


def test_pivot_plans_over_the_node(tmp_path):
    """The node with task.type pivot (parameters task.tool, task.center) plans the problem
    file's query; every waypoint of ~/plan's answer keeps the tool point at c."""
    pytest.importorskip("rclpy")
    from cdh_planner.model.pose import quaternion_from_tau, rotation_from_quaternion
    from cdh_planner.ros.client import PlannerClient, pose_stamped
    from ros_harness import NodeProcess, claimed_domain

    problem = load_problem(PIVOT_FILE)
    params = ["task.type:=pivot", "task.tool:=[0.0, 0.0, 0.1]", "task.center:=[0.0, 0.0, 0.35]"]

    def msg(pose):
        return pose_stamped(list(pose.p) + list(quaternion_from_tau(pose.tau)), "cdh_base")

    with claimed_domain() as domain:
        node = NodeProcess(domain, tmp_path, params=params)
        try:
            with PlannerClient(domain_id=domain) as client:
                client.wait_for_node(30.0)
                answer = client.plan(msg(problem.start), msg(problem.goal), timeout_s=120)
        finally:
            assert node.stop() == 0, node.log()
    assert answer.success, answer.values
    poses = answer.path.poses
    p = np.array([[s.pose.position.x, s.pose.position.y, s.pose.position.z] for s in poses])
    q = np.array([[s.pose.orientation.x, s.pose.orientation.y, s.pose.orientation.z,
                   s.pose.orientation.w] for s in poses])
    tip = p + np.einsum("nij,j->ni", rotation_from_quaternion(q), np.array(PIVOT.tool))
    assert len(poses) > 2 and np.max(np.linalg.norm(tip - PIVOT.center, axis=1)) < 1e-6
