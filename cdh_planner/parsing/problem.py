"""Planning problem files (YAML): robot, task, cost, strategy, settings, start and goal.

    robot: ../robot1.yaml            # relative to this file, or absolute
    task: {type: slice, fixed: {x: 0.0, y: 0.0, z: 0.35, sigma: 0.5934}}
    cost: so3                        # optional: so3 | great_circle | se3 (default by task)
    strategy: astar                  # optional: auto or a registered one (astar, gbf)
    planner: {radius: 0.1, timeout_s: 60, max_charts: 100000, max_memory_mb: 1024, margin_floor: 0.001}
    start: {position: [x, y, z], tau: [phi, theta, sigma]}   # or quaternion: [x, y, z, w]
    goal:  {lambda: [alpha1, alpha2]}                         # or the task's own coordinates
    scene: {cable_radius: 0.001, obstacles: [...]}            # optional (scene/schema.py), or a scene file

Units: m and rad. Every error is an InputError naming the key (``start.tau[1]``).
"""

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..errors import MAX_POSITION_M, InputError, check_keys
from ..model.robot import load_robot
from .. import files
from ..model.task import COORDINATES, task_from_dict
from ..model.pose import Pose
from ..scene.schema import default_scene, load_scene, scene_from_dict
from ..settings import SETTINGS, PlannerSettings, check_setting
from .poses import number_list, pose_from_dict

# the settings schema decides which keys go beside ``planner:`` (strategy, cost) and which in it
TOP_SETTINGS = tuple(k for k, s in SETTINGS.items() if s.top_level)
TOP_KEYS = ("robot", "task", *TOP_SETTINGS, "planner", "start", "goal", "description", "scene")
SETTING_KEYS = tuple(k for k in SETTINGS if k not in TOP_SETTINGS)
MAX_TEXT_CHARS = 4096  # the robot path and the description


@dataclass
class Problem:
    robot: object
    task: object
    settings: PlannerSettings
    start: Pose
    goal: Pose
    path: str = ""
    description: str = ""
    scene: object = None  # scene.schema.Scene, or None: no collision checks


def load_problem(path):
    """Read and validate a problem file."""
    path = Path(path)
    doc = files.read_yaml_mapping(path, "problem", "robot, task, start, goal")
    return problem_from_dict(doc, base_dir=path.parent, source=str(path))


def problem_from_dict(doc, base_dir=".", source=""):
    if not isinstance(doc, dict):
        raise InputError("problem", doc, "expected a mapping with robot, task, start, goal")
    check_keys("", doc, TOP_KEYS, required=("robot", "task", "start", "goal"))
    robot_path = doc["robot"]
    if not isinstance(robot_path, str) or not robot_path or len(robot_path) > MAX_TEXT_CHARS \
            or "\x00" in robot_path:
        raise InputError("robot", robot_path, "expected the path of a robot file")
    robot_file = Path(robot_path) if Path(robot_path).is_absolute() else Path(base_dir) / robot_path
    if not robot_file.exists():
        raise InputError("robot", robot_path, f"robot file not found ({robot_file})")
    robot = load_robot(robot_file)
    description = doc.get("description", "")
    if not isinstance(description, str) or len(description) > MAX_TEXT_CHARS:
        raise InputError("description", description, f"expected a text of at most {MAX_TEXT_CHARS} characters")
    task = task_from_dict(doc["task"])
    settings = settings_from_dict(doc.get("planner") or {}, "planner")
    for key in TOP_SETTINGS:
        if key in doc:
            settings = replace(settings, **{key: check_setting(key, doc[key])})
    start = pose_in_task(doc["start"], task, "start")
    goal = pose_in_task(doc["goal"], task, "goal")
    scene = _scene(doc["scene"], robot, base_dir) if doc.get("scene") is not None \
        else default_scene(robot)
    return Problem(robot, task, settings, start, goal, source, description, scene)


def _scene(value, robot, base_dir):
    """The problem's scene: a ``scene:`` mapping, or the path of a scene file (relative to
    the problem file)."""
    if isinstance(value, str):
        if not value or len(value) > MAX_TEXT_CHARS or "\x00" in value:
            raise InputError("scene", value, "expected a scene mapping or a scene file's path")
        return load_scene(Path(base_dir) / value, robot)
    return scene_from_dict(value, robot, base_dir=base_dir)


def settings_from_dict(d, where):
    """PlannerSettings of the ``planner:`` mapping, each value checked by the schema."""
    if not isinstance(d, dict):
        raise InputError(where, d, "expected a mapping of planner settings")
    check_keys(where, d, SETTING_KEYS)
    return PlannerSettings(**{k: check_setting(k, v, f"{where}.{k}") for k, v in d.items()})


def pose_in_task(d, task, where):
    """A start / goal: a full pose, or ``{lambda: [...]}`` in the task's own coordinates
    (``task.names``: the sphere's [alpha1, alpha2], the pivot's [phi, theta, sigma])."""
    if isinstance(d, dict) and "lambda" in d:
        extra = sorted(set(d) - {"lambda"})
        if extra:
            raise InputError(f"{where}.{extra[0]}", d[extra[0]], "give lambda alone")
        lam = number_list(f"{where}.lambda", d["lambda"], len(task.names), limit=MAX_POSITION_M)
        for j, name in enumerate(task.names):
            c = COORDINATES[name]
            if c.bounds is not None and not c.periodic and not c.bounds[0] <= lam[j] <= c.bounds[1]:
                raise InputError(f"{where}.lambda[{j}]", float(lam[j]), f"{name} must be in "
                                 f"[{c.bounds[0]:.4g}, {c.bounds[1]:.4g}] {c.unit}")
        p, tau = task.pose(lam[None])
        return Pose(p[0], tau[0])
    p, _, tau = pose_from_dict(d, where)
    return Pose(p, tau)
