"""``cdh-planner slice`` end to end, and the slice classification behind it."""
import struct
from pathlib import Path

import numpy as np
import pytest
import yaml

from cdh_planner import cli
from cdh_planner.wrench import wrench_feasibility
from cdh_planner.pictures import slices
from cdh_planner.model.robot import load_robot
from cdh_planner.model.task import SliceTask, SphereTask

from conftest import REPO as ROOT
ROBOT1_FILE = ROOT / "config" / "robot1.yaml"
ROBOT2_FILE = ROOT / "config" / "robot2.yaml"
SLICE1 = ["--fixed", "x=0", "y=0", "z=0.35", "sigma=34deg"]


def png_size(path):
    """(width, height) from a PNG header."""
    data = Path(path).read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


def test_robot1_slice_png_of_requested_size(tmp_path, capsys):
    out = tmp_path / "slice.png"
    rc = cli.main(["slice", str(ROBOT1_FILE), *SLICE1, "--free", "phi", "theta",
                   "--range", "phi=-pi:pi", "theta=0:pi", "--start", "-2.3", "1.6", "--goal", "1.7", "1.7",
                   "--segment", "--resolution", "60", "--size", "640x480", "-o", str(out)])
    assert rc == 0
    assert out.stat().st_size > 5000
    assert png_size(out) == (640, 480)
    text = capsys.readouterr().out
    assert "start (-2.3, 1.6): feasible" in text
    assert "goal (1.7, 1.7): feasible" in text
    assert "leaves C at s = 0.03" in text


def test_robot2_sphere_from_the_robot_files_task(tmp_path, capsys):
    # robot2.yaml carries the sphere task: no task option needed.
    out = tmp_path / "sphere.png"
    rc = cli.main(["slice", str(ROBOT2_FILE), "--range", "alpha1=-pi:pi", "alpha2=0:pi/2",
                   "--point", "q_1=0.55,pi/2", "--start", "0.55", "0.75", "--goal", "2.63", "0.75",
                   "--segment", "--resolution", "50", "-o", str(out)])
    assert rc == 0
    assert png_size(out) == (1000, 800)
    text = capsys.readouterr().out
    assert "leaves C at s = 0.04" in text
    assert "q_1 (0.55, 1.571): feasible" in text


def test_task_file_and_sphere_option_agree(tmp_path):
    task_file = tmp_path / "problem.yaml"
    task_file.write_text(yaml.safe_dump({"task": {"type": "sphere", "center": [0.0, 0.0, 0.306], "radius": 0.13}}))
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    common = ["--resolution", "20", "--size", "300x200"]
    assert cli.main(["slice", str(ROBOT2_FILE), "--task-file", str(task_file), *common, "-o", str(a)]) == 0
    assert cli.main(["slice", str(ROBOT2_FILE), "--sphere", "0,0,306mm,0.13", *common, "-o", str(b)]) == 0
    assert png_size(a) == png_size(b) == (300, 200)


