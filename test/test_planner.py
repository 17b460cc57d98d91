"""The planner end to end: paths of the paper's 2-D queries, no-path answers, periodic
angles, theta = 0 starts, multi-query, and the plan command's bad input."""
import json

import numpy as np
import pytest

from cdh_planner.cli import main
from cdh_planner.wrench import wrench_feasibility
from cdh_planner.parsing.problem import load_problem
from cdh_planner.model.pose import quaternion_from_tau
from cdh_planner.planner import Planner, PlannerSettings, Pose
from cdh_planner.search.strategies import Stop, run
from cdh_planner.status import Status
from cdh_planner.trajectory.path_check import check_motion, check_task_motion

from conftest import REPO as ROOT
PROBLEMS = ROOT / "config" / "problems"
SIGMA1 = 0.593411945678072
ROBOT1_SLICE = ("task: {type: slice, fixed: {x: 0.0, y: 0.0, z: 0.35, sigma: %r}}\n" % SIGMA1)


def robot1_problem(tmp_path, name, start, goal):
    text = (f"robot: {ROOT / 'config' / 'robot1.yaml'}\n" + ROBOT1_SLICE +
            f"start: {{position: [0.0, 0.0, 0.35], tau: [{start[0]}, {start[1]}, {SIGMA1}]}}\n"
            f"goal: {{position: [0.0, 0.0, 0.35], tau: [{goal[0]}, {goal[1]}, {SIGMA1}]}}\n")
    path = tmp_path / f"{name}.yaml"
    path.write_text(text)
    return path


def plan(problem, **settings):
    pr = load_problem(problem) if not hasattr(problem, "robot") else problem
    s = pr.settings
    for k, v in settings.items():
        setattr(s, k, v)
    planner = Planner(pr.robot, pr.task, s)
    return planner, pr, planner.plan(pr.start, pr.goal)


def assert_dense_feasible(robot, path, start, goal):
    """Every waypoint and the motion between them (position linear, slerp) is feasible,
    the path joins start to goal, times increase, lengths are the poses' lengths."""
    assert np.all(wrench_feasibility(robot, path.p, path.tau).feasible)
    assert np.all(path.margin > 0)
    segments = check_motion(robot, path.p, path.quaternion)
    assert all(s.feasible and s.unresolved == 0 for s in segments)
    np.testing.assert_allclose(path.p[0], start.p, atol=1e-9)
    np.testing.assert_allclose(path.p[-1], goal.p, atol=1e-9)
    for k, pose in ((0, start), (-1, goal)):
        q = quaternion_from_tau(pose.tau)
        assert abs(abs(float(q @ path.quaternion[k])) - 1.0) < 1e-9
    assert np.all(np.diff(path.t) > 0)
    np.testing.assert_allclose(path.lengths, wrench_feasibility(robot, path.p, path.tau).lengths)


@pytest.mark.parametrize("name,strategy", [("robot2_q1_q2", "astar"), ("robot2_q2_q3", "gbf"),
                                           ("robot1_qs2_qg", "gbf"),
                                           ("robot2_q2_q3_sigma_free", "gbf"),
                                           ("robot2_q2_q3_free_flight", "gbf")])
def test_table1_2d_queries_give_dense_feasible_paths(name, strategy):
    planner, pr, res = plan(PROBLEMS / f"{name}.yaml", strategy=strategy)
    assert res.success, res.message
    assert res.reason == "ok" and res.n == len(pr.task.names)
    assert res.charts > 1 or res.stats["direct"]  # q1 -> q2 and free flight: the direct motion is safe
    assert_dense_feasible(pr.robot, res.path, pr.start, pr.goal)
    # every waypoint lies on the task (sphere / slice) and the cost is the task metric
    assert float(np.max(pr.task.residual(res.path.p, res.path.tau))) < 1e-6
    assert res.cost >= planner.pose_cost(pr.start.p, pr.start.tau, pr.goal.p, pr.goal.tau) - 1e-9


def test_q2_q3_path_exists_where_the_straight_line_fails():
    planner, pr, res = plan(PROBLEMS / "robot2_q2_q3.yaml", strategy="astar")
    assert res.success
    ends = pr.task.coords(np.array([pr.start.p, pr.goal.p]), np.array([pr.start.tau, pr.goal.tau]))
    assert not check_task_motion(pr.robot, pr.task, ends)[0].feasible


