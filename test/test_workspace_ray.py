"""The workspace on Ray (studies.executors.RayExecutor): the same answers with 1 and 2 workers
and on a cluster started outside the command; a worker killed mid-job loses no sample and
counts none twice. Needs ray (requirements.txt); a local Ray of 2 CPUs, no cluster."""

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cdh_planner import cli
from cdh_planner.model.robot import load_robot
from cdh_planner.studies import workspace as ws
from cdh_planner.studies.executors import RayExecutor, SerialExecutor
from conftest import CONFIG, default_sigint

pytest.importorskip("ray")
ROBOT2 = CONFIG / "robot2.yaml"
SUMMARY_ONLY = ("seconds", "workers")  # how the run went, not what it answered


@pytest.fixture(scope="module", autouse=True)
def own_home(tmp_path_factory):
    """A HOME of this module's own: a local Ray started here (ray.init) writes its token to
    ~/.ray/auth_token, and the clusters the tests start read it there; the user's stays
    untouched."""
    home = tmp_path_factory.mktemp("home")
    saved = os.environ.get("HOME")
    os.environ["HOME"] = str(home)
    yield home
    os.environ["HOME"] = saved


@pytest.fixture(scope="module")
def robot():
    return load_robot(ROBOT2)


@pytest.fixture(scope="module")
def spec(robot):
    low, high = ws.default_box(robot)
    home = ws.default_home(robot, draws=20_000)
    return ws.WorkspaceSpec(samples=12_000, seed=11, box_low=low, box_high=high,
                            home_position=home[0], home_quaternion=home[1], reach=True,
                            timeout_s=30.0).check()


def answers(res):
    return (res.margin.tolist(), res.binding, res.reach_status, res.counts())


def test_one_and_two_ray_workers_answer_as_this_process(robot, spec):
    # 150 samples, about 40 reach plans: the answers compared, not the throughput (400 passed
    # its 300 s bound on a quiet machine in 30 s but not with every core busy and 2 workers)
    small = ws.WorkspaceSpec(**{**spec.__dict__, "samples": 150})
    serial = ws.run_workspace(robot, small, SerialExecutor())
    for workers in (1, 2):
        ex = RayExecutor(workers)
        try:
            res = ws.run_workspace(robot, small, ex)
        finally:
            ex.close()
        assert res.workers == workers
        assert answers(res) == answers(serial)
        assert np.array_equal(res.position, serial.position)


def test_two_ray_workers_answer_with_a_scene_as_this_process(robot, spec, tmp_path):
    """The scene travels with the job: each actor builds its collision model once; points
    and plans as in this process."""
    from cdh_planner.scene.schema import scene_from_dict
    centre = ((np.array(spec.box_low) + np.array(spec.box_high)) / 2).tolist()
    scene = scene_from_dict({"cable_radius": 0.001, "platform": {"type": "sphere", "radius": 0.03},
                             "obstacles": [{"id": "ball", "type": "sphere", "radius": 0.04,
                                            "position": centre}]}, robot)
    home = ws.default_home(robot, draws=5000, scene=scene)
    small = ws.WorkspaceSpec(**{**spec.__dict__, "samples": 300, "home_position": home[0],
                                "home_quaternion": home[1]})
    serial = ws.run_workspace(robot, small, SerialExecutor(), scene=scene)
    ex = RayExecutor(2)
    try:
        res = ws.run_workspace(robot, small, ex, scene=scene)
    finally:
        ex.close()
    assert answers(res) == answers(serial)
    assert any(b.startswith("collision") for b in res.binding) and res.counts()["planned"] > 0


