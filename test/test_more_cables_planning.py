"""Planning for robots with more than six cables (docs/more-cables.md, "Planning with
m > 6 cables"): every task and both strategies on robot2_8, a CoGiRo plan, and each plan
checked at its samples by the independent LP oracle (test/lp_oracle.py), not by the
package's own facet test."""

import dataclasses

import numpy as np
import pytest

from cdh_planner.wrench import band_feasibility, wrench_feasibility
from cdh_planner.parsing.problem import load_problem
from cdh_planner.manifold.configuration import ConfigurationConstraint
from cdh_planner.model.forward_kinematics import forward_kinematics_many
from cdh_planner.model.kinematics import forward_kinematics
from cdh_planner.model.pose import rotation_tt
from cdh_planner.model.robot import load_robot
from cdh_planner.model.pose import Pose
from cdh_planner.model.task import task_from_dict
from cdh_planner.planner import Planner
from cdh_planner.settings import PlannerSettings
from cdh_planner.status import Status
from cdh_planner.trajectory.path_check import SlerpPath

from conftest import CONFIG
from lp_oracle import ellipsoid_held

PROBLEMS = CONFIG / "problems"
SAMPLES_PER_SEGMENT = 3  # poses of the motion between waypoints the LP checks (s = 0, 1/3, 2/3)


def planned(name, strategy, **settings):
    pr = load_problem(PROBLEMS / f"{name}.yaml")
    s = dataclasses.replace(pr.settings, strategy=strategy, timeout_s=60, **settings)
    return pr, Planner(pr.robot, pr.task, s).plan(pr.start, pr.goal)


def lp_check(robot, path, seed=0):
    """The path's waypoints and SAMPLES_PER_SEGMENT poses of each motion between them
    (position linear, orientation slerp): w0 and random boundary wrenches of the ellipsoid
    are held by tensions in range (LP). Returns the number of poses checked."""
    motion = SlerpPath(path.p, path.quaternion)
    seg = np.repeat(np.arange(motion.n_segments), SAMPLES_PER_SEGMENT)
    s = np.tile(np.arange(SAMPLES_PER_SEGMENT) / SAMPLES_PER_SEGMENT, motion.n_segments)
    p, R = motion(seg, s)
    p, R = np.vstack([p, path.p[-1:]]), np.concatenate([R, rotation_tt(path.tau[-1:])])
    held = ellipsoid_held(robot, p, R, np.random.default_rng(seed))
    assert held.all(), f"{np.sum(~held)} of {len(held)} poses not held: first at {p[~held][0]}"
    return len(held)


@pytest.mark.parametrize("strategy", ["astar", "gbf"])
@pytest.mark.parametrize("name, atlas", [("robot2_8_q2_q3", True), ("robot2_8_pivot", True),
                                         ("robot2_8_slice", True),
                                         ("robot2_8_q2_q3_free_flight", False)])
def test_robot2_8_plans_every_task(name, atlas, strategy):
    pr, res = planned(name, strategy)
    assert res.success, res.message
    assert res.stats["direct"] is not atlas  # the sphere, pivot and slice queries need the atlas
    path = res.path
    assert path.lengths.shape == (len(path), 8)
    f = band_feasibility(pr.robot, path.p, path.tau)
    assert np.all(f.margin > 0)
    # the published band is the rule's and inside the limits at every waypoint
    assert np.all(path.tension_min >= pr.robot.tension_min - 1e-9)
    assert np.all(path.tension_max <= pr.robot.tension_max + 1e-9)
    assert lp_check(pr.robot, path) > 3 * (len(path) - 1)


def test_cogiro_plans_and_the_lp_holds_its_samples():
    """A CoGiRo free-flight query (quasi-static, so the test stays short): the direct
    motion of a 2.5 m move with a 0.6 rad turn."""
    robot = load_robot(CONFIG / "cogiro.yaml")
    task = task_from_dict({"type": "free"})
    pl = Planner(robot, task, dataclasses.replace(
        load_problem(PROBLEMS / "cogiro_turn_at_edge.yaml").settings, dynamics="quasi_static"))
    res = pl.plan(Pose(np.array([0.0, 0.0, 2.0]), np.array([0.0, 0.0, 0.0])),
                  Pose(np.array([2.0, 1.5, 2.5]), np.array([0.0, 0.1, 0.6])))
    assert res.success, res.message
    assert lp_check(robot, res.path) > 10


