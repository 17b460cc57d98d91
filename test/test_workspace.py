"""``cdh-planner workspace`` and its library (studies.workspace) without Ray: the samples are
a function of (seed, index), the point answers are verify's, the counts and fractions agree
with the poses, bounds are answers, bad input is one line and exit 2."""

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cdh_planner import cli
from cdh_planner.model.robot import load_robot
from cdh_planner.studies import workspace as ws
from cdh_planner.studies.executors import SerialExecutor
from conftest import CONFIG

ROBOT2 = CONFIG / "robot2.yaml"


@pytest.fixture(scope="module")
def robot():
    return load_robot(ROBOT2)


@pytest.fixture(scope="module")
def home(robot):
    return ws.default_home(robot, draws=20_000)


def spec_of(robot, home, **kw):
    low, high = ws.default_box(robot)
    return ws.WorkspaceSpec(**{"samples": 400, "seed": 3, "box_low": low, "box_high": high,
                               "home_position": home[0], "home_quaternion": home[1], **kw}).check()


def test_sample_i_depends_on_seed_and_index_only(robot, home):
    spec = spec_of(robot, home)
    p, q = ws.sample_poses(spec, 0, 40)
    for start, count in ((0, 1), (7, 5), (39, 1), (13, 27)):
        pp, qq = ws.sample_poses(spec, start, count)
        assert np.array_equal(pp, p[start:start + count]) and np.array_equal(qq, q[start:start + count])
    other, _ = ws.sample_poses(spec_of(robot, home, seed=4), 0, 40)
    assert not np.allclose(other, p)


def test_samples_lie_in_the_box_and_within_the_tilt(robot, home):
    spec = spec_of(robot, home, tilt=np.deg2rad(20))
    p, q = ws.sample_poses(spec, 0, 5000)
    assert np.all(p >= spec.box_low) and np.all(p <= spec.box_high)
    assert np.allclose(np.linalg.norm(q, axis=1), 1) and np.all(q[:, 3] >= 0)
    angle = (Rotation.from_quat(home[1]).inv() * Rotation.from_quat(q)).magnitude()
    assert angle.max() <= spec.tilt + 1e-12
    # uniform in the ball of rotation vectors: P(angle < t/2) = 1/8
    assert abs(np.mean(angle < spec.tilt / 2) - 1 / 8) < 0.02


def test_point_answers_equal_verify_for_the_same_poses(tmp_path, robot, home, capsys):
    spec = spec_of(robot, home, samples=60)
    res = ws.run_workspace(robot, spec, SerialExecutor())
    poses = [{"position": p, "quaternion": q} for p, q in zip(res.position.tolist(), res.quaternion.tolist())]
    (tmp_path / "poses.json").write_text(json.dumps(poses))
    cli.main(["verify", str(ROBOT2), str(tmp_path / "poses.json"), "--json", str(tmp_path / "v.json")])
    capsys.readouterr()
    verified = json.loads((tmp_path / "v.json").read_text())["poses"]
    assert [v["feasible"] for v in verified] == res.feasible.tolist()
    assert np.allclose([v["margin"] for v in verified], res.margin, rtol=0, atol=1e-12)
    assert [v["binding"] for v in verified] == res.binding


def test_counts_and_fractions_agree_with_the_poses(tmp_path, capsys):
    out = tmp_path / "w.json"
    assert cli.main(["workspace", str(ROBOT2), "--samples", "300", "--seed", "5", "--no-ray",
                     "--reach", "--timeout", "20", "--json", str(out), "--quiet"]) == 0
    doc = json.loads(out.read_text())
    poses = doc["poses"]
    assert [p["index"] for p in poses] == list(range(300))
    feasible = [p["feasible"] for p in poses]
    reachable = [p["reachable"] for p in poses]
    c, f = doc["counts"], doc["fractions"]
    assert c["feasible"] == sum(feasible) and c["evaluated"] == 300 and doc["complete"]
    assert all(p["feasible"] == (p["margin"] > 0) for p in poses)
    assert c["reachable"] == sum(r is True for r in reachable)
    assert c["unknown"] == sum(r is None for r in reachable)
    assert not any(r for r, ok in zip(reachable, feasible) if not ok)  # reachable => feasible
    assert c["planned"] == c["feasible"] == c["reachable"] + c["unreachable_feasible"] + c["unknown"]
    assert f["feasible"] == pytest.approx(c["feasible"] / 300)
    assert f["reachable"] == pytest.approx(c["reachable"] / 300) and f["reachable"] <= f["feasible"]
    assert c["reachable"] > 0 and doc["workers"] == 1
    assert "feasible" in capsys.readouterr().out


@pytest.mark.parametrize("n, workers", [(0, 2), (1, 2), (80, 2), (1000, 2), (10**5, 2), (10**5, 3200), (77, 5)])
def test_reach_calls_plan_each_target_once_in_batches_of_bounded_size(n, workers):
    targets = list(range(3, 3 + 2 * n, 2))
    calls = ws.reach_calls(targets, workers)
    assert [j for _, batch in calls for j in batch] == targets  # each once, in order
    sizes = {len(batch) for _, batch in calls[:-1]}
    assert len(sizes) <= 1 and max(sizes | {1}) <= ws.MAX_PLANS_PER_CALL
    if max(sizes | {1}) > 1:  # batched only with enough calls left for every worker
        assert len(calls) >= workers * ws.CALLS_PER_WORKER


