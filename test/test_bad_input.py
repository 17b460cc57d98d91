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

from cdh_planner import cli
from cdh_planner import files
from cdh_planner.commands import verify as verify_cmd
from cdh_planner.errors import MAX_MESSAGE_CHARS, InputError
from cdh_planner.wrench import wrench_feasibility
from cdh_planner.parsing.poses import load_poses, poses_from_obj
from cdh_planner.parsing.problem import load_problem
from cdh_planner.model.robot import load_robot
from cdh_planner.trajectory import path_check as tv
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
    (tmp_path / "d.png").mkdir()
    assert "is a directory" in run_cli(capsys, ["plan", "--quiet", PROBLEM, "--plot",
                                                tmp_path / "d.png"])
    assert "expected a .png file" in run_cli(capsys, ["plan", "--quiet", PROBLEM, "--plot",
                                                      tmp_path / "out.txt"])
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
    monkeypatch.setattr("pathlib.Path.write_bytes", full)
    monkeypatch.setattr("cdh_planner.commands.outputs.write_pieces", full)  # verify's JSON
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
    monkeypatch.setattr("cdh_planner.parsing.poses.MAX_POSES", 3)
    with pytest.raises(InputError, match="at most 3 poses"):
        poses_from_obj([POSE] * 4)


def test_verify_report_is_linear_in_the_poses():
    """The report and the JSON used to read whole-array properties per pose (O(N^2)): the
    whole-array reads of the feasibility record are counted (not timed), and 4x the poses
    must not read more of them."""
    robot = load_robot(ROBOT2)

    class Counted:
        """The record, counting the reads that return an array of one entry per pose."""
        def __init__(self, record, n):
            self._record, self._n, self.reads = record, n, 0

        def __getattr__(self, name):
            value = getattr(self._record, name)
            if isinstance(value, np.ndarray) and value.shape[:1] == (self._n,):
                self.reads += 1
            return value

    def array_reads(n):
        k = np.arange(n)
        poses = poses_from_obj([{"position": [0.01 * np.sin(i), 0.01 * np.cos(i), 0.3],
                                 "tau": [0.0, 0.1, 0.0]} for i in k.tolist()])
        feas = Counted(wrench_feasibility(robot, poses.positions, R=poses.rotations), n)
        segments = tv.check_motion(robot, poses.positions, poses.quaternions)
        with open(os.devnull, "w") as null:
            stdout, sys.stdout = sys.stdout, null
            try:
                verify_cmd.print_report(robot, poses, feas, segments, True)
            finally:
                sys.stdout = stdout
        verify_cmd.result_json(robot, poses, feas, segments, True, 1e-3, 1e-3)
        return feas.reads

    small, large = array_reads(500), array_reads(2000)
    assert 0 < large <= small, (small, large)


def test_feasibility_columns_are_computed_once():
    robot = load_robot(ROBOT2)
    f = wrench_feasibility(robot, np.array([[0.0, 0.0, 0.35]]), tau=np.array([[0.0, 0.1, 0.0]]))
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

    monkeypatch.setattr("cdh_planner.commands.verify.wrench_feasibility", broken)
    line = run_cli(capsys, ["verify", ROBOT2, poses], code=3)
    assert "internal error: ZeroDivisionError: a bug" in line and "--debug" in line
    rc = cli.main(["--debug", "verify", str(ROBOT2), str(poses)])
    err = capsys.readouterr().err
    assert rc == 3 and "Traceback" in err and err.splitlines()[-1].startswith("cdh-planner: error:")


def test_recursion_and_memory_errors_are_internal(capsys, poses, monkeypatch):
    for exc in (RecursionError, MemoryError):
        def broken(*args, **kwargs):
            raise exc("deep")

        monkeypatch.setattr("cdh_planner.commands.verify.wrench_feasibility", broken)
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


# ----------------------------------------------------------------------------- outputs vs inputs

def _problem_copy(tmp_path):
    """A problem file in tmp_path naming a robot file copied beside it: (problem, robot)."""
    robot = tmp_path / "robot.yaml"
    robot.write_text(ROBOT2.read_text())
    problem = tmp_path / "problem.yaml"
    problem.write_text(PROBLEM.read_text().replace("../robot2.yaml", "robot.yaml"))
    return problem, robot


