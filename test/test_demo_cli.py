"""``cdh-planner demo`` end to end: the paper's verdicts, the pictures, the exit codes, and
the ROS story (node, q_1 -> q_2 -> q_3 planned over ROS and streamed, recorded, replayed,
shut down, pictures) over real DDS in a domain of its own."""
import contextlib
import io
import math
import re
import struct
from pathlib import Path

import numpy as np
import pytest

from cdh_planner import cli
from cdh_planner.commands import demo as demo_cmd
from cdh_planner.commands.demo import paper
from cdh_planner.commands.demo.steps import Step
from cdh_planner.wrench import wrench_feasibility
from cdh_planner.trajectory.path_check import TaskLinePath

from conftest import REPO as ROOT
CHECK_STEPS = demo_cmd.STEPS[:3]  # robots, poses, motions: everything but the pictures


def png_size(path):
    """(width, height) from a PNG header."""
    data = Path(path).read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


def run_quiet(func, *args, **kwargs):
    """(return value, stdout text) of func(*args, **kwargs)."""
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        value = func(*args, **kwargs)
    return value, buf.getvalue()


@pytest.fixture(scope="module")
def full_run(tmp_path_factory):
    """One whole ``cdh-planner demo --out DIR`` run: (exit code, stdout, DIR)."""
    out = tmp_path_factory.mktemp("demo") / "out"  # does not exist yet: the demo creates it
    rc, text = run_quiet(cli.main, ["demo", "--out", str(out)])
    return rc, text, out


@pytest.fixture(scope="module")
def checked(tmp_path_factory):
    """The Demo record of the checking steps (no pictures)."""
    demo, _ = run_quiet(demo_cmd.run_demo, tmp_path_factory.mktemp("checks"), steps=CHECK_STEPS)
    return demo


def line_with(text, robot, *parts):
    """The one table row of ``robot`` containing all ``parts``."""
    lines = [line for line in text.splitlines()
             if line.startswith(f"{robot} ") and all(p in line for p in parts)]
    assert len(lines) == 1, (parts, lines)
    return lines[0]


def test_demo_exits_0_and_prints_the_papers_verdicts(full_run):
    rc, text, _ = full_run
    assert rc == 0, text[-2500:]
    for robot, label in [("robot1", "q_s"), ("robot1", "q_g"), ("robot2", "q_1"), ("robot2", "q_2"),
                         ("robot2", "q_3")]:
        row = line_with(text, robot, f"  {label}  ").split()
        assert row[:2] == [robot, label]
        assert "yes" in row and row[-2:] == ["feasible:", "agrees"]
    slerp = line_with(text, "robot1", "q_s -> q_g", "linear + slerp")
    assert "UNSAFE, leaves C at s = 0.1" in slerp and slerp.endswith("unsafe: agrees")
    assert "UNSAFE, leaves C at s = 0.03" in line_with(text, "robot1", "q_s -> q_g", "line in (phi, theta)")
    safe = line_with(text, "robot2", "q_1 -> q_2", "line in (alpha1, alpha2)")
    assert "safe, worst margin +0.05" in safe and safe.endswith("safe: agrees")
    unsafe = line_with(text, "robot2", "q_2 -> q_3", "line in (alpha1, alpha2)")
    assert "UNSAFE, leaves C at s = 0.04" in unsafe and unsafe.endswith("unsafe within 10 %: agrees")
    assert "every verdict is the expected one" in text
    assert "DIFFERS" not in text


def test_demo_writes_the_two_slice_pictures(full_run):
    rc, text, out = full_run
    assert rc == 0, text[-2500:]
    for name in ("robot1_slice.png", "robot2_sphere.png"):
        path = out / name
        assert path.stat().st_size > 20_000  # a real picture, not an empty canvas
        assert png_size(path) == (1000, 800)
        assert f"wrote {path}" in text
    assert re.search(rf"files in {re.escape(str(out.resolve()))}/: robot1_slice.png, "
                     r"robot2_sphere.png, robot2_sphere_ball.png, cdh_planner_\d{8}-\d{6}_\d+\.mcap, "
                     r"robot2_plans.png, robot2_execution.png\n", text)
    # The drawn segments are the ones verified: same first unsafe points.
    assert "segment q_s -> q_g leaves C at 3.2 %" in text
    assert "segment q_2 -> q_3 leaves C at 4.3 %" in text


def test_demo_obstacle_step(full_run):
    """Robot 2 free flight q_2 -> q_3 with a ball on cable 3: the straight motion is
    wrench-feasible but hits the ball; the plan goes around it, dense-checked; the slice
    shows the poses in collision."""
    rc, text, out = full_run
    assert rc == 0, text[-2500:]
    step = text[text.index("== 5. An obstacle on the straight motion"):]
    step = step[:step.index("\n== ")]
    assert re.search(r"no scene: wrench-feasible; with the ball: hits at s = 0\.\d+ "
                     r"\(collision winch_3 / ball\)", step), step
    assert re.search(r"dense check against the ball and the wrench: clear; least clearance "
                     r"at a waypoint [\d.]+ mm", step), step
    assert png_size(out / "robot2_sphere_ball.png") == (1000, 800)


