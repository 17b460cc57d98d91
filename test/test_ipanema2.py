"""config/ipanema2.yaml, an 8-cable robot whose cables pull from above and below (CASPR's
IPAnema 2): it loads as CASPR gives it, its nominal tensions hold the load, and a free-flight
query whose straight motion is infeasible plans to a densely feasible path."""

import dataclasses

import numpy as np

from cdh_planner.model.pose import Pose, quaternion_from_tau
from cdh_planner.model.robot import load_robot
from cdh_planner.model.task import task_from_dict
from cdh_planner.parsing.problem import load_problem
from cdh_planner.planner import Planner
from cdh_planner.trajectory.path_check import SlerpPath, check_motion, check_path
from cdh_planner.wrench import (cable_vectors, nominal_wrench, load_point, screw_jacobian,
                                wrench_feasibility)

from conftest import CONFIG

# benchmarks/eight_cables.py's first IPAnema 2 query (seed 0): a 2.8 m move with a 2 rad turn
START = Pose(np.array([-0.17668792, 0.14833405, -1.84254337]),
             np.array([-1.40356517, 0.39786813, 0.04900696]))
GOAL = Pose(np.array([1.95425647, -0.05442201, 0.76654105]),
            np.array([0.50979348, 0.45366699, -0.14917301]))


def test_ipanema2_loads_as_caspr_gives_it_and_its_tensions_hold_the_load():
    robot = load_robot(CONFIG / "ipanema2.yaml")
    assert robot.base_anchors.shape == robot.platform_anchors.shape == (8, 3)
    assert np.allclose(np.sort(np.unique(robot.base_anchors[:, 2])), [1.0, 5.0])
    assert np.allclose(robot.force, [0.0, 0.0, -10.0 * 9.80665])
    p, R = np.array([[0.0, 0.0, 2.5], [1.0, 0.5, 3.0]]), np.array([np.eye(3)] * 2)
    f = wrench_feasibility(robot, p, R=R)
    assert np.all(f.margin > 0), f.binding
    # the published nominal tensions hold the nominal wrench: J t0 = w0
    u = cable_vectors(robot, p, R)
    u /= np.linalg.norm(u, axis=-1)[..., None]
    held = np.einsum("nij,nj->ni", screw_jacobian(robot, u), f.tension_nominal)
    assert np.allclose(held, nominal_wrench(robot, load_point(robot, p, R)), atol=1e-8)


def test_an_ipanema2_query_with_an_infeasible_straight_motion_plans_densely_feasible():
    robot = load_robot(CONFIG / "ipanema2.yaml")
    ends = np.array([START.tau, GOAL.tau])
    straight = SlerpPath(np.array([START.p, GOAL.p]), quaternion_from_tau(ends))
    assert not check_path(robot, straight)[0].feasible
    settings = dataclasses.replace(  # quasi-static, so that the test stays short
        load_problem(CONFIG / "problems" / "cogiro_turn_at_edge.yaml").settings,
        dynamics="quasi_static", timeout_s=60)
    res = Planner(robot, task_from_dict({"type": "free"}), settings).plan(START, GOAL)
    assert res.success, res.message
    assert all(seg.feasible for seg in check_motion(robot, res.path.p, res.path.quaternion))
