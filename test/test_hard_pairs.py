"""Robot 2's hard random free-flight pair (benchmarks/vs_ompl.py, seed 0): what made it hard,
checked on its pieces (the whole query takes minutes: benchmarks/atlas_growth.py)."""

import numpy as np

from cdh_planner.feasibility import evaluate
from cdh_planner.model.task import FreeTask
from cdh_planner.planner import CHORD_SAMPLES, Planner, PlannerSettings

from conftest import REPO as ROOT
from cdh_planner.model.robot import load_robot

# two points of a chart link the search once returned on that pair (radius 0.25): task
# coordinates x, y, z (m), phi, theta, sigma (rad)
WALL = np.array([[0.07667044, -0.01403909, 0.18461494, -2.33300748, 0.824286, -3.07555495],
                 [0.07896003, -0.01348529, 0.1835247, -2.3432414, 0.87888023, -3.0556273]])


def test_a_link_across_a_wall_thinner_than_the_probe_is_found_on_the_route():
    """Both ends feasible, every probed pose feasible, yet the motion crosses a wall (the
    wrench matrix near singular: margin far below zero) between two probed poses: the
    route check densifies as the path will be and names that motion (the search then cuts
    its link: it used to answer with a route that could not be made a path)."""
    robot = load_robot(ROOT / "config" / "robot2.yaml")
    planner = Planner(robot, FreeTask(), PlannerSettings(radius=0.25))
    p, tau = planner.task.pose(WALL)
    assert np.all(evaluate(robot, p, tau).margin > 0.05)
    assert planner._probe(WALL, CHORD_SAMPLES)  # the probe alone missed the wall
    s = np.linspace(0.0, 1.0, 401)
    pp, R = planner._direct_motion(WALL)(np.zeros(s.size, dtype=int), s)
    margin = evaluate(robot, pp, R=R).margin
    assert margin.min() < -1.0 and 0.0 < np.mean(margin < 0) < 1 / (CHORD_SAMPLES - 1)
    xs = [planner.constraint.lift(p[k], tau[k]) for k in range(2)]
    assert planner._route_unsafe(xs, frozenset()) == 0
    assert planner._route_unsafe(xs, frozenset({0})) is None  # a direct motion: checked before