def test_plan_json_onto_its_problem_file_is_refused_as_a_process(tmp_path):
    """Found by the bad-input campaign: ``plan P.yaml --json P.yaml`` replaced P.yaml with its JSON."""
    problem, _ = _problem_copy(tmp_path)
    before = problem.read_bytes()
    rc, err = run_process(["plan", "--quiet", problem, "--json", problem])
    assert rc == 2 and len(err) == 1, err
    assert "--json" in err[0] and "the problem file" in err[0] and str(problem) in err[0]
    assert problem.read_bytes() == before


def test_no_output_names_an_input(tmp_path, capsys, poses, monkeypatch):
    """Every output option of every command, against every input of the command: the
    same name, a symbolic link, a hard link, a path through ``..``; refused before the
    work, the input unchanged."""
    def no_work(*args, **kwargs):
        raise AssertionError("worked before checking the outputs")

    monkeypatch.setattr("cdh_planner.commands.plan.Planner", no_work)
    monkeypatch.setattr("cdh_planner.commands.verify.check_motion", no_work)
    monkeypatch.setattr("cdh_planner.commands.slice.render_slice", no_work)
    problem, robot = _problem_copy(tmp_path)
    (tmp_path / "sub").mkdir()
    (tmp_path / "link.yaml").symlink_to(problem)
    os.link(robot, tmp_path / "hard.yaml")
    png = tmp_path / "robot.png"   # a robot file under a picture's name
    png.write_text(ROBOT2.read_text())
    task = tmp_path / "task.png"
    task.write_text("task: {type: sphere, center: [0.0, 0.0, 0.306], radius: 0.13}\n")
    before = {f: f.read_bytes() for f in (problem, robot, poses, png, task)}
    cases = [
        (["plan", "--quiet", problem, "--json", problem], "the problem file"),
        (["plan", "--quiet", problem, "--json", tmp_path / "link.yaml"], "the problem file"),
        (["plan", "--quiet", problem, "--json", tmp_path / "sub" / ".." / "problem.yaml"],
         "the problem file"),
        (["plan", "--quiet", problem, "--json", robot], "the robot file"),
        (["plan", "--quiet", problem, "--json", tmp_path / "hard.yaml"], "the robot file"),
        (["plan", "--quiet", problem, "--json", tmp_path / "o.png", "--plot",
          tmp_path / "o.png"], "the --json output"),
        (["plan", "--quiet", problem, "--json", tmp_path / "o_tensions.png", "--plot",
          tmp_path / "o.png"], "the --json output"),
        (["verify", robot, poses, "--json", poses], "the poses file"),
        (["verify", robot, poses, "--json", tmp_path / "hard.yaml"], "the robot file"),
        (["slice", png, "--sphere", "0,0,0.306,0.13", "-o", png], "the robot file"),
        (["slice", ROBOT2, "--task-file", task, "-o", task], "the --task-file"),
    ]
    for argv, label in cases:
        line = run_cli(capsys, argv)
        assert label in line, (argv, line)
    assert {f: f.read_bytes() for f in before} == before


def test_recover_onto_its_run_file_is_refused(tmp_path, capsys):
    run = tmp_path / "run.mcap"
    _write_recording(run)
    before = run.read_bytes()
    (tmp_path / "link.mcap").symlink_to(run)
    for out in (run, tmp_path / "link.mcap"):
        assert "the run file" in run_cli(capsys, ["recover", run, "-o", out])
    assert run.read_bytes() == before


def test_demo_out_dir_may_not_overwrite_its_robot_files(tmp_path, capsys):
    """``demo --out D --config-dir C``: none of the demo's files in D may be one of C's
    robot files (here C/robot1.yaml is a link to D/node.log, which the demo writes)."""
    out, config = tmp_path / "out", tmp_path / "config"
    out.mkdir(), config.mkdir()
    (config / "robot2.yaml").write_text(ROBOT2.read_text())
    (out / "node.log").write_text(ROBOT1.read_text())
    (config / "robot1.yaml").symlink_to(out / "node.log")
    line = run_cli(capsys, ["demo", "--out", out, "--config-dir", config])
    assert "node.log" in line and "robot1.yaml" in line


