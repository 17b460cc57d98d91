"""Packaging: package.xml and setup.py declare every runtime dependency the package imports,
setup.py installs the launch file, the launch file (read with ast: ``launch`` is not on
PyPI) starts the node through an entry point that exists, and the licences ship."""

import ast
import runpy
import sys
import xml.etree.ElementTree as ET

import pytest
import setuptools

from conftest import PACKAGE, REPO

LAUNCH = REPO / "launch" / "cdh_planner.launch.py"

# top-level import -> (package.xml key, setup.py install_requires name or None for ROS
# packages, which package.xml alone declares)
THIRD_PARTY = {
    "numpy": ("python3-numpy", "numpy"),
    "scipy": ("python3-scipy", "scipy"),
    "yaml": ("python3-yaml", "pyyaml"),
    "matplotlib": ("python3-matplotlib", "matplotlib"),
    "tqdm": ("python3-tqdm", "tqdm"),
    "threadpoolctl": ("python3-threadpoolctl", "threadpoolctl"),
    "numba": ("python3-numba", "numba"),
    "toppra": ("python3-toppra-pip", "toppra"),
    "mcap": ("mcap-ros2-support", "mcap"),
    "mcap_ros2": ("mcap-ros2-support", "mcap-ros2-support"),
    "rosbags": ("python3-rosbags-pip", "rosbags"),
    "coal": ("coal", "coal"),
    "trimesh": ("python3-trimesh-pip", "trimesh"),
    "ray": ("python3-ray-pip", "ray"),
    "mujoco": ("python3-mujoco", "mujoco"),
    "orjson": ("python3-orjson", "orjson"),
}
ROS = {"rclpy", "ament_index_python", "builtin_interfaces", "rcl_interfaces", "action_msgs",
       "std_msgs", "std_srvs", "geometry_msgs", "nav_msgs", "trajectory_msgs", "sensor_msgs",
       "diagnostic_msgs", "visualization_msgs", "shape_msgs", "service_msgs",
       "cdh_planner_interfaces",
       "control_msgs", "tf2_msgs"}
# the interfaces of the PlanPath action server and the FollowJointTrajectory client
ACTION_INTERFACES = {"action_msgs", "cdh_planner_interfaces", "control_msgs"}


def package_imports():
    """Top-level names of the non-standard-library modules that cdh_planner imports."""
    names = set()
    for f in PACKAGE.rglob("*.py"):
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.Import):
                names |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split(".")[0])
    return {n for n in names if n not in sys.stdlib_module_names and n != "cdh_planner"}


def exec_depends():
    root = ET.parse(REPO / "package.xml").getroot()
    return {e.text.strip() for tag in ("exec_depend", "depend") for e in root.iter(tag)}


@pytest.fixture(scope="module")
def setup_kwargs(monkeypatch_module):
    """The keyword arguments setup.py gives setuptools.setup (setup.py run, setup not)."""
    captured = {}
    monkeypatch_module.setattr(setuptools, "setup", lambda **kw: captured.update(kw))
    monkeypatch_module.chdir(REPO)
    runpy.run_path(str(REPO / "setup.py"), run_name="__main__")
    return captured


@pytest.fixture(scope="module")
def monkeypatch_module():
    mp = pytest.MonkeyPatch()
    yield mp
    mp.undo()


def test_every_import_is_a_known_dependency():
    unknown = package_imports() - set(THIRD_PARTY) - ROS
    assert not unknown, (f"cdh_planner imports {sorted(unknown)}: declare them in package.xml "
                         f"and setup.py (or requirements.txt) and add them to this test's tables")


# no rosdep key exists for these (ros/rosdistro rosdep/python.yaml, checked 2026-12):
# package.xml names them in a comment as pip-only, with the reason, instead of a key that
# would make `rosdep install` fail
PIP_ONLY = {"threadpoolctl", "ray", "mujoco", "orjson"}
# the non-ROS keys package.xml uses, each checked in ros/rosdistro's rosdep/python.yaml
# (2026-12): a new one must be checked there and added here
ROSDEP_KEYS = {"python3-numpy", "python3-scipy", "python3-yaml", "python3-matplotlib",
               "python3-numba", "python3-tqdm", "mcap-ros2-support", "python3-rosbags-pip",
               "python3-toppra-pip", "python3-pytest", "python3-pytest-timeout",
               "python3-hypothesis", "python3-yourdfpy-pip",
               # python.yaml's pip key for trimesh; coal is a package released into the
               # Jazzy distribution (ros-jazzy-coal), which rosdep resolves by its name
               "python3-trimesh-pip", "coal"}


