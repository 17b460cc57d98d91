"""Bad input at the edges: every class gives exit 2 and one short line on stderr, no
traceback, within a few seconds (README, Command line: the exit-code contract).

Classes: binary and non-UTF-8 files, deep nesting, YAML alias bombs, unreadable files
(a directory, a FIFO, EIO), output paths that cannot be written, huge verify jobs,
numbers written as strings, absurd magnitudes, degenerate robots, a tiny cable speed;
and the contract itself (exit 3 for an internal error, --debug for the traceback).
"""
import errno
import json
import os
import re
import subprocess
import sys
import time

import numpy as np
import pytest
import yaml

from cdh_planner import cli, files
from cdh_planner.commands import verify as verify_cmd
from cdh_planner.errors import MAX_MESSAGE_CHARS, InputError
from cdh_planner.feasibility import evaluate
from cdh_planner.io.poses import load_poses, poses_from_obj
from cdh_planner.io.problem import load_problem
from cdh_planner.model.robot import load_robot
from cdh_planner.trajectory import verify as tv
from cdh_planner.trajectory.timing import MAX_DURATION_S, time_parameterize

from conftest import CONFIG, PROBLEMS, REPO

ROBOT1 = CONFIG / "robot1.yaml"
ROBOT2 = CONFIG / "robot2.yaml"
PROBLEM = PROBLEMS / "robot2_q2_q3.yaml"
POSE = {"position": [0.0, 0.0, 0.35], "tau": [0.0, 0.1, 0.0]}
# Only a hang or a blow-up (an alias bomb or a deep nesting expanded): a refusal takes a
# fraction of this even on a loaded machine. Not a speed test: timings are in benchmarks/.
SECONDS = 30.0


# ----------------------------------------------------------------------------- helpers

def run_cli(capsys, argv, code=2):
    """cli.main(argv) in-process: the exit code is ``code``, stderr one line (returned)
    of at most ~200 characters, no traceback, within SECONDS."""
    t0 = time.perf_counter()
    rc = cli.main([str(a) for a in argv])
    elapsed = time.perf_counter() - t0
    out = capsys.readouterr()
    assert rc == code, out.err
    lines = out.err.splitlines()
    assert len(lines) == 1, out.err
    assert lines[0].startswith("cdh-planner: error: ")
    assert len(lines[0]) <= len("cdh-planner: error: ") + MAX_MESSAGE_CHARS
    assert "Traceback" not in out.err + out.out
    assert elapsed < SECONDS, (argv, elapsed)
    return lines[0]


def run_process(argv, timeout=SECONDS + 10):
    """The real entry point as a process: (exit code, stderr lines); a hang or a blow-up
    runs into ``timeout`` (s: SECONDS and the imports)."""
    proc = subprocess.run([sys.executable, "-m", "cdh_planner.cli", *map(str, argv)],
                          capture_output=True, text=True, cwd=REPO, timeout=timeout)
    return proc.returncode, proc.stderr.splitlines()


@pytest.fixture
def poses(tmp_path):
    path = tmp_path / "poses.json"
    path.write_text(json.dumps([POSE]))
    return path


def robot_doc():
    return yaml.safe_load(ROBOT2.read_text())


def write_robot(tmp_path, **changes):
    """robot2.yaml with robot.<key> replaced (as YAML text, so YAML's own typing applies)."""
    doc = robot_doc()
    robot = doc["cdh_planner"]["ros__parameters"]["robot"]
    robot.update(changes)
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def write_problem(tmp_path, text_edit=None, **changes):
    doc = yaml.safe_load(PROBLEM.read_text())
    doc["robot"] = str(ROBOT2)
    for key, value in changes.items():
        doc[key] = value
    text = yaml.safe_dump(doc)
    if text_edit:
        text = text_edit(text)
    path = tmp_path / "problem.yaml"
    path.write_text(text)
    return path


ALIAS_BOMB = "\n".join(["a: &a [x, x, x, x, x, x, x, x, x]"] + [
    f"{b}: &{b} [*{a}, *{a}, *{a}, *{a}, *{a}, *{a}, *{a}, *{a}, *{a}]"
    for a, b in zip("abcdefgh", "bcdefghi")]) + "\n"


# ----------------------------------------------------------------------------- binary, not UTF-8