def _write_recording(path, n=3):
    """A small complete run file (RunRecorder; needs the ROS 2 message packages)."""
    pytest.importorskip("mcap_ros2")
    JointState = pytest.importorskip("sensor_msgs.msg").JointState
    from cdh_planner.recording.mcap_log import RunRecorder
    with RunRecorder(path) as rec:
        for i in range(n):
            rec.write("/cmd", JointState(name=["w"], position=[float(i)]), 1000 + i)
    return path


# ----------------------------------------------------------------------------- duplicate keys

def test_a_duplicate_json_key_is_refused_as_a_process(tmp_path):
    """Found by the bad-input campaign: json keeps the last of two equal keys; a pose file with two
    positions was accepted silently."""
    path = tmp_path / "dup.json"
    path.write_text('[{"position": [1e308, 0, 0.35], "position": [0, 0, 0.35], '
                    '"tau": [0, 0.1, 0]}]')
    rc, err = run_process(["verify", ROBOT2, path])
    assert rc == 2 and len(err) == 1, err
    assert "duplicate key 'position'" in err[0] and str(path) in err[0]


@pytest.mark.parametrize("text, key", [
    ('{"poses": [{"position": [0, 0, 0.35], "tau": [0, 0.1, 0], "tau": [0, 0.2, 0]}]}', "tau"),
    ('{"poses": [], "poses": [{"position": [0, 0, 0.35], "tau": [0, 0.1, 0]}]}', "poses"),
])
def test_duplicate_json_keys_are_refused_at_any_depth(tmp_path, capsys, text, key):
    path = tmp_path / "dup.json"
    path.write_text(text)
    assert f"duplicate key {key!r}" in run_cli(capsys, ["verify", ROBOT2, path])
    json.loads(text.replace(f'"{key}": [0, 0.2, 0]', '"x": 1'))  # valid JSON otherwise


def test_duplicate_yaml_keys_are_refused(tmp_path, capsys, poses):
    """In a problem file (top level), a robot file (nested): the key and its line named;
    1 and 1.0 are one key (equal in Python); a merge key's entries may be overridden."""
    text = PROBLEM.read_text().replace("../robot2.yaml", str(ROBOT2))
    problem = tmp_path / "p.yaml"
    problem.write_text(text + "goal: {lambda: [2.63, 0.7]}\n")
    line = run_cli(capsys, ["plan", "--quiet", problem])
    assert "duplicate key 'goal'" in line and f"line {len(text.splitlines()) + 1}," in line
    robot = tmp_path / "r.yaml"
    robot.write_text(ROBOT2.read_text().replace("robot:\n", "robot:\n      name: a\n      name: b\n", 1))
    assert "duplicate key 'name'" in run_cli(capsys, ["verify", robot, poses])
    with pytest.raises(InputError, match="duplicate key 1.0"):
        files.parse_yaml("{1: a, 1.0: b}", "x")
    assert files.parse_yaml("a: {<<: {b: 1, c: 2}, b: 3}", "x") == {"a": {"b": 3, "c": 2}}


# ----------------------------------------------------------------------------- huge numbers in messages

def test_huge_numbers_are_shown_short(capsys):
    """Found by the bad-input campaign: a position of 1e308 was printed as a 309-digit number. An error
    shows a huge integer as a float is shown; the planner's pose text has 6 digits."""
    from cdh_planner.errors import short_repr
    from cdh_planner.pipeline.lift import describe
    assert short_repr(int(1e308)) == "1e+308" and short_repr(-10 ** 400) == "-~1e399"
    assert short_repr(10 ** 15) == "1000000000000000"
    line = run_cli(capsys, ["plan", "--quiet", PROBLEM, "--max-charts", "1e308"])
    assert "--max-charts = 1e+308: must be <=" in line
    text = describe(np.array([1e308, 0.081092, -0.2]), np.array([0.5, 1.25, -np.pi]))
    assert text == "p = [1e+308, 0.081092, -0.2] m, tau = [0.5, 1.25, -3.14159] rad"


# ----------------------------------------------------------------------------- call, replay: ROS input

START, GOAL = "0 0 0.176 0 0 0 1", "0.081092 0.049718 0.217387 0.208539 -0.340136 0 0.916962"


@pytest.fixture
def ros_domain(monkeypatch):
    """A claimed ROS domain (ros_harness) set for this process and its children."""
    pytest.importorskip("rclpy")
    from ros_harness import claimed_domain
    with claimed_domain() as domain:
        monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
        monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        yield domain


