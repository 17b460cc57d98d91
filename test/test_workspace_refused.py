"""``workspace --reach`` on eight cables: a sample the facet test calls feasible but where
the published tension rule's band does not fit is a goal the planner refuses
(``reach_refused``, counted as ``refused``), not a sample "without a path"."""

import numpy as np

from cdh_planner.cable_feasibility import feasibility_of, planning_feasibility
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
    k = np.flatnonzero((feasibility_of(robot, p, tau).margin > 0)
                       & (planning_feasibility(robot, p, tau).margin < 0))
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
    assert planning_feasibility(robot, sample_p, tau[None]).margin[0] < 0  # the band's
    assert res.reach_status == ["goal_infeasible"] and res.reachable == [False]
    c = res.counts()
    assert (c["refused"], c["unreachable_feasible"], c["reachable"]) == (1, 0, 0)
    doc = ws.result_dict(robot, res)
    assert doc["poses"][0]["reach_refused"] is True and doc["counts"]["refused"] == 1
