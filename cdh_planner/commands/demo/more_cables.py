"""The demo's step for robots with more than six cables (docs/more-cables.md): robot2_8,
the paper's Robot 2 with two more cables, plans the sphere task q_2 -> q_3 whose direct
motion leaves C, on the configuration manifold with the facet test and the tension rule's
band as its domain; the path is checked densely and its published band stays in the limits."""

import dataclasses

import numpy as np

from ...model.pose import Pose
from ...model.robot import load_robot
from ...planner import Planner
from ...settings import PlannerSettings
from .steps import Step, table

ROBOT_FILE = "robot2_8.yaml"


def plan_eight_cables(demo):
    """Plan robot2_8's sphere task q_2 -> q_3 with both strategies; a failed plan or a band
    outside the limits is a verdict that differs."""
    path = demo.config_dir / ROBOT_FILE
    robot = load_robot(path)
    task = demo.tasks["robot2"]
    ends = [Pose(*demo.pose("robot2", label)) for label in ("q_2", "q_3")]
    print(f"{robot.name}: {path}: {len(robot.winch_names)} cables, the paper's Robot 2 and "
          "two more (cables 4 and 5 mirrored)")
    rows = []
    for strategy in ("astar", "gbf"):
        settings = dataclasses.replace(PlannerSettings(), strategy=strategy, timeout_s=60)
        res = Planner(robot, task, settings).plan(*ends)
        inside = res.success and bool(np.all(res.path.tension_min >= robot.tension_min - 1e-9)
                                      and np.all(res.path.tension_max <= robot.tension_max + 1e-9))
        if not inside:
            demo.differs.append(f"{robot.name} q_2 -> q_3 ({strategy}): {res.message}")
        rows.append([strategy, "yes" if res.success else "NO", str(res.charts),
                     f"{res.time_s:.2f}", f"{res.cost:.3f}" if res.success else "-",
                     f"{res.least_margin:+.4f}" if res.success else "-",
                     "inside" if inside else "OUTSIDE", res.message])
    table(["strategy", "path", "charts", "time (s)", "cost (rad)", "least margin",
           "band vs limits", "message"], rows)
    print("8 cables: the atlas covers the sphere task's configuration manifold; a pose is in "
          "its domain when the tension rule's band t0 +- v (published per waypoint and cable) "
          "is inside the limits, which also proves the wrench ellipsoid inside the zonotope")


STEPS = [Step("more_cables", "Robots with more than six cables: robot2_8 plans q_2 -> q_3",
              plan_eight_cables)]