def test_a_killed_worker_loses_no_sample_and_counts_none_twice(robot, spec):
    """Plans to the feasible samples of 12000 on 2 actors; one actor process is killed
    (SIGKILL) after the first answers: every call is answered exactly once, as in-process."""
    points = ws.run_workspace(robot, ws.WorkspaceSpec(**{**spec.__dict__, "reach": False}),
                              SerialExecutor())
    targets = np.flatnonzero(points.feasible)[:60].tolist()
    calls = [("reach", (j,)) for j in targets]
    ex = RayExecutor(2)
    try:
        victim = ex.pids()[0]
        job = ws.Job(robot, spec)
        got = []
        for n, (i, out) in enumerate(ex.map(job, calls)):
            got.append((i, out[0][:2]))
            if n == 3:
                os.kill(victim, signal.SIGKILL)
        assert victim not in ex.pids()  # the actor was restarted: another process
    finally:
        ex.close()
    assert sorted(i for i, _ in got) == list(range(len(calls)))
    serial = dict(SerialExecutor().map(job, calls))
    assert {i: out for i, out in got} == {i: out[0][:2] for i, out in serial.items()}


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_cluster_started_outside_answers_as_a_local_ray(tmp_path, capsys):
    """``ray start --head --block`` on localhost (this test starts and stops it), then the
    command with --ray-address: the same poses and answers as --workers 2."""
    port = _free_port()
    address_file = Path(os.environ["RAY_TMPDIR"], "ray", "ray_current_cluster")  # ours goes
    had_file = address_file.exists()
    head = subprocess.Popen(
        [sys.executable, "-m", "ray.scripts.scripts", "start", "--head", "--block",
         f"--port={port}", "--num-cpus=2", "--include-dashboard=false", "--disable-usage-stats"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        common = [str(ROBOT2), "--samples", "300", "--seed", "2", "--reach", "--quiet"]
        outs = {}
        for name, extra in (("local", ["--workers", "2"]),
                            ("cluster", ["--workers", "2", "--ray-address", f"127.0.0.1:{port}"])):
            outs[name] = tmp_path / f"{name}.json"
            deadline = time.monotonic() + 120
            while True:  # the head takes seconds to accept drivers on a loaded machine
                rc = cli.main(["workspace", *common, *extra, "--json", str(outs[name])])
                if rc == 0 or time.monotonic() > deadline:
                    break
                time.sleep(2)
            assert rc == 0, capsys.readouterr().err
        docs = [json.loads(outs[k].read_text()) for k in ("local", "cluster")]
        for doc in docs:
            for key in SUMMARY_ONLY:
                doc.pop(key)
        assert docs[0] == docs[1]
        assert docs[0]["counts"]["planned"] > 0
    finally:
        head.terminate()  # the head stops its daemons in 2 s (SIGTERM to all of them: 30 s)
        try:
            head.wait(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(head.pid, signal.SIGKILL)
            head.wait(timeout=30)
        if not had_file and address_file.exists() and f":{port}" in address_file.read_text():
            address_file.unlink()


def test_a_sweep_on_two_ray_workers_answers_as_in_this_process(tmp_path, capsys):
    sweep = tmp_path / "sweep.yaml"
    sweep.write_text(f"robot: {ROBOT2}\nvary:\n  robot.tension_max: [[4, 4, 4, 4, 4, 4], [5, 5, 5, 5, 5, 5]]\n"
                     "workspace: {samples: 150, seed: 4, reach: true, timeout: 30}\n")
    rows = {}
    for name, extra in (("serial", ["--no-ray"]), ("ray", ["--workers", "2"])):
        assert cli.main(["sweep", str(sweep), "--out", str(tmp_path / name), "--quiet", *extra]) == 0
        lines = (tmp_path / name / "results.csv").read_text().splitlines()
        header = lines[0].split(",")
        keep = [k for k, h in enumerate(header) if "seconds" not in h]
        rows[name] = [[line.split(",")[k] for k in keep] for line in lines]
    assert rows["serial"] == rows["ray"] and len(rows["ray"]) == 3
    capsys.readouterr()


def test_ctrl_c_while_ray_workers_plan_leaves_stdout_clean(tmp_path):
    """SIGINT to ``workspace --reach --workers 2`` while the actors have plans in flight
    (seen by a "reach: k/N" progress line, k < N): exit 130, "interrupted" on stderr and
    nothing of Ray's on stdout (killing busy actors first made the raylet print a coloured
    "will be retried" line per call there). 4000 samples give some 340 reach plans: tens of
    seconds on a fast machine, so a progress line (one per 5 s off a terminal) comes before
    the end; 500 samples (43 plans) once ended inside the first 5 s."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "cdh_planner.cli", "workspace", str(ROBOT2), "--samples", "4000",
         "--seed", "3", "--workers", "2", "--reach", "--timeout", "600"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=tmp_path, env=dict(os.environ),
        preexec_fn=default_sigint)
    try:
        seen = []
        for raw in proc.stderr:   # the event: the reach stage under way, not finished
            line = raw.decode(errors="replace")
            seen.append(line)
            done, _, total = line.partition(" ")[2].partition(" ")[0].partition("/")
            if line.startswith("reach: ") and done.isdigit() and int(done) < int(total):
                break
        else:
            pytest.fail(f"no reach progress before the end: {''.join(seen)[-500:]}")
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(30)
    assert proc.returncode == 130, err.decode(errors="replace")[-500:]
    assert b"interrupted" in err
    assert out == b"", out[:300]
