"""Start-up imports only what a command uses: checked in fresh
interpreters through sys.modules, not by timing."""

import json
import subprocess
import sys

import pytest

from cdh_planner import cli
from conftest import REPO, aot_built

HEAVY = ("toppra", "matplotlib", "matplotlib.pyplot", "rclpy", "scipy.spatial", "numba", "numpy",
         "scipy", "scipy.interpolate", "scipy.sparse", "scipy.linalg", "scipy.optimize", "numpy.ma",
         "coal", "numpy.random", "yaml", "hashlib")
SCIPY = {"scipy", "scipy.spatial", "scipy.interpolate", "scipy.sparse", "scipy.linalg", "scipy.optimize"}


def _modules_after(code):
    """The subset of HEAVY in sys.modules after running ``code`` in a fresh interpreter."""
    probe = f"import sys, json\n{code}\nprint(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def _modules_after_plan(name, check):
    """_modules_after planning config/problems/NAME.yaml (exit 0) and running ``check``
    (Python, on ``out``, the printed text)."""
    problem = REPO / "config" / "problems" / f"{name}.yaml"
    return _modules_after("import contextlib, io, re\nfrom cdh_planner import cli\n"
                          "with contextlib.redirect_stdout(io.StringIO()) as out:\n"
                          f"    assert cli.main(['plan', {str(problem)!r}, '--quiet']) == 0\n"
                          f"{check}\n")


def test_importing_the_cli_loads_no_heavy_library():
    assert _modules_after("import cdh_planner.cli") == set()


def test_help_imports_no_command_module():
    code = ("import contextlib, io\nfrom cdh_planner import cli\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n    assert cli.main(['--help']) == 0\n"
            "assert not [m for m in sys.modules if m.startswith('cdh_planner.commands.')]")
    assert _modules_after(code) == set()


def test_plan_command_parser_loads_no_plotting_and_no_ros():
    code = "from cdh_planner import cli\ncli.build_parser(['plan'])"
    loaded = _modules_after(code)
    assert not loaded & {"matplotlib", "matplotlib.pyplot", "rclpy", "numba"}


def test_a_direct_motion_plan_loads_no_plotting_ros_numba_or_scipy_module():
    """robot2_q1_q2: one direct motion, dynamically timed (toppra runs), no chart: numpy
    alone does its rotations, splines and small banded solves (for start-up: scipy's
    submodules were 0.2 s of its 0.55 s)."""
    loaded = _modules_after_plan("robot2_q1_q2", "assert 'dynamic timing' in out.getvalue()")
    assert "toppra" in loaded
    assert not loaded & ({"matplotlib", "matplotlib.pyplot", "rclpy", "numba", "numpy.ma"} | SCIPY)


def test_a_plan_over_charts_past_a_ball_loads_no_numpy_random_or_scipy():
    """robot2_q2_q3_ball: an atlas of charts (their fixed directions and the polytopes' hash
    weights are read, not drawn: test_atlas_draws), dynamically timed, a scene."""
    loaded = _modules_after_plan("robot2_q2_q3_ball",
                                 "assert re.search(r'over [1-9][0-9]* charts', out.getvalue())")
    assert "toppra" in loaded
    # nor hashlib (OpenSSL; the kernels' digests are CPython's own SHA-256's: aot.py)
    assert not loaded & ({"numpy.random", "hashlib", "matplotlib", "rclpy", "numba"} | SCIPY)


def _kernels_built():
    """Whether every kernel module has its ahead-of-time build (``make``)."""
    from cdh_planner.manifold import kernels
    from cdh_planner.scene import kernels as scene_kernels
    from cdh_planner.model import elastic_kernel
    from cdh_planner.wrench import compiled
    from cdh_planner import accuracy_kernel
    from cdh_planner.trajectory import motion_kernel
    return aot_built(kernels, scene_kernels, compiled, elastic_kernel, accuracy_kernel,
                     motion_kernel)


@pytest.mark.skipif(not _kernels_built(), reason="no ahead-of-time kernels built (make)")
def test_an_eight_cable_plan_and_verify_compile_nothing(tmp_path):
    """robot2_8 planned over charts (the manifold's kernel, the band test: the centred
    rule), CoGiRo poses verified (the facet test, the accuracy's zonotope):
    with the kernels built ahead of time numba is never imported, so nothing is compiled."""
    problem = REPO / "config" / "problems" / "robot2_8_pivot.yaml"
    poses = tmp_path / "poses.json"
    poses.write_text(json.dumps([{"position": [0.0, 0.0, 2.5], "tau": [0.0, 0.0, 0.0]},
                                 {"position": [0.5, 0.2, 2.6], "tau": [0.0, 0.1, 0.0]}]))
    cogiro = REPO / "config" / "cogiro.yaml"
    code = ("import contextlib, io\nfrom cdh_planner import cli\n"
            "with contextlib.redirect_stdout(io.StringIO()) as out:\n"
            f"    assert cli.main(['plan', {str(problem)!r}, '--quiet']) == 0\n"
            f"    assert cli.main(['verify', {str(cogiro)!r}, {str(poses)!r}, '--json', "
            f"{str(tmp_path / 'out.json')!r}]) == 0\n"
            "import re\nassert re.search(r'over [1-9][0-9]* charts', out.getvalue())\n"
            "assert 'ALL FEASIBLE' in out.getvalue()")
    assert "numba" not in _modules_after(code)