@pytest.mark.parametrize("argv, text", [
    # found by the bad-input campaign: poses the node refused (292) are checked as a pose file's are
    (["--start", "nan 0 0.176 0 0 0 1"], "--start.position[0] = nan: expected a finite number"),
    (["--start", "0 inf 0.176 0 0 0 1"], "--start.position[1] = inf: expected a finite number"),
    (["--start", "0 0 0.176 0 0 0 0"], "--start.quaternion = [0.0, 0.0, 0.0, 0.0]: zero"),
    (["--start", "0 0 0.176 0 0 0 2"], "not normalised (norm 2"),
    (["--start", "0 0 0.176 0 0 nan 1"], "--start.quaternion[2] = nan: expected a finite"),
    (["--start", "1e308 0 0.176 0 0 0 1"], "--start.position[0] = 1e+308: must be within"),
    (["--start", "0 0 0.176 0 0 0"], "expected 7 numbers"),
    (["--start", START, "--goal", "0 0 0.2 0.7 0.7 0.7 0.7"], "--goal.quaternion"),
    # found by the bad-input campaign: InvalidServiceNameException and RCLError were exit 3
    (["--start", START, "--node", "bad name!!"], "--node = 'bad name!!': not a valid ROS"),
    (["--start", START, "--node", "/9lives"], "not a valid ROS node name"),
    (["--start", START, "--ros-args", "-r", "::::"],
     "--ros-args = '-r ::::': ROS 2 cannot start with them: failed to initialize rcl: "
     "Couldn't parse remap rule"),
    (["--start", START, "--ros-args", "-p", "x:=[1"], "--ros-args = '-p x:=[1'"),
    (["--start", START, "--ros-args", "--params-file", "/no/such.yaml"], "--ros-args = '--p"),
    (["--start", START, "--timeout", "nan"], "--timeout = nan"),
])
def test_call_refuses_bad_input_before_joining_ros(capsys, ros_domain, argv, text):
    argv = ["call", "--goal", GOAL, *argv] if "--goal" not in argv else ["call", *argv]
    line = run_cli(capsys, argv)
    assert text in line, line


def test_a_bad_ros_environment_is_bad_input(capsys, ros_domain, monkeypatch):
    monkeypatch.setenv("ROS_DOMAIN_ID", "abc")
    line = run_cli(capsys, ["call", "--start", START, "--goal", GOAL])
    assert "ROS environment = " in line and "ROS_DOMAIN_ID is not an integral number" in line


def test_call_refusals_as_processes_are_one_line(ros_domain):
    """Found by the bad-input campaign: as the campaign ran them, rcl's own log line included."""
    for argv, text in ((["--ros-args", "-r", "::::"], "--ros-args"),
                       (["--node", "bad name!!"], "--node")):
        rc, err = run_process(["call", "--start", START, "--goal", GOAL, *argv])
        assert rc == 2 and len(err) == 1 and text in err[0], (argv, err)


def test_call_without_a_node_says_so_in_one_line_exit_1(ros_domain):
    """Found by the bad-input campaign: with no node it waited for --timeout and exited 3 (internal
    error); now it waits at most call.NODE_WAIT_S for the node's services."""
    from cdh_planner.commands.call import NODE_WAIT_S
    rc, err = run_process(["call", "--start", START, "--goal", GOAL])
    assert rc == 1 and len(err) == 1, err
    assert f"no service /cdh_planner/plan after {NODE_WAIT_S:g} s" in err[0]


def test_replay_refuses_bad_ros_input(tmp_path, capsys, ros_domain):
    run = _write_recording(tmp_path / "run.mcap")
    line = run_cli(capsys, ["replay", run, "--delay", "0", "--ros-args", "-r", "::::"])
    assert "--ros-args = '-r ::::'" in line


