"""The robot description: ``robot_description`` (latched, over DDS) and ``cdh-planner urdf``
give the same URDF, which yourdfpy parses: the z-up fixed frame over the paper's z-down
frame, the anchors where the robot file puts them, the platform on a floating joint."""

import io
import subprocess

import numpy as np
import yourdfpy
from std_msgs.msg import String

from cdh_planner.ros.client import PlannerClient
from cdh_planner.ros.core.description import urdf
from cdh_planner.ros.interface import LATCHED
from cdh_planner.ros.core.params import node_config
from ros_harness import ROBOT2, NodeProcess, claimed_domain, cli, file_parameters

ROBOT = node_config(file_parameters(ROBOT2)).robot


def _parse(text):
    return yourdfpy.URDF.load(io.StringIO(text), build_scene_graph=True, load_meshes=False)


def _check(model, robot):
    names = {link.name for link in model.robot.links}
    assert {"world", "cdh_base", "cdh_platform"} <= names
    assert {f"{n}_base_anchor" for n in robot.winch_names} <= names
    assert {f"{n}_platform_anchor" for n in robot.winch_names} <= names
    joints = {j.name: j for j in model.robot.joints}
    assert joints["cdh_base_to_cdh_platform"].type == "floating"
    turn = model.get_transform("cdh_base", "world")              # cdh_base in world
    np.testing.assert_allclose(turn[:3, :3], np.diag([1.0, -1.0, -1.0]), atol=1e-15)
    for name, a, b in zip(robot.winch_names, robot.base_anchors, robot.platform_anchors):
        np.testing.assert_allclose(
            model.get_transform(f"{name}_base_anchor", "cdh_base")[:3, 3], a, atol=1e-15)
        np.testing.assert_allclose(
            model.get_transform(f"{name}_platform_anchor", "cdh_platform")[:3, 3], b,
            atol=1e-15)


def test_robot_description_over_dds_parses_as_urdf_and_is_the_commands(tmp_path):
    with claimed_domain() as domain, NodeProcess(domain, tmp_path, fake=True) as node, \
            PlannerClient(domain_id=domain) as client:
        got = []
        client.node.create_subscription(String, "/robot_description", got.append, LATCHED)
        client.wait_for_node(30.0)
        assert client.spin_until(lambda: got, 10.0), node.log()
        text = got[-1].data
    _check(_parse(text), ROBOT)
    printed = subprocess.run(cli("urdf", str(ROBOT2)), capture_output=True, text=True,
                             timeout=60)
    assert printed.returncode == 0, printed.stderr
    assert printed.stdout == text


def test_urdf_command_writes_a_file_and_refuses_bad_input(tmp_path):
    out = tmp_path / "robot2.urdf"
    r = subprocess.run(cli("urdf", str(ROBOT2), "-o", str(out), "--fixed-frame", "map"),
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and out.exists(), r.stderr
    model = _parse(out.read_text())
    assert "map" in {link.name for link in model.robot.links}
    for args, field in ((["-o", str(ROBOT2)], "--output"), (["--base-frame", ""], "--base-frame"),
                        (["--platform-frame", "cdh_base"], "--platform-frame")):
        r = subprocess.run(cli("urdf", str(ROBOT2), *args), capture_output=True, text=True,
                           timeout=60)
        assert r.returncode == 2 and field in r.stderr and len(r.stderr.splitlines()) == 1, \
            r.stderr
    r = subprocess.run(cli("urdf", str(tmp_path / "none.yaml")), capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 2, r.stderr


def test_the_load_s_mass_and_inertia_are_the_platforms():
    robot = ROBOT
    assert robot.mass == 0.6                  # config/robot2.yaml: a 0.6 kg disc
    link = {link.name: link for link in _parse(urdf(robot)).robot.links}["cdh_platform"]
    assert link.inertial.mass == robot.mass
    np.testing.assert_allclose(link.inertial.origin[:3, 3], robot.load_point, atol=0)
    np.testing.assert_allclose(link.inertial.inertia, robot.inertia, atol=0)