@pytest.mark.skipif(not _kernels_built(), reason="no ahead-of-time kernels built (make)")
def test_verify_with_a_scene_clear_of_the_bounds_loads_no_coal_numba_or_scipy(tmp_path):
    """Robot 2 poses next to the ball of config/scenes/robot2_ball.yaml, written to --json:
    the compiled kernel's lower bounds settle every pose, so coal (30 - 60 ms to import) is
    never loaded; nor numba, scipy or numpy.random (the robot file's probes)."""
    poses = tmp_path / "poses.json"
    poses.write_text(json.dumps([{"position": [0.0, 0.0, 0.3], "tau": [0.0, 0.1, 0.0]},
                                 {"position": [0.001, 0.0, 0.3], "tau": [0.0, 0.1, 0.0]}]))
    code = ("import contextlib, io\nfrom cdh_planner import cli\n"
            "with contextlib.redirect_stdout(io.StringIO()) as out:\n"
            f"    assert cli.main(['verify', {str(REPO / 'config' / 'robot2.yaml')!r}, "
            f"{str(poses)!r}, '--scene', {str(REPO / 'config' / 'scenes' / 'robot2_ball.yaml')!r}, "
            f"'--json', {str(tmp_path / 'out.json')!r}]) == 0\n")
    assert _modules_after(code) == {"numpy", "yaml"}


def test_toppra_is_imported_without_matplotlib_and_its_plt_still_works():
    code = ("import cdh_planner.trajectory.dynamics\n"
            "import toppra.algorithm.algorithm as a\n"
            "assert 'matplotlib' not in sys.modules\n"
            "import matplotlib\nmatplotlib.use('Agg')\nimport matplotlib.pyplot as plt\n"
            "assert a.plt.figure is plt.figure")
    assert "toppra" in _modules_after(code)


@pytest.mark.parametrize("argv, expected", [
    (["plan", "x.yaml"], "plan"), (["--debug", "node"], "node"), (["--help", "plan"], None),
    (["plan", "--help"], "plan"), ([], None), (["--version"], None), (["nonsense"], None),
])
def test_requested_command(argv, expected):
    assert cli.requested_command(argv) == expected


def test_summaries_are_the_commands_own_help():
    sub = next(a for a in cli.build_parser()._actions if a.dest == "command")
    helps = {a.dest: a.help for a in sub._choices_actions}
    assert helps == {name: cli.summaries()[name] for name in helps}
    assert set(helps) == set(cli.COMMANDS)