def test_recover_and_replay_refuse_a_damaged_chunk(tmp_path, capsys):
    """Found by the bad-input campaign: recover on a bad chunk CRC was exit 3; replay gave exit 2."""
    run = _write_recording(tmp_path / "run.mcap")
    data = bytearray(run.read_bytes())
    data[data.index(b"/cmd", 200) + 40] ^= 0xFF   # inside the chunk of a message
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    for argv in (["recover", damaged, "-o", tmp_path / "out.mcap"], ["replay", damaged]):
        line = run_cli(capsys, argv)
        assert "damaged MCAP data" in line and "CRCValidationError" in line, line
    assert not (tmp_path / "out.mcap").exists()
    rc, err = run_process(["recover", damaged, "-o", tmp_path / "out.mcap"])
    assert rc == 2 and len(err) == 1 and "damaged MCAP data" in err[0], err


def test_replay_refuses_a_recorded_topic_name_rclpy_refuses(tmp_path, capsys, ros_domain):
    """A file written by another tool with a topic named '/bad topic!!': rclpy's
    InvalidTopicNameException on its publisher was exit 3."""
    JointState = pytest.importorskip("sensor_msgs.msg").JointState
    from cdh_planner.recording.mcap_log import RunRecorder
    path = tmp_path / "bad.mcap"
    with RunRecorder(path) as rec:
        rec.write("/bad topic!!", JointState(name=["w"], position=[1.0]), 1000)
    line = run_cli(capsys, ["replay", path, "--delay", "0"])
    assert "RUN = '/bad topic!!': a recorded topic whose name is not a valid ROS" in line


def test_command_line_text_that_is_not_utf8_is_refused(tmp_path, capsys, ros_domain):
    """Bytes of argv that are not UTF-8 reach Python as lone surrogates: matplotlib raised
    TypeError on a --title holding one (exit 3); a ROS message cannot carry one either."""
    bad = b"q\xff".decode("utf-8", "surrogateescape")
    for argv, field in ((["slice", ROBOT2, "--title", bad, "-o", tmp_path / "s.png"], "--title"),
                        (["slice", ROBOT2, "--point", f"{bad}=1,1", "-o", tmp_path / "s.png"],
                         "--point"),
                        (["call", "--start", START, "--goal", GOAL, "--frame", bad], "--frame")):
        line = run_cli(capsys, argv)
        assert f"{field} = " in line and "not UTF-8 text (byte 0xff at 1)" in line, line


def test_recover_tells_a_summary_cut_short_from_none(tmp_path, capsys):
    """Found by the bad-input campaign: a disk that fills while the node closes its file leaves a summary
    cut short, and recover said 'the node was killed'. A file cut after the writer's
    DataEnd record (its summary begun) is told apart from one that just stops."""
    import io
    from mcap.records import DataEnd
    from mcap.stream_reader import StreamReader
    data = _write_recording(tmp_path / "run.mcap").read_bytes()
    stream = io.BytesIO(data)
    next(r for r in StreamReader(stream, emit_chunks=True).records if isinstance(r, DataEnd))
    data_end = stream.tell()
    for cut, says in ((data_end + 1, "summary was cut short"), (len(data) - 9, "cut short"),
                      (data_end - 20, "did not end normally")):
        path = tmp_path / f"cut{cut}.mcap"
        path.write_bytes(data[:cut])
        assert cli.main(["recover", str(path), "-o", str(tmp_path / f"out{cut}.mcap")]) == 0
        out = capsys.readouterr().out
        assert "3 messages" in out and says in out and "was killed" not in out, out


def test_replay_requests_refuses_a_request_that_does_not_decode(tmp_path, capsys, ros_domain):
    """A file (of another tool) whose GetPlan event holds bytes that are not one: rclpy's
    RMWError on deserializing it was exit 3."""
    from mcap.writer import CompressionType, Writer
    from cdh_planner.recording.ros_schemas import full_definition, recorded_type
    name = recorded_type("nav_msgs/srv/GetPlan_Event")
    path = tmp_path / "garbage.mcap"
    with open(path, "wb") as f:
        writer = Writer(f, compression=CompressionType.NONE)
        writer.start(profile="ros2", library="test")
        schema = writer.register_schema(name, "ros2msg", full_definition(name).encode())
        channel = writer.register_channel("/cdh_planner/plan/_service_event", "cdr", schema)
        writer.add_message(channel, log_time=1000, data=b"\x00\x01\x00\x00" + b"\xff" * 40,
                           publish_time=1000)
        writer.finish()
    line = run_cli(capsys, ["replay", path, "--requests", "--timeout", "1"])
    assert "a recorded request or parameter event does not decode" in line, line
