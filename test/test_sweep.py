"""``cdh-planner sweep`` (studies.sweep) without Ray: the product of the varied keys, one CSV
row and one JSON per design, the same poses asked of every design (so a looser bound keeps
every feasible pose feasible), bad files refused naming the field, SIGINT then --resume
runs every design once."""

import csv
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from cdh_planner import cli
from cdh_planner.model.robot import GRAVITY
from cdh_planner.studies import sweep as sw
from conftest import CONFIG, REPO, default_sigint

ROBOT2 = CONFIG / "robot2.yaml"
LOW, HIGH = [4.0] * 6, [6.58] * 6


def write_sweep(tmp_path, workspace="{samples: 300, seed: 1}", vary=None, extra=""):
    vary = vary or f"robot.tension_max: [{LOW}, {HIGH}]\n  robot.load.mass: [0.4, 0.6]"
    path = tmp_path / "sweep.yaml"
    path.write_text(f"robot: {ROBOT2}\nvary:\n  {vary}\nworkspace: {workspace}\n{extra}")
    return path


def test_designs_rows_and_paired_poses(tmp_path, capsys):
    path = write_sweep(tmp_path, extra=f"queries: [{CONFIG / 'problems' / 'robot2_q1_q2.yaml'}]\n")
    out = tmp_path / "out"
    assert cli.main(["sweep", str(path), "--out", str(out), "--no-ray", "--quiet"]) == 0
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert [r["design"] for r in rows] == ["0", "1", "2", "3"]
    assert [(json.loads(r["robot.tension_max"]), float(r["robot.load.mass"])) for r in rows] == \
        [(LOW, 0.4), (LOW, 0.6), (HIGH, 0.4), (HIGH, 0.6)]
    assert all(r["query1_success"] == "True" for r in rows)
    docs = [json.loads((out / f"design_{k:04d}.json").read_text()) for k in range(4)]
    for row, doc in zip(rows, docs):
        poses = doc["workspace"]["poses"]
        assert float(row["feasible_fraction"]) == pytest.approx(np.mean([p["feasible"] for p in poses]))
        assert doc["metrics"]["query1_success"] is True
    feasible = [np.array([p["feasible"] for p in d["workspace"]["poses"]]) for d in docs]
    positions = [[p["position"] for p in d["workspace"]["poses"]] for d in docs]
    assert all(p == positions[0] for p in positions)  # every design is asked the same poses
    for low, high in ((0, 2), (1, 3)):  # a higher tension_max keeps each feasible pose feasible
        assert np.all(feasible[high][feasible[low]])
    assert (out / "sweep.png").read_bytes()[:4] == b"\x89PNG"
    assert "4 designs" in capsys.readouterr().out


def test_varying_the_mass_alone_scales_the_load_force(tmp_path):
    sweep = sw.load_sweep(write_sweep(tmp_path, vary="robot.load.mass: [0.4, 0.6]"))
    for design, mass in zip(sweep.designs, (0.4, 0.6)):
        assert np.linalg.norm(design.robot.force) == pytest.approx(mass * GRAVITY)
        assert np.allclose(design.robot.force[:2], 0) and design.robot.force[2] > 0


@pytest.mark.parametrize("vary, workspace, extra, field", [
    ("robot.tension_max: [[4, 4, 4, 4, 4, 4]]", "{samples: 10}", "colour: red\n", "colour"),
    ("robot.tension_maximum: [[4, 4, 4, 4, 4, 4]]", "{samples: 10}", "", "vary.robot.tension_maximum"),
    ("tension_max: [[4, 4, 4, 4, 4, 4]]", "{samples: 10}", "", "vary.tension_max"),
    ("robot.tension_max: []", "{samples: 10}", "", "vary.robot.tension_max"),
    ("robot.tension_max: [[4, 4, 4, 4, 4, -4]]", "{samples: 10}", "", "vary.robot.tension_max"),
    ("robot.length_max: [0.1]", "{samples: 10}", "", "vary.robot.length_max"),
    ("robot.load.mass: [0.6, yes]", "{samples: 10}", "", "vary.robot.load.mass"),
    ("robot.tension_max: [[4, 4, 4, 4, 4, 4]]", "{samples: 0}", "", "workspace.samples"),
    ("robot.tension_max: [[4, 4, 4, 4, 4, 4]]", "{samples: 10, speed: 2}", "", "workspace.speed"),
    ("robot.tension_max: [[4, 4, 4, 4, 4, 4]]", "{samples: 10, timeout: -1}", "", "workspace.timeout"),
    ("robot.tension_max: [[4, 4, 4, 4, 4, 4]]", "{samples: 10, tilt: 4}", "", "workspace.tilt"),
    ("robot.tension_max: [[4, 4, 4, 4, 4, 4]]", "{samples: 10}", "queries: [nowhere.yaml]\n", "queries[0]"),
])
def test_bad_sweep_files_are_refused_naming_the_field(tmp_path, capsys, vary, workspace, extra, field):
    path = write_sweep(tmp_path, workspace=workspace, vary=vary, extra=extra)
    assert cli.main(["sweep", str(path), "--out", str(tmp_path / "out"), "--no-ray", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"error: {field}" in err, err
    assert not (tmp_path / "out" / "results.csv").exists()


def test_sigint_then_resume_runs_every_design_once(tmp_path):
    """Designs of ~2 s each (plans from home); SIGINT once the first is written; exit 130;
    --resume keeps the designs written (same bytes, same mtime) and does the rest."""
    path = write_sweep(tmp_path, workspace="{samples: 200, seed: 2, reach: true, timeout: 10}",
                       vary=f"robot.tension_max: [{LOW}, [5, 5, 5, 5, 5, 5], {HIGH}]\n"
                            "  robot.load.mass: [0.5, 0.6]")
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "cdh_planner.cli", "sweep", str(path), "--out", str(out),
           "--no-ray", "--quiet"]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=default_sigint)
    deadline = time.monotonic() + 120
    while not (out / "design_0000.json").exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    done = {p.name: p.stat().st_mtime_ns for p in out.glob("design_*.json")}
    assert 1 <= len(done) < 6
    assert not list(out.glob(".*tmp"))  # no half-written file left behind
    csv_file = out / "results.csv"  # written after each design's JSON: one behind at most
    rows = list(csv.DictReader(csv_file.open())) if csv_file.exists() else []
    assert len(done) - 1 <= len(rows) <= len(done)
    rc = subprocess.run(cmd + ["--resume"], env=env, capture_output=True, text=True, timeout=300)
    assert rc.returncode == 0, rc.stderr
    assert rc.stdout.count("done before, kept") == len(done)
    assert {n: (out / n).stat().st_mtime_ns for n in done} == done
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert [r["design"] for r in rows] == [str(k) for k in range(6)]


@pytest.mark.parametrize("text, held", [("", "the file is empty"), ("[1, 2]\n", "the file holds a list")])
def test_an_empty_sweep_file_is_refused_naming_the_file(tmp_path, capsys, text, held):
    path = tmp_path / "sweep.yaml"
    path.write_text(text)
    assert cli.main(["sweep", str(path), "--out", str(tmp_path / "out"), "--no-ray", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"error: sweep = '{path}': {held}" in err, err


def test_the_example_sweep_file_in_config_reads():
    """config/sweeps/robot2_tension_and_load.yaml, the documented example (module docstring of studies.sweep)."""
    sweep = sw.load_sweep(CONFIG / "sweeps" / "robot2_tension_and_load.yaml")
    assert len(sweep.designs) == 4 and sweep.keys == ("robot.tension_max", "robot.load.mass")