def test_the_configuration_manifold_has_the_task_dimension():
    """Free flight: 6 variables, no equation; the sphere: the pose and two task variables
    under the sphere's equations, dimension 2; ``inside`` is the planner's margin floor."""
    pr = load_problem(PROBLEMS / "robot2_8_q2_q3.yaml")
    c = ConfigurationConstraint(pr.robot, pr.task, margin_floor=1e-3)
    assert c.dim == 2 and c.n_vars == 8
    x = c.lift(pr.start.p, pr.start.tau)
    F, J = c.residual_and_jacobian(x)
    assert np.max(np.abs(F)) < 1e-9 and np.linalg.matrix_rank(J) == c.n_vars - c.dim
    # finite differences of the task equations
    h, d = 1e-6, np.random.default_rng(0).normal(size=c.n_vars)
    fd = (c.residual_and_jacobian(x + h * d)[0] - c.residual_and_jacobian(x - h * d)[0]) / (2 * h)
    assert np.allclose(fd, J @ d, atol=1e-6)
    assert c.inside(x)
    assert c.margin(x) == pytest.approx(float(band_feasibility(
        pr.robot, pr.start.p[None], pr.start.tau[None]).margin[0]))


def test_planning_margin_is_the_closed_form_for_six_cables_and_the_band_for_more():
    rng = np.random.default_rng(3)
    r6 = load_robot(CONFIG / "robot2.yaml")
    p = np.array([0.0, 0.0, 0.3]) + rng.uniform(-0.05, 0.05, (200, 3))
    tau = rng.uniform(-0.5, 0.5, (200, 3))
    a, b = band_feasibility(r6, p, tau), wrench_feasibility(r6, p, tau)
    assert np.array_equal(a.margin, b.margin) and np.array_equal(a.binding, b.binding)
    r8 = load_robot(CONFIG / "robot2_8.yaml")
    p = np.array([0.0, 0.0, 0.3]) + rng.uniform(-0.1, 0.1, (400, 3))
    tau = rng.uniform(-0.8, 0.8, (400, 3))
    f, z = band_feasibility(r8, p, tau), wrench_feasibility(r8, p, tau)
    band_ok = np.all(f.margins > 0, axis=(1, 2))
    assert np.array_equal(f.margin > 0, band_ok) and 0 < band_ok.sum() < len(p)
    # where the facet test holds, the band is the facet test's (the same centred rule), and a band
    # inside the tension limits is exactly the facet test's "ok" (lengths aside): it implies the
    # facet test
    held = z.wrench_margin > 0
    assert np.allclose(f.margins[held], z.margins[held], rtol=0, atol=1e-12)
    tensions_ok = np.all(f.margins[:, 2:] > 0, axis=(1, 2))
    assert np.array_equal(tensions_ok, z.tension_status == "ok")
    assert np.all(z.wrench_margin[tensions_ok] > 0)


def test_forward_kinematics_many_is_least_squares_for_eight_cables():
    """The vectorised Gauss-Newton equals the one-pose least squares to 1e-7 on lengths
    with 0.1 mm of noise, and reports the residual."""
    robot = load_robot(CONFIG / "robot2_8.yaml")
    rng = np.random.default_rng(1)
    p = np.array([0.0, 0.0, 0.3]) + 0.03 * rng.standard_normal((10, 3))
    R = rotation_tt(0.2 * np.abs(rng.standard_normal((10, 3))))
    d = p[:, None, :] + np.einsum("nij,kj->nki", R, robot.platform_anchors) - robot.base_anchors
    L = np.linalg.norm(d, axis=2) + 1e-4 * rng.standard_normal((10, 8))
    fk = forward_kinematics_many(robot, L, p, R)
    assert fk.ok.all() and np.all(fk.residual > 1e-6)
    for k in range(10):
        one = forward_kinematics(robot, L[k], p[k], R[k])
        assert one.ok
        assert np.allclose(fk.p[k], one.p, atol=1e-7) and np.allclose(fk.R[k], one.R, atol=1e-7)
        assert fk.residual[k] == pytest.approx(one.residual, rel=1e-3)


@pytest.mark.parametrize("strategy", ["astar", "gbf"])
def test_no_path_out_of_an_island_of_the_band_domain(strategy):
    """robot2_8's slice at p = (0, 0, 0.3) m, sigma = 0: the tilted poses around
    (phi, theta) = (-1.55, 2.2) are an island where the band fits, apart from the level
    poses. The domain predicate bounds the atlas: the island's side is exhausted (NO_PATH
    at the chart radius, not a timeout), and every chart centre is inside the domain."""
    robot = load_robot(CONFIG / "robot2_8.yaml")
    task = task_from_dict({"type": "slice", "fixed": {"x": 0.0, "y": 0.0, "z": 0.3, "sigma": 0.0}})
    planner = Planner(robot, task, dataclasses.replace(PlannerSettings(), strategy=strategy,
                                                       timeout_s=60))
    res = planner.plan(Pose(np.array([0.0, 0.0, 0.3]), np.array([-1.55, 2.2, 0.0])),
                       Pose(np.array([0.0, 0.0, 0.3]), np.array([-2.9, 1.0, 0.0])))
    assert (res.success, res.reason) == (False, Status.NO_PATH), res.message
    assert "exhausted" in res.message and res.charts > 50
    c = planner.constraint
    centres = np.array([ch.x for ch in planner.atlas.charts])
    assert np.all(c.inside_many(centres))
