"""Robot 2's hard random free-flight pair (benchmarks/vs_ompl.py, seed 0): what made it hard,
checked on its pieces (the search on it takes minutes: benchmarks/atlas_growth.py), and the
rule that answers it at once (det J keeps its sign on C)."""

from dataclasses import replace

import numpy as np

from cdh_planner.wrench import wrench_feasibility
from cdh_planner.parsing.problem import load_problem
from cdh_planner.model.robot import load_robot
from cdh_planner.model.pose import Pose
from cdh_planner.model.task import FreeTask
from cdh_planner.pipeline.route import CHORD_SAMPLES
from cdh_planner.planner import Planner, PlannerSettings
from cdh_planner.status import Status
from cdh_planner.trajectory.path_check import SlerpPath

from conftest import REPO as ROOT

# two points of a chart link the search once returned on that pair (radius 0.25): task
# coordinates x, y, z (m), phi, theta, sigma (rad)
WALL = np.array([[0.07667044, -0.01403909, 0.18461494, -2.33300748, 0.824286, -3.07555495],
                 [0.07896003, -0.01348529, 0.1835247, -2.3432414, 0.87888023, -3.0556273]])


# random_free_queries(robot2, 25, seed=0)[21] (vs_ompl --queries 50: query 43; --queries 16:
# query 13): (p m, tau rad) of start and goal, as drawn (drawing takes ~10 s: not redone here)
HARD_PAIR = (([-0.0203878067349772, 0.14221667004966423, 0.3307361593824715],
              [2.385770296628108, 0.8425207574491589, -2.5779576548125718]),
             ([0.09044407436090807, -0.051830832897104814, 0.14770741378322044],
              [-2.1479606931675637, 0.871138039318119, -2.9962072462396834]))


def test_a_link_across_a_wall_thinner_than_the_probe_is_found_on_the_route():
    """Both ends feasible, every probed pose feasible, yet the motion crosses a wall (the
    wrench matrix near singular: margin far below zero) between two probed poses: the
    route check densifies as the path will be and names that motion (the search then cuts
    its link: it used to answer with a route that could not be made a path)."""
    robot = load_robot(ROOT / "config" / "robot2.yaml")
    planner = Planner(robot, FreeTask(), PlannerSettings(radius=0.25))
    p, tau = planner.task.pose(WALL)
    assert np.all(wrench_feasibility(robot, p, tau).margin > 0.05)
    assert planner.validity.probe(WALL, CHORD_SAMPLES)  # the probe alone missed the wall
    s = np.linspace(0.0, 1.0, 401)
    pp, R = planner.validity.direct_motion(WALL)(np.zeros(s.size, dtype=int), s)
    margin = wrench_feasibility(robot, pp, R=R).margin
    assert margin.min() < -1.0 and 0.0 < np.mean(margin < 0) < 1 / (CHORD_SAMPLES - 1)
    xs = [planner.constraint.lift(p[k], tau[k]) for k in range(2)]
    assert planner.route.route_unsafe(xs, frozenset()) == 0
    assert planner.route.route_unsafe(xs, frozenset({0})) is None  # a direct motion: checked before


def test_the_hard_pair_lies_across_the_singularity_and_is_answered_at_once():
    """vs_ompl's seed-0 pair that no planner answered in 60 s (Robot 2, query 43 of 50):
    det J has opposite signs at its ends, so no path exists at any resolution; the planner
    says so before building a chart."""
    robot = load_robot(ROOT / "config" / "robot2.yaml")
    start, goal = (Pose(np.array(p), np.array(tau)) for p, tau in HARD_PAIR)
    det = wrench_feasibility(robot, np.array([start.p, goal.p]), np.array([start.tau, goal.tau])).det_j
    assert det[0] * det[1] < 0
    res = Planner(robot, FreeTask(), PlannerSettings()).plan(start, goal)
    assert (res.success, res.reason, res.charts) == (False, Status.NO_PATH, 0)
    assert "singularity" in res.message


def test_det_j_keeps_its_sign_along_every_planned_path():
    """Why the rule holds: J is never singular on C, so det J cannot change sign along a
    feasible motion; checked on the dense motion of planned paths of both robots."""
    for name in ("robot1_qs_qg", "robot2_q2_q3_sigma_free"):
        pr = load_problem(ROOT / "config" / "problems" / f"{name}.yaml")
        res = Planner(pr.robot, pr.task, replace(pr.settings, strategy="gbf")).plan(pr.start, pr.goal)
        assert res.success
        s = np.linspace(0.0, 1.0, 50)
        motion = SlerpPath(res.path.p, res.path.quaternion)
        seg = np.repeat(np.arange(motion.n_segments), s.size)
        p, R = motion(seg, np.tile(s, motion.n_segments))
        det = wrench_feasibility(pr.robot, p, R=R).det_j
        assert np.all(det * det[0] > 0)