def test_top_level_help_lists_every_summary(capsys):
    assert cli.main(["--help"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    for name, summary in cli.summaries().items():
        assert name in out and " ".join(summary.split()) in out


def test_toppra_is_imported_without_scipy_interpolate_or_sparse_and_they_still_work():
    """Its names from them are stand-ins that reach the real classes at first use."""
    code = ("import cdh_planner.trajectory.dynamics\n"
            "import toppra.interpolator as ti, toppra.simplepath as sp\n"
            "import toppra.solverwrapper.ecos_solverwrapper as ecos\n"
            "assert 'scipy.interpolate' not in sys.modules and 'scipy.sparse' not in sys.modules\n"
            "assert 'scipy' not in sys.modules\n"
            "import numpy as np\n"
            "path = ti.SplineInterpolator([0.0, 1.0, 2.0], [[0.0], [1.0], [0.0]])\n"
            "assert abs(path(0.5)[0] - ti.CubicSpline([0.0, 1.0, 2.0], [0.0, 1.0, 0.0])(0.5)) < 1e-15\n"
            "import scipy.interpolate\n"
            "assert type(path.cspl) is scipy.interpolate.CubicSpline\n"
            "assert sp.BPoly.from_derivatives == scipy.interpolate.BPoly.from_derivatives\n"
            "assert ecos.scipy.sparse.lil_matrix((2, 2)).shape == (2, 2)\n")
    loaded = _modules_after(code)
    assert {"toppra", "scipy.interpolate", "scipy.sparse"} <= loaded


def test_a_planning_algorithm_that_needs_scipy_still_gets_it():
    """The deferred imports stop at toppra: the first chart's k-d tree, a long path's
    banded solve and other commands import scipy as usual."""
    code = ("import cdh_planner.trajectory.dynamics\n"
            "import numpy as np\n"
            "from cdh_planner.ports import splines\n"
            "n = splines.DENSE_MAX + 1\n"
            "ab = np.vstack([np.ones(n), 4 * np.ones(n), np.ones(n)])\n"
            "x = splines.solve_banded((1, 1), ab, np.ones(n))\n"
            "assert abs(x[n // 2] - 1 / 6) < 1e-12\n"
            "from scipy.spatial import cKDTree\n"
            "assert cKDTree(np.eye(3)).query([1.0, 0.0, 0.0])[1] == 0\n")
    assert {"scipy.linalg", "scipy.spatial"} <= _modules_after(code)


def test_toppra_defers_scipy_interpolate_also_when_scipy_is_already_loaded():
    code = ("import scipy.linalg\n"
            "import cdh_planner.trajectory.dynamics\n"
            "assert 'scipy.interpolate' not in sys.modules and 'scipy.sparse' not in sys.modules\n"
            "import toppra.interpolator as ti\n"
            "assert abs(ti.CubicSpline([0.0, 1.0], [0.0, 2.0])(0.5) - 1.0) < 1e-15\n")
    assert "scipy.interpolate" in _modules_after(code)


@pytest.mark.parametrize("given, expected", [(None, "1"), ("2", "2")])
def test_the_cli_asks_for_one_blas_thread_unless_told_otherwise(given, expected):
    """Set before numpy loads OpenBLAS (its thread pool's start is 30 ms of a plan)."""
    import os
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if given is not None:
        env["OPENBLAS_NUM_THREADS"] = given
    code = ("import contextlib, io, os\nfrom cdh_planner import cli\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n    cli.main(['--help'])\n"
            "print(os.environ['OPENBLAS_NUM_THREADS'])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env)
    assert out.stdout.strip() == expected


@pytest.mark.parametrize("own", [True, False])
def test_only_the_processs_own_command_freezes_its_modules_and_the_collector_runs_after(own):
    """main() of the process (argv from sys.argv): the modules its command imported frozen
    out of the cycle collector, which is on again; main(argv) of a caller: left alone."""
    call = ("sys.argv = ['cdh-planner', 'plan', '--help']\ncli.main()" if own
            else "cli.main(['plan', '--help'])")
    code = ("import contextlib, gc, io, sys\nfrom cdh_planner import cli\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            f"    {call}\n"
            "assert 'cdh_planner.commands.plan' in sys.modules and gc.isenabled()\n"
            f"assert (gc.get_freeze_count() > 10000) is {own}\n")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_a_plan_process_exits_with_its_output_whole(tmp_path):
    """``python -m cdh_planner.cli``: the process's own command, whose exit freezes the objects
    still alive (its finalization then skips the collector): the JSON and stdout complete."""
    problem = REPO / "config" / "problems" / "robot2_q1_q2.yaml"
    out = tmp_path / "plan.json"
    run = subprocess.run([sys.executable, "-m", "cdh_planner.cli", "plan", str(problem), "--quiet",
                          "--json", str(out)], capture_output=True, text=True)
    assert run.returncode == 0 and run.stdout.rstrip().endswith(f"JSON: {out}")
    assert json.loads(out.read_text())["success"] is True


def test_a_runs_parser_holds_only_its_command_and_help_holds_every_one():
    def choices(parser):
        return set(next(a for a in parser._actions if a.dest == "command").choices)
    assert choices(cli.build_parser(["plan"], others=False)) == {"plan"}
    assert choices(cli.build_parser([])) == set(cli.COMMANDS)


@pytest.mark.parametrize("columns", [None, "57", "200", "0", "wide"])
def test_help_is_as_wide_as_argparse_makes_it(monkeypatch, columns):
    """The parsers' formatters get their width from ``cli.help_width``, not from argparse
    (which imports shutil for it): the same width as argparse's default, COLUMNS or the
    terminal's (here none: stdout is captured) less 2."""
    import shutil
    if columns is None:
        monkeypatch.delenv("COLUMNS", raising=False)
    else:
        monkeypatch.setenv("COLUMNS", columns)
    assert cli.help_width() == shutil.get_terminal_size().columns - 2
    parser = cli.build_parser(["verify"], others=False)
    subparser = parser._subparsers._group_actions[0].choices["verify"]
    for p in (parser, subparser):
        assert p._get_formatter()._width == cli.help_width()


def test_a_commands_parsing_imports_no_shutil():
    """argparse imports shutil (with bz2 and lzma, 3 ms) for a formatter without a width."""
    probe = ("import sys\nfrom cdh_planner import cli\n"
             "p = cli.build_parser(['verify'], others=False)\n"
             "p.parse_args(['verify', 'robot.yaml', 'poses.json'])\n"
             "print(sorted({'shutil', 'bz2', 'lzma'} & set(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
