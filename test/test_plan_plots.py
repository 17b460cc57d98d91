"""Pictures of a planning query (cdh_planner.pictures.plans): geometric helpers on simple
inputs, and the PNGs of a small real query (Robot 1, theta = 0 start, Greedy Best-First)."""

from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from matplotlib.image import imread
from matplotlib.path import Path as MplPath

from cdh_planner.pictures.plans import axis_range, chart_polygons, order_by_angle, plot_plan, \
    split_at_wraps, unwrap_about, wrap, wrap_copies, zoom
from cdh_planner.parsing.problem import load_problem
from cdh_planner.model.task import SphereTask
from cdh_planner.status import Status
from cdh_planner.planner import Planner

from conftest import REPO as ROOT
PI = np.pi


# ----- helpers ------------------------------------------------------------------------------
def test_wrap_only_periodic_columns():
    y = np.array([[3.5, 3.5], [-3.5, -3.5], [PI, 0.2]])
    w = wrap(y, [True, False])
    np.testing.assert_allclose(w[:, 0], [3.5 - 2 * PI, -3.5 + 2 * PI, -PI])
    np.testing.assert_allclose(w[:, 1], y[:, 1])


def test_unwrap_about_centre_keeps_polygon_in_one_piece():
    centre = np.array([3.1, 1.0])
    poly = np.array([[3.0, 0.9], [-3.1, 0.9], [-3.1, 1.1], [3.0, 1.1]])  # straddles +-pi
    u = unwrap_about(poly, centre, [True, False])
    np.testing.assert_allclose(u[:, 0], [3.0, 2 * PI - 3.1, 2 * PI - 3.1, 3.0])
    np.testing.assert_allclose(u[:, 1], poly[:, 1])
    assert np.all(np.abs(u[:, 0] - centre[0]) < PI)


def test_order_by_angle_counter_clockwise():
    square = np.array([[1, 1], [-1, -1], [1, -1], [-1, 1]], dtype=float)
    ordered = order_by_angle(square, np.zeros(2))
    np.testing.assert_allclose(ordered, [[-1, -1], [1, -1], [1, 1], [-1, 1]])
    x, y = ordered[:, 0], ordered[:, 1]
    area = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
    assert area == pytest.approx(4.0)  # positive: counter-clockwise, not self-crossing
    np.testing.assert_allclose(order_by_angle(square + 5.0), ordered + 5.0)  # default: mean


def test_wrap_copies():
    inside = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    assert len(wrap_copies(inside, [True, False])) == 1
    over = np.array([[3.0, 0.0], [3.3, 0.0], [3.3, 1.0]])  # crosses +pi on column 0
    copies = wrap_copies(over, [True, False])
    assert len(copies) == 2
    np.testing.assert_allclose(copies[0], over)
    np.testing.assert_allclose(copies[1], over - [2 * PI, 0.0])
    under = -over
    np.testing.assert_allclose(wrap_copies(under, [True, False])[1], under + [2 * PI, 0.0])
    assert len(wrap_copies(over, [False, False])) == 1  # a non-periodic coordinate never wraps
    corner = np.array([[3.0, 3.0], [3.3, 3.0], [3.3, 3.3]])  # both periodic, both over
    assert len(wrap_copies(corner, [True, True])) == 4


def test_split_at_wraps():
    straight = np.array([[0.0, 0.5], [0.5, 0.6], [1.0, 0.7]])
    pieces = split_at_wraps(straight, [True, False])
    assert len(pieces) == 1
    np.testing.assert_allclose(pieces[0], straight)
    across = np.array([[3.0, 0.5], [3.1, 0.6], [-3.1, 0.7], [-3.0, 0.8]])
    a, b = split_at_wraps(across, [True, False])
    np.testing.assert_allclose(a, [[3.0, 0.5], [3.1, 0.6], [2 * PI - 3.1, 0.7]])
    np.testing.assert_allclose(b, [[3.1 - 2 * PI, 0.6], [-3.1, 0.7], [-3.0, 0.8]])
    assert a[-1, 0] > PI and b[0, 0] < -PI  # each piece reaches the edge
    assert len(split_at_wraps(across[:, ::-1], [False, True])) == 2
    assert len(split_at_wraps(across, [False, False])) == 1
    assert len(split_at_wraps(across[:1], [True, False])) == 1


