"""The planning pipeline's stages one at a time (cdh_planner/pipeline): what each one
promises, checked against the closed form (wrench.wrench_feasibility, the dense check) and
against identities (a straight evenly spaced line is smoothing's fixed point, densifying
only inserts, the metrics are distances)."""

import math

import numpy as np
import pytest

from conftest import PROBLEMS
from cdh_planner.errors import InputError
from cdh_planner.wrench import wrench_feasibility
from cdh_planner.parsing.problem import load_problem
from cdh_planner.model.pose import Pose, quaternion_from_tau, rotation_angle_between, rotation_tt
from cdh_planner.pipeline import lift as L
from cdh_planner.pipeline.densify import Densify
from cdh_planner.pipeline.metrics import task_cost, task_costs
from cdh_planner.pipeline.route import DIRECT_STEP_M, DIRECT_STEP_RAD, Route
from cdh_planner.pipeline.smooth import CLEARANCE_STEP_M, CLEARANCE_STEP_RAD, Smooth
from cdh_planner.pipeline.timing import time_stage
from cdh_planner.pipeline.validity import Validity, wrapped
from cdh_planner.planner import Planner
from cdh_planner.search.strategies import Stop
from cdh_planner.status import Status


def stages(name, **settings):
    """(problem, planner, start and goal task coordinates (2, k)) of a problem file."""
    pr = load_problem(PROBLEMS / f"{name}.yaml")
    for k, v in settings.items():
        setattr(pr.settings, k, v)
    planner = Planner(pr.robot, pr.task, pr.settings)
    ends = pr.task.coords(np.array([pr.start.p, pr.goal.p]), np.array([pr.start.tau, pr.goal.tau]))
    return pr, planner, ends


def step_sizes(validity, y):
    """Per consecutive pair of rows of y: (position m, rotation rad) of the direct motion."""
    return validity.direct_motion(y).speeds()


# ----- validity ---------------------------------------------------------------------------
def test_validity_of_poses_is_the_margin_above_the_floor():
    pr, planner, ends = stages("robot1_qs_qg")
    v = planner.validity
    rng = np.random.default_rng(3)
    y = ends[0] + rng.normal(scale=0.3, size=(200, ends.shape[1]))
    p, tau = pr.task.pose(y)
    margin = wrench_feasibility(pr.robot, p, tau).margin
    np.testing.assert_array_equal(v.margins(y), margin)
    np.testing.assert_array_equal(v.pose(y), margin >= pr.settings.margin_floor)
    assert 0 < v.pose(y).sum() < len(y)  # both kinds were drawn


@pytest.mark.parametrize("name,safe", [("robot2_q1_q2", True), ("robot1_qs_qg", False),
                                       ("robot2_q2_q3", False)])
def test_validity_of_the_direct_motion_matches_the_paper(name, safe):
    """Table 1's straight lines: safe for Robot 2's q1 -> q2, unsafe for the others."""
    _, planner, ends = stages(name)
    assert planner.validity.motion(ends[0], ends[1]) is safe


def test_direct_motion_joins_its_rows_and_takes_the_short_arc():
    pr, planner, ends = stages("robot1_qs1_qg")
    v = planner.validity
    motion = v.direct_motion(ends)
    p, R = motion(np.array([0, 0]), np.array([0.0, 1.0]))
    for k in (0, 1):
        pk, tk = pr.task.pose(ends[k:k + 1])
        np.testing.assert_allclose(p[k], pk[0], atol=1e-12)
        assert rotation_angle_between(R[k], rotation_tt(tk[0])) < 1e-9
    d = wrapped(np.array([[3.0, -3.5, 7.0]]), np.array([True, True, False]))
    np.testing.assert_allclose(d, [[3.0, 2 * math.pi - 3.5, 7.0]])