def test_home_itself_is_reachable_with_a_zero_tilt_sample_at_home(robot, home):
    """A box of one point (the home position, +-1 um) and no tilt: every sample is home."""
    p = np.asarray(home[0])
    spec = spec_of(robot, home, samples=3, tilt=0.0, reach=True, box_low=tuple(p - 1e-6),
                   box_high=tuple(p + 1e-6))
    res = ws.run_workspace(robot, spec, SerialExecutor())
    assert res.feasible.all() and res.reachable == [True] * 3


def test_max_seconds_is_an_answer_not_an_error(robot, home):
    ticks = iter(np.arange(0.0, 1e4, 1.0))
    spec = spec_of(robot, home, samples=3 * ws.POINT_CHUNK)
    res = ws.run_workspace(robot, spec, SerialExecutor(), max_seconds=1.5, clock=lambda: next(ticks))
    assert res.stopped == "max_seconds"
    c = res.counts()
    assert 0 < c["evaluated"] < c["samples"]
    assert np.isnan(res.margin[c["evaluated"]:]).all()  # the samples not done are not counted
    assert res.fractions()["feasible"] == c["feasible"] / c["evaluated"]


@pytest.mark.parametrize("extra, field", [
    (["--samples", "0"], "--samples"),
    (["--samples", str(ws.MAX_SAMPLES + 1)], "--samples"),
    (["--seed", "-1"], "--seed"),
    (["--tilt", "200deg"], "--tilt"),
    (["--box", "0,0,0,1,1"], "--box"),
    (["--box", "0,0,0.5,0.1,0.1,0.2"], "--box"),
    (["--reach", "--timeout", "0"], "--timeout"),
    (["--reach", "--timeout", "nan"], "--timeout"),
    (["--home", "0", "0", "0", "0", "0", "0"], "--home"),   # on the base plane: not feasible
    (["--workers", "0"], "--workers"),
    (["--no-ray", "--workers", "2"], "--no-ray"),
    (["--max-seconds", "0"], "--max-seconds"),
    (["--json", "/nonexistent/dir/w.json"], "--json"),
    (["--plot", "w.txt"], "--plot"),
    (["--samples", "ten"], "--samples"),
    (["--tilt", "10deg", "--task-file", str(CONFIG / "problems" / "robot2_q2_q3.yaml")], "--tilt"),
    (["--task-file", str(CONFIG / "robot1.yaml")], "--task-file"),
])
def test_bad_input_is_one_line_naming_the_option_exit_2(extra, field, capsys):
    assert cli.main(["workspace", str(ROBOT2), "--no-ray", "--quiet", *extra]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and field in err, err


def test_plot_is_written(tmp_path, capsys):
    out = tmp_path / "w.png"
    assert cli.main(["workspace", str(ROBOT2), "--samples", "200", "--no-ray", "--plot",
                     str(out), "--quiet"]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    capsys.readouterr()


def test_no_ray_run_and_other_commands_import_no_ray():
    """Ray is a dependency of the studies' Ray executor only."""
    import subprocess
    import sys
    code = ("import sys, contextlib, io\nfrom cdh_planner import cli\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            f"    assert cli.main(['workspace', {str(ROBOT2)!r}, '--samples', '50', '--no-ray', '--quiet']) == 0\n"
            "import cdh_planner.ros.node.planner_node, cdh_planner.commands.plan, cdh_planner.commands.sweep\n"
            "print('ray' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "False"


def test_task_file_samples_lie_on_the_task_and_a_home_off_it_is_refused(tmp_path, capsys):
    """Robot 2's sphere task: every sample on the sphere (residual < 1e-12 m), the sampled
    alpha1 over [-pi, pi]; a --home off the sphere is one line naming --home, exit 2."""
    problem = CONFIG / "problems" / "robot2_q2_q3.yaml"
    out = tmp_path / "t.json"
    assert cli.main(["workspace", str(ROBOT2), "--samples", "500", "--no-ray", "--quiet",
                     "--task-file", str(problem), "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    p = np.array([q["position"] for q in doc["poses"]])
    assert np.allclose(np.linalg.norm(p - [0, 0, 0.306], axis=1), 0.13, atol=1e-12)
    assert 0 < doc["fractions"]["feasible"] < 1 and doc["task"].startswith("sphere")
    assert cli.main(["workspace", str(ROBOT2), "--no-ray", "--quiet", "--task-file", str(problem),
                     "--home", "0", "0", "0.2", "0", "0", "0"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--home" in err and "off the task" in err


def _weak_robot(tmp_path):
    """Robot 2 with tension_max 0.5 N: it holds its 0.6 kg load at no pose."""
    path = tmp_path / "weak.yaml"
    path.write_text(ROBOT2.read_text().replace("tension_max: [6.58, 6.58, 6.58, 6.58, 6.58, 6.58]",
                                               "tension_max: [0.5, 0.5, 0.5, 0.5, 0.5, 0.5]"))
    return path


def test_a_robot_that_holds_its_load_nowhere_is_said_so_in_one_line(tmp_path, capsys):
    """No --home given: the error names the robot file and why (no feasible pose among the
    default home's draws), not --home, a flag the user did not give; the sweep of that robot
    says the same (before: 0 % feasible, exit 0)."""
    weak = _weak_robot(tmp_path)
    assert cli.main(["workspace", str(weak), "--samples", "20", "--no-ray", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--home" not in err, err
    assert f"error: robot = '{weak}': holds its load nowhere: none of 100000 poses" in err, err
    sweep = tmp_path / "sweep.yaml"
    sweep.write_text(f"robot: {weak}\nvary:\n  robot.load.mass: [0.6]\n"
                     "workspace: {samples: 20}\n")
    assert cli.main(["sweep", str(sweep), "--out", str(tmp_path / "out"), "--no-ray",
                     "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "holds its load nowhere" in err, err
