"""Clearance (planner.clearance_weight): paths that trade length for margin.

Robot 2 q2 -> q3 at a positive weight keeps at least 0.05 N of tension margin everywhere
along the returned path (checked here at 0.25 mm / 0.05 deg steps, independently of the
planner's own report) and is at most 30 % longer than the shortest path; Robot 1 q_s -> q_g
still has a path; weight 0 is the shortest path exactly as before; the smoothing never
raises the clearance cost; the plan command reports the least margins."""
import json
import math

import numpy as np
import pytest

from cdh_planner.cli import main
from cdh_planner.wrench import wrench_feasibility
from cdh_planner.parsing.problem import load_problem
from cdh_planner.planner import Planner
from cdh_planner.trajectory import clearance
from cdh_planner.trajectory.path_check import SlerpPath, check_motion

from conftest import REPO
PROBLEMS = REPO / "config" / "problems"
WEIGHT = 1.0


def plan(name, **settings):
    pr = load_problem(PROBLEMS / f"{name}.yaml")
    for k, v in settings.items():
        setattr(pr.settings, k, v)
    planner = Planner(pr.robot, pr.task, pr.settings)
    return planner, pr, planner.plan(pr.start, pr.goal)


def dense_margins(robot, path, step_m=2.5e-4, step_rad=np.deg2rad(0.05)):
    """(least normalised margin, least tension margin N) over the motion between the
    waypoints (position linear, slerp), sampled at fixed fine steps."""
    motion = SlerpPath(path.p, path.quaternion)
    dp, da = motion.speeds()
    n = np.maximum(1, np.ceil(np.maximum(dp / step_m, da / step_rad))).astype(int) + 1
    seg = np.repeat(np.arange(motion.n_segments), n)
    s = np.concatenate([np.linspace(0.0, 1.0, k) for k in n])
    p, R = motion(seg, s)
    f = wrench_feasibility(robot, p, R=R)
    low = f.tension_nominal - f.tension_spread - robot.tension_min
    high = robot.tension_max - f.tension_nominal - f.tension_spread
    return float(f.margin.min()), float(np.minimum(low, high).min())


@pytest.fixture(scope="module")
def robot2_shortest():
    return plan("robot2_q2_q3")


def test_phi_is_scale_free_and_never_below_zero():
    m = np.array([1e-3, 2e-3, 0.1, 0.2, 0.5, 0.7])
    ph = clearance.phi(m)
    assert np.all(ph >= 0) and ph[4] == 0 and ph[5] == 0
    assert ph[0] - ph[1] == pytest.approx(math.log(2)) == ph[2] - ph[3]
    lengths = np.array([0.1, 0.2])
    np.testing.assert_array_equal(clearance.segment_costs(lengths, [0.01, 0.1, 0.3], 0.0), lengths)
    assert np.all(clearance.segment_costs(lengths, [0.01, 0.1, 0.3], 1.0) > lengths)


def test_robot2_keeps_tension_margin_at_bounded_length(robot2_shortest):
    _, _, shortest = robot2_shortest
    _, pr, res = plan("robot2_q2_q3", clearance_weight=WEIGHT)
    assert shortest.success and res.success
    assert dense_margins(pr.robot, shortest.path)[1] < 0.05  # the shortest path grazes a limit
    least, least_n = dense_margins(pr.robot, res.path)
    assert least_n >= 0.05, least_n
    assert res.cost <= 1.3 * shortest.cost, (res.cost, shortest.cost)
    assert all(s.feasible and s.unresolved == 0
               for s in check_motion(pr.robot, res.path.p, res.path.quaternion))
    # the planner's report agrees with the independent dense check
    assert res.least_tension_margin == pytest.approx(least_n, abs=1e-3)
    assert res.least_margin == pytest.approx(least, abs=1e-4)


def test_robot1_still_has_a_path_with_clearance():
    # Robot 1 has no path at all at margin_floor 0.01: clearance must not remove the
    # narrow passages the path needs
    _, _, floored = plan("robot1_qs_qg", margin_floor=0.01, strategy="gbf")
    assert not floored.success
    _, pr, res = plan("robot1_qs_qg", clearance_weight=WEIGHT)
    assert res.success, res.message
    assert all(s.feasible and s.unresolved == 0
               for s in check_motion(pr.robot, res.path.p, res.path.quaternion))
    _, _, shortest = plan("robot1_qs_qg", strategy="gbf")
    assert res.least_margin > shortest.least_margin


def test_weight_zero_is_the_shortest_path_exactly(robot2_shortest):
    planner, _, res = robot2_shortest
    # the search sees the task metric as cost and heuristic, and the Laplacian smoothing runs
    assert planner.clearance_weight == 0 and planner.cost is planner.length
    assert planner.heuristic is None and planner.strategy == "astar"
    # Table 1 (benchmarks/table1.py): 175 charts, cost 0.1808, 215 waypoints (planned; and
    # the points a controller's quintic needs, trajectory.executed)
    assert (res.charts, len(res.path) - res.stats["points_added"]) == (175, 215)
    assert res.cost == pytest.approx(0.1808494884221968, rel=1e-9)


def test_smoothing_never_raises_the_clearance_cost(robot2_shortest):
    _, pr, shortest = robot2_shortest
    planner = Planner(pr.robot, pr.task, pr.settings.__class__(clearance_weight=WEIGHT))
    route = pr.task.coords(shortest.path.p, shortest.path.tau)

    smooth, margins = planner.smooth, planner.validity.margins

    def cost(y):
        lengths = smooth.lengths(y[:-1], y[1:])
        return float(np.sum(clearance.segment_costs(lengths, margins(y), WEIGHT)))

    before = cost(smooth.resample(route))
    smoothed = smooth(route)
    assert cost(smoothed) < 0.9 * before
    assert np.all(margins(smoothed) >= pr.settings.margin_floor)
    np.testing.assert_array_equal(smoothed[[0, -1]], route[[0, -1]])


def test_plan_command_reports_the_least_margins(tmp_path, capsys):
    out = tmp_path / "r.json"
    code = main(["plan", str(PROBLEMS / "robot2_q2_q3.yaml"), "--quiet", "--json", str(out),
                 "--clearance-weight", str(WEIGHT)])
    assert code == 0
    doc = json.loads(out.read_text())
    assert doc["least_tension_margin_n"] >= 0.05
    assert 0 < doc["least_margin"] <= min(w["margin"] for w in doc["path"]) + 1e-9
    line = capsys.readouterr().out
    assert f"least margin {doc['least_margin']:.4f} ({doc['least_tension_margin_n']:.3g} N)" in line


def test_node_plan_result_carries_the_least_margins():
    pytest.importorskip("diagnostic_msgs")
    from builtin_interfaces.msg import Time
    from cdh_planner.ros.core import plan_requests
    _, pr, res = plan("robot2_q1_q2", clearance_weight=WEIGHT)
    status = plan_requests.result_status(res, pr.robot, "r#1", "", Time(sec=1))
    values = {kv.key: kv.value for kv in status.values}
    assert float(values["least_margin"]) == res.least_margin
    assert float(values["least_tension_margin_n"]) == res.least_tension_margin
    assert float(values["least_margin"]) <= float(values["min_margin"]) + 1e-9
