"""Search strategies are plug-ins: one registered class (search/strategies.py) is a choice of
every edge (settings, CLI, node parameter, action check, docs, pictures) and plans."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cdh_planner.cli import build_parser
from cdh_planner.errors import InputError
from cdh_planner.parsing.problem import load_problem
from cdh_planner.planner import Planner
from cdh_planner.search.strategies import STRATEGIES, AStar, GreedyBestFirst, Strategy, register
from cdh_planner.settings import SETTINGS, PlannerSettings, check_setting
from cdh_planner.status import Status

PROBLEMS = Path(__file__).resolve().parents[1] / "config" / "problems"


class WeightedAStar(AStar):
    """The test's new strategy, all of it: A* with its heuristic weighted by ``weight``."""

    name = "wastar"
    label = "weighted A*"
    description = "A* with its heuristic weighted by 2: fewer charts, a costlier route"
    admissible = True
    weight = 2.0

    def priority(self, g, h):
        return g + self.weight * h


class UnitWeightAStar(WeightedAStar):
    name = "wastar1"
    label = "weighted A* (w = 1)"
    weight = 1.0


@pytest.fixture
def registered():
    for cls in (WeightedAStar, UnitWeightAStar):
        register(cls)
    yield
    for cls in (WeightedAStar, UnitWeightAStar):
        del STRATEGIES[cls.name]


def _sub_parser(name):
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    return sub.choices[name]


def _choices(parser, dest):
    return next(a for a in parser._actions if a.dest == dest).choices


def test_a_new_strategy_is_one_class_and_a_choice_everywhere(registered):
    from cdh_planner.ros.core import params
    from cdh_planner.ros.core import plan_requests
    from cdh_planner.ros.client import plan_path_goal
    pytest.importorskip("nav_msgs")
    from ros_harness import Q2, sphere_pose_msg
    # the settings schema and its check
    assert "wastar" in SETTINGS["strategy"].choices
    assert check_setting("strategy", "wastar") == "wastar"
    assert PlannerSettings(strategy="wastar").check().strategy == "wastar"
    # the node parameter (its spec, its check and the generated docs)
    spec = params.SPEC["planner.strategy"]
    assert "wastar" in spec.choices and params.check_value(spec, "wastar") == "wastar"
    row = next(r for r in params.parameters_markdown().splitlines() if "`planner.strategy`" in r)
    assert "auto, astar, gbf, wastar" in row
    # the CLI: plan's flag and call's
    assert "wastar" in _choices(_sub_parser("plan"), "strategy")
    assert "wastar" in _choices(_sub_parser("call"), "strategy")
    # the action's check of a goal
    goal = plan_path_goal(None, sphere_pose_msg(Q2), use_current_start=True, strategy="wastar")
    assert plan_requests.goal_refusal(goal, "cdh_base", "astar") is None
    goal.strategy = "dijkstra"
    assert plan_requests.goal_refusal(goal, "cdh_base", "astar").reason is Status.BAD_STRATEGY


def test_unregistered_it_is_no_choice():
    assert "wastar" not in SETTINGS["strategy"].choices
    with pytest.raises(InputError, match="strategy"):
        check_setting("strategy", "wastar")
    with pytest.raises(SystemExit):
        _sub_parser("plan").parse_args(["problem.yaml", "--strategy", "wastar"])


def _plan(name, strategy, **settings):
    pr = load_problem(PROBLEMS / f"{name}.yaml")
    planner = Planner(pr.robot, pr.task, replace(pr.settings, strategy=strategy, **settings))
    return planner, pr, planner.plan(pr.start, pr.goal)


def test_it_plans_robot2_q2_q3_and_labels_the_picture(registered):
    from cdh_planner.pictures import plans
    planner, pr, res = _plan("robot2_q2_q3", "wastar")
    assert res.success and res.strategy == "wastar" and res.charts > 0, res.message
    assert np.isfinite(res.cost) and res.cost > 0
    assert plans._title(planner, pr, res).count("weighted A*: path found") == 1


def test_weight_one_is_a_star_exactly(registered):
    """priority g + 1 h is A*'s: the same charts, route and cost (the search is the class's)."""
    _, _, a = _plan("robot1_qs1_qg", "astar")
    _, _, w = _plan("robot1_qs1_qg", "wastar1")
    assert a.success and w.success
    assert (w.charts, w.cost, w.stats.get("expanded")) == (a.charts, a.cost, a.stats.get("expanded"))
    assert np.array_equal(w.path.tau, a.path.tau) and np.array_equal(w.path.p, a.path.p)


def test_admissible_decides_the_heuristic_under_a_clearance_cost(registered):
    """A strategy whose heuristic must be admissible gets the task metric (a lower bound of
    the clearance cost), any other the greedy heuristic; without a clearance weight, the cost."""
    pr = load_problem(PROBLEMS / "robot2_q2_q3.yaml")
    planner = Planner(pr.robot, pr.task, replace(pr.settings, clearance_weight=1.0))
    c = planner.constraint
    xs, xg = c.lift(pr.start.p, pr.start.tau), c.lift(pr.goal.p, pr.goal.tau)
    route = planner.route
    for name in ("astar", "wastar", "gbf"):
        h = route.heuristic(name)
        expect = planner.length if STRATEGIES[name].admissible else route.greedy_heuristic
        assert planner._strategy(name) == name and h(xs, xg) == expect(xs, xg)
    assert route.heuristic("wastar")(xs, xg) < planner.cost(xs, xg)
    plain = Planner(pr.robot, pr.task, replace(pr.settings, clearance_weight=0.0))
    assert plain._strategy("wastar") == "wastar" and plain.route.heuristic("wastar") is None


def test_register_refuses_what_would_be_ambiguous():
    class Auto(GreedyBestFirst):
        name = "auto"

    class Other(GreedyBestFirst):
        pass  # same name as gbf, another class

    class Unlabelled(Strategy):
        name, description = "nolabel", "a strategy without a label"

    for cls, match in ((Auto, "caller's choice"), (Other, "already registered"),
                       (Unlabelled, "label")):
        with pytest.raises(ValueError, match=match):
            register(cls)
    assert STRATEGIES["gbf"] is GreedyBestFirst and "nolabel" not in STRATEGIES
    assert register(GreedyBestFirst) is GreedyBestFirst  # registering again is harmless


def test_the_built_ins_are_the_registry():
    assert list(STRATEGIES) == ["astar", "gbf"]
    assert (AStar.admissible, GreedyBestFirst.admissible) == (True, False)
    assert AStar().priority(1.0, 2.0) == 3.0 and GreedyBestFirst().priority(1.0, 2.0) == 2.0
    assert tuple(SETTINGS["strategy"].choices) == ("auto", "astar", "gbf")