def test_axis_range_and_zoom():
    assert axis_range("phi", [0.1, 0.2]) == (-PI, PI)
    assert axis_range("alpha2", [0.5, 1.2]) == (0.0, PI / 2)  # the lower hemisphere
    assert axis_range("alpha2", [-0.5, 1.2]) == (-PI / 2, PI / 2)
    assert axis_range("theta", [0.0, 1.7]) == (0.0, PI)
    lo, hi = axis_range("x", [0.1, 0.3])
    assert lo == pytest.approx(0.08) and hi == pytest.approx(0.32)
    full = ((-PI, PI), (0.0, PI / 2))
    data = np.array([[0.5, 0.9], [2.6, 1.5]])
    (a0, a1), (b0, b1) = zoom(full, data)
    assert a0 == pytest.approx(0.5 - 0.525) and a1 == pytest.approx(2.6 + 0.525)
    assert b0 == pytest.approx(0.75) and b1 == PI / 2  # clipped to the original range
    wide = np.array([[-3.0, 0.1], [3.0, 1.5]])
    assert zoom(full, wide) == full


# ----- a real query ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def query():
    problem = load_problem(ROOT / "config/problems/robot1_qs2_qg.yaml")
    planner = Planner(problem.robot, problem.task, replace(problem.settings, strategy="astar"))
    result = planner.plan(problem.start, problem.goal)
    assert result.success
    return planner, problem, result


def _check_png(path, width, height):
    assert Path(path).is_file()
    img = imread(path)
    assert img.shape[:2] == (height, width)
    rgb = img[..., :3].reshape(-1, 3)
    assert rgb.std() > 0.05  # not blank
    assert len(np.unique(np.round(rgb * 255).astype(int), axis=0)) > 20


def test_plot_plan_writes_both_pictures(query, tmp_path):
    planner, problem, result = query
    out = tmp_path / "plan.png"
    written = plot_plan(planner, problem, result, out, resolution=60)
    assert written == [str(out), str(tmp_path / "plan_tensions.png")]
    _check_png(written[0], 1000, 800)
    _check_png(written[1], 1200, 800)


def test_plot_plan_without_path_draws_the_atlas_only(query, tmp_path):
    planner, problem, result = query
    failed = replace(result, success=False, reason=Status.TIMEOUT, path=None)
    written = plot_plan(planner, problem, failed, tmp_path / "fail.png", resolution=40)
    assert written == [str(tmp_path / "fail.png")]
    _check_png(written[0], 1000, 800)


def test_plot_plan_three_free_coordinates_tensions_only(query, tmp_path):
    _, problem, result = query
    stub = SimpleNamespace(task=SphereTask(free_torsion=True))  # n = 3: no slice picture
    written = plot_plan(stub, problem, result, tmp_path / "n3.png")
    assert written == [str(tmp_path / "n3_tensions.png")]
    _check_png(written[0], 1200, 800)


def test_chart_polygons_contain_their_centres(query):
    planner, _, _ = query
    polys = chart_polygons(planner)
    assert len(polys) == len(planner.atlas.charts)
    kinds = {k for k, _, _ in polys}
    assert kinds <= {"closed", "open", "frontier"} and "closed" in kinds
    for kind, centre, poly in polys:
        assert poly is not None and poly.shape[1] == 2
        assert np.all(np.abs(poly[:, 0] - centre[0]) <= PI)  # unwrapped around the centre
        assert MplPath(poly).contains_point(centre, radius=1e-9) or \
            MplPath(poly).contains_point(centre, radius=-1e-9)
        x, y = poly[:, 0], poly[:, 1]
        assert abs(0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)) > 0