@pytest.mark.parametrize("content, text", [
    (b"\xff\xfe\x00\x01binary\x00", "not UTF-8"),
    ("name: r\xe9sum\xe9\n".encode("latin-1"), "not UTF-8"),
    (b"robot: {a: 1}\x00\x00", "NUL"),
    (bytes(range(256)) * 4, "not UTF-8"),
])
def test_binary_files_are_refused(tmp_path, capsys, poses, content, text):
    bad = tmp_path / "bad.yaml"
    bad.write_bytes(content)
    assert text in run_cli(capsys, ["verify", bad, poses])
    assert text in run_cli(capsys, ["verify", ROBOT2, bad])  # as a pose file
    assert text in run_cli(capsys, ["plan", "--quiet", bad])


# ----------------------------------------------------------------------------- nesting, sizes

def test_deep_nesting_is_refused(tmp_path, capsys, poses):
    deep = tmp_path / "deep.yaml"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    assert "nested deeper than" in run_cli(capsys, ["verify", deep, poses])
    assert "nested deeper than" in run_cli(capsys, ["plan", "--quiet", deep])
    assert "nested deeper than" in run_cli(capsys, ["verify", ROBOT2, deep])  # JSON
    nested = tmp_path / "nested.yaml"
    nested.write_text("a:\n" + "".join("  " * i + f" k{i}:\n" for i in range(1, 200)))
    assert "nested deeper than" in run_cli(capsys, ["verify", nested, poses])


def test_deep_nesting_as_a_process(tmp_path, poses):
    deep = tmp_path / "deep.yaml"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    rc, err = run_process(["verify", deep, poses])
    assert rc == 2 and len(err) == 1 and "nested deeper than" in err[0], err


def test_million_number_list_is_refused_with_a_short_line(tmp_path, capsys, poses):
    big = ",".join(["1.5"] * 1_000_000)
    pose_file = tmp_path / "big.json"
    pose_file.write_text(f'[{{"position": [{big}], "tau": [0, 0.1, 0]}}]')
    line = run_cli(capsys, ["verify", ROBOT2, pose_file])
    assert "1000000 entries" in line
    robot = tmp_path / "big.yaml"
    robot.write_text(f"cdh_planner:\n  ros__parameters:\n    robot:\n      base_anchors: [{big}]\n")
    assert "file too large" in run_cli(capsys, ["verify", robot, poses])
    # under the size limit, a long list gets a short error line too
    robot.write_text(f"cdh_planner:\n  ros__parameters:\n    robot:\n      base_anchors: [{big[:600_000]}]\n")
    assert "entries" in run_cli(capsys, ["verify", robot, poses])
    robot.write_text(f"cdh_planner:\n  ros__parameters:\n    robot:\n      base_anchors: [{big[:30_000]}]\n")
    run_cli(capsys, ["verify", robot, poses])


