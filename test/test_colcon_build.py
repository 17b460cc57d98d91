"""A colcon workspace holding this repository builds both packages, cdh_planner (ament_python,
the repository's root) and cdh_planner_interfaces (ament_cmake, interfaces/), and the
installed workspace gives the node's types and files. Slow (about a minute, more the first
time: colcon is installed into build/colcon-tools from test/requirements-colcon.txt):

    .venv/bin/python -m pytest -m slow test/test_colcon_build.py

The workspace is a copy of the working tree in a temporary folder, built as
interfaces/README.md says for a venv: AMENT_PREFIX_PATH and CMAKE_PREFIX_PATH name the
venv, ``--base-paths`` names the repository and its interfaces/ folder (colcon does not
look inside a package's folder, and the root holds cdh_planner's package.xml), and
``-DPython3_EXECUTABLE`` the venv's python. interfaces/control_msgs has a COLCON_IGNORE:
colcon users take the real control_msgs.
"""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import REPO

pytestmark = pytest.mark.slow
TOOLS = REPO / "build" / "colcon-tools"
PIN = REPO / "test" / "requirements-colcon.txt"


def colcon_env():
    env = dict(os.environ, AMENT_PREFIX_PATH=sys.prefix, CMAKE_PREFIX_PATH=sys.prefix,
               PYTHONPATH=str(TOOLS), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    return env


def ensure_colcon():
    if not (TOOLS / "colcon_core").is_dir():
        subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target",
                        str(TOOLS), "-r", str(PIN)], check=True, timeout=600)


def copy_working_tree(dest):
    """The repository's tracked and untracked, not ignored, files (no .venv, no build/)."""
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=REPO,
                           capture_output=True, check=True).stdout.decode().split("\0")
    for name in filter(None, files):
        src = REPO / name
        if src.is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)


def colcon(ws, *args, timeout=900):
    return subprocess.run([sys.executable, "-m", "colcon", *args], cwd=ws, env=colcon_env(),
                          capture_output=True, text=True, timeout=timeout)


@pytest.mark.timeout(1200)
def test_colcon_builds_the_node_and_its_interfaces(tmp_path):
    ensure_colcon()
    ws = tmp_path / "ws"
    src = ws / "src" / "cdh_planner"
    src.mkdir(parents=True)
    copy_working_tree(src)
    paths = ["--base-paths", "src/cdh_planner", "src/cdh_planner/interfaces"]

    listed = colcon(ws, "list", "--names-only", *paths)
    assert listed.returncode == 0, listed.stderr
    assert sorted(listed.stdout.split()) == ["cdh_planner", "cdh_planner_interfaces"]

    built = colcon(ws, "build", *paths, "--event-handlers", "console_direct-",
                   "--cmake-args", "-DBUILD_TESTING=OFF", f"-DPython3_EXECUTABLE={sys.executable}")
    assert built.returncode == 0, built.stdout[-3000:] + built.stderr[-3000:]
    install = ws / "install"
    assert (install / "cdh_planner" / "share" / "cdh_planner" / "launch"
            / "cdh_planner.launch.py").is_file()
    assert (install / "cdh_planner" / "share" / "cdh_planner" / "LICENSE").is_file()
    script = install / "cdh_planner" / "lib" / "cdh_planner" / "cdh-planner"
    assert script.is_file()   # what `ros2 run cdh_planner cdh-planner` and the launch file run

    # The installed workspace, sourced as interfaces/README.md says: AMENT_PREFIX_PATH first,
    # then install/setup.bash.
    check = (
        "from pathlib import Path\n"
        "import cdh_planner, cdh_planner_interfaces\n"
        "from ament_index_python.packages import get_package_share_directory as share\n"
        "from cdh_planner_interfaces.action import PlanPath\n"
        "from rclpy.serialization import serialize_message, deserialize_message\n"
        "r = PlanPath.Result(error_code=PlanPath.Result.CANCELED)\n"
        "assert deserialize_message(serialize_message(r), PlanPath.Result) == r\n"
        "for p in (cdh_planner.__file__, cdh_planner_interfaces.__file__,\n"
        "          share('cdh_planner'), share('cdh_planner_interfaces')):\n"
        "    print(Path(p).resolve())\n")
    env = {k: v for k, v in colcon_env().items() if k not in ("PYTHONPATH", "CMAKE_PREFIX_PATH")}
    run = subprocess.run(
        ["bash", "-c", f'source install/setup.bash && "{sys.executable}" -c "$CHECK" && '
                       f'"{script}" --help'],
        cwd=ws, env=dict(env, CHECK=check), capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    lines = run.stdout.splitlines()
    for line in lines[:4]:
        assert Path(line).is_relative_to(install.resolve()), line
    assert "usage: cdh-planner" in run.stdout