def test_different_components_answer_no_path(tmp_path):
    """The island of C around (phi, theta) = (-1.3, 2.0) is not connected to q_g: it lies
    across det J = 0 (J is never singular on C), known before any chart (the search alone
    exhausts the island: test_six_d)."""
    problem = robot1_problem(tmp_path, "island", (-1.3, 2.0), (1.7, 1.7))
    _, pr, res = plan(problem, strategy="gbf")
    assert not res.success and res.reason == "no_path"
    assert "singularity det J = 0" in res.message and res.path is None and res.charts == 0
    det = wrench_feasibility(pr.robot, np.array([pr.start.p, pr.goal.p]), np.array([pr.start.tau, pr.goal.tau])).det_j
    assert det[0] * det[1] < 0
    ends = pr.task.coords(np.array([pr.start.p, pr.goal.p]), np.array([pr.start.tau, pr.goal.tau]))
    assert not check_task_motion(pr.robot, pr.task, ends)[0].feasible


def test_path_across_phi_pi(tmp_path):
    problem = robot1_problem(tmp_path, "wrap", (2.8, 0.4), (-2.8, 0.4))
    _, pr, res = plan(problem)
    assert res.success
    assert_dense_feasible(pr.robot, res.path, pr.start, pr.goal)
    phi = res.path.tau[:, 0]
    assert np.all(np.abs(phi) > 2.0)  # went across +-pi, not the long way through 0
    assert res.cost < 0.5


def test_start_on_theta_zero(tmp_path):
    problem = robot1_problem(tmp_path, "pole", (-2.3, 0.0), (-1.0, 0.3))
    _, pr, res = plan(problem)
    assert res.success, res.message
    assert res.path.tau[0, 1] == pytest.approx(0.0, abs=1e-12)
    assert_dense_feasible(pr.robot, res.path, pr.start, pr.goal)


def test_second_query_reuses_the_atlas():
    pr = load_problem(PROBLEMS / "robot2_q2_q3.yaml")  # q1 -> q2 is a direct motion: no atlas
    planner = Planner(pr.robot, pr.task, pr.settings)
    first = planner.plan(pr.start, pr.goal)
    n_charts = len(planner.atlas.charts)
    again = planner.plan(pr.goal, pr.start)  # reversed, inside the same atlas
    assert first.success and again.success
    # the reuse is in the charts, not in a timing: little growth (open charts on the way)
    assert len(planner.atlas.charts) <= 1.25 * n_charts
    assert again.cost == pytest.approx(first.cost, rel=0.05)


def test_infeasible_start_and_goal_are_refused():
    pr = load_problem(PROBLEMS / "robot2_q1_q2.yaml")
    planner = Planner(pr.robot, pr.task, pr.settings)
    bad = Pose(*[a[0] for a in pr.task.pose(np.array([[1.0, 0.0]]))])  # on the equator: not feasible
    assert not wrench_feasibility(pr.robot, bad.p[None], bad.tau[None]).feasible[0]
    res = planner.plan(bad, pr.goal)
    assert (res.success, res.reason) == (False, "start_infeasible") and "violated" in res.message
    res = planner.plan(pr.start, bad)
    assert (res.success, res.reason) == (False, "goal_infeasible")
    off = Pose(pr.start.p + np.array([0.01, 0.0, 0.0]), pr.start.tau)
    res = planner.plan(off, pr.goal)
    assert res.reason == "invalid" and "off the sphere task" in res.message


def test_timeout_and_chart_limit_are_reported():
    _, _, res = plan(PROBLEMS / "robot1_qs_qg.yaml", max_charts=20)
    assert (res.success, res.reason) == (False, "chart_limit")
    _, _, res = plan(PROBLEMS / "robot1_qs_qg.yaml", timeout_s=0.05)
    assert (res.success, res.reason) == (False, "timeout")


# ----- the command line ----------------------------------------------------------------
def test_plan_command_writes_the_json_contract(tmp_path, capsys):
    out = tmp_path / "r.json"
    code = main(["plan", str(PROBLEMS / "robot2_q1_q2.yaml"), "--quiet", "--json", str(out)])
    assert code == 0
    doc = json.loads(out.read_text())
    for key in ("success", "reason", "strategy", "n", "m", "charts", "time_s", "cost", "path"):
        assert key in doc
    assert doc["success"] and doc["n"] == 2 and doc["m"] == 92
    w = doc["path"][0]
    for key in ("p", "quaternion", "tau", "lengths", "tension_min", "tension_nominal",
                "tension_max", "t"):
        assert key in w
    assert len(w["lengths"]) == 6 and len(w["quaternion"]) == 4
    assert "path found" in capsys.readouterr().out