# ----- lift -------------------------------------------------------------------------------
def test_lift_puts_start_and_goal_on_the_manifold_at_their_poses():
    pr, planner, _ = stages("robot2_q2_q3")
    points, why = planner.lift(pr.start, pr.goal, pr.settings.task_tolerance)
    assert why is None
    for label, pose in (("start", pr.start), ("goal", pr.goal)):
        x = points[label]
        p, tau = planner.constraint.pose(x)
        np.testing.assert_allclose(p, pose.p, atol=L.TASK_TOL)
        assert rotation_angle_between(rotation_tt(tau), rotation_tt(pose.tau)) < L.TASK_TOL
        assert planner.atlas.in_domain(x)


def test_lift_says_why_not():
    pr, planner, _ = stages("robot2_q2_q3")
    off = Pose(pr.goal.p + np.array([0.0, 0.0, 0.05]), pr.goal.tau)  # off the slice's z
    points, (reason, message) = planner.lift(pr.start, off, 1e-3)
    assert points is None and reason == Status.INVALID and message.startswith("goal pose is off")
    far = Pose(pr.start.p, pr.start.tau + np.array([0.0, 1.5, 0.0]))   # a steep tilt
    if not wrench_feasibility(pr.robot, far.p[None], far.tau[None]).feasible[0]:
        points, (reason, message) = planner.lift(far, pr.goal, 1e-3)
        assert reason == Status.infeasible("start") and "not wrench-feasible" in message
    with pytest.raises(InputError) as err:
        planner.lift(Pose(pr.start.p, [0.0, math.nan, 0.0]), pr.goal, 1e-3)
    assert err.value.field == "start.tau"
    with pytest.raises(InputError) as err:
        L.finite_vector("goal.p", [1.0, 2.0], 3)
    assert err.value.field == "goal.p"


# ----- route ------------------------------------------------------------------------------
def test_route_takes_a_valid_direct_motion_at_the_planned_spacing():
    pr, planner, ends = stages("robot2_q1_q2")
    points, _ = planner.lift(pr.start, pr.goal, pr.settings.task_tolerance)
    y, charts, direct, failed = planner.route(points, Stop(max_charts=100), "astar")
    assert direct and charts == 0 and failed is None and len(planner.atlas.charts) == 0
    np.testing.assert_allclose(y[[0, -1]], ends, atol=1e-9)
    dp, da = step_sizes(planner.validity, y)
    assert np.all(dp <= DIRECT_STEP_M * (1 + 1e-9)) and np.all(da <= DIRECT_STEP_RAD * (1 + 1e-9))
    assert np.all(planner.validity.pose(y))


def test_route_searches_when_the_direct_motion_is_not_valid():
    pr, planner, ends = stages("robot1_qs1_qg", strategy="gbf")
    points, _ = planner.lift(pr.start, pr.goal, pr.settings.task_tolerance)
    y, charts, direct, failed = planner.route(points, Stop(max_charts=5_000), "gbf")
    assert failed is None and not direct and charts > 0
    # the lifted ends: phi at theta = 0 is chosen by the other end (model.task.end_taus)
    np.testing.assert_allclose(y[[0, -1]], planner.route.coords([points["start"], points["goal"]]),
                               atol=1e-9)
    assert np.all(planner.validity.pose(y))
    _, _, _, failed = Planner(pr.robot, pr.task, pr.settings).route(points, Stop(max_charts=3), "gbf")
    assert failed[0] == Status.CHART_LIMIT and failed[2]["expanded"] >= 0


def test_clearance_cost_is_never_below_the_length_and_is_the_length_at_weight_zero():
    pr, planner, _ = stages("robot2_q2_q3")
    assert planner.route.cost is planner.length and planner.route.heuristic("astar") is None
    points, _ = planner.lift(pr.start, pr.goal, pr.settings.task_tolerance)
    xs, xg = points["start"], points["goal"]
    weighted = Route(planner.constraint, planner.atlas, planner.validity, planner.length, 0.5,
                     planner.radius, planner.densify.densify)
    assert weighted.cost(xs, xg) >= planner.length(xs, xg) > 0
    assert weighted.heuristic("astar") is planner.length   # admissible: a lower bound
    assert weighted.heuristic("gbf")(xs, xg) >= planner.length(xs, xg)