def test_default_resolution_is_classified_in_whole_chunks(tmp_path, monkeypatch, capsys):
    """Fast by construction, not by a stopwatch: the default 400 x 400 grid goes to the
    feasibility test in ceil(400^2 / CHUNK) vectorised calls covering each cell once."""
    sizes = []

    def counted(robot, p, *args, **kwargs):
        sizes.append(len(p))
        return wrench_feasibility(robot, p, *args, **kwargs)

    monkeypatch.setattr(slices, "wrench_feasibility", counted)
    assert cli.main(["slice", str(ROBOT1_FILE), *SLICE1, "-o", str(tmp_path / "s.png")]) == 0
    assert "400 x 400 grid" in capsys.readouterr().out
    assert sum(sizes) == 400 * 400 and len(sizes) == -(-400 * 400 // slices.CHUNK)


@pytest.mark.parametrize("argv, text", [
    (["--fixed", "x=0", "y=0", "z=0.35"], "--free = ['phi', 'theta', 'sigma']"),
    (["--fixed", "x=0", "y=0", "z=0.35", "--free", "phi", "theta"], "add --fixed sigma=VALUE"),
    ([*SLICE1, "--range", "phi=1:0"], "LO must be below HI"),
    ([*SLICE1, "--range", "phi=a:b"], "--range phi = 'a'"),
    ([*SLICE1, "--range", "x=0:1"], "not a picture axis"),
    ([*SLICE1, "--fixed", "w=3"], "unknown coordinate"),  # repeated options accumulate
    ([*SLICE1, "--fixed", "sigma=0"], "given twice"),
    (["--fixed", "x=0", "y=0", "z=0.35", "w=1", "--free", "phi", "theta"], "unknown coordinate"),
    (["--fixed", "x=0", "y=0", "z=0.35", "sigma=0.5", "--free", "x", "phi"], "not a free coordinate"),
    ([*SLICE1, "--segment", "--start", "0", "1"], "needs both --start and --goal"),
    ([*SLICE1, "--start", "0"], "expected two values"),
    ([*SLICE1, "--resolution", "1"], "--resolution = 1"),
    ([*SLICE1, "--size", "10x10"], "--size"),
    (["--sphere", "0,0,0.3"], "CX,CY,CZ,R"),
    (["--sphere", "0,0,0.3,-1"], "must be positive"),
    (["--task-file", "/nonexistent/task.yaml"], "file not found"),
    (["--fixed", "x=0", "y=0", "z=0.35", "sigma=thirty"], "--fixed sigma = 'thirty'"),
])
def test_bad_slice_arguments_exit_2(tmp_path, capsys, argv, text):
    rc = cli.main(["slice", str(ROBOT1_FILE), *argv, "-o", str(tmp_path / "x.png")])
    err = capsys.readouterr().err
    assert rc == 2
    assert "Traceback" not in err
    assert text in err


def test_output_must_be_png_in_an_existing_directory(tmp_path, capsys):
    assert cli.main(["slice", str(ROBOT1_FILE), *SLICE1, "-o", str(tmp_path / "x.jpg")]) == 2
    assert cli.main(["slice", str(ROBOT1_FILE), *SLICE1, "-o", str(tmp_path / "no" / "x.png")]) == 2
    assert "directory does not exist" in capsys.readouterr().err


def test_robot1_without_task_is_an_error(tmp_path, capsys):
    assert cli.main(["slice", str(ROBOT1_FILE), "-o", str(tmp_path / "x.png")]) == 2
    assert "no task" in capsys.readouterr().err


# --- the classification ---------------------------------------------------------------------

def test_classes_follow_the_documented_rule():
    robot = load_robot(ROBOT1_FILE)
    view = slices.SliceView(task=SliceTask(fixed={"x": 0.0, "y": 0.0, "phi": 0.3, "theta": 0.4, "sigma": 0.0}),
                           axes=("z", "z"), ranges=((0.0, 0.7), (0.0, 0.7)))
    z = np.linspace(0.0, 0.7, 300)
    p = np.column_stack([np.zeros_like(z), np.zeros_like(z), z])
    f = wrench_feasibility(robot, p, tau=np.tile([0.3, 0.4, 0.0], (z.size, 1)))
    cls = slices.classify(f)
    length_out = np.any(f.margins[:, :2] <= 0, axis=(1, 2))
    assert np.all((cls == slices.FEASIBLE) == f.feasible)
    assert np.all((cls == slices.LENGTH_OUT) == (~f.feasible & length_out))
    assert np.all((cls == slices.TENSION_OUT) == (~f.feasible & ~length_out))
    # This line through the workspace meets all three classes.
    assert set(np.unique(cls)) == {slices.FEASIBLE, slices.LENGTH_OUT, slices.TENSION_OUT}
    assert view.coords([0.1], [0.2]).shape == (1, 1)


def test_compute_slice_matches_pointwise_evaluation():
    robot = load_robot(ROBOT2_FILE)
    task = SphereTask(center=(0.0, 0.0, 0.306), radius=0.13)
    view = slices.SliceView(task=task, axes=("alpha1", "alpha2"), ranges=((-np.pi, np.pi), (0.0, np.pi / 2)))
    grid = slices.compute_slice(robot, view, resolution=30)
    assert grid.classes.shape == (30, 30)
    j, i = 7, 21  # row (alpha2), column (alpha1)
    p, tau = task.pose([[grid.xs[i], grid.ys[j]]])
    f = wrench_feasibility(robot, p, tau)
    assert grid.margin[j, i] == pytest.approx(f.margin[0])
    assert grid.det_j[j, i] == pytest.approx(f.det_j[0])
    assert grid.classes[j, i] == slices.classify(f)[0]
    np.testing.assert_allclose(grid.xs[[0, -1]], [-np.pi + np.pi / 30, np.pi - np.pi / 30])


def test_pi_tick_labels():
    fmt = slices._pi_formatter(np.pi / 4)
    assert [fmt(k * np.pi / 4, None) for k in (-4, -3, -2, 0, 1, 2)] == [
        r"$-\pi$", r"$-3\pi/4$", r"$-\pi/2$", "0", r"$\pi/4$", r"$\pi/2$"]


def test_repeated_options_accumulate(tmp_path):
    out = tmp_path / "s.png"
    assert cli.main(["slice", str(ROBOT1_FILE), "--fixed", "x=0", "y=0", "--fixed", "z=350mm", "sigma=34deg",
                     "--range", "phi=-pi:pi", "--range", "theta=0:pi/2", "--point", "a=0,0.5", "--point", "b=1,1",
                     "--resolution", "10", "-o", str(out)]) == 0
    assert png_size(out) == (1000, 800)