def test_package_xml_declares_every_runtime_dependency():
    declared = exec_depends()
    needed = {THIRD_PARTY[n][0] if n in THIRD_PARTY else n
              for n in package_imports() if n not in PIP_ONLY}
    assert needed - declared == set()
    text = (REPO / "package.xml").read_text()
    for name in PIP_ONLY:
        assert f"pip-only: {name}" in text and THIRD_PARTY[name][0] not in declared
    assert ACTION_INTERFACES <= package_imports() and ACTION_INTERFACES <= declared
    assert {"launch", "launch_ros"} <= declared   # for the launch file


def test_every_package_xml_key_is_a_rosdep_key_or_ros():
    root = ET.parse(REPO / "package.xml").getroot()
    keys = {e.text.strip() for tag in ("exec_depend", "depend", "test_depend", "build_depend")
            for e in root.iter(tag)}
    assert keys - ROS - {"launch", "launch_ros", "lifecycle_msgs"} == ROSDEP_KEYS
    tests = {e.text.strip() for e in root.iter("test_depend")}
    assert {"python3-pytest", "python3-pytest-timeout", "python3-hypothesis",
            "python3-yourdfpy-pip"} <= tests   # what test/ imports beyond the runtime


def test_setup_py_requires_every_python_dependency(setup_kwargs):
    required = set(setup_kwargs["install_requires"])
    needed = {THIRD_PARTY[n][1] for n in package_imports() if n in THIRD_PARTY}
    assert needed - required == set()
    pinned = {line.split("==")[0].strip().lower() for line in
              (REPO / "requirements.txt").read_text().splitlines() if "==" in line}
    assert {r.lower() for r in required} - {"setuptools"} <= pinned


def test_setup_py_installs_the_launch_file_and_licence(setup_kwargs):
    files = dict(setup_kwargs["data_files"])
    assert files["share/cdh_planner/launch"] == ["launch/cdh_planner.launch.py"]
    assert "LICENSE" in files["share/cdh_planner"]
    scripts = setup_kwargs["entry_points"]["console_scripts"]
    assert "cdh-planner = cdh_planner.cli:main" in scripts


def _calls(tree, name):
    return [n for n in ast.walk(tree) if isinstance(n, ast.Call)
            and getattr(n.func, "id", getattr(n.func, "attr", None)) == name]


def _kwargs(call):
    return {k.arg: k.value for k in call.keywords}