# ----- smooth -----------------------------------------------------------------------------
def test_a_straight_evenly_spaced_route_is_the_fixed_point_of_smoothing():
    pr, planner, ends = stages("robot2_q1_q2")
    y = ends[0] + np.linspace(0.0, 1.0, 11)[:, None] * (ends[1] - ends[0])
    np.testing.assert_allclose(planner.smooth(y), y, atol=1e-12)


def test_smoothing_moves_only_to_valid_poses_and_keeps_the_ends():
    pr, planner, ends = stages("robot2_q1_q2")   # its straight line is valid (Table 1)
    rng = np.random.default_rng(5)
    line = ends[0] + np.linspace(0.0, 1.0, 15)[:, None] * (ends[1] - ends[0])
    y = line.copy()
    y[1:-1] += rng.normal(scale=0.01, size=y[1:-1].shape)
    y[1:-1] = np.where(planner.validity.pose(y[1:-1])[:, None], y[1:-1], line[1:-1])
    out = planner.smooth(y)
    np.testing.assert_array_equal(out[[0, -1]], y[[0, -1]])
    moved = np.any(out != y, axis=1)
    assert moved.any() and np.all(planner.validity.pose(out[moved]))
    polyline = lambda z: float(np.sum(np.linalg.norm(np.diff(z, axis=0), axis=1)))  # noqa: E731
    assert polyline(out) < polyline(y)


def test_resampling_keeps_the_ends_the_line_and_the_step():
    pr, planner, ends = stages("robot2_q2_q3")
    smooth = Smooth(planner.validity, planner.pose_costs, 0.5)
    y = smooth.resample(ends)
    np.testing.assert_array_equal(y[[0, -1]], ends)
    dp, da = step_sizes(planner.validity, y)
    assert np.all((dp <= CLEARANCE_STEP_M * (1 + 1e-9)) & (da <= CLEARANCE_STEP_RAD * (1 + 1e-9)))
    u = (y - ends[0]) @ (ends[1] - ends[0]) / np.sum((ends[1] - ends[0]) ** 2)
    np.testing.assert_allclose(ends[0] + u[:, None] * (ends[1] - ends[0]), y, atol=1e-12)
    lo, hi = smooth.coordinate_bounds()
    names = list(pr.task.names)
    if "theta" in names:
        assert (lo[names.index("theta")], hi[names.index("theta")]) == (0.0, math.pi)


# ----- densify ----------------------------------------------------------------------------
def test_densify_only_inserts_and_ends_dense_feasible():
    pr, planner, _ = stages("robot1_qs1_qg", strategy="gbf")
    points, _ = planner.lift(pr.start, pr.goal, pr.settings.task_tolerance)
    y, *_ = planner.route(points, Stop(max_charts=5_000), "gbf")
    sparse = y[::4] if (len(y) - 1) % 4 == 0 else np.concatenate([y[::4], y[-1:]])
    dense, verified = planner.densify.densify(sparse)
    assert verified and len(dense) >= len(sparse)
    index = [int(np.flatnonzero(np.all(dense == row, axis=1))[0]) for row in sparse]
    assert index == sorted(index) and index[0] == 0 and index[-1] == len(dense) - 1
    p, tau = pr.task.pose(dense)
    assert all(s.feasible and s.unresolved == 0
               for s in planner.validity.segments(p, quaternion_from_tau(tau)))
    path = planner.densify.planned_path(dense, verified)
    np.testing.assert_allclose(path.lengths, wrench_feasibility(pr.robot, p, tau).lengths)
    assert np.all(np.diff(path.t) > 0)


