"""The demo's obstacle step: Robot 2 in free flight from q_2 to q_3 (the poses of the
paper's sphere task) with a 1 cm ball on cable 3 half way along the straight motion
(``config/problems/robot2_q2_q3_ball.yaml``, its scene ``config/scenes/robot2_ball.yaml``).

The straight motion (position linear, orientation slerp) is wrench-feasible, but cable 3
runs through the ball: the dense check with the scene says where and what binds. The planner
then goes around it; its path is checked densely again, against the ball and the wrench.
The sphere task's C-space slice is drawn with the poses in collision in dark grey.
"""

import math

import numpy as np

from ...pictures.slices import COLLISION, Marker, SliceView
from ...parsing.problem import load_problem
from ...model.pose import quaternion_from_tau, rotation_from_quaternion
from ...planner import Planner
from ...scene.collision import CollisionModel
from ...trajectory.path_check import check_motion
from ..slice import render_slice
from .steps import Step

PROBLEM = "problems/robot2_q2_q3_ball.yaml"   # in the config directory
PICTURE = "robot2_sphere_ball.png"
PICTURE_RANGES = ((-math.pi, math.pi), (0.0, math.pi / 2))
SPHERE_POINTS = {"q_2": (0.55, 0.75), "q_3": (2.63, 0.75)}   # the paper's, (alpha1, alpha2)


def obstacle_step(demo):
    problem = load_problem(demo.config_dir / PROBLEM)
    robot, scene = problem.robot, problem.scene
    collision = CollisionModel(robot, scene)
    ball = scene.obstacles[0]
    print(f"{problem.description}: {ball.id} of radius {ball.radius * 1e3:g} mm at "
          f"[{', '.join(f'{v:.4f}' for v in ball.position)}] m, cables {scene.cable_radius * 1e3:g} mm")
    ends = np.array([problem.start.p, problem.goal.p])
    q = quaternion_from_tau(np.array([problem.start.tau, problem.goal.tau]))
    bare = check_motion(robot, ends, q)[0]
    hit = check_motion(robot, ends, q, collision=collision)[0]
    print(f"straight motion (linear + slerp), no scene: "
          f"{'wrench-feasible' if bare.feasible else 'UNSAFE'}; with the ball: "
          + ("clear" if hit.feasible else f"hits at s = {hit.first_unsafe.s:.3f} "
                                          f"({hit.first_unsafe.binding})"))
    _expect(demo, "straight motion without the scene is wrench-feasible", bare.feasible)
    _expect(demo, "straight motion hits the ball", not hit.feasible
            and "ball" in hit.first_unsafe.binding)
    result = Planner(robot, problem.task, problem.settings, scene=scene).plan(problem.start,
                                                                            problem.goal)
    if not result.success:
        _expect(demo, f"a plan around the ball ({result.message})", False)
        return
    path = result.path
    check = check_motion(robot, path.p, path.quaternion, collision=collision)
    clear = all(c.feasible for c in check)
    least = min(collision.clearance(p, R).distance
                for p, R in zip(path.p, _rotations(path.quaternion)))
    print(f"plan: {len(path)} waypoints over {result.charts} charts in {result.time_s:.2f} s; "
          f"dense check against the ball and the wrench: {'clear' if clear else 'NOT CLEAR'}; "
          f"least clearance at a waypoint {least * 1e3:.2f} mm")
    _expect(demo, "the planned path keeps clear of the ball, densely", clear)
    _picture(demo, problem.robot, collision)


def _picture(demo, robot, collision):
    """The sphere task's slice with the poses in collision in dark grey."""
    view = SliceView(task=demo.tasks["robot2"], axes=("alpha1", "alpha2"), ranges=PICTURE_RANGES)
    out = demo.out_dir / PICTURE
    result = render_slice(robot, view, out, resolution=400, size=(1000, 800),
                          markers=[Marker(k, *c) for k, c in SPHERE_POINTS.items()],
                          segment=tuple(SPHERE_POINTS.values()), collision=collision)
    demo.files.append(out)
    share = float(np.mean(result.grid.classes == COLLISION))
    print(f"sphere task slice with the ball: {100 * share:.1f} % of it in collision (dark "
          f"grey)\n  wrote {out}")


def _rotations(quaternions):
    return rotation_from_quaternion(np.asarray(quaternions))


def _expect(demo, what, ok):
    if not ok:
        demo.differs.append(f"obstacle: {what}: not so")


STEPS = [Step("obstacle", "An obstacle on the straight motion: Robot 2 free flight q_2 -> q_3",
              obstacle_step)]