def test_demo_ros_story(full_run):
    """The node plans q_1 -> q_2 -> q_3 through its action, each motion dense-safe: the first
    streamed to its last waypoint at the stream rate; then the simulated ros2_control
    controller takes over and the second, planned from the measured pose, runs through it
    to its last waypoint; the recording replays (commands identical, goals answered the same
    by a fresh node); both nodes stop with exit 0; the run file is a complete MCAP; the
    summary table and the two pictures."""
    rc, text, out = full_run
    assert rc == 0, text[-3000:]
    assert "DIFFERS" not in text and "FAILED" not in text and "skipped" not in text
    ros = text[text.index("== 6. The ROS 2 node"):]
    assert re.search(r"node /cdh_planner ready in [\d.]+ s: base_frame cdh_base, task.type "
                     r"sphere, planner.strategy auto", ros)
    parts = {}
    for leg in ("q_1 -> q_2", "q_2 -> q_3"):
        start, goal = leg.split(" -> ")
        head = re.search(rf"goal ~/plan_path: .*{start}.* -> {goal} ", ros)
        assert head, ros[:600]
        part = parts[leg] = ros[head.start():]
        planned = re.search(r"planned in ([\d.]+) s \((\d+) charts, astar\): (\d+) waypoints, "
                            r"path ([\d.]+) m, duration ([\d.]+) s, lowest tension margin "
                            r"([\d.]+) N", part)
        assert planned, part[:400]
        assert float(planned.group(6)) > 0   # no bound on the planning time: a loaded machine is slow, not wrong
        assert "checked densely: safe, worst margin +" in part
        assert "execution completed" in part.split("\n== ")[0], part[:1500]
        parts[leg] = (part.split("\n== ")[0], planned)
    part, planned = parts["q_1 -> q_2"]
    streamed = re.search(r"streamed (\d+) cable commands over ([\d.]+) s \(([\d.]+) Hz\); "
                         r"last = the final waypoint's cable lengths within 0.0e\+00 m", part)
    assert streamed, part[:800]
    assert 45.0 <= float(streamed.group(3)) <= 55.0                 # stream_rate_hz 50
    assert abs(float(streamed.group(2)) - float(planned.group(5))) < 0.1
    assert "set execution.mode follow_joint_trajectory: done" in ros
    part, _ = parts["q_2 -> q_3"]
    assert re.search(r"start from the forward kinematics of the measured lengths: [\d.e+-]+ m "
                     r"from q_2", part), part[:800]
    assert "through /cable_controller/follow_joint_trajectory" in part
    assert "start not checked" not in part                           # the winches are measured
    assert re.search(r"the controller moved the winches: \d+ joint states; the last = the "
                     r"final waypoint's cable lengths within 0.0e\+00 m", part), part[:1500]
    assert re.search(r"received (\d+) republished commands \(recorded \1 over [\d.]+ s\): "
                     r"identical to the ones streamed live", ros)
    assert "goal 1: MATCHES" in ros and "goal 2 (use_current_start" in ros
    assert "2 of 2 answers match the recording" in ros
    assert "fresh node stopped by SIGINT, exit code 0" in ros
    assert re.search(r"node stopped by SIGINT in [\d.]+ s, exit code 0", ros)
    assert "complete MCAP (rosbags reads it)" in ros
    assert re.search(r"/cdh_planner/plan_path/_action/send_goal/_service_event: 2\n", ros)
    assert re.search(r"/cdh_planner/plan_path/_action/get_result/_service_event: 2\n", ros)
    [run_file] = (out / "runs").glob("*.mcap")
    assert str(run_file) in ros
    rows = [line.split() for line in ros.splitlines() if line.startswith("q_")]
    assert [r[:3] for r in rows] == [["q_1", "->", "q_2"], ["q_2", "->", "q_3"]]
    assert all(r[-2] == "safe" for r in rows)
    assert rows[0][-1].endswith("_commands:completed") and rows[1][-1] == "controller:completed"
    for name, size in (("robot2_plans.png", (1000, 600)), ("robot2_execution.png", (1000, 700))):
        assert (out / name).stat().st_size > 20_000 and png_size(out / name) == size
        assert f"wrote {out / name}" in ros
    assert "node.log" in ros and (out / "node.log").is_file()