def test_plan_command_no_path_exits_1(tmp_path, capsys):
    problem = robot1_problem(tmp_path, "island", (-1.3, 2.0), (1.7, 1.7))
    assert main(["plan", str(problem), "--quiet", "--strategy", "gbf"]) == 1
    assert "no path (no_path)" in capsys.readouterr().out


BAD = {
    "unknown task type": ("task: {type: torus}", "task.type"),
    "missing goal": ("goal: null", "goal"),
    "negative radius": ("planner: {radius: -0.1}", "planner.radius"),  # 0: by the dimension
    "margin floor 1": ("planner: {margin_floor: 1.0}", "planner.margin_floor"),
    "string for a number": ("planner: {timeout_s: '5'}", "planner.timeout_s"),
    "start off the sphere": ("start: {position: [0.0, 0.0, 0.2], tau: [0.0, 0.0, 0.0]}", None),
    "NaN in start": ("start: {position: [.nan, 0.0, 0.2], tau: [0.0, 0.0, 0.0]}", "start.position[0]"),
    "lambda on a slice": (None, "start.lambda"),
    "unknown key": ("speed: 3", "speed"),
    "bad strategy": ("strategy: dijkstra", "strategy"),
}


@pytest.mark.parametrize("case", BAD)
def test_bad_problems_give_a_clear_error(case, tmp_path, capsys):
    line, field = BAD[case]
    text = (PROBLEMS / "robot2_q1_q2.yaml").read_text().replace("../robot2.yaml", str(ROOT / "config" / "robot2.yaml"))
    if case == "lambda on a slice":
        text = robot1_problem(tmp_path, "x", (-2.3, 1.6), (1.7, 1.7)).read_text() + "\n"
        text = text.replace("start: {position: [0.0, 0.0, 0.35], tau: [-2.3, 1.6, %r]}" % SIGMA1,
                            "start: {lambda: [0.1, 0.2, 0.3]}")  # the slice has 2 coordinates
    else:
        key = line.split(":")[0]
        lines = [ln for ln in text.splitlines() if not ln.startswith(key + ":")]
        text = "\n".join(lines + ([line] if line != "goal: null" else [])) + "\n"
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    code = main(["plan", str(path), "--quiet"])
    err = capsys.readouterr()
    assert code != 0
    assert "Traceback" not in err.err + err.out
    if field is not None:
        assert code == 2 and field in err.err
    else:
        assert code == 1 and "off the sphere task" in err.out


def test_radius_option_is_validated(capsys):
    assert main(["plan", str(PROBLEMS / "robot2_q1_q2.yaml"), "--radius", "-1"]) == 2
    assert "--radius" in capsys.readouterr().err


def test_implicit_task_constraint(tmp_path):
    """Eq. 15: the Robot 1 slice written as C(p, tau) = 0 plans like the slice."""
    from cdh_planner.model.pose import wrap_angle
    from cdh_planner.model.task import ImplicitTask

    def slice_equations(p, tau):
        C = np.array([p[0], p[1], p[2] - 0.35, wrap_angle(tau[2] - SIGMA1)])
        dC = np.zeros((4, 6))
        dC[0, 0] = dC[1, 1] = dC[2, 2] = dC[3, 5] = 1.0
        return C, dC

    pr = load_problem(robot1_problem(tmp_path, "implicit", (1.7, 0.0), (1.7, 1.7)))
    task = ImplicitTask(slice_equations, 4)
    planner = Planner(pr.robot, task, PlannerSettings(strategy="gbf"))
    res = planner.plan(pr.start, pr.goal)
    assert res.success and res.n == 2
    assert float(np.max(task.residual(res.path.p, res.path.tau))) < 1e-6
    assert_dense_feasible(pr.robot, res.path, pr.start, pr.goal)


def test_complete_atlas_closes_every_chart(tmp_path):
    """--complete: after the goal, the start's component (the island) is covered."""
    problem = robot1_problem(tmp_path, "island2", (-1.3, 2.0), (-1.2, 1.9))
    planner, pr, res = plan(problem, strategy="gbf", complete=True)
    assert res.success
    assert all(ch.closed for ch in planner.atlas.charts)
    # the search from both ends (alone: the planner answers this pair before any chart,
    # across det J = 0) grows the goal's side as much as the island until the island is
    # exhausted: about twice the island's charts
    pr = load_problem(robot1_problem(tmp_path, "island", (-1.3, 2.0), (1.7, 1.7)))
    other = Planner(pr.robot, pr.task, pr.settings)
    c = other.constraint
    out = run(other.atlas, c.lift(pr.start.p, pr.start.tau), c.lift(pr.goal.p, pr.goal.tau), other.cost,
              Stop(max_charts=20_000), "gbf", other.route.direct_x, link_ok=other.route.link_ok,
              route_check=other.route.route_unsafe)
    assert out.status == Status.NO_PATH
    island = len(planner.atlas.charts)
    assert 0.8 * island < len(other.atlas.charts) < 2.4 * island