def test_files_over_the_size_limit_are_refused(tmp_path, capsys, poses):
    big = tmp_path / "big.yaml"
    big.write_text("# padding\n" * (files.YAML_LIMITS.max_bytes // 10 + 1))
    assert "file too large" in run_cli(capsys, ["verify", big, poses])
    assert "file too large" in run_cli(capsys, ["plan", "--quiet", big])


def test_error_lines_stay_short_whatever_the_value():
    values = [list(range(10**6)), "x" * 10**6, {str(i): i for i in range(10**5)}, 10**5000,
              [[[[[[[[[[1]]]]]]]]]], b"\x00" * 10**6, np.zeros(10**6)]
    loop = []
    loop.append(loop)
    values.append(loop)
    for value in values:
        t0 = time.perf_counter()
        message = str(InputError("robot." + "x" * 1000, value, "reason\nwith lines " * 100))
        assert len(message) <= MAX_MESSAGE_CHARS and "\n" not in message
        assert time.perf_counter() - t0 < SECONDS     # only a hang (the self-looping list)


# ----------------------------------------------------------------------------- aliases

def test_alias_bomb_is_refused_fast(tmp_path, capsys, poses):
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text(ALIAS_BOMB)
    assert len(ALIAS_BOMB) < 500
    assert "not allowed" in run_cli(capsys, ["verify", bomb, poses])
    assert "not allowed" in run_cli(capsys, ["plan", "--quiet", bomb])
    rc, err = run_process(["verify", bomb, poses])
    assert rc == 2 and len(err) == 1 and "anchors (&name) are not allowed" in err[0], err


def test_a_single_alias_is_refused(tmp_path):
    doc = robot_doc()
    text = yaml.safe_dump(doc).replace("robot:\n", "robot: &r\n", 1) + "other: *r\n"
    path = tmp_path / "r.yaml"
    path.write_text(text)
    with pytest.raises(InputError, match="not allowed"):
        load_robot(path)
    path.write_text("a: *unknown\n")
    with pytest.raises(InputError, match="aliases"):
        files.read_yaml(path, "robot")


# ----------------------------------------------------------------------------- unreadable files

def test_a_directory_is_refused(tmp_path, capsys, poses):
    assert "is a directory" in run_cli(capsys, ["verify", tmp_path, poses])
    assert "is a directory" in run_cli(capsys, ["verify", ROBOT2, tmp_path])
    assert "is a directory" in run_cli(capsys, ["plan", "--quiet", tmp_path])
    problem = write_problem(tmp_path, robot=str(tmp_path))
    assert "is a directory" in run_cli(capsys, ["plan", "--quiet", problem])


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_a_fifo_is_refused_without_blocking(tmp_path, capsys, poses):
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    assert "not a regular file" in run_cli(capsys, ["verify", fifo, poses])
    assert "not a regular file" in run_cli(capsys, ["verify", ROBOT2, fifo])


def test_a_read_error_is_refused(tmp_path, capsys, poses, monkeypatch):
    """EIO while reading (a failing disk, a special file): exit 2, one line."""
    real_open = open

    def failing_open(path, mode="r", *args, **kwargs):
        if str(path).endswith("eio.yaml"):
            raise OSError(errno.EIO, os.strerror(errno.EIO), str(path))
        return real_open(path, mode, *args, **kwargs)

    bad = tmp_path / "eio.yaml"
    bad.write_text("x: 1\n")
    monkeypatch.setattr("builtins.open", failing_open)
    assert "Input/output error" in run_cli(capsys, ["verify", bad, poses])


@pytest.mark.skipif(not os.path.exists("/proc/self/mem"), reason="no /proc")
def test_a_special_file_that_fails_to_read(capsys, poses):
    assert "cannot read" in run_cli(capsys, ["verify", "/proc/self/mem", poses])


def test_missing_files(tmp_path, capsys, poses):
    assert "file not found" in run_cli(capsys, ["verify", tmp_path / "none.yaml", poses])
    assert "file not found" in run_cli(capsys, ["plan", "--quiet", tmp_path / "none.yaml"])
    problem = write_problem(tmp_path, robot="none.yaml")
    assert "not found" in run_cli(capsys, ["plan", "--quiet", problem])


# ----------------------------------------------------------------------------- output paths

def test_outputs_are_checked_before_the_work(tmp_path, capsys, poses, monkeypatch):
    def no_planning(*args, **kwargs):
        raise AssertionError("planned before checking the outputs")

    monkeypatch.setattr("cdh_planner.commands.plan.Planner", no_planning)
    monkeypatch.setattr("cdh_planner.commands.verify.check_motion", no_planning)
    monkeypatch.setattr("cdh_planner.commands.slice.render_slice", no_planning)
    assert "is a directory" in run_cli(capsys, ["verify", ROBOT2, poses, "--json", tmp_path])
    assert "directory does not exist" in run_cli(
        capsys, ["verify", ROBOT2, poses, "--json", tmp_path / "no" / "out.json"])
    assert "is a directory" in run_cli(capsys, ["plan", "--quiet", PROBLEM, "--json", tmp_path])
    assert "is a directory" in run_cli(capsys, ["plan", "--quiet", PROBLEM, "--plot", tmp_path])
    (tmp_path / "p_tensions.png").mkdir()
    assert "p_tensions.png" in run_cli(capsys, ["plan", "--quiet", PROBLEM, "--plot", tmp_path / "p.png"])
    (tmp_path / "dir.png").mkdir()
    assert "is a directory" in run_cli(capsys, ["slice", ROBOT2, "-o", tmp_path / "dir.png"])


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full")
def test_a_full_disk_at_the_end_is_one_line(capsys, poses):
    line = run_cli(capsys, ["verify", ROBOT2, poses, "--json", "/dev/full"])
    assert "No space left on device" in line


def test_a_write_error_at_the_end_is_one_line(tmp_path, capsys, poses, monkeypatch):
    def full(self, *args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self))

    monkeypatch.setattr("pathlib.Path.write_text", full)
    line = run_cli(capsys, ["verify", ROBOT2, poses, "--json", tmp_path / "out.json"])
    assert "--json" in line and "No space left" in line


# ----------------------------------------------------------------------------- huge verify

def test_far_apart_poses_are_refused_up_front(tmp_path, capsys):
    path = tmp_path / "far.json"
    path.write_text(json.dumps([POSE, {"position": [1e6, 0.0, 0.35], "tau": [0, 0.1, 0]}]))
    assert "must be within +-1000" in run_cli(capsys, ["verify", ROBOT2, path])
    path.write_text(json.dumps([POSE, {"position": [900.0, 0.0, 0.35], "tau": [0, 0.1, 0]}]))
    assert "samples of one segment" in run_cli(capsys, ["verify", ROBOT2, path])


def test_a_tiny_step_is_refused_up_front(tmp_path, capsys):
    path = tmp_path / "two.json"
    path.write_text(json.dumps([POSE, {"position": [0.01, 0.0, 0.35], "tau": [0, 0.1, 0]}]))
    line = run_cli(capsys, ["verify", ROBOT2, path, "--step", "1e-12"])
    assert "segment 0 -> 1" in line and "samples" in line
    path.write_text(json.dumps([POSE, {"position": [0.0, 0.0, 0.35], "tau": [0, 0.2, 0]}]))
    assert "samples" in run_cli(capsys, ["verify", ROBOT2, path, "--angle-step", "1e-300"])
    assert "must be positive" in run_cli(capsys, ["verify", ROBOT2, path, "--step", "0"])


def test_too_many_samples_in_all_are_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(tv, "MAX_INITIAL_SAMPLES", 1000)
    path = tmp_path / "many.json"
    path.write_text(json.dumps([{"position": [0.0, 0.0, 0.3 + 1e-3 * (k % 2)], "tau": [0, 0.1, 0]}
                                for k in range(600)]))
    assert "samples of one check" in run_cli(capsys, ["verify", ROBOT2, path])


def test_too_many_poses_are_refused(monkeypatch):
    monkeypatch.setattr("cdh_planner.io.poses.MAX_POSES", 3)
    with pytest.raises(InputError, match="at most 3 poses"):
        poses_from_obj([POSE] * 4)


def test_verify_report_is_linear_in_the_poses():
    """The report and the JSON used to read whole-array properties per pose (O(N^2)):
    4x the poses must cost well under 16x the time."""
    robot = load_robot(ROBOT2)

    def cost(n):
        k = np.arange(n)
        poses = poses_from_obj([{"position": [0.01 * np.sin(i), 0.01 * np.cos(i), 0.3],
                                 "tau": [0.0, 0.1, 0.0]} for i in k.tolist()])
        feas = evaluate(robot, poses.positions, R=poses.rotations)
        segments = tv.check_motion(robot, poses.positions, poses.quaternions)
        best = np.inf
        for _ in range(2):
            t0 = time.perf_counter()
            with open(os.devnull, "w") as null:
                stdout, sys.stdout = sys.stdout, null
                try:
                    verify_cmd.print_report(robot, poses, feas, segments, True)
                finally:
                    sys.stdout = stdout
            verify_cmd.dump_rows(verify_cmd.result_dict(robot, poses, feas, segments, True, 1e-3, 1e-3))
            best = min(best, time.perf_counter() - t0)
        return best

    small, large = cost(2000), cost(8000)
    assert large < 8 * small, (small, large)


def test_feasibility_columns_are_computed_once():
    robot = load_robot(ROBOT2)
    f = evaluate(robot, np.array([[0.0, 0.0, 0.35]]), tau=np.array([[0.0, 0.1, 0.0]]))
    assert f.tension_min is f.tension_min and f.feasible is f.feasible


# ----------------------------------------------------------------------------- strict types

def test_numbers_as_strings_are_refused(tmp_path, capsys, poses):
    robot = write_robot(tmp_path, length_max=[0.6, "0.6", 0.6, 0.6, 0.6, 0.6])
    assert "robot.length_max[1] = '0.6': expected a number" in run_cli(capsys, ["verify", robot, poses])
    robot = write_robot(tmp_path, base_anchors=["0.1"] * 18)
    assert "robot.base_anchors[0]" in run_cli(capsys, ["verify", robot, poses])
    pose_file = tmp_path / "str.json"
    pose_file.write_text(json.dumps([{"position": [0, "0.1", 0.35], "tau": [0, 0.1, 0]}]))
    assert "poses[0].position[1]" in run_cli(capsys, ["verify", ROBOT2, pose_file])
    problem = write_problem(tmp_path, text_edit=lambda t: t.replace("radius: 0.13", "radius: '0.13'"))
    assert "task.radius = '0.13': expected a number" in run_cli(capsys, ["plan", "--quiet", problem])
    problem = write_problem(tmp_path, planner={"timeout_s": "10"})
    assert "planner.timeout_s" in run_cli(capsys, ["plan", "--quiet", problem])
    problem = write_problem(tmp_path, start={"lambda": [0.55, "0.75"]})
    assert "start.lambda[1]" in run_cli(capsys, ["plan", "--quiet", problem])


def test_yaml_1_2_floats_are_numbers_and_quoted_ones_strings():
    doc = files.parse_yaml("a: [1.0e4, 1e-3, -2E+2, .5, 3, '0.1', \"2\"]", "x")
    assert doc["a"] == [1e4, 1e-3, -200.0, 0.5, 3, "0.1", "2"]


# ----------------------------------------------------------------------------- magnitudes

def test_absurd_magnitudes_are_refused(tmp_path, capsys, poses):
    pose_file = tmp_path / "big.json"
    pose_file.write_text(json.dumps([{"position": [1e308, 0, 0.35], "tau": [0, 0.1, 0]}]))
    assert "poses[0].position[0] = 1e+308: must be within +-1000" in run_cli(
        capsys, ["verify", ROBOT2, pose_file])
    pose_file.write_text('[{"position": [1e999, 0, 0.35], "tau": [0, 0.1, 0]}]')
    assert "finite" in run_cli(capsys, ["verify", ROBOT2, pose_file])
    robot = write_robot(tmp_path, base_anchors=[1e308] + [0.1] * 17)
    assert "robot.base_anchors[0]" in run_cli(capsys, ["verify", robot, poses])
    robot = write_robot(tmp_path, tension_max=[1e300] * 6)
    assert "robot.tension_max[0]" in run_cli(capsys, ["verify", robot, poses])
    robot = write_robot(tmp_path, load={"force": [0.0, 0.0, -1e200]})
    assert "robot.load.force[2]" in run_cli(capsys, ["verify", robot, poses])
    problem = write_problem(tmp_path, task={"type": "sphere", "center": [1e308, 0.0, 0.306],
                                            "radius": 0.13, "free_torsion": False})
    assert "task.center[0]" in run_cli(capsys, ["plan", "--quiet", problem])
    problem = write_problem(tmp_path, text_edit=lambda t: t.replace("radius: 0.13", "radius: 1e308"))
    assert "task.radius" in run_cli(capsys, ["plan", "--quiet", problem])
    problem = write_problem(tmp_path, task={"type": "slice", "fixed": {"x": 0.0, "y": 0.0, "z": 1e10}})
    assert "task.fixed.z" in run_cli(capsys, ["plan", "--quiet", problem])


def test_tiny_cable_speed_is_refused(tmp_path, capsys):
    problem = write_problem(tmp_path, planner={"max_cable_speed": 1e-300})
    assert "planner.max_cable_speed = 1e-300: must be >= 0.0001" in run_cli(capsys, ["plan", "--quiet", problem])
    assert "--max-cable-speed" in run_cli(capsys, ["plan", "--quiet", PROBLEM, "--max-cable-speed", "1e-12"])
    assert "--max-cable-accel" in run_cli(capsys, ["plan", "--quiet", PROBLEM, "--max-cable-accel", "0"])


def test_timing_refuses_a_trajectory_too_long():
    L = np.linspace(0.3, 0.5, 20)[:, None] * np.ones(6)
    with pytest.raises(InputError, match="would last"):
        time_parameterize(L, 1e-300, 0.2)
    with pytest.raises(InputError, match="max_cable_speed"):
        time_parameterize(L, 1e-9, 0.2)
    assert time_parameterize(L, 1e-4, 1e-4).duration <= MAX_DURATION_S


# ----------------------------------------------------------------------------- degenerate robots

@pytest.mark.parametrize("key, anchors, text", [
    ("base_anchors", [0.1, 0.2, 0.0] * 6, "coincident"),
    ("base_anchors", [c for k in range(6) for c in (0.1 * k, 0.05 * k, 0.0)], "collinear"),
    ("platform_anchors", [0.0, 0.0, 0.0] * 6, "coincident"),
    ("platform_anchors", [c for k in range(6) for c in (0.0, 0.02 * k - 0.05, 0.0)], "collinear"),
])
def test_degenerate_robots_are_refused(tmp_path, capsys, poses, key, anchors, text):
    robot = write_robot(tmp_path, **{key: anchors})
    line = run_cli(capsys, ["verify", robot, poses])
    assert f"robot.{key}" in line and text in line


def test_singular_everywhere_is_refused_even_when_not_collinear(tmp_path):
    """Cables 1 and 2 share both anchors (A_1 = A_2, B_1 = B_2): the same line twice, so
    J has rank <= 5 at every pose, although no anchors are collinear."""
    doc = robot_doc()["cdh_planner"]["ros__parameters"]["robot"]
    A, B = list(doc["base_anchors"]), list(doc["platform_anchors"])
    A[3:6] = A[0:3]
    B[3:6] = B[0:3]
    with pytest.raises(InputError, match="J is singular at all 16 poses") as err:
        load_robot(write_robot(tmp_path, base_anchors=A, platform_anchors=B))
    assert err.value.field == "robot.base_anchors"


def test_the_shipped_robots_and_problems_stay_valid():
    for robot in CONFIG.glob("*.yaml"):
        load_robot(robot)
    for problem in PROBLEMS.glob("*.yaml"):
        load_problem(problem)


# ----------------------------------------------------------------------------- the contract

def test_internal_errors_are_exit_3_and_one_line(capsys, poses, monkeypatch):
    def broken(*args, **kwargs):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr("cdh_planner.commands.verify.evaluate", broken)
    line = run_cli(capsys, ["verify", ROBOT2, poses], code=3)
    assert "internal error: ZeroDivisionError: a bug" in line and "--debug" in line
    rc = cli.main(["--debug", "verify", str(ROBOT2), str(poses)])
    err = capsys.readouterr().err
    assert rc == 3 and "Traceback" in err and err.splitlines()[-1].startswith("cdh-planner: error:")


def test_recursion_and_memory_errors_are_internal(capsys, poses, monkeypatch):
    for exc in (RecursionError, MemoryError):
        def broken(*args, **kwargs):
            raise exc("deep")

        monkeypatch.setattr("cdh_planner.commands.verify.evaluate", broken)
        assert exc.__name__ in run_cli(capsys, ["verify", ROBOT2, poses], code=3)


def test_debug_shows_the_traceback_of_an_input_error(capsys, tmp_path, poses):
    assert cli.main(["--debug", "verify", str(tmp_path), str(poses)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" in err and "InputError" in err


def test_valid_input_still_exits_0(tmp_path, capsys, poses):
    assert cli.main(["verify", str(ROBOT2), str(poses), "--json", str(tmp_path / "o.json")]) == 0
    doc = json.loads((tmp_path / "o.json").read_text())
    assert doc["all_feasible"] is True and len(doc["poses"]) == 1
    assert re.search(r"ALL FEASIBLE", capsys.readouterr().out)


def test_loaders_raise_only_input_errors(tmp_path):
    path = tmp_path / "x.yaml"
    for text in ["", "[]", "a: b", "!!python/object:os.system {}", "? [a]\n: 1", "{a: 1, a: 2}",
                 "--- 1\n--- 2\n", "a: !!binary aGVsbG8=", "x: 2020-01-01", "x: 0x" + "f" * 5000,
                 "x: " + "9" * 5000]:
        path.write_text(text)
        for load in (load_robot, load_problem, load_poses):
            try:
                load(path)
            except InputError:
                pass


def test_command_line_quantities_are_bounded(tmp_path, capsys, poses):
    assert "--step" in run_cli(capsys, ["verify", ROBOT2, poses, "--step", "1e300"])
    assert "--angle-step" in run_cli(capsys, ["verify", ROBOT2, poses, "--angle-step", "1e300deg"])
    argv = ["slice", ROBOT1, "--fixed", "x=0", "y=0", "z=1e300", "sigma=0", "--free", "phi", "theta",
            "-o", tmp_path / "s.png"]
    assert "--fixed z" in run_cli(capsys, argv)
    argv = ["slice", ROBOT2, "--title", "x" * 10**5, "-o", tmp_path / "s.png"]
    assert "--title" in run_cli(capsys, argv)


def test_a_closed_stdout_stops_quietly(tmp_path):
    """``cdh-planner verify ... | head``: exit 141 (as SIGPIPE), nothing on stderr."""
    path = tmp_path / "many.json"
    path.write_text(json.dumps([POSE] * 3000))
    proc = subprocess.Popen([sys.executable, "-m", "cdh_planner.cli", "verify", str(ROBOT2), str(path)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=REPO)
    proc.stdout.close()
    err = proc.stderr.read()
    assert proc.wait(timeout=60) == cli.EXIT_BROKEN_PIPE
    assert err == b""