def test_pose_verdicts_agree_with_the_closed_form_and_the_limits(checked):
    assert set(checked.poses) == {("robot1", "q_s"), ("robot1", "q_g"), ("robot2", "q_1"),
                                  ("robot2", "q_2"), ("robot2", "q_3")}
    # Robot 1 poses on the slice p = [0, 0, 0.35] m, sigma = 34 deg.
    for label in ("q_s", "q_g"):
        v = checked.poses[("robot1", label)]
        np.testing.assert_allclose(v.position, [0.0, 0.0, 0.35])
        assert v.tau[2] == pytest.approx(math.radians(34))
    # Robot 2 poses on the sphere of radius 0.13 m around [0, 0, 0.306] m.
    for label in ("q_1", "q_2", "q_3"):
        v = checked.poses[("robot2", label)]
        assert np.linalg.norm(v.position - [0.0, 0.0, 0.306]) == pytest.approx(0.13)
    for (name, _), v in checked.poses.items():
        robot = checked.robots[name]
        assert v.feasible and v.agrees and v.margin > 0
        # Feasible: the whole tension envelope is strictly inside the limits.
        assert robot.tension_min.max() < v.tension_low < v.tension_high < robot.tension_max.min()
        # The margin is the normalised distance to the binding bound.
        f = wrench_feasibility(robot, v.position[None], v.tau[None])
        kind, cable = v.binding[:-1].split("[")
        i = int(cable) - 1
        expected = {
            "length_min": (f.lengths[0, i] - robot.length_min[i]) / (robot.length_max[i] - robot.length_min[i]),
            "length_max": (robot.length_max[i] - f.lengths[0, i]) / (robot.length_max[i] - robot.length_min[i]),
            "tension_min": (f.tension_min[0, i] - robot.tension_min[i]) / (robot.tension_max[i] - robot.tension_min[i]),
            "tension_max": (robot.tension_max[i] - f.tension_max[0, i]) / (robot.tension_max[i] - robot.tension_min[i]),
        }[kind]
        assert v.margin == pytest.approx(expected, rel=1e-12)
    # the paper's Sec. 5.1: Robot 1's q_s, q_g have a margin of about 0.04 (millimetre units).
    assert 0.02 < checked.poses[("robot1", "q_s")].margin < 0.06
    assert 0.02 < checked.poses[("robot1", "q_g")].margin < 0.06


def test_motion_verdicts_and_where_they_leave_c(checked):
    by_key = {(m.motion.robot, m.motion.start, m.motion.goal, m.motion.interpolation): m
              for m in checked.motions}
    assert not by_key[("robot1", "q_s", "q_g", "slerp")].safe
    assert not by_key[("robot1", "q_s", "q_g", "task")].safe
    assert by_key[("robot2", "q_1", "q_2", "task")].safe
    q2q3 = by_key[("robot2", "q_2", "q_3", "task")]
    assert not q2q3.safe and 0.03 < q2q3.leaves_at < 0.06  # the paper: after about 4 % of the way
    assert all(m.agrees is not False for m in checked.motions)
    assert checked.differs == []
    # The first unsafe point is a boundary point of C along the line: feasible just before,
    # infeasible just after.
    task = checked.tasks["robot2"]
    line = TaskLinePath(task, [[0.55, 0.75], [2.63, 0.75]])
    s = q2q3.leaves_at
    p, R = line(np.zeros(2, dtype=int), np.array([s - 1e-6, s + 1e-6]))
    margin = wrench_feasibility(checked.robots["robot2"], p, R=R).margin
    assert margin[0] > 0 > margin[1]
    # Along q_1 -> q_2 the margin never falls below its value at the worst sample.
    safe = by_key[("robot2", "q_1", "q_2", "task")].check
    line = TaskLinePath(task, [[0.55, math.pi / 2], [0.55, 0.75]])
    s = np.linspace(0.0, 1.0, 2001)
    p, R = line(np.zeros(s.size, dtype=int), s)
    assert wrench_feasibility(checked.robots["robot2"], p, R=R).margin.min() >= safe.worst.margin - 1e-9


def test_a_verdict_that_differs_from_the_paper_gives_exit_1(tmp_path, monkeypatch):
    flipped = (paper.PaperPose("robot2", "q_2", (0.55, 0.75), feasible=False),)
    monkeypatch.setattr(paper, "PAPER_POSES", paper.PAPER_POSES + flipped)
    monkeypatch.setattr(demo_cmd, "STEPS", demo_cmd.STEPS[:2])
    rc, text = run_quiet(cli.main, ["demo", "--out", str(tmp_path)])
    assert rc == 1
    assert "DIFFERS FROM THE EXPECTED" in text
    assert "robot2 q_2: feasible, expected not feasible" in text


def test_steps_can_be_appended(tmp_path):
    seen = []
    extra = Step("later", "A later step", lambda d: seen.append(sorted(d.robots)))
    demo, text = run_quiet(demo_cmd.run_demo, tmp_path, steps=demo_cmd.STEPS[:1] + [extra])
    assert seen == [["robot1", "robot2"]]
    assert "== 2. A later step" in text


def test_config_dir_found_from_the_package():
    path = demo_cmd.find_config_dir()
    assert (path / "robot1.yaml").is_file() and (path / "robot2.yaml").is_file()
    if (ROOT / "config" / "robot1.yaml").is_file():  # a checkout / editable install
        assert path.resolve() == (ROOT / "config").resolve()


@pytest.mark.parametrize("args, field", [
    (["--out", "{file}"], "--out"),
    (["--out", "{dir}", "--config-dir", "{dir}"], "--config-dir"),
])
def test_bad_directories_give_one_line_errors(tmp_path, capsys, args, field):
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    argv = ["demo"] + [a.format(file=a_file, dir=tmp_path) for a in args]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"cdh-planner: error: {field} = ") and "\n" not in err