def test_a_call_may_override_the_strategy_and_the_time_limit():
    """PlanPath's per-goal strategy and timeout_s: the call's own, checked, the settings
    untouched."""
    from cdh_planner.errors import InputError
    pr = load_problem(PROBLEMS / "robot2_q2_q3.yaml")
    planner = Planner(pr.robot, pr.task, PlannerSettings(strategy="astar"))
    assert planner.plan(pr.start, pr.goal, strategy="gbf").strategy == "gbf"
    late = planner.plan(pr.start, pr.goal, strategy="astar", timeout_s=1e-9)
    assert late.reason == "timeout" and "1e-09 s" in late.message
    assert planner.settings.strategy == "astar" and planner.settings.timeout_s == 60.0
    for field, kwargs in (("strategy", {"strategy": "bfs"}), ("timeout_s", {"timeout_s": -1.0}),
                          ("timeout_s", {"timeout_s": float("nan")})):
        with pytest.raises(InputError) as err:
            planner.plan(pr.start, pr.goal, **kwargs)
        assert err.value.field == field


def test_a_cancel_stops_the_complete_atlas_growth_too():
    """A cancel during --complete's growth (after the path is found) ends it at once: the
    node's cancel bound holds in every phase."""
    pr = load_problem(PROBLEMS / "robot2_q1_q2.yaml")   # a direct motion: no search
    planner = Planner(pr.robot, pr.task, PlannerSettings(complete=True, radius=0.02))

    class CancelAt:
        """Set from the AT-th poll on (the growth polls once per chart expansion); counts
        the polls that saw it set and the charts there were then."""
        AT = 20

        def __init__(self):
            self.polls, self.seen_set, self.charts = 0, 0, None

        def is_set(self):
            self.polls += 1
            if self.polls < self.AT:
                return False
            self.seen_set += 1
            self.charts = self.charts or len(planner.atlas.charts)
            return True

    cancel = CancelAt()
    res = planner.plan(pr.start, pr.goal, cancel=cancel)
    assert res.success                       # the path was found before the cancel
    # the growth ended at the first poll that saw the cancel: no chart after it; the second
    # look is the time stage's (a cancel before it leaves the path's check to run to the end)
    assert cancel.seen_set == 2 and len(planner.atlas.charts) == cancel.charts
    assert not all(ch.closed for ch in planner.atlas.charts)   # growth cut short


def test_start_equal_to_goal_gives_a_path_that_stays(tmp_path):
    problem = robot1_problem(tmp_path, "same", (-2.3, 1.6), (-2.3, 1.6))
    _, pr, res = plan(problem)
    assert res.success and len(res.path) == 2 and res.cost == 0.0
    assert np.all(np.diff(res.path.t) > 0)
    np.testing.assert_allclose(res.path.p[0], res.path.p[1])


def test_a_pose_within_the_task_tolerance_is_projected_onto_the_task():
    """Robot 2's q1 -> q2 written to 6 decimals is about 3e-6 off the sphere: within the
    default task_tolerance (1e-3) it plans from the projected poses; with a tighter
    tolerance it is refused, naming the distance."""
    from dataclasses import replace as _replace
    from cdh_planner.planner import Pose, PlannerSettings
    pr = load_problem(PROBLEMS / "robot2_q1_q2.yaml")
    start, goal = (Pose(np.round(q.p, 6), np.round(q.tau, 6)) for q in (pr.start, pr.goal))
    off = pr.task.residual(np.array([goal.p]), np.array([goal.tau]))[0]
    assert 1e-7 < off < 1e-3
    res = Planner(pr.robot, pr.task, pr.settings).plan(start, goal)
    off = pr.task.residual(res.path.p, res.path.tau)
    assert res.success and off[0] < 1e-9 and off[-1] < 1e-9
    # the points added for a controller (trajectory.executed) are samples of the timed
    # spline motion, which leaves the sphere by up to ~1e-6 m between planned waypoints
    assert off.max() < 5e-6 and np.sum(off < 1e-9) >= len(off) - res.stats["points_added"]
    tight = Planner(pr.robot, pr.task, _replace(pr.settings, task_tolerance=1e-8)).plan(start, goal)
    assert tight.reason == "invalid" and "beyond the tolerance 1e-08" in tight.message
    assert not Planner(pr.robot, pr.task, PlannerSettings()).plan(start, goal, tolerance=1e-8).success
