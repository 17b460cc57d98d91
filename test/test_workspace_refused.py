"""``workspace --reach`` on eight cables: a sample the facet test calls feasible but where
the published tension rule's band does not fit is a goal the planner refuses
(``reach_refused``, counted as ``refused``), not a sample "without a path"."""

import numpy as np

from cdh_planner.wrench import wrench_feasibility, band_feasibility
from cdh_planner.model.pose import quaternion_from_tau
from cdh_planner.model.robot import load_robot
from cdh_planner.studies import workspace as ws
from cdh_planner.studies.executors import SerialExecutor
from conftest import CONFIG


def _facet_feasible_band_not(robot):
    """A pose (p, tau) of robot2_8 that the facet test holds and the band rule does not."""
    low, high = ws.default_box(robot)
    rng = np.random.default_rng(0)
    p = rng.uniform(low, high, (20000, 3))
    tau = rng.uniform(-0.5, 0.5, (20000, 3))
    k = np.flatnonzero((wrench_feasibility(robot, p, tau).margin > 0)
                       & (band_feasibility(robot, p, tau).margin < 0))
    assert k.size, "no such pose among the draws"
    return p[k[0]], tau[k[0]]


def test_a_goal_whose_band_does_not_fit_is_refused_not_without_a_path():
    robot = load_robot(CONFIG / "robot2_8.yaml")
    p, tau = _facet_feasible_band_not(robot)
    q = quaternion_from_tau(tau[None])[0]
    spec = ws.WorkspaceSpec(samples=1, seed=0, box_low=tuple(p - 1e-12), box_high=tuple(p + 1e-12),
                            home_position=(0.0, 0.0, 0.15), home_quaternion=(0.0, 0.0, 0.0, 1.0),
                            tilt=0.0, tilt_about=tuple(q), reach=True, timeout_s=10.0).check()
    res = ws.run_workspace(robot, spec, SerialExecutor())
    sample_p, sample_q = ws.sample_poses(spec, 0, 1)
    assert res.feasible.tolist() == [True]  # verify's facet test
    assert band_feasibility(robot, sample_p, tau[None]).margin[0] < 0  # the band's
    assert res.reach_status == ["goal_infeasible"] and res.reachable == [False]
    c = res.counts()
    assert (c["refused"], c["unreachable_feasible"], c["reachable"]) == (1, 0, 0)
    doc = ws.result_dict(robot, res)
    assert doc["poses"][0]["reach_refused"] is True and doc["counts"]["refused"] == 1


def test_six_cable_goals_under_the_margin_floor_are_refused_naming_the_floor(capsys):
    """Robot 2 (six cables, no band): a feasible sample whose margin is under the planner's
    margin floor (1e-3) is refused as a goal because of the floor; the summary says so (before:
    "the tension rule's band does not fit", a rule six cables do not have)."""
    from cdh_planner.commands.workspace import print_summary
    robot = load_robot(CONFIG / "robot2.yaml")
    low, high = ws.default_box(robot)
    rng = np.random.default_rng(1)
    p, tau = rng.uniform(low, high, (20000, 3)), rng.uniform(-0.5, 0.5, (20000, 3))
    margin = wrench_feasibility(robot, p, tau).margin
    k = np.flatnonzero((margin > 0) & (margin < 1e-3))
    assert k.size, "no pose just inside the boundary among the draws"
    q = quaternion_from_tau(tau[k[0]][None])[0]
    spec = ws.WorkspaceSpec(samples=1, seed=0, box_low=tuple(p[k[0]] - 1e-12),
                            box_high=tuple(p[k[0]] + 1e-12), home_position=(0.0, 0.0, 0.15),
                            home_quaternion=(0.0, 0.0, 0.0, 1.0), tilt=0.0, tilt_about=tuple(q),
                            reach=True, timeout_s=10.0).check()
    res = ws.run_workspace(robot, spec, SerialExecutor())
    assert 0 < res.margin[0] < spec.settings.margin_floor
    assert res.reach_status == ["goal_infeasible"]
    c = res.counts()
    assert (c["refused"], c["refused_under_floor"], c["refused_band"]) == (1, 1, 0)
    print_summary(robot, res)
    out = capsys.readouterr().out
    assert "1 refused as goals (1 feasible but under the margin floor 0.001)" in out, out
    assert "band" not in out
