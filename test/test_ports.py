"""The start-up ports (cdh_planner/ports/) against the libraries they stand for: with
CDH_PLANNER_USE_SCIPY=1 the planner uses scipy's classes and toppra's own import, and its
answers agree with the ports' to rounding; the lean toppra import is never visible to
another thread."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import REPO


def _run(code, use_scipy):
    env = dict(os.environ, CDH_PLANNER_USE_SCIPY="1" if use_scipy else "0")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         check=True, timeout=240)
    return out.stdout.strip().splitlines()[-1]


def test_the_switch_gives_scipys_own_classes_and_toppras_own_import():
    code = ("import sys\nfrom cdh_planner import ports\n"
            "from scipy.spatial.transform import Rotation, RotationSpline, Slerp\n"
            "from scipy.interpolate import CubicSpline\nfrom scipy.linalg import solve_banded\n"
            "assert (ports.Rotation, ports.Slerp, ports.RotationSpline, ports.CubicSpline,\n"
            "        ports.solve_banded) == (Rotation, Slerp, RotationSpline, CubicSpline, solve_banded)\n"
            "import cdh_planner.trajectory.dynamics\n"
            "import toppra.algorithm.algorithm as a\n"
            "print('matplotlib.pyplot' in sys.modules and a.plt is sys.modules['matplotlib.pyplot'])")
    assert _run(code, use_scipy=True) == "True"
    assert _run("from cdh_planner import ports\nprint(ports.Rotation.__module__)", use_scipy=False) \
        == "cdh_planner.ports.rotation"


@pytest.mark.parametrize("problem", ["robot2_q1_q2", "robot2_q2_q3"])
def test_plans_with_scipy_and_with_the_ports_agree_to_rounding(tmp_path, problem):
    """robot2_q1_q2: a direct motion, dynamically timed (splines, rotations, toppra);
    robot2_q2_q3: an atlas search and a smoothing (banded solves) as well."""
    answers = []
    for use_scipy in (False, True):
        out = tmp_path / f"{use_scipy}.json"
        code = ("from cdh_planner import cli\n"
                f"print(cli.main(['plan', {str(REPO / 'config' / 'problems' / (problem + '.yaml'))!r},"
                f" '--quiet', '--json', {str(out)!r}]))")
        assert _run(code, use_scipy) == "0"
        answers.append(json.loads(out.read_text()))
    ports_plan, scipy_plan = answers
    assert len(ports_plan["path"]) == len(scipy_plan["path"])
    for key in ("p", "quaternion", "lengths", "commanded_lengths", "tension_nominal", "t"):
        ours = np.array([w[key] for w in ports_plan["path"]], dtype=float)
        theirs = np.array([w[key] for w in scipy_plan["path"]], dtype=float)
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-9, err_msg=key)


def test_no_other_thread_sees_a_stand_in_while_toppra_imports():
    """A watcher thread scans sys.modules as often as the interpreter lets it while the
    main thread imports toppra lean: every module it finds is a real one."""
    code = ("import sys, threading, types\nsys.setswitchinterval(1e-6)\n"
            "from cdh_planner.ports import lean_toppra\n"
            "seen, done = set(), threading.Event()\n"
            "def watch():\n"
            "    while not done.is_set():\n"
            "        for name, m in list(sys.modules.items()):\n"
            "            if isinstance(m, lean_toppra._Deferred):\n"
            "                seen.add(name)\n"
            "t = threading.Thread(target=watch); t.start()\n"
            "toppra = lean_toppra.import_lean()\n"
            "done.set(); t.join()\n"
            "assert 'matplotlib' not in sys.modules and 'scipy.interpolate' not in sys.modules\n"
            "print(sorted(seen))")
    assert _run(code, use_scipy=False) == "[]"
