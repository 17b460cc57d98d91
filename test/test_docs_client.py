"""The Python client of docs/ros-node.md ("Client side"), copied from the docs and run as a
script against a node (TEST DOUBLE planner, test/doubles/fake_planner.py): it prints the
outcome in every case and exits non-zero unless the execution completed (before, the old
one printed nothing and exited 0 when the goal ended NO_CURRENT_STATE)."""

import re
import subprocess
import sys

from conftest import REPO
from ros_harness import (Q1, ControllerDouble, NodeProcess, claimed_domain, ros_env)
from test_ros_execution import ROBOT, _lengths

ACTION = "/cable_controller/follow_joint_trajectory"


def _docs_client(tmp_path):
    text = (REPO / "docs" / "ros-node.md").read_text()
    section = text[text.index("## Client side"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    script = tmp_path / "client.py"
    script.write_text(code)
    return script


def _run(script, domain):
    r = subprocess.run([sys.executable, str(script)], env=ros_env(domain), capture_output=True,
                       text=True, timeout=120)
    return r.returncode, r.stdout.strip().splitlines()


def test_no_node_prints_why_and_exits_1(tmp_path):
    script = _docs_client(tmp_path)
    with claimed_domain() as domain:
        rc, lines = _run(script, domain)
    assert rc == 1 and len(lines) == 1 and lines[0].startswith("error: no service"), lines


def test_no_joint_states_prints_no_current_state_and_exits_1(tmp_path):
    script = _docs_client(tmp_path)
    with claimed_domain() as domain, NodeProcess(domain, tmp_path / "runs", fake=True):
        rc, lines = _run(script, domain)
    assert rc == 1 and len(lines) == 1, lines
    assert lines[0].startswith("no plan: error 293: use_current_start:"), lines   # NO_CURRENT_STATE


def test_a_completed_execution_prints_completed_and_exits_0(tmp_path):
    script = _docs_client(tmp_path)
    params = ["execution.mode:=follow_joint_trajectory", f"execution.controller_action:={ACTION}"]
    with claimed_domain() as domain, \
            ControllerDouble(domain, *ROBOT.winch_names, "--action", ACTION, "--time-scale", 4.0,
                             "--kinematic", "--initial", *map(repr, _lengths(Q1).tolist())) as double, \
            NodeProcess(domain, tmp_path / "runs", params=params, fake=True):
        assert double.ready.wait(30.0)
        rc, lines = _run(script, domain)
    assert rc == 0 and lines and lines[-1].startswith("completed: execution completed"), lines
