"""Planning problem files (YAML): robot, task, cost, strategy, settings, start and goal.

    robot: ../robot1.yaml            # relative to this file, or absolute
    task: {type: slice, fixed: {x: 0.0, y: 0.0, z: 0.35, sigma: 0.5934}}
    cost: so3                        # optional: so3 | great_circle | se3 (default by task)
    strategy: astar                  # optional: auto | astar | gbf
    planner: {radius: 0.1, timeout_s: 60, max_charts: 100000, max_memory_mb: 1024, margin_floor: 0.001}
    start: {position: [x, y, z], tau: [phi, theta, sigma]}   # or quaternion: [x, y, z, w]
    goal:  {lambda: [alpha1, alpha2]}                         # sphere task only

Units: m and rad. Every error is an InputError naming the key (``start.tau[1]``).
"""

from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..model.robot import load_robot, read_yaml
from ..model.task import SphereTask, task_from_dict
from ..planner import COSTS, PlannerSettings, Pose
from ..search.search import STRATEGIES
from .poses import number_list, pose_from_dict, short_repr

TOP_KEYS = ("robot", "task", "cost", "strategy", "planner", "start", "goal", "description")
SETTING_KEYS = ("radius", "timeout_s", "max_charts", "max_memory_mb", "margin_floor", "complete",
                "max_cable_speed", "max_cable_accel")


@dataclass
class Problem:
    robot: object
    task: object
    settings: PlannerSettings
    start: Pose
    goal: Pose
    path: str = ""
    description: str = ""


def load_problem(path):
    """Read and validate a problem file."""
    path = Path(path)
    doc = read_yaml(path, "problem")
    return problem_from_dict(doc, base_dir=path.parent, source=str(path))


def problem_from_dict(doc, base_dir=".", source=""):
    if not isinstance(doc, dict):
        raise InputError("problem", short_repr(doc), "expected a mapping with robot, task, start, goal")
    unknown = sorted(set(doc) - set(TOP_KEYS))
    if unknown:
        raise InputError(unknown[0], doc[unknown[0]], f"unknown key (allowed: {', '.join(TOP_KEYS)})")
    for key in ("robot", "task", "start", "goal"):
        if key not in doc:
            raise InputError(key, None, "required key is missing")
    robot_path = doc["robot"]
    if not isinstance(robot_path, str) or not robot_path:
        raise InputError("robot", robot_path, "expected the path of a robot file")
    robot_file = Path(robot_path) if Path(robot_path).is_absolute() else Path(base_dir) / robot_path
    if not robot_file.is_file():
        raise InputError("robot", robot_path, f"robot file not found ({robot_file})")
    robot = load_robot(robot_file)
    task = task_from_dict(doc["task"])
    settings = settings_from_dict(doc.get("planner") or {}, "planner")
    if "strategy" in doc:
        settings = replace(settings, strategy=_choice("strategy", doc["strategy"], ("auto",) + STRATEGIES))
    if "cost" in doc:
        settings = replace(settings, cost=_choice("cost", doc["cost"], COSTS))
    start = pose_in_task(doc["start"], task, "start")
    goal = pose_in_task(doc["goal"], task, "goal")
    return Problem(robot, task, settings, start, goal, source, str(doc.get("description", "")))


def settings_from_dict(d, where):
    if not isinstance(d, dict):
        raise InputError(where, short_repr(d), "expected a mapping of planner settings")
    unknown = sorted(set(d) - set(SETTING_KEYS))
    if unknown:
        raise InputError(f"{where}.{unknown[0]}", d[unknown[0]],
                         f"unknown setting (allowed: {', '.join(SETTING_KEYS)})")
    kinds = {f.name: f.type for f in fields(PlannerSettings)}
    values = {}
    for key, value in d.items():
        if kinds[key] in (bool, "bool"):
            if not isinstance(value, bool):
                raise InputError(f"{where}.{key}", value, "expected true or false")
        elif isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) \
                or value <= 0:
            raise InputError(f"{where}.{key}", value, "must be a positive finite number")
        elif kinds[key] in (int, "int") and int(value) != value:
            raise InputError(f"{where}.{key}", value, "must be an integer")
        values[key] = int(value) if kinds[key] in (int, "int") else value
    return PlannerSettings(**values)


def pose_in_task(d, task, where):
    """A start / goal: a full pose, or for the sphere task ``{lambda: [a1, a2(, sigma)]}``."""
    if isinstance(d, dict) and "lambda" in d:
        if not isinstance(task, SphereTask):
            raise InputError(f"{where}.lambda", d["lambda"], "only the sphere task has lambda coordinates")
        extra = sorted(set(d) - {"lambda"})
        if extra:
            raise InputError(f"{where}.{extra[0]}", d[extra[0]], "give lambda alone")
        lam = number_list(f"{where}.lambda", d["lambda"], len(task.names))
        if not -np.pi / 2 <= lam[1] <= np.pi / 2:
            raise InputError(f"{where}.lambda[1]", float(lam[1]), "alpha2 must be in [-pi/2, pi/2] rad")
        p, tau = task.pose(lam[None])
        return Pose(p[0], tau[0])
    p, _, tau = pose_from_dict(d, where)
    return Pose(p, tau)


def _choice(key, value, allowed):
    if value not in allowed:
        raise InputError(key, value, f"expected one of {', '.join(allowed)}")
    return value

