"""The task metrics: path cost between poses, in rad or m (the planner's and the node's).

    cost = task_cost(robot, task, "auto")      # float of one pair of poses
    costs = task_costs(robot, task, "se3")     # vectorised over (..., 3) arrays
"""

import numpy as np

from ..errors import InputError
from ..model.pose import rotation_angle_between, rotation_tt
from ..settings import COSTS


def task_costs(robot, task, kind="auto"):
    """cost(p_a, tau_a, p_b, tau_b) between poses (m, rad; arrays (..., 3) -> (...)) of
    ``kind`` (COSTS), one of the task's ``costs``: ``so3`` the SO(3) geodesic (rad, the
    paper's for orientation slices), ``se3`` |dp| + L |angle| (m, L = mean platform anchor
    radius), or the task's own (the sphere's ``great_circle``). ``auto``: the task's
    ``default_cost``."""
    kind = task.default_cost if kind == "auto" else kind
    if kind not in COSTS:
        raise InputError("cost", kind, f"expected one of {', '.join(COSTS)}")
    if kind not in task.costs:
        raise InputError("cost", kind, f"not a cost of the {task.describe()} (its costs: "
                                       f"{', '.join(task.costs)})")
    L = float(np.mean(np.linalg.norm(robot.platform_anchors, axis=1)))
    if kind == "so3":
        return lambda pa, ta, pb, tb: rotation_angle_between(rotation_tt(ta), rotation_tt(tb))
    if kind == "se3":
        return lambda pa, ta, pb, tb: (np.linalg.norm(pb - pa, axis=-1)
                                       + L * rotation_angle_between(rotation_tt(ta), rotation_tt(tb)))
    return task.own_cost(kind)


def task_cost(robot, task, kind="auto"):
    """``task_costs`` of one pair of poses, as a float."""
    costs = task_costs(robot, task, kind)
    return lambda pa, ta, pb, tb: float(costs(pa, ta, pb, tb))