def test_densify_refuses_a_path_through_an_infeasible_pose():
    pr, planner, ends = stages("robot1_qs_qg")
    bad = ends[0] + np.linspace(0.0, 1.0, 400)[:, None] * (ends[1] - ends[0])
    assert not planner.validity.pose(bad).all()   # the straight line leaves C (Table 1)
    assert Densify(planner.validity, 1.0, 1.0)(bad) is None


# ----- time -------------------------------------------------------------------------------
def test_time_stage_checks_the_path_as_executed_and_reports_its_least_margins():
    pr, planner, ends = stages("robot2_q1_q2")
    y = planner.route.direct_points(ends[0], ends[1])
    path = planner.densify(y)
    timed = time_stage(pr.robot, path, pr.settings)
    assert timed.executed.ok and np.all(np.diff(timed.path.t) > 0)
    least, least_n = timed.least
    assert 0 < least <= float(np.min(path.margin)) + 1e-12
    f = wrench_feasibility(pr.robot, path.p, path.tau)
    assert least_n <= float(np.min(np.minimum(f.tension_min - pr.robot.tension_min,
                                              pr.robot.tension_max - f.tension_max))) + 1e-9


# ----- metrics ----------------------------------------------------------------------------
def test_task_metrics_are_distances():
    pr = load_problem(PROBLEMS / "robot2_q2_q3_free_flight.yaml")
    se3 = task_costs(pr.robot, pr.task, "se3")
    rng = np.random.default_rng(11)
    p, tau = rng.normal(scale=0.05, size=(3, 3)), rng.normal(scale=0.5, size=(3, 3))
    d = lambda a, b: float(se3(p[a], tau[a], p[b], tau[b]))  # noqa: E731
    assert d(0, 0) == pytest.approx(0.0, abs=1e-7) and d(0, 1) == pytest.approx(d(1, 0))
    assert d(0, 2) <= d(0, 1) + d(1, 2) + 1e-12
    same = float(se3(p[0], tau[0], p[1], tau[0]))
    assert same == pytest.approx(np.linalg.norm(p[1] - p[0]), rel=1e-9)
    assert isinstance(task_cost(pr.robot, pr.task)(p[0], tau[0], p[1], tau[1]), float)
    with pytest.raises(InputError) as err:
        task_costs(pr.robot, pr.task, "great_circle")
    assert err.value.field == "cost"


def test_with_a_scene_validity_is_the_least_of_wrench_and_collision_margins():
    """The one plug-in point: a ball on cable 1 halfway along Robot 2's straight
    free-flight motion makes that motion invalid, and every pose's margin is
    min(wrench margin, clearance / unit)."""
    from cdh_planner.scene.collision import COLLISION_UNIT_M
    from cdh_planner.scene.schema import scene_from_dict
    pr, planner, ends = stages("robot2_q2_q3_free_flight")
    assert planner.validity.motion(ends[0], ends[1])          # without a scene: valid
    pm, Rm = planner.validity.direct_motion(ends)(np.array([0]), np.array([0.5]))
    on_cable = 0.5 * (pr.robot.base_anchors[0] + pm[0] + Rm[0] @ pr.robot.platform_anchors[0])
    ball = {"id": "ball", "type": "sphere", "radius": 0.005, "position": on_cable.tolist()}
    v = Validity(pr.robot, pr.task, pr.settings.margin_floor,
                 scene_from_dict({"cable_radius": 0.001, "obstacles": [ball]}))
    assert not v.motion(ends[0], ends[1])
    y = v.direct_motion(ends)
    s = np.linspace(0.0, 1.0, 41)
    pp, R = y(np.zeros(s.size, dtype=int), s)
    wrench = wrench_feasibility(pr.robot, pp, R=R).margin
    clear = np.array([v.collision.clearance(a, b).margin for a, b in zip(pp, R)]) / COLLISION_UNIT_M
    np.testing.assert_allclose(v.pose_margins(pp, R=R)[0], np.minimum(wrench, clear), rtol=1e-9)
    assert np.min(clear) < 0 < np.min(wrench)