def test_launch_file_declares_the_robot_argument_and_starts_the_node():
    tree = ast.parse(LAUNCH.read_text())
    functions = {f.name for f in tree.body if isinstance(f, ast.FunctionDef)}
    assert "generate_launch_description" in functions
    imported = {(n.module, a.name) for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)
                for a in n.names}
    assert {("launch.actions", "DeclareLaunchArgument"), ("launch_ros.actions", "Node"),
            ("launch.substitutions", "LaunchConfiguration")} <= imported

    declare, mode = _calls(tree, "DeclareLaunchArgument")[:2]
    assert ast.literal_eval(declare.args[0]) == "robot"
    assert ast.literal_eval(mode.args[0]) == "execution_mode"
    from cdh_planner.ros.core.params import SPEC
    # the mode's choices are the registry's (a new command outlet needs no change there)
    assert ("cdh_planner.ros.execution.command_outlets", "OUTLETS") in imported
    assert ast.unparse(_kwargs(mode)["choices"]) == "list(OUTLETS)"
    assert ast.literal_eval(_kwargs(mode)["default_value"]) == SPEC["execution.mode"].default
    default = _kwargs(declare)["default_value"]
    parts = [ast.literal_eval(a) for a in default.elts[1:]] if isinstance(default, ast.List) \
        else [ast.literal_eval(a) for a in default.args[0].elts[1:]]
    assert (REPO / "/".join(parts)).is_file()   # config/robot2.yaml, installed by setup.py

    (node,) = _calls(tree, "Node")
    kw = _kwargs(node)
    assert ast.literal_eval(kw["package"]) == "cdh_planner"
    assert ast.literal_eval(kw["executable"]) == "cdh-planner"
    assert ast.literal_eval(kw["arguments"]) == ["node"]
    param, overrides = kw["parameters"].elts
    assert param.func.id == "LaunchConfiguration" and ast.literal_eval(param.args[0]) == "robot"
    given = {ast.literal_eval(k): v for k, v in zip(overrides.keys, overrides.values)}
    assert {k: (v.func.id, ast.literal_eval(v.args[0])) for k, v in given.items()} == {
        "execution.mode": ("LaunchConfiguration", "execution_mode"),
        "use_sim_time": ("LaunchConfiguration", "use_sim_time")}
    # namespace, use_sim_time and log_level are launch arguments
    declared = {ast.literal_eval(c.args[0]): _kwargs(c)
                for c in _calls(tree, "DeclareLaunchArgument")}
    assert {"namespace", "use_sim_time", "log_level"} <= set(declared)
    assert ast.literal_eval(declared["use_sim_time"]["default_value"]) == "false"
    assert kw["namespace"].func.id == "LaunchConfiguration"
    assert ast.literal_eval(kw["namespace"].args[0]) == "namespace"
    level_flag, level = kw["ros_arguments"].elts
    assert ast.literal_eval(level_flag) == "--log-level" and ast.literal_eval(level.args[0]) == \
        "log_level"


def test_the_launch_files_command_exists_and_knows_node():
    """``cdh-planner node`` is what the launch file runs: the entry point resolves and
    ``node`` is one of its commands."""
    from importlib.metadata import entry_points
    (ep,) = [e for e in entry_points(group="console_scripts") if e.name == "cdh-planner"]
    assert ep.value == "cdh_planner.cli:main" and callable(ep.load())
    assert (PACKAGE / "commands" / "node.py").is_file()


def test_licences_ship():
    text = (REPO / "LICENSE").read_text()
    assert "Apache License" in text and "Version 2.0, January 2004" in text
    assert "END OF TERMS AND CONDITIONS" in text
    root = ET.parse(REPO / "package.xml").getroot()
    assert root.findtext("license") == "Apache-2.0"
    for name in ("control_msgs", "tf2_msgs"):
        copy = REPO / "interfaces" / name
        assert "Redistribution and use in source and binary forms" in (copy / "LICENSE").read_text()
        assert ET.parse(copy / "package.xml").getroot().findtext("license") == "BSD-3-Clause"
        assert "install(FILES LICENSE" in (copy / "CMakeLists.txt").read_text()
        assert (copy / "COLCON_IGNORE").exists()


def test_rviz_config_shows_the_nodes_latched_outputs(setup_kwargs):
    """config/cdh_planner.rviz (installed with the config files): the fixed frame is the
    node's default fixed_frame (z up), and its displays subscribe to the node's ~/markers and
    ~/path with the latched QoS they are published with."""
    import yaml
    from cdh_planner.ros.core.params import SPEC
    cfg = yaml.safe_load((REPO / "config" / "cdh_planner.rviz").read_text())
    manager = cfg["Visualization Manager"]
    assert manager["Global Options"]["Fixed Frame"] == SPEC["fixed_frame"].default
    topics = {d["Topic"]["Value"]: d for d in manager["Displays"] if "Topic" in d}
    assert set(topics) == {"/cdh_planner/markers", "/cdh_planner/path",
                           "/cdh_planner/live_markers", "/cdh_planner/scene_markers"}
    # the plan's and the scene's; live: volatile
    latched = {"/cdh_planner/markers", "/cdh_planner/path", "/cdh_planner/scene_markers"}
    assert all((d["Topic"]["Durability Policy"] == "Transient Local") == (t in latched)
               for t, d in topics.items())
    assert "config/cdh_planner.rviz" in dict(setup_kwargs["data_files"])["share/cdh_planner/config"]
